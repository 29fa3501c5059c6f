//! `dielectric`: a smooth interface between two dielectrics (glass,
//! water): delta reflection and refraction weighted by the Fresnel terms.

use super::fresnel::{fresnel_dielectric, refract};
use super::{
    default_albedo, eta_props, eval_factor, sample_reflect_or_transmit, scalar_param,
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

/// Smooth dielectric. Parameters (Mitsuba 3): `int_ior` (default bk7,
/// 1.5046), `ext_ior` (default air), numbers or material names;
/// `specular_reflectance`, `specular_transmittance` (optional, default 1).
/// The relative index `eta = int_ior / ext_ior` is parameter `<key>.eta`
/// (not differentiable, as in Mitsuba).
///
/// Transport is radiance (camera paths): refracted weights carry the
/// `1/η²` solid-angle compression factor.
#[derive(Clone, Debug)]
pub struct Dielectric {
    pub eta: ParamId,
    pub specular_reflectance: Option<Texture>,
    pub specular_transmittance: Option<Texture>,
}

impl Dielectric {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Dielectric> {
        let eta = eta_props(node, 1.5046, 1.000277)?;
        let eta = scalar_param(
            node,
            "eta",
            eta,
            ParamFlags::NON_DIFFERENTIABLE,
            Domain::Positive,
            ctx,
        )?;
        let (specular_reflectance, specular_transmittance) = specular_factors(node, ctx)?;
        Ok(Dielectric {
            eta,
            specular_reflectance,
            specular_transmittance,
        })
    }
}

impl BsdfT for Dielectric {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DELTA_REFLECTION
            .union(BsdfFlags::DELTA_TRANSMISSION)
            .union(BsdfFlags::TWO_SIDED)
    }
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Dielectric(DielectricContext {
            wi: si.wi,
            eta: store.read::<R>(self.eta, 0),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
            specular_transmittance: eval_factor(&self.specular_transmittance, store, si),
        }));
        1
    }
}

/// [`Dielectric`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct DielectricContext<R: ScalarReal> {
    wi: V3<R>,
    eta: R,
    specular_reflectance: Option<Spectrum<R>>,
    specular_transmittance: Option<Spectrum<R>>,
}

impl<R: ScalarReal> BsdfContextT<R> for DielectricContext<R> {
    fn eval(&self, _: V3<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn pdf(&self, _: Vec3) -> f32 {
        0.0
    }
    fn sample(&self, u1: f32, _u2: Vec2) -> Option<BsdfSample<R>> {
        let wi = self.wi;
        if wi.z.val() == 0.0 {
            return None;
        }
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, self.eta);
        let wo = refract(wi, V3::cst(Vec3::Z), cos_t, eta_ti);
        // radiance is scaled by η_ti² crossing the interface
        let value = (-f + 1.0) * eta_ti * eta_ti;
        sample_reflect_or_transmit(
            wi,
            f,
            self.specular_reflectance,
            self.specular_transmittance,
            u1,
            (wo, value, eta_it.val(), BsdfFlags::DELTA_TRANSMISSION),
        )
    }
    fn albedo(&self) -> Spectrum<R> {
        default_albedo(self)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{BsdfContextT, BsdfFlags};
    use crate::bsdf::fresnel::fresnel_dielectric;
    use crate::testing::Pcg32;
    use glam::{Vec2, Vec3};

    #[test]
    fn snell_fresnel_and_energy() {
        let (b, store) = build(
            "dielectric",
            &[("int_ior", string("water")), ("ext_ior", string("air"))],
        );
        check_direction_derivatives(&b, &store, 3);
        let eta = 1.3330f32 / 1.000277;
        assert!((store.data(store.id("b.eta").unwrap())[0] - eta).abs() < 1e-6);
        for wi in [
            dir(0.8, 0.4),
            dir(0.2, 2.0),
            dir(-0.8, 0.4),
            dir(-0.5, 1.0),
            dir(-0.9, 5.0),
        ] {
            let s = si::<f32>(wi);
            let (f, ..) = fresnel_dielectric(wi.z, eta);
            let mut rng = Pcg32::new(3);
            let (mut nr, n) = (0, 4000);
            for _ in 0..n {
                let bs = b
                    .context(&store.primal(), &s)
                    .sample(rng.next_f32(), Vec2::ZERO)
                    .unwrap();
                if bs.lobe == BsdfFlags::DELTA_REFLECTION {
                    nr += 1;
                    assert!((bs.wo.val() - Vec3::new(-wi.x, -wi.y, wi.z)).length() < 1e-6);
                    assert!((bs.weight.x - 1.0).abs() < 1e-5 && (bs.pdf - f).abs() < 1e-6);
                } else {
                    assert_eq!(bs.lobe, BsdfFlags::DELTA_TRANSMISSION);
                    // Snell's law: η_i sin θi = η_t sin θt, opposite sides
                    let (ni, nt) = if wi.z > 0.0 { (1.0, eta) } else { (eta, 1.0) };
                    let si_ = (1.0 - wi.z * wi.z).sqrt();
                    let st = (1.0 - bs.wo.z * bs.wo.z).sqrt();
                    assert!((ni * si_ - nt * st).abs() < 1e-5 && bs.wo.z * wi.z < 0.0);
                    assert!((bs.wo.length() - 1.0).abs() < 1e-5);
                    assert!((bs.wo.x * wi.y - bs.wo.y * wi.x).abs() < 1e-6, "same plane");
                    // radiance scaling (η_i/η_t)²; energy weight × η² = 1
                    assert!((bs.weight.x - (ni / nt).powi(2)).abs() < 1e-5);
                    assert!((bs.eta - nt / ni).abs() < 1e-5);
                }
            }
            // reflection frequency ~ Binomial(n, F)
            assert_binomial(nr, n, f, &format!("{wi:?}: "));
            let (a, _) = albedo_estimate(&b, &store, wi, 2000, 9);
            assert!((a.x - 1.0).abs() < 1e-4, "{a}");
            assert!(
                eval_f32(&b, &store, wi, -wi) == glam::Vec3::ZERO
                    && pdf_f32(&b, &store, wi, -wi) == 0.0
            );
        }
        // total internal reflection from inside at grazing angles
        let bs = b
            .context(&store.primal(), &si::<f32>(dir(-0.2, 0.0)))
            .sample(0.999, Vec2::ZERO)
            .unwrap();
        assert_eq!(bs.lobe, BsdfFlags::DELTA_REFLECTION);
    }

    #[test]
    fn tints_and_errors() {
        let (b, store) = build(
            "dielectric",
            &[
                ("int_ior", float(1.5)),
                ("specular_transmittance", rgb(0.5, 0.5, 0.5)),
            ],
        );
        check_direction_derivatives(&b, &store, 3);
        assert!(store.id("b.specular_transmittance.value").is_some());
        assert!(store.id("b.specular_reflectance.value").is_none());
        let bs = b
            .context(&store.primal(), &si::<f32>(Vec3::Z))
            .sample(0.99, Vec2::ZERO)
            .unwrap();
        assert!(
            (bs.weight.x - 0.5 / (1.5f32 / 1.000277).powi(2)).abs() < 1e-5,
            "{bs:?}"
        );
        let n = node_with_key("dielectric", "b", &[("int_ior", string("glass"))]);
        let e = crate::bsdf::Bsdf::from_node(&n, &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown material 'glass'") && e.contains("bk7"),
            "{e}"
        );
    }
}
