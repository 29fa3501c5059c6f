//! `roughconductor`: a rough metal, the microfacet model of Cook and
//! Torrance with Walter et al. 2007's normalisation:
//! `f cos θo = F(⟨wi,m⟩) D(m) G(wi,wo,m) / (4 cos θi)`, `m = (wi+wo)/|wi+wo|`.

use super::conductor::{ConductorIor, ConductorIorValue};
use super::fresnel::reflect;
use super::microfacet::{MicrofacetDistribution, Roughness};
use super::{
    default_albedo, eval_factor, modulate, specular_factor, BsdfContextT, BsdfFlags, BsdfSample,
    BsdfT, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::ParamView;
use crate::scene::description::{LoadContext, Node};
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Rough conductor. Parameters (Mitsuba 3): `distribution` (beckmann |
/// ggx, default beckmann), `alpha` or `alpha_u`/`alpha_v` (default 0.1),
/// `sample_visible` (default true), `material` / `eta` / `k`,
/// `specular_reflectance` (optional, default 1).
#[derive(Clone, Debug)]
pub struct RoughConductor {
    pub roughness: Roughness,
    pub ior: ConductorIor,
    pub specular_reflectance: Option<Texture>,
}

impl RoughConductor {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<RoughConductor> {
        let roughness = Roughness::from_node(node, ctx)?;
        let ior = ConductorIor::from_node(node, ctx)?;
        let specular_reflectance = specular_factor(node, "specular_reflectance", ctx)?;
        Ok(RoughConductor {
            roughness,
            ior,
            specular_reflectance,
        })
    }
}

impl BsdfT for RoughConductor {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::GLOSSY_REFLECTION
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::RoughConductor(RoughConductorContext {
            wi: si.wi,
            distr: self.roughness.distribution(store, si),
            ior: self.ior.eval(store, si),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
        }));
        1
    }
}

/// [`RoughConductor`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct RoughConductorContext<R: ScalarReal> {
    wi: V3<R>,
    distr: MicrofacetDistribution<R>,
    ior: ConductorIorValue<R>,
    specular_reflectance: Option<Spectrum<R>>,
}

