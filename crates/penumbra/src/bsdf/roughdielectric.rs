//! `roughdielectric`: a rough interface between two dielectrics, after
//! Walter et al. 2007, "Microfacet Models for Refraction through Rough
//! Surfaces" (reflection: F D G / (4 |cos θi|); transmission: eq. 21).

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet::{MicrofacetDistribution, Roughness};
use super::{
    default_albedo, eta_props, eval_factor, modulate, scalar_param, smooth_sample,
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

/// Rough dielectric. Parameters (Mitsuba 3): `int_ior` (default bk7),
/// `ext_ior` (default air), `distribution` (default beckmann), `alpha` or
/// `alpha_u`/`alpha_v` (default 0.1), `sample_visible` (default true),
/// `specular_reflectance`, `specular_transmittance` (optional). `eta` is
/// parameter `<key>.eta`. Radiance transport: the transmitted value
/// includes the 1/η² factor (it cancels the η² of the half-vector
/// Jacobian, as in Mitsuba and pbrt).
#[derive(Clone, Debug)]
pub struct RoughDielectric {
    pub roughness: Roughness,
    pub eta: ParamId,
    pub specular_reflectance: Option<Texture>,
    pub specular_transmittance: Option<Texture>,
}

impl RoughDielectric {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<RoughDielectric> {
        let eta = eta_props(node, 1.5046, 1.000277)?;
        let eta = scalar_param(
            node,
            "eta",
            eta,
            ParamFlags::DIFFERENTIABLE,
            Domain::Positive,
            ctx,
        )?;
        let roughness = Roughness::from_node(node, ctx)?;
        let (specular_reflectance, specular_transmittance) = specular_factors(node, ctx)?;
        Ok(RoughDielectric {
            roughness,
            eta,
            specular_reflectance,
            specular_transmittance,
        })
    }

    /// The half vector of (wi, wo), oriented to +z, and whether the pair
    /// is a reflection; `None` for degenerate configurations.
    fn half_vector(wi: Vec3, wo: Vec3, eta: f32) -> Option<(Vec3, bool)> {
        if wi.z == 0.0 || wo.z == 0.0 {
            return None;
        }
        let reflect = wi.z * wo.z > 0.0;
        let e = if reflect {
            1.0
        } else if wi.z > 0.0 {
            eta
        } else {
            1.0 / eta
        };
        let m = wi + wo * e;
        let l = m.length();
        if !(l > 0.0) {
            return None;
        }
        let m = m / l;
        Some((if m.z < 0.0 { -m } else { m }, reflect))
    }
}

impl BsdfT for RoughDielectric {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::GLOSSY_REFLECTION
            .union(BsdfFlags::GLOSSY_TRANSMISSION)
            .union(BsdfFlags::TWO_SIDED)
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::RoughDielectric(RoughDielectricContext {
            wi: si.wi,
            eta: store.read::<R>(self.eta, 0),
            distr: self.roughness.distribution(store, si),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
            specular_transmittance: eval_factor(&self.specular_transmittance, store, si),
        }));
        1
    }
}

/// [`RoughDielectric`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct RoughDielectricContext<R: ScalarReal> {
    wi: V3<R>,
    eta: R,
    distr: MicrofacetDistribution<R>,
    specular_reflectance: Option<Spectrum<R>>,
    specular_transmittance: Option<Spectrum<R>>,
}

