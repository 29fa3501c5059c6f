//! Mitsuba's `bitmap` texture: an image (PNG, JPEG, OpenEXR) looked up by
//! surface uv with bilinear or nearest filtering.

use super::TextureT;
use crate::ad::lanes::{lanes3, LaneMask, Lanes};
use crate::ad::{Float, ScalarReal};
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::image::Image;
use crate::image::{read_image, srgb_to_linear};
use crate::math::{floor_i64, Spectrum, Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Texel filter of a bitmap lookup (`filter_type`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterType {
    /// Bilinear interpolation between the four nearest texel centres.
    Bilinear,
    /// The texel containing the lookup point.
    Nearest,
}

/// What happens to lookups outside [0, 1]² (`wrap_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WrapMode {
    /// Periodic tiling.
    Repeat,
    /// Tiling with every other copy mirrored.
    Mirror,
    /// The border texels extend outwards.
    Clamp,
}

impl WrapMode {
    /// Maps a texel index (possibly outside `0..n`) into `0..n`.
    #[inline]
    pub fn wrap(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        // inside the image (most lookups): no integer division
        if (0..n).contains(&i) {
            return i as usize;
        }
        (match self {
            WrapMode::Repeat => i.rem_euclid(n),
            WrapMode::Clamp => i.clamp(0, n - 1),
            WrapMode::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n {
                    m
                } else {
                    2 * n - 1 - m
                }
            }
        }) as usize
    }
}

/// Reads a `to_uv` transform parameter (3×3 affine, row-major, stored as
/// `<key>.to_uv`) and applies it to `uv`.
#[inline]
pub(crate) fn apply_to_uv<R: ScalarReal>(store: &ParamView, id: ParamId, uv: V2<R>) -> V2<R> {
    // one look-up of the parameter and one bounds check for its two rows
    let m = &store.data(id)[..6];
    V2::new(
        uv.x * m[0] + uv.y * m[1] + m[2],
        uv.x * m[3] + uv.y * m[4] + m[5],
    )
}

/// Registers a `to_uv` transform as the non-differentiable parameter
/// `<key>.to_uv`, a row-major 3×3 affine matrix like Mitsuba's
/// `AffineTransform3f`.
pub(crate) fn add_to_uv(key: &str, t: &Transform, ctx: &mut LoadContext) -> Result<ParamId> {
    // uv' = M (u, v, 0, 1): columns 0, 1 and 3 of the 4×4, rows 0 and 1
    let (c0, c1, c3) = (t.m.x_axis, t.m.y_axis, t.m.w_axis);
    let data = vec![c0.x, c1.x, c3.x, c0.y, c1.y, c3.y, 0.0, 0.0, 1.0];
    ctx.store.add(
        format!("{key}.to_uv"),
        data,
        vec![3, 3],
        ParamFlags::NON_DIFFERENTIABLE,
        Domain::Finite,
    )
}

/// An image texture. Texels live in the parameter store as `<key>.data`
/// (shape `[h, w, c]`, c = 1 or 3, linear values, differentiable); row 0
/// of the image file is v = 0 and texel (i, j) has its centre at
/// uv = ((i + ½)/w, (j + ½)/h), as in Mitsuba 3.
#[derive(Clone, Debug)]
pub struct Bitmap {
    pub data: ParamId,
    pub to_uv: ParamId,
    pub width: usize,
    pub height: usize,
    /// 1 (monochrome) or 3 (RGB; alpha is dropped).
    pub channels: usize,
    pub filter: FilterType,
    pub wrap: WrapMode,
}

impl Bitmap {
    /// Builds a bitmap from its node: `filename`, `filter_type`
    /// (bilinear | nearest), `wrap_mode` (repeat | mirror | clamp), `raw`
    /// (default false: PNG/JPEG data is sRGB-decoded to linear at load;
    /// EXR data is linear and used as is), `to_uv`, and Mitsuba 3's
    /// storage options:
    /// - `format` (auto | variant | float16 | fp16 | uint8): `float16` and
    ///   `fp16` round the linear texels to half precision, as Mitsuba
    ///   stores them; the others keep f32, which renders as Mitsuba's
    ///   `variant` and 8-bit storage do (Mitsuba linearises 8-bit texels
    ///   before interpolating them too). Unlike Mitsuba's `uint8`, the
    ///   data stays differentiable; and `auto` does not round 16-bit
    ///   images to half precision.
    /// - `accel` (true): CUDA hardware interpolation in Mitsuba; no
    ///   effect on the CPU, in Mitsuba's LLVM variants as here.
    ///
    /// `domain`: that of the slot the bitmap fills (see [`Bitmap::new`]).
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Bitmap> {
        let filename = node
            .string_opt("filename")?
            .ok_or_else(|| node.error("missing required parameter 'filename'"))?;
        let path = ctx.resolve_path(node, "filename", &filename)?;
        let filter = match node
            .choice("filter_type", &["bilinear", "nearest"])?
            .as_str()
        {
            "nearest" => FilterType::Nearest,
            _ => FilterType::Bilinear,
        };
        let wrap = match node
            .choice("wrap_mode", &["repeat", "mirror", "clamp"])?
            .as_str()
        {
            "mirror" => WrapMode::Mirror,
            "clamp" => WrapMode::Clamp,
            _ => WrapMode::Repeat,
        };
        let raw = node.bool("raw", false)?;
        let half_precision = matches!(
            node.choice("format", &["auto", "variant", "float16", "fp16", "uint8"])?
                .as_str(),
            "float16" | "fp16"
        );
        node.bool("accel", true)?;
        let img = read_image(&path).map_err(|e| node.error(e))?;
        let channels = if img.channels >= 3 { 3 } else { 1 };
        let mut img = img.take_channels(channels);
        let is_exr = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !is_exr && !raw {
            for v in img.data.iter_mut() {
                *v = srgb_to_linear(*v);
            }
        }
        if half_precision {
            for v in img.data.iter_mut() {
                *v = half::f16::from_f32(*v).to_f32();
            }
        }
        let to_uv = node.transform("to_uv")?;
        Bitmap::new(&node.key, img, filter, wrap, &to_uv, domain, ctx).map_err(|e| node.error(e))
    }

