//! `pplastic`: Mitsuba 3's "polarized plastic", rendered unpolarised as its
//! RGB variants do. The pBRDF of Baek et al. 2018 ("Simultaneous
//! Acquisition of Polarimetric SVBRDF and Normals") without the Mueller
//! calculus: a rough microfacet reflection at the surface, added to a
//! Lambertian term attenuated by a smooth refraction into the material and
//! one out of it,
//!
//!   f cos θo = s F(wi·h) D(h) G(wi, wo, h) / (4 cos θi)
//!            + ρ (1 − F(cos θi)) (1 − F(cos θo)) cos θo / π.
//!
//! Unlike `roughplastic` the two terms are simply added (no internal
//! reflections of the coating): not energy conserving, never brighter than
//! the incident light. Sampling picks the specular lobe with the fixed
//! probability s̄ / (ρ̄ + s̄) of the texture means, the diffuse lobe by
//! cosine sampling, and weights by the mixture's pdf (as Mitsuba does).

use super::fresnel::fresnel_dielectric;
use super::microfacet::{warn_if_smooth, MicrofacetDistribution, MicrofacetType};
use super::plastic::{coating_reflectances, sampling_weight};
use super::roughplastic::{coating_reflection, glossy_or_diffuse_pdf, sample_glossy_or_diffuse};
use super::{
    eta_props, eval_factor, modulate, scalar_param, smooth_sample, BsdfContextT, BsdfFlags,
    BsdfSample, BsdfT, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Texture, TextureT};
use glam::{Vec2, Vec3};

/// Polarised plastic, unpolarised. Parameters (Mitsuba 3):
/// `diffuse_reflectance` (default 0.5), `specular_reflectance` (optional
/// factor), `int_ior` (default polypropylene), `ext_ior` (default air),
/// `distribution` (default beckmann), `alpha` (default 0.1) or `alpha_u` +
/// `alpha_v`, `sample_visible` (default true). Parameters
/// `<key>.diffuse_reflectance…`, `<key>.specular_reflectance…`,
/// `<key>.eta`, `<key>.alpha` (or `<key>.alpha_u`, `<key>.alpha_v`), all
/// differentiable, as Mitsuba's `traverse` exposes them.
#[derive(Clone, Debug)]
pub struct PPlastic {
    pub kind: MicrofacetType,
    pub alpha_u: ParamId,
    /// `None`: isotropic (`alpha`).
    pub alpha_v: Option<ParamId>,
    pub sample_visible: bool,
    pub eta: ParamId,
    pub diffuse_reflectance: Texture,
    pub specular_reflectance: Option<Texture>,
    pub specular_sampling_weight: f32,
}

impl PPlastic {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<PPlastic> {
        let kind = match node.choice("distribution", &["beckmann", "ggx"])?.as_str() {
            "ggx" => MicrofacetType::Ggx,
            _ => MicrofacetType::Beckmann,
        };
        let eta = eta_props(node, 1.49, 1.000277)?;
        if eta == 1.0 {
            return Err(node.error(
                "the interior and exterior indices of refraction are equal: \
                 the surface would reflect nothing; make 'int_ior' differ from 'ext_ior'",
            ));
        }
        // roughness as scalars (Mitsuba's pplastic takes floats only)
        let mut roughness = |name: &str| -> Result<ParamId> {
            warn_if_smooth(node, name);
            let value = node.float_checked(name, 0.1, false)?;
            scalar_param(
                node,
                name,
                value,
                ParamFlags::DIFFERENTIABLE,
                Domain::NonNegative,
                ctx,
            )
        };
        let (alpha_u, alpha_v) = if node.has("alpha_u") || node.has("alpha_v") {
            if !(node.has("alpha_u") && node.has("alpha_v")) {
                return Err(node.error("both 'alpha_u' and 'alpha_v' must be given"));
            }
            if node.has("alpha") {
                return Err(node.error("give either 'alpha' or 'alpha_u' and 'alpha_v', not both"));
            }
            (roughness("alpha_u")?, Some(roughness("alpha_v")?))
        } else {
            (roughness("alpha")?, None)
        };
        let sample_visible = node.bool("sample_visible", true)?;
        let eta = scalar_param(
            node,
            "eta",
            eta,
            ParamFlags::DIFFERENTIABLE,
            Domain::Positive,
            ctx,
        )?;
        let (diffuse_reflectance, specular_reflectance) = coating_reflectances(node, ctx)?;
        Ok(PPlastic {
            kind,
            alpha_u,
            alpha_v,
            sample_visible,
            eta,
            diffuse_reflectance,
            specular_reflectance,
            specular_sampling_weight: 0.5,
        })
    }

