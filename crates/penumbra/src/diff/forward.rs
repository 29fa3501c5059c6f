//! Forward-mode differentiation: the integrators run on dual numbers whose
//! tangent is seeded from the parameter store (`Dual::from_param`), so the
//! derivative image along a tangent direction costs one extra pass of the
//! same code (like Mitsuba's `render_forward`). When geometry or the
//! camera moves, the boundary term of primary visibility is added
//! (`primary_boundary.rs`). The budgets of both terms come from the call's
//! options, else from the integrator (`sppc`, `sppp`; see
//! `integrator::Budgets`).

use super::{
    delta_shadow_boundary, primary_boundary, shadow_boundary, warn_missing_boundary_terms,
    BoundaryTerms,
};
use crate::ad::Dual;
use crate::error::Result;
use crate::integrator::{render::render_samples, RenderOptions, Rendered};
use crate::params::{ParamView, Seeds};
use crate::scene::Scene;

/// The derivative image dI/dθ·t along the tangent `t` given per parameter
/// key (each slice as long as the parameter). Parameters not listed have
/// zero tangent. The interior term uses the same random numbers as
/// [`crate::integrator::render`] with the same options, so it is the
/// derivative of that very estimate with its film samples held fixed; the
/// boundary term of primary visibility, added when the tangent moves
/// geometry or a pinhole or orthographic camera, is estimated by samples of
/// its own on the edges. The tangents live in this call, not in the scene.
/// `opts.spp` and `opts.sppp`, where given, override the integrator's
/// `sppc` and `sppp`; a budget of 0 leaves its term out.
pub fn render_forward(
    scene: &Scene,
    tangents: &[(&str, &[f32])],
    opts: &RenderOptions,
) -> Result<Rendered> {
    let opts = &scene.integrator.derivative_options(scene, opts)?;
    let seeds = Seeds::tangents(&scene.params, tangents)?;
    let keys: Vec<&str> = tangents.iter().map(|(k, _)| *k).collect();
    let terms = BoundaryTerms::of(scene, opts)?;
    let edges_move = warn_missing_boundary_terms(scene, &keys, terms)?;
    let store = scene.params.view(&seeds);
    let mut image = derivative_image(scene, &store, opts)?;
    if edges_move && terms.primary {
        primary_boundary::add_primary_boundary(scene, &store, opts, &mut image)?;
    }
    if edges_move && terms.shadow {
        shadow_boundary::add_shadow_boundary(scene, &store, opts, &mut image)?;
    }
    if edges_move && terms.delta_shadow {
        delta_shadow_boundary::add_delta_shadow_boundary(scene, &store, opts, &mut image)?;
    }
    Ok(image)
}

fn derivative_image(scene: &Scene, store: &ParamView, opts: &RenderOptions) -> Result<Rendered> {
    let integrator = &scene.integrator;
    integrator.check_differentiable()?;
    if opts.spp == Some(0) {
        // sppc = 0: the interior term is off
        let (width, height) = scene.sensor(opts.sensor)?.film.crop_size;
        return Ok(Rendered {
            width,
            height,
            channel_names: vec!["R".into(), "G".into(), "B".into()],
            data: vec![0.0; width * height * 3],
            non_finite_samples: 0,
        });
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
