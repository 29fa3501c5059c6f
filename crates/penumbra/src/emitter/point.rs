//! Mitsuba's `point` emitter: an isotropic point light.

use super::{eval_uniform, DirectionSample, EmitterT};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::{Shape, SurfaceInteraction};
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamStore};
use crate::scene::{LoadContext, Node};
use crate::texture::{Channels, Texture};
use glam::{Vec2, Vec3};

/// Radiant intensity `intensity` (W/sr, key `<key>.intensity.value`)
/// emitted equally in all directions from `position` (or the origin of
/// `to_world`; giving both is an error, as in Mitsuba).
#[derive(Clone, Debug)]
pub struct Point {
    pub intensity: Texture,
    pub position: Vec3,
}

impl Point {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Point> {
        let intensity = Texture::from_prop(
            node,
            "intensity",
            Some(1.0),
            Channels::Rgb,
            Domain::NonNegative,
            ctx,
        )?;
        let position = match (node.vec3_opt("position")?, node.has("to_world")) {
            (Some(_), true) => {
                return Err(
                    node.error("only one of the parameters 'position' and 'to_world' can be given")
                )
            }
            (Some(p), false) => p,
            (None, _) => node.transform("to_world")?.point(Vec3::ZERO),
        };
        Ok(Point {
            intensity,
            position,
        })
    }
}

impl EmitterT for Point {
    /// The light's position, with weight `I / dist²` (pdf 1, delta).
    fn sample_direction<R: Real>(
        &self,
        store: &ParamStore,
        _shapes: &[Shape],
        ref_p: Vec3,
        _u: Vec2,
    ) -> Option<(DirectionSample, Spectrum<R>)> {
        let to = self.position - ref_p;
        let dist2 = to.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let ds = DirectionSample {
            p: self.position,
            n: Vec3::ZERO,
            d: to / dist,
            dist,
            pdf: 1.0,
            delta: true,
        };
        let i = eval_uniform::<R>(&self.intensity, store);
        Some((ds, i.scale(1.0 / dist2)))
    }
    fn pdf_direction(
        &self,
        _: &ParamStore,
        _: &[Shape],
        _: Vec3,
        _: Vec3,
        _: Vec3,
        _: Vec3,
    ) -> f32 {
        0.0
    }
    fn eval_surface<R: Real>(&self, _: &ParamStore, _: &SurfaceInteraction<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn eval_environment<R: Real>(&self, _: &ParamStore, _: Vec3) -> Spectrum<R> {
        V3::zero()
    }
    fn is_delta(&self) -> bool {
        true
    }
    fn is_environment(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::emitter::test_util::node;
    use crate::emitter::Emitter;
    use crate::scene::Value;

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
        let (ds, w) = e
            .sample_direction::<f32>(&ctx.store, &[], ref_p, Vec2::splat(0.5))
            .unwrap();
        // Mitsuba: weight 0.5, d (0,0,-1), dist 2, pdf 1, delta
        assert_eq!(w.val(), Vec3::splat(0.5));
        assert_eq!(
            (ds.d, ds.dist, ds.pdf, ds.delta),
            (-Vec3::Z, 2.0, 1.0, true)
        );
        assert!(e.is_delta());
        ctx.store
            .set_tangent("lamp.intensity.value", &[1.0, 0.0, 0.0])
            .unwrap();
        let (_, w) = e
            .sample_direction::<Dual>(&ctx.store, &[], ref_p, Vec2::splat(0.5))
            .unwrap();
        assert_eq!((w.x.d, w.y.d), (0.25, 0.0));
    }

    #[test]
    fn to_world_places_the_light_and_conflicts_with_position() {
        let t = Transform::translate(Vec3::new(1.0, 2.0, 3.0));
        let n = node("point", "l", vec![("to_world", Value::Transform(t))]);
        let e = Point::from_node(&n, &mut LoadContext::default()).unwrap();
        assert_eq!(e.position, Vec3::new(1.0, 2.0, 3.0));
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
