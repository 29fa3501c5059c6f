//! `blendbsdf`: a linear blend of two BSDFs, `(1 − w) f0 + w f1`.

use super::{
    chosen_with, nested_bsdfs, reuse_uniform, smooth_sample, Bsdf, BsdfContextT, BsdfFlags,
    BsdfSample, BsdfT, NestedContext, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Blend of two nested BSDFs (keys `<key>.bsdf_0`, `<key>.bsdf_1`) by
/// `weight` (float or texture in [0, 1], required; 0 = first, 1 =
/// second). Sampling picks a component with probability (1 − w, w); smooth
/// samples get the blend's pdf and `eval / pdf` as weight (one-sample MIS
/// over the components), delta samples the component's weight.
#[derive(Clone, Debug)]
pub struct BlendBsdf {
    pub weight: Texture,
    pub bsdfs: [Box<Bsdf>; 2],
}

impl BlendBsdf {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<BlendBsdf> {
        let weight = Texture::from_prop(
            node,
            "weight",
            None,
            Channels::Mono,
            Domain::UnitInterval,
            ctx,
        )?;
        let nested = nested_bsdfs(node, &["bsdf_0", "bsdf_1"])?;
        if nested.len() != 2 {
            return Err(node.error(format!("expects two nested BSDFs, found {}", nested.len())));
        }
        let b0 = Bsdf::from_node(&nested[0], ctx)?;
        let b1 = Bsdf::from_node(&nested[1], ctx)?;
        Ok(BlendBsdf {
            weight,
            bsdfs: [Box::new(b0), Box::new(b1)],
        })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        for b in &mut self.bsdfs {
            b.parameters_changed(store);
        }
    }

    fn w<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        self.weight.eval_1(store, si).clamp(0.0, 1.0)
    }
}

impl BsdfT for BlendBsdf {
    fn flags(&self) -> BsdfFlags {
        self.bsdfs[0].flags().union(self.bsdfs[1].flags())
    }

    fn context_len(&self) -> usize {
        1 + self.bsdfs[0].context_len() + self.bsdfs[1].context_len()
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let weight = self.w(store, si);
        let n0 = self.bsdfs[0].write_context(store, si, &mut nodes[1..]);
        let n1 = self.bsdfs[1].write_context(store, si, &mut nodes[1 + n0..]);
        nodes[0] = Some(NodeContext::BlendBsdf(BlendBsdfContext {
            weight,
            second: 1 + n0,
        }));
        1 + n0 + n1
    }
}

/// [`BlendBsdf`] at a vertex: the weight, followed in the [`BsdfContext`]
/// by the contexts of the two nested BSDFs.
///
/// [`BsdfContext`]: super::BsdfContext
#[derive(Clone, Copy, Debug)]
pub struct BlendBsdfContext<R: ScalarReal> {
    weight: R,
    /// Where the second nested BSDF's context is, relative to this one's.
    second: usize,
}

impl<R: ScalarReal> BlendBsdfContext<R> {
    fn nested<'c, 'a>(&self, this: NestedContext<'c, 'a, R>) -> [NestedContext<'c, 'a, R>; 2] {
        [this.at(1), this.at(self.second)]
    }

    pub(crate) fn eval(&self, this: NestedContext<'_, '_, R>, wo: V3<R>) -> Spectrum<R> {
        let w = self.weight;
        let [b0, b1] = self.nested(this);
        b0.eval(wo) * (-w + 1.0) + b1.eval(wo) * w
    }

    pub(crate) fn pdf(&self, this: NestedContext<'_, '_, R>, wo: Vec3) -> f32 {
        let w = self.weight.val();
        let [b0, b1] = self.nested(this);
        let mut p = 0.0;
        if w < 1.0 {
            p += (1.0 - w) * b0.pdf(wo);
        }
        if w > 0.0 {
            p += w * b1.pdf(wo);
        }
        p
    }

