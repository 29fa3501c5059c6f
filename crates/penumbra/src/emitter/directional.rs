//! Mitsuba's `directional` emitter: parallel light from infinitely far
//! away.

use super::{delta_light_queries, emission_prop, eval_uniform, far_point, vec3_or_to_world};
use super::{BoundingSphere, DirectionSample, EmitterSample, EmitterT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Shape;
use crate::math::V3;
use crate::params::ParamView;
use crate::scene::description::{LoadContext, Node};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Irradiance `irradiance` (W/m² on a surface facing the light, key
/// `<key>.irradiance.value`) travelling along `direction` (or local +z of
/// `to_world`).
#[derive(Clone, Debug)]
pub struct Directional {
    pub irradiance: Texture,
    /// Unit direction the light travels in (world space).
    pub direction: Vec3,
    /// The scene's bounding sphere (see `Emitter::set_scene_bounds`).
    pub bounds: BoundingSphere,
}

impl Directional {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Directional> {
        let irradiance = emission_prop(node, "irradiance", ctx)?;
        let dir = vec3_or_to_world(node, "direction", |t| t.vector(Vec3::Z))?;
        let direction = dir.normalize();
        if !direction.is_finite() {
            return Err(node.error("the light direction must be a non-zero vector"));
        }
        Ok(Directional {
            irradiance,
            direction,
            bounds: BoundingSphere::default(),
        })
    }
}

impl EmitterT for Directional {
    /// The direction towards the light (`−direction`), weight `E` (pdf 1,
    /// delta, infinite distance; `p` is outside the scene bounds).
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        _u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let d = -self.direction;
        let ds = DirectionSample {
            p: far_point(&self.bounds, ref_p.val(), d),
            n: self.direction,
            d,
            dist: f32::INFINITY,
            pdf: 1.0,
            delta: true,
        };
        Some(EmitterSample::fixed_direction(
            ds,
            eval_uniform::<R>(&self.irradiance, store),
        ))
    }
    delta_light_queries!();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emitter::test_util::node;
    use crate::emitter::Emitter;
    use crate::emitter::EmitterSample;
    use crate::math::V3;
    use crate::scene::description::Value;

    #[test]
    fn light_comes_from_minus_direction() {
        let mut ctx = LoadContext::default();
        let n = node(
            "directional",
            "sun",
            vec![
                ("irradiance", Value::Float(2.0)),
                ("direction", Value::Vector(Vec3::new(0.0, 0.0, -3.0))),
            ],
        );
        let mut e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        e.set_scene_bounds(Vec3::ZERO, 3.0 * 3f32.sqrt());
        let EmitterSample { ds, weight: w, .. } = e
            .sample_direction::<f32>(&ctx.store.primal(), &[], V3::cst(Vec3::ZERO), Vec2::ZERO)
            .unwrap();
        assert_eq!(w.val(), Vec3::splat(2.0));
        assert_eq!(
            (ds.d, ds.n, ds.pdf, ds.delta),
            (Vec3::Z, -Vec3::Z, 1.0, true)
        );
        assert!(ds.dist.is_infinite());
        // outside the scene's bounding sphere (Mitsuba: p = (0, 0, 10.39))
        assert!((ds.p - Vec3::new(0.0, 0.0, 10.392)).length() < 1e-2);
        assert!(ctx.store.id("sun.irradiance.value").is_some());
    }
}
