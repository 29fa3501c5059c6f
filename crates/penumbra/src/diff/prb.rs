//! Reverse mode, one path at a time.
//!
//! Each sample's path is traced once on [`Var`]s, which record the path's
//! computation on a thread-local tape; its radiance L is then
//! back-propagated with the adjoint radiance δL = ∂loss/∂L of the sample
//! (gathered from the adjoint image through the pixel filter) and the tape
//! is cleared. The derivative is exactly that of the sample's estimate, in
//! the parameterisation the integrator uses (see `crate::integrator::scatter`),
//! whatever couples the vertices: with attached geometry a vertex depends
//! on the previous ones (the camera ray, the chain of delta bounces, the
//! direction between two moving points), which a per-vertex replay
//! (Vicini et al. 2021, "Path Replay Backpropagation", where only
//! material parameters move) cannot follow.
//!
//! Memory: the tape holds one path (a few hundred nodes per vertex, kept
//! by each worker thread), plus the parameter and image buffers; it does
//! not grow with the image size or the sample count. Unlike Mitsuba's
//! megakernel on a GPU, one CPU thread owns one path at a time, so storing
//! that path's tape costs kilobytes.
//!
//! The boundary term of primary visibility is added by
//! `primary_boundary.rs`, which records one edge at a time.

use super::prb_lanes::LaneAdjoint;
use super::{
    delta_shadow_boundary, primary_boundary, shadow_boundary, warn_missing_boundary_terms,
    BoundaryTerms,
};
use crate::ad::lanes::{each_lane, LaneMask, Lanes};
use crate::ad::reverse::{backward, clear_tape};
use crate::ad::Var;
use crate::error::{Error, Result};
use crate::image::film::PixelSplat;
use crate::image::ImageBlock;
use crate::integrator::lanes::lane_width;
use crate::integrator::render::{report_non_finite, SampleLayout};
use crate::integrator::RenderOptions;
use crate::params::{ParamId, ParamView, Seeds};
use crate::scene::Scene;
use glam::Vec2;
use std::borrow::Cow;
use std::sync::Mutex;

/// Gradients of a loss with respect to scene parameters, shaped like the
/// parameters.
#[derive(Clone, Debug, Default)]
pub struct Gradients {
    pub entries: Vec<GradEntry>,
    /// Samples left out because their radiance (or, for a boundary term,
    /// their value) was NaN or infinite (reported once per call with
    /// [`crate::warn()`]); a single non-finite element adjoint is dropped
    /// by [`crate::ad::reverse::backward`].
    pub non_finite_samples: usize,
}

#[derive(Clone, Debug)]
pub struct GradEntry {
    pub key: String,
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

impl Gradients {
    pub fn get(&self, key: &str) -> Option<&[f32]> {
        self.entries
            .iter()
            .find(|e| e.key == key)
            .map(|e| e.data.as_slice())
    }
}

/// Elements per page of [`TileSums`] (log2).
const PAGE_BITS: u32 = 9;
const PAGE: usize = 1 << PAGE_BITS;

/// One worker's gradient sums over the tile it traces, one per
/// (parameter, element), added in the order the samples scatter them: the
/// same sums a map keyed by element would hold, at the cost of an array
/// access. The recorded elements are numbered in one flat index space
/// (`offsets`: where each parameter starts) cut into pages of [`PAGE`]
/// elements; a page gets its storage when the tile first touches it, so a
/// worker holds the pages its tile reads (a density grid or a texture may
/// have millions of elements, a tile's paths touch few of them).
///
/// The additions wait on memory (a 64³ density grid's sums are larger
/// than a core's L2 cache), so they are kept lean: in f32, as Mitsuba's
/// gradient buffers (half the footprint of f64; a tile's sums differ from
/// f64 ones by about 1e-6 relative, far below the estimate's noise; the
/// tiles are added in f64), and with no test on the value added to (which
/// elements were touched is found by scanning the touched pages at the
/// end of the tile).
pub(super) struct TileSums<'a> {
    offsets: &'a [usize],
    /// Per page: 1 + its slot in `values`; 0 if the tile has not touched it.
    page_slot: Vec<u32>,
    /// The pages touched, in slot order.
    pages: Vec<u32>,
    /// [`PAGE`] sums per slot; all zero between tiles.
    values: Vec<f32>,
}

impl<'a> TileSums<'a> {
    fn new(offsets: &'a [usize]) -> Self {
        let n = offsets.last().copied().unwrap_or(0);
        TileSums {
            offsets,
            page_slot: vec![0; n.div_ceil(PAGE)],
            pages: Vec::new(),
            values: Vec::new(),
        }
    }