    pub(crate) fn sample(
        &self,
        this: NestedContext<'_, '_, R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        let w_r = self.weight;
        let w = w_r.val();
        let (idx, start, prob, prob_r) = if u1 >= w {
            (0, w, 1.0 - w, -w_r + 1.0)
        } else {
            (1, 0.0, w, w_r)
        };
        if !(prob > 0.0) {
            return None;
        }
        let bs = self.nested(this)[idx].sample(reuse_uniform(u1, start, prob), u2)?;
        if bs.lobe.has(BsdfFlags::DELTA) {
            Some(chosen_with(bs, prob, prob_r))
        } else {
            smooth_sample(&this, bs.wo.val(), bs.eta, bs.lobe)
        }
    }

    pub(crate) fn albedo(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        let w = self.weight;
        let [b0, b1] = self.nested(this);
        b0.albedo() * (-w + 1.0) + b1.albedo() * w
    }

    pub(crate) fn null_transmission(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        let w = self.weight;
        let [b0, b1] = self.nested(this);
        b0.null_transmission() * (-w + 1.0) + b1.null_transmission() * w
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfContextT, BsdfFlags};
    use crate::ad::Dual;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::LoadContext;

    #[test]
    fn blend_values_sampling_and_derivative() {
        let n = node_with_key(
            "blendbsdf",
            "bl",
            &[
                ("weight", float(0.3)),
                ("a", nested("bl", "a", "diffuse", &[])),
                (
                    "b",
                    nested("bl", "b", "roughconductor", &[("alpha", float(0.3))]),
                ),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap();
        let store = ctx.store;
        for k in [
            "bl.weight.value",
            "bl.bsdf_0.reflectance.value",
            "bl.bsdf_1.alpha.value",
        ] {
            assert!(store.id(k).is_some(), "{k}");
        }
        let Bsdf::BlendBsdf(bb) = &b else { panic!() };
        let wi = dir(0.7, 0.0);
        let wo = dir(0.6, 3.0);
        let s = si::<f32>(wi);
        let want = bb.bsdfs[0]
            .context(&store.primal(), &s)
            .eval(V3::cst(wo))
            .val()
            * 0.7
            + bb.bsdfs[1]
                .context(&store.primal(), &s)
                .eval(V3::cst(wo))
                .val()
                * 0.3;
        assert!((eval_f32(&b, &store, wi, wo) - want).abs().max_element() < 1e-6);
        check_smooth(&b, &store, &[wi, dir(0.2, 1.0)], 1);
        let seeds = Seeds::tangents(&store, &[("bl.weight.value", &[1.0])]).unwrap();
        let store = store.view(&seeds);
        let d = b.context(&store, &si::<Dual>(wi)).eval(V3::cst(wo));
        let diff = bb.bsdfs[1].context(&store, &s).eval(V3::cst(wo)).val()
            - bb.bsdfs[0].context(&store, &s).eval(V3::cst(wo)).val();
        assert!((d.x.d - diff.x).abs() < 1e-5);

        // blend with a delta lobe: its samples carry the component weight
        let n = node_with_key(
            "blendbsdf",
            "b2",
            &[
                ("weight", float(0.5)),
                ("a", nested("b2", "a", "diffuse", &[])),
                ("b", nested("b2", "b", "conductor", &[])),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap();
        let bs = b
            .context(&ctx.store.primal(), &si::<f32>(wi))
            .sample(0.1, glam::Vec2::splat(0.5))
            .unwrap();
        assert_eq!(bs.lobe, BsdfFlags::DELTA_REFLECTION);
        assert!((bs.pdf - 0.5).abs() < 1e-6 && (bs.weight.x - 1.0).abs() < 1e-6);
        let (a, se) = albedo_estimate(&b, &ctx.store, wi, 20_000, 1);
        assert!((a.x - 0.75).abs() < 4.0 * se.x + 1e-4, "{a} ± {se}");
    }
}
