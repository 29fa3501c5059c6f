//! Warps from the unit square to common domains, each with its density.
//! Sampling is primal: sampled points are constants for differentiation
//! (detached sampling, docs/architecture.md §1), computed in `f32` or, for
//! the warps written over [`Float`], in lanes.

use crate::ad::Float;
use crate::math::{V2, V3};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

/// Shirley–Chiu concentric map from the square to the unit disk
/// (area-preserving, low distortion).
#[inline(always)]
pub fn square_to_uniform_disk_concentric<F: Float>(u: V2<F>) -> V2<F> {
    let x = u.x * 2.0 - 1.0;
    let y = u.y * 2.0 - 1.0;
    // Which of |x|, |y| is larger is a coin flip per sample: one division
    // and selects instead of two branches the processor cannot predict.
    let wide = x.abs().gt(y.abs());
    let (r, other) = (F::select(wide, x, y), F::select(wide, y, x));
    // φ = q when |x| is larger, π/2 − q otherwise, and cos(π/2 − q) =
    // sin q: one sine and cosine of |q| ≤ π/4, by polynomial
    let (sin_q, cos_q) = sin_cos_quarter(other / r * FRAC_PI_4);
    let (c, s) = (F::select(wide, cos_q, sin_q), F::select(wide, sin_q, cos_q));
    // the centre (where other / r is 0 / 0)
    let centre = x.equals(0.0) & y.equals(0.0);
    let zero = F::cst(0.0);
    V2::new(
        F::select(centre, zero, r * c),
        F::select(centre, zero, r * s),
    )
}

/// Sine and cosine of 2πu for u in [0, 1] (an angle in turns, as the
/// warps draw it): the nearest quarter turn j and the rest x = 2πu − jπ/2
/// in [−π/4, π/4] (exact but for one rounding), the rest's sine and cosine
/// by [`sin_cos_quarter`], turned by j quarters (a swap and sign flips,
/// without branches). Within 1.5e-7 of the exact values; libm's `sincosf`
/// of a rounded 2πu is no closer (2πu itself is off by up to 2.4e-7).
#[inline(always)]
pub fn sin_cos_turns(u: f32) -> (f32, f32) {
    let t = 4.0 * u;
    let j = (t + 0.5) as u32;
    let (s, c) = sin_cos_quarter((t - j as f32) * FRAC_PI_2);
    let (a, b) = if j & 1 == 0 { (s, c) } else { (c, s) };
    // quarters 2 and 3 negate the sine, quarters 1 and 2 the cosine
    let flip = |v: f32, bit: u32| f32::from_bits(v.to_bits() ^ ((bit & 2) << 30));
    (flip(a, j), flip(b, j + 1))
}

