//! The render loop: image tiles in parallel (rayon), samples splatted into
//! per-tile blocks through the reconstruction filter, tiles merged in a
//! fixed order, so the image is identical for a given seed whatever the
//! number of threads.

use super::lanes::{lane_width, LanePath};
use crate::error::{Error, Result};
use crate::image::ImageBlock;
use crate::sampler::SampleStream;
use crate::scene::Scene;
use crate::sensor::{CameraSample, Sensor};
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
    /// Derivative passes: edge samples per pixel of the boundary term of
    /// primary visibility (Mitsuba's `sppp`: `sppp × pixels` samples on the
    /// edges), default: `spp`; 0 turns the term off.
    pub sppp: Option<u32>,
    /// Derivative passes: samples per pixel of the boundary term of the
    /// visibility seen from the first vertex: shadows, and with path
    /// tracing beyond depth 2 every edge seen from there (Mitsuba's
    /// `sppi`), default: `spp`; 0 turns the term off.
    pub sppi: Option<u32>,
    /// Seed of all random numbers (combined with the sampler's own seed).
    pub seed: u64,
    /// Which of the scene's sensors to render (default: the first).
    pub sensor: usize,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Called as tiles finish.
    pub progress: Option<Arc<ProgressFn>>,
    /// Render even if the film's buffers would need more memory than is
    /// available (otherwise such a render fails before allocating).
    pub force: bool,
    /// Set from another thread to stop early; the render then fails with
    /// [`Error::Interrupted`].
    pub cancel: Option<Arc<AtomicBool>>,
    /// Paths shaded at once by the path tracer in lanes: 1 for the scalar
    /// loop, or 4, 8, 16 where the processor has them (default: the
    /// environment variable `PENUMBRA_LANES`, else 4). Finite-difference
    /// checks need 1: the loop in lanes estimates the same image with other
    /// directions for the same random numbers, and derivatives that are
    /// not in lanes replay the scalar loop.
    pub lanes: Option<usize>,
}

/// A rendered image: `height × width × channels`, row-major, top row
/// first, with the channels' names (`R`, `G`, `B`, `dd.T`, …).
#[derive(Clone, Debug)]
pub struct Rendered {
    pub width: usize,
    pub height: usize,
    pub channel_names: Vec<String>,
    pub data: Vec<f32>,
    /// Samples left out of the image because a value was NaN or infinite
    /// (reported once per render with [`crate::warn()`]).
    pub non_finite_samples: usize,
}

impl Rendered {
    pub fn channels(&self) -> usize {
        self.channel_names.len()
    }
}

/// Renders the scene with its integrator and sensor. With an `rgba` film,
/// an alpha channel follows the colour: 1 where the camera ray hits a
/// surface, 0 where it escapes (as Mitsuba).
pub fn render(scene: &Scene, opts: &RenderOptions) -> Result<Rendered> {
    let integrator = &scene.integrator;
    let mut names = integrator.channel_names();
    let alpha = scene.sensor(opts.sensor)?.film.alpha;
    let n = names.len();
    if alpha {
        if n > 64 {
            return Err(Error::Invalid(
                "an rgba film supports at most 64 channels".into(),
            ));
        }
        names.insert(3.min(n), "A".into());
    }
    let lanes = LanePath::new(scene, lane_width(opts.lanes)?);
    let (block, non_finite_samples) = if let Some(lanes) = &lanes {
        render_tiles(scene, opts, names.len(), "render", |layout, tile, block| {
            lanes.render_tile(layout, tile, alpha, block)
        })?
    } else {
        render_samples(scene, opts, names.len(), "render", |cs, rng, out| {
            if alpha {
                // colour, alpha, then any further (AOV) channels
                let mut buf = [0.0f32; 64];
                let rest = &mut buf[..n];
                // the integrator's own camera ray where it traced one
                let hit = integrator.sample(scene, cs, rng, rest).unwrap_or_else(|| {
                    let ray = cs.ray::<f32>(&scene.params.primal()).val();
                    scene.intersect(&ray).is_some()
                });
                let k = 3.min(n);
                out[..k].copy_from_slice(&rest[..k]);
                out[k] = if hit { 1.0 } else { 0.0 };
                out[k + 1..].copy_from_slice(&rest[k..]);
            } else {
                integrator.sample(scene, cs, rng, out);
            }
        })?
    };
    Ok(Rendered {
        width: block.width,
        height: block.height,
        channel_names: names,
        data: block.develop(),
        non_finite_samples,
    })
}

