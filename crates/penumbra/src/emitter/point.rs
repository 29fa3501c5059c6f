//! Mitsuba's `point` emitter: an isotropic point light.

use super::{
    delta_light_queries, emission_prop, eval_uniform, point_light_sample, vec3_or_to_world,
    EmitterSample, EmitterT,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Shape;
use crate::math::V3;
use crate::params::{Domain, ParamFlags, ParamId, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Radiant intensity `intensity` (W/sr, key `<key>.intensity.value`)
/// emitted equally in all directions from `position` (key
/// `<key>.position`, differentiable: moving the light moves its shadows;
/// given directly or as the origin of `to_world`; giving both is an
/// error, as in Mitsuba).
#[derive(Clone, Debug)]
pub struct Point {
    pub intensity: Texture,
    pub position: ParamId,
}

impl Point {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Point> {
        let intensity = emission_prop(node, "intensity", ctx)?;
        let p = vec3_or_to_world(node, "position", |t| t.point(Vec3::ZERO))?;
        let position = ctx.store.add(
            format!("{}.position", node.key),
            p.to_array().to_vec(),
            vec![3],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        Ok(Point {
            intensity,
            position,
        })
    }
}

impl EmitterT for Point {
    /// The light's position, with weight `I / dist²` (pdf 1, delta).
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        _u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let (ds, d, dist2) = point_light_sample(store.read3(self.position, 0), ref_p)?;
        let i = eval_uniform::<R>(&self.intensity, store);
        Some(EmitterSample {
            ds,
            d,
            weight: i * dist2.recip(),
        })
    }
    delta_light_queries!();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::emitter::test_util::node;
    use crate::emitter::Emitter;
    use crate::emitter::EmitterSample;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::Value;

    #[test]
    fn inverse_square_falloff_and_differentiable_intensity() {
        let mut ctx = LoadContext::default();
        let n = node(
            "point",
            "lamp",
            vec![
                ("intensity", Value::Float(2.0)),
                ("position", Value::Point(Vec3::new(0.0, 0.0, 1.0))),
            ],
        );
        let e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        let ref_p = Vec3::new(0.0, 0.0, 3.0);
        let EmitterSample { ds, weight: w, .. } = e
            .sample_direction::<f32>(&ctx.store.primal(), &[], V3::cst(ref_p), Vec2::splat(0.5))
            .unwrap();
        // Mitsuba: weight 0.5, d (0,0,-1), dist 2, pdf 1, delta
        assert_eq!(w.val(), Vec3::splat(0.5));
        assert_eq!(
            (ds.d, ds.dist, ds.pdf, ds.delta),
            (-Vec3::Z, 2.0, 1.0, true)
        );
        assert!(e.is_delta());
        let seeds =
            Seeds::tangents(&ctx.store, &[("lamp.intensity.value", &[1.0, 0.0, 0.0])]).unwrap();
        let EmitterSample { weight: w, .. } = e
            .sample_direction::<Dual>(
                &ctx.store.view(&seeds),
                &[],
                V3::cst(ref_p),
                Vec2::splat(0.5),
            )
            .unwrap();
        assert_eq!((w.x.d, w.y.d), (0.25, 0.0));
    }

    #[test]
    fn to_world_places_the_light_and_conflicts_with_position() {
        let t = Transform::translate(Vec3::new(1.0, 2.0, 3.0));
        let n = node("point", "l", vec![("to_world", Value::Transform(t))]);
        let mut ctx = LoadContext::default();
        let e = Point::from_node(&n, &mut ctx).unwrap();
        assert_eq!(ctx.store.data(e.position), &[1.0, 2.0, 3.0]);
        assert_eq!(ctx.store.id("l.position"), Some(e.position));
        let n = node(
            "point",
            "l",
            vec![
                ("to_world", Value::Transform(t)),
                ("position", Value::Point(Vec3::ZERO)),
            ],
        );
        let e = Emitter::from_node(&n, None, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.xml:1") && e.contains("only one of"), "{e}");
    }
    use crate::math::Transform;
}