    /// A bitmap over linear image data `img` (1 or 3 channels) registered
    /// under parameter key `<key>.data` with `domain`, the valid range of
    /// the slot it fills (a reflectance: [0, 1]), so that optimisers keep
    /// the texels in it. Data outside the domain (an HDR image used as a
    /// reflectance) renders as it is, as in Mitsuba, with a warning; the
    /// texels are then only required to be finite.
    pub fn new(
        key: &str,
        img: Image,
        filter: FilterType,
        wrap: WrapMode,
        to_uv: &Transform,
        domain: Domain,
        ctx: &mut LoadContext,
    ) -> Result<Bitmap> {
        if !(img.channels == 1 || img.channels == 3) || img.width == 0 || img.height == 0 {
            return Err(crate::Error::Invalid(format!(
                "bitmap '{key}': need a non-empty image with 1 or 3 channels, got {}x{}x{}",
                img.width, img.height, img.channels
            )));
        }
        let to_uv = add_to_uv(key, to_uv, ctx)?;
        let (width, height, channels) = (img.width, img.height, img.channels);
        let outside = img.data.iter().filter(|&&v| !domain.admits(v)).count();
        let domain = if outside > 0 && img.data.iter().all(|v| v.is_finite()) {
            crate::warn(format!(
                "bitmap '{key}': {outside} of {} texel values are outside the range of the \
                 parameter it sets (values {}); rendered as they are, and an optimiser \
                 will not keep '{key}.data' in that range",
                img.data.len(),
                domain.describe()
            ));
            Domain::Finite
        } else {
            domain
        };
        let data = ctx.store.add(
            format!("{key}.data"),
            img.data,
            vec![height, width, channels],
            ParamFlags::DIFFERENTIABLE,
            domain,
        )?;
        Ok(Bitmap {
            data,
            to_uv,
            width,
            height,
            channels,
            filter,
            wrap,
        })
    }

    /// Texel (x, y) (already wrapped) as RGB, read through the store.
    #[inline]
    fn texel<R: ScalarReal>(&self, store: &ParamView, x: usize, y: usize) -> Spectrum<R> {
        let i = y * self.width + x;
        if self.channels == 3 {
            store.read3(self.data, i)
        } else {
            V3::splat(store.read(self.data, i))
        }
    }

    /// The filtered value at texture coordinates `uv` (after `to_uv`).
    pub fn lookup<R: ScalarReal>(&self, store: &ParamView, uv: V2<R>) -> Spectrum<R> {
        if !R::DIFFERENTIABLE {
            return V3::cst(self.lookup_primal(store.data(self.data), uv.val()));
        }
        let (w, h) = (self.width, self.height);
        match self.filter {
            FilterType::Nearest => {
                let x = floor_i64(uv.x.val() * w as f32);
                let y = floor_i64(uv.y.val() * h as f32);
                self.texel(store, self.wrap.wrap(x, w), self.wrap.wrap(y, h))
            }
            FilterType::Bilinear => {
                let (taps, fx, fy) = self.bilinear_taps(uv);
                if fx.is_const() && fy.is_const() {
                    // the weights are constants (the uv does not move):
                    // one weighted read per channel, one tape node each in
                    // reverse mode instead of a product and a sum per
                    // texel and channel
                    let terms = self.bilinear_terms(taps, fx.val(), fy.val());
                    return if self.channels == 3 {
                        let channel = |c: usize| {
                            R::param_sum(store, self.data, &terms.map(|(i, w)| (3 * i + c, w)))
                        };
                        V3::new(channel(0), channel(1), channel(2))
                    } else {
                        V3::splat(R::param_sum(store, self.data, &terms))
                    };
                }
                let [xa, xb, ya, yb] = taps;
                let (gx, gy) = (R::cst(1.0) - fx, R::cst(1.0) - fy);
                let top = self.texel(store, xa, ya) * gx + self.texel(store, xb, ya) * fx;
                let bottom = self.texel(store, xa, yb) * gx + self.texel(store, xb, yb) * fx;
                top * gy + bottom * fy
            }
        }
    }

