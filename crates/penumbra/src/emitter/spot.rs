//! Mitsuba's `spot` emitter: a point light restricted to a cone, with a
//! linear falloff between the beam width and the cutoff angle, optionally
//! modulated by a texture projected through the cone.

use super::{delta_light_queries, emission_prop, eval_uniform, point_light_sample, surface_si};
use super::{EmitterSample, EmitterT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Shape;
use crate::math::{Transform, V2, V3};
use crate::params::{Domain, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Intensity `intensity` (key `<key>.intensity.value`) emitted from the
/// origin of `to_world` around its local +z axis: full within
/// `beam_width` (degrees, default ¾ of the cutoff), falling linearly in
/// angle to zero at `cutoff_angle` (degrees, default 20), as Mitsuba 3's
/// `spot`. An optional `texture` (spatially varying, keys
/// `<key>.texture.…`) multiplies the intensity: it is projected through
/// the cone, the edge of the cutoff cone touching the edges of its unit
/// uv square.
#[derive(Clone, Debug)]
pub struct Spot {
    pub intensity: Texture,
    pub texture: Option<Texture>,
    pub to_world: Transform,
    /// Cutoff angle in radians.
    pub cutoff: f32,
    /// Beam width in radians.
    pub beam_width: f32,
}

impl Spot {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Spot> {
        let intensity = emission_prop(node, "intensity", ctx)?;
        let cutoff_deg = node.float_checked("cutoff_angle", 20.0, true)?;
        if cutoff_deg > 180.0 {
            let p = node.prop("cutoff_angle").expect("non-default value");
            return Err(node.prop_error(
                p,
                format!("must be at most 180 degrees, found {cutoff_deg}"),
            ));
        }
        let beam_deg = node.float_checked("beam_width", cutoff_deg * 0.75, false)?;
        let texture = match node.prop("texture") {
            None => None,
            Some(p) => match Texture::from_prop(node, "texture", None, Channels::Rgb, Domain::NonNegative, ctx)? {
                // as Mitsuba, which refuses a constant there
                Texture::Uniform(_) => {
                    return Err(node.prop_error(p, "must be a spatially varying texture (e.g. a bitmap); give a constant as 'intensity'"))
                }
                t => Some(t),
            },
        };
        Ok(Spot {
            intensity,
            texture,
            to_world: node.transform("to_world")?,
            cutoff: cutoff_deg.to_radians(),
            beam_width: beam_deg.to_radians(),
        })
    }

    /// The angular falloff for an emitted direction `local` (unit, in the
    /// light's frame): 1 inside the beam, `(cutoff − θ) / (cutoff − beam)`
    /// in the transition, 0 outside the cutoff.
    pub fn falloff<R: ScalarReal>(&self, local: V3<R>) -> R {
        let cos_theta = local.z;
        if !(cos_theta.val() > self.cutoff.cos()) {
            return R::cst(0.0);
        }
        if cos_theta.val() >= self.beam_width.cos() {
            return R::cst(1.0);
        }
        ((R::cst(self.cutoff) - cos_theta.clamp(-1.0, 1.0).acos())
            / (self.cutoff - self.beam_width))
            .clamp(0.0, 1.0)
    }

    /// The texture's uv for an emitted direction `local` (in the light's
    /// frame, z > 0): the direction's slopes x/z, y/z over tan(cutoff),
    /// mapped from [−1, 1] to [0, 1], as Mitsuba's `spot` maps them.
    pub fn direction_to_uv<R: ScalarReal>(&self, local: V3<R>) -> V2<R> {
        let k = local.z * self.cutoff.tan();
        V2::new(
            R::cst(0.5) + R::cst(0.5) * local.x / k,
            R::cst(0.5) + R::cst(0.5) * local.y / k,
        )
    }
}

impl EmitterT for Spot {
    /// The light's position, with weight `I · falloff / dist²` (pdf 1,
    /// delta); `None` outside the cone.
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        _u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let pos = self.to_world.point(Vec3::ZERO);
        let (ds, d, dist2) = point_light_sample(V3::cst(pos), ref_p)?;
        // the direction from the light to ref_p in the light's frame
        let inv = self.to_world.inverse().m;
        let row = |i: usize| V3::cst(inv.row(i).truncate());
        let local = V3::new(-row(0).dot(d), -row(1).dot(d), -row(2).dot(d)).normalize();
        let f = self.falloff(local);
        if !(f.val() > 0.0) {
            return None;
        }
        let mut i = eval_uniform::<R>(&self.intensity, store);
        if let Some(texture) = &self.texture {
            let mut si = surface_si::<R>(Vec3::ZERO, Vec3::Z, Vec2::ZERO, Vec3::Z, 0, 0);
            si.uv = self.direction_to_uv(local);
            i = i.mul_elem(texture.eval(store, &si));
        }
        Some(EmitterSample {
            ds,
            d,
            weight: i * (f / dist2),
        })
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

    /// Mitsuba 3.9.1's weights for a unit-intensity spot (cutoff 20°,
    /// beam 10°) seen from distance 2 at these angles off its axis.
    #[test]
    fn falloff_matches_mitsuba() {
        let mut ctx = LoadContext::default();
        let n = node(
            "spot",
            "s",
            vec![
                ("cutoff_angle", Value::Float(20.0)),
                ("beam_width", Value::Float(10.0)),
            ],
        );
        let e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        for (deg, want) in [
            (0.0f32, Some(0.25)),
            (5.0, Some(0.25)),
            (9.9, Some(0.25)),
            (12.0, Some(0.2)),
            (15.0, Some(0.125)),
            (19.0, Some(0.025)),
            (21.0, None),
            (120.0, None),
        ] {
            let a = deg.to_radians();
            let p = Vec3::new(2.0 * a.sin(), 0.0, 2.0 * a.cos());
            let r = e.sample_direction::<f32>(&ctx.store.primal(), &[], V3::cst(p), Vec2::ZERO);
            match (r, want) {
                (Some(EmitterSample { ds, weight: w, .. }), Some(want)) => {
                    assert!(
                        (w.val() - Vec3::splat(want)).abs().max_element() < 1e-5,
                        "{deg}: {w:?}"
                    );
                    assert!(ds.delta && ds.pdf == 1.0 && (ds.dist - 2.0).abs() < 1e-5);
                    assert!((ds.d + p.normalize()).length() < 1e-5);
                }
                (None, None) => {}
                (r, w) => panic!("{deg}°: got {r:?}, want {w:?}"),
            }
        }
    }

    /// Mitsuba's `direction_to_uv`: the cutoff cone meets the edges of
    /// the unit uv square; a constant `texture` is refused, as Mitsuba
    /// refuses it.
    #[test]
    fn texture_uv_and_constant_texture_refused() {
        let n = node("spot", "s", vec![("cutoff_angle", Value::Float(30.0))]);
        let s = Spot::from_node(&n, &mut LoadContext::default()).unwrap();
        let (c, t) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
        for (local, want) in [
            (Vec3::Z, [0.5, 0.5]),
            (Vec3::new(t, 0.0, c), [1.0, 0.5]),
            (Vec3::new(0.0, -t, c), [0.5, 0.0]),
            (
                Vec3::new(-0.1, 0.2, 1.0).normalize(),
                [
                    0.5 - 0.05 / 30f32.to_radians().tan(),
                    0.5 + 0.1 / 30f32.to_radians().tan(),
                ],
            ),
        ] {
            let uv = s.direction_to_uv::<f32>(V3::cst(local));
            assert!(
                (uv.x - want[0]).abs() < 1e-5 && (uv.y - want[1]).abs() < 1e-5,
                "{local}: {uv:?}"
            );
        }
        let n = node("spot", "s", vec![("texture", Value::Rgb(Vec3::ONE))]);
        let e = Spot::from_node(&n, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'texture'") && e.contains("spatially varying"),
            "{e}"
        );
    }

    #[test]
    fn default_beam_width_and_to_world() {
        // cutoff 40° → beam 30°; light at (0,0,5) pointing down −z
        let t =
            crate::math::Transform::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y).unwrap();
        let n = node(
            "spot",
            "s",
            vec![
                ("cutoff_angle", Value::Float(40.0)),
                ("to_world", Value::Transform(t)),
            ],
        );
        let s = Spot::from_node(&n, &mut LoadContext::default()).unwrap();
        assert!((s.beam_width.to_degrees() - 30.0).abs() < 1e-4);
        assert_eq!(s.falloff::<f32>(V3::cst(Vec3::Z)), 1.0);
        let d = |deg: f32| Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
        assert!((s.falloff::<f32>(V3::cst(d(35.0))) - 0.5).abs() < 1e-5);
        let mut ctx = LoadContext::default();
        let e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        assert!(e
            .sample_direction::<f32>(
                &ctx.store.primal(),
                &[],
                V3::cst(Vec3::new(0.0, 0.0, 0.0)),
                Vec2::ZERO
            )
            .is_some());
        assert!(e
            .sample_direction::<f32>(
                &ctx.store.primal(),
                &[],
                V3::cst(Vec3::new(0.0, 0.0, 10.0)),
                Vec2::ZERO
            )
            .is_none());
    }
}