impl<R: ScalarReal> BsdfContextT<R> for RoughConductorContext<R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let wi = self.wi;
        if !(wi.z.val() > 0.0 && wo.z.val() > 0.0) {
            return V3::zero();
        }
        let m = (wi + wo).normalize();
        let d = self.distr.eval(m);
        if d.val() == 0.0 {
            return V3::zero();
        }
        let g = self.distr.g(wi, wo, m);
        let f = self.ior.fresnel(wi.dot(m));
        modulate(f * (d * g / (wi.z * 4.0)), self.specular_reflectance)
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let wi = self.wi.val();
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return 0.0;
        }
        let m = (wi + wo).normalize();
        // the micro- and macro-surface must agree on the side (as in eval)
        if !(wi.dot(m) > 0.0 && wo.dot(m) > 0.0) {
            return 0.0;
        }
        self.distr.detach().pdf(wi, m) / (4.0 * wo.dot(m))
    }

    fn sample(&self, _u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let wi = self.wi.val();
        if !(wi.z > 0.0) {
            return None;
        }
        let (m, pdf_m) = self.distr.detach().sample(wi, u2);
        let wo = reflect(V3::from(wi), V3::from(m)).val();
        if !(pdf_m > 0.0 && wo.z > 0.0 && wo.dot(m) > 0.0) {
            return None;
        }
        let pdf = pdf_m / (4.0 * wo.dot(m));
        let wo = V3::cst(wo);
        let f = self.eval(wo);
        Some(BsdfSample {
            wo,
            pdf,
            weight: f.scale(1.0 / pdf),
            eta: 1.0,
            lobe: BsdfFlags::GLOSSY_REFLECTION,
        })
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
    use crate::params::ParamStore;
    use crate::params::Seeds;
    use glam::Vec3;

    #[test]
    fn sampling_matches_pdf() {
        let configs: Vec<Vec<(&str, crate::scene::description::Value)>> = vec![
            vec![("distribution", string("ggx")), ("alpha", float(0.2))],
            vec![("alpha", float(0.3))],
            vec![
                ("distribution", string("ggx")),
                ("alpha_u", float(0.1)),
                ("alpha_v", float(0.4)),
            ],
            vec![("alpha_u", float(0.4)), ("alpha_v", float(0.1))],
            vec![
                ("distribution", string("ggx")),
                ("alpha", float(0.5)),
                ("sample_visible", boolean(false)),
            ],
            vec![("alpha", float(0.3)), ("sample_visible", boolean(false))],
        ];
        let wis = [dir(0.9, 0.3), dir(0.15, 2.0), Vec3::Z];
        for c in &configs {
            let (b, store) = build("roughconductor", c);
            check_smooth(&b, &store, &wis, configs.len());
        }
    }

    /// White furnace: with a perfect mirror Fresnel term the albedo is the
    /// single-scattering energy: ≤ 1, near 1 for low roughness at normal
    /// incidence; the sampling estimate agrees with a quadrature of eval.
    #[test]
    fn energy_is_conserved() {
        for (dist, alpha) in [
            ("ggx", 0.1),
            ("beckmann", 0.1),
            ("ggx", 0.8),
            ("beckmann", 0.8),
        ] {
            let (b, store) = build(
                "roughconductor",
                &[("distribution", string(dist)), ("alpha", float(alpha))],
            );
            for wi in [dir(0.95, 0.0), dir(0.5, 1.0), dir(0.1, 2.0)] {
                let (a, msg) = check_energy(&b, &store, wi, 5, 1.0, &format!("{dist} {alpha}"));
                if alpha < 0.2 && wi.z > 0.9 {
                    assert!(a > 0.95, "{msg}");
                }
            }
        }
    }

    /// Forward-mode derivative of eval with respect to alpha equals the
    /// central finite difference; f32 and Dual primal values are equal.
    #[test]
    fn alpha_derivative_matches_finite_differences() {
        for dist in ["ggx", "beckmann"] {
            let (b, store) = build(
                "roughconductor",
                &[
                    ("distribution", string(dist)),
                    ("alpha", float(0.2)),
                    ("material", string("Cu")),
                ],
            );
            let seeds = Seeds::tangents(&store, &[("b.alpha.value", &[1.0])]).unwrap();
            let wi = dir(0.7, 0.2);
            for wo in [dir(0.6, 3.0), dir(0.8, 3.3), dir(0.3, 2.5)] {
                let d = b
                    .context(&store.view(&seeds), &si::<Dual>(wi))
                    .eval(V3::cst(wo));
                let f = b.context(&store.primal(), &si::<f32>(wi)).eval(V3::cst(wo));
                assert_eq!([d.x.v, d.y.v, d.z.v], [f.x, f.y, f.z], "primal differs");
                let h = 1e-3;
                let mut s2 = store.clone();
                s2.set("b.alpha.value", &[0.2 + h]).unwrap();
                let fp = b.context(&s2.primal(), &si::<f32>(wi)).eval(V3::cst(wo));
                s2.set("b.alpha.value", &[0.2 - h]).unwrap();
                let fm = b.context(&s2.primal(), &si::<f32>(wi)).eval(V3::cst(wo));
                let fd = (fp.y - fm.y) / (2.0 * h);
                assert!(
                    (d.y.d - fd).abs() <= 0.01 * fd.abs() + 1e-3,
                    "{dist} {wo:?}: dual {} fd {fd}",
                    d.y.d
                );
                assert!(d.y.d != 0.0);
            }
        }
    }

    /// Consistent sampling derivatives (docs/architecture.md §1): the derivative of
    /// J(α) = ∫ f(ωi, ωo; α) h(ωo) dωo estimated with detached sampling
    /// (sampled ωo and its pdf are constants, only f is differentiated)
    /// matches the derivative of J by quadrature; the mixed estimator that
    /// differentiates the pdf but keeps the sample fixed does not.
    #[test]
    fn detached_sampling_derivative_is_right_and_mixed_is_wrong() {
        use crate::testing::Pcg32;
        let alpha = 0.3f32;
        let (b, store) = build(
            "roughconductor",
            &[
                ("distribution", string("ggx")),
                ("alpha", float(alpha as f64)),
                ("material", string("Au")),
            ],
        );
        let wi = dir(0.6, 0.4);
        let h = |w: Vec3| 1.0 + w.x + 0.5 * w.y * w.y;
        // reference: central difference of J by midpoint quadrature over the
        // hemisphere in (cos θ, φ)
        let quad = |store: &ParamStore| -> f64 {
            let (nz, nphi) = (600, 600);
            let mut sum = 0.0f64;
            for i in 0..nz {
                let z = (i as f32 + 0.5) / nz as f32;
                for j in 0..nphi {
                    let phi = (j as f32 + 0.5) / nphi as f32 * std::f32::consts::TAU;
                    let w = dir(z, phi);
                    sum += (b
                        .context(&store.primal(), &si::<f32>(wi))
                        .eval(V3::cst(w))
                        .y
                        * h(w)) as f64;
                }
            }
            sum * std::f64::consts::TAU / (nz * nphi) as f64
        };
        let eps = 2e-3;
        let mut s2 = store.clone();
        s2.set("b.alpha.value", &[alpha + eps]).unwrap();
        let jp = quad(&s2);
        s2.set("b.alpha.value", &[alpha - eps]).unwrap();
        let jm = quad(&s2);
        let reference = (jp - jm) / (2.0 * eps as f64);

        let seeds = Seeds::tangents(&store, &[("b.alpha.value", &[1.0])]).unwrap();
        let mut rng = Pcg32::new(11);
        let n = 200_000;
        let (mut det, mut det2, mut mix, mut mix2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let (u1, u2) = (rng.next_f32(), rng.next_2d());
            let Some(bs) = b
                .context(&store.view(&seeds), &si::<Dual>(wi))
                .sample(u1, u2)
            else {
                continue;
            };
            let hw = h(bs.wo.val()) as f64;
            // detached: d(f)/dα / p, with the sample and p constant
            let d = bs.weight.y.d as f64 * hw;
            // mixed: d(f/p)/dα at the fixed sample, pdf differentiated
            let f = (bs.weight.y.v * bs.pdf) as f64;
            let df = bs.weight.y.d as f64 * bs.pdf as f64;
            s2.set("b.alpha.value", &[alpha + eps]).unwrap();
            let pp = b.context(&s2.primal(), &si::<f32>(wi)).pdf(bs.wo.val()) as f64;
            s2.set("b.alpha.value", &[alpha - eps]).unwrap();
            let pm = b.context(&s2.primal(), &si::<f32>(wi)).pdf(bs.wo.val()) as f64;
            let p = bs.pdf as f64;
            let dp = (pp - pm) / (2.0 * eps as f64);
            let m = (df * p - f * dp) / (p * p) * hw;
            det += d;
            det2 += d * d;
            mix += m;
            mix2 += m * m;
        }
        let nf = n as f64;
        let (det, mix) = (det / nf, mix / nf);
        let se_det = ((det2 / nf - det * det) / nf).sqrt();
        let se_mix = ((mix2 / nf - mix * mix) / nf).sqrt();
        eprintln!("dJ/dα: quadrature {reference:.5}, detached {det:.5} ± {se_det:.5}, mixed {mix:.5} ± {se_mix:.5}");
        assert!((det - reference).abs() < 4.0 * se_det + 1e-3 * reference.abs());
        assert!(
            (mix - reference).abs() > 10.0 * se_mix,
            "the mixed estimator should be biased"
        );
    }
}

