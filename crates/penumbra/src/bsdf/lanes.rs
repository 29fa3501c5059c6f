//! The BSDFs of the path tracer in lanes (`integrator/lanes.rs`): each
//! lane of a block holds the BSDF of its own vertex, and a block's values,
//! densities and samples are computed for all its lanes at once, each
//! plugin's formulas in the lanes whose vertex has that plugin (the other
//! lanes masked off, and the plugins no lane has skipped).
//!
//! Written for lanes so far: `diffuse`, and `roughconductor`,
//! `roughdielectric` and `roughplastic` with an isotropic GGX distribution
//! sampled by its visible normals, whose parameters other than the
//! diffuse reflectances are plain values ([`LaneBsdf::of`]). The
//! formulas are the plugins' own (same conventions, same lobe choices with
//! the same random numbers, same densities), primal and with masks for
//! their branches; the one difference is the disk sample under the
//! visible normals ([`ggx::sample_visible`]), so the same random numbers
//! give other, equally distributed, directions.

use super::fresnel::{fresnel_conductor, fresnel_dielectric_primal, reflect, refract};
use super::microfacet::{ggx, MicrofacetType, Roughness, MIN_ALPHA};
use super::plastic::specular_probability;
use super::{lambert_eval, lambert_pdf, lambert_sample, Bsdf, RoughPlastic};
use crate::ad::lanes::{LaneMask, Lanes};
use crate::ad::{Float, Mask, Real};
use crate::math::{warp, Spectrum, V2, V3};
use crate::params::{ParamId, ParamView};
use crate::texture::Texture;
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// A BSDF written for lanes, with the values of its parameters.
#[derive(Clone, Copy, Debug)]
pub(crate) enum LaneBsdf<'a> {
    /// `diffuse`: its reflectance is the vertex's albedo.
    Diffuse,
    /// `roughconductor`: roughness, complex index of refraction, factor.
    RoughConductor {
        alpha: f32,
        eta: Vec3,
        k: Vec3,
        specular: Vec3,
    },
    /// `roughdielectric`: roughness, relative index of refraction, the
    /// factors of reflection and transmission.
    RoughDielectric {
        alpha: f32,
        eta: f32,
        reflect: Vec3,
        transmit: Vec3,
    },
    /// `roughplastic` (its tables of the interface's transmittance are
    /// the plugin's): the diffuse base is the vertex's albedo.
    RoughPlastic {
        plastic: &'a RoughPlastic,
        alpha: f32,
        eta: f32,
        specular: Vec3,
    },
}

/// The value of a texture that is a plain value.
fn plain(texture: &Texture, store: &ParamView) -> Option<Vec3> {
    match texture {
        Texture::Uniform(u) if !store.is_recorded(u.id) => Some(u.value::<f32>(store).val()),
        _ => None,
    }
}

/// A scalar parameter's value, held constant by the lanes: `None` where
/// it is recorded for derivatives.
fn constant(id: ParamId, store: &ParamView) -> Option<f32> {
    (!store.is_recorded(id)).then(|| store.value(id, 0))
}

/// An optional factor's plain value (1 where it is not given).
fn plain_factor(factor: &Option<Texture>, store: &ParamView) -> Option<Vec3> {
    factor.as_ref().map_or(Some(Vec3::ONE), |t| plain(t, store))
}

/// An isotropic GGX roughness of plain value sampled by its visible
/// normals, clamped as [`super::microfacet::MicrofacetDistribution::new`].
fn plain_ggx(roughness: &Roughness, store: &ParamView) -> Option<f32> {
    let ggx = roughness.kind == MicrofacetType::Ggx && roughness.sample_visible;
    (ggx && roughness.alpha_v.is_none())
        .then(|| plain(&roughness.alpha_u, store))
        .flatten()
        .map(|a| a.x.max(MIN_ALPHA))
}

