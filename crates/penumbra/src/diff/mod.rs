//! Derivative estimators: forward (tangent) mode, path-replay reverse mode,
//! and (to come) boundary terms (docs/architecture.md §4). Forward mode
//! gives a derivative image for a tangent over the parameters; reverse mode
//! gives gradients for every differentiable parameter.

mod check;
mod forward;
mod prb;

pub use check::{check_gradient, CheckOptions, CheckReport, Estimate};
pub use forward::render_forward;
pub use prb::{render_backward, GradEntry, Gradients};

use crate::error::{Error, Result};
use crate::scene::Scene;

/// The seed of a gradient pass (reverse or forward mode) that follows a
/// render with seed `seed`, unless the caller sets one: `seed` with its low
/// 32 bits flipped by the golden-ratio constant `0x9e3779b9`.
///
/// Replaying the image's own samples would make the gradient of a
/// non-linear loss (L2) biased by the covariance of the image noise and
/// the derivative noise (Mitsuba's `seed_grad` exists for this reason).
/// The rule maps distinct seeds to distinct seeds, and small seeds (the
/// iteration counters of optimisation loops) far away from each other,
/// so no image seed of a loop is reused as a gradient seed.
pub fn gradient_seed(seed: u64) -> u64 {
    seed ^ 0x9e37_79b9
}

/// Fails if a parameter with a non-zero tangent or a requested gradient
/// moves visibility discontinuities (vertex positions, transforms): their
/// derivatives need boundary terms, which no integrator computes yet, and
/// an interior-only estimate would be silently wrong.
pub(crate) fn check_no_discontinuous(scene: &Scene, keys: &[&str]) -> Result<()> {
    for key in keys {
        let id = scene.params.require(key)?;
        if scene.params.get(id).flags.discontinuous {
            return Err(Error::Param {
                key: key.to_string(),
                msg: "derivatives with respect to geometry need boundary terms \
                      (silhouettes, shadow edges), which Penumbra's integrators do not \
                      compute yet; refusing to return an interior-only estimate"
                    .into(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::gradient_seed;

    #[test]
    fn gradient_seeds_differ_from_every_small_image_seed() {
        for seed in 0..100_000u64 {
            let g = gradient_seed(seed);
            assert_ne!(g, seed);
            assert!(
                g >= 100_000,
                "gradient seed {g} of {seed} is also a loop's image seed"
            );
            assert_eq!(gradient_seed(g), seed, "the rule is a bijection");
        }
    }
}
