//! `principledthin`: the thin-surface variant of the principled BSDF as
//! Mitsuba 3 defines it (Burley 2015, "Extending the Disney BRDF to a BSDF
//! with Integrated Subsurface Scattering", §4: thin surfaces). A sheet
//! with no interior: both sides behave alike (the directions are mirrored
//! to the side of `wi`), light leaves on the other side without bending.
//! Lobes:
//!
//! - the diffuse, retro-reflection, fake subsurface and sheen lobes of
//!   `principled`, weighted by (1 − spec_trans)(1 − diff_trans/2);
//! - Lambertian transmission, weighted by (1 − spec_trans) diff_trans/2;
//! - GGX reflection with a dielectric Fresnel term (tinted towards
//!   `base_color` by `spec_tint`) and GGX transmission, the reflection
//!   about a microfacet mirrored to the other side, with roughness scaled
//!   by 0.65 η − 0.35 (Burley 2015, figure 15), tinted by `base_color`;
//!   both weighted by spec_trans.

use super::fresnel::{fresnel_dielectric, reflect};
use super::microfacet::{MicrofacetDistribution, MicrofacetType};
use super::principled::{
    diffuse_lobe, given_nonzero, main_roughness, schlick_f0, schlick_fresnel, sheen_lobe, tint,
};
use super::{smooth_sample, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{warp, Spectrum, V3};
use crate::params::{Domain, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The thin principled BSDF. Parameters (Mitsuba 3): `base_color` (RGB
/// texture, default 0.5), `roughness` (default 0.5), `anisotropic`,
/// `spec_trans`, `spec_tint`, `sheen`, `sheen_tint`, `flatness` (float
/// textures in [0, 1], default 0), `diff_trans` (float texture in [0, 2],
/// default 0), `eta` (float texture, default 1.5),
/// `specular_reflectance_sampling_rate`,
/// `specular_transmittance_sampling_rate`,
/// `diffuse_reflectance_sampling_rate`,
/// `diffuse_transmittance_sampling_rate` (floats, default 1). Every
/// texture is differentiable (`<key>.<name>.value` or the texture's own
/// keys).
#[derive(Clone, Debug)]
pub struct PrincipledThin {
    pub base_color: Texture,
    pub roughness: Texture,
    pub anisotropic: Texture,
    pub spec_trans: Texture,
    pub spec_tint: Texture,
    pub sheen: Texture,
    pub sheen_tint: Texture,
    pub flatness: Texture,
    pub diff_trans: Texture,
    pub eta: Texture,
    /// Whether the file gave a non-zero `spec_trans` / `diff_trans` (the
    /// lobes it declares, as Mitsuba's).
    pub has_spec_trans: bool,
    pub has_diff_trans: bool,
    /// Sampling rates of specular reflection and transmission, diffuse
    /// reflection and transmission.
    pub rates: [f32; 4],
}

impl PrincipledThin {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<PrincipledThin> {
        let mut texture = |name: &str, default: f32, channels: Channels, domain: Domain| {
            Texture::from_prop(node, name, Some(default), channels, domain, ctx)
        };
        let unit = Domain::UnitInterval;
        let base_color = texture("base_color", 0.5, Channels::Rgb, unit)?;
        let roughness = texture("roughness", 0.5, Channels::Mono, unit)?;
        let anisotropic = texture("anisotropic", 0.0, Channels::Mono, unit)?;
        let spec_trans = texture("spec_trans", 0.0, Channels::Mono, unit)?;
        let spec_tint = texture("spec_tint", 0.0, Channels::Mono, unit)?;
        let sheen = texture("sheen", 0.0, Channels::Mono, unit)?;
        let sheen_tint = texture("sheen_tint", 0.0, Channels::Mono, unit)?;
        let flatness = texture("flatness", 0.0, Channels::Mono, unit)?;
        let diff_trans = texture("diff_trans", 0.0, Channels::Mono, Domain::NonNegative)?;
        let eta = texture("eta", 1.5, Channels::Mono, Domain::Positive)?;
        let rate = |name: &str| -> Result<f32> {
            let v = node.float(name, 1.0)?;
            if !(v >= 0.0) {
                let p = node
                    .prop(name)
                    .expect("a rate other than the default was given");
                return Err(node.prop_error(p, format!("must be >= 0, found {v}")));
            }
            Ok(v)
        };
        Ok(PrincipledThin {
            base_color,
            roughness,
            anisotropic,
            spec_trans,
            spec_tint,
            sheen,
            sheen_tint,
            flatness,
            diff_trans,
            eta,
            has_spec_trans: given_nonzero(node, "spec_trans"),
            has_diff_trans: given_nonzero(node, "diff_trans"),
            rates: [
                rate("specular_reflectance_sampling_rate")?,
                rate("specular_transmittance_sampling_rate")?,
                rate("diffuse_reflectance_sampling_rate")?,
                rate("diffuse_transmittance_sampling_rate")?,
            ],
        })
    }
}

impl BsdfT for PrincipledThin {
    fn flags(&self) -> BsdfFlags {
        let mut f = BsdfFlags::DIFFUSE_REFLECTION
            .union(BsdfFlags::GLOSSY_REFLECTION)
            .union(BsdfFlags::TWO_SIDED);
        if self.has_spec_trans {
            f = f.union(BsdfFlags::GLOSSY_TRANSMISSION);
        }
        if self.has_diff_trans {
            f = f.union(BsdfFlags::DIFFUSE_TRANSMISSION);
        }
        f
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let roughness = self.roughness.eval_1(store, si);
        let anisotropic = self.anisotropic.eval_1(store, si);
        let eta = self.eta.eval_1(store, si);
        let (au, av) = main_roughness(roughness, anisotropic);
        // transmission roughness scaled by the index (Burley 2015, fig. 15)
        let (tu, tv) = main_roughness(roughness * (eta * 0.65 - 0.35), anisotropic);
        nodes[0] = Some(NodeContext::PrincipledThin(PrincipledThinContext {
            bsdf: self,
            wi: si.wi,
            eta,
            base_color: self.base_color.eval(store, si),
            roughness,
            reflection: MicrofacetDistribution::new(MicrofacetType::Ggx, au, av, true),
            transmission: MicrofacetDistribution::new(MicrofacetType::Ggx, tu, tv, true),
            spec_trans: self.spec_trans.eval_1(store, si),
            spec_tint: self.spec_tint.eval_1(store, si),
            sheen: self.sheen.eval_1(store, si),
            sheen_tint: self.sheen_tint.eval_1(store, si),
            flatness: self.flatness.eval_1(store, si),
            // Mitsuba's diff_trans runs over [0, 2]: half of it is the
            // transmitted fraction of the diffuse energy
            diff_trans: self.diff_trans.eval_1(store, si) * 0.5,
        }));
        1
    }
}

/// [`PrincipledThin`] at a vertex: every texture evaluated there.
#[derive(Clone, Copy, Debug)]
pub struct PrincipledThinContext<'a, R: ScalarReal> {
    bsdf: &'a PrincipledThin,
    wi: V3<R>,
    eta: R,
    base_color: Spectrum<R>,
    roughness: R,
    reflection: MicrofacetDistribution<R>,
    transmission: MicrofacetDistribution<R>,
    spec_trans: R,
    spec_tint: R,
    sheen: R,
    sheen_tint: R,
    flatness: R,
    diff_trans: R,
}

/// `v` mirrored to the side of +z when `side` is negative (the thin sheet
/// is symmetric: everything is computed as seen from above).
fn to_front<R: ScalarReal>(v: V3<R>, side: f32) -> V3<R> {
    if side < 0.0 {
        -v
    } else {
        v
    }
}

/// The half vector of `wi` (above the sheet) and `wo` mirrored above it,
/// and whether the microfacet is seen from both on the sides the lobe
/// needs (`wo` above for reflection, below for transmission).
fn half_vector(wi: Vec3, wo: Vec3) -> Option<(Vec3, bool)> {
    let wh = (wi + Vec3::new(wo.x, wo.y, wo.z.abs())).normalize();
    if !wh.is_finite() {
        return None;
    }
    let compatible = wi.dot(wh) > 0.0 && (wo.dot(wh) > 0.0) == (wo.z > 0.0);
    Some((wh, compatible))
}

impl<R: ScalarReal> PrincipledThinContext<'_, R> {
    /// Selection probabilities of (specular reflection, specular
    /// transmission, diffuse reflection, diffuse transmission).
    fn lobe_probabilities(&self) -> [f32; 4] {
        let [r_sr, r_st, r_dr, r_dt] = self.bsdf.rates;
        let (s, d) = (self.spec_trans.val(), self.diff_trans.val());
        let p = [
            0.5 * s * r_sr,
            0.5 * s * r_st,
            r_dr * (1.0 - s) * (1.0 - d),
            r_dt * (1.0 - s) * d,
        ];
        let total: f32 = p.iter().sum();
        if !(total > 0.0) {
            return [0.0; 4];
        }
        p.map(|x| x / total)
    }
}

impl<R: ScalarReal> BsdfContextT<R> for PrincipledThinContext<'_, R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let side = self.wi.z.val();
        if side == 0.0 || wo.z.val() == 0.0 {
            return V3::zero();
        }
        let wi = to_front(self.wi, side);
        let wo = to_front(wo, side);
        let Some((_, compatible)) = half_vector(wi.val(), wo.val()) else {
            return V3::zero();
        };
        let reflect = wo.z.val() > 0.0;
        let wh = (wi + V3::new(wo.x, wo.y, wo.z.abs())).normalize();
        let (cos_i, cos_o) = (wi.z, wo.z.abs());
        let one = R::cst(1.0);
        let mut value = V3::zero();
        if self.spec_trans.val() > 0.0 && compatible {
            let cos_ih = wi.dot(wh);
            let f = fresnel_dielectric(cos_ih, self.eta).0;
            if reflect {
                let tinted_f0 = tint(self.base_color) * schlick_f0(self.eta);
                let tinted = schlick_fresnel(tinted_f0, cos_ih, self.eta);
                let fr = V3::splat(f) + (tinted - V3::splat(f)) * self.spec_tint;
                let d = self.reflection.eval(wh);
                let g = self.reflection.g(wi, wo, wh);
                value += fr * (self.spec_trans * d * g / (cos_i * 4.0));
            } else {
                let d = self.transmission.eval(wh);
                let g = self.transmission.g(wi, wo, wh);
                let t = self.spec_trans * (one - f) * d * g / (cos_i * 4.0);
                value += self.base_color * t;
            }
        }
        let diffuse = (one - self.spec_trans) * (one - self.diff_trans);
        if reflect && self.spec_trans.val() < 1.0 && self.diff_trans.val() < 1.0 {
            let cos_d = wh.dot(wo);
            let lobe = diffuse_lobe(self.roughness, self.flatness, cos_i, cos_o, cos_d);
            value += self.base_color * (diffuse * cos_o * lobe * FRAC_1_PI);
            let sheen = sheen_lobe(self.base_color, self.sheen_tint, cos_d);
            value += sheen * (self.sheen * diffuse * cos_o);
        }
        if !reflect && self.spec_trans.val() < 1.0 && self.diff_trans.val() > 0.0 {
            let w = (one - self.spec_trans) * self.diff_trans * cos_o * FRAC_1_PI;
            value += self.base_color * w;
        }
        value
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let side = self.wi.z.val();
        if side == 0.0 || wo.z == 0.0 {
            return 0.0;
        }
        let wi = to_front(self.wi, side).val();
        let wo = to_front(V3::from(wo), side).val();
        let [p_sr, p_st, p_dr, p_dt] = self.lobe_probabilities();
        let reflect = wo.z > 0.0;
        let mut pdf = if reflect {
            p_dr * warp::square_to_cosine_hemisphere_pdf(wo.into())
        } else {
            p_dt * warp::square_to_cosine_hemisphere_pdf((-wo).into())
        };
        if let Some((wh, true)) = half_vector(wi, wo) {
            let jacobian = 1.0 / (4.0 * Vec3::new(wo.x, wo.y, wo.z.abs()).dot(wh)).abs();
            pdf += if reflect {
                p_sr * self.reflection.detach().pdf(wi, wh)
            } else {
                p_st * self.transmission.detach().pdf(wi, wh)
            } * jacobian;
        }
        pdf
    }

    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let side = self.wi.z.val();
        if side == 0.0 {
            return None;
        }
        let wi = to_front(self.wi, side).val();
        let [p_sr, p_st, p_dr, _] = self.lobe_probabilities();
        let mirror = |m: Vec3| reflect(V3::from(wi), V3::from(m)).val();
        let (wo, lobe) = if u1 < p_sr {
            let (m, _) = self.reflection.detach().sample(wi, u2);
            (mirror(m), BsdfFlags::GLOSSY_REFLECTION)
        } else if u1 < p_sr + p_st {
            let (m, _) = self.transmission.detach().sample(wi, u2);
            let wo = mirror(m);
            (Vec3::new(wo.x, wo.y, -wo.z), BsdfFlags::GLOSSY_TRANSMISSION)
        } else if u1 < p_sr + p_st + p_dr {
            (
                Vec3::from(warp::square_to_cosine_hemisphere(u2.into())),
                BsdfFlags::DIFFUSE_REFLECTION,
            )
        } else {
            (
                -Vec3::from(warp::square_to_cosine_hemisphere(u2.into())),
                BsdfFlags::DIFFUSE_TRANSMISSION,
            )
        };
        // a glossy sample must leave on its lobe's side, through a
        // microfacet both directions see (as Mitsuba's sampler checks)
        let glossy = lobe.has(BsdfFlags::GLOSSY_REFLECTION.union(BsdfFlags::GLOSSY_TRANSMISSION));
        if glossy {
            let reflected = lobe == BsdfFlags::GLOSSY_REFLECTION;
            let (_, compatible) = half_vector(wi, wo)?;
            if !compatible || (wo.z > 0.0) != reflected || wo.z == 0.0 {
                return None;
            }
        }
        let wo = if side < 0.0 { -wo } else { wo };
        smooth_sample(self, wo, 1.0, lobe)
    }

    fn albedo(&self) -> Spectrum<R> {
        self.base_color
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::*;
    use crate::ad::Dual;
    use crate::params::Seeds;
    use crate::scene::description::Value;

    /// Case A: every lobe, transmission included; case B: the defaults
    /// but for a base colour and roughness (no transmission).
    fn case(name: &str) -> Vec<(&'static str, Value)> {
        match name {
            "A" => vec![
                ("base_color", rgb(0.8, 0.4, 0.2)),
                ("roughness", float(0.4)),
                ("spec_trans", float(0.5)),
                ("eta", float(1.4)),
                ("spec_tint", float(0.5)),
                ("anisotropic", float(0.5)),
                ("sheen", float(0.7)),
                ("sheen_tint", float(0.4)),
                ("flatness", float(0.3)),
                ("diff_trans", float(0.6)),
            ],
            _ => vec![
                ("base_color", rgb(0.3, 0.6, 0.9)),
                ("roughness", float(0.3)),
            ],
        }
    }

    /// Values of Mitsuba 3.9.1 (scalar_rgb) principledthin `eval` /
    /// `pdf`, from both sides.
    #[test]
    fn matches_mitsuba_values() {
        assert_matches_mitsuba("principledthin", PRINCIPLEDTHIN_REF, case);
    }

    #[test]
    fn sampling_matches_pdf() {
        let cases = [case("A"), case("B")];
        let wis = [dir(0.85, 0.2), dir(0.25, 1.5), dir(-0.7, 0.4)];
        for props in &cases {
            let (b, store) = build("principledthin", props);
            check_smooth(&b, &store, &wis, cases.len());
        }
    }

    /// Forward-mode derivatives of `eval` with respect to every
    /// parameter match central differences of the f32 evaluation.
    #[test]
    fn parameter_derivatives_match_finite_differences() {
        let (b, store) = build("principledthin", &case("A"));
        let pairs = [
            (dir(0.8, 0.3), dir(0.6, 2.5)),
            (dir(0.4, 1.0), dir(0.9, 3.9)),
            (dir(0.7, 0.1), dir(-0.5, 3.0)),
            (dir(-0.6, 0.3), dir(0.8, 2.0)),
            (dir(-0.6, 0.3), dir(-0.8, 3.0)),
        ];
        for key in [
            "base_color",
            "roughness",
            "anisotropic",
            "spec_trans",
            "spec_tint",
            "sheen",
            "sheen_tint",
            "flatness",
            "diff_trans",
            "eta",
        ] {
            let full = format!("b.{key}.value");
            let v0 = store.data(store.id(&full).unwrap()).to_vec();
            let mut tangent = vec![0.0; v0.len()];
            tangent[0] = 1.0;
            let seeds = Seeds::tangents(&store, &[(full.as_str(), &tangent[..])]).unwrap();
            let shifted = |h: f32| {
                let mut s = store.clone();
                let mut v = v0.clone();
                v[0] += h;
                s.set(&full, &v).unwrap();
                s
            };
            let h = 1e-3;
            let (sp, sm) = (shifted(h), shifted(-h));
            for &(wi, wo) in &pairs {
                let d = b
                    .context(&store.view(&seeds), &si::<Dual>(wi))
                    .eval(V3::cst(wo));
                let fd = (eval_f32(&b, &sp, wi, wo) - eval_f32(&b, &sm, wi, wo)) / (2.0 * h);
                let dv = Vec3::new(d.x.d, d.y.d, d.z.d);
                let value = eval_f32(&b, &store, wi, wo);
                assert!(
                    (dv - fd)
                        .abs()
                        .cmple(fd.abs() * 1e-2 + value.abs() * 2e-3 + 1e-5)
                        .all(),
                    "{key} {wi} {wo}: derivative {dv} vs finite difference {fd}"
                );
            }
        }
    }

    /// (case, wi, wo, eval rgb, pdf) from Mitsuba 3.9.1.
    #[allow(clippy::excessive_precision)]
    const PRINCIPLEDTHIN_REF: &[MitsubaRow] = &[
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [-0.21821789023599236, 0.4364357804719847, 0.8728715609439694],
            [7.1874656e-02, 3.6189172e-02, 1.8346431e-02],
            1.1530435e-01,
        ),
        (
            "A",
            [0.9701425001453318, 0.0, 0.24253562503633294],
            [0.10411584125907071, 0.10411584125907071, 0.9891004919611717],
            [8.9393556e-02, 4.5124684e-02, 2.2990245e-02],
            1.3727312e-01,
        ),
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                0.9434563530497265,
            ],
            [1.3733965e-01, 8.0158740e-02, 5.1568285e-02],
            9.2770970e-01,
        ),
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.21566554640687682,
                0.10783277320343841,
                -0.9704949588309457,
            ],
            [1.5882894e-01, 7.9414472e-02, 3.9707236e-02],
            1.2462192e-01,
        ),
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                -0.9434563530497265,
            ],
            [1.3058767e+01, 6.5293837e+00, 3.2646918e+00],
            8.4195557e+00,
        ),
        (
            "A",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [
                -0.12309149097933274,
                0.49236596391733095,
                0.8616404368553291,
            ],
            [3.1659913e-01, 1.5829957e-01, 7.9149783e-02],
            2.2368391e-01,
        ),
        (
            "A",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [-0.3418817293789138, 0.2279211529192759, -0.9116846116771036],
            [1.0873372e-01, 6.0943179e-02, 3.7047908e-02],
            5.6815559e-01,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [-0.21821789023599236, 0.4364357804719847, 0.8728715609439694],
            [8.3353207e-02, 1.6670641e-01, 2.5005960e-01],
            2.7784365e-01,
        ),
        (
            "B",
            [0.9701425001453318, 0.0, 0.24253562503633294],
            [0.10411584125907071, 0.10411584125907071, 0.9891004919611717],
            [9.2150427e-02, 1.8430085e-01, 2.7645126e-01],
            3.1484047e-01,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                0.9434563530497265,
            ],
            [9.0093449e-02, 1.8018690e-01, 2.7028033e-01],
            3.0031148e-01,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.21566554640687682,
                0.10783277320343841,
                -0.9704949588309457,
            ],
            [0.0000000e+00, 0.0000000e+00, 0.0000000e+00],
            0.0000000e+00,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                -0.9434563530497265,
            ],
            [0.0000000e+00, 0.0000000e+00, 0.0000000e+00],
            0.0000000e+00,
        ),
        (
            "B",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [
                -0.12309149097933274,
                0.49236596391733095,
                0.8616404368553291,
            ],
            [0.0000000e+00, 0.0000000e+00, 0.0000000e+00],
            0.0000000e+00,
        ),
        (
            "B",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [-0.3418817293789138, 0.2279211529192759, -0.9116846116771036],
            [8.7059468e-02, 1.7411894e-01, 2.6117840e-01],
            2.9019821e-01,
        ),
    ];
}