impl<'a> LaneBsdf<'a> {
    /// `bsdf` written for lanes, with the texture of its diffuse
    /// reflectance, if it has one (the loop looks it up per lane: a plain
    /// value or a texture over uv); `None` where it is not written for
    /// lanes (see the module documentation), or where a parameter it holds
    /// constant (all but the diffuse reflectance) is recorded in `store`:
    /// reverse mode in lanes differentiates diffuse reflectances only.
    pub(crate) fn of(
        bsdf: &'a Bsdf,
        store: &ParamView,
    ) -> Option<(LaneBsdf<'a>, Option<&'a Texture>)> {
        Some(match bsdf {
            Bsdf::Diffuse(d) => (LaneBsdf::Diffuse, Some(&d.reflectance)),
            Bsdf::RoughConductor(c) => (
                LaneBsdf::RoughConductor {
                    alpha: plain_ggx(&c.roughness, store)?,
                    eta: plain(&c.ior.eta, store)?,
                    k: plain(&c.ior.k, store)?,
                    specular: plain_factor(&c.specular_reflectance, store)?,
                },
                None,
            ),
            Bsdf::RoughDielectric(d) => (
                LaneBsdf::RoughDielectric {
                    alpha: plain_ggx(&d.roughness, store)?,
                    eta: constant(d.eta, store)?,
                    reflect: plain_factor(&d.specular_reflectance, store)?,
                    transmit: plain_factor(&d.specular_transmittance, store)?,
                },
                None,
            ),
            Bsdf::RoughPlastic(p) => {
                let ggx = p.kind == MicrofacetType::Ggx && p.sample_visible;
                (
                    LaneBsdf::RoughPlastic {
                        plastic: p,
                        alpha: ggx.then(|| constant(p.alpha, store))??.max(MIN_ALPHA),
                        eta: constant(p.eta, store)?,
                        specular: plain_factor(&p.specular_reflectance, store)?,
                    },
                    Some(&p.diffuse_reflectance),
                )
            }
            _ => return None,
        })
    }

    /// The parameters the lanes hold constant in a BSDF written for them
    /// (all but its diffuse reflectance): a roughness, an index of
    /// refraction, a specular factor. `None` where one is not a list of
    /// parameters ([`Texture::param_ids`]).
    pub(crate) fn held_params(bsdf: &Bsdf) -> Option<Vec<ParamId>> {
        let ids = |textures: &[Option<&Texture>]| -> Option<Vec<ParamId>> {
            let mut ids = Vec::new();
            for texture in textures.iter().flatten() {
                ids.extend(texture.param_ids()?);
            }
            Some(ids)
        };
        Some(match bsdf {
            Bsdf::RoughConductor(c) => ids(&[
                Some(&c.roughness.alpha_u),
                Some(&c.ior.eta),
                Some(&c.ior.k),
                c.specular_reflectance.as_ref(),
            ])?,
            Bsdf::RoughDielectric(d) => {
                let mut held = ids(&[
                    Some(&d.roughness.alpha_u),
                    d.specular_reflectance.as_ref(),
                    d.specular_transmittance.as_ref(),
                ])?;
                held.push(d.eta);
                held
            }
            Bsdf::RoughPlastic(p) => {
                let mut held = ids(&[p.specular_reflectance.as_ref()])?;
                held.extend([p.alpha, p.eta]);
                held
            }
            _ => Vec::new(),
        })
    }
}

/// Per lane, a sampled direction, its density, its weight, the relative
/// index of refraction along it, and whether the lane has a sample
/// ([`BsdfLanes::sample`]).
pub(crate) type LaneSample<const N: usize> = (
    V3<Lanes<N>>,
    Lanes<N>,
    Spectrum<Lanes<N>>,
    Lanes<N>,
    LaneMask<N>,
);

/// The BSDFs at the vertices of a block's lanes, seen from the lanes'
/// incident directions `wi` (local frames), with their diffuse
/// reflectances.
/// It borrows the other plugins' parameters ([`MixedLanes`]) where it
/// would hold them: with them inside, it was too large for registers and
/// was copied on its way into place, whichever BSDFs the block has, with
/// loads that waited on the stores that had just made its parts (4 % of
/// the kernels' samples on cbox, whose BSDFs are all `diffuse`).
pub(crate) struct BsdfLanes<'m, 'a, const N: usize> {
    wi: V3<Lanes<N>>,
    albedo: V3<Lanes<N>>,
    /// Where a lane has another plugin than `diffuse`, the plugins'
    /// parameters in lanes; else the block's values, densities and samples
    /// are the Lambertian ones, inline.
    mixed: Option<&'m MixedLanes<'a, N>>,
}