    /// The four texels of a bilinear lookup (pixel indices) and their
    /// weights, for fractional position `(fx, fy)` between the taps
    /// `[x0, x1, y0, y1]` of [`Bitmap::bilinear_taps`].
    fn bilinear_terms(&self, [xa, xb, ya, yb]: [usize; 4], fx: f32, fy: f32) -> [(usize, f32); 4] {
        let (gx, gy) = (1.0 - fx, 1.0 - fy);
        let w = self.width;
        [
            (ya * w + xa, gx * gy),
            (ya * w + xb, fx * gy),
            (yb * w + xa, gx * fy),
            (yb * w + xb, fx * fy),
        ]
    }

    /// The adjoint of [`Bitmap::eval`] where only the texels are recorded
    /// (`to_uv` is not, so the uv and the filter's weights are constants):
    /// `add(first, shares)` for each texel the look-up at `uv` reads with
    /// weight `w`: its elements from `first` on get `w · g_c` each (channel
    /// c's adjoint being `g_c`; one element for a one-channel texture). The
    /// transpose of [`Bitmap::lookup_primal`], term for term, so the same
    /// sums as reverse mode through [`Bitmap::lookup`] on a tape, without
    /// one (reverse mode in lanes, `diff/prb_lanes.rs`).
    pub(crate) fn scatter_adjoint(
        &self,
        store: &ParamView,
        uv: Vec2,
        g: Vec3,
        mut add: impl FnMut(usize, &[f32]),
    ) {
        debug_assert!(!store.is_recorded(self.to_uv));
        let uv = apply_to_uv::<f32>(store, self.to_uv, V2::cst(uv)).val();
        let mut texel = |i: usize, weight: f32| {
            if self.channels == 3 {
                add(3 * i, &(g * weight).to_array());
            } else {
                // one value read into the three channels
                add(i, &[(g.x + g.y + g.z) * weight]);
            }
        };
        match self.filter {
            FilterType::Nearest => texel(self.nearest(uv), 1.0),
            FilterType::Bilinear => {
                let (taps, fx, fy) = self.bilinear_taps::<f32>(V2::cst(uv));
                for (i, weight) in self.bilinear_terms(taps, fx, fy) {
                    if weight != 0.0 {
                        texel(i, weight);
                    }
                }
            }
        }
    }

    /// The texel (row-major index) nearest filtering reads at `uv`.
    fn nearest(&self, uv: Vec2) -> usize {
        let (w, h) = (self.width, self.height);
        let x = floor_i64(uv.x * w as f32);
        let y = floor_i64(uv.y * h as f32);
        self.wrap.wrap(y, h) * w + self.wrap.wrap(x, w)
    }

    /// [`Bitmap::lookup`] without derivatives, reading the texels `data`
    /// directly (the same arithmetic as a lookup whose uv does not move).
    fn lookup_primal(&self, data: &[f32], uv: Vec2) -> Vec3 {
        let texel = |i: usize| self.texel_primal(data, i);
        match self.filter {
            FilterType::Nearest => texel(self.nearest(uv)),
            FilterType::Bilinear => {
                let (taps, fx, fy) = self.bilinear_taps::<f32>(V2::cst(uv));
                // [`crate::ad::weighted_sum`] per channel, texel by texel: the same
                // terms in the same order, zero weights skipped alike, so
                // the same value as a lookup with derivatives
                let mut v = Vec3::ZERO;
                for (i, w) in self.bilinear_terms(taps, fx, fy) {
                    if w != 0.0 {
                        v += texel(i) * w;
                    }
                }
                v
            }
        }
    }

