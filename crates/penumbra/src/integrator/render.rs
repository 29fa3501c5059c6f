//! The render loop: image tiles in parallel (rayon), samples splatted into
//! per-tile blocks through the reconstruction filter, tiles merged in a
//! fixed order, so the image is identical for a given seed whatever the
//! number of threads.

use crate::error::{Error, Result};
use crate::geometry::Ray;
use crate::image::ImageBlock;
use crate::sampler::SampleStream;
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

/// Side of the square image tiles rendered as one task.
const TILE: usize = 32;

/// Reports progress: `(tiles done, tiles in all)`.
pub type ProgressFn = dyn Fn(usize, usize) + Send + Sync;

/// How to render.
#[derive(Clone, Default)]
pub struct RenderOptions {
    /// Samples per pixel (default: the scene sampler's `sample_count`).
    pub spp: Option<u32>,
    /// Seed of all random numbers (combined with the sampler's own seed).
    pub seed: u64,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    pub progress: Option<Arc<ProgressFn>>,
    /// Set from another thread to stop early; the render then fails with
    /// [`Error::Interrupted`].
    pub cancel: Option<Arc<AtomicBool>>,
}

/// A rendered image: `height × width × channels`, row-major, top row
/// first, with the channels' names (`R`, `G`, `B`, `dd.T`, …).
#[derive(Clone, Debug)]
pub struct Rendered {
    pub width: usize,
    pub height: usize,
    pub channel_names: Vec<String>,
    pub data: Vec<f32>,
}

impl Rendered {
    pub fn channels(&self) -> usize {
        self.channel_names.len()
    }
}

/// Renders the scene with its integrator and sensor.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<Rendered> {
    let integrator = &scene.integrator;
    let names = integrator.channel_names();
    let block = render_samples(scene, opts, names.len(), |ray, rng, out| {
        integrator.sample(scene, ray, rng, out)
    })?;
    Ok(Rendered {
        width: block.width,
        height: block.height,
        channel_names: names,
        data: block.develop(),
    })
}

/// Runs `sample(ray, stream, out)` for every sample of every pixel of the
/// sensor's crop window (and its border, with `sample_border`), splats the
/// `channels` values it writes, and returns the merged crop-window block.
/// Shared by primal, forward-mode and reverse-mode rendering.
pub(crate) fn render_samples<F>(
    scene: &Scene,
    opts: &RenderOptions,
    channels: usize,
    sample: F,
) -> Result<ImageBlock>
where
    F: Fn(Ray, &mut SampleStream, &mut [f32]) + Sync,
{
    let sensor = &scene.sensor;
    let film = &sensor.film;
    let sampler = &sensor.sampler;
    let spp = opts.spp.unwrap_or_else(|| sampler.sample_count());
    if spp == 0 {
        return Err(Error::Invalid("spp must be at least 1".into()));
    }
    let filter = &film.rfilter;
    let margin = filter.border() as i64;
    let (cw, ch) = (film.crop_size.0 as i64, film.crop_size.1 as i64);
    // region whose pixels receive samples
    let b = if film.sample_border { margin } else { 0 };
    let (rx0, ry0, rw, rh) = (-b, -b, cw + 2 * b, ch + 2 * b);
    let tiles_x = (rw as usize).div_ceil(TILE);
    let tiles_y = (rh as usize).div_ceil(TILE);
    let n_tiles = tiles_x * tiles_y;
    let done = AtomicUsize::new(0);
    let inv_size = Vec2::new(1.0 / film.width as f32, 1.0 / film.height as f32);
    let crop_off = Vec2::new(film.crop_offset.0 as f32, film.crop_offset.1 as f32);
    let lens = sensor.needs_aperture_sample();

    let render_tile = |t: usize| -> Option<ImageBlock> {
        if let Some(c) = &opts.cancel {
            if c.load(Ordering::Relaxed) {
                return None;
            }
        }
        let tx0 = rx0 + ((t % tiles_x) * TILE) as i64;
        let ty0 = ry0 + ((t / tiles_x) * TILE) as i64;
        let tw = (TILE as i64).min(rx0 + rw - tx0);
        let th = (TILE as i64).min(ry0 + rh - ty0);
        let mut block = ImageBlock::new(
            tx0 - margin,
            ty0 - margin,
            (tw + 2 * margin) as usize,
            (th + 2 * margin) as usize,
            channels,
        );
        let mut out = vec![0.0f32; channels];
        for y in ty0..ty0 + th {
            for x in tx0..tx0 + tw {
                // a key per film pixel (border pixels included)
                let pixel = ((y + 0x8000) as u64) << 32 | (x + 0x8000) as u64;
                for s in 0..spp {
                    let mut rng = sampler.stream(opts.seed, pixel, s, spp);
                    let u = rng.next_2d();
                    let pos = Vec2::new(x as f32 + u.x, y as f32 + u.y);
                    let lens_u = if lens { rng.next_2d() } else { Vec2::ZERO };
                    let ray = sensor.sample_ray((pos + crop_off) * inv_size, lens_u);
                    out.fill(0.0);
                    sample(ray, &mut rng, &mut out);
                    if out.iter().all(|v| v.is_finite()) {
                        block.put(filter, pos.x, pos.y, &out);
                    }
                }
            }
        }
        let k = done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(p) = &opts.progress {
            p(k, n_tiles);
        }
        Some(block)
    };

    let run =
        || -> Vec<Option<ImageBlock>> { (0..n_tiles).into_par_iter().map(render_tile).collect() };
    let blocks = match opts.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build()
            .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?
            .install(run),
        None => run(),
    };
    let mut image = ImageBlock::new(0, 0, cw as usize, ch as usize, channels);
    for b in blocks {
        image.accumulate(&b.ok_or(Error::Interrupted)?);
    }
    Ok(image)
}