/// The BSDFs of a block some of whose lanes have other plugins than
/// `diffuse`, their parameters in lanes. Its methods are out of line:
/// inlined into the loop's eight kernels (four widths, primal and reverse
/// mode), they took LLVM over fifteen minutes to compile, and gathering
/// their parameters inline made cbox, which has none of them, 14 % slower.
pub(crate) struct MixedLanes<'a, const N: usize> {
    wi: V3<Lanes<N>>,
    /// The lanes of each plugin (a lane without a vertex has none).
    diffuse: LaneMask<N>,
    conductor: LaneMask<N>,
    dielectric: LaneMask<N>,
    plastic: LaneMask<N>,
    /// The diffuse reflectance (`diffuse`, `roughplastic`).
    albedo: V3<Lanes<N>>,
    alpha: Lanes<N>,
    /// The index of refraction (a conductor's real part per channel; a
    /// dielectric's or plastic's in `x`) and a conductor's imaginary part.
    eta: V3<Lanes<N>>,
    k: V3<Lanes<N>>,
    /// The factor of reflection, and of a dielectric's transmission.
    specular: V3<Lanes<N>>,
    transmit: V3<Lanes<N>>,
    /// A plastic's plugin (its transmittance table), the probability of
    /// sampling its coating, and its diffuse base's value per unit of the
    /// transmittance out along `wo` times `cos θo` (what depends on `wi`
    /// alone of the plugin's `coated_diffuse`).
    plastics: [Option<&'a RoughPlastic>; N],
    p_coating: Lanes<N>,
    base: V3<Lanes<N>>,
}

impl<'m, 'a, const N: usize> BsdfLanes<'m, 'a, N> {
    /// The BSDFs of the lanes with diffuse reflectances `albedo`, seen
    /// along `wi`: `mixed` (from [`MixedLanes::new`] with the same
    /// `albedo` and `wi`) where some lane has another plugin than
    /// `diffuse`, else `None`.
    #[inline(always)]
    pub(crate) fn new(
        mixed: Option<&'m MixedLanes<'a, N>>,
        albedo: V3<Lanes<N>>,
        wi: V3<Lanes<N>>,
    ) -> Self {
        BsdfLanes { wi, albedo, mixed }
    }

    /// `f(wi, wo) · |cos θo|` per lane.
    #[inline(always)]
    pub(crate) fn eval(&self, wo: V3<Lanes<N>>) -> Spectrum<Lanes<N>> {
        match &self.mixed {
            Some(mixed) => mixed.eval(wo),
            None => lambert_eval(self.wi, wo, self.albedo),
        }
    }

    /// The density with which [`BsdfLanes::sample`] gives `wo`, per lane.
    #[inline(always)]
    pub(crate) fn pdf(&self, wo: V3<Lanes<N>>) -> Lanes<N> {
        match &self.mixed {
            Some(mixed) => mixed.pdf(wo),
            None => lambert_pdf(self.wi.z, wo),
        }
    }

    /// A direction per lane from `u1` (the lobe) and `u2` (the direction in
    /// it): the direction, its density, the weight `eval / pdf`, the
    /// relative index of refraction along it, and the lanes with a sample.
    /// A diffuse lane's weight is its albedo and its density the cosine's,
    /// as [`lambert_sample`] gives them.
    #[inline(always)]
    pub(crate) fn sample(&self, u1: Lanes<N>, u2: V2<Lanes<N>>) -> LaneSample<N> {
        match &self.mixed {
            Some(mixed) => mixed.sample(u1, u2),
            None => {
                let (wo, pdf, sampled) = lambert_sample(self.wi.z, u2);
                (wo, pdf, self.albedo, Lanes::splat(1.0), sampled)
            }
        }
    }
}

