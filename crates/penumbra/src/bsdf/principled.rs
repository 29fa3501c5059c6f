//! `principled`: the Disney principled BSDF as Mitsuba 3 defines it (Burley
//! 2012, "Physically Based Shading at Disney"; Burley 2015, "Extending the
//! Disney BRDF to a BSDF with Integrated Subsurface Scattering"), without
//! subsurface scattering. Lobes:
//!
//! - a diffuse lobe with Burley's retro-reflection, blended towards the
//!   Hanrahan-Krueger-like "fake subsurface" lobe by `flatness`, and a
//!   sheen lobe (Schlick weight of the half angle), weighted by
//!   (1 − metallic)(1 − spec_trans);
//! - the main specular lobe: GGX microfacet reflection (anisotropic through
//!   `anisotropic`) whose Fresnel term blends the exact dielectric
//!   reflectance, Schlick's approximation tinted towards `base_color`
//!   (`spec_tint`) and the metallic Schlick reflectance of `base_color`;
//! - rough dielectric transmission (Walter et al. 2007, "Microfacet Models
//!   for Refraction through Rough Surfaces", eq. 21) tinted by
//!   √base_color, weighted by (1 − metallic) spec_trans;
//! - a clearcoat: GTR1 ("generalised Trowbridge-Reitz", γ = 1) normals,
//!   Schlick Fresnel with F0 = 0.04 and the GGX masking of roughness 0.25,
//!   weighted by clearcoat / 4, written as Mitsuba writes it (f·cos =
//!   clearcoat/4 · F D G |cos θo|).
//!
//! Values, lobe selection probabilities and the front/back-side rules
//! follow Mitsuba 3's `principled` plugin, so that its scenes render the
//! same; Mitsuba's `has_*` shortcuts for absent parameters are not needed
//! (an absent weight is a zero texture, whose lobe then adds nothing).

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet::{MicrofacetDistribution, MicrofacetType};
use super::{smooth_sample, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NodeContext};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{warp, Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamView};
use crate::scene::description::{LoadContext, Node, Value};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// How the index of refraction was given: Mitsuba accepts either `eta`
/// or `specular` (the normal-incidence reflectance ×12.5 of Burley's
/// parameterisation), never both, and exposes the one given.
#[derive(Clone, Copy, Debug)]
pub enum Ior {
    /// Parameter `<key>.eta`: the relative index of refraction.
    Eta(ParamId),
    /// Parameter `<key>.specular`: η = 2 / (1 − √(0.08 specular)) − 1.
    Specular(ParamId),
}

/// The principled BSDF. Parameters (Mitsuba 3, all but `eta` and the
/// sampling rates in [0, 1]): `base_color` (RGB texture, default 0.5),
/// `roughness` (default 0.5), `anisotropic`, `metallic`, `spec_trans`,
/// `spec_tint`, `sheen`, `sheen_tint`, `flatness`, `clearcoat`,
/// `clearcoat_gloss` (float textures, default 0), `eta` or `specular`
/// (float, default specular 0.5), `main_specular_sampling_rate`,
/// `clearcoat_sampling_rate`, `diffuse_reflectance_sampling_rate`
/// (floats, default 1). Every texture is differentiable
/// (`<key>.<name>.value` or the texture's own keys), and so is `eta` or
/// `specular`.
#[derive(Clone, Debug)]
pub struct Principled {
    pub base_color: Texture,
    pub roughness: Texture,
    pub anisotropic: Texture,
    pub metallic: Texture,
    pub spec_trans: Texture,
    pub spec_tint: Texture,
    pub sheen: Texture,
    pub sheen_tint: Texture,
    pub flatness: Texture,
    pub clearcoat: Texture,
    pub clearcoat_gloss: Texture,
    pub ior: Ior,
    /// Whether the file gave a non-zero `spec_trans`: then η = 1 (or
    /// specular 0) is replaced as in Mitsuba by 1.001 (1e-3), as a
    /// transmitting interface of index 1 has no refraction to sample.
    pub has_spec_trans: bool,
    pub main_specular_sampling_rate: f32,
    pub clearcoat_sampling_rate: f32,
    pub diffuse_reflectance_sampling_rate: f32,
}

/// Whether parameter `name` is given and not the float 0 (Mitsuba's test
/// for the lobes a principled BSDF has).
pub(super) fn given_nonzero(node: &Node, name: &str) -> bool {
    node.props
        .iter()
        .find(|p| p.name == name)
        .is_some_and(|p| !matches!(p.value, Value::Float(v) if v == 0.0))
}