/// Warns once that `count` samples of a pass (`what`: "render", …) were
/// NaN or infinite and left out. A sample is dropped whole rather than
/// clamped: one NaN would otherwise poison its pixel (or, in reverse mode,
/// every gradient it touches), and the others are unbiased without it up
/// to the weight of the dropped ones, which the count lets a user judge.
pub(crate) fn report_non_finite(what: &str, count: usize, layout: &SampleLayout) {
    if count > 0 {
        let (w, h) = layout.size();
        crate::warn(format!(
            "{what}: {count} sample(s) had a NaN or infinite value and were left out \
             ({} samples per pixel, {w}x{h} pixels); look for extreme emitter or texture values",
            layout.spp
        ));
    }
}

/// The rectangle of film pixels (crop-window coordinates, possibly
/// negative in the sampled border) whose samples one task takes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tile {
    pub x0: i64,
    pub y0: i64,
    pub w: i64,
    pub h: i64,
}

/// Everything that fixes where samples go: shared by all passes over the
/// image so that they draw exactly the same samples.
pub(crate) struct SampleLayout<'a> {
    pub sensor: &'a Sensor,
    pub spp: u32,
    seed: u64,
    inv_size: Vec2,
    crop_off: Vec2,
    lens: bool,
    /// The sampled region (crop window, plus the filter border with
    /// `sample_border`).
    region: Tile,
    /// How far (pixels) one sample's filter reaches beyond its pixel.
    pub margin: i64,
}