    /// Updates the lobe-selection probability from the texture means.
    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.specular_sampling_weight =
            sampling_weight(store, &self.diffuse_reflectance, &self.specular_reflectance);
    }
}

impl BsdfT for PPlastic {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::GLOSSY_REFLECTION.union(BsdfFlags::DIFFUSE_REFLECTION)
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let alpha_u = store.read::<R>(self.alpha_u, 0);
        let alpha_v = self.alpha_v.map_or(alpha_u, |a| store.read::<R>(a, 0));
        nodes[0] = Some(NodeContext::PPlastic(PPlasticContext {
            wi: si.wi,
            eta: store.read::<R>(self.eta, 0),
            distr: MicrofacetDistribution::new(self.kind, alpha_u, alpha_v, self.sample_visible),
            diffuse_reflectance: self.diffuse_reflectance.eval(store, si),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
            specular_probability: self.specular_sampling_weight,
        }));
        1
    }
}

/// [`PPlastic`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct PPlasticContext<R: ScalarReal> {
    wi: V3<R>,
    eta: R,
    distr: MicrofacetDistribution<R>,
    diffuse_reflectance: Spectrum<R>,
    specular_reflectance: Option<Spectrum<R>>,
    specular_probability: f32,
}

impl<R: ScalarReal> BsdfContextT<R> for PPlasticContext<R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let wi = self.wi;
        if !(wi.z.val() > 0.0 && wo.z.val() > 0.0) {
            return V3::zero();
        }
        let eta = self.eta;
        let spec = coating_reflection(&self.distr, wi, wo, eta);
        let t_i = -fresnel_dielectric(wi.z, eta).0 + 1.0;
        let t_o = -fresnel_dielectric(wo.z, eta).0 + 1.0;
        let diff = self.diffuse_reflectance * (t_i * t_o * wo.z * std::f32::consts::FRAC_1_PI);
        modulate(spec, self.specular_reflectance) + diff
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let wi = self.wi.val();
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return 0.0;
        }
        glossy_or_diffuse_pdf(&self.distr.detach(), wi, wo, self.specular_probability)
    }

    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let wi = self.wi.val();
        if !(wi.z > 0.0) {
            return None;
        }
        let (wo, lobe) =
            sample_glossy_or_diffuse(&self.distr.detach(), wi, self.specular_probability, u1, u2)?;
        smooth_sample(self, wo, 1.0, lobe)
    }

    fn albedo(&self) -> Spectrum<R> {
        self.diffuse_reflectance
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::BsdfContextT;
    use crate::ad::Dual;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::Value;
    use glam::Vec3;

    #[test]
    fn sampling_matches_pdf() {
        let cases: Vec<Vec<(&str, Value)>> = vec![
            vec![
                ("distribution", string("ggx")),
                ("alpha", float(0.1)),
                ("diffuse_reflectance", rgb(0.1, 0.3, 0.7)),
            ],
            vec![("alpha_u", float(0.05)), ("alpha_v", float(0.3))],
        ];
        let wis = [dir(0.85, 0.2), dir(0.15, 1.5)];
        check_sampling_and_albedo("pplastic", &cases, &wis, 4);
    }

    /// The forward-mode derivative of `eval` with respect to each scalar
    /// parameter matches the central difference of the f32 `eval`.
    #[test]
    fn parameter_derivatives() {
        let props = |au: f64, av: f64, ior: f64| {
            vec![
                ("distribution", string("ggx")),
                ("alpha_u", float(au)),
                ("alpha_v", float(av)),
                ("int_ior", float(ior)),
                ("ext_ior", float(1.0)),
                ("diffuse_reflectance", rgb(0.2, 0.4, 0.6)),
            ]
        };
        let (au, av, ior) = (0.2, 0.35, 1.5);
        let (b, store) = build("pplastic", &props(au, av, ior));
        let h = 1e-3;
        for (wi, wo) in [
            (dir(0.8, 0.3), dir(0.6, 2.9)),
            (dir(0.4, 1.0), dir(0.5, 4.0)),
        ] {
            for (key, k) in [("b.alpha_u", 0), ("b.alpha_v", 1), ("b.eta", 2)] {
                let seeds = Seeds::tangents(&store, &[(key, &[1.0])]).unwrap();
                let d = b
                    .context(&store.view(&seeds), &si::<Dual>(wi))
                    .eval(V3::cst(wo));
                let d = Vec3::new(d.x.d, d.y.d, d.z.d);
                let at = |x: f64| {
                    let mut v = [au, av, ior];
                    v[k] = x;
                    let (b, s) = build("pplastic", &props(v[0], v[1], v[2]));
                    eval_f32(&b, &s, wi, wo)
                };
                let x = [au, av, ior][k];
                let fd = (at(x + h) - at(x - h)) / (2.0 * h as f32);
                assert!(fd.abs().max_element() > 1e-3, "{key}: no signal");
                assert_derivative(d, fd, at(x), &|| format!("d eval / d {key} at {wi}, {wo}"));
            }
        }
    }

    /// Values of Mitsuba 3.9.1 (scalar_rgb) pplastic `eval` / `pdf`
    /// (diffuse_reflectance (0.1, 0.3, 0.7), int_ior 1.5, ext_ior 1),
    /// printed by `bsdf.eval(ctx, si, wo)` and `bsdf.pdf(ctx, si, wo)`
    /// with `si.wi = wi` in the local frame.
    #[test]
    fn matches_mitsuba_values() {
        for &(dist, alpha, wi, wo, f_ref, p_ref) in PPLASTIC_REF {
            let (b, store) = build(
                "pplastic",
                &[
                    ("distribution", string(dist)),
                    ("alpha", float(alpha as f64)),
                    ("int_ior", float(1.5)),
                    ("ext_ior", float(1.0)),
                    ("diffuse_reflectance", rgb(0.1, 0.3, 0.7)),
                ],
            );
            let (wi, wo) = (Vec3::from(wi).normalize(), Vec3::from(wo).normalize());
            let f = eval_f32(&b, &store, wi, wo);
            let p = pdf_f32(&b, &store, wi, wo);
            let f_ref = Vec3::from(f_ref);
            assert!(
                (f - f_ref).abs().max_element() <= 1e-5 * (1.0 + f_ref.max_element()),
                "{dist} α={alpha} wi={wi} wo={wo}: eval {f} vs Mitsuba {f_ref}"
            );
            assert!(
                (p - p_ref).abs() <= 1e-5 * (1.0 + p_ref),
                "{dist} α={alpha} wi={wi} wo={wo}: pdf {p} vs Mitsuba {p_ref}"
            );
        }
    }

    /// (distribution, alpha, wi, wo, eval, pdf)
    type Case = (&'static str, f32, [f32; 3], [f32; 3], [f32; 3], f32);
    // Mitsuba's values as printed (9 digits)
    #[allow(clippy::excessive_precision)]
    const PPLASTIC_REF: &[Case] = &[
        (
            "beckmann",
            0.1,
            [0.3, 0.1, 0.9],
            [-0.2, 0.05, 0.8],
            [1.69622138e-01, 2.26419061e-01, 3.40012908e-01],
            2.65886831e+00,
        ),
        (
            "beckmann",
            0.1,
            [0.3, 0.1, 0.9],
            [-0.31, -0.09, 0.95],
            [3.64581734e-01, 4.20108020e-01, 5.31160653e-01],
            6.20883274e+00,
        ),
        (
            "ggx",
            0.25,
            [0.7, 0.0, 0.4],
            [-0.5, 0.2, 0.6],
            [5.17597385e-02, 9.28186774e-02, 1.74936548e-01],
            4.66449648e-01,
        ),
        (
            "ggx",
            0.25,
            [0.1, 0.6, 0.5],
            [0.2, -0.3, 0.9],
            [3.79794948e-02, 9.13554281e-02, 1.98107302e-01],
            2.73621827e-01,
        ),
        (
            "beckmann",
            0.4,
            [0.9, 0.1, 0.1],
            [0.1, 0.1, 0.9],
            [1.46085992e-02, 4.22391035e-02, 9.75001082e-02],
            9.73492414e-02,
        ),
    ];
}