    #[inline]
    pub(super) fn add(&mut self, id: ParamId, i: usize, g: f32) {
        let flat = self.offsets[id.0 as usize] + i;
        let at = self.slot_of(flat >> PAGE_BITS) * PAGE + (flat & (PAGE - 1));
        self.values[at] += g;
    }

    /// Adds `gs` to elements `i..i + gs.len()` of parameter `id` (a
    /// texel's channels): one page look-up where the run lies in one page,
    /// the same sums as [`TileSums::add`] element by element.
    #[inline]
    pub(super) fn add_run(&mut self, id: ParamId, i: usize, gs: &[f32]) {
        let flat = self.offsets[id.0 as usize] + i;
        let within = flat & (PAGE - 1);
        if within + gs.len() > PAGE {
            for (j, &g) in gs.iter().enumerate() {
                self.add(id, i + j, g);
            }
            return;
        }
        let at = self.slot_of(flat >> PAGE_BITS) * PAGE + within;
        for (v, &g) in self.values[at..at + gs.len()].iter_mut().zip(gs) {
            *v += g;
        }
    }

    /// The slot of `page` in `values` (counted from 0), given storage the
    /// first time the tile touches the page.
    #[inline(always)]
    fn slot_of(&mut self, page: usize) -> usize {
        let mut slot = self.page_slot[page] as usize;
        if slot == 0 {
            self.pages.push(page as u32);
            slot = self.pages.len();
            self.page_slot[page] = slot as u32;
            if self.values.len() < slot * PAGE {
                self.values.resize(slot * PAGE, 0.0);
            }
        }
        slot - 1
    }

    /// The tile's sums that are not zero, (parameter, element, sum) (a sum
    /// that is zero would add nothing); leaves the buffers zero for the
    /// next tile.
    fn take(&mut self) -> Vec<(u32, u32, f64)> {
        let mut out = Vec::new();
        for (page, values) in self.pages.iter().zip(self.values.chunks_exact_mut(PAGE)) {
            let first = *page as usize * PAGE;
            for (j, v) in values.iter_mut().enumerate() {
                if *v != 0.0 {
                    let flat = first + j;
                    // the parameter whose range holds `flat`
                    let id = self.offsets.partition_point(|&o| o <= flat) - 1;
                    out.push((id as u32, (flat - self.offsets[id]) as u32, *v as f64));
                    *v = 0.0;
                }
            }
            self.page_slot[*page as usize] = 0;
        }
        self.pages.clear();
        out
    }
}

