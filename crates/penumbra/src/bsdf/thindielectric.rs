//! `thindielectric`: a thin dielectric slab (window pane) with both
//! interfaces and all internal reflections folded into one surface;
//! transmitted light continues undeflected.

use super::fresnel::fresnel_dielectric;
use super::{
    default_albedo, eta_props, eval_factor, modulate, sample_reflect_or_transmit, scalar_param,
    specular_factors, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Thin dielectric. Parameters (Mitsuba 3): `int_ior` (default bk7),
/// `ext_ior` (default air), `specular_reflectance`,
/// `specular_transmittance` (optional). Reflectance including the
/// internal bounces: `R' = R + T² R / (1 − R²) = 2R / (1 + R)`. As in
/// Mitsuba, the transmitted lobe is a `NULL` (pass-through) lobe.
#[derive(Clone, Debug)]
pub struct ThinDielectric {
    pub eta: ParamId,
    pub specular_reflectance: Option<Texture>,
    pub specular_transmittance: Option<Texture>,
}

impl ThinDielectric {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<ThinDielectric> {
        let eta = eta_props(node, 1.5046, 1.000277)?;
        let eta = scalar_param(
            node,
            "eta",
            eta,
            ParamFlags::DIFFERENTIABLE,
            Domain::Positive,
            ctx,
        )?;
        let (specular_reflectance, specular_transmittance) = specular_factors(node, ctx)?;
        Ok(ThinDielectric {
            eta,
            specular_reflectance,
            specular_transmittance,
        })
    }
}

impl BsdfT for ThinDielectric {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DELTA_REFLECTION
            .union(BsdfFlags::NULL)
            .union(BsdfFlags::TWO_SIDED)
    }
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::ThinDielectric(ThinDielectricContext {
            wi: si.wi,
            eta: store.read::<R>(self.eta, 0),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
            specular_transmittance: eval_factor(&self.specular_transmittance, store, si),
        }));
        1
    }
}

/// [`ThinDielectric`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct ThinDielectricContext<R: ScalarReal> {
    wi: V3<R>,
    eta: R,
    specular_reflectance: Option<Spectrum<R>>,
    specular_transmittance: Option<Spectrum<R>>,
}

impl<R: ScalarReal> BsdfContextT<R> for ThinDielectricContext<R> {
    fn eval(&self, _: V3<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn pdf(&self, _: Vec3) -> f32 {
        0.0
    }
    fn sample(&self, u1: f32, _u2: Vec2) -> Option<BsdfSample<R>> {
        let f = self.reflectance();
        sample_reflect_or_transmit(
            self.wi,
            f,
            self.specular_reflectance,
            self.specular_transmittance,
            u1,
            (-self.wi, -f + 1.0, 1.0, BsdfFlags::NULL),
        )
    }
    fn albedo(&self) -> Spectrum<R> {
        default_albedo(self)
    }
    fn null_transmission(&self) -> Spectrum<R> {
        modulate(
            V3::splat(-self.reflectance() + 1.0),
            self.specular_transmittance,
        )
    }
}

impl<R: ScalarReal> ThinDielectricContext<R> {
    /// `R'`, the reflectance with the internal bounces.
    fn reflectance(&self) -> R {
        let (f, ..) = fresnel_dielectric(self.wi.z.abs(), self.eta);
        if f.val() < 1.0 {
            f * 2.0 / (f + 1.0)
        } else {
            f
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{BsdfContextT, BsdfFlags};
    use crate::ad::Dual;
    use crate::bsdf::fresnel::fresnel_dielectric;
    use crate::params::Seeds;
    use crate::testing::Pcg32;
    use glam::Vec2;

    #[test]
    fn pass_through_and_internal_reflections() {
        let (b, store) = build(
            "thindielectric",
            &[("int_ior", float(1.5)), ("ext_ior", float(1.0))],
        );
        check_direction_derivatives(&b, &store, 3);
        for wi in [dir(0.9, 0.1), dir(-0.4, 2.0)] {
            let f = fresnel_dielectric(wi.z.abs(), 1.5).0;
            let r = 2.0 * f / (1.0 + f);
            let s = si::<f32>(wi);
            let mut rng = Pcg32::new(1);
            let (mut nr, n) = (0, 4000);
            for _ in 0..n {
                let bs = b
                    .context(&store.primal(), &s)
                    .sample(rng.next_f32(), Vec2::ZERO)
                    .unwrap();
                assert!((bs.weight.x - 1.0).abs() < 1e-5 && bs.eta == 1.0);
                if bs.lobe == BsdfFlags::DELTA_REFLECTION {
                    nr += 1;
                    assert!((bs.wo.z - wi.z).abs() < 1e-6 && (bs.wo.x + wi.x).abs() < 1e-6);
                } else {
                    assert_eq!(bs.lobe, BsdfFlags::NULL);
                    assert!((bs.wo.val() + wi).length() < 1e-6);
                }
            }
            assert_binomial(nr, n, r, "");
        }
        // eta is differentiable: d weight / d eta of the reflected lobe
        let seeds = Seeds::tangents(&store, &[("b.eta", &[1.0])]).unwrap();
        let store = store.view(&seeds);
        let bs = b
            .context(&store, &si::<Dual>(dir(0.5, 0.0)))
            .sample(0.0, Vec2::ZERO)
            .unwrap();
        assert!(bs.weight.x.d > 0.0, "{bs:?}");
    }
}
