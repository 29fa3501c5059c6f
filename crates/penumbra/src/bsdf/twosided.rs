//! `twosided`: makes one-sided (reflection-only) BSDFs reflect on both
//! sides of the surface.

use super::{
    nested_bsdfs, Bsdf, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NestedContext, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
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

fn flip<R: ScalarReal>(si: &SurfaceInteraction<R>) -> SurfaceInteraction<R> {
    let mut s = *si;
    s.wi = V3::new(si.wi.x, si.wi.y, -si.wi.z);
    s
}

fn flip_v<R: ScalarReal>(v: V3<R>) -> V3<R> {
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

    fn context_len(&self) -> usize {
        1 + self.front.context_len().max(self.back.context_len())
    }

    /// Only the side `si.wi` is on gets a context (the front's when `wi`
    /// is in the surface, for the albedo).
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let z = si.wi.z.val();
        let side = if z > 0.0 {
            Side::Front
        } else if z < 0.0 {
            Side::Back
        } else {
            Side::Edge
        };
        nodes[0] = Some(NodeContext::TwoSided(TwoSidedContext { side }));
        1 + match side {
            Side::Back => self.back.write_context(store, &flip(si), &mut nodes[1..]),
            _ => self.front.write_context(store, si, &mut nodes[1..]),
        }
    }
}

/// Where the incident direction is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Front,
    /// Below the surface: directions are mirrored for the back BSDF.
    Back,
    /// In the surface: nothing scatters.
    Edge,
}

/// [`TwoSided`] at a vertex: the side, followed in the [`BsdfContext`]
/// by the context of that side's BSDF.
///
/// [`BsdfContext`]: super::BsdfContext
#[derive(Clone, Copy, Debug)]
pub struct TwoSidedContext {
    side: Side,
}

impl TwoSidedContext {
    pub(crate) fn eval<R: ScalarReal>(
        &self,
        this: NestedContext<'_, '_, R>,
        wo: V3<R>,
    ) -> Spectrum<R> {
        match self.side {
            Side::Front => this.at(1).eval(wo),
            Side::Back => this.at(1).eval(flip_v(wo)),
            Side::Edge => V3::zero(),
        }
    }

    pub(crate) fn pdf<R: ScalarReal>(&self, this: NestedContext<'_, '_, R>, wo: Vec3) -> f32 {
        match self.side {
            Side::Front => this.at(1).pdf(wo),
            Side::Back => this.at(1).pdf(flip_v(V3::from(wo)).val()),
            Side::Edge => 0.0,
        }
    }

    pub(crate) fn sample<R: ScalarReal>(
        &self,
        this: NestedContext<'_, '_, R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        match self.side {
            Side::Front => this.at(1).sample(u1, u2),
            Side::Back => {
                let mut bs = this.at(1).sample(u1, u2)?;
                bs.wo = flip_v(bs.wo);
                Some(bs)
            }
            Side::Edge => None,
        }
    }

    pub(crate) fn albedo<R: ScalarReal>(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        this.at(1).albedo()
    }

    pub(crate) fn null_transmission<R: ScalarReal>(
        &self,
        this: NestedContext<'_, '_, R>,
    ) -> Spectrum<R> {
        match self.side {
            Side::Front | Side::Back => this.at(1).null_transmission(),
            Side::Edge => V3::zero(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfContextT};
    use crate::scene::description::LoadContext;

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
            .context(&ctx.store.primal(), &si::<f32>(wi_b))
            .sample(0.3, glam::Vec2::splat(0.3))
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
