//! Test utilities shared by the plugin tests: a Pearson χ² goodness-of-fit
//! test of direction samplers against their densities, as used by pbrt and
//! Mitsuba to validate importance sampling, and the lookup of the
//! repository's test data.

use glam::{Vec2, Vec3};
use std::f64::consts::PI;
use std::path::PathBuf;

/// A data file of the repository (`rel` is relative to its root, e.g.
/// `scenes/meshes/icosphere3.ply`). Panics naming the file when it is
/// missing: a test without its data fails, it never skips.
pub fn repo_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(rel);
    assert!(
        p.exists(),
        "test data {} is missing (expected at {}); it is part of the repository",
        rel,
        p.display()
    );
    p
}

/// A small deterministic generator for tests (PCG32, O'Neill 2014).
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

impl Pcg32 {
    pub fn new(seed: u64) -> Pcg32 {
        let mut r = Pcg32 {
            state: 0,
            inc: (seed << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(0x853c49e6748fea9b ^ seed);
        r.next_u32();
        r
    }
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }
    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }
}

/// ln Γ(x) for x > 0 (Lanczos approximation, g = 7, n = 9).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // reflection formula
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Upper regularised incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a):
/// by its power series for x < a + 1, else by its continued fraction
/// (modified Lentz evaluation).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_pre = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        // P(a,x) = e^{-x} x^a / Γ(a) · Σ x^n / (a (a+1) … (a+n))
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * ln_pre.exp()
    } else {
        // Q(a,x) = e^{-x} x^a / Γ(a) · 1/(x+1-a- 1·(1-a)/(x+3-a- 2(2-a)/(x+5-a- …)))
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        ln_pre.exp() * h
    }
}

/// Outcome of a χ² test (printed by failing assertions).
#[derive(Debug)]
#[allow(dead_code)] // statistic, dof and accepted are read through Debug
pub struct Chi2Result {
    pub p_value: f64,
    pub statistic: f64,
    pub dof: usize,
    /// ∫ pdf over the sphere (≤ 1; < 1 when delta lobes carry mass).
    pub pdf_integral: f64,
    /// Fraction of samples that were returned (not rejected).
    pub accepted: f64,
}

/// Pearson χ² test of a direction sampler against its solid-angle density
/// on the unit sphere, binned in (cos θ, φ) so that all bins have equal
/// solid angle.
///
/// `sample(rng)` draws one direction (or `None` when the sampler fails or
/// picks a delta lobe, which `pdf` does not describe); `pdf(w)` is the
/// density of the smooth part. Expected counts integrate `pdf` over each bin
/// with a fine midpoint rule; bins expecting fewer than 5 samples are pooled
/// (Cochran's rule).
pub struct Chi2Test {
    pub cos_theta_bins: usize,
    pub phi_bins: usize,
    /// Sub-samples per bin side for integrating the pdf.
    pub integration_res: usize,
    pub samples: usize,
    pub seed: u64,
}

impl Default for Chi2Test {
    fn default() -> Self {
        Chi2Test {
            cos_theta_bins: 20,
            phi_bins: 40,
            integration_res: 12,
            samples: 200_000,
            seed: 7,
        }
    }
}

impl Chi2Test {
    fn bin_of(&self, w: Vec3) -> usize {
        let z = (w.z as f64).clamp(-1.0, 1.0);
        let ti =
            (((z + 1.0) * 0.5 * self.cos_theta_bins as f64) as usize).min(self.cos_theta_bins - 1);
        let mut phi = (w.y as f64).atan2(w.x as f64);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let pi = ((phi / (2.0 * PI) * self.phi_bins as f64) as usize).min(self.phi_bins - 1);
        ti * self.phi_bins + pi
    }

