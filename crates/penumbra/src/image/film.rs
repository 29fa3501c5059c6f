//! The film (Mitsuba's `hdrfilm`): image size, crop window, reconstruction
//! filter, and the accumulation of filtered samples.

use super::rfilter::ReconstructionFilter;
use crate::ad::lanes::{LaneMask, Lanes};
use crate::ad::{Float, Mask, Real};
use crate::error::Result;
use crate::math::{ceil_i64, floor_i64};
use crate::scene::{Class, Node};

/// Image geometry and reconstruction.
#[derive(Clone, Debug)]
pub struct Film {
    /// Full film size (pixels).
    pub width: usize,
    pub height: usize,
    /// The crop window that is rendered: offset and size.
    pub crop_offset: (usize, usize),
    pub crop_size: (usize, usize),
    pub rfilter: ReconstructionFilter,
    /// Also place samples in the border outside the crop window that the
    /// filter reaches, so edge pixels get as many samples as inner ones.
    pub sample_border: bool,
    /// Keep an alpha channel in the output (`pixel_format="rgba"`).
    pub alpha: bool,
}

impl Film {
    pub fn from_node(node: &Node) -> Result<Film> {
        if node.plugin != "hdrfilm" {
            return Err(node.error(format!(
                "unknown film plugin '{}' (Penumbra has: hdrfilm)",
                node.plugin
            )));
        }
        let width = node.int_min("width", 768, 1)? as usize;
        let height = node.int_min("height", 576, 1)? as usize;
        let cx = node.int_min("crop_offset_x", 0, 0)? as usize;
        let cy = node.int_min("crop_offset_y", 0, 0)? as usize;
        let cw = node.int_min("crop_width", width as i64, 1)? as usize;
        let ch = node.int_min("crop_height", height as i64, 1)? as usize;
        if cx + cw > width || cy + ch > height {
            return Err(node.error(format!(
                "crop window {cw}x{ch} at ({cx}, {cy}) exceeds the film size {width}x{height}"
            )));
        }
        let alpha = node.choice("pixel_format", &["rgb", "rgba"])? == "rgba";
        // Output precision: Penumbra always writes float32 EXR.
        node.choice("component_format", &["float32", "float16"])?;
        node.choice("file_format", &["openexr", "exr"])?;
        // Mitsuba 0.6's text overlay on the image; Mitsuba 3's hdrfilm accepts
        // the parameter in scenes of every version and draws nothing.
        node.bool("banner", false)?;
        let rfilter = match node.children(Class::Rfilter).as_slice() {
            [] => ReconstructionFilter::gaussian(0.5),
            [f] => ReconstructionFilter::from_node(f)?,
            _ => return Err(node.error("more than one <rfilter>")),
        };
        let sample_border = node.bool("sample_border", false)?;
        Ok(Film {
            width,
            height,
            crop_offset: (cx, cy),
            crop_size: (cw, ch),
            rfilter,
            sample_border,
            alpha,
        })
    }

    /// A film of the given size with a box filter (tests, defaults).
    pub fn new(width: usize, height: usize, rfilter: ReconstructionFilter) -> Film {
        Film {
            width,
            height,
            crop_offset: (0, 0),
            crop_size: (width, height),
            rfilter,
            sample_border: false,
            alpha: false,
        }
    }
}

/// Weighted sums of filtered samples over a rectangle of pixels (a tile,
/// or the whole crop window), in f64; `channels` values per sample.
#[derive(Clone, Debug)]
pub struct ImageBlock {
    /// Pixel coordinates (in the crop window) of the block's first pixel;
    /// may be negative for blocks that include the filter margin.
    pub x0: i64,
    pub y0: i64,
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// `channels` weighted sums, then the weight sum, per pixel.
    pub data: Vec<f64>,
}

impl ImageBlock {
    pub fn new(x0: i64, y0: i64, width: usize, height: usize, channels: usize) -> ImageBlock {
        ImageBlock {
            x0,
            y0,
            width,
            height,
            channels,
            data: vec![0.0; width * height * (channels + 1)],
        }
    }

    /// Calls `f(i, j, w)` for every pixel `(i, j)` of this block that the
    /// filter centred on the continuous position `(px, py)` reaches with
    /// weight `w ≠ 0` (negative lobes included; pixel `(i, j)` spans `[i, i+1) × [j, j+1)`).
    #[inline]
    pub fn footprint(
        &self,
        filter: &ReconstructionFilter,
        px: f32,
        py: f32,
        f: impl FnMut(i64, i64, f64),
    ) {
        let bounds = (self.x0, self.y0, self.width as i64, self.height as i64);
        Self::footprint_in(bounds, filter, px, py, f);
    }

