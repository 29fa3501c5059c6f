//! `twosided`: makes one-sided (reflection-only) BSDFs reflect on both
//! sides of the surface.

use super::{nested_bsdfs, Bsdf, BsdfFlags, BsdfSample, BsdfT};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{ParamStore, ParamView};
use crate::scene::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Two-sided wrapper: one nested BSDF used on both sides, or two (front,
/// back). Seen from the back (`wi.z < 0`), directions are mirrored
/// through the surface (z negated) before the nested BSDF is called. As
/// in Mitsuba, the nested parameters are keyed `<key>.brdf_0` and
/// `<key>.brdf_1`, and nested BSDFs must not transmit.
#[derive(Clone, Debug)]
pub struct TwoSided {
    pub front: Box<Bsdf>,
    pub back: Box<Bsdf>,
}

fn flip<R: Real>(si: &SurfaceInteraction<R>) -> SurfaceInteraction<R> {
    let mut s = *si;
    s.wi = V3::new(si.wi.x, si.wi.y, -si.wi.z);
    s
}

fn flip_v<R: Real>(v: V3<R>) -> V3<R> {
    V3::new(v.x, v.y, -v.z)
}

impl TwoSided {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<TwoSided> {
        let nested = nested_bsdfs(node, &["brdf_0", "brdf_1"])?;
        let mut built = Vec::new();
        for n in &nested {
            let b = Bsdf::from_node(n, ctx)?;
            if b.flags().has(BsdfFlags::TRANSMISSION) {
                return Err(node.error(format!(
                    "the nested '{}' transmits light; only reflecting BSDFs can be nested in a twosided BSDF",
                    n.plugin
                )));
            }
            built.push(b);
        }
        let front = Box::new(built[0].clone());
        let back = Box::new(built.pop().expect("at least one nested BSDF"));
        Ok(TwoSided { front, back })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.front.parameters_changed(store);
        self.back.parameters_changed(store);
    }
}

impl BsdfT for TwoSided {
    fn flags(&self) -> BsdfFlags {
        self.front
            .flags()
            .union(self.back.flags())
            .union(BsdfFlags::TWO_SIDED)
    }

    fn eval<R: Real>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        wo: V3<R>,
    ) -> Spectrum<R> {
        let z = si.wi.z.val();
        if z > 0.0 {
            self.front.eval(store, si, wo)
        } else if z < 0.0 {
            self.back.eval(store, &flip(si), flip_v(wo))
        } else {
            V3::zero()
        }
    }

    fn pdf<R: Real>(&self, store: &ParamView, si: &SurfaceInteraction<R>, wo: Vec3) -> f32 {
        let z = si.wi.z.val();
        if z > 0.0 {
            self.front.pdf(store, si, wo)
        } else if z < 0.0 {
            self.back.pdf(store, &flip(si), flip_v(V3::from(wo)).val())
        } else {
            0.0
        }
    }

    fn sample<R: Real>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        let z = si.wi.z.val();
        if z > 0.0 {
            self.front.sample(store, si, u1, u2)
        } else if z < 0.0 {
            let mut bs = self.back.sample(store, &flip(si), u1, u2)?;
            bs.wo = flip_v(bs.wo);
            Some(bs)
        } else {
            None
        }
    }

    fn albedo<R: Real>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        if si.wi.z.val() >= 0.0 {
            self.front.albedo(store, si)
        } else {
            self.back.albedo(store, &flip(si))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfT};
    use crate::scene::LoadContext;

    #[test]
    fn both_sides_and_keys() {
        let n = node_with_key(
            "twosided",
            "mat",
            &[(
                "bsdf",
                nested(
                    "mat",
                    "bsdf",
                    "diffuse",
                    &[("reflectance", rgb(0.2, 0.4, 0.6))],
                ),
            )],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap();
        let store = ctx.store;
        assert!(store.id("mat.brdf_0.reflectance.value").is_some());
        let wi = dir(0.6, 0.5);
        let wo = dir(0.3, 2.0);
        let f = eval_f32(&b, &store, wi, wo);
        let wi_b = glam::Vec3::new(wi.x, wi.y, -wi.z);
        let wo_b = glam::Vec3::new(wo.x, wo.y, -wo.z);
        assert_eq!(f, eval_f32(&b, &store, wi_b, wo_b));
        assert!(f.x > 0.0 && eval_f32(&b, &store, wi_b, wo) == glam::Vec3::ZERO);
        check_smooth(&b, &store, &[wi, wi_b, dir(-0.1, 4.0)], 1);

        // two different sides; the back is a mirror
        let n = node_with_key(
            "twosided",
            "m2",
            &[
                ("bsdf_0", nested("m2", "bsdf_0", "diffuse", &[])),
                ("bsdf_1", nested("m2", "bsdf_1", "conductor", &[])),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap();
        assert!(ctx
            .store
            .id("m2.brdf_1.specular_reflectance.value")
            .is_some());
        let bs = b
            .sample(
                &ctx.store.primal(),
                &si::<f32>(wi_b),
                0.3,
                glam::Vec2::splat(0.3),
            )
            .unwrap();
        assert!(
            (bs.wo.val() - glam::Vec3::new(-wi.x, -wi.y, -wi.z)).length() < 1e-6,
            "{bs:?}"
        );

        let n = node_with_key(
            "twosided",
            "m3",
            &[("bsdf", nested("m3", "bsdf", "dielectric", &[]))],
        );
        let e = Bsdf::from_node(&n, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("transmits"), "{e}");
    }
}