impl<'a, const N: usize> MixedLanes<'a, N> {
    /// The parameters of the plugins `bsdfs(k)` of the lanes `k` (`None`:
    /// a lane without a vertex), with diffuse reflectances `albedo`, seen
    /// along `wi`.
    #[inline(never)]
    pub(crate) fn new(
        bsdfs: &impl Fn(usize) -> Option<LaneBsdf<'a>>,
        albedo: V3<Lanes<N>>,
        wi: V3<Lanes<N>>,
    ) -> Self {
        let mut b = MixedLanes {
            wi,
            diffuse: LaneMask::from_fn(|k| matches!(bsdfs(k), Some(LaneBsdf::Diffuse))),
            conductor: LaneMask::splat(false),
            dielectric: LaneMask::splat(false),
            plastic: LaneMask::splat(false),
            albedo,
            alpha: Lanes::splat(1.0),
            eta: V3::splat(Lanes::splat(1.0)),
            k: V3::zero(),
            specular: V3::splat(Lanes::splat(1.0)),
            transmit: V3::splat(Lanes::splat(1.0)),
            plastics: [None; N],
            base: V3::zero(),
            p_coating: Lanes::splat(0.0),
        };
        let set = |v: &mut V3<Lanes<N>>, k: usize, x: Vec3| {
            (v.x.0[k], v.y.0[k], v.z.0[k]) = (x.x, x.y, x.z);
        };
        for k in 0..N {
            match bsdfs(k) {
                Some(LaneBsdf::RoughConductor {
                    alpha,
                    eta,
                    k: kappa,
                    specular,
                }) => {
                    b.conductor.0[k] = -1;
                    b.alpha.0[k] = alpha;
                    set(&mut b.eta, k, eta);
                    set(&mut b.k, k, kappa);
                    set(&mut b.specular, k, specular);
                }
                Some(LaneBsdf::RoughDielectric {
                    alpha,
                    eta,
                    reflect,
                    transmit,
                }) => {
                    b.dielectric.0[k] = -1;
                    b.alpha.0[k] = alpha;
                    b.eta.x.0[k] = eta;
                    set(&mut b.specular, k, reflect);
                    set(&mut b.transmit, k, transmit);
                }
                Some(LaneBsdf::RoughPlastic {
                    plastic,
                    alpha,
                    eta,
                    specular,
                }) => {
                    b.plastic.0[k] = -1;
                    b.alpha.0[k] = alpha;
                    b.eta.x.0[k] = eta;
                    set(&mut b.specular, k, specular);
                    b.plastics[k] = Some(plastic);
                    // as the plugin's context: the coating is sampled in
                    // proportion to its reflectance along wi
                    let t_i = plastic.transmittance(wi.z.0[k]);
                    b.p_coating.0[k] =
                        specular_probability(1.0 - t_i, plastic.specular_sampling_weight);
                    let rho = Vec3::new(albedo.x.0[k], albedo.y.0[k], albedo.z.0[k]);
                    let internal = plastic.internal_reflectance;
                    let denom = if plastic.nonlinear {
                        Vec3::ONE - rho * internal
                    } else {
                        Vec3::splat(1.0 - internal)
                    };
                    set(
                        &mut b.base,
                        k,
                        rho / denom * (t_i / (eta * eta) * FRAC_1_PI),
                    );
                }
                _ => {}
            }
        }
        b
    }

