//! Forward-mode differentiation: the integrators run on dual numbers whose
//! tangent is seeded from the parameter store (`Dual::from_param`), so the
//! derivative image along a tangent direction costs one extra pass of the
//! same code (like Mitsuba's `render_forward`). When geometry or the
//! camera moves, the boundary term of primary visibility is added
//! (`primary_boundary.rs`, its own budget `RenderOptions::sppp`).

use super::{primary_boundary, warn_missing_boundary_terms};
use crate::ad::Dual;
use crate::error::{Error, Result};
use crate::integrator::{render::render_samples, Integrator, RenderOptions, Rendered};
use crate::scene::Scene;

/// The derivative image dI/dθ·t along the tangent `t` given per parameter
/// key (each slice as long as the parameter). Parameters not listed have
/// zero tangent. The interior term uses the same random numbers as
/// [`crate::integrator::render`] with the same options, so it is the
/// derivative of that very estimate with its film samples held fixed; the
/// boundary term of primary visibility, added when the tangent moves
/// geometry or a pinhole or orthographic camera, is estimated by samples of
/// its own on the edges.
pub fn render_forward(
    scene: &mut Scene,
    tangents: &[(&str, &[f32])],
    opts: &RenderOptions,
) -> Result<Rendered> {
    let keys: Vec<&str> = tangents.iter().map(|(k, _)| *k).collect();
    let primary = primary_boundary::applies(scene, opts)?;
    let geometry_moves = warn_missing_boundary_terms(scene, &keys, primary)?;
    scene.params.clear_tangents();
    for (key, t) in tangents {
        scene.params.set_tangent(key, t)?;
    }
    let result = derivative_image(scene, opts, geometry_moves).and_then(|mut image| {
        if geometry_moves && primary {
            primary_boundary::add_primary_boundary(scene, opts, &mut image)?;
        }
        Ok(image)
    });
    scene.params.clear_tangents();
    result
}

fn derivative_image(scene: &Scene, opts: &RenderOptions, geometry_moves: bool) -> Result<Rendered> {
    let integrator = &scene.integrator;
    if let Integrator::Aov(_) = integrator {
        return Err(Error::Invalid(
            "the aov integrator has no derivatives; use path or direct".into(),
        ));
    }
    let (block, non_finite_samples) =
        render_samples(scene, opts, 3, "forward mode", |cs, rng, out| {
            if let Some(l) = integrator.radiance::<Dual>(scene, cs, rng, geometry_moves) {
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
