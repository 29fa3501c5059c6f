//! Independent uniform samples (Mitsuba's `independent`).

use super::{mix64, to_unit};
use crate::error::Result;
use crate::scene::description::Node;
use glam::Vec2;

/// Uncorrelated uniform random numbers.
#[derive(Clone, Debug)]
pub struct Independent {
    pub sample_count: u32,
    pub seed: u64,
}

impl Independent {
    pub fn from_node(node: &Node) -> Result<Independent> {
        Ok(Independent {
            sample_count: node.int_min("sample_count", 4, 1)? as u32,
            seed: node.int_min("seed", 0, 0)? as u64,
        })
    }
}

/// SplitMix64's increment, ⌊2⁶⁴/φ⌋ (Steele, Lea, Flood 2014, "Fast
/// splittable pseudorandom number generators").
const GOLDEN: u64 = 0x9e3779b97f4a7c15;

/// The state of one sample's stream: (pixel key, sample index) hashed
/// once, so that each draw then costs one hash.
#[inline(always)]
pub(crate) fn sample_state(key: u64, index: u32) -> u64 {
    mix64(key ^ (index as u64 + 1).wrapping_mul(GOLDEN))
}

/// SplitMix64's output number `dim + 1` from `state`: a hash of the
/// position, so that any dimension is drawn without the ones before it.
#[inline(always)]
fn draw(state: u64, dim: u32) -> u64 {
    mix64(state.wrapping_add((dim as u64 + 1).wrapping_mul(GOLDEN)))
}

/// Uniform number of dimension `dim` of the stream `state`.
#[inline(always)]
pub(crate) fn uniform_1d(state: u64, dim: u32) -> f32 {
    to_unit(draw(state, dim))
}

/// Uniform point of dimensions `dim`, `dim + 1` of the stream `state`,
/// both from one hash: its top 24 bits and the 24 below them (the hash
/// mixes every output bit with every input bit, so the two are
/// independent).
#[inline(always)]
pub(crate) fn uniform_2d(state: u64, dim: u32) -> Vec2 {
    let bits = draw(state, dim);
    Vec2::new(to_unit(bits), to_unit(bits << 24))
}

/// Uniform number for (pixel key, sample index, dimension), for the
/// patterns that jitter or permute with independent numbers.
#[inline(always)]
pub(crate) fn uniform(key: u64, index: u32, dim: u32) -> f32 {
    uniform_1d(sample_state(key, index), dim)
}