    /// [`BsdfLanes::eval`].
    #[inline(never)]
    fn eval(&self, wo: V3<Lanes<N>>) -> Spectrum<Lanes<N>> {
        let (wi, zero) = (self.wi, Lanes::<N>::splat(0.0));
        let mut f = V3::zero();
        if self.diffuse.any() {
            f = V3::select(self.diffuse, lambert_eval(wi, wo, self.albedo), f);
        }
        let above = wi.z.gt(0.0) & wo.z.gt(0.0);
        if self.conductor.any() {
            let m = (wi + wo).normalize();
            let dg = self.microfacet_dg(wi, wo, m);
            let fr = fresnel_conductor(wi.dot(m), self.eta, self.k);
            let v = fr.mul_elem(self.specular) * (dg / (wi.z * 4.0));
            f = V3::select(self.conductor & above & dg.gt(0.0), v, f);
        }
        if self.dielectric.any() {
            let eta_p = self.eta.x;
            let reflected = (wi.z * wo.z).gt(0.0);
            let eta = Lanes::select(wi.z.gt(0.0), eta_p, eta_p.recip());
            let m = (wi + V3::select(reflected, wo, wo * eta)).normalize();
            let m = V3::select(m.z.lt(0.0), -m, m);
            let dg = self.microfacet_dg(wi, wo, m);
            let (fr, ..) = fresnel_dielectric_primal(wi.dot(m), eta_p);
            let r = fr * dg / (wi.z.abs() * 4.0);
            let (wim, wom) = (wi.dot(m), wo.dot(m));
            let denom = wim + eta * wom;
            let t = ((-fr + 1.0) * dg * wim * wom / (wi.z * denom * denom)).abs();
            let v = V3::select(reflected, self.specular * r, self.transmit * t);
            let some = self.dielectric & !wi.z.equals(0.0) & !wo.z.equals(0.0) & dg.gt(0.0);
            f = V3::select(some, v, f);
        }
        if self.plastic.any() {
            let eta = self.eta.x;
            let m = (wi + wo).normalize();
            let dg = self.microfacet_dg(wi, wo, m);
            let (fr, ..) = fresnel_dielectric_primal(wi.dot(m), eta);
            let coating = Lanes::select(dg.gt(0.0), fr * dg / (wi.z * 4.0), zero);
            let t_o = self.plastic_transmittance(wo.z);
            let v = self.specular * coating + self.base * (t_o * wo.z);
            f = V3::select(self.plastic & above, v, f);
        }
        f
    }

    /// [`BsdfLanes::pdf`].
    #[inline(never)]
    fn pdf(&self, wo: V3<Lanes<N>>) -> Lanes<N> {
        let (wi, zero) = (self.wi, Lanes::<N>::splat(0.0));
        let mut p = Lanes::<N>::splat(0.0);
        if self.diffuse.any() {
            p = Lanes::select(self.diffuse, lambert_pdf(wi.z, wo), p);
        }
        let above = wi.z.gt(0.0) & wo.z.gt(0.0);
        if (self.conductor | self.plastic).any() {
            // the density of a reflection by the visible normals
            let m = (wi + wo).normalize();
            let (wim, wom) = (wi.dot(m), wo.dot(m));
            let seen = wim.gt(0.0) & wom.gt(0.0);
            let reflection = Lanes::select(
                seen,
                ggx::pdf_visible(self.alpha, wi, m) / (wom * 4.0),
                zero,
            );
            p = Lanes::select(self.conductor & above, reflection, p);
            if self.plastic.any() {
                let ps = self.p_coating;
                let diffuse = warp::square_to_cosine_hemisphere_pdf(wo);
                let v = ps * reflection + (-ps + 1.0) * diffuse;
                p = Lanes::select(self.plastic & above, v, p);
            }
        }
        if self.dielectric.any() {
            let eta_p = self.eta.x;
            let reflected = (wi.z * wo.z).gt(0.0);
            let eta = Lanes::select(wi.z.gt(0.0), eta_p, eta_p.recip());
            let h = wi + wo * Lanes::select(reflected, Lanes::splat(1.0), eta);
            let len = h.length();
            let m = h * len.recip();
            let m = V3::select(m.z.lt(0.0), -m, m);
            let (wim, wom) = (wi.dot(m), wo.dot(m));
            let sides = (wim * wi.z).gt(0.0) & (wom * wo.z).gt(0.0);
            let den = wim + eta * wom;
            let dwh_dwo = Lanes::select(
                reflected,
                (wom * 4.0).recip(),
                eta * eta * wom / (den * den),
            );
            let wi_up = V3::select(wi.z.lt(0.0), -wi, wi);
            let (fr, ..) = fresnel_dielectric_primal(wim, eta_p);
            let lobe = Lanes::select(reflected, fr, -fr + 1.0);
            let v = ggx::pdf_visible(self.alpha, wi_up, m) * lobe * dwh_dwo.abs();
            let some =
                self.dielectric & !wi.z.equals(0.0) & !wo.z.equals(0.0) & len.gt(0.0) & sides;
            p = Lanes::select(some, v, p);
        }
        p
    }