/// Sine and cosine of `x` in [−π/4, π/4] (within 2 ulp there) by the
/// minimax polynomials of Cephes' single-precision `sinf`/`cosf`
/// (S. Moshier, "Methods and Programs for Mathematical Functions", 1989),
/// which need no range reduction on this interval: a few multiply-adds
/// instead of a call to libm's `sincosf`, on the path of every diffuse
/// bounce.
#[inline(always)]
fn sin_cos_quarter<F: Float>(x: F) -> (F, F) {
    let z = x * x;
    let sin = ((z * -1.951_529_6e-4 + 8.332_161e-3) * z - 1.666_665_5e-1) * z * x + x;
    let cos = ((z * 2.443_315_7e-5 - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - z * 0.5 + 1.0;
    (sin, cos)
}

/// Cosine-weighted hemisphere around +z (Malley's method).
#[inline(always)]
pub fn square_to_cosine_hemisphere<F: Float>(u: V2<F>) -> V3<F> {
    let d = square_to_uniform_disk_concentric(u);
    let z = (F::cst(1.0) - (d.x * d.x + d.y * d.y))
        .max(F::cst(0.0))
        .sqrt();
    V3::new(d.x, d.y, z)
}

#[inline(always)]
pub fn square_to_cosine_hemisphere_pdf<F: Float>(v: V3<F>) -> F {
    F::select(v.z.gt(0.0), v.z * FRAC_1_PI, F::cst(0.0))
}

#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turns(u.x);
    Vec3::new(r * cos_phi, r * sin_phi, z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 0.25 * FRAC_1_PI;

#[inline]
pub fn square_to_uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turns(u.x);
    Vec3::new(r * cos_phi, r * sin_phi, z)
}

pub const UNIFORM_HEMISPHERE_PDF: f32 = 0.5 * FRAC_1_PI;

/// Uniform directions in the cone of half-angle acos(cos_cutoff) around +z.
#[inline]
pub fn square_to_uniform_cone(u: Vec2, cos_cutoff: f32) -> Vec3 {
    let cos_theta = (1.0 - u.y) + u.y * cos_cutoff;
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (sin_phi, cos_phi) = sin_cos_turns(u.x);
    Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
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
    let (sin_phi, cos_phi) = sin_cos_turns(u.y);
    Vec2::new(r * cos_phi, r * sin_phi)
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

    /// The warps written over `Float` give, in 8 and 16 lanes, each lane's
    /// `f32` value bit for bit (the centre and the diagonals included).
    #[test]
    fn lane_warps_equal_the_scalar_ones() {
        use crate::ad::lanes::Lanes;
        fn check<const N: usize>(us: &[Vec2]) {
            for chunk in us.chunks(N) {
                let lane = |i: usize, f: fn(Vec2) -> f32| f(chunk[i.min(chunk.len() - 1)]);
                let u = V2::new(
                    Lanes::<N>::from_fn(|i| lane(i, |v| v.x)),
                    Lanes::from_fn(|i| lane(i, |v| v.y)),
                );
                let d = square_to_uniform_disk_concentric(u);
                let h = square_to_cosine_hemisphere(u);
                let p = square_to_cosine_hemisphere_pdf(V3::new(h.x, h.y, h.z - 0.5));
                for (i, &c) in chunk.iter().enumerate() {
                    let ui = V2::from(c);
                    let (ds, hs) = (
                        square_to_uniform_disk_concentric(ui),
                        square_to_cosine_hemisphere(ui),
                    );
                    let ps = square_to_cosine_hemisphere_pdf(V3::new(hs.x, hs.y, hs.z - 0.5));
                    let lanes = [d.x.0[i], d.y.0[i], h.x.0[i], h.y.0[i], h.z.0[i], p.0[i]];
                    let scalar = [ds.x, ds.y, hs.x, hs.y, hs.z, ps];
                    for (a, b) in lanes.iter().zip(scalar) {
                        assert_eq!(a.to_bits(), b.to_bits(), "u = {c:?}");
                    }
                }
            }
        }
        let mut us: Vec<Vec2> = grid(37).collect();
        us.extend([
            Vec2::splat(0.5),
            Vec2::ZERO,
            Vec2::ONE,
            Vec2::new(0.25, 0.25),
            Vec2::new(0.5, 0.9),
        ]);
        check::<8>(&us);
        check::<16>(&us);
    }

    /// The polynomial sine and cosine against f64 on a dense grid of
    /// [−π/4, π/4]: within 2 ulp of the exact value (relative to the
    /// larger of the value and the smallest normal, as near zero the sine
    /// is its argument).
    #[test]
    fn quarter_sine_and_cosine_are_within_two_ulp() {
        let n = 200_001;
        for i in 0..n {
            let x = FRAC_PI_4 * (2.0 * i as f32 / (n - 1) as f32 - 1.0);
            let (s, c) = sin_cos_quarter(x);
            let (se, ce) = (x as f64).sin_cos();
            for (got, exact) in [(s, se), (c, ce)] {
                let ulp = f32::EPSILON as f64 * exact.abs().max(f32::MIN_POSITIVE as f64);
                assert!(
                    (got as f64 - exact).abs() <= 2.0 * ulp,
                    "x = {x}: {got} against {exact}"
                );
            }
        }
    }

    /// 2πu's sine and cosine against f64 on a dense grid of [0, 1],
    /// within the bound of [`sin_cos_turns`]: 2 ulp of a value below one
    /// (1.2e-7) and the rounding of the rest x (3e-8).
    #[test]
    fn sine_and_cosine_of_turns_are_within_the_bound() {
        let n = 400_001;
        for i in 0..n {
            let u = i as f32 / (n - 1) as f32;
            let (s, c) = sin_cos_turns(u);
            let (se, ce) = (std::f64::consts::TAU * u as f64).sin_cos();
            assert!(
                (s as f64 - se).abs() <= 1.5e-7 && (c as f64 - ce).abs() <= 1.5e-7,
                "u = {u}: ({s}, {c}) against ({se}, {ce})"
            );
        }
    }

    /// The concentric map against its definition in f64 (Shirley and
    /// Chiu 1997): φ = π/4 · y/x or π/2 − π/4 · x/y.
    #[test]
    fn concentric_disk_matches_its_definition() {
        for u in grid(300) {
            let d = Vec2::from(square_to_uniform_disk_concentric(u.into()));
            let (x, y) = (2.0 * u.x as f64 - 1.0, 2.0 * u.y as f64 - 1.0);
            let (r, phi) = if x.abs() > y.abs() {
                (x, std::f64::consts::FRAC_PI_4 * (y / x))
            } else {
                (
                    y,
                    std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (x / y),
                )
            };
            let e = (r * phi.cos(), r * phi.sin());
            assert!(
                (d.x as f64 - e.0).abs() < 3e-7 && (d.y as f64 - e.1).abs() < 3e-7,
                "{u}: {d} against {e:?}"
            );
        }
    }

    #[test]
    fn warps_land_in_their_domains() {
        for u in grid(64) {
            assert!(Vec2::from(square_to_uniform_disk_concentric(u.into())).length() <= 1.0 + 1e-6);
            let c = Vec3::from(square_to_cosine_hemisphere(u.into()));
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
            .map(|u| square_to_cosine_hemisphere_pdf(square_to_uniform_sphere(u).into()) as f64)
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
