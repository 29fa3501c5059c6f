//! Forward-mode differentiation: the integrators run on dual numbers whose
//! tangent is seeded from the parameter store (`Dual::from_param`), so the
//! derivative image along a tangent direction costs one extra pass of the
//! same code (like Mitsuba's `render_forward`).

use super::warn_missing_boundary_terms;
use crate::ad::Dual;
use crate::error::{Error, Result};
use crate::integrator::{render::render_samples, Integrator, RenderOptions, Rendered};
use crate::params::{ParamView, Seeds};
use crate::scene::Scene;

/// The derivative image dI/dθ·t along the tangent `t` given per parameter
/// key (each slice as long as the parameter). Parameters not listed have
/// zero tangent. Uses the same random numbers as [`crate::integrator::render`]
/// with the same options, so it is the derivative of that very estimate.
/// The tangents live in this call, not in the scene.
pub fn render_forward(
    scene: &Scene,
    tangents: &[(&str, &[f32])],
    opts: &RenderOptions,
) -> Result<Rendered> {
    let seeds = Seeds::tangents(&scene.params, tangents)?;
    let keys: Vec<&str> = tangents.iter().map(|(k, _)| *k).collect();
    warn_missing_boundary_terms(scene, &keys)?;
    derivative_image(scene, &scene.params.view(&seeds), opts)
}

fn derivative_image(scene: &Scene, store: &ParamView, opts: &RenderOptions) -> Result<Rendered> {
    let integrator = &scene.integrator;
    if let Integrator::Aov(_) = integrator {
        return Err(Error::Invalid(
            "the aov integrator has no derivatives; use path or direct".into(),
        ));
    }
    let (block, non_finite_samples) =
        render_samples(scene, opts, 3, "forward mode", |cs, rng, out| {
            if let Some(l) = integrator.radiance::<Dual>(scene, store, cs, rng) {
                out.copy_from_slice(&[l.x.d, l.y.d, l.z.d]);
            }
        })?;
    Ok(Rendered {
        width: block.width,
        height: block.height,
        channel_names: vec!["R".into(), "G".into(), "B".into()],
        data: block.develop(),
        non_finite_samples,
    })
}
