//! The stratified samplers (`multijitter`, `ldsampler`, `orthogonal`)
//! against `independent` at equal sample counts: on their conformance
//! scenes (scenes/conformance/sampler_*.xml), the relMSE against Mitsuba's
//! reference must be lower than that of independent sampling. (That each
//! one is unbiased is the conformance test's job; that its points are
//! stratified is checked by the unit tests beside each sampler.)

use penumbra::image::read_image;
use penumbra::integrator::{render, RenderOptions};
use penumbra::sampler::{Independent, Sampler};
use penumbra::scene::Scene;
use std::path::PathBuf;

/// Independent renders averaged per estimate.
const SEEDS: u64 = 8;

/// relMSE of `scene` against `reference`, averaged over [`SEEDS`] renders
/// of the scene's sample count (weights as the conformance test's).
fn rel_mse(scene: &Scene, reference: &[f32]) -> f64 {
    let mut total = 0.0;
    for seed in 1..=SEEDS {
        let img = render(
            scene,
            &RenderOptions {
                seed,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(img.data.len(), reference.len());
        total += img
            .data
            .iter()
            .zip(reference)
            .map(|(&x, &r)| {
                let r = r as f64;
                (x as f64 - r).powi(2) / (r * r + 1e-2)
            })
            .sum::<f64>()
            / reference.len() as f64;
    }
    total / SEEDS as f64
}

#[test]
fn stratified_samplers_converge_faster_than_independent() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/conformance");
    for (name, plugin) in [
        ("sampler_multijitter", "multijitter"),
        ("sampler_ldsampler", "ldsampler"),
        ("sampler_orthogonal", "orthogonal"),
    ] {
        let mut scene = Scene::load_file(&dir.join(format!("{name}.xml")), &[]).unwrap();
        let reference = read_image(&dir.join("refs").join(format!("{name}.exr"))).unwrap();
        let sampler = scene.sensors[0].sampler.clone();
        assert_eq!(sampler.plugin_name(), plugin);
        let spp = sampler.sample_count();
        let ours = rel_mse(&scene, &reference.data);
        scene.sensors[0].sampler = Sampler::Independent(Independent {
            sample_count: spp,
            seed: sampler.seed(),
        });
        let independent = rel_mse(&scene, &reference.data);
        eprintln!(
            "{plugin}: {spp} spp, relMSE {ours:.4e}, independent {independent:.4e} \
             (ratio {:.3})",
            ours / independent
        );
        // each estimate averages 8 × 64² pixels × 3 channels: its own noise
        // is a few percent, far below the margin asked for
        assert!(
            ours < 0.95 * independent,
            "{plugin}: relMSE {ours:.4e} is not below independent sampling's {independent:.4e}"
        );
    }
}
