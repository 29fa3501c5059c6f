//! `diffuse`: the ideal Lambertian reflector.

use super::{BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext};
use crate::ad::{Float, Mask, Real, ScalarReal};
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{warp, Spectrum, V2, V3};
use crate::params::{Domain, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Lambertian reflection `f = reflectance / π` on the front side (+z).
/// Parameter: `reflectance` (float, rgb or texture, default 0.5).
#[derive(Clone, Debug)]
pub struct Diffuse {
    pub reflectance: Texture,
}

impl Diffuse {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Diffuse> {
        Ok(Diffuse {
            reflectance: Texture::from_prop(
                node,
                "reflectance",
                Some(0.5),
                Channels::Rgb,
                Domain::UnitInterval,
                ctx,
            )?,
        })
    }
}

impl BsdfT for Diffuse {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DIFFUSE_REFLECTION
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Diffuse(DiffuseContext {
            wi: si.wi,
            reflectance: self.reflectance.eval(store, si),
        }));
        1
    }
}

/// [`Diffuse`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct DiffuseContext<R: ScalarReal> {
    wi: V3<R>,
    reflectance: Spectrum<R>,
}

impl<R: ScalarReal> BsdfContextT<R> for DiffuseContext<R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        lambert_eval(self.wi, wo, self.reflectance)
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        lambert_pdf(self.wi.z.val(), wo.into())
    }

    fn sample(&self, _u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let (wo, pdf, valid) = lambert_sample(self.wi.z.val(), u2.into());
        valid.then(|| BsdfSample {
            wo: V3::cst(wo.into()),
            pdf,
            // f cos / pdf = reflectance exactly (cos/π cancels)
            weight: self.reflectance,
            eta: 1.0,
            lobe: BsdfFlags::DIFFUSE_REFLECTION,
        })
    }

    fn albedo(&self) -> Spectrum<R> {
        self.reflectance
    }
}

// Lambertian reflection written once for every number type: the scalar
// context above, and the path tracer in lanes (`integrator::lanes`), where
// each lane is another path.

/// `f(wi, wo) · cos θo` of Lambertian reflection: `reflectance · cos θo / π`
/// where both directions are on the front side, else zero.
#[inline(always)]
pub(crate) fn lambert_eval<R: Real>(wi: V3<R>, wo: V3<R>, reflectance: Spectrum<R>) -> Spectrum<R> {
    let front = wi.z.val().gt(0.0) & wo.z.val().gt(0.0);
    if front.none() {
        return V3::zero();
    }
    let f = reflectance * (wo.z * <R::Prim as Real>::cst(FRAC_1_PI));
    V3::select(front, f, V3::zero())
}

/// The density of [`lambert_sample`]'s directions: `cos θo / π` seen from
/// the front side, zero from the back.
#[inline(always)]
pub(crate) fn lambert_pdf<F: Float>(wi_z: F, wo: V3<F>) -> F {
    F::select(
        wi_z.gt(0.0),
        warp::square_to_cosine_hemisphere_pdf(wo),
        F::cst(0.0),
    )
}

/// A cosine-weighted direction for `u` (Malley's method), its density, and
/// whether it is a sample: only from the front side, never at a density of
/// zero (the horizon).
#[inline(always)]
pub(crate) fn lambert_sample<F: Float>(wi_z: F, u: V2<F>) -> (V3<F>, F, F::Mask) {
    let wo = warp::square_to_cosine_hemisphere(u);
    let pdf = warp::square_to_cosine_hemisphere_pdf(wo);
    (wo, pdf, wi_z.gt(0.0) & pdf.gt(0.0))
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use glam::Vec3;

    #[test]
    fn diffuse_sampling_and_values() {
        let (b, store) = build("diffuse", &[("reflectance", rgb(0.2, 0.5, 0.8))]);
        assert!(store.id("b.reflectance.value").is_some());
        let wi = dir(0.4, 0.7);
        let f = eval_f32(&b, &store, wi, dir(0.2, 0.5));
        assert!((f.y - 0.5 / std::f32::consts::PI * dir(0.2, 0.5).z).abs() < 1e-6);
        assert!(eval_f32(&b, &store, Vec3::new(0.0, 0.6, -0.8), Vec3::Z) == glam::Vec3::ZERO);
        assert!(eval_f32(&b, &store, wi, -Vec3::Z) == glam::Vec3::ZERO);
        check_smooth(&b, &store, &[wi, Vec3::Z, dir(0.05, 2.0)], 1);
        let (a, _) = albedo_estimate(&b, &store, wi, 20_000, 3);
        assert!(
            (a.x - 0.2).abs() < 1e-5 && (a.z - 0.8).abs() < 1e-5,
            "{a:?}"
        );
    }
}