impl Principled {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Principled> {
        let mut texture = |name: &str, default: f32, channels: Channels| {
            Texture::from_prop(
                node,
                name,
                Some(default),
                channels,
                Domain::UnitInterval,
                ctx,
            )
        };
        let base_color = texture("base_color", 0.5, Channels::Rgb)?;
        let roughness = texture("roughness", 0.5, Channels::Mono)?;
        let anisotropic = texture("anisotropic", 0.0, Channels::Mono)?;
        let metallic = texture("metallic", 0.0, Channels::Mono)?;
        let spec_trans = texture("spec_trans", 0.0, Channels::Mono)?;
        let spec_tint = texture("spec_tint", 0.0, Channels::Mono)?;
        let sheen = texture("sheen", 0.0, Channels::Mono)?;
        let sheen_tint = texture("sheen_tint", 0.0, Channels::Mono)?;
        let flatness = texture("flatness", 0.0, Channels::Mono)?;
        let clearcoat = texture("clearcoat", 0.0, Channels::Mono)?;
        let clearcoat_gloss = texture("clearcoat_gloss", 0.0, Channels::Mono)?;
        let ior = Self::ior_from_node(node, ctx)?;
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
        Ok(Principled {
            base_color,
            roughness,
            anisotropic,
            metallic,
            spec_trans,
            spec_tint,
            sheen,
            sheen_tint,
            flatness,
            clearcoat,
            clearcoat_gloss,
            ior,
            has_spec_trans: given_nonzero(node, "spec_trans"),
            main_specular_sampling_rate: rate("main_specular_sampling_rate")?,
            clearcoat_sampling_rate: rate("clearcoat_sampling_rate")?,
            diffuse_reflectance_sampling_rate: rate("diffuse_reflectance_sampling_rate")?,
        })
    }

    /// `eta` or `specular` (not both), registered under its own name.
    fn ior_from_node(node: &Node, ctx: &mut LoadContext) -> Result<Ior> {
        if node.has("eta") && node.has("specular") {
            return Err(node.error(
                "give either 'eta' or 'specular' (they set the same index of refraction), not both",
            ));
        }
        let key = |name: &str| format!("{}.{}", node.key, name);
        if node.has("eta") {
            let eta = node.float_checked("eta", 1.0, true)?;
            let id = ctx.store.add(
                key("eta"),
                vec![eta],
                vec![1],
                ParamFlags::DIFFERENTIABLE,
                Domain::Positive,
            )?;
            return Ok(Ior::Eta(id));
        }
        let specular = node.float("specular", 0.5)?;
        // η = 2 / (1 − √(0.08 s)) − 1 is finite and ≥ 1 for s in [0, 12.5)
        if !(0.0..12.5).contains(&specular) {
            let p = node.prop("specular").expect("an invalid value was given");
            return Err(node.prop_error(
                p,
                format!("must be in [0, 12.5) (Schlick's F0 × 12.5), found {specular}"),
            ));
        }
        let id = ctx.store.add(
            key("specular"),
            vec![specular],
            vec![1],
            ParamFlags::DIFFERENTIABLE,
            Domain::NonNegative,
        )?;
        Ok(Ior::Specular(id))
    }

    /// The relative index of refraction, in `R`.
    fn eta<R: ScalarReal>(&self, store: &ParamView) -> R {
        match self.ior {
            Ior::Eta(id) => {
                let eta = store.read::<R>(id, 0);
                if self.has_spec_trans && eta.val() == 1.0 {
                    R::cst(1.001)
                } else {
                    eta
                }
            }
            Ior::Specular(id) => {
                let s = store.read::<R>(id, 0);
                let s = if self.has_spec_trans && s.val() == 0.0 {
                    R::cst(1e-3)
                } else {
                    s
                };
                (-(s * 0.08).sqrt() + 1.0).recip() * 2.0 - 1.0
            }
        }
    }
}

