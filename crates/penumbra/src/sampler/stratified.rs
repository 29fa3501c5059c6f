//! Stratified (jittered) sampling (Mitsuba's `stratified`): within a pixel,
//! the `spp` samples of each 1D dimension fall in distinct strata of
//! [0,1), and those of each 2D dimension in distinct cells of a √spp × √spp
//! grid. Samples are assigned to strata through a hashed permutation per
//! (pixel, dimension) (Kensler 2013, "Correlated Multi-Jittered Sampling"),
//! so they stay a pure function of (seed, pixel, index, dimension).

use super::{independent::uniform, mix64, permute};
use crate::error::Result;
use crate::scene::description::Node;
use glam::Vec2;

/// Jittered stratified samples; the sample count is rounded up to a square.
#[derive(Clone, Debug)]
pub struct Stratified {
    /// Strata per axis of a 2D dimension.
    pub resolution: u32,
    pub seed: u64,
    /// Jitter within each stratum (false: stratum centres).
    pub jitter: bool,
}

impl Stratified {
    pub fn new(sample_count: u32, seed: u64, jitter: bool) -> Stratified {
        let resolution = (sample_count.max(1) as f64).sqrt().ceil() as u32;
        Stratified {
            resolution,
            seed,
            jitter,
        }
    }

    pub fn from_node(node: &Node) -> Result<Stratified> {
        let spp = node.int_min("sample_count", 4, 1)? as u32;
        let seed = node.int_min("seed", 0, 0)? as u64;
        let jitter = node.bool("jitter", true)?;
        Ok(Stratified::new(spp, seed, jitter))
    }

    pub fn sample_count(&self) -> u32 {
        self.resolution * self.resolution
    }
}

fn jitter_offset(key: u64, index: u32, dim: u32, jitter: bool) -> f32 {
    if jitter {
        uniform(key ^ 0x5bd1e995, index, dim)
    } else {
        0.5
    }
}

/// Sample `index` of `spp` in dimension `dim`. Indices beyond a square
/// (or beyond `spp` in a progressive pass) fall back to independent draws.
pub(crate) fn sample_1d(key: u64, index: u32, spp: u32, dim: u32, jitter: bool) -> f32 {
    if index >= spp {
        return uniform(key, index, dim);
    }
    let p = mix64(key ^ ((dim as u64) << 17)) as u32;
    let s = permute(index, spp, p);
    ((s as f32 + jitter_offset(key, index, dim, jitter)) / spp as f32).min(1.0 - f32::EPSILON)
}

pub(crate) fn sample_2d(key: u64, index: u32, spp: u32, dim: u32, jitter: bool) -> Vec2 {
    let res = (spp as f64).sqrt() as u32;
    if index >= res * res {
        return Vec2::new(uniform(key, index, dim), uniform(key, index, dim + 1));
    }
    let p = mix64(key ^ ((dim as u64) << 17) ^ 0xabcdef) as u32;
    let s = permute(index, res * res, p);
    let (sx, sy) = (s % res, s / res);
    let jx = jitter_offset(key, index, dim, jitter);
    let jy = jitter_offset(key, index, dim + 1, jitter);
    Vec2::new(
        ((sx as f32 + jx) / res as f32).min(1.0 - f32::EPSILON),
        ((sy as f32 + jy) / res as f32).min(1.0 - f32::EPSILON),
    )
}