    /// [`BsdfLanes::sample`].
    #[inline(never)]
    fn sample(&self, u1: Lanes<N>, u2: V2<Lanes<N>>) -> LaneSample<N> {
        let one = Lanes::<N>::splat(1.0);
        let wi = self.wi;
        let (wo, _, sampled) = lambert_sample(wi.z, u2);
        let mut wo = V3::select(self.diffuse, wo, V3::zero());
        let mut eta = one;
        let mut ok = self.diffuse & sampled;
        // a dielectric seen from inside samples the normals of the
        // interface turned towards wi
        let inside = wi.z.lt(0.0);
        let wi_up = V3::select(inside, -wi, wi);
        let m = ggx::sample_visible(self.alpha, wi_up, u2);
        let mirrored = reflect(wi, m);
        let visible = wi_up.dot(m).gt(0.0) & wi_up.z.gt(0.0);
        if self.conductor.any() {
            wo = V3::select(self.conductor, mirrored, wo);
            ok |= self.conductor & visible & mirrored.z.gt(0.0);
        }
        if self.plastic.any() {
            let coating = u1.lt(self.p_coating);
            let base = warp::square_to_cosine_hemisphere(u2);
            let w = V3::select(coating, mirrored, base);
            wo = V3::select(self.plastic, w, wo);
            ok |= self.plastic & wi.z.gt(0.0) & w.z.gt(0.0);
        }
        if self.dielectric.any() {
            let (fr, cos_t, eta_it, eta_ti) = fresnel_dielectric_primal(wi.dot(m), self.eta.x);
            let reflected = u1.lt(fr);
            let w = V3::select(reflected, mirrored, refract(wi, m, cos_t, eta_ti));
            let same_side = (w.z * wi.z).gt(0.0);
            // the lobe must leave on its own side
            let consistent =
                ((same_side & reflected) | !(same_side | reflected)) & !w.z.equals(0.0);
            wo = V3::select(self.dielectric, w, wo);
            eta = Lanes::select(self.dielectric & !reflected, eta_it, eta);
            ok |= self.dielectric & visible & consistent;
        }
        let p = self.pdf(wo);
        let ok = ok & p.gt(0.0);
        let weight = V3::select(self.diffuse, self.albedo, self.eval(wo) * p.recip());
        (wo, p, V3::select(ok, weight, V3::zero()), eta, ok)
    }

    /// `D(m) G(wi, wo, m)` of the lanes' roughness.
    #[inline(always)]
    fn microfacet_dg(&self, wi: V3<Lanes<N>>, wo: V3<Lanes<N>>, m: V3<Lanes<N>>) -> Lanes<N> {
        let a = self.alpha;
        ggx::eval(a, m) * ggx::smith_g1(a, wi, m) * ggx::smith_g1(a, wo, m)
    }