impl BsdfT for Principled {
    fn flags(&self) -> BsdfFlags {
        let f = BsdfFlags::DIFFUSE_REFLECTION.union(BsdfFlags::GLOSSY_REFLECTION);
        if self.has_spec_trans {
            f.union(BsdfFlags::GLOSSY_TRANSMISSION)
        } else {
            f
        }
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let roughness = self.roughness.eval_1(store, si);
        let anisotropic = self.anisotropic.eval_1(store, si);
        let (alpha_u, alpha_v) = main_roughness(roughness, anisotropic);
        let gloss = self.clearcoat_gloss.eval_1(store, si);
        nodes[0] = Some(NodeContext::Principled(PrincipledContext {
            bsdf: self,
            wi: si.wi,
            eta: self.eta(store),
            base_color: self.base_color.eval(store, si),
            roughness,
            distr: MicrofacetDistribution::new(MicrofacetType::Ggx, alpha_u, alpha_v, true),
            metallic: self.metallic.eval_1(store, si),
            spec_trans: self.spec_trans.eval_1(store, si),
            spec_tint: self.spec_tint.eval_1(store, si),
            sheen: self.sheen.eval_1(store, si),
            sheen_tint: self.sheen_tint.eval_1(store, si),
            flatness: self.flatness.eval_1(store, si),
            clearcoat: self.clearcoat.eval_1(store, si),
            // glossiness 0..1 maps to GTR1 roughness 0.1..0.001 (Burley 2012)
            clearcoat_alpha: gloss * -0.099 + 0.1,
        }));
        1
    }
}

/// GGX roughness (αu, αv) of the main lobe from Burley 2012's
/// parameters: α = roughness², stretched by aspect = √(1 − 0.9
/// anisotropic), at least 0.001.
pub(super) fn main_roughness<R: ScalarReal>(roughness: R, anisotropic: R) -> (R, R) {
    let a = roughness * roughness;
    let aspect = (-(anisotropic * 0.9) + 1.0).sqrt();
    let floor = R::cst(1e-3);
    ((a / aspect).max(floor), (a * aspect).max(floor))
}

/// Schlick's weight (1 − cos)⁵, with cos clamped to [0, 1].
fn schlick_weight<R: ScalarReal>(cos: R) -> R {
    let m = (-cos + 1.0).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Schlick's approximation F0 + (1 − F0) w of the reflectance of an
/// interface of relative index `eta` at the microfacet cosine `cos_i`
/// (Schlick 1994); where the light comes from the denser side, w uses the
/// cosine of the refracted direction (0 under total internal reflection).
pub(super) fn schlick_fresnel<R: ScalarReal>(f0: Spectrum<R>, cos_i: R, eta: R) -> Spectrum<R> {
    let eta_it = if cos_i.val() >= 0.0 { eta } else { eta.recip() };
    let w = if eta_it.val() > 1.0 {
        schlick_weight(cos_i.abs())
    } else {
        let eta_ti = eta_it.recip();
        let cos_t = (-(-(cos_i * cos_i) + 1.0) * (eta_ti * eta_ti) + 1.0).safe_sqrt();
        schlick_weight(cos_t)
    };
    f0.map(|f| f + (-f + 1.0) * w)
}

/// Schlick's normal-incidence reflectance ((η − 1) / (η + 1))².
pub(super) fn schlick_f0<R: ScalarReal>(eta: R) -> R {
    ((eta - 1.0) / (eta + 1.0)).sqr()
}

/// `base_color / luminance` (its hue at unit luminance), white for black.
pub(super) fn tint<R: ScalarReal>(base_color: Spectrum<R>) -> Spectrum<R> {
    let lum = base_color.luminance();
    if lum.val() > 0.0 {
        base_color / lum
    } else {
        V3::splat(R::cst(1.0))
    }
}

/// Burley 2012's GTR1 microfacet distribution (γ = 1) of the clearcoat:
/// D(m) = (α² − 1) / (π ln α² (1 + (α² − 1) cos² θm)), sampled by
/// inverting its cos θm marginal.
#[derive(Clone, Copy, Debug)]
struct Gtr1<R> {
    alpha: R,
}

impl<R: ScalarReal> Gtr1<R> {
    fn eval(&self, m: V3<R>) -> R {
        let a2 = self.alpha * self.alpha;
        let d = (a2 - 1.0) / ((a2 - 1.0) * (m.z * m.z) + 1.0) / (a2.ln() * PI);
        // negligible densities are zero, as in Mitsuba
        if (d.val() * m.z.val()) > 1e-20 {
            d
        } else {
            R::cst(0.0)
        }
    }
}

impl Gtr1<f32> {
    /// Density of [`sample`](Self::sample), per solid angle of normals.
    fn pdf(&self, m: Vec3) -> f32 {
        if m.z < 0.0 {
            0.0
        } else {
            m.z * self.eval(V3::from(m))
        }
    }

    fn sample(&self, u: Vec2) -> Vec3 {
        let a2 = self.alpha * self.alpha;
        let cos2 = (1.0 - a2.powf(1.0 - u.y)) / (1.0 - a2);
        let sin = (1.0 - cos2).max(0.0).sqrt();
        let (s, c) = warp::sin_cos_turns(u.x);
        Vec3::new(c * sin, s * sin, cos2.max(0.0).sqrt())
    }
}

/// `wi` mirrored to the upper hemisphere: the main lobe's microfacets
/// are sampled and their density evaluated as seen from outside.
fn upper(wi: Vec3) -> Vec3 {
    if wi.z < 0.0 {
        -wi
    } else {
        wi
    }
}

/// [`Principled`] at a vertex: every texture evaluated there.
#[derive(Clone, Copy, Debug)]
pub struct PrincipledContext<'a, R: ScalarReal> {
    bsdf: &'a Principled,
    wi: V3<R>,
    eta: R,
    base_color: Spectrum<R>,
    roughness: R,
    distr: MicrofacetDistribution<R>,
    metallic: R,
    spec_trans: R,
    spec_tint: R,
    sheen: R,
    sheen_tint: R,
    flatness: R,
    clearcoat: R,
    clearcoat_alpha: R,
}

