//! What the boundary estimators share: samples drawn in parallel chunks
//! and splatted onto the film through the reconstruction filter with the
//! film's own normalisation, in a fixed order.
//!
//! Pixel p of the film is `I_p = ∫ k_p(x) L(x) dx / W_p` over the sampled
//! film region, with `k_p` the filter centred on p and `W_p = ∫ k_p(x) dx`
//! (a pixel is the weighted mean of its samples, and the samples are
//! uniform over the film). A boundary sample at film position x with value
//! `v` (already divided by its density) adds `k_p(x) v / (W_p · N)` to every
//! pixel p the filter reaches, N being the number of samples.

use crate::ad::reverse::{backward, clear_tape};
use crate::ad::Var;
use crate::error::{Error, Result};
use crate::image::{ImageBlock, ReconstructionFilter};
use crate::integrator::{RenderOptions, Rendered};
use crate::sampler::SampleStream;
use crate::sensor::{CameraSample, Sensor};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// Samples drawn from one sample stream key (one parallel task).
pub(super) const CHUNK: u32 = 4096;
/// Chunks computed in parallel before their splats are visited (bounds
/// the memory of the splats in flight).
const CHUNKS_PER_BATCH: usize = 64;

/// The film rectangle where samples are taken (crop-window pixels).
#[derive(Clone, Copy)]
pub(super) struct Region {
    pub lo: Vec2,
    pub hi: Vec2,
}

impl Region {
    pub fn contains(&self, x: Vec2) -> bool {
        x.cmpge(self.lo).all() && x.cmplt(self.hi).all()
    }
}

/// The film of a boundary pass: the sampled region, the conversions
/// between film units and pixels, and the per-pixel normalisation.
pub(super) struct FilmSplatter<'a> {
    pub sensor: &'a Sensor,
    pub region: Region,
    pub crop_off: Vec2,
    /// Film units to pixels (the full film's size).
    pub scale: Vec2,
    pub n_samples: u64,
    /// Crop-window width, and the filter integrals `Wx(i)`, `Wy(j)` with
    /// `W_p = Wx(i) · Wy(j)` (separable filter, rectangular region).
    width: usize,
    wx: Vec<f64>,
    wy: Vec<f64>,
    pool: Option<rayon::ThreadPool>,
}

