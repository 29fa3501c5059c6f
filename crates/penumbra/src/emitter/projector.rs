//! Mitsuba's `projector` emitter: a delta-position light that projects its
//! `irradiance` texture into the scene through a pinhole, the reciprocal
//! of the `perspective` camera (same field-of-view parameters, same map
//! from directions to the image).

use super::{delta_light_queries, emission_prop, point_light_sample, surface_si};
use super::{EmitterSample, EmitterT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Shape;
use crate::math::{Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Texture, TextureT};
use glam::{Vec2, Vec3};

/// The texture `irradiance` (default 1; keys `<key>.irradiance.…`) times
/// `scale` (default 1, key `<key>.scale`, differentiable as in Mitsuba
/// 3.9), projected from the origin of `to_world` along its local +z axis
/// over the horizontal field of view `fov` (or `fov_axis`,
/// `focal_length`, as for sensors) of an image with the texture's aspect
/// ratio. A point at local position (x, y, z) sees the texel at
/// uv = (½ − ½·x/(z·t), ½ − ½·a·y/(z·t)), t = tan(x_fov/2), a the aspect
/// ratio, and receives `π · scale · irradiance(uv) / (z² cos θ)` with θ
/// the angle between the projector's axis and the direction to the point
/// (Mitsuba's projector.cpp: the irradiance is that of the plane z = 1
/// lit head-on; dist² cos³θ = z² cos θ).
#[derive(Clone, Debug)]
pub struct Projector {
    pub irradiance: Texture,
    pub scale: ParamId,
    pub to_world: Transform,
    /// tan(x_fov / 2).
    tan_half_fov: f32,
    /// Width over height of the irradiance texture (1 for a constant).
    aspect: f32,
}

impl Projector {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Projector> {
        let irradiance = emission_prop(node, "irradiance", ctx)?;
        let (width, height) = match &irradiance {
            Texture::Bitmap(b) => (b.width, b.height),
            _ => (1, 1),
        };
        let aspect = width as f32 / height as f32;
        let x_fov = crate::sensor::fov_x(node, aspect)?;
        let scale = node.float("scale", 1.0)?;
        let scale = ctx
            .store
            .add(
                format!("{}.scale", node.key),
                vec![scale],
                vec![1],
                ParamFlags::DIFFERENTIABLE,
                Domain::Finite,
            )
            .map_err(|e| node.error(e))?;
        Ok(Projector {
            irradiance,
            scale,
            to_world: node.transform("to_world")?,
            tan_half_fov: (x_fov.to_radians() * 0.5).tan(),
            aspect,
        })
    }

    /// The texture's uv for a point at `local` in the projector's frame
    /// (z > 0), as the perspective camera maps it onto its film.
    pub fn local_to_uv<R: ScalarReal>(&self, local: V3<R>) -> V2<R> {
        let k = local.z * self.tan_half_fov;
        V2::new(
            R::cst(0.5) - R::cst(0.5) * local.x / k,
            R::cst(0.5) - R::cst(0.5 * self.aspect) * local.y / k,
        )
    }
}

impl EmitterT for Projector {
    /// The projector's position, with weight `π · scale · E(uv) / (z² cos θ)`
    /// (pdf 1, delta); `None` outside the projected image.
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        _u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let local = self.to_world.inverse().point_r(ref_p);
        if !(local.z.val() > 0.0) {
            return None;
        }
        let uv = self.local_to_uv(local);
        let inside = |c: f32| (0.0..=1.0).contains(&c);
        if !(inside(uv.x.val()) && inside(uv.y.val())) {
            return None;
        }
        let pos = self.to_world.point(Vec3::ZERO);
        let (ds, d, _) = point_light_sample(V3::cst(pos), ref_p)?;
        // the axis as Mitsuba takes it: to_world applied to +z, unnormalised
        let axis = V3::cst(self.to_world.vector(Vec3::Z));
        let cos_theta = -axis.dot(d);
        let mut si = surface_si::<R>(Vec3::ZERO, Vec3::Z, Vec2::ZERO, Vec3::Z, 0, 0);
        si.uv = uv;
        let e = self.irradiance.eval(store, &si);
        let scale: R = store.read(self.scale, 0);
        let k = R::cst(std::f32::consts::PI) * scale / (local.z * local.z * cos_theta);
        Some(EmitterSample {
            ds,
            d,
            weight: e * k,
        })
    }
    delta_light_queries!();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emitter::test_util::node;
    use crate::emitter::Emitter;
    use crate::scene::description::Value;
    use std::f32::consts::TAU;

    /// Mitsuba 3.9.1's `sample_direction` weights (scalar_rgb) of a
    /// projector at the origin looking down +z, irradiance (1, 2, 3),
    /// scale 2, fov 40 (on the axis at distance 1: 2π·(1, 2, 3), which
    /// Mitsuba prints as 6.28319, 12.5664, 18.8496); `None` where
    /// Mitsuba's weight is 0 (outside the image, behind the projector).
    #[test]
    fn weights_match_mitsuba() {
        let mut ctx = LoadContext::default();
        let n = node(
            "projector",
            "p",
            vec![
                ("irradiance", Value::Rgb(Vec3::new(1.0, 2.0, 3.0))),
                ("scale", Value::Float(2.0)),
                ("fov", Value::Float(40.0)),
            ],
        );
        let e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        for (p, want) in [
            ([0.0, 0.0, 1.0], Some([TAU, 2.0 * TAU, 3.0 * TAU])),
            ([0.2, 0.1, 2.0], Some([1.58058, 3.16117, 4.74175])),
            ([-0.3, 0.2, 3.0], Some([0.703156, 1.40631, 2.10947])),
            ([0.5, 0.0, 1.0], None),
            ([0.0, 0.0, -1.0], None),
        ] {
            let p = Vec3::from(p);
            let r = e.sample_direction::<f32>(&ctx.store.primal(), &[], V3::cst(p), Vec2::ZERO);
            match (r, want) {
                (Some(s), Some(want)) => {
                    let w = s.weight.val();
                    assert!(
                        (w - Vec3::from(want)).abs().max_element() < 2e-5 * w.max_element(),
                        "{p}: {w}"
                    );
                    assert!(
                        s.ds.delta && s.ds.pdf == 1.0 && (s.ds.d + p.normalize()).length() < 1e-5
                    );
                }
                (None, None) => {}
                (r, w) => panic!("{p}: got {r:?}, want {w:?}"),
            }
        }
        assert!(ctx.store.id("p.scale").is_some() && ctx.store.id("p.irradiance.value").is_some());
    }

    /// uv as Mitsuba 3.9.1 reports it (`ds.uv`) for fov 30 along y on a
    /// square image.
    #[test]
    fn uv_matches_mitsuba() {
        let n = node(
            "projector",
            "p",
            vec![
                ("fov", Value::Float(30.0)),
                ("fov_axis", Value::Str("y".into())),
            ],
        );
        let p = Projector::from_node(&n, &mut LoadContext::default()).unwrap();
        for (local, want) in [
            ([0.2f32, 0.1, 2.0], [0.313397f32, 0.406699]),
            ([-0.3, 0.2, 3.0], [0.686603, 0.375598]),
            ([0.5, 0.0, 1.0], [-0.433013, 0.5]),
        ] {
            let uv = p.local_to_uv::<f32>(V3::cst(Vec3::from(local)));
            assert!(
                (uv.x - want[0]).abs() < 1e-5 && (uv.y - want[1]).abs() < 1e-5,
                "{local:?}: {uv:?}"
            );
        }
    }
}