impl<R: ScalarReal> BsdfContextT<R> for RoughDielectricContext<R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let eta_p = self.eta;
        let wi = self.wi;
        let cos_i = wi.z;
        if cos_i.val() == 0.0 || wo.z.val() == 0.0 {
            return V3::zero();
        }
        let reflect = cos_i.val() * wo.z.val() > 0.0;
        let eta = if cos_i.val() > 0.0 {
            eta_p
        } else {
            eta_p.recip()
        };
        let mut m = (wi + if reflect { wo } else { wo * eta }).normalize();
        if m.z.val() < 0.0 {
            m = -m;
        }
        let d = self.distr.eval(m);
        if d.val() == 0.0 {
            return V3::zero();
        }
        let g = self.distr.g(wi, wo, m);
        let (f, ..) = fresnel_dielectric(wi.dot(m), eta_p);
        if reflect {
            let v = f * d * g / (cos_i.abs() * 4.0);
            modulate(V3::splat(v), self.specular_reflectance)
        } else {
            let wim = wi.dot(m);
            let wom = wo.dot(m);
            let denom = wim + eta * wom;
            // η² of the Jacobian × 1/η² of radiance scaling = 1
            let v = ((-f + 1.0) * d * g * wim * wom / (cos_i * denom * denom)).abs();
            modulate(V3::splat(v), self.specular_transmittance)
        }
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let wi = self.wi.val();
        let eta_p = self.eta.val();
        let Some((m, reflect)) = RoughDielectric::half_vector(wi, wo, eta_p) else {
            return 0.0;
        };
        // micro- and macro-surface must agree on the sides
        if !(wi.dot(m) * wi.z > 0.0 && wo.dot(m) * wo.z > 0.0) {
            return 0.0;
        }
        let eta = if wi.z > 0.0 { eta_p } else { 1.0 / eta_p };
        let dwh_dwo = if reflect {
            1.0 / (4.0 * wo.dot(m))
        } else {
            let den = wi.dot(m) + eta * wo.dot(m);
            eta * eta * wo.dot(m) / (den * den)
        };
        let distr = self.distr.detach();
        let wi_up = if wi.z < 0.0 { -wi } else { wi };
        let mut p = distr.pdf(wi_up, m);
        let f = fresnel_dielectric(wi.dot(m), eta_p).0;
        p *= if reflect { f } else { 1.0 - f };
        p * dwh_dwo.abs()
    }

    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let wi = self.wi.val();
        if wi.z == 0.0 {
            return None;
        }
        let eta_p = self.eta.val();
        let distr = self.distr.detach();
        let wi_up = if wi.z < 0.0 { -wi } else { wi };
        let (m, pdf_m) = distr.sample(wi_up, u2);
        // back-facing microfacets (possible without visible-normal
        // sampling) scatter nothing (their G1 is zero)
        if !(pdf_m > 0.0 && wi_up.dot(m) > 0.0) {
            return None;
        }
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), eta_p);
        let (wi_v, m_v) = (V3::from(wi), V3::from(m));
        let (wo, lobe, eta) = if u1 < f {
            (reflect(wi_v, m_v).val(), BsdfFlags::GLOSSY_REFLECTION, 1.0)
        } else {
            (
                refract(wi_v, m_v, cos_t, eta_ti).val(),
                BsdfFlags::GLOSSY_TRANSMISSION,
                eta_it,
            )
        };
        let same_side = wo.z * wi.z > 0.0;
        if same_side != (lobe == BsdfFlags::GLOSSY_REFLECTION) || wo.z == 0.0 {
            return None;
        }
        smooth_sample(self, wo, eta, lobe)
    }

    fn albedo(&self) -> Spectrum<R> {
        default_albedo(self)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::BsdfContextT;
    use crate::ad::Dual;
    use crate::math::V3;
    use crate::scene::description::Value;

    #[test]
    fn sampling_matches_pdf_both_sides() {
        let configs: Vec<Vec<(&str, Value)>> = vec![
            vec![
                ("distribution", string("ggx")),
                ("alpha", float(0.1)),
                ("int_ior", float(1.5)),
                ("ext_ior", float(1.0)),
            ],
            vec![("alpha", float(0.3))],
            vec![
                ("distribution", string("ggx")),
                ("alpha_u", float(0.1)),
                ("alpha_v", float(0.4)),
            ],
            vec![
                ("distribution", string("ggx")),
                ("alpha", float(0.4)),
                ("sample_visible", boolean(false)),
            ],
        ];
        let wis = [
            dir(0.8, 0.3),
            dir(0.2, 2.0),
            dir(-0.7, 1.0),
            dir(-0.15, 4.0),
        ];
        for c in &configs {
            let (b, store) = build("roughdielectric", c);
            check_smooth(&b, &store, &wis, configs.len());
        }
    }

    /// R + T ≤ 1 (energy, undoing radiance scaling), and close to 1 for a
    /// smooth-ish interface seen from outside at normal incidence.
    #[test]
    fn energy_is_conserved() {
        for (dist, alpha) in [("ggx", 0.1), ("beckmann", 0.1), ("ggx", 0.7)] {
            let (b, store) = build(
                "roughdielectric",
                &[("distribution", string(dist)), ("alpha", float(alpha))],
            );
            for wi in [dir(0.9, 0.0), dir(0.3, 1.0), dir(-0.9, 2.0), dir(-0.4, 0.5)] {
                let eta2 = if wi.z > 0.0 {
                    1.5046f32 / 1.000277
                } else {
                    1.000277 / 1.5046
                }
                .powi(2);
                let (a, msg) = check_energy(&b, &store, wi, 13, eta2, &format!("{dist} {alpha}"));
                if alpha < 0.2 && wi.z.abs() > 0.85 {
                    assert!(a > 0.95, "{msg}");
                }
            }
        }
    }

    /// Values of Mitsuba 3.9.1 (scalar_rgb) `eval` / `pdf` for the scene's
    /// roughdielectric (GGX, alpha 0.1, eta 1.5), radiance mode.
    #[test]
    fn matches_mitsuba_values() {
        let (b, store) = build(
            "roughdielectric",
            &[
                ("distribution", string("ggx")),
                ("alpha", float(0.1)),
                ("int_ior", float(1.5)),
                ("ext_ior", float(1.0)),
            ],
        );
        for &(wi, wo, f_ref, p_ref) in super::tests_ref::ROUGHDIELECTRIC {
            let (wi, wo) = (
                glam::Vec3::from(wi).normalize(),
                glam::Vec3::from(wo).normalize(),
            );
            let f = eval_f32(&b, &store, wi, wo).x;
            let p = pdf_f32(&b, &store, wi, wo);
            assert!(
                (f - f_ref).abs() <= 1e-4 * f_ref.abs(),
                "{wi:?} {wo:?}: eval {f} vs {f_ref}"
            );
            assert!(
                (p - p_ref).abs() <= 1e-4 * p_ref.abs(),
                "{wi:?} {wo:?}: pdf {p} vs {p_ref}"
            );
        }
        // f32 and Dual give identical primal values
        let wi = glam::Vec3::new(0.3, 0.1, 0.9).normalize();
        let wo = glam::Vec3::new(-0.2, -0.1, -0.95).normalize();
        let a = b.context(&store.primal(), &si::<f32>(wi)).eval(V3::cst(wo));
        let d = b
            .context(&store.primal(), &si::<Dual>(wi))
            .eval(V3::cst(wo));
        assert_eq!(a.x, d.x.v);
    }
}