impl<'a> FilmSplatter<'a> {
    /// The film of `sensor` for `samples_per_pixel × pixels` samples, run
    /// on the threads `opts` asks for.
    pub fn new(sensor: &'a Sensor, samples_per_pixel: u32, opts: &RenderOptions) -> Result<Self> {
        let film = &sensor.film;
        let (cw, ch) = film.crop_size;
        let border = if film.sample_border {
            film.rfilter.border() as f32
        } else {
            0.0
        };
        let region = Region {
            lo: Vec2::splat(-border),
            hi: Vec2::new(cw as f32 + border, ch as f32 + border),
        };
        let filter = &film.rfilter;
        let integrals = |n: usize, lo: f32, hi: f32| -> Vec<f64> {
            (0..n)
                .map(|i| filter_integral(filter, lo - i as f32 - 0.5, hi - i as f32 - 0.5))
                .collect()
        };
        let pool = match opts.threads {
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n.max(1))
                    .build()
                    .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?,
            ),
            None => None,
        };
        Ok(FilmSplatter {
            sensor,
            region,
            crop_off: Vec2::new(film.crop_offset.0 as f32, film.crop_offset.1 as f32),
            scale: Vec2::new(film.width as f32, film.height as f32),
            n_samples: samples_per_pixel as u64 * (cw * ch) as u64,
            width: cw,
            wx: integrals(cw, region.lo.x, region.hi.x),
            wy: integrals(ch, region.lo.y, region.hi.y),
            pool,
        })
    }

    /// Crop-window pixels of the film position `f` (full film in [0, 1]²).
    pub fn to_pixels(&self, f: Vec2) -> Vec2 {
        f * self.scale - self.crop_off
    }

    /// The camera sample at crop-window pixel position `x`.
    pub fn camera_sample(&self, x: Vec2) -> CameraSample<'a> {
        CameraSample {
            sensor: self.sensor,
            film: (x + self.crop_off) / self.scale,
            lens: Vec2::ZERO,
        }
    }

    /// Runs `f` on the pass's threads.
    pub fn install<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        match &self.pool {
            Some(p) => p.install(f),
            None => f(),
        }
    }

    /// Computes the chunks of `n_samples` samples (`chunk(c, count)`: the
    /// samples of chunk c, of `count` samples, and how many of them were
    /// NaN or infinite) in parallel, and hands them to `visit` batch by
    /// batch in chunk order, so that what `visit` accumulates is the same
    /// for a seed whatever the number of threads. Returns the number of
    /// non-finite samples (and warns about them, naming `term`).
    pub fn run<S: Send>(
        &self,
        opts: &RenderOptions,
        term: &str,
        chunk: impl Fn(usize, u32) -> (Vec<S>, usize) + Sync,
        mut visit: impl FnMut(Vec<Vec<S>>),
    ) -> Result<usize> {
        let n_chunks = self.n_samples.div_ceil(CHUNK as u64) as usize;
        let mut non_finite = 0usize;
        for first in (0..n_chunks).step_by(CHUNKS_PER_BATCH) {
            let chunks = first..(first + CHUNKS_PER_BATCH).min(n_chunks);
            let results: Vec<Option<(Vec<S>, usize)>> = self.install(|| {
                chunks
                    .into_par_iter()
                    .map(|c| {
                        let cancelled = opts
                            .cancel
                            .as_ref()
                            .is_some_and(|c| c.load(Ordering::Relaxed));
                        let first = c as u64 * CHUNK as u64;
                        let count = (self.n_samples - first).min(CHUNK as u64) as u32;
                        (!cancelled).then(|| chunk(c, count))
                    })
                    .collect()
            });
            let mut batch = Vec::with_capacity(results.len());
            for r in results {
                let (splats, bad) = r.ok_or(Error::Interrupted)?;
                non_finite += bad;
                batch.push(splats);
            }
            visit(batch);
        }
        if non_finite > 0 {
            crate::warn(format!(
                "{term}: {non_finite} sample(s) had a NaN or infinite value and were left out"
            ));
        }
        Ok(non_finite)
    }

    /// Calls `f(u, rng)` for each of the `count` samples of chunk `c` of
    /// the stream `key` (a term's own) and `seed`: u in jittered strata of
    /// [0, 1) within the chunk, rng the sample's own stream for the rest.
    ///
    /// Why strata: the chunk's samples are summed with equal weights, so
    /// the sum stays unbiased, and the opposite contributions of the two
    /// sides of a moving shape cancel out much better than with
    /// independent positions.
    pub fn jittered(
        &self,
        seed: u64,
        key: u64,
        c: usize,
        count: u32,
        mut f: impl FnMut(f32, &mut SampleStream),
    ) {
        for k in 0..count {
            let mut rng = self.sensor.sampler.stream(seed, key | c as u64, k, CHUNK);
            let u = (k as f32 + rng.next_1d()) / count as f32;
            f(u.min(1.0 - f32::EPSILON), &mut rng);
        }
    }

    /// Calls `f(pixel, weight)` for every pixel p (index in the crop
    /// window) the filter reaches from film position `x`, with weight
    /// `k_p(x) / (W_p · N)`.
    pub fn footprint(&self, x: Vec2, mut f: impl FnMut(usize, f64)) {
        let bounds = ImageBlock::new(0, 0, self.wx.len(), self.wy.len(), 0);
        let n = self.n_samples as f64;
        bounds.footprint(&self.sensor.film.rfilter, x.x, x.y, |i, j, w| {
            let (i, j) = (i as usize, j as usize);
            f(j * self.width + i, w / (self.wx[i] * self.wy[j] * n));
        });
    }

    /// `Σ_p δI_p k_p(x) / (W_p · N)` per channel: the adjoint of a splat at
    /// `x` of the adjoint image `d_image` (crop window × 3).
    pub fn adjoint(&self, x: Vec2, d_image: &[f32]) -> [f64; 3] {
        let mut a = [0.0f64; 3];
        self.footprint(x, |p, w| {
            for (c, a) in a.iter_mut().enumerate() {
                *a += w * d_image[3 * p + c] as f64;
            }
        });
        a
    }
}

/// A boundary term whose samples are independent of the parameters and
/// splat onto the film one by one (the shadow terms): it draws them, and
/// [`add_splats`] and [`add_splat_gradients`] run the forward and the
/// reverse mode from the same samples.
pub(super) trait BoundarySamples: Sync {
    type Sample;
    /// Names the term in warnings.
    const TERM: &'static str;
    /// The term's sample streams (high bits, distinct from every other
    /// term's).
    const STREAM_KEY: u64;

    fn film(&self) -> &FilmSplatter<'_>;
    fn seed(&self) -> u64;
    /// The sample drawn at `u` (jittered, see [`FilmSplatter::jittered`])
    /// and `rng`, if it reaches the film with a non-zero value.
    fn sample(&self, u: f32, rng: &mut SampleStream) -> Option<Self::Sample>;
    /// Its film position (crop-window pixels).
    fn position(s: &Self::Sample) -> Vec2;
    fn is_finite(s: &Self::Sample) -> bool;

    /// What `emit` keeps of the samples of chunk `c` (`count` samples),
    /// and the number of non-finite ones.
    fn chunk<S>(
        &self,
        c: usize,
        count: u32,
        emit: impl Fn(&Self::Sample) -> Option<S>,
    ) -> (Vec<S>, usize) {
        let mut out = Vec::new();
        let mut non_finite = 0;
        self.film()
            .jittered(self.seed(), Self::STREAM_KEY, c, count, |u, rng| {
                let Some(sample) = self.sample(u, rng) else {
                    return;
                };
                if !Self::is_finite(&sample) {
                    non_finite += 1;
                } else if let Some(s) = emit(&sample) {
                    out.push(s);
                }
            });
        (out, non_finite)
    }
}

