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
//!
//! The majorant is local: with a grid extinction, m is the bound of the
//! cell of a coarse majorant grid the collision lies in (`majorant.rs`),
//! still [`MAJORANT_FACTOR`] × the largest extinction the cell can read.
//! Both trackers walk the cells along the ray (regular tracking: an
//! exponential optical depth is drawn once per tentative collision and
//! spent across cells, m × length per cell), and cells of majorant 0 are
//! skipped: empty space costs no lookups. A grid whose cells differ too
//! little for the walk to pay is tracked in one segment against its
//! largest majorant (`MajorantGrid::single`).
//!
//! Empty cells and derivatives: the derivative of the transmittance
//! through a cell is carried by its null collisions, one −1/m per
//! collision at rate m. A cell whose voxels are all 0 has none, so its
//! voxels would get no gradient, and a cell of tiny majorant would give
//! theirs with a huge variance; yet in a reconstruction voxels at 0 must
//! be able to grow. So while the extinction grid's values are
//! differentiated (a tangent is set for them, or reverse mode records
//! them), no cell's majorant is below [`TRACKED_FLOOR`] × the largest
//! extinction. This depends on the derivative call, the same for all its
//! samples and every number type, never on the number type: a path
//! makes the same decisions in f32 and on the tape. Primal renders, and
//! derivatives of the albedo or the scale (which have no derivative where
//! the density is 0), skip empty cells entirely. A grid that is 0
//! everywhere has no majorant at all and gets no gradient.

use super::{FreeFlight, Medium};
use crate::ad::ScalarReal;
use crate::geometry::Ray;
use crate::math::Spectrum;
use crate::params::ParamView;
use crate::sampler::SampleStream;

/// The majorant over the largest extinction it bounds.
pub(super) const MAJORANT_FACTOR: f32 = 1.1;

/// The least majorant of a cell while the extinction grid is
/// differentiated, over the largest extinction of the medium: the same
/// margin as [`MAJORANT_FACTOR`] adds where the density is at its largest.
pub(super) const TRACKED_FLOOR: f32 = 0.1;

/// An optical depth to the next tentative collision (in units of the
/// majorant times distance).
#[inline]
fn optical_depth(rng: &mut SampleStream) -> f32 {
    -(1.0 - rng.next_1d()).ln()
}

/// Whether the tracking weight σ_n / (m − mean σ) of a null collision is
/// 1 with no derivative (a grey extinction that carries none), so that it
/// need not be multiplied in.
#[inline]
fn null_is_one<R: ScalarReal>(sigma_t: Spectrum<R>) -> bool {
    let s = sigma_t.val();
    s.min_element() == s.max_element()
        && sigma_t.x.is_const()
        && sigma_t.y.is_const()
        && sigma_t.z.is_const()
}

pub(super) fn sample_free_flight<R: ScalarReal>(
    medium: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
    rng: &mut SampleStream,
) -> FreeFlight<R> {
    let mut weight = Spectrum::<R>::splat(R::cst(1.0));
    let mono = medium.sigma_t.is_mono();
    let mut walk = medium.segments(store, ray, t_max);
    let Some(mut seg) = walk.next() else {
        return FreeFlight::Pass { weight };
    };
    let mut tau = optical_depth(rng);
    let mut t = seg.t0;
    loop {
        let m = seg.majorant;
        let dt = tau / m;
        if t + dt >= seg.t1 {
            // the rest of the optical depth goes on to the next segment
            tau = (tau - (seg.t1 - t) * m).max(0.0);
            let Some(next) = walk.next() else {
                return FreeFlight::Pass { weight };
            };
            seg = next;
            t = seg.t0;
            continue;
        }
        t += dt;
        let p = ray.at(t);
        let sigma_t = medium.extinction::<R>(store, p);
        let mean = sigma_t.val().element_sum() / 3.0;
        if rng.next_1d() < mean / m {
            let albedo = medium.albedo.eval::<R>(store, p);
            let scatter = sigma_t.mul_elem(albedo) * R::cst(1.0 / mean);
            return FreeFlight::Scatter {
                t,
                p,
                weight: weight.mul_elem(scatter),
            };
        }
        if !null_is_one(sigma_t) {
            let k = R::cst(1.0 / (m - mean));
            weight = if mono {
                weight * ((R::cst(m) - sigma_t.x) * k)
            } else {
                weight.mul_elem(sigma_t.map(|s| (R::cst(m) - s) * k))
            };
        }
        tau = optical_depth(rng);
    }
}

pub(super) fn transmittance<R: ScalarReal>(
    medium: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
    rng: &mut SampleStream,
) -> Spectrum<R> {
    let mut tr = Spectrum::<R>::splat(R::cst(1.0));
    let mono = medium.sigma_t.is_mono();
    let mut walk = medium.segments(store, ray, t_max);
    let Some(mut seg) = walk.next() else {
        return tr;
    };
    let mut tau = optical_depth(rng);
    let mut t = seg.t0;
    loop {
        let m = seg.majorant;
        let dt = tau / m;
        if t + dt >= seg.t1 {
            tau = (tau - (seg.t1 - t) * m).max(0.0);
            let Some(next) = walk.next() else {
                return tr;
            };
            seg = next;
            t = seg.t0;
            continue;
        }
        t += dt;
        let sigma_t = medium.extinction::<R>(store, ray.at(t));
        let k = 1.0 / m;
        tr = if mono {
            tr * ((R::cst(m) - sigma_t.x) * k)
        } else {
            tr.mul_elem(sigma_t.map(|s| (R::cst(m) - s) * k))
        };
        // Without derivatives a zero estimate stays zero. With them it does
        // not end here: the derivative of a factor that is zero is not.
        if !R::DIFFERENTIABLE && tr.val() == glam::Vec3::ZERO {
            return tr;
        }
        tau = optical_depth(rng);
    }
}