/// The half vector of (wi, wo) and what the lobes need about the pair.
struct HalfVector {
    /// Generalised half vector (Walter et al. 2007), oriented to +z.
    wh: Vec3,
    reflect: bool,
    /// |dωh / dωo|: the Jacobian from half vectors to outgoing directions.
    jacobian: f32,
    /// The microfacet is seen from both `wi` and `wo` on the sides a
    /// reflection (resp. a refraction) needs.
    compatible: bool,
}

impl<R: ScalarReal> PrincipledContext<'_, R> {
    /// (brdf, bsdf): the weights (1 − metallic)(1 − spec_trans) of the
    /// diffuse and sheen lobes and (1 − metallic) spec_trans of the
    /// transmission.
    fn lobe_weights(&self) -> (R, R) {
        let dielectric = -self.metallic + 1.0;
        (
            dielectric * (-self.spec_trans + 1.0),
            dielectric * self.spec_trans,
        )
    }

    /// The selection probabilities of (diffuse, clearcoat, transmission,
    /// reflection) for incident `wi` and the dielectric Fresnel
    /// reflectance `f` at the microfacet (Mitsuba's sampling rates: below
    /// the surface only reflection and transmission, split by `f`).
    fn lobe_probabilities(&self, wi: Vec3, f: f32) -> [f32; 4] {
        let b = self.bsdf;
        let (brdf, bsdf) = self.lobe_weights();
        let (brdf, bsdf) = (brdf.val(), bsdf.val());
        let p = if wi.z > 0.0 {
            let rate = b.main_specular_sampling_rate;
            [
                brdf * b.diffuse_reflectance_sampling_rate,
                0.25 * self.clearcoat.val() * b.clearcoat_sampling_rate,
                rate * bsdf * (1.0 - f),
                rate * (1.0 - bsdf * (1.0 - f)),
            ]
        } else {
            let trans = if b.has_spec_trans { 1.0 - f } else { 0.0 };
            [0.0, 0.0, trans, f]
        };
        let total: f32 = p.iter().sum();
        if !(total > 0.0) {
            return [0.0; 4];
        }
        p.map(|x| x / total)
    }

    /// The half vector of `wi`, `wo` (primal); `None` at grazing angles.
    fn half_vector(&self, wo: Vec3) -> Option<HalfVector> {
        let wi = self.wi.val();
        if wi.z == 0.0 || wo.z == 0.0 {
            return None;
        }
        let reflect = wi.z * wo.z > 0.0;
        let eta = self.eta.val();
        let eta_path = if wi.z > 0.0 { eta } else { 1.0 / eta };
        let wh = (wi + wo * if reflect { 1.0 } else { eta_path }).normalize();
        if !wh.is_finite() {
            return None;
        }
        let wh = if wh.z < 0.0 { -wh } else { wh };
        let (i_h, o_h) = (wi.dot(wh), wo.dot(wh));
        let jacobian = if reflect {
            1.0 / (4.0 * o_h).abs()
        } else {
            (eta_path * eta_path * o_h / (i_h + eta_path * o_h).powi(2)).abs()
        };
        let m = wh * wi.z.signum();
        let compatible = wi.dot(m) > 0.0
            && if reflect {
                wo.dot(m) > 0.0
            } else {
                wo.dot(m) < 0.0
            };
        Some(HalfVector {
            wh,
            reflect,
            jacobian,
            compatible,
        })
    }

    /// Mitsuba's principled Fresnel term of the main reflection: on the
    /// front side the dielectric reflectance `f` for the untinted
    /// dielectric part, Schlick's of the tinted F0 for the `spec_tint`
    /// part and of `base_color` for the metallic part; on the back side
    /// `bsdf · f`.
    fn reflection_fresnel(&self, f: R, cos_ih: R, front: bool, bsdf: R) -> Spectrum<R> {
        if !front {
            return V3::splat(bsdf * f);
        }
        let (metallic, spec_tint) = (self.metallic, self.spec_tint);
        let eta_it = if cos_ih.val() >= 0.0 {
            self.eta
        } else {
            self.eta.recip()
        };
        let tinted_f0 = tint(self.base_color) * schlick_f0(eta_it);
        let metal = schlick_fresnel(self.base_color, cos_ih, self.eta) * metallic;
        let tinted = schlick_fresnel(tinted_f0, cos_ih, self.eta) * ((-metallic + 1.0) * spec_tint);
        let dielectric = f * (-metallic + 1.0) * (-spec_tint + 1.0);
        metal + tinted + V3::splat(dielectric)
    }

    /// Diffuse, retro-reflection, fake subsurface and sheen (front side,
    /// reflection), times |cos θo|.
    fn diffuse_and_sheen(&self, wo: V3<R>, wh: V3<R>, brdf: R) -> Spectrum<R> {
        let (cos_i, cos_o) = (self.wi.z.abs(), wo.z.abs());
        let cos_d = wh.dot(wo);
        let lobe = diffuse_lobe(self.roughness, self.flatness, cos_i, cos_o, cos_d);
        let diffuse = self.base_color * (brdf * cos_o * lobe * FRAC_1_PI);
        let sheen = sheen_lobe(self.base_color, self.sheen_tint, cos_d);
        diffuse + sheen * (self.sheen * (-self.metallic + 1.0) * cos_o)
    }
}

