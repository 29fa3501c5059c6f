//! Derivative estimators: forward (tangent) mode, path-replay reverse mode,
//! and boundary terms (docs/architecture.md §4): both modes add the
//! boundary terms of primary visibility ([`primary_boundary`]) and of the
//! visibility seen from the first vertex, shadows ([`shadow_boundary`]). Forward mode gives a
//! derivative image for a tangent over the parameters; reverse mode gives
//! gradients for every differentiable parameter.

mod check;
mod delta_shadow_boundary;
mod forward;
mod prb;
mod prb_lanes;
mod primary_boundary;
mod shadow_boundary;
mod splat;

pub use check::{
    check_gradient, perturbation_tangent, translation_tangent, CheckOptions, CheckReport, Estimate,
};
pub use forward::render_forward;
pub use prb::{render_backward, GradEntry, Gradients};

use crate::emitter::EmitterT;
use crate::error::{Error, Result};
use crate::geometry::Shape;
use crate::integrator::{Integrator, RenderOptions};
use crate::scene::Scene;

/// The seed of a gradient pass (reverse or forward mode) that follows a
/// render with seed `seed`, unless the caller sets one: `seed` with its low
/// 32 bits flipped by the golden-ratio constant `0x9e3779b9`.
///
/// Replaying the image's own samples would make the gradient of a
/// non-linear loss (L2) biased by the covariance of the image noise and
/// the derivative noise (Mitsuba's `seed_grad` exists for this reason).
/// The rule maps distinct seeds to distinct seeds, and small seeds (the
/// iteration counters of optimisation loops) far away from each other,
/// so no image seed of a loop is reused as a gradient seed.
pub fn gradient_seed(seed: u64) -> u64 {
    seed ^ 0x9e37_79b9
}

/// The boundary terms a derivative pass estimates.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BoundaryTerms {
    /// Edges seen by the camera ([`primary_boundary`]).
    pub primary: bool,
    /// Edges seen from the first vertex: shadows ([`shadow_boundary`]).
    pub shadow: bool,
    /// Shadows of point, spot, projector and directional emitters
    /// ([`delta_shadow_boundary`]).
    pub delta_shadow: bool,
}

impl BoundaryTerms {
    /// The terms that apply to the render `opts` describes.
    pub(crate) fn of(scene: &Scene, opts: &RenderOptions) -> Result<BoundaryTerms> {
        Ok(BoundaryTerms {
            primary: primary_boundary::applies(scene, opts)?,
            shadow: shadow_boundary::applies(scene, opts)?,
            delta_shadow: delta_shadow_boundary::applies(scene, opts)?,
        })
    }
}

/// Warns (once per call, naming the keys) when derivatives are requested
/// for parameters that move visibility discontinuities (vertex positions,
/// transforms, the camera) and some boundary term those edges need is not
/// estimated, naming the missing terms: the result is biased wherever
/// such an edge moves. Not an error: the other terms are right; never
/// silent.
///
/// Besides a term the pass does not run at all, the estimators leave out:
/// the shadows cast by analytic shapes (spheres, disks, cylinders; the
/// silhouettes of spheres and disks seen by a pinhole or orthographic
/// camera are estimated), the outlines of cylinders seen by the camera
/// (named when a moving key is a cylinder's or moves no other shape: the
/// camera's), visibility seen from the second and later vertices of a
/// path, and every edge of the shapes of shape groups seen through their
/// instances (their silhouettes and the shadows they cast).
///
/// Returns whether any of the keys moves a visibility edge (then the
/// boundary terms apply).
pub(crate) fn warn_missing_boundary_terms(
    scene: &Scene,
    keys: &[&str],
    terms: BoundaryTerms,
) -> Result<bool> {
    let mut moving = Vec::new();
    for key in keys {
        let id = scene.params.require(key)?;
        if scene.params.get(id).flags.discontinuous {
            moving.push(*key);
        }
    }
    if moving.is_empty() {
        return Ok(false);
    }
    if let Integrator::VolPath(_) = scene.integrator {
        return Err(Error::Invalid(format!(
            "{} moves geometry or the camera: the volumetric path tracer differentiates \
             media, materials and emitters, not geometry (its boundary terms and moving \
             paths through media are not implemented); differentiate other parameters, or \
             use the path integrator for a scene without media",
            moving.join(", ")
        )));
    }
    let analytic = |s: &Shape| s.as_mesh().is_none();
    let mut missing = Vec::new();
    if !terms.primary {
        // thin lenses, or no primary budget; otherwise the term covers the
        // edges of meshes and the outlines of spheres and disks
        missing.push("primary visibility (silhouettes seen by the camera)");
    } else if cylinder_outlines_move(scene, &moving)? {
        missing.push("the outlines of cylinders");
    }
    let area_lights = scene.emitters.iter().any(|e| !e.is_delta());
    let delta_lights = scene.emitters.iter().any(|e| e.is_delta());
    if (area_lights && !terms.shadow) || (delta_lights && !terms.delta_shadow) {
        missing.push("shadows");
    } else if scene.shapes.iter().any(analytic) {
        missing.push("the shadows cast by spheres, disks and cylinders");
    }
    if scene.integrator.traces_indirect_light() {
        missing.push("indirect visibility (edges seen after a bounce)");
    }
    if !scene.instances.is_empty() {
        // the edge tables are per shape, in the group's space; instances
        // would need them transformed per instance
        missing.push(
            "the edges of instanced shapes (shapegroup/instance: their silhouettes and shadows)",
        );
    }
    if !missing.is_empty() {
        crate::warn(missing_boundary_terms_message(&moving, &missing));
    }
    Ok(true)
}

