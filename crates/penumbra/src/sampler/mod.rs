//! Samplers. Every sample is a pure function of (seed, pixel, sample index,
//! dimension), so that a path can be regenerated exactly (path replay) on
//! any thread, in any order.

mod independent;
mod stratified;

pub use independent::Independent;
pub use stratified::Stratified;

use crate::error::Result;
use crate::scene::Node;
use glam::Vec2;

/// All sampler plugins.
#[derive(Clone, Debug)]
pub enum Sampler {
    Independent(Independent),
    Stratified(Stratified),
}

impl Sampler {
    pub fn from_node(node: &Node) -> Result<Sampler> {
        let s = match node.plugin.as_str() {
            "independent" => Sampler::Independent(Independent::from_node(node)?),
            "stratified" => Sampler::Stratified(Stratified::from_node(node)?),
            other => {
                return Err(node.error(format!(
                    "unknown sampler plugin '{other}' (Penumbra has: independent, stratified)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(s)
    }

    /// Samples per pixel.
    pub fn sample_count(&self) -> u32 {
        match self {
            Sampler::Independent(s) => s.sample_count,
            Sampler::Stratified(s) => s.sample_count(),
        }
    }

    /// The sampler's own seed (added to the render seed).
    pub fn seed(&self) -> u64 {
        match self {
            Sampler::Independent(s) => s.seed,
            Sampler::Stratified(s) => s.seed,
        }
    }

    /// The same sampler with another sample count (CLI `--spp`).
    pub fn with_sample_count(&self, spp: u32) -> Sampler {
        match self {
            Sampler::Independent(s) => Sampler::Independent(Independent {
                sample_count: spp,
                ..s.clone()
            }),
            Sampler::Stratified(s) => Sampler::Stratified(Stratified::new(spp, s.seed, s.jitter)),
        }
    }

    /// The sample stream of one sample of one pixel (`pixel`: any unique
    /// key of the pixel). `spp` is the number
    /// of samples taken in this pass (stratification is over them).
    #[inline]
    pub fn stream(&self, seed: u64, pixel: u64, index: u32, spp: u32) -> SampleStream {
        SampleStream {
            key: mix64(mix64(seed.wrapping_add(self.seed())) ^ pixel),
            index,
            spp,
            dim: 0,
            strata: match self {
                Sampler::Independent(_) => None,
                Sampler::Stratified(s) => Some(s.jitter),
            },
        }
    }
}

/// The random numbers of one sample path, drawn dimension by dimension.
#[derive(Clone, Debug)]
pub struct SampleStream {
    /// Hash of (seed, pixel).
    key: u64,
    index: u32,
    spp: u32,
    dim: u32,
    /// `Some(jitter)` for stratified sampling.
    strata: Option<bool>,
}

impl SampleStream {
    /// The next uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        let d = self.dim;
        self.dim += 1;
        match self.strata {
            None => independent::uniform(self.key, self.index, d),
            Some(jitter) => stratified::sample_1d(self.key, self.index, self.spp, d, jitter),
        }
    }

    /// The next uniform point in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let d = self.dim;
        self.dim += 2;
        match self.strata {
            None => Vec2::new(
                independent::uniform(self.key, self.index, d),
                independent::uniform(self.key, self.index, d + 1),
            ),
            Some(jitter) => stratified::sample_2d(self.key, self.index, self.spp, d, jitter),
        }
    }

    /// The dimension the next draw will use.
    pub fn dimension(&self) -> u32 {
        self.dim
    }
}

/// A 64-bit finaliser with good avalanche (the SplitMix64 / Stafford
/// "Mix13" constants).
#[inline(always)]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
    z ^ (z >> 31)
}

/// Maps the top 24 bits of `x` to a float in [0, 1).
#[inline(always)]
pub(crate) fn to_unit(x: u64) -> f32 {
    (x >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sampler(kind: &str, spp: u32) -> Sampler {
        match kind {
            "independent" => Sampler::Independent(Independent {
                sample_count: spp,
                seed: 0,
            }),
            _ => Sampler::Stratified(Stratified::new(spp, 0, true)),
        }
    }

    #[test]
    fn streams_are_pure_functions_of_their_coordinates() {
        for kind in ["independent", "stratified"] {
            let s = sampler(kind, 16);
            let a: Vec<f32> = {
                let mut st = s.stream(3, 17, 5, 16);
                (0..10).map(|_| st.next_1d()).collect()
            };
            let b: Vec<f32> = {
                let mut st = s.stream(3, 17, 5, 16);
                (0..10).map(|_| st.next_1d()).collect()
            };
            assert_eq!(a, b);
            let mut other = s.stream(3, 18, 5, 16);
            assert_ne!(a[0], other.next_1d());
        }
    }

    /// Means and a coarse histogram of many streams are uniform; a failure
    /// here would bias every estimate.
    #[test]
    fn samples_are_uniform() {
        for kind in ["independent", "stratified"] {
            let s = sampler(kind, 64);
            let mut hist = [0u32; 16];
            let n_pix = 500;
            for p in 0..n_pix {
                for i in 0..64 {
                    let mut st = s.stream(1, p, i, 64);
                    for _ in 0..4 {
                        let u = st.next_2d();
                        assert!((0.0..1.0).contains(&u.x) && (0.0..1.0).contains(&u.y));
                        hist[((u.x * 4.0) as usize) * 4 + (u.y * 4.0) as usize] += 1;
                    }
                }
            }
            let expect = (n_pix * 64 * 4) as f64 / 16.0;
            for h in hist {
                // 6 standard deviations of a binomial count
                let sd = (expect * (15.0 / 16.0)).sqrt();
                assert!((h as f64 - expect).abs() < 6.0 * sd, "{kind}: {hist:?}");
            }
        }
    }

    /// Stratified: within one pixel, each of the spp strata of a dimension
    /// holds exactly one sample.
    #[test]
    fn stratified_covers_every_stratum_once() {
        let s = sampler("stratified", 16);
        for dim_draws in 0..3 {
            let mut seen1 = [0u32; 16];
            let mut seen2 = [0u32; 16];
            for i in 0..16 {
                let mut st = s.stream(9, 4, i, 16);
                for _ in 0..dim_draws {
                    st.next_1d();
                }
                let u = st.next_1d();
                seen1[(u * 16.0) as usize] += 1;
                let v = st.next_2d();
                seen2[(v.x * 4.0) as usize * 4 + (v.y * 4.0) as usize] += 1;
            }
            assert!(seen1.iter().all(|&c| c == 1), "{seen1:?}");
            assert!(seen2.iter().all(|&c| c == 1), "{seen2:?}");
        }
    }
}