/// Burley 2012's diffuse lobe with retro-reflection, blended by
/// `flatness` towards his Hanrahan-Krueger-like subsurface approximation,
/// without the albedo / π and the cosine: a function of the cosines of
/// `wi`, `wo` (to the normal, positive) and of the half angle `cos_d`.
pub(super) fn diffuse_lobe<R: ScalarReal>(
    roughness: R,
    flatness: R,
    cos_i: R,
    cos_o: R,
    cos_d: R,
) -> R {
    let (f_i, f_o) = (schlick_weight(cos_i), schlick_weight(cos_o));
    let f_diff = (-(f_i * 0.5) + 1.0) * (-(f_o * 0.5) + 1.0);
    let rr = roughness * cos_d * cos_d * 2.0;
    let f_retro = rr * (f_o + f_i + f_o * f_i * (rr - 1.0));
    let f_ss90 = rr * 0.5;
    let f_ss = ((f_ss90 - 1.0) * f_o + 1.0) * ((f_ss90 - 1.0) * f_i + 1.0);
    let f_ss = (f_ss * ((cos_o + cos_i).recip() - 0.5) + 0.5) * 1.25;
    let lobe = f_diff + f_retro;
    lobe + (f_ss - lobe) * flatness
}

/// Burley 2012's sheen, without its weight and cosine: the Schlick
/// weight of the half angle, tinted towards the hue of `base_color` by
/// `sheen_tint`.
pub(super) fn sheen_lobe<R: ScalarReal>(
    base_color: Spectrum<R>,
    sheen_tint: R,
    cos_d: R,
) -> Spectrum<R> {
    let white = V3::splat(R::cst(1.0));
    let color = white + (tint(base_color) - white) * sheen_tint;
    color * schlick_weight(cos_d.abs())
}

