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

/// `x.ceil() as i64` (saturating; NaN gives 0): the truncation corrected
/// by a comparison, without the call to `ceilf` that a build for baseline
/// x86-64 (no SSE4.1 `roundss`) makes: the film's footprints, texel and
/// voxel look-ups do this per sample.
#[inline(always)]
pub(crate) fn ceil_i64(x: f32) -> i64 {
    let t = x as i64;
    t.saturating_add(((t as f32) < x) as i64)
}

/// `x.floor() as i64`, as [`ceil_i64`].
#[inline(always)]
pub(crate) fn floor_i64(x: f32) -> i64 {
    let t = x as i64;
    t.saturating_sub(((t as f32) > x) as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_ceil_and_floor_match_the_float_ones() {
        let mut xs = vec![0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e-30, -1e-30];
        xs.extend([8388607.5, -8388607.5, 16777216.0, 3e9, -3e9, 1e30, -1e30]);
        xs.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
        xs.extend((-400..400).map(|k| k as f32 * 0.37 + 0.01));
        for x in xs {
            assert_eq!(ceil_i64(x), x.ceil() as i64, "ceil {x}");
            assert_eq!(floor_i64(x), x.floor() as i64, "floor {x}");
        }
    }
}