#[cfg(test)]
mod tests_ref {
    /// (wi, wo, eval, pdf) from Mitsuba 3.9.1.
    type RefRow = ([f32; 3], [f32; 3], f32, f32);
    #[allow(clippy::excessive_precision)]
    pub const ROUGHDIELECTRIC: &[RefRow] = &[
        (
            [0.3, 0.1, 0.9],
            [-0.2, -0.1, -0.95],
            3.0811674e+01,
            6.9335861e+01,
        ),
        (
            [0.3, 0.1, 0.9],
            [-0.3, -0.1, 0.9],
            3.3913729e-01,
            3.3924186e-01,
        ),
        (
            [0.5, 0.0, 0.5],
            [-0.6, 0.0, 0.55],
            5.2878779e-01,
            5.3035647e-01,
        ),
        (
            [0.5, 0.0, 0.5],
            [-0.25, 0.02, -0.9],
            7.4094675e-02,
            1.6674538e-01,
        ),
        (
            [0.2, 0.3, -0.8],
            [-0.3, -0.5, -0.7],
            6.9046274e-02,
            6.9165841e-02,
        ),
        (
            [0.2, 0.3, -0.8],
            [-0.25, -0.45, 0.85],
            9.0298586e+00,
            4.0169477e+00,
        ),
        (
            [0.0, 0.0, 1.0],
            [0.05, 0.0, -1.0],
            1.1651066e+01,
            2.6215057e+01,
        ),
        (
            [0.7, 0.1, -0.3],
            [-0.7, -0.1, -0.3],
            1.9827820e+01,
            2.0099483e+01,
        ),
    ];
}