    /// [`TextureT::eval`] in f32 at the uv `uv` (before `to_uv`) of each
    /// lane of `lanes`, all at once (the loop in lanes); zero in the other
    /// lanes. Bilinear filtering runs the arithmetic of
    /// [`Bitmap::lookup_primal`] in lanes, the same terms in the same
    /// order, so the same value in each lane; the texels are read lane by
    /// lane.
    #[inline(always)]
    pub(crate) fn eval_lanes<const N: usize>(
        &self,
        store: &ParamView,
        uv: V2<Lanes<N>>,
        lanes: LaneMask<N>,
    ) -> V3<Lanes<N>> {
        let data = store.data(self.data);
        let m = &store.data(self.to_uv)[..6];
        let u = uv.x * m[0] + uv.y * m[1] + m[2];
        let v = uv.x * m[3] + uv.y * m[4] + m[5];
        if self.filter == FilterType::Nearest {
            let value = |k: usize| {
                let texel = self.nearest(Vec2::new(u.0[k], v.0[k]));
                self.texel_primal(data, texel)
            };
            return lanes3(|k| if lanes.lane(k) { value(k) } else { Vec3::ZERO });
        }
        let (w, h) = (self.width, self.height);
        let x = u * w as f32 - 0.5;
        let y = v * h as f32 - 0.5;
        // `floor_i64` in lanes: the same integers (`as` saturates as it
        // does) and fractions
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let mut taps = [[0usize; 4]; N];
        for (k, taps) in taps.iter_mut().enumerate() {
            if lanes.lane(k) {
                let (x0, y0) = (x0.0[k] as i64, y0.0[k] as i64);
                let (xa, xb) = (self.wrap.wrap(x0, w), self.wrap.wrap(x0 + 1, w));
                let (ya, yb) = (self.wrap.wrap(y0, h), self.wrap.wrap(y0 + 1, h));
                *taps = [ya * w + xa, ya * w + xb, yb * w + xa, yb * w + xb];
            }
        }
        // the weights of `bilinear_terms`, and its sum with zero weights
        // skipped (adding zero instead leaves the sum as it is)
        let (gx, gy) = (Lanes::splat(1.0) - fx, Lanes::splat(1.0) - fy);
        let weights = [gx * gy, fx * gy, gx * fy, fx * fy];
        let mut value = V3::<Lanes<N>>::zero();
        for (t, weight) in weights.into_iter().enumerate() {
            let texel = lanes3(|k| {
                if lanes.lane(k) {
                    self.texel_primal(data, taps[k][t])
                } else {
                    Vec3::ZERO
                }
            });
            let term = texel * weight;
            value += V3::select(weight.equals(0.0), V3::zero(), term);
        }
        value
    }

    /// Texel `i` (row-major) of the texels `data`, its channels read as
    /// one vector.
    #[inline(always)]
    fn texel_primal(&self, data: &[f32], i: usize) -> Vec3 {
        if self.channels == 3 {
            Vec3::from_slice(&data[3 * i..3 * i + 3])
        } else {
            Vec3::splat(data[i])
        }
    }

    /// The texel columns and rows `[x0, x1, y0, y1]` (wrapped) between
    /// whose centres `uv` lies, and its fractional position `(fx, fy)`
    /// from the (x0, y0) centre: texel centres at integer coordinates.
    fn bilinear_taps<R: ScalarReal>(&self, uv: V2<R>) -> ([usize; 4], R, R) {
        let (w, h) = (self.width, self.height);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        let (x0, y0) = (floor_i64(x.val()), floor_i64(y.val()));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let taps = [
            self.wrap.wrap(x0, w),
            self.wrap.wrap(x0 + 1, w),
            self.wrap.wrap(y0, h),
            self.wrap.wrap(y0 + 1, h),
        ];
        (taps, fx, fy)
    }

    /// The gradient (∂/∂u, ∂/∂v) of [`eval_1`](TextureT::eval_1) at the
    /// interaction's uv, as Mitsuba 3's bitmap `eval_1_grad` computes it
    /// (for `bumpmap`): the derivative of the bilinear interpolation of
    /// the texels' values (luminances for RGB data) in texel units,
    /// carried through the transpose of `to_uv`'s linear part and scaled
    /// by the resolution (the chain rule exactly when `to_uv` does not mix
    /// u and v or the image is square). Zero for nearest filtering, whose
    /// value is piecewise constant.
    pub fn eval_1_grad<R: ScalarReal>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> V2<R> {
        if self.filter == FilterType::Nearest {
            return V2::zero();
        }
        let uv = apply_to_uv(store, self.to_uv, si.uv);
        let ([xa, xb, ya, yb], fx, fy) = self.bilinear_taps(uv);
        let f = |x, y| {
            let v = self.texel::<R>(store, x, y);
            if self.channels == 3 {
                v.luminance()
            } else {
                v.x
            }
        };
        let (f00, f10, f01, f11) = (f(xa, ya), f(xb, ya), f(xa, yb), f(xb, yb));
        let (gx, gy) = (R::cst(1.0) - fx, R::cst(1.0) - fy);
        let df_dx = (f10 - f00) * gy + (f11 - f01) * fy;
        let df_dy = (f01 - f00) * gx + (f11 - f10) * fx;
        let m = |i| store.value(self.to_uv, i);
        V2::new(
            (df_dx * m(0) + df_dy * m(3)) * self.width as f32,
            (df_dx * m(1) + df_dy * m(4)) * self.height as f32,
        )
    }
}

