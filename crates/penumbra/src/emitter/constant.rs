//! Mitsuba's `constant` emitter: the same radiance from every direction.

use super::{
    emission_prop, eval_uniform, far_point, BoundingSphere, DirectionSample, EmitterSample,
    EmitterT,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::{Shape, SurfaceInteraction};
use crate::math::{warp, Spectrum, V3};
use crate::params::{ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Radiance `radiance` (key `<key>.radiance.value`) arriving from all
/// directions at infinity; sampled uniformly on the sphere (pdf 1/(4π)).
#[derive(Clone, Debug)]
pub struct Constant {
    pub radiance: Texture,
    pub bounds: BoundingSphere,
}

impl Constant {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Constant> {
        let radiance = emission_prop(node, "radiance", ctx)?;
        Ok(Constant {
            radiance,
            bounds: BoundingSphere::default(),
        })
    }

    /// The density per solid angle of its directions, the same in every
    /// direction: uniform on the sphere.
    pub(crate) const DIRECTION_PDF: f32 = warp::UNIFORM_SPHERE_PDF;

    /// The direction of the sample for `u` and its density per solid
    /// angle. (The path tracer in lanes samples a constant of plain
    /// radiance with it, without an emitter sample.)
    #[inline(always)]
    pub(crate) fn sample_direction_primal(u: Vec2) -> (Vec3, f32) {
        (warp::square_to_uniform_sphere(u), Constant::DIRECTION_PDF)
    }
}

impl EmitterT for Constant {
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let (d, pdf) = Constant::sample_direction_primal(u);
        let ds = DirectionSample {
            p: far_point(&self.bounds, ref_p.val(), d),
            n: -d,
            d,
            dist: f32::INFINITY,
            pdf,
            delta: false,
        };
        Some(EmitterSample::fixed_direction(
            ds,
            eval_uniform::<R>(&self.radiance, store).scale(1.0 / pdf),
        ))
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
        Constant::DIRECTION_PDF
    }
    fn eval_surface<R: ScalarReal>(&self, _: &ParamView, _: &SurfaceInteraction<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn eval_environment<R: ScalarReal>(&self, store: &ParamView, _d: V3<R>) -> Spectrum<R> {
        eval_uniform::<R>(&self.radiance, store)
    }
    fn is_delta(&self) -> bool {
        false
    }
    fn is_environment(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::emitter::test_util::{node, CHI2_ALPHA};
    use crate::emitter::Emitter;
    use crate::emitter::EmitterSample;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::Value;
    use crate::testing::Chi2Test;
    use std::f32::consts::PI;

    fn make() -> (Emitter, LoadContext) {
        let mut ctx = LoadContext::default();
        let n = node(
            "constant",
            "sky",
            vec![("radiance", Value::Rgb(Vec3::new(1.0, 2.0, 0.5)))],
        );
        (Emitter::from_node(&n, None, &mut ctx).unwrap(), ctx)
    }

    #[test]
    fn uniform_sphere_sampling_with_consistent_weights() {
        let (e, ctx) = make();
        let s = &ctx.store;
        let ref_p = Vec3::new(0.3, -0.2, 0.1);
        let r = Chi2Test::default().run(
            |rng| {
                let EmitterSample { ds, weight: w, .. } =
                    e.sample_direction::<f32>(&s.primal(), &[], V3::cst(ref_p), rng.next_2d())?;
                assert!((ds.pdf - 1.0 / (4.0 * PI)).abs() < 1e-7);
                assert!(!ds.delta && ds.dist.is_infinite());
                // weight = radiance / pdf, and pdf_direction agrees
                let want = e.eval_environment::<f32>(&s.primal(), V3::cst(ds.d)).val() / ds.pdf;
                assert!((w.val() - want).abs().max_element() < 1e-4 * want.max_element());
                assert_eq!(e.pdf_direction(s, &[], ref_p, ds.d, ds.p, ds.n), ds.pdf);
                // the sample point lies along d, outside the unit sphere
                assert!(((ds.p - ref_p).normalize() - ds.d).length() < 1e-5);
                assert!(ds.p.length() > 1.0);
                Some(ds.d)
            },
            |d| e.pdf_direction(s, &[], ref_p, d, Vec3::ZERO, Vec3::ZERO),
        );
        assert!(r.p_value > CHI2_ALPHA, "{r:?}");
        assert!((r.pdf_integral - 1.0).abs() < 1e-3);
        assert!(e.is_environment() && !e.is_delta());
    }

    #[test]
    fn radiance_is_differentiable() {
        let (e, ctx) = make();
        let seeds =
            Seeds::tangents(&ctx.store, &[("sky.radiance.value", &[0.0, 1.0, 0.0])]).unwrap();
        let store = ctx.store.view(&seeds);
        let EmitterSample { weight: w, .. } = e
            .sample_direction::<Dual>(&store, &[], V3::cst(Vec3::ZERO), Vec2::new(0.2, 0.7))
            .unwrap();
        assert!((w.y.d - 4.0 * PI).abs() < 1e-4 && w.x.d == 0.0);
        let l = e.eval_environment::<Dual>(&store, V3::cst(Vec3::X));
        assert_eq!((l.y.v, l.y.d), (2.0, 1.0));
    }
}
