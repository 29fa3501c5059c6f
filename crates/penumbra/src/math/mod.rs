//! Vectors, frames, transforms, warps and distributions.

mod distribution;
mod frame;
mod transform;
mod vector;
pub mod warp;

pub use distribution::{DiscreteDistribution, Distribution2D};
pub use frame::Frame;
pub use transform::Transform;
pub use vector::{Spectrum, V2, V3};

/// Offset applied along the normal to ray origins leaving a surface,
/// relative to the magnitude of the hit position (avoids self-intersection).
pub const RAY_EPSILON: f32 = 1e-4;
