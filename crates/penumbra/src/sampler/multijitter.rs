//! Correlated multi-jittered sampling (Mitsuba's `multijitter`; Kensler
//! 2013, "Correlated Multi-Jittered Sampling", Pixar technical memo 13-01).
//!
//! The n samples of a pixel fill an nx × ny grid of cells (n = nx·ny); each
//! cell is further cut into ny columns and nx rows of substrata, and a
//! sample's substratum within its cell is chosen so that the n points are
//! also stratified into n intervals on each axis: the x substratum of cell
//! (x, y) is a permutation of y, the y substratum a permutation of x (the
//! shuffles are shared by a whole row or column: Kensler's "correlated"
//! variant, which keeps the points apart). Which sample lands in which
//! cell is a hashed permutation of the sample index per (pixel, dimension),
//! and every random choice derives from (seed, pixel), so different seeds
//! give independent patterns.

use super::{independent::uniform, mix64, permute, round_up_warning};
use crate::error::Result;
use crate::scene::description::Node;
use glam::Vec2;

/// Correlated multi-jittered samples; the sample count is rounded up to a
/// grid whose aspect ratio is close to 1.
#[derive(Clone, Debug)]
pub struct Multijitter {
    pub sample_count: u32,
    pub seed: u64,
    /// Random position within each substratum (false: its centre).
    pub jitter: bool,
}

impl Multijitter {
    pub fn from_node(node: &Node) -> Result<Multijitter> {
        let requested = node.int_min("sample_count", 4, 1)? as u32;
        let sample_count = rounded_count(requested);
        round_up_warning(
            node,
            requested,
            sample_count,
            "a grid of nearly square aspect",
        );
        Ok(Multijitter {
            sample_count,
            seed: node.int_min("seed", 0, 0)? as u64,
            jitter: node.bool("jitter", true)?,
        })
    }
}

/// The grid of `spp` samples, (columns nx, rows ny): ny = ⌊√spp⌋ and
/// nx = ⌈spp / ny⌉, as Mitsuba chooses it.
fn grid(spp: u32) -> (u32, u32) {
    let ny = ((spp.max(1) as f64).sqrt() as u32).max(1);
    (spp.max(1).div_ceil(ny), ny)
}

/// The smallest grid size that holds `spp` samples (Mitsuba's rounding).
pub(crate) fn rounded_count(spp: u32) -> u32 {
    let (nx, ny) = grid(spp);
    nx * ny
}

fn offset(key: u64, index: u32, dim: u32, jitter: bool) -> f32 {
    if jitter {
        uniform(key ^ 0x2545f4914f6cdd1d, index, dim)
    } else {
        0.5
    }
}

/// Per-(pixel, dimension) permutation seed, salted per use.
fn perm_seed(key: u64, dim: u32, salt: u64) -> u32 {
    mix64(key ^ ((dim as u64) << 40) ^ salt) as u32
}

/// Sample `index` of a pass of `spp` in 1D dimension `dim`: one sample per
/// interval of width 1/n, n the rounded count.
pub(crate) fn sample_1d(key: u64, index: u32, spp: u32, dim: u32, jitter: bool) -> f32 {
    let n = rounded_count(spp);
    let s = permute(index % n, n, perm_seed(key, dim, 0x6a09e667));
    ((s as f32 + offset(key, index, dim, jitter)) / n as f32).min(1.0 - f32::EPSILON)
}

/// Sample `index` of a pass of `spp` in the 2D dimension pair (`dim`,
/// `dim + 1`).
pub(crate) fn sample_2d(key: u64, index: u32, spp: u32, dim: u32, jitter: bool) -> Vec2 {
    let (nx, ny) = grid(spp);
    let cell = permute(index % (nx * ny), nx * ny, perm_seed(key, dim, 0xbb67ae85));
    let (x, y) = (cell % nx, cell / nx);
    // substrata: a column of the cell indexed by the row, a row by the column
    let sub_x = permute(y, ny, perm_seed(key, dim, 0x3c6ef372));
    let sub_y = permute(x, nx, perm_seed(key, dim, 0xa54ff53a));
    let jx = offset(key, index, dim, jitter);
    let jy = offset(key, index, dim + 1, jitter);
    Vec2::new(
        ((x as f32 + (sub_x as f32 + jx) / ny as f32) / nx as f32).min(1.0 - f32::EPSILON),
        ((y as f32 + (sub_y as f32 + jy) / nx as f32) / ny as f32).min(1.0 - f32::EPSILON),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_count_rounds_like_mitsuba() {
        // measured with Mitsuba 3.9.1's `multijitter`
        for (asked, got) in [
            (1, 1),
            (2, 2),
            (4, 4),
            (5, 6),
            (10, 12),
            (16, 16),
            (17, 20),
            (32, 35),
            (50, 56),
            (128, 132),
            (200, 210),
            (256, 256),
        ] {
            assert_eq!(rounded_count(asked), got, "{asked}");
        }
    }

    /// The defining property: within a pixel, the n points of a 2D
    /// dimension occupy every grid cell once and every one of the n
    /// intervals of each axis once; a 1D dimension every interval once.
    #[test]
    fn points_are_stratified_in_2d_and_in_both_projections() {
        for n in [4, 12, 16, 20] {
            for key in [1u64, 77, 12345] {
                let (nx, ny) = grid(n);
                let mut cells = vec![0; n as usize];
                let (mut px, mut py, mut p1) = (
                    vec![0; n as usize],
                    vec![0; n as usize],
                    vec![0; n as usize],
                );
                for i in 0..n {
                    let u = sample_2d(key, i, n, 2, true);
                    cells[(u.y * ny as f32) as usize * nx as usize + (u.x * nx as f32) as usize] +=
                        1;
                    px[(u.x * n as f32) as usize] += 1;
                    py[(u.y * n as f32) as usize] += 1;
                    p1[(sample_1d(key, i, n, 4, true) * n as f32) as usize] += 1;
                }
                for (what, h) in [("cells", cells), ("x", px), ("y", py), ("1d", p1)] {
                    assert!(h.iter().all(|&c| c == 1), "n {n}, {what}: {h:?}");
                }
            }
        }
    }
}