    /// A plastic's transmittance into the coating along a direction of
    /// cosine `cos` (its plugin's table, lane by lane).
    #[inline(always)]
    fn plastic_transmittance(&self, cos: Lanes<N>) -> Lanes<N> {
        Lanes::from_fn(|k| self.plastics[k].map_or(0.0, |p| p.transmittance(cos.0[k])))
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::BsdfContextT;
    use super::*;
    use crate::math::warp::square_to_uniform_sphere;
    use crate::params::ParamStore;
    use crate::testing::Pcg32;
    use glam::Vec2;

    /// The plugins written for lanes, each in configurations that reach
    /// every branch: the back side, total internal reflection (a dielectric
    /// seen from inside), nonlinear plastic.
    fn plugins() -> Vec<(&'static str, Bsdf, ParamStore)> {
        let ggx = || ("distribution", string("ggx"));
        [
            ("diffuse", vec![("reflectance", rgb(0.2, 0.5, 0.8))]),
            (
                "roughconductor",
                vec![
                    ggx(),
                    ("alpha", float(0.2)),
                    ("eta", rgb(0.143, 0.374, 1.442)),
                    ("k", rgb(3.983, 2.385, 1.603)),
                    ("specular_reflectance", rgb(0.9, 0.8, 0.7)),
                ],
            ),
            (
                "roughconductor",
                vec![ggx(), ("alpha", float(0.6)), ("material", string("Cu"))],
            ),
            (
                "roughdielectric",
                vec![ggx(), ("alpha", float(0.1)), ("int_ior", float(1.5))],
            ),
            (
                "roughdielectric",
                vec![
                    ggx(),
                    ("alpha", float(0.5)),
                    ("int_ior", float(1.33)),
                    ("specular_transmittance", rgb(0.5, 0.7, 0.9)),
                ],
            ),
            (
                "roughplastic",
                vec![
                    ggx(),
                    ("alpha", float(0.1)),
                    ("diffuse_reflectance", rgb(0.1, 0.3, 0.7)),
                ],
            ),
            (
                "roughplastic",
                vec![
                    ggx(),
                    ("alpha", float(0.4)),
                    ("int_ior", float(1.7)),
                    ("nonlinear", boolean(true)),
                    ("diffuse_reflectance", rgb(0.8, 0.3, 0.1)),
                ],
            ),
        ]
        .into_iter()
        .map(|(name, props)| {
            let (b, store) = build(name, &props);
            (name, b, store)
        })
        .collect()
    }

    /// What [`BsdfLanes`] reads of `b` in four lanes seen along `wi`
    /// ([`Lanes4::bsdf`]).
    struct Lanes4<'a> {
        mixed: Option<MixedLanes<'a, 4>>,
        albedo: V3<Lanes<4>>,
        wi: V3<Lanes<4>>,
    }

    impl<'a> Lanes4<'a> {
        fn bsdf(&self) -> BsdfLanes<'_, 'a, 4> {
            BsdfLanes::new(self.mixed.as_ref(), self.albedo, self.wi)
        }
    }