    pub fn run(
        &self,
        mut sample: impl FnMut(&mut Pcg32) -> Option<Vec3>,
        pdf: impl Fn(Vec3) -> f32,
    ) -> Chi2Result {
        let nb = self.cos_theta_bins * self.phi_bins;
        let mut observed = vec![0.0f64; nb];
        let mut rng = Pcg32::new(self.seed);
        let mut accepted = 0usize;
        for _ in 0..self.samples {
            if let Some(w) = sample(&mut rng) {
                assert!(
                    (w.length() - 1.0).abs() < 1e-3,
                    "sampled direction is not unit length: {w:?}"
                );
                observed[self.bin_of(w)] += 1.0;
                accepted += 1;
            }
        }
        // expected counts: N ∫_bin pdf dω, with dω = d(cos θ) dφ
        let res = self.integration_res;
        let dz = 2.0 / (self.cos_theta_bins * res) as f64;
        let dphi = 2.0 * PI / (self.phi_bins * res) as f64;
        let mut expected = vec![0.0f64; nb];
        let mut integral = 0.0;
        for ti in 0..self.cos_theta_bins * res {
            let z = -1.0 + (ti as f64 + 0.5) * dz;
            let r = (1.0 - z * z).max(0.0).sqrt();
            for pi in 0..self.phi_bins * res {
                let phi = (pi as f64 + 0.5) * dphi;
                let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                let p = pdf(w) as f64;
                assert!(p >= 0.0 && p.is_finite(), "pdf({w:?}) = {p}");
                let mass = p * dz * dphi;
                integral += mass;
                let b = (ti / res) * self.phi_bins + pi / res;
                expected[b] += mass * self.samples as f64;
            }
        }
        // pool small bins
        let (mut stat, mut dof) = (0.0, 0usize);
        let (mut pool_o, mut pool_e) = (0.0, 0.0);
        for b in 0..nb {
            if expected[b] < 5.0 {
                pool_o += observed[b];
                pool_e += expected[b];
            } else {
                stat += (observed[b] - expected[b]).powi(2) / expected[b];
                dof += 1;
            }
        }
        if pool_e > 0.0 {
            stat += (pool_o - pool_e).powi(2) / pool_e;
            dof += 1;
        } else if pool_o > 0.0 {
            // samples where the pdf is zero: certain failure
            stat = f64::INFINITY;
        }
        let dof = dof.saturating_sub(1).max(1);
        Chi2Result {
            p_value: gamma_q(dof as f64 / 2.0, stat / 2.0),
            statistic: stat,
            dof,
            pdf_integral: integral,
            accepted: accepted as f64 / self.samples as f64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::warp;

    #[test]
    fn gamma_q_matches_known_values() {
        // Q(1, x) = e^{-x}; Q(k/2, x/2) is the χ² survival function
        for x in [0.1, 1.0, 3.0, 10.0] {
            assert!((gamma_q(1.0, x) - (-x).exp()).abs() < 1e-10);
        }
        // χ² with 10 dof: P(X > 18.307) = 0.05
        assert!((gamma_q(5.0, 18.307 / 2.0) - 0.05).abs() < 1e-4);
        // 100 dof: P(X > 124.342) = 0.05
        assert!((gamma_q(50.0, 124.342 / 2.0) - 0.05).abs() < 1e-4);
    }

    #[test]
    fn accepts_a_correct_sampler_and_rejects_a_wrong_one() {
        let t = Chi2Test::default();
        let ok = t.run(
            |r| {
                Some(Vec3::from(warp::square_to_cosine_hemisphere(
                    r.next_2d().into(),
                )))
            },
            |v| warp::square_to_cosine_hemisphere_pdf(v.into()),
        );
        assert!(ok.p_value > 0.01, "{ok:?}");
        assert!((ok.pdf_integral - 1.0).abs() < 1e-3);
        // uniform hemisphere samples tested against the cosine density
        let bad = t.run(
            |r| Some(warp::square_to_uniform_hemisphere(r.next_2d())),
            |v| warp::square_to_cosine_hemisphere_pdf(v.into()),
        );
        assert!(bad.p_value < 1e-6, "{bad:?}");
    }
}