impl TextureT for Bitmap {
    fn eval<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        self.lookup(store, apply_to_uv(store, self.to_uv, si.uv))
    }
    /// The value (monochrome data) or its luminance (RGB data), as
    /// Mitsuba 3's bitmap `eval_1`.
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        let v = self.eval(store, si);
        if self.channels == 3 {
            v.luminance()
        } else {
            v.x
        }
    }
    fn mean(&self, store: &ParamStore) -> f32 {
        let d = store.data(self.data);
        (d.iter().map(|&v| v as f64).sum::<f64>() / d.len() as f64) as f32
    }
    fn max(&self, store: &ParamStore) -> f32 {
        store
            .data(self.data)
            .iter()
            .cloned()
            .fold(f32::MIN, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::params::Seeds;
    use crate::scene::description::{Class, Value};
    use crate::texture::{si_at_uv, test_node, Texture};
    use glam::Vec3;

    /// 4×3 RGB image with texel (x, y) = (x + 1, 10 (y + 1), 0.5).
    fn grid() -> Image {
        let mut img = Image::new(4, 3, 3);
        for y in 0..3 {
            for x in 0..4 {
                img.set(x, y, 0, x as f32 + 1.0);
                img.set(x, y, 1, 10.0 * (y as f32 + 1.0));
                img.set(x, y, 2, 0.5);
            }
        }
        img
    }

    fn make(filter: FilterType, wrap: WrapMode, to_uv: Transform) -> (Bitmap, LoadContext) {
        let mut ctx = LoadContext::default();
        let b = Bitmap::new(
            "tex",
            grid(),
            filter,
            wrap,
            &to_uv,
            Domain::Finite,
            &mut ctx,
        )
        .unwrap();
        (b, ctx)
    }

    fn at(b: &Bitmap, ctx: &LoadContext, u: f32, v: f32) -> Vec3 {
        b.eval::<f32>(&ctx.store.primal(), &si_at_uv(u, v)).val()
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-4
    }

    // Expected values are hand-computed with texel centres at
    // ((i + ½)/w, (j + ½)/h) and row 0 at v = 0; they coincide with what
    // Mitsuba 3.9.1 returns for the same image.
    #[test]
    fn bilinear_repeat_lookups() {
        let (b, ctx) = make(FilterType::Bilinear, WrapMode::Repeat, Transform::IDENTITY);
        let cases = [
            // at a texel centre: the texel
            ((0.125, 1.0 / 6.0), Vec3::new(1.0, 10.0, 0.5)),
            // halfway between texels 0 and 1 of row 0
            ((0.25, 1.0 / 6.0), Vec3::new(1.5, 10.0, 0.5)),
            // uv = 0: halfway between the last and first texel in u and v
            ((0.0, 0.0), Vec3::new(2.5, 20.0, 0.5)),
            // x = 3.46, y = 2.47: weights 0.54/0.46 between columns 3 and 0
            (
                (0.99, 0.99),
                Vec3::new(0.54 * 4.0 + 0.46, 30.0 * 0.53 + 10.0 * 0.47, 0.5),
            ),
            // outside [0,1]: periodic
            ((1.1, 0.1), Vec3::new(1.3, 14.0, 0.5)),
            ((-0.1, 0.1), Vec3::new(3.7, 14.0, 0.5)),
        ];
        for ((u, v), want) in cases {
            let got = at(&b, &ctx, u, v);
            assert!(close(got, want), "uv ({u}, {v}): {got} vs {want}");
        }
        // eval_1 of RGB data is its luminance (Mitsuba's bitmap eval_1)
        let l = b.eval_1::<f32>(&ctx.store.primal(), &si_at_uv(0.125, 1.0 / 6.0));
        assert!(
            (l - (0.212671 + 7.15160 + 0.5 * 0.072169)).abs() < 1e-4,
            "{l}"
        );
        assert!((b.mean(&ctx.store) - (2.5 + 20.0 + 0.5) / 3.0).abs() < 1e-5);
        assert_eq!(b.max(&ctx.store), 30.0);
    }

    #[test]
    fn mirror_clamp_and_nearest_lookups() {
        let (m, ctx) = make(FilterType::Bilinear, WrapMode::Mirror, Transform::IDENTITY);
        // x = 3.9: columns 3 and 4, where 4 mirrors to 3; y = -0.2: rows
        // -1 and 0, where -1 mirrors to 0
        assert!(close(at(&m, &ctx, 1.1, 0.1), Vec3::new(4.0, 10.0, 0.5)));
        assert!(close(at(&m, &ctx, -0.1, 0.1), Vec3::new(1.0, 10.0, 0.5)));
        assert!(close(at(&m, &ctx, 1.9, 0.1), Vec3::new(1.0, 10.0, 0.5)));
        let (c, ctx) = make(FilterType::Bilinear, WrapMode::Clamp, Transform::IDENTITY);
        assert!(close(at(&c, &ctx, 1.1, 0.1), Vec3::new(4.0, 10.0, 0.5)));
        assert!(close(at(&c, &ctx, -0.1, 0.9), Vec3::new(1.0, 30.0, 0.5)));
        let (n, ctx) = make(FilterType::Nearest, WrapMode::Repeat, Transform::IDENTITY);
        assert_eq!(at(&n, &ctx, 0.24, 0.1).x, 1.0);
        assert_eq!(at(&n, &ctx, 0.26, 0.1).x, 2.0);
        assert_eq!(at(&n, &ctx, -0.1, 0.1).x, 4.0);
        assert_eq!(at(&n, &ctx, 0.5, 0.34).y, 20.0);
        let (nm, ctx) = make(FilterType::Nearest, WrapMode::Mirror, Transform::IDENTITY);
        assert_eq!(at(&nm, &ctx, -1.1, 0.1).x, 4.0);
        assert_eq!(at(&nm, &ctx, 2.1, 0.1).x, 1.0);
    }

    #[test]
    fn to_uv_is_applied_before_the_lookup() {
        let s = Transform::new(glam::Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0))).unwrap();
        let (b, ctx) = make(FilterType::Bilinear, WrapMode::Repeat, s);
        // uv (0.1, 0.05) -> (0.2, 0.15): x = 0.3, y = -0.05
        assert!(close(at(&b, &ctx, 0.1, 0.05), Vec3::new(1.3, 11.0, 0.5)));
        let t = Transform::translate(Vec3::new(0.25, 0.5, 0.0))
            .after(&Transform::rotate(Vec3::Z, 90.0));
        let (b, ctx) = make(FilterType::Bilinear, WrapMode::Repeat, t);
        // uv (0.1, 0.05) -> rotate (-0.05, 0.1) -> translate (0.2, 0.6)
        assert!(close(at(&b, &ctx, 0.1, 0.05), Vec3::new(1.3, 23.0, 0.5)));
        assert_eq!(ctx.store.get(b.to_uv).key, "tex.to_uv");
    }

    #[test]
    fn texel_derivatives_are_the_bilinear_weights() {
        let (b, ctx) = make(FilterType::Bilinear, WrapMode::Repeat, Transform::IDENTITY);
        // x = 1.3 (columns 1, 2; weights 0.7, 0.3), y = 0.8 (rows 0, 1; 0.2, 0.8)
        let (u, v) = (1.8 / 4.0, 1.3 / 3.0);
        let n = 4 * 3 * 3;
        let cases = [
            ((1, 0), 0.7 * 0.2),
            ((2, 0), 0.3 * 0.2),
            ((1, 1), 0.7 * 0.8),
            ((2, 1), 0.3 * 0.8),
            ((0, 0), 0.0),
            ((3, 2), 0.0),
        ];
        for ((x, y), w) in cases {
            for c in 0..3 {
                let mut t = vec![0.0; n];
                t[(y * 4 + x) * 3 + c] = 1.0;
                let seeds = Seeds::tangents(&ctx.store, &[("tex.data", &t)]).unwrap();
                let r = b.eval::<Dual>(&ctx.store.view(&seeds), &si_at_uv(u, v));
                for k in 0..3 {
                    let want = if k == c { w } else { 0.0 };
                    assert!(
                        (r[k].d - want).abs() < 1e-5,
                        "texel ({x},{y}) c{c} k{k}: {:?}",
                        r[k]
                    );
                }
            }
        }
        // eval_1 (luminance) derivative: weight × luminance coefficient
        let mut t = vec![0.0; n];
        t[(4 + 1) * 3 + 1] = 1.0; // texel (1, 1), green
        let seeds = Seeds::tangents(&ctx.store, &[("tex.data", &t)]).unwrap();
        let l = b.eval_1::<Dual>(&ctx.store.view(&seeds), &si_at_uv(u, v));
        assert!((l.d - 0.56 * 0.715160).abs() < 1e-5, "{l:?}");
    }

    /// The tape-free adjoint of a look-up is the transpose of its
    /// derivative: for every texel element e, the scattered adjoint equals
    /// g · ∂value/∂e from forward mode (one tangent per element), for both
    /// filters, wrap modes that fold back, a `to_uv` transform, and uvs on
    /// texel centres (zero weights) and outside [0, 1].
    #[test]
    fn scattered_adjoints_are_the_transposed_derivatives() {
        let g = Vec3::new(0.3, -1.7, 2.1);
        let to_uv = Transform::scale(Vec3::new(2.0, 1.0, 1.0));
        for filter in [FilterType::Bilinear, FilterType::Nearest] {
            for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
                let (b, ctx) = make(filter, wrap, to_uv);
                let recorded = Seeds::recorded(&ctx.store, &[b.data]).unwrap();
                let store = ctx.store.view(&recorded);
                let n = 4 * 3 * 3;
                for (u, v) in [(0.2, 0.3), (0.0625, 1.0 / 6.0), (-0.4, 1.3), (0.99, 0.01)] {
                    let mut scattered = vec![0.0f32; n];
                    b.scatter_adjoint(&store, Vec2::new(u, v), g, |i, d| {
                        for (s, d) in scattered[i..].iter_mut().zip(d) {
                            *s += d;
                        }
                    });
                    for (e, &got) in scattered.iter().enumerate() {
                        let mut t = vec![0.0; n];
                        t[e] = 1.0;
                        let seeds = Seeds::tangents(&ctx.store, &[("tex.data", &t)]).unwrap();
                        let r = b.eval::<Dual>(&ctx.store.view(&seeds), &si_at_uv(u, v));
                        let want = g.x * r.x.d + g.y * r.y.d + g.z * r.z.d;
                        assert!(
                            (got - want).abs() < 1e-5,
                            "{filter:?} {wrap:?} uv ({u}, {v}) element {e}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    fn write_png8(path: &std::path::Path, px: &[u8], w: u32, h: u32) {
        image::save_buffer(path, px, w, h, image::ExtendedColorType::Rgb8).unwrap();
    }

    #[test]
    fn png_is_srgb_decoded_unless_raw() {
        let dir = std::env::temp_dir().join(format!("penumbra-bitmap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.png");
        // 2×2: (128, 64, 255), (0, 10, 200) / (255, 255, 255), (0, 0, 0)
        write_png8(
            &p,
            &[128, 64, 255, 0, 10, 200, 255, 255, 255, 0, 0, 0],
            2,
            2,
        );
        let file = Value::Str(p.to_str().unwrap().into());
        for (raw, want) in [
            (false, Vec3::new(0.215_861, 0.051_269, 1.0)),
            (true, Vec3::new(128.0 / 255.0, 64.0 / 255.0, 1.0)),
        ] {
            let node = test_node(
                Class::Texture,
                "bitmap",
                "tex",
                vec![
                    ("filename", file.clone()),
                    ("raw", Value::Bool(raw)),
                    ("filter_type", Value::Str("nearest".into())),
                ],
            );
            let mut ctx = LoadContext::default();
            let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
            let got = t
                .eval::<f32>(&ctx.store.primal(), &si_at_uv(0.25, 0.25))
                .val();
            assert!(close(got, want), "raw {raw}: {got} vs {want}");
            let p = ctx.store.get(ctx.store.require("tex.data").unwrap());
            assert_eq!(p.shape, vec![2, 2, 3]);
            assert!(p.flags.differentiable);
        }
        // bilinear interpolates decoded (linear) values, as Mitsuba does
        let node = test_node(
            Class::Texture,
            "bitmap",
            "tex",
            vec![("filename", file.clone())],
        );
        let mut ctx = LoadContext::default();
        let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
        let got = t
            .eval::<f32>(&ctx.store.primal(), &si_at_uv(0.5, 0.25))
            .val();
        assert!(
            close(got, Vec3::new(0.107_93, 0.027_152, 0.788_79)),
            "{got}"
        );
        // bad choices and unknown parameters are errors with the location
        let node = test_node(
            Class::Texture,
            "bitmap",
            "tex",
            vec![
                ("filename", file.clone()),
                ("wrap_mode", Value::Str("wrap".into())),
            ],
        );
        let e = Texture::from_node(&node, Domain::Finite, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("test.xml:1") && e.contains("'wrap' is not one of"),
            "{e}"
        );
        let node = test_node(
            Class::Texture,
            "bitmap",
            "tex",
            vec![
                ("filename", file),
                ("filtertype", Value::Str("nearest".into())),
            ],
        );
        let e = Texture::from_node(&node, Domain::Finite, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown parameter 'filtertype'"), "{e}");
    }

    /// `format` (Mitsuba's storage precision) and `accel` (CUDA only) are
    /// accepted: float16/fp16 round the linear texels to half precision,
    /// the other formats keep them as they are.
    #[test]
    fn storage_format_and_accel() {
        let dir = std::env::temp_dir().join(format!("penumbra-format-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.png");
        write_png8(&p, &[128, 64, 255], 1, 1);
        let file = Value::Str(p.to_str().unwrap().into());
        let load = |format: &str| {
            let node = test_node(
                Class::Texture,
                "bitmap",
                "tex",
                vec![
                    ("filename", file.clone()),
                    ("format", Value::Str(format.into())),
                    ("accel", Value::Bool(false)),
                ],
            );
            let mut ctx = LoadContext::default();
            Texture::from_node(&node, Domain::Finite, &mut ctx).map(|t| {
                t.eval::<f32>(&ctx.store.primal(), &si_at_uv(0.5, 0.5))
                    .val()
            })
        };
        let linear = Vec3::new(0.215_861, 0.051_269, 1.0);
        for format in ["auto", "variant", "uint8"] {
            assert!(close(load(format).unwrap(), linear), "{format}");
        }
        for format in ["float16", "fp16"] {
            let got = load(format).unwrap();
            // the nearest halves: 0.2158203 (10-bit mantissa), 0.05126953
            assert_eq!(got, Vec3::new(0.215_820_31, 0.051_269_53, 1.0), "{format}");
        }
        let e = load("fp32").unwrap_err().to_string();
        assert!(
            e.contains("'fp32' is not one of: auto, variant, float16, fp16, uint8"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn reads_the_reference_scene_texture() {
        let p = crate::testing::repo_file("scenes/textures/texture.exr");
        let img = read_image(&p).unwrap();
        let node = test_node(
            Class::Texture,
            "bitmap",
            "plane.bsdf.reflectance",
            vec![("filename", Value::Str(p.to_str().unwrap().into()))],
        );
        let mut ctx = LoadContext::default();
        let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
        let Texture::Bitmap(b) = &t else {
            panic!("not a bitmap")
        };
        assert_eq!((b.width, b.height), (img.width, img.height));
        // EXR data is linear: the texel at a centre comes back unchanged
        let (x, y) = (img.width / 3, img.height / 2);
        let u = (x as f32 + 0.5) / img.width as f32;
        let v = (y as f32 + 0.5) / img.height as f32;
        let got = t.eval::<f32>(&ctx.store.primal(), &si_at_uv(u, v)).val();
        let c = |k: usize| img.get(x, y, k.min(img.channels - 1));
        let want = if img.channels >= 3 {
            Vec3::new(c(0), c(1), c(2))
        } else {
            Vec3::splat(c(0))
        };
        assert!((got - want).abs().max_element() < 1e-4 * (1.0 + want.max_element()));
        assert!(ctx.store.id("plane.bsdf.reflectance.data").is_some());
    }

    /// A bitmap nested in a reflectance slot takes the slot's domain, [0,
    /// 1], so that optimisers project its texels into it; HDR data outside
    /// it still loads (as in Mitsuba), with the finite domain.
    #[test]
    fn bitmap_takes_the_domain_of_its_slot() {
        let dir = std::env::temp_dir().join(format!("penumbra-domain-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (name, texel, want) in [
            ("ldr.exr", 0.8f32, Domain::UnitInterval),
            ("hdr.exr", 1.5, Domain::Finite),
        ] {
            let mut img = Image::new(2, 2, 3);
            img.data.fill(texel);
            let file = dir.join(name);
            crate::image::write_exr(&file, &img, &["R", "G", "B"]).unwrap();
            let tex = test_node(
                Class::Texture,
                "bitmap",
                "b.reflectance",
                vec![("filename", Value::Str(file.display().to_string()))],
            );
            let bsdf = test_node(
                Class::Bsdf,
                "diffuse",
                "b",
                vec![("reflectance", Value::Node(std::rc::Rc::new(tex)))],
            );
            let mut ctx = LoadContext::default();
            crate::bsdf::Bsdf::from_node(&bsdf, &mut ctx).unwrap();
            let p = ctx
                .store
                .get(ctx.store.require("b.reflectance.data").unwrap());
            assert_eq!(p.domain, want, "{name}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn monochrome_bitmaps_splat() {
        let mut img = Image::new(2, 1, 1);
        img.data = vec![0.25, 0.75];
        let mut ctx = LoadContext::default();
        let b = Bitmap::new(
            "m",
            img,
            FilterType::Bilinear,
            WrapMode::Clamp,
            &Transform::IDENTITY,
            Domain::Finite,
            &mut ctx,
        )
        .unwrap();
        let si = si_at_uv(0.5, 0.5);
        assert!(close(
            b.eval::<f32>(&ctx.store.primal(), &si).val(),
            Vec3::splat(0.5)
        ));
        assert!((b.eval_1::<f32>(&ctx.store.primal(), &si) - 0.5).abs() < 1e-6);
    }

    /// A block of lookups in lanes gives each lane the value of the f32
    /// lookup, bit for bit: every filter and wrap mode, a `to_uv`, uvs
    /// inside and outside [0, 1]², texel centres and edges (zero weights),
    /// and zero in the lanes left out.
    #[test]
    fn lookups_in_lanes_are_the_f32_lookups() {
        let to_uv = Transform::new(
            glam::Mat4::from_scale(Vec3::new(2.0, 1.0, 1.0))
                * glam::Mat4::from_translation(Vec3::new(0.1, -0.3, 0.0)),
        )
        .unwrap();
        let mut rng = crate::sampler::SampleStream::PLACEHOLDER;
        for filter in [FilterType::Bilinear, FilterType::Nearest] {
            for wrap in [WrapMode::Repeat, WrapMode::Mirror, WrapMode::Clamp] {
                for t in [Transform::IDENTITY, to_uv] {
                    let (b, ctx) = make(filter, wrap, t);
                    let store = ctx.store.primal();
                    for round in 0..64 {
                        let uv: [Vec2; 8] = std::array::from_fn(|k| match (round % 4, k % 2) {
                            // on texel centres and between them
                            (0, _) => Vec2::new((k as f32 + 0.5) / 4.0, (round % 3) as f32 / 6.0),
                            (_, 0) => rng.next_2d() * 3.0 - Vec2::splat(1.0),
                            _ => rng.next_2d(),
                        });
                        let lanes = LaneMask::<8>::from_fn(|k| k != 3);
                        let uv_lanes =
                            V2::new(Lanes::from_fn(|k| uv[k].x), Lanes::from_fn(|k| uv[k].y));
                        let v = b.eval_lanes(&store, uv_lanes, lanes);
                        for (k, uv) in uv.iter().enumerate() {
                            let expected = if k == 3 {
                                Vec3::ZERO
                            } else {
                                at(&b, &ctx, uv.x, uv.y)
                            };
                            let got = crate::ad::lanes::lane3(v, k);
                            assert_eq!(
                                got.to_array().map(f32::to_bits),
                                expected.to_array().map(f32::to_bits),
                                "{filter:?} {wrap:?} at {uv}: {got} in lanes, {expected} in f32"
                            );
                        }
                    }
                }
            }
        }
    }
}
