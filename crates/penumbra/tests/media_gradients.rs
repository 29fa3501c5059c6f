//! Derivatives with respect to every differentiable medium parameter
//! against central finite differences with the same random numbers, and
//! forward against reverse mode, on the bundled volume scenes at 32².
//!
//! Finite differences: I(θ + εt) − I(θ − εt) over 2ε, both sides rendered
//! with the same seeds. The sampled distances move continuously with θ
//! (t = −ln(1 − u)/σ, or the majorant's rate), so most paths are the same
//! on both sides; a path whose free flight crosses a surface on one side
//! only changes, which makes the difference noisy, not biased. Each
//! comparison takes the image sums of K batches of both estimates; their
//! paired differences give the standard error, and the two must agree
//! within 4 of it (plus ε² curvature, below 1e-3 relative at the steps
//! used: 1 % for constants, 5 % for the grid, whose noisier differences
//! need the larger step).

use penumbra::diff::{render_backward, render_forward};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;

use crate::volume_scenes;

const BATCHES: u64 = 8;

fn opts(spp: u32, seed: u64) -> RenderOptions {
    RenderOptions {
        spp: Some(spp),
        seed,
        ..Default::default()
    }
}

/// The scene at 32² (the volume scenes; the conformance scenes are small
/// already) with the parameter `key` set to `value` (if given).
fn scene(name: &str, key: &str, value: Option<&[f32]>) -> Scene {
    let defines: &[(&str, &str)] = if name.starts_with("conformance/") {
        &[]
    } else {
        &[("res", "32")]
    };
    let mut s = volume_scenes::load(name, defines);
    if let Some(v) = value {
        s.params.set(key, v).unwrap();
        s.update().unwrap();
    }
    s
}

fn image_sum(data: &[f32]) -> f64 {
    data.iter().map(|&v| v as f64).sum()
}

/// Forward mode along `tangent` against central differences of step
/// `eps` (relative to the tangent), `spp` per batch.
fn check_against_finite_differences(
    name: &str,
    key: &str,
    value: Option<Vec<f32>>,
    tangent: Vec<f32>,
    eps: f32,
    spp: u32,
) {
    let base = scene(name, key, value.as_deref());
    let x0 = base.params.data(base.params.require(key).unwrap()).to_vec();
    let shifted = |sign: f32| -> Vec<f32> {
        x0.iter()
            .zip(&tangent)
            .map(|(x, t)| x + sign * eps * t)
            .collect()
    };
    let plus = scene(name, key, Some(&shifted(1.0)));
    let minus = scene(name, key, Some(&shifted(-1.0)));
    let (mut fd, mut ad) = (Vec::new(), Vec::new());
    for b in 0..BATCHES {
        let o = opts(spp, 500 + b);
        let ip = image_sum(&render(&plus, &o).unwrap().data);
        let im = image_sum(&render(&minus, &o).unwrap().data);
        fd.push((ip - im) / (2.0 * eps as f64));
        ad.push(image_sum(
            &render_forward(&base, &[(key, &tangent)], &o).unwrap().data,
        ));
    }
    let n = BATCHES as f64;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
    let diff: Vec<f64> = fd.iter().zip(&ad).map(|(f, a)| f - a).collect();
    let md = mean(&diff);
    let se = (diff.iter().map(|d| (d - md).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    eprintln!(
        "{name} {key}: forward {:.4}, finite differences {:.4} (difference {md:.4} ± {se:.4})",
        mean(&ad),
        mean(&fd)
    );
    assert!(
        md.abs() <= 4.0 * se + 1e-3 * mean(&ad).abs(),
        "{name} {key}: forward {} vs finite differences {} (± {se})",
        mean(&ad),
        mean(&fd)
    );
}

#[test]
fn homogeneous_medium_parameters_match_finite_differences() {
    for (key, tangent) in [
        ("medium.albedo.value.value", vec![0.9, 0.7, 0.5]),
        ("medium.sigma_t.value.value", vec![3.0]),
        ("medium.scale", vec![1.0]),
    ] {
        check_against_finite_differences("volume_homog", key, None, tangent, 0.01, 64);
    }
}

/// The density grid at the usual initial guess of a reconstruction (a
/// uniform 0.3, where the extinction equals its maximum everywhere: the
/// case in which a majorant equal to the maximum loses the derivative of
/// transmittance) along a uniform tangent, and as loaded, scaled; the
/// albedo and the scale.
#[test]
fn heterogeneous_medium_parameters_match_finite_differences() {
    let density = "medium.sigma_t.data";
    let n = 64 * 64 * 64;
    check_against_finite_differences(
        "volume_hetero",
        density,
        Some(vec![0.3; n]),
        vec![0.3; n],
        0.05,
        32,
    );
    // scaling the loaded grid (its empty voxels must stay ≥ 0)
    let loaded = scene("volume_hetero", density, None);
    let grid = loaded
        .params
        .data(loaded.params.require(density).unwrap())
        .to_vec();
    check_against_finite_differences("volume_hetero", density, None, grid, 0.05, 32);
    for (key, tangent) in [
        ("medium.albedo.value.value", vec![0.9, 0.9, 0.9]),
        ("medium.scale", vec![25.0]),
    ] {
        check_against_finite_differences("volume_hetero", key, None, tangent, 0.05, 32);
    }
}

/// The anisotropy of a Henyey-Greenstein phase function (the smoke of the
/// conformance scene with media inside, outside and around the camera).
#[test]
fn phase_function_anisotropy_matches_finite_differences() {
    let name = "conformance/medium_interior_exterior";
    check_against_finite_differences(name, "smoke.phase_function.g", None, vec![1.0], 0.05, 128);
}

/// Reverse mode gives ⟨δI, dI/dθ · t⟩ for an adjoint image δI; with the
/// same seeds it replays the very paths of forward mode, so the two agree
/// up to rounding.
#[test]
fn forward_and_reverse_modes_agree_on_media() {
    for (name, key) in [
        ("volume_homog", "medium.sigma_t.value.value"),
        ("volume_homog", "medium.albedo.value.value"),
        ("volume_hetero", "medium.sigma_t.data"),
        ("volume_hetero", "medium.scale"),
    ] {
        let s = scene(name, key, None);
        let len = s.params.data(s.params.require(key).unwrap()).len();
        // a tangent and an adjoint image that vary across elements
        let tangent: Vec<f32> = (0..len).map(|i| 1.0 + (i % 7) as f32 * 0.1).collect();
        let o = opts(4, 9);
        let fwd = render_forward(&s, &[(key, &tangent)], &o).unwrap();
        let adjoint: Vec<f32> = (0..fwd.data.len())
            .map(|i| 0.5 + (i % 5) as f32 * 0.25)
            .collect();
        let lhs: f64 = fwd
            .data
            .iter()
            .zip(&adjoint)
            .map(|(d, a)| *d as f64 * *a as f64)
            .sum();
        let g = render_backward(&s, &adjoint, Some(&[key]), &o).unwrap();
        let rhs: f64 = g
            .get(key)
            .unwrap()
            .iter()
            .zip(&tangent)
            .map(|(g, t)| *g as f64 * *t as f64)
            .sum();
        eprintln!("{name} {key}: forward {lhs:.6e}, reverse {rhs:.6e}");
        assert!(
            (lhs - rhs).abs() <= 1e-4 * lhs.abs().max(rhs.abs()),
            "{name} {key}: forward {lhs} vs reverse {rhs}"
        );
    }
}
