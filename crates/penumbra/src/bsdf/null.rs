//! `null`: an index-matched, invisible surface (medium boundaries,
//! cut-outs): light passes straight through.

use super::{BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::ParamView;
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Null BSDF: a `NULL` lobe with `wo = −wi` and weight 1; no parameters.
#[derive(Clone, Debug, Default)]
pub struct Null;

impl Null {
    pub fn from_node(_node: &Node, _ctx: &mut LoadContext) -> Result<Null> {
        Ok(Null)
    }
}

impl BsdfT for Null {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::NULL.union(BsdfFlags::TWO_SIDED)
    }
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        _: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Null(NullContext { wi: si.wi }));
        1
    }
}

/// [`Null`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct NullContext<R: ScalarReal> {
    wi: V3<R>,
}

impl<R: ScalarReal> BsdfContextT<R> for NullContext<R> {
    fn eval(&self, _: V3<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn pdf(&self, _: Vec3) -> f32 {
        0.0
    }
    fn sample(&self, _u1: f32, _u2: Vec2) -> Option<BsdfSample<R>> {
        Some(BsdfSample::pass_through(
            self.wi,
            1.0,
            V3::splat(R::cst(1.0)),
        ))
    }
    fn albedo(&self) -> Spectrum<R> {
        V3::zero()
    }
    fn null_transmission(&self) -> Spectrum<R> {
        V3::splat(R::cst(1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{BsdfContextT, BsdfFlags};

    #[test]
    fn passes_through() {
        let (b, store) = build("null", &[]);
        check_direction_derivatives(&b, &store, 3);
        for wi in [dir(0.3, 1.0), dir(-0.8, 2.0)] {
            let bs = b
                .context(&store.primal(), &si::<f32>(wi))
                .sample(0.5, glam::Vec2::ZERO)
                .unwrap();
            assert_eq!(bs.lobe, BsdfFlags::NULL);
            assert_eq!(bs.wo.val(), -wi);
            assert_eq!(bs.weight.val(), glam::Vec3::ONE);
            assert!(eval_f32(&b, &store, wi, -wi) == glam::Vec3::ZERO);
        }
        let n = node_with_key("null", "b", &[("reflectance", float(0.5))]);
        let e = crate::bsdf::Bsdf::from_node(&n, &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown parameter 'reflectance'"), "{e}");
    }
}