    fn lanes<'a>(b: &'a Bsdf, store: &ParamStore, wi: [Vec3; 4]) -> Lanes4<'a> {
        let view = store.primal();
        let (lb, albedo) = LaneBsdf::of(b, &view).expect("written for lanes");
        let albedo = V3::cst(albedo.map_or(Vec3::ZERO, |t| plain(t, &view).unwrap()));
        let wi = v3(wi);
        let mixed = !matches!(lb, LaneBsdf::Diffuse);
        let mixed = mixed.then(|| MixedLanes::new(&|_| Some(lb), albedo, wi));
        Lanes4 { mixed, albedo, wi }
    }

    fn v3(v: [Vec3; 4]) -> V3<Lanes<4>> {
        V3::new(
            Lanes::from_fn(|k| v[k].x),
            Lanes::from_fn(|k| v[k].y),
            Lanes::from_fn(|k| v[k].z),
        )
    }

    fn lane(v: V3<Lanes<4>>, k: usize) -> Vec3 {
        Vec3::new(v.x.0[k], v.y.0[k], v.z.0[k])
    }

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 2e-4 * b.abs() + 1e-6
    }

    /// Values and densities in lanes are the plugins' (to rounding), for
    /// pairs of directions drawn over the whole sphere.
    #[test]
    fn values_and_densities_are_the_plugins() {
        let mut rng = Pcg32::new(5);
        for (name, b, store) in plugins() {
            for _ in 0..2000 {
                let wi: [Vec3; 4] =
                    std::array::from_fn(|_| square_to_uniform_sphere(rng.next_2d()));
                let wo: [Vec3; 4] =
                    std::array::from_fn(|_| square_to_uniform_sphere(rng.next_2d()));
                let case = lanes(&b, &store, wi);
                let bl = case.bsdf();
                let (f, p) = (bl.eval(v3(wo)), bl.pdf(v3(wo)));
                for k in 0..4 {
                    let f_ref = eval_f32(&b, &store, wi[k], wo[k]);
                    let p_ref = pdf_f32(&b, &store, wi[k], wo[k]);
                    let at = format!("{name}: wi {:?} wo {:?}", wi[k], wo[k]);
                    let fk = lane(f, k);
                    assert!(
                        (0..3).all(|c| close(fk[c], f_ref[c])),
                        "{at}: f {fk} vs {f_ref}"
                    );
                    assert!(close(p.0[k], p_ref), "{at}: pdf {} vs {p_ref}", p.0[k]);
                }
            }
        }
    }

    /// Samples in lanes are distributed as the plugins' samples: for
    /// incident directions on both sides, the mean of `weight · η² · h(wo)`
    /// (green channel) over 2¹⁸ samples, for a smooth `h` that tells
    /// directions apart, agrees with the plugin's own sampling within 4.5
    /// standard errors of the difference (independent random numbers; a
    /// chance of 10⁻⁵ per case if both are right). Each lane's density is
    /// its [`BsdfLanes::pdf`], and its weight `eval / pdf`.
    #[test]
    fn samples_are_distributed_as_the_plugins() {
        let h = |w: Vec3| 1.0 + w.x + 0.5 * w.y * w.y + 0.3 * w.z;
        let n = 1 << 18;
        for (name, b, store) in plugins() {
            for wi in [dir(0.9, 0.3), dir(0.3, 2.0), dir(-0.6, 1.0), Vec3::Z] {
                let ctx = b.context(&store.primal(), &si::<f32>(wi));
                let case = lanes(&b, &store, [wi; 4]);
                let bl = case.bsdf();
                let (mut rng_a, mut rng_b) = (Pcg32::new(1), Pcg32::new(2));
                let (mut sa, mut sa2, mut sb, mut sb2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
                for _ in 0..n / 4 {
                    let u1 = Lanes::<4>::from_fn(|_| rng_a.next_f32());
                    let u: [Vec2; 4] = std::array::from_fn(|_| rng_a.next_2d());
                    let u2 = V2::new(Lanes::from_fn(|k| u[k].x), Lanes::from_fn(|k| u[k].y));
                    let (wo, pdf, weight, eta, ok) = bl.sample(u1, u2);
                    let (p_at, f_at) = (bl.pdf(wo), bl.eval(wo));
                    for k in 0..4 {
                        if !ok.lane(k) {
                            continue;
                        }
                        let w = lane(wo, k);
                        assert!(close(pdf.0[k], p_at.0[k]), "{name}: pdf of the sample");
                        if bl.mixed.is_some() {
                            let v = lane(f_at, k).y / p_at.0[k];
                            assert!(close(lane(weight, k).y, v), "{name}: weight of the sample");
                        }
                        let x = (lane(weight, k).y * eta.0[k] * eta.0[k] * h(w)) as f64;
                        (sa, sa2) = (sa + x, sa2 + x * x);
                    }
                    for _ in 0..4 {
                        let (u1, u2) = (rng_b.next_f32(), rng_b.next_2d());
                        if let Some(bs) = ctx.sample(u1, u2) {
                            let x = (bs.weight.y * bs.eta * bs.eta * h(bs.wo.val())) as f64;
                            (sb, sb2) = (sb + x, sb2 + x * x);
                        }
                    }
                }
                let nf = n as f64;
                let (ma, mb) = (sa / nf, sb / nf);
                let var = (sa2 / nf - ma * ma) / nf + (sb2 / nf - mb * mb) / nf;
                let t = (ma - mb) / var.sqrt().max(1e-12);
                assert!(
                    t.abs() < 4.5,
                    "{name}, wi {wi:?}: lanes {ma} vs plugin {mb} (t = {t})"
                );
            }
        }
    }

    /// What is not written for lanes is refused, for the scalar loop.
    #[test]
    fn other_bsdfs_are_not_written_for_lanes() {
        for (name, props) in [
            ("roughconductor", vec![("alpha", float(0.2))]),
            (
                "roughconductor",
                vec![
                    ("distribution", string("ggx")),
                    ("alpha_u", float(0.1)),
                    ("alpha_v", float(0.3)),
                ],
            ),
            (
                "roughdielectric",
                vec![
                    ("distribution", string("ggx")),
                    ("sample_visible", boolean(false)),
                ],
            ),
            ("dielectric", vec![]),
        ] {
            let (b, store) = build(name, &props);
            assert!(
                LaneBsdf::of(&b, &store.primal()).is_none(),
                "{name} {props:?}"
            );
        }
    }
}