impl<R: ScalarReal> BsdfContextT<R> for PrincipledContext<'_, R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let Some(h) = self.half_vector(wo.val()) else {
            return V3::zero();
        };
        let wi = self.wi;
        let front = wi.z.val() > 0.0;
        let (brdf, bsdf) = self.lobe_weights();
        // the half vector in R, so that eval is differentiable in wi and wo
        let e = if h.reflect {
            R::cst(1.0)
        } else if front {
            self.eta
        } else {
            self.eta.recip()
        };
        let wh = (wi + wo * e).normalize();
        let wh = if wh.z.val() < 0.0 { -wh } else { wh };
        let cos_ih = wi.dot(wh);
        let f = fresnel_dielectric(cos_ih, self.eta).0;
        let d = self.distr.eval(wh);
        let g = self.distr.g(wi, wo, wh);
        let mut value = V3::zero();
        if h.reflect && h.compatible {
            if f.val() > 0.0 {
                let fr = self.reflection_fresnel(f, cos_ih, front, bsdf);
                value += fr * (d * g / (wi.z.abs() * 4.0));
            }
            if front && self.clearcoat.val() > 0.0 {
                let f_cc = schlick_fresnel(V3::splat(R::cst(0.04)), cos_ih, self.eta).x;
                let d_cc = Gtr1 {
                    alpha: self.clearcoat_alpha,
                }
                .eval(wh);
                // Smith masking of GGX with α = 0.25 (Burley 2012)
                let coat_alpha = R::cst(0.25);
                let g_cc =
                    MicrofacetDistribution::new(MicrofacetType::Ggx, coat_alpha, coat_alpha, true)
                        .g(wi, wo, wh);
                value += V3::splat(self.clearcoat * 0.25 * f_cc * d_cc * g_cc * wo.z.abs());
            }
        }
        if !h.reflect && h.compatible && bsdf.val() > 0.0 && f.val() < 1.0 {
            // Walter et al. 2007, eq. 21, radiance transport (the 1/η²
            // of radiance cancels the η² of the Jacobian)
            let cos_oh = wo.dot(wh);
            let denom = cos_ih + cos_oh * e;
            let t = (-f + 1.0) * d * g * cos_ih * cos_oh / (wi.z * denom * denom);
            value += self.base_color.map(|c| c.sqrt()) * (bsdf * t.abs());
        }
        if h.reflect && front && brdf.val() > 0.0 {
            value += self.diffuse_and_sheen(wo, wh, brdf);
        }
        value
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let Some(h) = self.half_vector(wo) else {
            return 0.0;
        };
        let wi = self.wi.val();
        let f = fresnel_dielectric(wi.dot(h.wh), self.eta.val()).0;
        let [p_diffuse, p_clearcoat, p_trans, p_reflect] = self.lobe_probabilities(wi, f);
        let mut pdf = 0.0;
        if h.reflect {
            pdf += p_diffuse * warp::square_to_cosine_hemisphere_pdf(wo.into());
        }
        if h.compatible {
            let distr = self.distr.detach();
            let p_normal = distr.pdf(upper(wi), h.wh);
            if h.reflect {
                let p_coat = Gtr1 {
                    alpha: self.clearcoat_alpha.val(),
                }
                .pdf(h.wh);
                pdf += (p_reflect * p_normal + p_clearcoat * p_coat) * h.jacobian;
            } else {
                pdf += p_trans * p_normal * h.jacobian;
            }
        }
        pdf
    }

    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        let wi = self.wi.val();
        let (_, bsdf) = self.lobe_weights();
        if wi.z == 0.0 || !(wi.z > 0.0 || bsdf.val() > 0.0) {
            return None;
        }
        let (m, _) = self.distr.detach().sample(upper(wi), u2);
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), self.eta.val());
        let [p_diffuse, p_clearcoat, p_trans, _] = self.lobe_probabilities(wi, f);
        let (wo, eta, lobe) = if u1 < p_diffuse {
            let wo = Vec3::from(warp::square_to_cosine_hemisphere(u2.into()));
            (wo, 1.0, BsdfFlags::DIFFUSE_REFLECTION)
        } else if u1 < p_diffuse + p_clearcoat {
            let m = Gtr1 {
                alpha: self.clearcoat_alpha.val(),
            }
            .sample(u2);
            (reflect_f32(wi, m), 1.0, BsdfFlags::GLOSSY_REFLECTION)
        } else if u1 < p_diffuse + p_clearcoat + p_trans {
            let wo = refract(V3::from(wi), V3::from(m), cos_t, eta_ti).val();
            (wo, eta_it, BsdfFlags::GLOSSY_TRANSMISSION)
        } else {
            (reflect_f32(wi, m), 1.0, BsdfFlags::GLOSSY_REFLECTION)
        };
        // a glossy sample must leave on the side of its lobe, through a
        // microfacet that both directions see (as Mitsuba's sampler checks)
        let h = self.half_vector(wo)?;
        let transmitted = lobe == BsdfFlags::GLOSSY_TRANSMISSION;
        if h.reflect == transmitted || (lobe != BsdfFlags::DIFFUSE_REFLECTION && !h.compatible) {
            return None;
        }
        smooth_sample(self, wo, eta, lobe)
    }

    fn albedo(&self) -> Spectrum<R> {
        self.base_color
    }
}

