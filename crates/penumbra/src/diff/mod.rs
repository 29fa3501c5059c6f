//! Derivative estimators: forward (tangent) mode, and (to come) path-replay
//! reverse mode and boundary terms. They return through the doors fixed in
//! DESIGN.md §3: forward mode gives a derivative image for a tangent over
//! the parameters; reverse mode gives gradients for every differentiable
//! parameter.

mod check;
mod forward;
mod prb;

pub use check::{check_gradient, CheckOptions, CheckReport, Estimate};
pub use forward::render_forward;
pub use prb::{render_backward, GradEntry, Gradients};

use crate::error::{Error, Result};
use crate::scene::Scene;

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
