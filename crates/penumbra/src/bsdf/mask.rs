//! `mask`: opacity masks (leaves, fences): a blend of a nested BSDF and a
//! null pass-through.

use super::{
    chosen_with, nested_bsdfs, reuse_uniform, Bsdf, BsdfContextT, BsdfFlags, BsdfSample, BsdfT,
    NestedContext, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Opacity mask: `opacity` (float or texture in [0, 1], default 0.5) of
/// the nested BSDF (key `<key>.nested_bsdf`), the rest passes through as
/// a `NULL` lobe (wo = −wi).
#[derive(Clone, Debug)]
pub struct Mask {
    pub opacity: Texture,
    pub nested: Box<Bsdf>,
}

impl Mask {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Mask> {
        let opacity = Texture::from_prop(
            node,
            "opacity",
            Some(0.5),
            Channels::Mono,
            Domain::UnitInterval,
            ctx,
        )?;
        let nested = nested_bsdfs(node, &["nested_bsdf"])?;
        let nested = Box::new(Bsdf::from_node(&nested[0], ctx)?);
        Ok(Mask { opacity, nested })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.nested.parameters_changed(store);
    }

    fn o<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        self.opacity.eval_1(store, si).clamp(0.0, 1.0)
    }
}

impl BsdfT for Mask {
    fn flags(&self) -> BsdfFlags {
        self.nested
            .flags()
            .union(BsdfFlags::NULL)
            .union(BsdfFlags::TWO_SIDED)
    }

    fn context_len(&self) -> usize {
        1 + self.nested.context_len()
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Mask(MaskContext {
            wi: si.wi,
            opacity: self.o(store, si),
        }));
        1 + self.nested.write_context(store, si, &mut nodes[1..])
    }
}

/// [`Mask`] at a vertex: the opacity, followed in the [`BsdfContext`] by
/// the nested BSDF's context.
///
/// [`BsdfContext`]: super::BsdfContext
#[derive(Clone, Copy, Debug)]
pub struct MaskContext<R: ScalarReal> {
    wi: V3<R>,
    opacity: R,
}

impl<R: ScalarReal> MaskContext<R> {
    pub(crate) fn eval(&self, this: NestedContext<'_, '_, R>, wo: V3<R>) -> Spectrum<R> {
        this.at(1).eval(wo) * self.opacity
    }

    pub(crate) fn pdf(&self, this: NestedContext<'_, '_, R>, wo: Vec3) -> f32 {
        self.opacity.val() * this.at(1).pdf(wo)
    }

    pub(crate) fn sample(
        &self,
        this: NestedContext<'_, '_, R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        let o_r = self.opacity;
        let o = o_r.val();
        if u1 >= o {
            let p = 1.0 - o;
            let weight = V3::splat((-o_r + 1.0) / p);
            return Some(BsdfSample::pass_through(self.wi, p, weight));
        }
        let bs = this.at(1).sample(reuse_uniform(u1, 0.0, o), u2)?;
        Some(chosen_with(bs, o, o_r))
    }

    pub(crate) fn albedo(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        this.at(1).albedo() * self.opacity
    }

    pub(crate) fn null_transmission(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        V3::splat(-self.opacity + 1.0) + this.at(1).null_transmission() * self.opacity
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfContextT, BsdfFlags};
    use crate::scene::description::LoadContext;

    #[test]
    fn opacity_splits_samples() {
        let n = node_with_key(
            "mask",
            "leaf",
            &[
                ("opacity", float(0.25)),
                ("bsdf", nested("leaf", "bsdf", "diffuse", &[])),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap();
        let store = ctx.store;
        assert!(
            store.id("leaf.opacity.value").is_some()
                && store.id("leaf.nested_bsdf.reflectance.value").is_some()
        );
        let wi = dir(0.6, 1.0);
        let bs = b
            .context(&store.primal(), &si::<f32>(wi))
            .sample(0.9, glam::Vec2::splat(0.5))
            .unwrap();
        assert_eq!(bs.lobe, BsdfFlags::NULL);
        assert!(
            (bs.wo.val() + wi).length() < 1e-6
                && (bs.pdf - 0.75).abs() < 1e-6
                && (bs.weight.x - 1.0).abs() < 1e-6
        );
        check_smooth(&b, &store, &[wi], 1);
        // pass-through + 0.25 × diffuse albedo 0.5
        let (a, se) = albedo_estimate(&b, &store, wi, 20_000, 8);
        assert!(
            (a.x - (0.75 + 0.125)).abs() < 4.0 * se.x + 1e-4,
            "{a} ± {se}"
        );
    }
}
