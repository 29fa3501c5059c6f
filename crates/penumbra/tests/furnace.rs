//! White furnace: a white diffuse sphere inside a uniform environment of
//! radiance 1 must look exactly like the environment (every path's
//! expected value is 1), for the path tracer with unbounded depth and
//! Russian roulette. Any energy gain or loss (BSDF normalisation, MIS
//! weights, emitter pdfs, roulette weights) shows as a mean ≠ 1. The same
//! holds for a sphere of non-absorbing medium (albedo 1) seen by the
//! volumetric path tracer, behind a null or a dielectric boundary: it
//! checks the free-flight weights, delta tracking's null collisions, the
//! phase functions and the transmittance of shadow rays.

use crate::common;

use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::path::Path;

fn furnace(bsdf: &str) -> (f64, f64) {
    furnace_with("path", bsdf)
}

/// The furnace with `integrator` and the sphere's contents `shape` (its
/// BSDF, media).
fn furnace_with(integrator: &str, shape: &str) -> (f64, f64) {
    let sensor = common::sensor_xml("0, 0, 4", 30.0, 32, 64, Some("box"));
    let xml = format!(
        r#"<scene version="3.0.0">
            <integrator type="{integrator}"/>
            {sensor}
            <shape type="sphere">{shape}</shape>
            <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
        </scene>"#
    );
    let scene = Scene::load_str(&xml, Path::new("furnace.xml"), &[]).unwrap();
    let img = render(
        &scene,
        &RenderOptions {
            seed: 3,
            ..Default::default()
        },
    )
    .unwrap();
    // mean and its standard error over pixels (pixels are independent)
    let v: Vec<f64> = img.data.iter().map(|&x| x as f64).collect();
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn white_diffuse_sphere_disappears_in_a_furnace() {
    let (mean, se) =
        furnace(r#"<bsdf type="diffuse"><rgb name="reflectance" value="1, 1, 1"/></bsdf>"#);
    eprintln!("diffuse furnace: {mean} ± {se}");
    assert!((mean - 1.0).abs() < 5.0 * se + 1e-4, "mean {mean} ± {se}");
}

#[test]
fn smooth_dielectric_sphere_disappears_in_a_furnace() {
    // lossless: every path carries weight 1 (reflection or refraction)
    let (mean, se) = furnace(r#"<bsdf type="dielectric"/>"#);
    eprintln!("dielectric furnace: {mean} ± {se}");
    assert!((mean - 1.0).abs() < 5.0 * se + 1e-3, "mean {mean} ± {se}");
}

#[test]
fn scattering_media_disappear_in_a_furnace() {
    let homogeneous = r#"<medium type="homogeneous" name="interior">
            <rgb name="sigma_t" value="0.5, 0.75, 1"/>
            <float name="scale" value="3"/>
            <float name="albedo" value="1"/>
            <phase type="hg"><float name="g" value="0.6"/></phase>
        </medium>"#;
    // a constant extinction tracked against a majorant: null collisions
    let heterogeneous = r#"<medium type="heterogeneous" name="interior">
            <volume type="constvolume" name="sigma_t"><float name="value" value="2"/></volume>
            <float name="albedo" value="1"/>
            <phase type="hg"><float name="g" value="-0.4"/></phase>
        </medium>"#;
    for (boundary, medium, tol) in [
        ("null", homogeneous, 1e-4),
        ("null", heterogeneous, 1e-4),
        // lossless glass around the medium
        ("dielectric", homogeneous, 1e-3),
    ] {
        let (mean, se) = furnace_with("volpath", &format!(r#"<bsdf type="{boundary}"/>{medium}"#));
        eprintln!("{boundary} boundary: {mean} ± {se}");
        assert!(
            (mean - 1.0).abs() < 5.0 * se + tol,
            "{boundary}: mean {mean} ± {se}\n{medium}"
        );
    }
}
