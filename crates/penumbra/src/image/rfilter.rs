//! Reconstruction filters (Mitsuba's `rfilter` plugins). Samples are
//! splatted to every pixel whose centre lies within the filter radius,
//! weighted by the separable filter; each pixel is the weighted mean.

use crate::error::Result;
use crate::scene::Node;

/// A separable reconstruction filter.
#[derive(Clone, Debug, PartialEq)]
pub enum ReconstructionFilter {
    /// Radius 0.5: each sample counts for its own pixel only.
    Box,
    /// `max(0, 1 - |x| / r)`, radius r (default 1).
    Tent { radius: f32 },
    /// Truncated Gaussian `max(0, exp(-x²/2σ²) - exp(-r²/2σ²))` with
    /// r = 4σ (default σ = 0.5), as Mitsuba 3 defines it.
    Gaussian { stddev: f32, radius: f32 },
}

impl ReconstructionFilter {
    pub fn from_node(node: &Node) -> Result<ReconstructionFilter> {
        let f = match node.plugin.as_str() {
            "box" => ReconstructionFilter::Box,
            "tent" => ReconstructionFilter::Tent {
                radius: node.float_checked("radius", 1.0, true)?,
            },
            "gaussian" => {
                let stddev = node.float_checked("stddev", 0.5, true)?;
                ReconstructionFilter::Gaussian {
                    stddev,
                    radius: 4.0 * stddev,
                }
            }
            other => {
                return Err(node.error(format!(
                    "unknown rfilter plugin '{other}' (Penumbra has: box, tent, gaussian)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(f)
    }

    pub fn radius(&self) -> f32 {
        match self {
            ReconstructionFilter::Box => 0.5,
            ReconstructionFilter::Tent { radius } => *radius,
            ReconstructionFilter::Gaussian { radius, .. } => *radius,
        }
    }

    /// The 1D filter at offset `x` (pixels) from the pixel centre.
    #[inline]
    pub fn eval(&self, x: f32) -> f32 {
        match self {
            ReconstructionFilter::Box => {
                if x.abs() <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            ReconstructionFilter::Tent { radius } => (1.0 - x.abs() / radius).max(0.0),
            ReconstructionFilter::Gaussian { stddev, radius } => {
                let alpha = -1.0 / (2.0 * stddev * stddev);
                ((alpha * x * x).exp() - (alpha * radius * radius).exp()).max(0.0)
            }
        }
    }

    /// The 1D filter at the centres of pixels `first, first + 1, …` (one
    /// per element of `out`) seen from position `c`, i.e. at offsets
    /// `(first + k) + 0.5 - c`: the same values as
    /// [`ReconstructionFilter::eval`], with the per-filter constants
    /// computed once.
    #[inline]
    pub fn eval_span(&self, first: i64, c: f32, out: &mut [f32]) {
        match self {
            ReconstructionFilter::Gaussian { stddev, radius } => {
                let alpha = -1.0 / (2.0 * stddev * stddev);
                let cut = (alpha * radius * radius).exp();
                for (k, o) in out.iter_mut().enumerate() {
                    let x = (first + k as i64) as f32 + 0.5 - c;
                    *o = ((alpha * x * x).exp() - cut).max(0.0);
                }
            }
            _ => {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = self.eval((first + k as i64) as f32 + 0.5 - c);
                }
            }
        }
    }

    /// Pixels (beyond a sample's own) that one sample can reach on each
    /// side: `ceil(radius - 0.5)`.
    pub fn border(&self) -> usize {
        (self.radius() - 0.5).max(0.0).ceil() as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eval_span_equals_eval_exactly() {
        let filters = [
            ReconstructionFilter::Box,
            ReconstructionFilter::Tent { radius: 1.5 },
            ReconstructionFilter::Gaussian {
                stddev: 0.5,
                radius: 2.0,
            },
            ReconstructionFilter::Gaussian {
                stddev: 1.3,
                radius: 5.2,
            },
        ];
        for f in &filters {
            for (first, c) in [(-3i64, -1.37f32), (10, 12.01), (254, 255.999), (0, 0.5)] {
                let mut out = [0.0f32; 9];
                f.eval_span(first, c, &mut out);
                for (k, &v) in out.iter().enumerate() {
                    let want = f.eval((first + k as i64) as f32 + 0.5 - c);
                    assert_eq!(
                        v.to_bits(),
                        want.to_bits(),
                        "{f:?} at pixel {}",
                        first + k as i64
                    );
                }
            }
        }
    }
}
