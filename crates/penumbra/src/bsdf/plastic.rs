//! `plastic`: a diffuse base under a smooth dielectric coating, Mitsuba
//! 3's model: specular Fresnel reflection plus a diffuse term attenuated by
//! the Fresnel transmittances in and out and boosted by the internal
//! reflections at the coating, `ρ / (1 − F_dr,int)` (or `ρ / (1 − ρ F_dr,int)`
//! when `nonlinear`), with `F_dr` the diffuse Fresnel reflectance.

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance};
use super::{
    eta_props, eval_factor, modulate, scalar_param, smooth_sample, specular_factor, BsdfContextT,
    BsdfFlags, BsdfSample, BsdfT, NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{warp, Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Smooth plastic. Parameters (Mitsuba 3): `diffuse_reflectance` (default
/// 0.5), `specular_reflectance` (optional, default 1), `int_ior` (default
/// polypropylene, 1.49), `ext_ior` (default air), `nonlinear` (default
/// false). `eta` is parameter `<key>.eta` (not differentiable).
#[derive(Clone, Debug)]
pub struct Plastic {
    pub diffuse_reflectance: Texture,
    pub specular_reflectance: Option<Texture>,
    pub eta: ParamId,
    pub nonlinear: bool,
    /// Share of samples steered to the specular lobe before the Fresnel
    /// factor: `s_mean / (d_mean + s_mean)` (updated by
    /// [`Plastic::parameters_changed`]).
    pub specular_sampling_weight: f32,
}

/// Diffuse term shared by `plastic` and `roughplastic`:
/// `ρ / (1 − F_int) · cos θo / π / η² · t_i t_o` (or `ρ / (1 − ρ F_int)`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn coated_diffuse<R: ScalarReal>(
    rho: Spectrum<R>,
    nonlinear: bool,
    internal_reflectance: R,
    eta: R,
    t_i: R,
    t_o: R,
    cos_o: R,
) -> Spectrum<R> {
    let denom = if nonlinear {
        rho.map(|c| -(c * internal_reflectance) + 1.0)
    } else {
        V3::splat(-internal_reflectance + 1.0)
    };
    rho.div_elem(denom) * (t_i * t_o / (eta * eta) * (cos_o * FRAC_1_PI))
}

/// Probability of sampling the specular lobe given the Fresnel
/// reflectance `f_i` of the incident direction.
pub(crate) fn specular_probability(f_i: f32, specular_sampling_weight: f32) -> f32 {
    let ps = f_i * specular_sampling_weight;
    let pd = (1.0 - f_i) * (1.0 - specular_sampling_weight);
    if ps + pd > 0.0 {
        ps / (ps + pd)
    } else {
        0.0
    }
}

pub(crate) fn sampling_weight(
    store: &ParamStore,
    diffuse: &Texture,
    specular: &Option<Texture>,
) -> f32 {
    let d = diffuse.mean(store);
    let s = specular.as_ref().map_or(1.0, |t| t.mean(store));
    if d + s > 0.0 {
        s / (d + s)
    } else {
        0.5
    }
}

/// The diffuse base of `plastic` and `roughplastic`:
/// [`coating_reflectances`] and `nonlinear` (default false).
pub(crate) fn coated_diffuse_props(
    node: &Node,
    ctx: &mut LoadContext,
) -> Result<(Texture, Option<Texture>, bool)> {
    let (diffuse_reflectance, specular_reflectance) = coating_reflectances(node, ctx)?;
    let nonlinear = node.bool("nonlinear", false)?;
    Ok((diffuse_reflectance, specular_reflectance, nonlinear))
}

/// The reflectances of the plastics: `diffuse_reflectance` (RGB in
/// [0, 1], default 0.5) and `specular_reflectance` (optional factor).
pub(crate) fn coating_reflectances(
    node: &Node,
    ctx: &mut LoadContext,
) -> Result<(Texture, Option<Texture>)> {
    let diffuse_reflectance = Texture::from_prop(
        node,
        "diffuse_reflectance",
        Some(0.5),
        Channels::Rgb,
        Domain::UnitInterval,
        ctx,
    )?;
    let specular_reflectance = specular_factor(node, "specular_reflectance", ctx)?;
    Ok((diffuse_reflectance, specular_reflectance))
}

impl Plastic {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Plastic> {
        let eta = eta_props(node, 1.49, 1.000277)?;
        let eta = scalar_param(
            node,
            "eta",
            eta,
            ParamFlags::NON_DIFFERENTIABLE,
            Domain::Positive,
            ctx,
        )?;
        let (diffuse_reflectance, specular_reflectance, nonlinear) =
            coated_diffuse_props(node, ctx)?;
        Ok(Plastic {
            diffuse_reflectance,
            specular_reflectance,
            eta,
            nonlinear,
            specular_sampling_weight: 0.5,
        })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.specular_sampling_weight =
            sampling_weight(store, &self.diffuse_reflectance, &self.specular_reflectance);
    }
}

impl BsdfT for Plastic {
    fn flags(&self) -> BsdfFlags {
        BsdfFlags::DELTA_REFLECTION.union(BsdfFlags::DIFFUSE_REFLECTION)
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        nodes[0] = Some(NodeContext::Plastic(PlasticContext {
            bsdf: self,
            wi: si.wi,
            eta: store.read::<R>(self.eta, 0),
            diffuse_reflectance: self.diffuse_reflectance.eval(store, si),
            specular_reflectance: eval_factor(&self.specular_reflectance, store, si),
        }));
        1
    }
}

/// [`Plastic`] at a vertex.
#[derive(Clone, Copy, Debug)]
pub struct PlasticContext<'a, R: ScalarReal> {
    bsdf: &'a Plastic,
    wi: V3<R>,
    eta: R,
    diffuse_reflectance: Spectrum<R>,
    specular_reflectance: Option<Spectrum<R>>,
}

impl<R: ScalarReal> BsdfContextT<R> for PlasticContext<'_, R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        let cos_i = self.wi.z;
        if !(cos_i.val() > 0.0 && wo.z.val() > 0.0) {
            return V3::zero();
        }
        let eta = self.eta;
        let t_i = -fresnel_dielectric(cos_i, eta).0 + 1.0;
        let t_o = -fresnel_dielectric(wo.z, eta).0 + 1.0;
        let f_int = fresnel_diffuse_reflectance(eta.recip());
        coated_diffuse(
            self.diffuse_reflectance,
            self.bsdf.nonlinear,
            f_int,
            eta,
            t_i,
            t_o,
            wo.z,
        )
    }

    fn pdf(&self, wo: Vec3) -> f32 {
        let cos_i = self.wi.z.val();
        if !(cos_i > 0.0 && wo.z > 0.0) {
            return 0.0;
        }
        let f_i = fresnel_dielectric(cos_i, self.eta.val()).0;
        let pd = 1.0 - specular_probability(f_i, self.bsdf.specular_sampling_weight);
        warp::square_to_cosine_hemisphere_pdf(wo.into()) * pd
    }

    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        if !(self.wi.z.val() > 0.0) {
            return None;
        }
        let f_i = fresnel_dielectric(self.wi.z, self.eta).0;
        let ps = specular_probability(f_i.val(), self.bsdf.specular_sampling_weight);
        if u1 < ps {
            let w = modulate(V3::splat(f_i / ps), self.specular_reflectance);
            return Some(BsdfSample::specular_reflection(self.wi, ps, w));
        }
        let wo = Vec3::from(warp::square_to_cosine_hemisphere(u2.into()));
        smooth_sample(self, wo, 1.0, BsdfFlags::DIFFUSE_REFLECTION)
    }

    fn albedo(&self) -> Spectrum<R> {
        self.diffuse_reflectance
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{BsdfContextT, BsdfFlags};
    use crate::bsdf::fresnel::fresnel_dielectric;
    use glam::Vec2;

    #[test]
    fn sampling_matches_pdf_and_lobes() {
        let cases: Vec<Vec<(&str, crate::scene::description::Value)>> = vec![
            vec![],
            vec![
                ("diffuse_reflectance", rgb(0.1, 0.3, 0.7)),
                ("nonlinear", boolean(true)),
                ("int_ior", float(1.7)),
            ],
        ];
        let wis = [dir(0.9, 0.2), dir(0.1, 1.0)];
        check_sampling_and_albedo("plastic", &cases, &wis, 2);
        // specular lobe: mirror direction, weight = F / P(specular)
        let (b, store) = build("plastic", &[]);
        let wi = dir(0.5, 0.3);
        let bs = b
            .context(&store.primal(), &si::<f32>(wi))
            .sample(0.0, Vec2::splat(0.5))
            .unwrap();
        assert_eq!(bs.lobe, BsdfFlags::DELTA_REFLECTION);
        let f = fresnel_dielectric(0.5f32, 1.49 / 1.000277).0;
        assert!((bs.weight.x * bs.pdf - f).abs() < 1e-6, "{bs:?}");
        assert!(b
            .context(&store.primal(), &si::<f32>(-wi))
            .sample(0.0, Vec2::splat(0.5))
            .is_none());
    }

    /// Values of Mitsuba 3.9.1 (scalar_rgb) plastic `eval` and `pdf`.
    #[test]
    fn matches_mitsuba_values() {
        for &(nonlinear, wi, wo, f_ref, p_ref) in PLASTIC_REF {
            let (b, store) = build(
                "plastic",
                &[
                    ("diffuse_reflectance", rgb(0.1, 0.3, 0.7)),
                    ("nonlinear", boolean(nonlinear)),
                ],
            );
            let (wi, wo) = (
                glam::Vec3::from(wi).normalize(),
                glam::Vec3::from(wo).normalize(),
            );
            let f = eval_f32(&b, &store, wi, wo);
            let p = pdf_f32(&b, &store, wi, wo);
            for c in 0..3 {
                assert!(
                    (f[c] - f_ref[c]).abs() <= 1e-4 * f_ref[c].abs() + 1e-7,
                    "{wi:?} {wo:?}: {f} vs {f_ref:?}"
                );
            }
            assert!(
                (p - p_ref).abs() <= 1e-4 * p_ref + 1e-7,
                "pdf {p} vs {p_ref}"
            );
        }
    }

    /// (nonlinear, wi, wo, eval rgb, pdf) from Mitsuba 3.9.1.
    type RefRow = (bool, [f32; 3], [f32; 3], [f32; 3], f32);
    #[allow(clippy::excessive_precision)]
    const PLASTIC_REF: &[RefRow] = &[
        (
            false,
            [0.3, 0.1, 0.9],
            [-0.2, 0.4, 0.8],
            [2.8211704e-02, 8.4635109e-02, 1.9748192e-01],
            2.5022188e-01,
        ),
        (
            false,
            [0.8, 0.0, 0.2],
            [0.1, 0.1, 0.95],
            [2.4245564e-02, 7.2736695e-02, 1.6971895e-01],
            1.5590753e-01,
        ),
        (
            false,
            [0.1, 0.2, 0.95],
            [-0.9, 0.3, 0.1],
            [1.5688693e-03, 4.7066081e-03, 1.0982085e-02],
            3.0065136e-02,
        ),
        (
            false,
            [0.3, 0.1, 0.9],
            [-0.3, -0.1, 0.9],
            [3.0528087e-02, 9.1584265e-02, 2.1369660e-01],
            2.7045608e-01,
        ),
        (
            true,
            [0.3, 0.1, 0.9],
            [-0.2, 0.4, 0.8],
            [1.2278295e-02, 4.2121407e-02, 1.3785216e-01],
            2.5022188e-01,
        ),
        (
            true,
            [0.8, 0.0, 0.2],
            [0.1, 0.1, 0.95],
            [1.0552152e-02, 3.6199775e-02, 1.1847223e-01],
            1.5590753e-01,
        ),
        (
            true,
            [0.1, 0.2, 0.95],
            [-0.9, 0.3, 0.1],
            [6.8280316e-04, 2.3423962e-03, 7.6660393e-03],
            3.0065136e-02,
        ),
        (
            true,
            [0.3, 0.1, 0.9],
            [-0.3, -0.1, 0.9],
            [1.3286431e-02, 4.5579877e-02, 1.4917082e-01],
            2.7045608e-01,
        ),
    ];
}
