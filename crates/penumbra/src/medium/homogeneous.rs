//! A medium with constant coefficients (Mitsuba's `homogeneous`).
//!
//! Distances are sampled in closed form. With an RGB extinction, a channel
//! c is picked uniformly and t is drawn from σ_c e^{-σ_c t}; the weight
//! divides by the density of the whole one-sample mixture over channels,
//! p(t) = mean_c σ_c e^{-σ_c t} (the balance heuristic over channels,
//! "spectral MIS"), so every channel stays unbiased. With a grey
//! extinction the weight of a scattering event is the albedo, that of a
//! pass 1, exactly. Transmittance is exp(-σ_t d), in closed form: the
//! expectation of any tracking estimator, without its variance.

use super::{FreeFlight, Medium};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::{Spectrum, V3};
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::description::{Node, Value};

/// A homogeneous medium's coefficients must be constants: refuses a
/// volume other than `constvolume` before it is built.
pub(super) fn check_constant(node: &Node) -> Result<()> {
    for name in ["sigma_t", "albedo"] {
        if let Some(p) = node.prop(name) {
            if matches!(&p.value, Value::Node(v) if v.plugin != "constvolume") {
                return Err(node.prop_error(
                    p,
                    "a homogeneous medium needs a constant (float, rgb, spectrum or \
                     constvolume); use a heterogeneous medium for a grid",
                ));
            }
        }
    }
    Ok(())
}

/// e^{-σ t} per channel, in `R`; at t = ∞, 1 where σ = 0 and 0 elsewhere
/// (a ray that leaves the scene inside a medium).
#[inline]
fn attenuation<R: ScalarReal>(sigma_t: Spectrum<R>, t: f32) -> Spectrum<R> {
    sigma_t.map(|s| {
        if t.is_finite() {
            (-(s * t)).exp()
        } else {
            R::cst(if s.val() == 0.0 { 1.0 } else { 0.0 })
        }
    })
}

pub(super) fn sample_free_flight<R: ScalarReal>(
    m: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
    rng: &mut SampleStream,
) -> FreeFlight<R> {
    let (sigma_t, albedo) = m.coefficients::<R>(store, ray.o);
    let s = sigma_t.val();
    let channel = ((rng.next_1d() * 3.0) as usize).min(2);
    let u = rng.next_1d();
    let t = -(1.0 - u).ln() / s[channel];
    if t < t_max {
        let density = (s * (-s * t).exp()).element_sum() / 3.0;
        let weight = attenuation(sigma_t, t).mul_elem(sigma_t.mul_elem(albedo));
        FreeFlight::Scatter {
            t,
            p: ray.at(t),
            weight: weight * R::cst(1.0 / density),
        }
    } else {
        let pass = attenuation::<f32>(V3::cst(s), t_max).val().element_sum() / 3.0;
        FreeFlight::Pass {
            weight: attenuation(sigma_t, t_max) * R::cst(1.0 / pass),
        }
    }
}

pub(super) fn transmittance<R: ScalarReal>(
    m: &Medium,
    store: &ParamView,
    ray: &Ray,
    t_max: f32,
) -> Spectrum<R> {
    attenuation(m.extinction::<R>(store, ray.o), t_max)
}
