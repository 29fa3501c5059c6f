//! Independent uniform samples (Mitsuba's `independent`).

use super::{mix64, to_unit};
use crate::error::Result;
use crate::scene::description::Node;

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

/// Uniform number for (pixel key, sample index, dimension): a hash, so
/// any sample can be regenerated without state.
#[inline(always)]
pub(crate) fn uniform(key: u64, index: u32, dim: u32) -> f32 {
    to_unit(mix64(
        key ^ mix64(((index as u64) << 32 | dim as u64).wrapping_add(0x9e3779b97f4a7c15)),
    ))
}
