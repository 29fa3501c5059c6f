//! Warps from the unit square to common domains, each with its density.
//! Sampling is plain f32: sampled points are constants for differentiation
//! (detached sampling, docs/architecture.md §1).

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

/// Shirley–Chiu concentric map from the square to the unit disk
/// (area-preserving, low distortion).
#[inline]
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let x = 2.0 * u.x - 1.0;
    let y = 2.0 * u.y - 1.0;
    if x == 0.0 && y == 0.0 {
        return Vec2::ZERO;
    }
    // Which of |x|, |y| is larger is a coin flip per sample: one division
    // and selects instead of two branches the processor cannot predict
    // (the same values as branching).
    let wide = x.abs() > y.abs();
    let (r, other) = if wide { (x, y) } else { (y, x) };
    let q = FRAC_PI_4 * (other / r);
    let phi = if wide { q } else { FRAC_PI_2 - q };
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// Cosine-weighted hemisphere around +z (Malley's method).
#[inline]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

#[inline]
pub fn square_to_cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 {
        v.z * FRAC_1_PI
    } else {
        0.0
    }
}

#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 0.25 * FRAC_1_PI;

#[inline]
pub fn square_to_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_HEMISPHERE_PDF: f32 = 0.5 * FRAC_1_PI;

/// Uniform directions in the cone of half-angle acos(cos_cutoff) around +z.
#[inline]
pub fn square_to_uniform_cone(u: Vec2, cos_cutoff: f32) -> Vec3 {
    let cos_theta = (1.0 - u.y) + u.y * cos_cutoff;
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u.x;
    Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta)
}

#[inline]
pub fn square_to_uniform_cone_pdf(v: Vec3, cos_cutoff: f32) -> f32 {
    if v.z >= cos_cutoff {
        1.0 / (2.0 * PI * (1.0 - cos_cutoff))
    } else {
        0.0
    }
}

/// Uniform barycentrics (b1, b2) on a triangle (Heitz 2019, "A
/// Low-Distortion Map Between Triangle and Square").
#[inline]
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let (mut b0, mut b1) = (u.x / 2.0, u.y / 2.0);
    let offset = b1 - b0;
    if offset > 0.0 {
        b1 += offset;
    } else {
        b0 -= offset;
    }
    Vec2::new(b0, b1)
}

/// Standard normal pair by the Box–Muller transform.
#[inline]
pub fn square_to_std_normal(u: Vec2) -> Vec2 {
    let r = (-2.0 * (1.0 - u.x).max(f32::MIN_POSITIVE).ln()).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec2::new(r * phi.cos(), r * phi.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> impl Iterator<Item = Vec2> {
        (0..n * n).map(move |i| {
            Vec2::new(
                ((i % n) as f32 + 0.5) / n as f32,
                ((i / n) as f32 + 0.5) / n as f32,
            )
        })
    }

    #[test]
    fn warps_land_in_their_domains() {
        for u in grid(64) {
            assert!(square_to_uniform_disk_concentric(u).length() <= 1.0 + 1e-6);
            let c = square_to_cosine_hemisphere(u);
            assert!((c.length() - 1.0).abs() < 1e-5 && c.z >= 0.0);
            assert!((square_to_uniform_sphere(u).length() - 1.0).abs() < 1e-5);
            let k = square_to_uniform_cone(u, 0.8);
            assert!(k.z >= 0.8 - 1e-6 && (k.length() - 1.0).abs() < 1e-5);
            let b = square_to_uniform_triangle(u);
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }

    /// The cosine-hemisphere pdf integrates to one against uniform
    /// sphere sampling (midpoint rule over a fine grid).
    #[test]
    fn cosine_pdf_integrates_to_one() {
        let n = 512;
        let sum: f64 = grid(n)
            .map(|u| square_to_cosine_hemisphere_pdf(square_to_uniform_sphere(u)) as f64)
            .sum();
        let integral = sum / (n * n) as f64 / UNIFORM_SPHERE_PDF as f64;
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
    }

    /// The triangle warp is uniform: equal counts in the four sub-triangles
    /// made by the edge midpoints.
    #[test]
    fn triangle_warp_is_uniform() {
        let mut counts = [0usize; 4];
        for u in grid(200) {
            let b = square_to_uniform_triangle(u);
            let b0 = 1.0 - b.x - b.y;
            let k = if b.x > 0.5 {
                0
            } else if b.y > 0.5 {
                1
            } else if b0 > 0.5 {
                2
            } else {
                3
            };
            counts[k] += 1;
        }
        for c in counts {
            assert!((c as f64 / 40000.0 - 0.25).abs() < 0.01, "{counts:?}");
        }
    }
}