    /// [`ImageBlock::footprint`] over the block `(x0, y0, width, height)`.
    /// The separable filter is evaluated once per column and once per row
    /// (not once per pixel).
    #[inline(always)]
    fn footprint_in(
        (x0, y0, width, height): (i64, i64, i64, i64),
        filter: &ReconstructionFilter,
        px: f32,
        py: f32,
        mut f: impl FnMut(i64, i64, f64),
    ) {
        if let ReconstructionFilter::Box = filter {
            // A sample strictly inside pixel (i, j) reaches that pixel only
            // (|k + 0.5 − c| ≤ 0.5 holds for k = ⌊c⌋ alone when c is not
            // an integer): no footprint, no loops. A sample on a pixel
            // border (or NaN) takes the general test below.
            let (i, j) = (px as i64, py as i64);
            if (i as f32) < px && (j as f32) < py {
                if (x0..x0 + width).contains(&i) && (y0..y0 + height).contains(&j) {
                    f(i, j, 1.0);
                }
                return;
            }
        }
        let r = filter.radius();
        // pixels whose centre (i + 0.5) is within r of px
        let i0 = ceil_i64(px - 0.5 - r).max(x0);
        let i1 = floor_i64(px - 0.5 + r).min(x0 + width - 1);
        let j0 = ceil_i64(py - 0.5 - r).max(y0);
        let j1 = floor_i64(py - 0.5 + r).min(y0 + height - 1);
        if i1 < i0 {
            return;
        }
        if let ReconstructionFilter::Box = filter {
            // one pixel (two or four on pixel borders), weight one: the
            // test of `ReconstructionFilter::eval`, without the weights'
            // tables below
            let inside = |k: i64, c: f32| (k as f32 + 0.5 - c).abs() <= 0.5;
            for j in (j0..=j1).filter(|&j| inside(j, py)) {
                for i in (i0..=i1).filter(|&i| inside(i, px)) {
                    f(i, j, 1.0);
                }
            }
            return;
        }
        // row and column weights, evaluated once per sample for
        // footprints up to 16 pixels wide
        const CACHE: usize = 16;
        let nx = (i1 - i0 + 1) as usize;
        let ny = (j1 - j0 + 1).max(0) as usize;
        if nx <= CACHE && ny <= CACHE {
            let (mut wx, mut wy) = ([0.0f32; CACHE], [0.0f32; CACHE]);
            filter.eval_span(i0, px, &mut wx[..nx]);
            filter.eval_span(j0, py, &mut wy[..ny]);
            for (dj, &ey) in wy[..ny].iter().enumerate() {
                if ey == 0.0 {
                    continue;
                }
                for (di, &ex) in wx[..nx].iter().enumerate() {
                    let w = (ey * ex) as f64;
                    if w != 0.0 {
                        f(i0 + di as i64, j0 + dj as i64, w);
                    }
                }
            }
            return;
        }
        for j in j0..=j1 {
            let wy = filter.eval(j as f32 + 0.5 - py);
            if wy == 0.0 {
                continue;
            }
            for i in i0..=i1 {
                let w = (wy * filter.eval(i as f32 + 0.5 - px)) as f64;
                if w != 0.0 {
                    f(i, j, w);
                }
            }
        }
    }

    /// Splats a sample at continuous crop-window position `(px, py)` to
    /// every pixel of the block the filter reaches.
    #[inline]
    pub fn put(&mut self, filter: &ReconstructionFilter, px: f32, py: f32, values: &[f32]) {
        debug_assert_eq!(values.len(), self.channels);
        let (x0, y0, width) = (self.x0, self.y0, self.width);
        let bounds = (x0, y0, width as i64, self.height as i64);
        let data = &mut self.data[..];
        let stride = values.len() + 1;
        if let Ok(rgb) = <&[f32; 3]>::try_from(values) {
            // RGB, the common case: a pixel's three sums and its weight
            // are one [f64; 4], updated with SIMD multiplies and adds (the
            // same operations as below, the weight's as `w · 1`) instead of
            // four scalar ones, each with a bounds check
            let v = rgb.map(f64::from);
            let v = [v[0], v[1], v[2], 1.0];
            Self::footprint_in(bounds, filter, px, py, |i, j, w| {
                let o = (((j - y0) as usize) * width + (i - x0) as usize) * 4;
                let px: &mut [f64; 4] = (&mut data[o..o + 4]).try_into().expect("four f64");
                for (acc, v) in px.iter_mut().zip(v) {
                    *acc += w * v;
                }
            });
            return;
        }
        Self::footprint_in(bounds, filter, px, py, |i, j, w| {
            let o = (((j - y0) as usize) * width + (i - x0) as usize) * stride;
            let (sums, weight) = data[o..o + stride].split_at_mut(stride - 1);
            for (acc, v) in sums.iter_mut().zip(values) {
                *acc += w * *v as f64;
            }
            weight[0] += w;
        });
    }

