//! A medium whose coefficients come from volumes (Mitsuba's
//! `heterogeneous`), sampled by tracking against a majorant m ≥ σ_t
//! (Woodcock et al. 1965; the null-collision formulation of Galtier et al.
//! 2013 and Kutz et al. 2017, "Spectral and decomposition tracking").
//!
//! Tentative collisions are drawn at rate m. At each, σ_t(x) (all
//! channels) is read and the collision is real with probability
//! P = mean_c σ_c / m, null otherwise. A real one scatters with weight
//! σ_s / (m P); a null one continues with weight σ_n / (m (1 − P)), where
//! σ_n = m − σ_t. For a grey medium both weights are the albedo and 1,
//! exactly: delta tracking. The probabilities are constants of the
//! derivative (detached sampling); the weights carry the derivatives of
//! σ_t and α at the sampled points, which is an unbiased estimate of the
//! derivative as long as a null collision can happen wherever σ_t may
//! change (Nimier-David et al. 2022, "Unbiased inverse volume rendering
//! with differential trackers", §4). Hence the majorant is a little larger
//! than the largest extinction ([`MAJORANT_FACTOR`]): with m = max σ_t, a
//! region at the maximum (a uniform grid, the usual initial guess of a
//! reconstruction) never has null collisions and the derivative of its
//! transmittance would be lost.
//!
//! Transmittance is estimated by ratio tracking (Novák et al. 2014): the
//! product of σ_n / m over the tentative collisions, differentiable as it
//! stands.

use super::{FreeFlight, Medium};
use crate::ad::Real;
use crate::geometry::Ray;
use crate::math::Spectrum;
use crate::params::ParamView;
use crate::sampler::SampleStream;

/// The majorant over the largest extinction of the medium.
pub(super) const MAJORANT_FACTOR: f32 = 1.1;

/// The next tentative collision after `t` at rate `m`.
#[inline]
fn next_collision(t: f32, m: f32, rng: &mut SampleStream) -> f32 {
    t - (1.0 - rng.next_1d()).ln() / m
}

pub(super) fn sample_free_flight<R: Real>(
    medium: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
    rng: &mut SampleStream,
) -> FreeFlight<R> {
    let mut weight = Spectrum::<R>::splat(R::cst(1.0));
    let m = medium.majorant;
    let Some((mut t, t_end)) = medium.clip(ray, t_max).filter(|_| m > 0.0) else {
        return FreeFlight::Pass { weight };
    };
    loop {
        t = next_collision(t, m, rng);
        if t >= t_end {
            return FreeFlight::Pass { weight };
        }
        let p = ray.at(t);
        let (sigma_t, albedo) = medium.coefficients::<R>(store, p);
        let mean = sigma_t.val().element_sum() / 3.0;
        let real = mean / m;
        if rng.next_1d() < real {
            let scatter = sigma_t.mul_elem(albedo) * R::cst(1.0 / mean);
            return FreeFlight::Scatter {
                t,
                p,
                weight: weight.mul_elem(scatter),
            };
        }
        // 1 for a grey medium, unless derivatives are wanted
        let s = sigma_t.val();
        if R::DIFFERENTIABLE || s.min_element() != s.max_element() {
            let null = sigma_t.map(|s| R::cst(m) - s) * R::cst(1.0 / (m - mean));
            weight = weight.mul_elem(null);
        }
    }
}

pub(super) fn transmittance<R: Real>(
    medium: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
    rng: &mut SampleStream,
) -> Spectrum<R> {
    let mut tr = Spectrum::<R>::splat(R::cst(1.0));
    let m = medium.majorant;
    let Some((mut t, t_end)) = medium.clip(ray, t_max).filter(|_| m > 0.0) else {
        return tr;
    };
    loop {
        t = next_collision(t, m, rng);
        if t >= t_end {
            return tr;
        }
        let (sigma_t, _) = medium.coefficients::<R>(store, ray.at(t));
        tr = tr.mul_elem(sigma_t.map(|s| (R::cst(m) - s) * (1.0 / m)));
        // Without derivatives a zero estimate stays zero. With them it does
        // not end here: the derivative of a factor that is zero is not.
        if !R::DIFFERENTIABLE && tr.val() == glam::Vec3::ZERO {
            return tr;
        }
    }
}
