//! Orthogonal-array sampling (Mitsuba's `orthogonal`; Jarosz et al. 2019,
//! "Orthogonal array sampling for Monte Carlo rendering", EGSR).
//!
//! With n = p² samples (p prime), Bose's construction gives p + 1 columns
//! of an orthogonal array of strength 2: sample i = p·a₀ + a₁ has the
//! values a₀, a₁ and (a₀ + c·a₁) mod p for c = 1 … p − 1. Any two columns
//! take every pair of values exactly once, so every pair of dimensions is
//! stratified into p × p cells. Each dimension uses one column for its
//! stratum and a second column for the substratum inside it (the
//! multi-jittered refinement of the paper), so each dimension alone is
//! stratified into n intervals. Strata and substrata are shuffled by
//! hashed permutations per (pixel, dimension) and the sample order by one
//! per (pixel, group of p + 1 dimensions); the dimensions beyond the
//! array's p + 1 columns start a fresh, independently shuffled array.

use super::{independent::uniform, mix64, permute, round_up_warning};
use crate::error::Result;
use crate::scene::description::Node;

/// Orthogonal-array samples of strength 2; the sample count is rounded up
/// to the square of a prime.
#[derive(Clone, Debug)]
pub struct Orthogonal {
    pub sample_count: u32,
    pub seed: u64,
    /// Random position within each substratum (false: its centre).
    pub jitter: bool,
}

impl Orthogonal {
    pub fn from_node(node: &Node) -> Result<Orthogonal> {
        let requested = node.int_min("sample_count", 4, 1)? as u32;
        let sample_count = rounded_count(requested);
        round_up_warning(node, requested, sample_count, "the square of a prime");
        let strength = node.int_min("strength", 2, 1)?;
        if strength != 2 {
            crate::warn(format!(
                "{}: {node}: strength {strength} is not supported; Penumbra builds \
                 arrays of strength 2 (every pair of dimensions stratified), as \
                 Mitsuba recommends",
                node.loc
            ));
        }
        Ok(Orthogonal {
            sample_count,
            seed: node.int_min("seed", 0, 0)? as u64,
            jitter: node.bool("jitter", true)?,
        })
    }
}

fn is_prime(x: u32) -> bool {
    x >= 2
        && (2..)
            .take_while(|d| d * d <= x)
            .all(|d| !x.is_multiple_of(d))
}

/// The array's strata per dimension: the smallest prime p ≥ 2 with
/// p² ≥ `spp`.
fn prime_side(spp: u32) -> u32 {
    let mut p = 2;
    while p * p < spp || !is_prime(p) {
        p += 1;
    }
    p
}

/// The smallest square of a prime that is at least `spp` (Mitsuba's
/// rounding).
pub(crate) fn rounded_count(spp: u32) -> u32 {
    let p = prime_side(spp);
    p * p
}

/// Sample `index` of a pass of `spp` in dimension `dim`.
pub(crate) fn sample_1d(key: u64, index: u32, spp: u32, dim: u32, jitter: bool) -> f32 {
    let p = prime_side(spp);
    let n = p * p;
    let (group, column) = (dim / (p + 1), dim % (p + 1));
    let i = permute(
        index % n,
        n,
        mix64(key ^ ((group as u64) << 40) ^ 0x9b05688c2b3e6c1f) as u32,
    );
    let (a0, a1) = (i / p, i % p);
    // Bose: column 0 is a₀, column 1 is a₁, column c ≥ 2 is
    // a₀ + (c − 1)·a₁ mod p; no two columns are proportional, which is
    // what strength 2 needs
    let value = |c: u32| match c {
        0 => a0,
        1 => a1,
        c => (a0 + (c - 1) * a1) % p,
    };
    // the substratum column: the neighbour in the pairs (0,1), (2,3), …;
    // with an odd number of columns the last one pairs with column 0
    let partner = if column ^ 1 <= p { column ^ 1 } else { 0 };
    let h = mix64(key ^ ((dim as u64) << 40) ^ 0x1f83d9abfb41bd6b);
    let stratum = permute(value(column), p, h as u32);
    let sub = permute(value(partner), p, (h >> 32) as u32);
    let j = if jitter {
        uniform(key ^ 0x5be0cd19137e2179, index, dim)
    } else {
        0.5
    };
    ((stratum as f32 + (sub as f32 + j) / p as f32) / p as f32).min(1.0 - f32::EPSILON)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_count_rounds_like_mitsuba() {
        // measured with Mitsuba 3.9.1's `orthogonal`
        for (asked, got) in [
            (1, 4),
            (4, 4),
            (5, 9),
            (9, 9),
            (10, 25),
            (16, 25),
            (26, 49),
            (50, 121),
            (100, 121),
            (256, 289),
        ] {
            assert_eq!(rounded_count(asked), got, "{asked}");
        }
    }

    /// Strength 2 with the multi-jittered refinement: every pair of the
    /// first 2(p + 1) dimensions of the same array is stratified into
    /// p × p cells, and every dimension into n intervals.
    #[test]
    fn every_pair_of_dimensions_is_stratified() {
        for p in [2u32, 3, 5, 7] {
            let n = p * p;
            for key in [5u64, 808] {
                let pts: Vec<Vec<f32>> = (0..n)
                    .map(|i| (0..p + 1).map(|d| sample_1d(key, i, n, d, true)).collect())
                    .collect();
                for d in 0..=p {
                    let mut h = vec![0; n as usize];
                    for s in &pts {
                        h[(s[d as usize] * n as f32) as usize] += 1;
                    }
                    assert!(h.iter().all(|&c| c == 1), "p {p}, dim {d}: {h:?}");
                    for e in d + 1..=p {
                        let mut cells = vec![0; n as usize];
                        for s in &pts {
                            let (x, y) = (s[d as usize], s[e as usize]);
                            cells
                                [(y * p as f32) as usize * p as usize + (x * p as f32) as usize] +=
                                1;
                        }
                        assert!(cells.iter().all(|&c| c == 1), "p {p}, dims {d},{e}");
                    }
                }
            }
        }
    }
}