    /// The adjoint of developing, for the adjoint of splatting
    /// ([`AdjointImage::gather`]): `d_image[p] / W_p` per pixel p and
    /// channel, where `W_p` is pixel p's total filter weight (the weight
    /// channel of this block, which must hold the whole crop window) and
    /// `d_image` is `∂loss/∂pixel`, RGB, row-major; zero where no sample
    /// reached the pixel. Dividing once per pixel here saves a division
    /// per pixel reached by each sample.
    pub fn adjoint_image(&self, d_image: &[f32]) -> AdjointImage {
        let stride = self.channels + 1;
        let data = self
            .data
            .chunks_exact(stride)
            .zip(d_image.chunks_exact(3))
            .map(|(px, d)| {
                let total = px[self.channels];
                if total != 0.0 {
                    std::array::from_fn(|c| (d[c] as f64 / total) as f32)
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        AdjointImage {
            bounds: (self.x0, self.y0, self.width as i64, self.height as i64),
            data,
        }
    }

    /// Adds the overlapping part of `other` into this block.
    pub fn accumulate(&mut self, other: &ImageBlock) {
        let stride = self.channels + 1;
        for oy in 0..other.height {
            let y = other.y0 + oy as i64 - self.y0;
            if y < 0 || y >= self.height as i64 {
                continue;
            }
            for ox in 0..other.width {
                let x = other.x0 + ox as i64 - self.x0;
                if x < 0 || x >= self.width as i64 {
                    continue;
                }
                let d = (y as usize * self.width + x as usize) * stride;
                let s = (oy * other.width + ox) * stride;
                for c in 0..stride {
                    self.data[d + c] += other.data[s + c];
                }
            }
        }
    }

    /// Weighted means per pixel (zero where the weights sum to zero), as f32
    /// row-major `height × width × channels`.
    pub fn develop(&self) -> Vec<f32> {
        let stride = self.channels + 1;
        let mut out = Vec::with_capacity(self.width * self.height * self.channels);
        for px in self.data.chunks_exact(stride) {
            let w = px[self.channels];
            // a weight sum may be negative (filters with negative lobes)
            let inv = if w != 0.0 { 1.0 / w } else { 0.0 };
            out.extend(px[..self.channels].iter().map(|v| (v * inv) as f32));
        }
        out
    }
}

/// `∂loss/∂pixel` divided by each pixel's total filter weight
/// ([`ImageBlock::adjoint_image`]).
pub struct AdjointImage {
    /// (x0, y0, width, height) of the crop window, as in [`ImageBlock`].
    bounds: (i64, i64, i64, i64),
    data: Vec<[f32; 3]>,
}

impl AdjointImage {
    /// The adjoint of splatting then developing: the derivative of the
    /// loss with respect to the RGB value of a sample at `(px, py)`,
    /// `Σ_p w_p · d_image[p] / W_p` over the pixels p it reaches.
    pub fn gather(&self, filter: &ReconstructionFilter, px: f32, py: f32) -> [f32; 3] {
        let (x0, y0, width, _) = self.bounds;
        let mut out = [0.0f32; 3];
        ImageBlock::footprint_in(self.bounds, filter, px, py, |i, j, w| {
            let a = &self.data[((j - y0) * width + (i - x0)) as usize];
            let w = w as f32;
            for (o, a) in out.iter_mut().zip(a) {
                *o += w * a;
            }
        });
        out
    }
}

/// The most pixels a sample reaches on each side of its own through
/// [`PixelSplat`] and [`PixelGather`]: Lanczos' three lobes, a Gaussian
/// up to σ = 0.875. Wider filters take the per-sample [`ImageBlock::put`]
/// and [`AdjointImage::gather`].
const MAX_REACH: usize = 3;
/// Pixels of the widest window, row by row.
const WINDOW: usize = (2 * MAX_REACH + 1) * (2 * MAX_REACH + 1);
/// Channels a [`PixelSplat`] sums (RGB and alpha).
const MAX_CHANNELS: usize = 4;

/// The pixels a filter reaches from the samples of one pixel: a square
/// of side `2 reach + 1` about it, where that fits [`MAX_REACH`]. Shared
/// by [`PixelSplat`] and [`PixelGather`].
#[derive(Clone, Copy)]
struct PixelWindow {
    x: i64,
    y: i64,
    reach: usize,
}

/// Per pixel column and row of a window, each lane's filter weight.
type SpanWeights<const N: usize> = ([Lanes<N>; 2 * MAX_REACH + 1], [Lanes<N>; 2 * MAX_REACH + 1]);

impl PixelWindow {
    /// The window of `filter`, if it fits: a sample in pixel x (at a
    /// position in `[x, x + 1]`, the end included for rounding) reaches the
    /// pixels whose centres are within the radius r, `ceil(x − 0.5 − r) ≥
    /// x − ⌊r + 0.5⌋` to `floor(x + 0.5 + r) = x + ⌊r + 0.5⌋`.
    fn new(filter: &ReconstructionFilter) -> Option<PixelWindow> {
        let reach = (filter.radius() + 0.5).floor();
        (reach <= MAX_REACH as f32).then_some(PixelWindow {
            x: 0,
            y: 0,
            reach: reach as usize,
        })
    }

    /// Pixels along a side.
    #[inline(always)]
    fn side(&self) -> usize {
        2 * self.reach + 1
    }

    /// The window's first column and row.
    #[inline(always)]
    fn origin(&self) -> (i64, i64) {
        let reach = self.reach as i64;
        (self.x - reach, self.y - reach)
    }

    /// The filter's weights of the samples at `(px[k], py[k])` (in this
    /// pixel) per column and row of the window, the first
    /// [`PixelWindow::side`] of each.
    #[inline(always)]
    fn weights<const N: usize>(
        &self,
        filter: &ReconstructionFilter,
        px: Lanes<N>,
        py: Lanes<N>,
    ) -> SpanWeights<N> {
        let (side, (x0, y0)) = (self.side(), self.origin());
        let zero = Lanes::splat(0.0);
        let (mut wx, mut wy) = ([zero; 2 * MAX_REACH + 1], [zero; 2 * MAX_REACH + 1]);
        filter.eval_span_lanes(x0, px, &mut wx[..side]);
        filter.eval_span_lanes(y0, py, &mut wy[..side]);
        (wx, wy)
    }
}

/// The samples of one pixel splatted `N` at a time (the path tracer in
/// lanes, `integrator::lanes`), summed where they land: per pixel of the
/// window the filter reaches from the sample's pixel, per channel and
/// for the weights, each lane's running sum in f32, added once into the
/// block's f64 sums when the pixel is done ([`PixelSplat::flush`]). A
/// block of samples thus costs the window's multiplies and adds in lanes,
/// where splatting it sample by sample into the f64 sums took each pixel's
/// sum over the lanes (13 % of cbox's lane kernel with its Gaussian
/// filter).
pub struct PixelSplat<const N: usize> {
    window: PixelWindow,
    /// Per pixel of the window, row by row: the sums of the channels'
    /// weighted values, then of the weights.
    sums: [[Lanes<N>; MAX_CHANNELS + 1]; WINDOW],
}

impl<const N: usize> PixelSplat<N> {
    /// A splat for `filter`, if its window is small enough.
    pub fn new(filter: &ReconstructionFilter) -> Option<PixelSplat<N>> {
        Some(PixelSplat {
            window: PixelWindow::new(filter)?,
            sums: [[Lanes::splat(0.0); MAX_CHANNELS + 1]; WINDOW],
        })
    }

    /// Starts pixel `(x, y)`, with nothing splatted (after the previous
    /// pixel's [`PixelSplat::flush`]).
    #[inline(always)]
    pub fn start(&mut self, x: i64, y: i64) {
        let side = self.window.side();
        (self.window.x, self.window.y) = (x, y);
        for s in &mut self.sums[..side * side] {
            *s = [Lanes::splat(0.0); MAX_CHANNELS + 1];
        }
    }

    /// Splats sample `k` at `(px[k], py[k])`, in this pixel, with the
    /// values `values[c][k]`; lanes where `keep[k]` is false are left out
    /// (their values may be NaN).
    #[inline(always)]
    pub fn add<const C: usize>(
        &mut self,
        filter: &ReconstructionFilter,
        px: Lanes<N>,
        py: Lanes<N>,
        values: [Lanes<N>; C],
        keep: LaneMask<N>,
    ) {
        const { assert!(C <= MAX_CHANNELS) };
        let PixelWindow { x, y, reach } = self.window;
        debug_assert!((0..N).all(|k| !keep.lane(k)
            || ((x as f32..=x as f32 + 1.0).contains(&px.0[k])
                && (y as f32..=y as f32 + 1.0).contains(&py.0[k]))));
        let side = self.window.side();
        let zero = Lanes::splat(0.0);
        let values = values.map(|v| Lanes::select(keep, v, zero));
        if let ReconstructionFilter::Box = filter {
            // samples strictly inside the pixel (all of them, nearly
            // always) reach it alone, with weight one: as `footprint_in`
            // has it, without the window's weights
            let (x, y) = (x as f32, y as f32);
            let inside = px.gt(x) & px.lt(x + 1.0) & py.gt(y) & py.lt(y + 1.0);
            if (inside | !keep).all() {
                let centre = &mut self.sums[reach * side + reach];
                for (s, v) in centre.iter_mut().zip(&values) {
                    *s += *v;
                }
                centre[C] += Lanes::select(keep, Lanes::splat(1.0), zero);
                return;
            }
        }
        let (mut wx, mut wy) = self.window.weights(filter, px, py);
        // both zero in the lanes left out, whose positions may lie far
        // from the pixel: no weight of theirs reaches the sums, whatever
        // a filter computes there
        for w in wx[..side].iter_mut().chain(&mut wy[..side]) {
            *w = Lanes::select(keep, *w, zero);
        }
        for (row, ey) in self.sums[..side * side].chunks_exact_mut(side).zip(&wy) {
            for (sums, ex) in row.iter_mut().zip(&wx) {
                let w = *ey * *ex;
                for (s, v) in sums.iter_mut().zip(&values) {
                    *s += w * *v;
                }
                sums[C] += w;
            }
        }
    }

    /// Adds the pixel's sums to `block` (the pixels of the window within
    /// it), `C` channels as [`PixelSplat::add`] had them.
    #[inline(always)]
    pub fn flush<const C: usize>(&self, block: &mut ImageBlock) {
        debug_assert_eq!(C, block.channels);
        let (side, (x0, y0)) = (self.window.side(), self.window.origin());
        let stride = C + 1;
        for (dj, row) in self.sums[..side * side].chunks_exact(side).enumerate() {
            let j = y0 + dj as i64 - block.y0;
            if !(0..block.height as i64).contains(&j) {
                continue;
            }
            for (di, sums) in row.iter().enumerate() {
                let i = x0 + di as i64 - block.x0;
                if !(0..block.width as i64).contains(&i) {
                    continue;
                }
                let o = (j as usize * block.width + i as usize) * stride;
                let pixel = &mut block.data[o..o + stride];
                for (acc, s) in pixel.iter_mut().zip(sums) {
                    *acc += lane_sum::<N>(|k| s.0[k] as f64);
                }
            }
        }
    }
}

/// [`AdjointImage::gather`] for the samples of one pixel, `N` at a time:
/// the adjoint values of the window the filter reaches from the pixel
/// read once ([`PixelGather::start`]), each block's weights and sums in
/// lanes.
pub struct PixelGather {
    window: PixelWindow,
    /// Per pixel of the window, row by row: the adjoint image's RGB (zero
    /// outside the crop window).
    values: [[f32; 3]; WINDOW],
}

impl PixelGather {
    /// A gather for `filter`, if its window is small enough.
    pub fn new(filter: &ReconstructionFilter) -> Option<PixelGather> {
        Some(PixelGather {
            window: PixelWindow::new(filter)?,
            values: [[0.0; 3]; WINDOW],
        })
    }

    /// Reads the window of pixel `(x, y)` from `image`.
    #[inline(always)]
    pub fn start(&mut self, image: &AdjointImage, x: i64, y: i64) {
        (self.window.x, self.window.y) = (x, y);
        let (side, (wx0, wy0)) = (self.window.side(), self.window.origin());
        let (x0, y0, width, height) = image.bounds;
        for (dj, row) in self.values[..side * side]
            .chunks_exact_mut(side)
            .enumerate()
        {
            let j = wy0 + dj as i64 - y0;
            for (di, v) in row.iter_mut().enumerate() {
                let i = wx0 + di as i64 - x0;
                let inside = (0..height).contains(&j) && (0..width).contains(&i);
                *v = if inside {
                    image.data[(j * width + i) as usize]
                } else {
                    [0.0; 3]
                };
            }
        }
    }

    /// `AdjointImage::gather` of the samples at `(px[k], py[k])`, in this
    /// pixel: the RGB derivatives of the loss with respect to their
    /// values.
    #[inline(always)]
    pub fn gather<const N: usize>(
        &self,
        filter: &ReconstructionFilter,
        px: Lanes<N>,
        py: Lanes<N>,
    ) -> [Lanes<N>; 3] {
        let side = self.window.side();
        let zero = Lanes::splat(0.0);
        let (wx, wy) = self.window.weights(filter, px, py);
        let mut out = [zero; 3];
        for (row, ey) in self.values[..side * side].chunks_exact(side).zip(&wy) {
            let mut along = [zero; 3];
            for (v, ex) in row.iter().zip(&wx) {
                for (a, v) in along.iter_mut().zip(v) {
                    *a += *ex * *v;
                }
            }
            for (o, a) in out.iter_mut().zip(along) {
                *o += *ey * a;
            }
        }
        out
    }
}

/// `f(0) + … + f(N − 1)` summed pairwise (halves, then quarters, …), so
/// that the additions of each step are independent and run as vector
/// instructions; `N` a power of two.
#[inline(always)]
fn lane_sum<const N: usize>(f: impl Fn(usize) -> f64) -> f64 {
    debug_assert!(N.is_power_of_two());
    let mut a = [0.0f64; N];
    for (k, a) in a.iter_mut().enumerate() {
        *a = f(k);
    }
    let mut n = N;
    while n > 1 {
        n /= 2;
        for k in 0..n {
            a[k] += a[k + n];
        }
    }
    a[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_filter_averages_samples_within_their_pixel() {
        let f = ReconstructionFilter::Box;
        let mut b = ImageBlock::new(0, 0, 2, 1, 1);
        b.put(&f, 0.2, 0.5, &[1.0]);
        b.put(&f, 0.9, 0.1, &[3.0]);
        b.put(&f, 1.5, 0.5, &[5.0]);
        assert_eq!(b.develop(), vec![2.0, 5.0]);
    }

    /// The footprint of a sample is the pixels of positive weight
    /// `eval(x) · eval(y)`, with that weight, also for samples on pixel
    /// borders and corners (where a box filter reaches two or four pixels)
    /// and near the block's edges.
    #[test]
    fn footprints_weigh_pixels_by_the_filter() {
        let filters = [
            ReconstructionFilter::Box,
            ReconstructionFilter::Tent { radius: 1.5 },
        ];
        let coords = [0.0f32, 0.5, 1.0, 1.25, 2.0, 2.5, 2.999, 3.0, 3.7, 4.0];
        for f in &filters {
            for &px in &coords {
                for &py in &coords {
                    let block = ImageBlock::new(0, 1, 4, 3, 1);
                    let mut got = Vec::new();
                    block.footprint(f, px, py, |i, j, w| got.push((i, j, w)));
                    let mut want = Vec::new();
                    for j in 1..4i64 {
                        for i in 0..4i64 {
                            let w = f.eval(j as f32 + 0.5 - py) * f.eval(i as f32 + 0.5 - px);
                            if w != 0.0 {
                                want.push((i, j, w as f64));
                            }
                        }
                    }
                    assert_eq!(got, want, "{f:?} at ({px}, {py})");
                }
            }
        }
    }

    /// The filters of the lanes' tests: every kind, a narrow Gaussian
    /// (its window a single pixel) and the default one.
    fn window_filters() -> [ReconstructionFilter; 6] {
        [
            ReconstructionFilter::Box,
            ReconstructionFilter::Tent { radius: 1.5 },
            ReconstructionFilter::gaussian(0.5),
            ReconstructionFilter::gaussian(0.1),
            ReconstructionFilter::Mitchell {
                b: 1.0 / 3.0,
                c: 1.0 / 3.0,
            },
            ReconstructionFilter::Lanczos { lobes: 3.0 },
        ]
    }

    /// Positions in pixel (x, y) for 8 lanes: uniform (a PCG step per
    /// number), or (`case` 1) on the pixel's borders, its own edges x and
    /// x + 1 included (which a rounded `x + u` can reach).
    fn lane_positions(x: i64, y: i64, case: u32, state: &mut u32) -> (Lanes<8>, Lanes<8>) {
        let mut uniform = || {
            *state = state.wrapping_mul(747796405).wrapping_add(2891336453);
            (*state >> 8) as f32 / (1u32 << 24) as f32
        };
        let offsets: [(f32, f32); 8] = std::array::from_fn(|k| match (case, k) {
            (1, 0) => (0.0, 0.5),
            (1, 1) => (1.0, 0.3),
            (1, 2) => (0.0, 0.0),
            (1, 3) => (0.4, 1.0),
            _ => (uniform(), uniform()),
        });
        (
            Lanes::from_fn(|k| x as f32 + offsets[k].0),
            Lanes::from_fn(|k| y as f32 + offsets[k].1),
        )
    }

    /// A pixel's samples through `PixelSplat`, two blocks of 8 lanes,
    /// add what `put` adds for each kept sample, for every filter:
    /// samples inside a pixel and on its borders, pixels at and beyond the
    /// block's edges (the window clipped), lanes left out (NaN values,
    /// positions far from the pixel), all
    /// kept or all left out. The window sums each lane's weighted values in
    /// f32 and takes the weights from `eval_span_lanes` (within 100 ε of
    /// `eval`, its test), so a pixel's sum may differ from the f64 sum of
    /// `put` by a few hundred ε of the sum of its terms' magnitudes.
    #[test]
    fn pixel_splat_adds_what_samples_one_by_one_add() {
        let mut state = 7u32;
        let zero = Lanes::<8>::splat(0.0);
        for f in &window_filters() {
            let splat = PixelSplat::<8>::new(f);
            let mut splat = splat.expect("a window up to three pixels on each side");
            for (x, y) in [(2, 2), (-1, 0), (4, 4), (-3, 1), (1, 6)] {
                for case in 0..4 {
                    let mut window = ImageBlock::new(-1, 0, 6, 5, 3);
                    let mut one_by_one = ImageBlock::new(-1, 0, 6, 5, 3);
                    let mut magnitudes = vec![0.0f64; 6 * 5 * 4];
                    splat.start(x, y);
                    for block in 0..2 {
                        let (px, py) = lane_positions(x, y, case + block, &mut state);
                        let keep = LaneMask::<8>::from_fn(|k| match case {
                            2 => true,
                            3 => false,
                            _ => k % 3 != 1,
                        });
                        // a lane left out may hold a position far away
                        let far = Lanes::select(keep, zero, Lanes::splat(1e4));
                        let (px, py) = (px + far, py + far);
                        let values: [Lanes<8>; 3] = std::array::from_fn(|c| {
                            Lanes::from_fn(|k| {
                                if keep.lane(k) {
                                    1.0 + c as f32 + (k as f32 * 0.37).fract()
                                } else {
                                    f32::NAN
                                }
                            })
                        });
                        splat.add(f, px, py, values, keep);
                        for k in (0..8).filter(|&k| keep.lane(k)) {
                            let v = values.map(|v| v.0[k]);
                            one_by_one.put(f, px.0[k], py.0[k], &v);
                            // the sums of |w| · |v| (and of |w|)
                            let bounds = (-1, 0, 6, 5);
                            ImageBlock::footprint_in(bounds, f, px.0[k], py.0[k], |i, j, w| {
                                let o = (j as usize * 6 + (i + 1) as usize) * 4;
                                for (c, v) in v.iter().chain(&[1.0]).enumerate() {
                                    magnitudes[o + c] += (w * *v as f64).abs();
                                }
                            });
                        }
                    }
                    splat.flush::<3>(&mut window);
                    let sums = window.data.iter().zip(&one_by_one.data).zip(&magnitudes);
                    for (i, ((a, b), m)) in sums.enumerate() {
                        assert!(
                            (a - b).abs() <= 300.0 * f32::EPSILON as f64 * m,
                            "{f:?}, pixel ({x}, {y}), case {case}, value {i}: {a} vs {b}"
                        );
                    }
                }
            }
        }
        // wider filters have no window: the loops splat sample by sample
        assert!(PixelSplat::<8>::new(&ReconstructionFilter::gaussian(1.3)).is_none());
        assert!(PixelGather::new(&ReconstructionFilter::Lanczos { lobes: 4.0 }).is_none());
    }

    /// `PixelGather` gives each lane what `AdjointImage::gather` gives its
    /// sample, for every filter, pixels at and beyond the crop window's
    /// edges among them (to the weights' precision, as above).
    #[test]
    fn pixel_gather_gathers_what_samples_one_by_one_gather() {
        let (w, h) = (6usize, 5usize);
        let mut weights = ImageBlock::new(0, 0, w, h, 0);
        weights
            .data
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = 0.5 + i as f64);
        let d_image: Vec<f32> = (0..w * h * 3)
            .map(|i| ((i * 7) % 11) as f32 - 5.0)
            .collect();
        let adjoint = weights.adjoint_image(&d_image);
        let mut state = 3u32;
        for f in &window_filters() {
            let mut window = PixelGather::new(f).expect("a window up to three pixels");
            for (x, y) in [(2, 2), (0, 0), (5, 4), (-1, 1), (3, 5)] {
                window.start(&adjoint, x, y);
                for case in 0..2 {
                    let (px, py) = lane_positions(x, y, case, &mut state);
                    let got = window.gather(f, px, py);
                    for k in 0..8 {
                        let want = adjoint.gather(f, px.0[k], py.0[k]);
                        let mut magnitude = 0.0f32;
                        ImageBlock::footprint_in(adjoint.bounds, f, px.0[k], py.0[k], |i, j, w| {
                            let a = adjoint.data[(j * 6 + i) as usize];
                            magnitude += a.iter().map(|a| (w as f32 * a).abs()).sum::<f32>();
                        });
                        for c in 0..3 {
                            assert!(
                                (got[c].0[k] - want[c]).abs() <= 300.0 * f32::EPSILON * magnitude,
                                "{f:?}, pixel ({x}, {y}), lane {k}: {} vs {}",
                                got[c].0[k],
                                want[c]
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn gaussian_splat_reaches_two_pixels_and_is_symmetric() {
        let f = ReconstructionFilter::gaussian(0.5);
        assert_eq!(f.border(), 2);
        let mut b = ImageBlock::new(-2, -2, 5, 5, 1);
        b.put(&f, 0.5, 0.5, &[1.0]);
        let w = |i: usize, j: usize| b.data[(j * 5 + i) * 2 + 1];
        // weight falls with distance and vanishes at the radius (2 pixels)
        assert!(w(2, 2) > w(1, 2) && w(1, 2) > 0.0 && w(0, 2) == 0.0);
        // to the precision of `eval_span` (100ε, see its test)
        assert!((w(1, 2) - w(3, 2)).abs() < 100.0 * f32::EPSILON as f64 * w(1, 2));
        assert!((f.eval(2.0)).abs() < 1e-7);
    }

    #[test]
    fn accumulating_tiles_equals_splatting_into_one_block() {
        let f = ReconstructionFilter::Tent { radius: 1.0 };
        let samples = [(0.3f32, 0.7f32, 1.0f32), (1.6, 0.2, 2.0), (2.9, 1.9, 4.0)];
        let mut whole = ImageBlock::new(0, 0, 3, 2, 1);
        let mut left = ImageBlock::new(-1, -1, 3, 4, 1);
        let mut right = ImageBlock::new(1, -1, 3, 4, 1);
        for &(x, y, v) in &samples {
            whole.put(&f, x, y, &[v]);
            if x < 1.0 {
                left.put(&f, x, y, &[v]);
            } else {
                right.put(&f, x, y, &[v]);
            }
        }
        let mut merged = ImageBlock::new(0, 0, 3, 2, 1);
        merged.accumulate(&left);
        merged.accumulate(&right);
        for (a, b) in merged.develop().iter().zip(whole.develop()) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    /// Gathering is the adjoint of splatting then developing: the
    /// derivative of `Σ_p d_image[p] · image[p]` with respect to one
    /// sample's value, by central differences of the developed image
    /// (linear in the value, so the difference is exact up to rounding).
    #[test]
    fn gather_is_the_adjoint_of_splat_and_develop() {
        let f = ReconstructionFilter::gaussian(0.5);
        let samples = [
            (0.3f32, 0.7f32),
            (1.6, 0.2),
            (2.9, 1.9),
            (3.5, 3.5),
            (0.0, 3.9),
        ];
        let (w, h) = (4, 4);
        let d_image: Vec<f32> = (0..w * h * 3)
            .map(|k| ((k * 7) % 11) as f32 - 5.0)
            .collect();
        let loss = |values: &[[f32; 3]]| -> f64 {
            let mut b = ImageBlock::new(0, 0, w, h, 3);
            for (&(x, y), v) in samples.iter().zip(values) {
                b.put(&f, x, y, v);
            }
            b.develop()
                .iter()
                .zip(&d_image)
                .map(|(&p, &d)| p as f64 * d as f64)
                .sum()
        };
        let mut weights = ImageBlock::new(0, 0, w, h, 0);
        for &(x, y) in &samples {
            weights.put(&f, x, y, &[]);
        }
        let adjoint = weights.adjoint_image(&d_image);
        let base = [[0.25f32, 0.5, 1.0]; 5];
        for (s, &(x, y)) in samples.iter().enumerate() {
            let g = adjoint.gather(&f, x, y);
            for c in 0..3 {
                let (mut up, mut down) = (base, base);
                up[s][c] += 0.125;
                down[s][c] -= 0.125;
                let fd = (loss(&up) - loss(&down)) / 0.25;
                assert!(
                    (g[c] as f64 - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                    "sample {s} channel {c}: {} vs {fd}",
                    g[c]
                );
            }
        }
    }
}
