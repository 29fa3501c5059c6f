//! The isotropic phase function (Mitsuba's `isotropic`): every direction
//! equally likely.

use crate::math::warp::square_to_uniform_sphere;
use glam::{Vec2, Vec3};

/// Its value and density: 1 / 4π per steradian.
pub(super) const DENSITY: f32 = 1.0 / (4.0 * std::f32::consts::PI);

/// A uniform direction on the sphere and its density.
#[inline]
pub(super) fn sample(u: Vec2) -> (Vec3, f32) {
    (square_to_uniform_sphere(u), DENSITY)
}