/// Gradients of a loss with respect to scene parameters, given
/// `d_image` = ∂loss/∂image (crop-window height × width × 3, row-major,
/// or × 4 with an rgba film, whose alpha entries are ignored; any other
/// length is an error naming both shapes),
/// by path replay with the same random numbers as
/// [`crate::integrator::render`] with the same options. `keys` selects
/// the parameters (default: every differentiable one that moves no surface,
/// frame or camera: materials, textures, emitters). When one of them moves
/// geometry or a pinhole or orthographic camera, the boundary term of
/// primary visibility is added, from the same edge samples as
/// [`super::render_forward`] takes with the same options (`sppp`), so that
/// the two modes agree up to rounding.
/// Which parameters are recorded, the tapes and the gradient sums live in
/// this call, not in the scene. `opts.spp`, where given, overrides the
/// integrator's `sppc`; 0 leaves the interior term out.
pub fn render_backward(
    scene: &Scene,
    d_image: &[f32],
    keys: Option<&[&str]>,
    opts: &RenderOptions,
) -> Result<Gradients> {
    let opts = &scene.integrator.derivative_options(scene, opts)?;
    scene.integrator.check_differentiable()?;
    let film = &scene.sensor(opts.sensor)?.film;
    let (cw, ch) = film.crop_size;
    let d_image: Cow<[f32]> = if film.alpha && d_image.len() == cw * ch * 4 {
        // RGBA: alpha does not depend on the parameters differentiated here
        Cow::Owned(
            d_image
                .chunks_exact(4)
                .flat_map(|px| [px[0], px[1], px[2]])
                .collect(),
        )
    } else {
        Cow::Borrowed(d_image)
    };
    if d_image.len() != cw * ch * 3 {
        let n = d_image.len();
        let got = if n.is_multiple_of(cw * ch) {
            format!("{ch}×{cw}×{}", n / (cw * ch))
        } else {
            format!("{n} values")
        };
        let film_shape = if film.alpha {
            format!("{ch}×{cw}×4 (RGBA; or {ch}×{cw}×3 without alpha)")
        } else {
            format!("{ch}×{cw}×3 (RGB)")
        };
        return Err(Error::Invalid(format!(
            "the adjoint image (∂loss/∂image) is {got}, but the film's image is {film_shape}, \
             height × width × channels; pass one value per pixel and channel"
        )));
    }
    if let Some(i) = d_image.iter().position(|v| !v.is_finite()) {
        return Err(Error::Invalid(format!(
            "the image gradient has a non-finite value at index {i}"
        )));
    }
    let terms = BoundaryTerms::of(scene, opts)?;
    let mut edges_move = false;
    let ids: Vec<ParamId> = match keys {
        Some(keys) => {
            edges_move = warn_missing_boundary_terms(scene, keys, terms)?;
            keys.iter()
                .map(|k| scene.params.require(k))
                .collect::<std::result::Result<_, _>>()?
        }
        None => scene
            .params
            .iter()
            .filter(|(_, p)| p.flags.differentiable && !p.flags.moves_frames)
            .map(|(id, _)| id)
            .collect(),
    };
    let seeds = Seeds::recorded(&scene.params, &ids)?;
    let store = scene.params.view(&seeds);
    let (mut sums, mut non_finite_samples) = if opts.spp == Some(0) {
        // sppc = 0: the interior term is off
        let zeros = scene.params.iter().map(|(_, p)| vec![0.0; p.data.len()]);
        (zeros.collect(), 0)
    } else {
        let lanes = LaneAdjoint::new(scene, &store, lane_width(opts.lanes)?);
        backward_pass(scene, &store, &d_image, opts, lanes.as_ref())?
    };
    if edges_move && terms.primary {
        non_finite_samples += primary_boundary::add_primary_boundary_gradients(
            scene, &store, &d_image, opts, &mut sums,
        )?;
    }
    if edges_move && terms.shadow {
        non_finite_samples += shadow_boundary::add_shadow_boundary_gradients(
            scene, &store, &d_image, opts, &mut sums,
        )?;
    }
    if edges_move && terms.delta_shadow {
        non_finite_samples += delta_shadow_boundary::add_delta_shadow_boundary_gradients(
            scene, &store, &d_image, opts, &mut sums,
        )?;
    }
    Ok(Gradients {
        non_finite_samples,
        entries: ids
            .iter()
            .map(|&id| {
                let p = scene.params.get(id);
                GradEntry {
                    key: p.key.clone(),
                    shape: p.shape.clone(),
                    data: sums[id.0 as usize].iter().map(|&g| g as f32).collect(),
                }
            })
            .collect(),
    })
}