/// Mirror reflection of `wi` about `m`, primal.
fn reflect_f32(wi: Vec3, m: Vec3) -> Vec3 {
    reflect(V3::from(wi), V3::from(m)).val()
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::Bsdf;
    use super::*;
    use crate::ad::Dual;
    use crate::params::Seeds;
    use crate::scene::description::Value;

    /// Case A: every reflection lobe (metallic, tinted specular,
    /// anisotropy, sheen, clearcoat, flatness); case B: transmission.
    fn case(name: &str) -> Vec<(&'static str, Value)> {
        match name {
            "A" => vec![
                ("base_color", rgb(0.8, 0.4, 0.2)),
                ("roughness", float(0.4)),
                ("metallic", float(0.3)),
                ("specular", float(0.6)),
                ("spec_tint", float(0.5)),
                ("anisotropic", float(0.5)),
                ("sheen", float(0.7)),
                ("sheen_tint", float(0.4)),
                ("clearcoat", float(0.6)),
                ("clearcoat_gloss", float(0.3)),
                ("flatness", float(0.3)),
            ],
            _ => vec![
                ("base_color", rgb(0.3, 0.6, 0.9)),
                ("roughness", float(0.3)),
                ("spec_trans", float(0.7)),
                ("eta", float(1.45)),
            ],
        }
    }

    /// Values of Mitsuba 3.9.1 (scalar_rgb) principled `eval` / `pdf`:
    /// reflection and transmission from both sides.
    #[test]
    fn matches_mitsuba_values() {
        assert_matches_mitsuba("principled", PRINCIPLED_REF, case);
    }

    /// χ² tests of sampling against `pdf` from both sides. Without
    /// transmission, below the surface, Mitsuba's `pdf` is that of the
    /// main reflection lobe, whose value is zero there and which `sample`
    /// never draws (kept for equal values, see `matches_mitsuba_values`):
    /// that case is tested from above only.
    #[test]
    fn sampling_matches_pdf() {
        let coated = vec![
            ("roughness", float(0.2)),
            ("clearcoat", float(1.0)),
            ("clearcoat_gloss", float(0.5)),
            ("clearcoat_sampling_rate", float(2.0)),
            ("spec_trans", float(0.3)),
            ("specular", float(0.3)),
        ];
        let cases = [(case("A"), false), (case("B"), true), (coated, true)];
        let above = [dir(0.85, 0.2), dir(0.25, 1.5)];
        let both = [dir(0.85, 0.2), dir(0.25, 1.5), dir(-0.7, 0.4)];
        for (props, transmits) in &cases {
            let (b, store) = build("principled", props);
            let wis: &[Vec3] = if *transmits { &both } else { &above };
            check_smooth(&b, &store, wis, cases.len());
        }
    }

    /// Forward-mode derivatives of `eval` with respect to every
    /// parameter match central differences of the f32 evaluation.
    #[test]
    fn parameter_derivatives_match_finite_differences() {
        let keys = [
            "base_color",
            "roughness",
            "metallic",
            "specular",
            "spec_tint",
            "anisotropic",
            "sheen",
            "sheen_tint",
            "clearcoat",
            "clearcoat_gloss",
            "flatness",
        ];
        let pairs = [
            (dir(0.8, 0.3), dir(0.6, 2.5)),
            (dir(0.4, 1.0), dir(0.9, 3.9)),
            (dir(0.7, 0.1), dir(-0.5, 3.0)),
            (dir(-0.6, 0.3), dir(0.8, 2.0)),
        ];
        let mut with_trans = case("A");
        with_trans.push(("spec_trans", float(0.4)));
        for (name, props, keys) in [
            ("A", case("A"), &keys[..]),
            (
                "trans",
                with_trans,
                &["spec_trans", "base_color", "specular"][..],
            ),
            ("B", case("B"), &["eta", "roughness", "spec_trans"][..]),
        ] {
            let (b, store) = build("principled", &props);
            for key in keys {
                let full = if *key == "specular" || *key == "eta" {
                    format!("b.{key}")
                } else {
                    format!("b.{key}.value")
                };
                let v0 = store.data(store.id(&full).unwrap()).to_vec();
                // the first element along the tangent
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
                    let fp = eval_f32(&b, &sp, wi, wo);
                    let fm = eval_f32(&b, &sm, wi, wo);
                    let fd = (fp - fm) / (2.0 * h);
                    let dv = Vec3::new(d.x.d, d.y.d, d.z.d);
                    let value = eval_f32(&b, &store, wi, wo);
                    assert!(
                        (dv - fd)
                            .abs()
                            .cmple(fd.abs() * 1e-2 + value.abs() * 2e-3 + 1e-5)
                            .all(),
                        "{name} {key} {wi} {wo}: derivative {dv} vs finite difference {fd}"
                    );
                }
            }
        }
    }

    #[test]
    fn eta_and_specular_together_are_an_error() {
        let n = node_with_key(
            "principled",
            "b",
            &[("eta", float(1.5)), ("specular", float(0.5))],
        );
        let e = Bsdf::from_node(&n, &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("either 'eta' or 'specular'"), "{e}");
        let n = node_with_key("principled", "b", &[("specular", float(13.0))]);
        let e = Bsdf::from_node(&n, &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("'specular'") && e.contains("[0, 12.5)"), "{e}");
    }

    /// (case, wi, wo, eval rgb, pdf) from Mitsuba 3.9.1.
    #[allow(clippy::excessive_precision)]
    const PRINCIPLED_REF: &[MitsubaRow] = &[
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [-0.21821789023599236, 0.4364357804719847, 0.8728715609439694],
            [1.6513264e-01, 8.4928781e-02, 4.4826850e-02],
            1.5796551e-01,
        ),
        (
            "A",
            [0.9701425001453318, 0.0, 0.24253562503633294],
            [0.10411584125907071, 0.10411584125907071, 0.9891004919611717],
            [2.0628613e-01, 1.0448731e-01, 5.3587899e-02],
            1.8021841e-01,
        ),
        (
            "A",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                0.9434563530497265,
            ],
            [1.1571852e+00, 6.4037114e-01, 3.8196424e-01],
            2.1515448e+00,
        ),
        (
            "A",
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
            "A",
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
            "A",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [-0.3418817293789138, 0.2279211529192759, -0.9116846116771036],
            [0.0000000e+00, 0.0000000e+00, 0.0000000e+00],
            1.8663448e+00,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [-0.21821789023599236, 0.4364357804719847, 0.8728715609439694],
            [2.7780045e-02, 5.2786008e-02, 7.7791959e-02],
            8.4503658e-02,
        ),
        (
            "B",
            [0.9701425001453318, 0.0, 0.24253562503633294],
            [0.10411584125907071, 0.10411584125907071, 0.9891004919611717],
            [2.8134385e-02, 5.5779513e-02, 8.3424643e-02],
            7.6005176e-02,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.3144854510165755,
                -0.10482848367219183,
                0.9434563530497265,
            ],
            [3.8037357e-01, 4.0740162e-01, 4.3442965e-01],
            2.6620541e+00,
        ),
        (
            "B",
            [0.3144854510165755, 0.10482848367219183, 0.9434563530497265],
            [
                -0.21566554640687682,
                0.10783277320343841,
                -0.9704949588309457,
            ],
            [4.0254135e-02, 5.6927942e-02, 6.9722205e-02],
            1.1887673e-01,
        ),
        (
            "B",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [
                -0.12309149097933274,
                0.49236596391733095,
                0.8616404368553291,
            ],
            [2.1757838e-01, 3.0770230e-01, 3.7685680e-01],
            2.7010077e-01,
        ),
        (
            "B",
            [0.2279211529192759, -0.3418817293789138, -0.9116846116771036],
            [-0.3418817293789138, 0.2279211529192759, -0.9116846116771036],
            [7.3126920e-02, 7.3126920e-02, 7.3126920e-02],
            1.0450997e-01,
        ),
    ];
}