/// Whether the outline of a cylinder moves in the image for the moving
/// (discontinuous) `keys`: one is a cylinder's, or one moves no shape at
/// all (the camera) while the scene holds a cylinder. A key that moves
/// another shape leaves the cylinders' outlines in place.
fn cylinder_outlines_move(scene: &Scene, keys: &[&str]) -> Result<bool> {
    let mut cylinders = scene
        .shapes
        .iter()
        .filter(|s| matches!(s, Shape::Cylinder(_)))
        .peekable();
    if cylinders.peek().is_none() {
        return Ok(false);
    }
    let cylinder_ids: Vec<_> = cylinders.flat_map(|s| s.geometry_params()).collect();
    for key in keys {
        let id = scene.params.require(key)?;
        let moves_a_shape = scene
            .shapes
            .iter()
            .any(|s| s.geometry_params().contains(&id));
        if cylinder_ids.contains(&id) || !moves_a_shape {
            return Ok(true);
        }
    }
    Ok(false)
}

/// The warning of [`warn_missing_boundary_terms`]: `keys` move geometry or
/// the camera, and the boundary terms of `missing` are not estimated.
pub fn missing_boundary_terms_message(keys: &[&str], missing: &[&str]) -> String {
    format!(
        "{} move(s) geometry or the camera: the boundary terms of {} are missing (not \
         estimated), so derivatives are biased where such an edge moves",
        keys.join(", "),
        missing.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::RenderOptions;
    use std::path::Path;

    /// The derivative state lives in the call: derivative calls with
    /// different tangents and recorded parameters run at the same time on
    /// one shared scene and give what they give one after the other.
    #[test]
    fn derivative_calls_share_a_scene() {
        let cbox = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cbox.xml");
        let d = [("res".to_string(), "8".to_string())];
        let scene = Scene::load_file(&cbox, &d).unwrap();
        let opts = RenderOptions {
            spp: Some(2),
            ..Default::default()
        };
        let red = [("red.reflectance.value", &[1.0f32, 0.0, 0.0][..])];
        let green = [("green.reflectance.value", &[0.0f32, 1.0, 0.0][..])];
        let adjoint = vec![1.0f32; 8 * 8 * 3];
        let keys = ["red.reflectance.value"];
        let run_all = || {
            std::thread::scope(|s| {
                let a = s.spawn(|| render_forward(&scene, &red, &opts).unwrap().data);
                let b = s.spawn(|| render_forward(&scene, &green, &opts).unwrap().data);
                let c = s.spawn(|| {
                    render_backward(&scene, &adjoint, Some(&keys), &opts)
                        .unwrap()
                        .entries[0]
                        .data
                        .clone()
                });
                (a.join().unwrap(), b.join().unwrap(), c.join().unwrap())
            })
        };
        let (a, b, c) = run_all();
        assert_eq!(a, render_forward(&scene, &red, &opts).unwrap().data);
        assert_eq!(b, render_forward(&scene, &green, &opts).unwrap().data);
        assert_ne!(a, b, "different tangents give different images");
        let g = render_backward(&scene, &adjoint, Some(&keys), &opts).unwrap();
        assert_eq!(c, g.entries[0].data);
        // nothing stays behind: a primal render and an unseeded read see no
        // derivative state
        let id = scene.params.require("red.reflectance.value").unwrap();
        assert!(!scene.params.primal().has_tangent(id));
        assert!(!scene.params.primal().is_recorded(id));
    }

    #[test]
    fn gradient_seeds_differ_from_every_small_image_seed() {
        for seed in 0..100_000u64 {
            let g = gradient_seed(seed);
            assert_ne!(g, seed);
            assert!(
                g >= 100_000,
                "gradient seed {g} of {seed} is also a loop's image seed"
            );
            assert_eq!(gradient_seed(g), seed, "the rule is a bijection");
        }
    }
}