#[cfg(test)]
mod mitsuba_ref {
    use super::super::test_util::*;
    use glam::Vec3;

    /// Values of Mitsuba 3.9.1 (scalar_rgb) `eval` / `pdf`: the reference
    /// scene's gold (GGX, alpha 0.2, rgb eta/k) and an anisotropic
    /// Beckmann variant (alpha_u 0.1, alpha_v 0.3).
    #[test]
    fn matches_mitsuba_values() {
        for &(dist, wi, wo, f_ref, p_ref) in REF {
            let mut props = vec![
                ("distribution", string(dist)),
                ("eta", rgb(0.143, 0.374, 1.442)),
                ("k", rgb(3.983, 2.385, 1.603)),
            ];
            if dist == "ggx" {
                props.push(("alpha", float(0.2)));
            } else {
                props.push(("alpha_u", float(0.1)));
                props.push(("alpha_v", float(0.3)));
            }
            let (b, store) = build("roughconductor", &props);
            let (wi, wo) = (Vec3::from(wi).normalize(), Vec3::from(wo).normalize());
            let f = eval_f32(&b, &store, wi, wo);
            let p = pdf_f32(&b, &store, wi, wo);
            for c in 0..3 {
                assert!(
                    (f[c] - f_ref[c]).abs() <= 1e-4 * f_ref[c].abs(),
                    "{dist} {wi:?} {wo:?}: {f} vs {f_ref:?}"
                );
            }
            assert!(
                (p - p_ref).abs() <= 1e-4 * p_ref,
                "{dist} pdf {p} vs {p_ref}"
            );
        }
    }

