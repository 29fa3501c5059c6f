//! Penumbra: a physics-based differentiable Monte Carlo renderer.
//!
//! See `docs/architecture.md` in the repository for the architecture and the
//! mathematics (interior vs boundary derivatives, detached sampling, path
//! replay) that the code follows.

// `!(x > 0.0)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod ad;
pub mod bsdf;
pub mod diff;
pub mod emitter;
pub mod error;
pub mod geometry;
pub mod image;
pub mod integrator;
pub mod math;
pub mod medium;
pub mod optim;
pub mod params;
pub mod phase;
pub mod sampler;
pub mod scene;
pub mod sensor;
#[cfg(test)]
pub(crate) mod testing;
pub mod texture;
pub mod volume;
pub mod warn;

pub use error::{Error, Result};
pub use warn::warn;