/// The interior term: every sample's path differentiated by the recorded
/// parameters, in lanes with `lanes` (`prb_lanes.rs`), else one path at a
/// time on a tape.
pub(super) fn backward_pass(
    scene: &Scene,
    store: &ParamView,
    d_image: &[f32],
    opts: &RenderOptions,
    lanes: Option<&LaneAdjoint>,
) -> Result<(Vec<Vec<f64>>, usize)> {
    let layout = SampleLayout::new(scene, opts)?;
    layout.check_memory(scene, opts, 3, true)?;
    let filter = &layout.sensor.film.rfilter;
    let (cw, ch) = layout.size();

    // 1. total filter weight per pixel (positions only: no tracing)
    let weight_blocks = layout.map_tiles(opts, |tile| {
        let mut block = layout.tile_block(tile, 0);
        // a pixel's samples eight at a time, summed over the pixel before
        // each pixel they reach is updated (filters too wide for the
        // window one sample at a time)
        const N: usize = 8;
        let mut splat = PixelSplat::<N>::new(filter);
        for y in tile.y0..tile.y0 + tile.h {
            for x in tile.x0..tile.x0 + tile.w {
                if let Some(splat) = &mut splat {
                    splat.start(x, y);
                }
                for first in (0..layout.spp).step_by(N) {
                    let pos: [Vec2; N] = each_lane(|k| {
                        let s = (first + k as u32).min(layout.spp - 1);
                        layout.camera_sample(x, y, s).0
                    });
                    let keep = LaneMask::from_fn(|k| first + (k as u32) < layout.spp);
                    let px = Lanes::from_fn(|k| pos[k].x);
                    let py = Lanes::from_fn(|k| pos[k].y);
                    match &mut splat {
                        Some(splat) => splat.add::<0>(filter, px, py, [], keep),
                        None => {
                            for k in (0..N).filter(|&k| keep.lane(k)) {
                                block.put(filter, px.0[k], py.0[k], &[]);
                            }
                        }
                    }
                }
                if let Some(splat) = &splat {
                    splat.flush::<0>(&mut block);
                }
            }
        }
        block
    })?;
    let mut weights = ImageBlock::new(0, 0, cw, ch, 0);
    for b in &weight_blocks {
        weights.accumulate(b);
    }
    let adjoint = weights.adjoint_image(d_image);

    // 2. trace every sample on recorded variables and backpropagate its
    //    adjoint radiance
    // the flat index of each recorded parameter's first element
    let mut offsets = Vec::with_capacity(scene.params.len() + 1);
    offsets.push(0);
    for (id, p) in scene.params.iter() {
        let n = if store.is_recorded(id) {
            p.data.len()
        } else {
            0
        };
        offsets.push(offsets.last().unwrap() + n);
    }
    // one TileSums per worker at most, handed from tile to tile
    let spare = Mutex::new(Vec::<TileSums>::new());
    let tiles = layout.map_tiles(opts, |tile| {
        let mut grads = spare
            .lock()
            .unwrap()
            .pop()
            .unwrap_or_else(|| TileSums::new(&offsets));
        let mut non_finite = 0usize;
        if let Some(lanes) = lanes {
            non_finite = lanes.tile(&layout, tile, &adjoint, &mut grads);
        } else {
            layout.for_each_sample(tile, |pos, cs, rng| {
                let delta = adjoint.gather(filter, pos.x, pos.y);
                if delta == [0.0; 3] {
                    return;
                }
                clear_tape();
                let l = scene
                    .integrator
                    .radiance::<Var>(scene, store, cs, rng)
                    .expect("path and direct integrators estimate radiance");
                if !l.val().is_finite() {
                    non_finite += 1;
                    clear_tape();
                    return;
                }
                // `backward` hands over finite values only
                backward(
                    &[(l.x, delta[0]), (l.y, delta[1]), (l.z, delta[2])],
                    |id, i, g| grads.add(id, i, g),
                );
            });
        }
        let sums = grads.take();
        spare.lock().unwrap().push(grads);
        (sums, non_finite)
    })?;
    let mut sums: Vec<Vec<f64>> = scene
        .params
        .iter()
        .map(|(id, p)| {
            if store.is_recorded(id) {
                vec![0.0; p.data.len()]
            } else {
                Vec::new()
            }
        })
        .collect();
    // each tile holds one sum per element: adding tiles in tile order
    // fixes the summation order
    let mut non_finite = 0;
    for (t, n) in tiles {
        non_finite += n;
        for (id, i, g) in t {
            sums[id as usize][i as usize] += g;
        }
    }
    report_non_finite("reverse mode", non_finite, &layout);
    Ok((sums, non_finite))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn an_adjoint_of_another_shape_is_an_error_naming_both_shapes() {
        let cbox = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cbox.xml");
        let d = [("res".to_string(), "8".to_string())];
        let scene = Scene::load_file(&cbox, &d).unwrap();
        let opts = RenderOptions {
            spp: Some(1),
            ..Default::default()
        };
        let keys = ["red.reflectance.value"];
        for (len, got) in [(8 * 8 * 4, "8×8×4"), (8 * 8 * 3 + 1, "193 values")] {
            let e = render_backward(&scene, &vec![1.0; len], Some(&keys), &opts)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!(
                    "the adjoint image (∂loss/∂image) is {got}, but the film's image is 8×8×3"
                )),
                "{e}"
            );
        }
        let g = render_backward(&scene, &[1.0; 8 * 8 * 3], Some(&keys), &opts).unwrap();
        assert_eq!(g.entries.len(), 1);

        // an rgba film takes its RGBA adjoint (alpha ignored) or an RGB one
        let text = std::fs::read_to_string(&cbox).unwrap();
        let rgb_format = "<string name=\"pixel_format\" value=\"rgb\"/>";
        assert!(text.contains(rgb_format));
        let text = text.replace(rgb_format, "<string name=\"pixel_format\" value=\"rgba\"/>");
        let rgba = Scene::load_str(&text, &cbox, &d).unwrap();
        let rgb_adjoint = [0.5f32; 8 * 8 * 3];
        let rgba_adjoint: Vec<f32> = (0..8 * 8 * 4)
            .map(|i| if i % 4 == 3 { 7.0 } else { 0.5 })
            .collect();
        let a = render_backward(&rgba, &rgb_adjoint, Some(&keys), &opts).unwrap();
        let b = render_backward(&rgba, &rgba_adjoint, Some(&keys), &opts).unwrap();
        assert_eq!(a.entries[0].data, b.entries[0].data);
        let e = render_backward(&rgba, &[1.0; 8 * 8 * 2], Some(&keys), &opts)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("is 8×8×2, but the film's image is 8×8×4 (RGBA; or 8×8×3 without alpha)"),
            "{e}"
        );
    }
}
