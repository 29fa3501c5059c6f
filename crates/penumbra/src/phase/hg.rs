//! The Henyey-Greenstein phase function (Henyey & Greenstein 1941;
//! Mitsuba's `hg`), parameterised by its mean cosine g ∈ (-1, 1): g > 0
//! scatters forward, g < 0 backward, g = 0 is isotropic.

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::math::{Frame, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Below this |g| the inversion of the CDF divides by ~0: sample uniformly
/// (the distribution is uniform to first order there).
const NEARLY_ISOTROPIC: f32 = 1e-3;

/// The anisotropy is parameter `<key>.g` (domain (-1, 1)).
#[derive(Clone, Debug)]
pub struct HenyeyGreenstein {
    pub g: ParamId,
}

impl HenyeyGreenstein {
    pub fn from_node(node: &Node, key: &str, ctx: &mut LoadContext) -> Result<Self> {
        let g = node.float("g", 0.8)?;
        let g = ctx
            .store
            .add(
                format!("{key}.g"),
                vec![g],
                vec![1],
                ParamFlags::DIFFERENTIABLE,
                Domain::OpenSignedUnit,
            )
            .map_err(|e| {
                node.prop("g")
                    .map_or_else(|| node.error(&e), |p| node.prop_error(p, &e))
            })?;
        Ok(HenyeyGreenstein { g })
    }

    /// (1 − g²) / (4π (1 + g² + 2g ⟨wi, wo⟩)^{3/2}): with `wi` pointing
    /// back along the incoming ray, ⟨wi, wo⟩ = −cos θ of the deflection.
    #[inline]
    pub fn eval<R: ScalarReal>(&self, store: &ParamView, wi: Vec3, wo: V3<R>) -> R {
        let g: R = store.read(self.g, 0);
        let cos = wo.dot(V3::cst(wi));
        let denom = R::cst(1.0) + g * g + g * cos * 2.0;
        (R::cst(1.0) - g * g) / (denom * denom.sqrt() * (4.0 * PI))
    }

    pub fn pdf(&self, store: &ParamStore, wi: Vec3, wo: Vec3) -> f32 {
        self.eval::<f32>(&store.primal(), wi, V3::cst(wo))
    }

    /// Inverts the CDF of the deflection cosine (Pharr et al., PBRT 4th
    /// ed., §11.3.1); the azimuth is uniform.
    pub fn sample(&self, store: &ParamStore, wi: Vec3, u: Vec2) -> (Vec3, f32) {
        let g = store.value(self.g, 0);
        let cos_deflection = if g.abs() < NEARLY_ISOTROPIC {
            1.0 - 2.0 * u.x
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin = (1.0 - cos_deflection * cos_deflection).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        // deflection measured from the direction of travel, −wi
        let frame = Frame::<f32>::from_normal(V3::cst(-wi));
        let local = V3::cst(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos_deflection));
        let wo = frame.to_world(local).val().normalize();
        (wo, self.pdf(store, wi, wo))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::description::{Class, Value};
    use crate::texture::test_node;

    fn hg(g: f32) -> (HenyeyGreenstein, ParamStore) {
        let node = test_node(Class::Phase, "hg", "p", vec![("g", Value::Float(g as f64))]);
        let mut ctx = LoadContext::default();
        let p = HenyeyGreenstein::from_node(&node, "m.phase_function", &mut ctx).unwrap();
        (p, ctx.store)
    }

    /// The density integrates to one over the sphere and its mean cosine
    /// (along the direction of travel) is g.
    #[test]
    fn normalised_with_mean_cosine_g() {
        for g in [-0.7f32, 0.0, 0.3, 0.7] {
            let (p, store) = hg(g);
            let wi = Vec3::new(0.3, -0.5, 0.8).normalize();
            let n = 400;
            let (mut total, mut mean_cos) = (0.0f64, 0.0f64);
            for i in 0..n {
                for j in 0..2 * n {
                    // midpoint rule in (cos, φ) about −wi
                    let c = -1.0 + 2.0 * (i as f32 + 0.5) / n as f32;
                    let phi = PI * (j as f32 + 0.5) / n as f32;
                    let s = (1.0 - c * c).sqrt();
                    let f = Frame::<f32>::from_normal(V3::cst(-wi));
                    let wo = f
                        .to_world(V3::cst(Vec3::new(s * phi.cos(), s * phi.sin(), c)))
                        .val();
                    let w =
                        p.pdf(&store, wi, wo) as f64 * (2.0 / n as f64) * (PI as f64 / n as f64);
                    total += w;
                    mean_cos += w * c as f64;
                }
            }
            assert!((total - 1.0).abs() < 1e-3, "g {g}: ∫ p = {total}");
            assert!(
                (mean_cos - g as f64).abs() < 2e-3,
                "g {g}: mean cos {mean_cos}"
            );
        }
    }

    /// χ² test of the sampled deflection cosines against the density
    /// (20 bins of cos θ, 100 000 samples: the statistic of a correct
    /// sampler exceeds 50 with probability < 1e-4 at 19 degrees of freedom).
    #[test]
    fn sampling_matches_the_density_chi2() {
        for g in [-0.7f32, 0.0, 0.7] {
            let (p, store) = hg(g);
            let wi = Vec3::new(-0.2, 0.9, 0.1).normalize();
            let bins = 20;
            let n = 100_000;
            let mut counts = vec![0f64; bins];
            let mut rng = crate::testing::Pcg32::new(7);
            for _ in 0..n {
                let (wo, pdf) = p.sample(&store, wi, rng.next_2d());
                assert!((pdf - p.pdf(&store, wi, wo)).abs() <= 1e-4 * pdf.max(1.0));
                let c = (-wo.dot(wi)).clamp(-1.0, 1.0);
                let b = (((c + 1.0) / 2.0 * bins as f32) as usize).min(bins - 1);
                counts[b] += 1.0;
            }
            // expected counts from the closed-form CDF of the cosine
            let cdf = |c: f32| -> f64 {
                if g == 0.0 {
                    return ((c + 1.0) / 2.0) as f64;
                }
                let g = g as f64;
                let c = c as f64;
                (1.0 - g * g) / (2.0 * g)
                    * (1.0 / (1.0 + g * g - 2.0 * g * c).sqrt() - 1.0 / (1.0 + g))
            };
            let mut chi2 = 0.0;
            for (b, &observed) in counts.iter().enumerate() {
                let lo = -1.0 + 2.0 * b as f32 / bins as f32;
                let hi = -1.0 + 2.0 * (b + 1) as f32 / bins as f32;
                let expected = n as f64 * (cdf(hi) - cdf(lo));
                chi2 += (observed - expected).powi(2) / expected;
            }
            assert!(chi2 < 50.0, "g {g}: χ² = {chi2}");
        }
    }
}