/// Forward mode: adds `Σ k_p(x)/(W_p N) · value(sample)` to every pixel p
/// of the derivative image, `value` being a sample's derivative along the
/// tangents (`None` where it is zero).
pub(super) fn add_splats<T: BoundarySamples>(
    term: &T,
    opts: &RenderOptions,
    image: &mut Rendered,
    value: impl Fn(&T::Sample) -> Option<Vec3> + Sync,
) -> Result<()> {
    let film = term.film();
    let mut acc = vec![0.0f64; image.data.len()];
    image.non_finite_samples += film.run(
        opts,
        T::TERM,
        |c, count| term.chunk(c, count, |s| value(s).map(|v| (T::position(s), v))),
        |batch| {
            for (x, v) in batch.iter().flatten() {
                film.footprint(*x, |p, w| {
                    for c in 0..3 {
                        acc[3 * p + c] += w * v[c] as f64;
                    }
                });
            }
        },
    )?;
    for (d, a) in image.data.iter_mut().zip(&acc) {
        *d += *a as f32;
    }
    Ok(())
}

/// Reverse mode: adds the term of the gradient of a loss with adjoint image
/// `d_image` (crop window × 3) to `sums` (per parameter, per element, for
/// the parameters recorded on the tape); returns the number of non-finite
/// samples left out. `outputs(sample, a)`, given the sample's adjoint
/// `a = Σ_p δI_p k_p(x)/(W_p N)` per channel, records the sample's motion
/// on a fresh tape and returns the outputs to backpropagate with their
/// weights (`None` when they are all zero). Each sample's tape is small and
/// lives inside its parallel chunk; the chunks' gradients are added in
/// chunk order (the result does not depend on the thread count).
pub(super) fn add_splat_gradients<T: BoundarySamples>(
    term: &T,
    opts: &RenderOptions,
    d_image: &[f32],
    sums: &mut [Vec<f64>],
    outputs: impl Fn(&T::Sample, [f64; 3]) -> Option<Vec<(Var, f32)>> + Sync,
) -> Result<usize> {
    let film = term.film();
    film.run(
        opts,
        T::TERM,
        |c, count| {
            term.chunk(c, count, |s| {
                let a = film.adjoint(T::position(s), d_image);
                clear_tape();
                let mut g = Vec::new();
                if let Some(outs) = outputs(s, a) {
                    backward(&outs, |id, i, v| g.push((id.0, i as u32, v as f64)));
                }
                clear_tape();
                // `backward` hands over finite values only
                (!g.is_empty()).then_some(g)
            })
        },
        |batch| {
            for (id, i, g) in batch.into_iter().flatten().flatten() {
                sums[id as usize][i as usize] += g;
            }
        },
    )
}

/// `∫_lo^hi k(u) du` of the 1D filter `k` (offsets in pixels), by
/// Simpson's rule on each side of 0 (the filters are smooth there but for
/// the tent's kink at 0 and the cut at the radius).
fn filter_integral(filter: &ReconstructionFilter, lo: f32, hi: f32) -> f64 {
    let r = filter.radius();
    let (lo, hi) = (lo.max(-r), hi.min(r));
    let simpson = |a: f32, b: f32| -> f64 {
        if !(b > a) {
            return 0.0;
        }
        const N: usize = 64;
        let h = (b - a) as f64 / N as f64;
        let f = |i: usize| filter.eval((a as f64 + h * i as f64) as f32) as f64;
        let mut s = f(0) + f(N);
        for i in 1..N {
            s += f(i) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    };
    simpson(lo, hi.min(0.0)) + simpson(lo.max(0.0), hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filter_integrals() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        let bx = ReconstructionFilter::Box;
        assert!(close(filter_integral(&bx, -10.0, 10.0), 1.0));
        assert!(close(filter_integral(&bx, 0.0, 10.0), 0.5));
        assert!(close(filter_integral(&bx, -0.2, 0.1), 0.3));
        let tent = ReconstructionFilter::Tent { radius: 1.0 };
        assert!(close(filter_integral(&tent, -5.0, 5.0), 1.0));
        assert!(close(filter_integral(&tent, 0.5, 5.0), 0.125));
        let g = ReconstructionFilter::gaussian(0.5);
        // a fine midpoint sum
        let n = 200_000;
        let sum: f64 = (0..n)
            .map(|i| g.eval(-0.7 + 2.0 * (i as f32 + 0.5) / n as f32) as f64)
            .sum::<f64>()
            * 2.0
            / n as f64;
        assert!((filter_integral(&g, -0.7, 1.3) - sum).abs() < 1e-5);
    }
}
