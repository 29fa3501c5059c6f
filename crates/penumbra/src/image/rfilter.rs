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

    /// Pixels (beyond a sample's own) that one sample can reach on each
    /// side: `ceil(radius - 0.5)`.
    pub fn border(&self) -> usize {
        (self.radius() - 0.5).max(0.0).ceil() as usize
    }
}