impl<'a> SampleLayout<'a> {
    pub fn new(scene: &'a Scene, opts: &RenderOptions) -> Result<SampleLayout<'a>> {
        let sensor = scene.sensor(opts.sensor)?;
        let film = &sensor.film;
        // as Mitsuba's render(spp=…), the sampler's pattern decides
        let spp = sensor.sampler.pass_count(opts.spp);
        if spp == 0 {
            return Err(Error::Invalid("spp must be at least 1".into()));
        }
        let margin = film.rfilter.border() as i64;
        let b = if film.sample_border { margin } else { 0 };
        let (cw, ch) = (film.crop_size.0 as i64, film.crop_size.1 as i64);
        Ok(SampleLayout {
            sensor,
            spp,
            seed: opts.seed,
            inv_size: Vec2::new(1.0 / film.width as f32, 1.0 / film.height as f32),
            crop_off: Vec2::new(film.crop_offset.0 as f32, film.crop_offset.1 as f32),
            lens: sensor.needs_aperture_sample(),
            region: Tile {
                x0: -b,
                y0: -b,
                w: cw + 2 * b,
                h: ch + 2 * b,
            },
            margin,
        })
    }

    /// Fails, unless `opts.force`, when the buffers of one pass over the
    /// film would need more memory than the system has available (Linux;
    /// elsewhere the check is skipped). `channels` values are splatted per
    /// sample; `reverse` adds the adjoint image and the gradient sums.
    pub fn check_memory(
        &self,
        scene: &Scene,
        opts: &RenderOptions,
        channels: usize,
        reverse: bool,
    ) -> Result<()> {
        if opts.force {
            return Ok(());
        }
        let Some(available) = available_memory() else {
            return Ok(());
        };
        let need = self.buffer_bytes(scene, channels, reverse);
        if need <= available as f64 {
            return Ok(());
        }
        let gib = |b: f64| b / (1u64 << 30) as f64;
        let (w, h) = (self.sensor.film.width, self.sensor.film.height);
        Err(Error::Invalid(format!(
            "the film {w}×{h} needs about {:.1} GiB; {:.1} GiB are available; \
             pass --force (CLI) / force=True (Python) to render anyway",
            gib(need),
            gib(available as f64)
        )))
    }

    /// A rough estimate of the bytes one pass allocates: the per-tile
    /// blocks (all alive until they are merged in tile order), the merged
    /// crop-window block, the developed image, and in reverse mode the
    /// adjoint image, the filter weights and the gradient sums.
    fn buffer_bytes(&self, scene: &Scene, channels: usize, reverse: bool) -> f64 {
        let (cw, ch) = self.size();
        let crop = cw as f64 * ch as f64;
        let r = self.region;
        let tiles = (r.w as f64 / TILE as f64).ceil() * (r.h as f64 / TILE as f64).ceil();
        let tile_side = (TILE as i64 + 2 * self.margin) as f64;
        let tile_px = tiles * tile_side * tile_side;
        // a block holds f64 sums of the channels and of the filter weight
        let per_px = 8.0 * (channels + 1) as f64;
        let primal = (tile_px + crop) * per_px + crop * channels as f64 * 4.0;
        if !reverse {
            return primal;
        }
        let weights = (tile_px + crop) * 8.0;
        let adjoint = crop * channels as f64 * 4.0;
        let grads: usize = scene
            .params
            .iter()
            .filter(|(_, p)| p.flags.differentiable)
            .map(|(_, p)| p.data.len())
            .sum();
        weights + adjoint + 16.0 * grads as f64
    }

    /// Crop-window size.
    pub fn size(&self) -> (usize, usize) {
        self.sensor.film.crop_size
    }

    /// Calls `f(film position in pixels, camera sample, sample stream)` for
    /// every sample of every pixel of `tile`, in a fixed order.
    #[inline]
    pub fn for_each_sample(
        &self,
        tile: Tile,
        mut f: impl FnMut(Vec2, &CameraSample, &mut SampleStream),
    ) {
        for y in tile.y0..tile.y0 + tile.h {
            for x in tile.x0..tile.x0 + tile.w {
                for s in 0..self.spp {
                    let (pos, cs, mut rng) = self.camera_sample(x, y, s);
                    f(pos, &cs, &mut rng);
                }
            }
        }
    }

    /// An empty block of `channels` values per pixel for the samples of
    /// `tile`: the tile and its filter margin.
    pub fn tile_block(&self, tile: Tile, channels: usize) -> ImageBlock {
        let m = self.margin;
        ImageBlock::new(
            tile.x0 - m,
            tile.y0 - m,
            (tile.w + 2 * m) as usize,
            (tile.h + 2 * m) as usize,
            channels,
        )
    }

    /// Sample `s` of pixel `(x, y)`: its film position in pixels, its
    /// camera sample and the stream of its further random numbers.
    #[inline(always)]
    pub fn camera_sample(&self, x: i64, y: i64, s: u32) -> (Vec2, CameraSample<'a>, SampleStream) {
        let mut rng = SampleStream::PLACEHOLDER;
        let (pos, cs) = self.camera_sample_of(x, y, self.pixel_key(x, y), s, &mut rng);
        (pos, cs, rng)
    }

    /// The hash every sample stream of pixel `(x, y)` starts from, for
    /// [`SampleLayout::camera_sample_of`].
    #[inline(always)]
    pub fn pixel_key(&self, x: i64, y: i64) -> u64 {
        // a key per film pixel (border pixels included)
        let pixel = ((y + 0x8000) as u64) << 32 | (x + 0x8000) as u64;
        self.sensor.sampler.pixel_key(self.seed, pixel)
    }

    /// [`SampleLayout::camera_sample`] of the pixel whose
    /// [`SampleLayout::pixel_key`] is `key`: for loops that take a pixel's
    /// samples together and hash its key once. The stream is written to
    /// `rng` and drawn from there: a stream returned by value, its draw
    /// count just written, was copied out with wider loads than that
    /// write, which stalled store forwarding (3 % of the lanes loop's
    /// perf samples on textured).
    #[inline(always)]
    pub fn camera_sample_of(
        &self,
        x: i64,
        y: i64,
        key: u64,
        s: u32,
        rng: &mut SampleStream,
    ) -> (Vec2, CameraSample<'a>) {
        let sensor = self.sensor;
        *rng = sensor.sampler.stream_of(key, s, self.spp);
        let u = rng.next_2d();
        let pos = Vec2::new(x as f32 + u.x, y as f32 + u.y);
        let lens_u = if self.lens { rng.next_2d() } else { Vec2::ZERO };
        let cs = CameraSample {
            sensor,
            film: (pos + self.crop_off) * self.inv_size,
            lens: lens_u,
        };
        (pos, cs)
    }

    /// Runs `per_tile` on every tile of the sampled region, in parallel,
    /// and returns the results in tile order (so that merging them is
    /// deterministic). Honours threads, progress and cancellation.
    pub fn map_tiles<T: Send>(
        &self,
        opts: &RenderOptions,
        per_tile: impl Fn(Tile) -> T + Sync,
    ) -> Result<Vec<T>> {
        let r = self.region;
        let tiles_x = (r.w as usize).div_ceil(TILE);
        let tiles_y = (r.h as usize).div_ceil(TILE);
        let n_tiles = tiles_x * tiles_y;
        let done = AtomicUsize::new(0);
        let run_tile = |t: usize| -> Option<T> {
            if let Some(c) = &opts.cancel {
                if c.load(Ordering::Relaxed) {
                    return None;
                }
            }
            let x0 = r.x0 + ((t % tiles_x) * TILE) as i64;
            let y0 = r.y0 + ((t / tiles_x) * TILE) as i64;
            let tile = Tile {
                x0,
                y0,
                w: (TILE as i64).min(r.x0 + r.w - x0),
                h: (TILE as i64).min(r.y0 + r.h - y0),
            };
            let out = per_tile(tile);
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(p) = &opts.progress {
                p(k, n_tiles);
            }
            Some(out)
        };
        let run = || -> Vec<Option<T>> { (0..n_tiles).into_par_iter().map(run_tile).collect() };
        let results = match opts.threads {
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?
                .install(run),
            None => run(),
        };
        results
            .into_iter()
            .map(|r| r.ok_or(Error::Interrupted))
            .collect()
    }
}

/// Memory the system can still give to this process, in bytes
/// (`MemAvailable` of /proc/meminfo); `None` where it is not known.
fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Runs `sample(ray, stream, out)` for every sample of every pixel of the
/// sensor's crop window (and its border, with `sample_border`), splats the
/// `channels` values it writes, and returns the merged crop-window block
/// and the number of samples left out for a non-finite value (reported
/// once with [`report_non_finite`]). Shared by primal and forward-mode
/// rendering.
pub(crate) fn render_samples<F>(
    scene: &Scene,
    opts: &RenderOptions,
    channels: usize,
    what: &str,
    sample: F,
) -> Result<(ImageBlock, usize)>
where
    F: Fn(&CameraSample, &mut SampleStream, &mut [f32]) + Sync,
{
    render_tiles(scene, opts, channels, what, |layout, tile, block| {
        let filter = &layout.sensor.film.rfilter;
        let mut out = vec![0.0f32; channels];
        let mut non_finite = 0usize;
        layout.for_each_sample(tile, |pos, cs, rng| {
            out.fill(0.0);
            sample(cs, rng, &mut out);
            if out.iter().all(|v| v.is_finite()) {
                block.put(filter, pos.x, pos.y, &out);
            } else {
                non_finite += 1;
            }
        });
        non_finite
    })
}

/// Runs `fill(layout, tile, block)` for every tile of the sampled region,
/// in parallel: it splats the samples of `tile` (`channels` values each)
/// into `block`, which covers the tile and its filter margin, and returns
/// how many it left out for a non-finite value. Returns the merged
/// crop-window block and the number left out (reported once with
/// [`report_non_finite`]).
pub(crate) fn render_tiles<F>(
    scene: &Scene,
    opts: &RenderOptions,
    channels: usize,
    what: &str,
    fill: F,
) -> Result<(ImageBlock, usize)>
where
    F: Fn(&SampleLayout, Tile, &mut ImageBlock) -> usize + Sync,
{
    let layout = SampleLayout::new(scene, opts)?;
    layout.check_memory(scene, opts, channels, false)?;
    let blocks = layout.map_tiles(opts, |tile| {
        let mut block = layout.tile_block(tile, channels);
        let non_finite = fill(&layout, tile, &mut block);
        (block, non_finite)
    })?;
    let (cw, ch) = layout.size();
    let mut image = ImageBlock::new(0, 0, cw, ch, channels);
    let mut non_finite = 0;
    for (b, n) in &blocks {
        image.accumulate(b);
        non_finite += n;
    }
    report_non_finite(what, non_finite, &layout);
    Ok((image, non_finite))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    #[cfg(target_os = "linux")]
    fn a_film_larger_than_memory_is_refused_before_allocating() {
        let cbox = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cbox.xml");
        let d = [("res".to_string(), "100000".to_string())];
        let scene = Scene::load_file(&cbox, &d).unwrap();
        let e = render(&scene, &RenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("the film 100000×100000 needs about"), "{e}");
        assert!(e.contains("GiB are available"), "{e}");
        assert!(e.contains("--force") && e.contains("force=True"), "{e}");
        // forward mode shares the check
        let e = crate::diff::render_forward(&scene, &[], &RenderOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs about"), "{e}");
    }

    #[test]
    fn the_alpha_of_an_rgba_film_is_where_the_camera_rays_reach_a_surface() {
        // path, direct and volpath report whether their own camera ray hit
        // something; an aov integrator's alpha comes from tracing the camera
        // ray again. The camera samples do not depend on the integrator, so
        // the alpha channels must agree value for value, and the scene
        // shows both surfaces and the environment.
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/textured.xml");
        let text = std::fs::read_to_string(&file).unwrap().replace(
            r#"name="pixel_format" value="rgb""#,
            r#"name="pixel_format" value="rgba""#,
        );
        let path_integrator = r#"<integrator type="path" id="integrator">
        <integer name="max_depth" value="$max_depth"/>
    </integrator>"#;
        assert!(text.contains(path_integrator) && text.contains("rgba"));
        let alpha = |integrator: &str| {
            let xml = text.replace(path_integrator, integrator);
            let d = [
                ("res".to_string(), "24".to_string()),
                ("spp".to_string(), "4".to_string()),
            ];
            let scene = Scene::load_str(&xml, &file, &d).unwrap();
            let img = render(&scene, &RenderOptions::default()).unwrap();
            let a = img.channel_names.iter().position(|c| c == "A").unwrap();
            let n = img.channels();
            img.data.chunks(n).map(|px| px[a]).collect::<Vec<f32>>()
        };
        let traced_again = alpha(
            r#"<integrator type="aov"><string name="aovs" value="dd.y:depth"/></integrator>"#,
        );
        let covered = traced_again.iter().filter(|&&a| a == 1.0).count();
        let empty = traced_again.iter().filter(|&&a| a == 0.0).count();
        assert!(
            covered > 0 && empty > 0,
            "{covered} covered, {empty} empty pixels"
        );
        for integrator in [
            path_integrator,
            r#"<integrator type="direct"/>"#,
            r#"<integrator type="volpath"/>"#,
        ] {
            assert_eq!(alpha(integrator), traced_again, "{integrator}");
        }
    }

    #[test]
    fn buffer_estimate_covers_the_images_of_a_pass() {
        let cbox = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cbox.xml");
        let d = [("res".to_string(), "64".to_string())];
        let scene = Scene::load_file(&cbox, &d).unwrap();
        let layout = SampleLayout::new(&scene, &RenderOptions::default()).unwrap();
        let primal = layout.buffer_bytes(&scene, 3, false);
        // at least the merged f64 block and the developed f32 image
        assert!(primal >= 64.0 * 64.0 * (4.0 * 8.0 + 3.0 * 4.0), "{primal}");
        // the adjoint image, and the merged weights
        let reverse = layout.buffer_bytes(&scene, 3, true);
        assert!(reverse >= 64.0 * 64.0 * (3.0 * 4.0 + 8.0), "{reverse}");
        assert!(layout.buffer_bytes(&scene, 7, false) > primal);
    }
}
