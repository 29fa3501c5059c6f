//! `mask`: opacity masks (leaves, fences): a blend of a nested BSDF and a
//! null pass-through.

use super::{chosen_with, nested_bsdfs, reuse_uniform, Bsdf, BsdfFlags, BsdfSample, BsdfT};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::{LoadContext, Node};
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

    fn o<R: Real>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
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

    fn eval<R: Real>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        wo: V3<R>,
    ) -> Spectrum<R> {
        self.nested.eval(store, si, wo) * self.o(store, si)
    }

    fn pdf<R: Real>(&self, store: &ParamView, si: &SurfaceInteraction<R>, wo: Vec3) -> f32 {
        self.o(store, si).val() * self.nested.pdf(store, si, wo)
    }

    fn sample<R: Real>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        let o_r = self.o(store, si);
        let o = o_r.val();
        if u1 >= o {
            let p = 1.0 - o;
            let weight = V3::splat((-o_r + 1.0) / p);
            return Some(BsdfSample::pass_through(si.wi, p, weight));
        }
        let bs = self
            .nested
            .sample(store, si, reuse_uniform(u1, 0.0, o), u2)?;
        Some(chosen_with(bs, o, o_r))
    }

    fn albedo<R: Real>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        self.nested.albedo(store, si) * self.o(store, si)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfFlags, BsdfT};
    use crate::scene::LoadContext;

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
            .sample(&store.primal(), &si::<f32>(wi), 0.9, glam::Vec2::splat(0.5))
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