    /// (distribution, wi, wo, eval rgb, pdf) from Mitsuba 3.9.1.
    type RefRow = (&'static str, [f32; 3], [f32; 3], [f32; 3], f32);
    #[allow(clippy::excessive_precision)]
    const REF: &[RefRow] = &[
        (
            "ggx",
            [0.3, 0.1, 0.9],
            [-0.2, -0.1, 0.95],
            [1.7503432e+00, 1.4530849e+00, 5.8703172e-01],
            1.8117048e+00,
        ),
        (
            "ggx",
            [0.5, 0.0, 0.5],
            [-0.6, 0.0, 0.55],
            [2.5983257e+00, 2.1575737e+00, 9.0838647e-01],
            2.7238510e+00,
        ),
        (
            "ggx",
            [0.2, 0.3, 0.8],
            [-0.3, -0.5, 0.7],
            [1.0034994e+00, 8.3290082e-01, 3.3929953e-01],
            1.0456039e+00,
        ),
        (
            "ggx",
            [0.7, 0.1, 0.3],
            [-0.75, -0.1, 0.3],
            [4.3251104e+00, 3.6740952e+00, 1.8710537e+00],
            4.7760901e+00,
        ),
        (
            "ggx",
            [0.0, 0.0, 1.0],
            [0.1, 0.05, 1.0],
            [1.6661249e+00, 1.3832045e+00, 5.5848587e-01],
            1.7237555e+00,
        ),
        (
            "beckmann",
            [0.3, 0.1, 0.9],
            [-0.2, -0.1, 0.95],
            [1.9732205e+00, 1.6381114e+00, 6.6178048e-01],
            2.0412650e+00,
        ),
        (
            "beckmann",
            [0.5, 0.0, 0.5],
            [-0.6, 0.0, 0.55],
            [3.4568264e+00, 2.8704479e+00, 1.2085223e+00],
            3.5816965e+00,
        ),
        (
            "beckmann",
            [0.2, 0.3, 0.8],
            [-0.3, -0.5, 0.7],
            [1.7132238e+00, 1.4219697e+00, 5.7926899e-01],
            1.7728893e+00,
        ),
        (
            "beckmann",
            [0.7, 0.1, 0.3],
            [-0.75, -0.1, 0.3],
            [6.4014039e+00, 5.4378653e+00, 2.7692637e+00],
            6.6686912e+00,
        ),
        (
            "beckmann",
            [0.0, 0.0, 1.0],
            [0.1, 0.05, 1.0],
            [1.9987146e+00, 1.6593180e+00, 6.6997010e-01],
            2.0675910e+00,
        ),
    ];
}
