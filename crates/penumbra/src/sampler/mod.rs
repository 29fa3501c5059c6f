//! Samplers. Every sample is a pure function of (seed, pixel, sample index,
//! dimension), so that a path can be regenerated exactly (path replay) on
//! any thread, in any order.

mod independent;
mod ldsampler;
mod multijitter;
mod orthogonal;
mod stratified;

pub use independent::Independent;
pub use ldsampler::LowDiscrepancy;
pub use multijitter::Multijitter;
pub use orthogonal::Orthogonal;
pub use stratified::Stratified;

use crate::error::Result;
use crate::scene::description::Node;
use glam::Vec2;

/// All sampler plugins.
#[derive(Clone, Debug)]
pub enum Sampler {
    Independent(Independent),
    Stratified(Stratified),
    Multijitter(Multijitter),
    LowDiscrepancy(LowDiscrepancy),
    Orthogonal(Orthogonal),
}

impl Sampler {
    pub fn from_node(node: &Node) -> Result<Sampler> {
        let s = match node.plugin.as_str() {
            "independent" => Sampler::Independent(Independent::from_node(node)?),
            "stratified" => Sampler::Stratified(Stratified::from_node(node)?),
            "multijitter" => Sampler::Multijitter(Multijitter::from_node(node)?),
            "ldsampler" => Sampler::LowDiscrepancy(LowDiscrepancy::from_node(node)?),
            "orthogonal" => Sampler::Orthogonal(Orthogonal::from_node(node)?),
            other => {
                return Err(node.error(format!(
                    "unknown sampler plugin '{other}' (Penumbra has: independent, stratified, \
                     multijitter, ldsampler, orthogonal)"
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
            Sampler::Multijitter(s) => s.sample_count,
            Sampler::LowDiscrepancy(s) => s.sample_count,
            Sampler::Orthogonal(s) => s.sample_count,
        }
    }

    /// The sample count this sampler takes when `spp` are asked for: the
    /// next count its pattern is built for (as Mitsuba's
    /// `set_sample_count`), with a warning when that differs from `spp`.
    pub fn round_sample_count(&self, spp: u32) -> u32 {
        if spp == 0 {
            return 0;
        }
        let n = match self {
            Sampler::Independent(_) | Sampler::Stratified(_) => spp,
            Sampler::Multijitter(_) => multijitter::rounded_count(spp),
            Sampler::LowDiscrepancy(_) => ldsampler::rounded_count(spp),
            Sampler::Orthogonal(_) => orthogonal::rounded_count(spp),
        };
        if n != spp {
            crate::warn(format!(
                "{spp} samples per pixel rounded up to {n}, the next count the '{}' \
                 sampler's pattern is built for",
                self.plugin_name()
            ));
        }
        n
    }

    /// Samples per pixel of a render that asks for `spp` (`None`: the
    /// sampler's own count), rounded as [`Sampler::round_sample_count`].
    pub fn pass_count(&self, spp: Option<u32>) -> u32 {
        spp.map_or_else(|| self.sample_count(), |n| self.round_sample_count(n))
    }

    /// The plugin name, as scene files write it.
    pub fn plugin_name(&self) -> &'static str {
        match self {
            Sampler::Independent(_) => "independent",
            Sampler::Stratified(_) => "stratified",
            Sampler::Multijitter(_) => "multijitter",
            Sampler::LowDiscrepancy(_) => "ldsampler",
            Sampler::Orthogonal(_) => "orthogonal",
        }
    }

    /// The sampler's own seed (added to the render seed).
    pub fn seed(&self) -> u64 {
        match self {
            Sampler::Independent(s) => s.seed,
            Sampler::Stratified(s) => s.seed,
            Sampler::Multijitter(s) => s.seed,
            Sampler::LowDiscrepancy(s) => s.seed,
            Sampler::Orthogonal(s) => s.seed,
        }
    }

    /// The same sampler with another sample count (CLI `--spp`), rounded
    /// as [`Sampler::round_sample_count`] does.
    pub fn with_sample_count(&self, spp: u32) -> Sampler {
        let n = self.round_sample_count(spp);
        match self {
            Sampler::Independent(s) => Sampler::Independent(Independent {
                sample_count: n,
                ..s.clone()
            }),
            Sampler::Stratified(s) => Sampler::Stratified(Stratified::new(n, s.seed, s.jitter)),
            Sampler::Multijitter(s) => Sampler::Multijitter(Multijitter {
                sample_count: n,
                ..s.clone()
            }),
            Sampler::LowDiscrepancy(s) => Sampler::LowDiscrepancy(LowDiscrepancy {
                sample_count: n,
                ..s.clone()
            }),
            Sampler::Orthogonal(s) => Sampler::Orthogonal(Orthogonal {
                sample_count: n,
                ..s.clone()
            }),
        }
    }

    /// The sample stream of one sample of one pixel (`pixel`: any unique
    /// key of the pixel). `spp` is the number
    /// of samples taken in this pass (stratification is over them).
    #[inline]
    pub fn stream(&self, seed: u64, pixel: u64, index: u32, spp: u32) -> SampleStream {
        self.stream_of(self.pixel_key(seed, pixel), index, spp)
    }

    /// The hash of (seed, pixel) that every sample stream of the pixel
    /// starts from: computed once per pixel by loops that take its
    /// samples together ([`Sampler::stream_of`]).
    #[inline(always)]
    pub fn pixel_key(&self, seed: u64, pixel: u64) -> u64 {
        mix64(mix64(seed.wrapping_add(self.seed())) ^ pixel)
    }

    /// [`Sampler::stream`] of the pixel whose [`Sampler::pixel_key`] is
    /// `key`.
    #[inline(always)]
    pub fn stream_of(&self, key: u64, index: u32, spp: u32) -> SampleStream {
        SampleStream {
            key,
            index,
            spp,
            dim: 0,
            pattern: match self {
                Sampler::Independent(_) => Pattern::Independent {
                    state: independent::sample_state(key, index),
                },
                Sampler::Stratified(s) => Pattern::Stratified { jitter: s.jitter },
                Sampler::Multijitter(s) => Pattern::Multijitter { jitter: s.jitter },
                Sampler::LowDiscrepancy(_) => Pattern::LowDiscrepancy,
                Sampler::Orthogonal(s) => Pattern::Orthogonal { jitter: s.jitter },
            },
        }
    }
}

/// How a stream places its samples (the sampler's kind and options).
#[derive(Clone, Copy, Debug)]
enum Pattern {
    /// `state`: the sample's stream, hashed once from (key, index).
    Independent {
        state: u64,
    },
    Stratified {
        jitter: bool,
    },
    Multijitter {
        jitter: bool,
    },
    LowDiscrepancy,
    Orthogonal {
        jitter: bool,
    },
}

/// Warns, at the place of `node`, that its `sample_count` was rounded up
/// to the count its pattern needs (`what`), as Mitsuba warns.
fn round_up_warning(node: &Node, requested: u32, rounded: u32, what: &str) {
    if requested != rounded {
        crate::warn(format!(
            "{}: {node}: sample_count {requested} rounded up to {rounded} ({what})",
            node.loc
        ));
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
    pattern: Pattern,
}

impl SampleStream {
    /// A stream that holds an array's place until the array is filled
    /// (the streams of a block of lanes, `[PLACEHOLDER; N]`, written lane
    /// by lane without building the array through closures).
    pub(crate) const PLACEHOLDER: SampleStream = SampleStream {
        key: 0,
        index: 0,
        spp: 1,
        dim: 0,
        pattern: Pattern::Independent { state: 0 },
    };

    /// The next uniform number in [0, 1).
    #[inline(always)]
    pub fn next_1d(&mut self) -> f32 {
        let d = self.dim;
        self.dim += 1;
        // the default sampler's draw inlined where it is drawn; the other
        // patterns behind a call, so that the common draw pays neither a
        // call nor the register saves the patterns' code needs
        match self.pattern {
            Pattern::Independent { state } => independent::uniform_1d(state, d),
            _ => self.pattern_1d(d),
        }
    }

    #[inline(never)]
    fn pattern_1d(&self, d: u32) -> f32 {
        let (key, index, spp) = (self.key, self.index, self.spp);
        match self.pattern {
            Pattern::Independent { state } => independent::uniform_1d(state, d),
            Pattern::Stratified { jitter } => stratified::sample_1d(key, index, spp, d, jitter),
            Pattern::Multijitter { jitter } => multijitter::sample_1d(key, index, spp, d, jitter),
            Pattern::LowDiscrepancy => ldsampler::sample_1d(key, index, spp, d),
            Pattern::Orthogonal { jitter } => orthogonal::sample_1d(key, index, spp, d, jitter),
        }
    }

    /// The next uniform point in [0, 1)².
    #[inline(always)]
    pub fn next_2d(&mut self) -> Vec2 {
        let d = self.dim;
        self.dim += 2;
        match self.pattern {
            Pattern::Independent { state } => independent::uniform_2d(state, d),
            _ => self.pattern_2d(d),
        }
    }

    #[inline(never)]
    fn pattern_2d(&self, d: u32) -> Vec2 {
        let (key, index, spp) = (self.key, self.index, self.spp);
        match self.pattern {
            Pattern::Independent { state } => independent::uniform_2d(state, d),
            Pattern::Stratified { jitter } => stratified::sample_2d(key, index, spp, d, jitter),
            Pattern::Multijitter { jitter } => multijitter::sample_2d(key, index, spp, d, jitter),
            Pattern::LowDiscrepancy => ldsampler::sample_2d(key, index, spp, d),
            // an orthogonal array stratifies every pair of dimensions
            Pattern::Orthogonal { jitter } => Vec2::new(
                orthogonal::sample_1d(key, index, spp, d, jitter),
                orthogonal::sample_1d(key, index, spp, d + 1, jitter),
            ),
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

/// Maps the top 24 bits of `x` to a float in [0, 1). Converted through
/// `u32`: one instruction on x86-64, where `u64 → f32` is a branchy
/// sequence (before AVX-512); the value is the same.
#[inline(always)]
pub(crate) fn to_unit(x: u64) -> f32 {
    ((x >> 40) as u32) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// Kensler's hashed permutation of `i` in [0, n) with seed `p`
/// (Kensler 2013, "Correlated Multi-Jittered Sampling"): a bijection of
/// [0, n) per seed, evaluated without tables (cycle-walking over the next
/// power of two).
pub(crate) fn permute(mut i: u32, n: u32, p: u32) -> u32 {
    if n <= 1 {
        return 0;
    }
    let mut w = n - 1;
    w |= w >> 1;
    w |= w >> 2;
    w |= w >> 4;
    w |= w >> 8;
    w |= w >> 16;
    loop {
        i ^= p;
        i = i.wrapping_mul(0xe170893d);
        i ^= p >> 16;
        i ^= (i & w) >> 4;
        i ^= p >> 8;
        i = i.wrapping_mul(0x0929eb3f);
        i ^= p >> 23;
        i ^= (i & w) >> 1;
        i = i.wrapping_mul(1 | p >> 27);
        i = i.wrapping_mul(0x6935fa69);
        i ^= (i & w) >> 11;
        i = i.wrapping_mul(0x74dcb303);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0x9e501cc3);
        i ^= (i & w) >> 2;
        i = i.wrapping_mul(0xc860a3df);
        i &= w;
        i ^= i >> 5;
        if i < n {
            return (i + p) % n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KINDS: [&str; 5] = [
        "independent",
        "stratified",
        "multijitter",
        "ldsampler",
        "orthogonal",
    ];

    fn sampler(kind: &str, spp: u32) -> Sampler {
        match kind {
            "independent" => Sampler::Independent(Independent {
                sample_count: spp,
                seed: 0,
            }),
            "stratified" => Sampler::Stratified(Stratified::new(spp, 0, true)),
            "multijitter" => Sampler::Multijitter(Multijitter {
                sample_count: spp,
                seed: 0,
                jitter: true,
            }),
            "ldsampler" => Sampler::LowDiscrepancy(LowDiscrepancy {
                sample_count: spp,
                seed: 0,
            }),
            "orthogonal" => Sampler::Orthogonal(Orthogonal {
                sample_count: spp,
                seed: 0,
                jitter: true,
            }),
            _ => unreachable!("test sampler kinds are listed in KINDS"),
        }
    }

    #[test]
    fn streams_are_pure_functions_of_their_coordinates() {
        for kind in KINDS {
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
    /// here would bias every estimate. (64 samples per pass: orthogonal
    /// arrays are built for 121 and use part of one.)
    #[test]
    fn samples_are_uniform() {
        for kind in KINDS {
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

    /// The independent sampler draws both coordinates of a 2D point from
    /// one hash (its top 24 bits and the 24 below): their joint
    /// distribution is uniform on a 32 × 32 grid (Pearson's χ² with 1023
    /// degrees of freedom, mean 1023 and standard deviation √2046 ≈ 45,
    /// allowed up to 6 standard deviations above its mean), and so are a
    /// point's x and the next 1D draw.
    #[test]
    fn independent_2d_coordinates_are_jointly_uniform() {
        let s = sampler("independent", 64);
        let (mut xy, mut x_next) = (vec![0u32; 1024], vec![0u32; 1024]);
        let n = 200 * 64;
        for p in 0..200 {
            for i in 0..64 {
                let mut st = s.stream(3, p, i, 64);
                let u = st.next_2d();
                let v = st.next_1d();
                let cell = |a: f32| (a * 32.0) as usize;
                xy[cell(u.x) * 32 + cell(u.y)] += 1;
                x_next[cell(u.x) * 32 + cell(v)] += 1;
            }
        }
        let expect = n as f64 / 1024.0;
        for (name, hist) in [("x, y", &xy), ("x, next", &x_next)] {
            let chi2: f64 = hist
                .iter()
                .map(|&c| (c as f64 - expect).powi(2) / expect)
                .sum();
            assert!(chi2 < 1023.0 + 6.0 * 2046f64.sqrt(), "{name}: χ² {chi2}");
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
