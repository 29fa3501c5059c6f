//! Reconstruction filters (Mitsuba's `rfilter` plugins). Samples are
//! splatted to every pixel whose centre lies within the filter radius,
//! weighted by the separable filter; each pixel is the weighted mean.

use crate::ad::lanes::Lanes;
use crate::ad::{Float, Real};
use crate::error::Result;
use crate::scene::Node;

/// A separable reconstruction filter.
#[derive(Clone, Debug, PartialEq)]
pub enum ReconstructionFilter {
    /// Radius 0.5: each sample counts for its own pixel only.
    Box,
    /// `max(0, 1 - |x| / r)`, radius r (default 1).
    Tent { radius: f32 },
    /// Truncated Gaussian `max(0, exp(-x²/2σ²) - exp(-r²/2σ²))` with
    /// r = 4σ (default σ = 0.5), as Mitsuba 3 defines it; `cut` is the
    /// subtracted `exp(-r²/2σ²)`, `step` = `exp(-1/σ²)` (see
    /// [`ReconstructionFilter::eval_span`]). Made by
    /// [`ReconstructionFilter::gaussian`].
    Gaussian {
        stddev: f32,
        radius: f32,
        cut: f32,
        step: f32,
    },
    /// The cubic of Mitchell and Netravali (1988, "Reconstruction filters
    /// in computer graphics") with parameters B and C, radius 2. Mitsuba's
    /// `mitchell` (default B = C = 1/3) and `catmullrom` (B = 0, C = 0.5).
    /// Negative lobes: a pixel is still the weighted mean, its weight sum
    /// may fall below the sum of its positive weights.
    Mitchell { b: f32, c: f32 },
    /// The windowed sinc `sinc(x) · sinc(x / lobes)`, radius `lobes`
    /// (Mitsuba's `lanczos`, default 3 lobes).
    Lanczos { lobes: f32 },
}

impl ReconstructionFilter {
    pub fn from_node(node: &Node) -> Result<ReconstructionFilter> {
        let f = match node.plugin.as_str() {
            "box" => ReconstructionFilter::Box,
            "tent" => ReconstructionFilter::Tent {
                radius: node.float_checked("radius", 1.0, true)?,
            },
            "gaussian" => ReconstructionFilter::gaussian(node.float_checked("stddev", 0.5, true)?),
            "mitchell" => ReconstructionFilter::Mitchell {
                b: node.float("B", 1.0 / 3.0)?,
                c: node.float("C", 1.0 / 3.0)?,
            },
            "catmullrom" => ReconstructionFilter::Mitchell { b: 0.0, c: 0.5 },
            "lanczos" => ReconstructionFilter::Lanczos {
                lobes: node.int_min("lobes", 3, 1)? as f32,
            },
            other => {
                return Err(node.error(format!(
                    "unknown rfilter plugin '{other}' (Penumbra has: box, tent, gaussian, \
                     mitchell, catmullrom, lanczos)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(f)
    }

    /// The Gaussian of standard deviation `stddev` (pixels), cut at 4σ.
    pub fn gaussian(stddev: f32) -> ReconstructionFilter {
        let radius = 4.0 * stddev;
        let alpha = -1.0 / (2.0 * stddev * stddev);
        ReconstructionFilter::Gaussian {
            stddev,
            radius,
            // once per filter, not per sample (an `exp` per row and column)
            cut: (alpha * radius * radius).exp(),
            step: (2.0 * alpha).exp(),
        }
    }

    pub fn radius(&self) -> f32 {
        match self {
            ReconstructionFilter::Box => 0.5,
            ReconstructionFilter::Tent { radius } => *radius,
            ReconstructionFilter::Gaussian { radius, .. } => *radius,
            ReconstructionFilter::Mitchell { .. } => 2.0,
            ReconstructionFilter::Lanczos { lobes } => *lobes,
        }
    }

    /// The 1D filter at offset `x` (pixels) from the pixel centre.
    #[inline]
    pub fn eval(&self, x: f32) -> f32 {
        match self {
            ReconstructionFilter::Box => {
                if x.abs() <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            ReconstructionFilter::Tent { radius } => (1.0 - x.abs() / radius).max(0.0),
            ReconstructionFilter::Gaussian { stddev, cut, .. } => {
                let alpha = -1.0 / (2.0 * stddev * stddev);
                ((alpha * x * x).exp() - cut).max(0.0)
            }
            ReconstructionFilter::Mitchell { b, c } => {
                let x = x.abs();
                let (x2, x3) = (x * x, x * x * x);
                let k = if x < 1.0 {
                    (12.0 - 9.0 * b - 6.0 * c) * x3
                        + (-18.0 + 12.0 * b + 6.0 * c) * x2
                        + (6.0 - 2.0 * b)
                } else if x < 2.0 {
                    (-b - 6.0 * c) * x3
                        + (6.0 * b + 30.0 * c) * x2
                        + (-12.0 * b - 48.0 * c) * x
                        + (8.0 * b + 24.0 * c)
                } else {
                    0.0
                };
                k / 6.0
            }
            ReconstructionFilter::Lanczos { lobes } => {
                let x = x.abs();
                if x > *lobes {
                    0.0
                } else if x < f32::EPSILON {
                    1.0
                } else {
                    let (x1, x2) = (std::f32::consts::PI * x, std::f32::consts::PI * x / lobes);
                    x1.sin() * x2.sin() / (x1 * x2)
                }
            }
        }
    }

    /// The 1D filter at the centres of pixels `first, first + 1, …` (one
    /// per element of `out`) seen from position `c`, i.e. at offsets
    /// `(first + k) + 0.5 - c`: the same values as
    /// [`ReconstructionFilter::eval`], with the per-filter constants
    /// computed once.
    #[inline]
    pub fn eval_span(&self, first: i64, c: f32, out: &mut [f32]) {
        match self {
            ReconstructionFilter::Gaussian {
                stddev, cut, step, ..
            } => {
                // g(x) = exp(αx²) at x = x₀ + k from two exponentials: the
                // ratio of neighbours g(x + 1) / g(x) = exp(α(2x + 1)) is
                // itself a geometric sequence of ratio exp(2α) (`step`).
                // A few roundings of a product (not the ~30 instructions of
                // an `exp`) per weight; computed only when there is a
                // second weight, since for a narrow filter (σ < 0.125) the
                // ratio alone may overflow.
                let alpha = -1.0 / (2.0 * stddev * stddev);
                let x0 = first as f32 + 0.5 - c;
                let mut g = (alpha * x0 * x0).exp();
                let mut ratio = if out.len() > 1 {
                    (alpha * (2.0 * x0 + 1.0)).exp()
                } else {
                    0.0
                };
                for o in out.iter_mut() {
                    *o = (g - *cut).max(0.0);
                    g *= ratio;
                    ratio *= *step;
                }
            }
            _ => {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = self.eval((first + k as i64) as f32 + 0.5 - c);
                }
            }
        }
    }

    /// [`ReconstructionFilter::eval_span`] for `N` positions at once, one
    /// `Lanes` per pixel of `out` (lane k seen from `c.0[k]`): the
    /// Gaussian's recurrence, the box and the tent in lanes, the cubic and
    /// the sinc lane by lane. Unlike `eval_span`'s callers, which ask only
    /// for the pixels within the radius, the window of [`PixelSplat`]
    /// (`crate::image::film`) asks for the pixels within ⌊r + 0.5⌋ of the
    /// samples' pixel, some past the radius, where the weights are zero.
    /// On such a window the Gaussian's terms stay within f32's normal
    /// range: the offsets are at most ⌊r + 0.5⌋ + 0.5 ≤ 4σ + 1, so that
    /// |αx²| ≤ (4 + 1/σ)² / 2 ≤ 72 and the ratios' |α(2x + 1)| ≤ 64 for
    /// σ ≥ 1/8 (no term is made past the last pixel), and
    /// a smaller σ reaches no neighbour (a window of one pixel, the
    /// recurrence's ratio not used).
    ///
    /// [`PixelSplat`]: crate::image::film::PixelSplat
    #[inline(always)]
    pub fn eval_span_lanes<const N: usize>(&self, first: i64, c: Lanes<N>, out: &mut [Lanes<N>]) {
        let zero = Lanes::splat(0.0);
        let x0 = Lanes::splat(first as f32 + 0.5) - c;
        match self {
            ReconstructionFilter::Box => {
                let mut x = x0;
                for o in out.iter_mut() {
                    *o = Lanes::select(x.abs().le(0.5), Lanes::splat(1.0), zero);
                    x += Lanes::splat(1.0);
                }
            }
            ReconstructionFilter::Tent { radius } => {
                let mut x = x0;
                for o in out.iter_mut() {
                    *o = (Lanes::splat(1.0) - x.abs() * (1.0 / radius)).max(zero);
                    x += Lanes::splat(1.0);
                }
            }
            ReconstructionFilter::Gaussian {
                stddev, cut, step, ..
            } => {
                let alpha = -1.0 / (2.0 * stddev * stddev);
                let mut g = (x0 * x0 * alpha).exp();
                let mut ratio = ((x0 * 2.0 + 1.0) * alpha).exp();
                // each term made just before its pixel, none past the last
                // (whose exponents would leave f32's normal range)
                for (d, o) in out.iter_mut().enumerate() {
                    if d >= 2 {
                        ratio *= Lanes::splat(*step);
                    }
                    if d >= 1 {
                        g *= ratio;
                    }
                    *o = (g - *cut).max(zero);
                }
            }
            _ => {
                for (d, o) in out.iter_mut().enumerate() {
                    *o = Lanes::from_fn(|k| self.eval(x0.0[k] + d as f32));
                }
            }
        }
    }

    /// Pixels (beyond a sample's own) that one sample can reach on each
    /// side: `ceil(radius - 0.5)`.
    pub fn border(&self) -> usize {
        (self.radius() - 0.5).max(0.0).ceil() as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{parse_str, Class};

    /// The filter of one `<rfilter>` element, on line 1 of a scene.
    fn parse(xml: &str) -> Result<ReconstructionFilter> {
        let text = format!("<scene version=\"3.0.0\">{xml}</scene>");
        let scene = parse_str(&text, std::path::Path::new("test.xml"), &[])?;
        ReconstructionFilter::from_node(&scene.children(Class::Rfilter)[0])
    }

    /// Values of Mitsuba 3.9.1's filters (`mi.load_dict({...}).eval(x)`,
    /// scalar_rgb) at x = 0, 0.3, 0.9, 1, 1.2, 1.7, 2, 2.5, 2.9, 3.1.
    #[test]
    fn negative_lobe_filters_match_mitsuba() {
        let xs = [0.0, 0.3, 0.9, 1.0, 1.2, 1.7, 2.0, 2.5, 2.9, 3.1];
        let cases: [(&str, ReconstructionFilter, [f32; 10]); 5] = [
            (
                "<rfilter type=\"mitchell\"/>",
                ReconstructionFilter::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 },
                [0.888889, 0.740389, 0.1193889, 0.0555556, -0.0142223, -0.0194999, 0.0, 0.0, 0.0, 0.0],
            ),
            (
                "<rfilter type=\"catmullrom\"/>",
                ReconstructionFilter::Mitchell { b: 0.0, c: 0.5 },
                [1.0, 0.8155, 0.0685, 0.0, -0.0640001, -0.0314999, 0.0, 0.0, 0.0, 0.0],
            ),
            (
                "<rfilter type=\"mitchell\"><float name=\"B\" value=\"0.2\"/><float name=\"C\" value=\"0.7\"/></rfilter>",
                ReconstructionFilter::Mitchell { b: 0.2, c: 0.7 },
                [0.9333333, 0.7893333, 0.1233333, 0.0333331, -0.0725339, -0.0432004, 0.0, 0.0, 0.0, 0.0],
            ),
            (
                "<rfilter type=\"lanczos\"/>",
                ReconstructionFilter::Lanczos { lobes: 3.0 },
                [1.0, 0.8443431, 0.0938159, 0.0, -0.1180006, -0.0832311, 0.0, 0.0243171, 0.0011675, 0.0],
            ),
            (
                "<rfilter type=\"lanczos\"><integer name=\"lobes\" value=\"2\"/></rfilter>",
                ReconstructionFilter::Lanczos { lobes: 2.0 },
                [1.0, 0.8269746, 0.0763568, 0.0, -0.078667, -0.0257535, 0.0, 0.0, 0.0, 0.0],
            ),
        ];
        for (xml, filter, want) in cases {
            assert_eq!(parse(xml).unwrap(), filter, "{xml}");
            for (x, w) in xs.iter().zip(want) {
                for v in [filter.eval(*x), filter.eval(-*x)] {
                    assert!((v - w).abs() < 2e-6, "{filter:?} at {x}: {v}, Mitsuba {w}");
                }
            }
        }
    }

    #[test]
    fn bad_filter_parameters_are_errors_naming_them() {
        for (xml, needle) in [
            (
                "<rfilter type=\"lanczos\"><integer name=\"lobes\" value=\"0\"/></rfilter>",
                "lobes",
            ),
            (
                "<rfilter type=\"catmullrom\"><float name=\"B\" value=\"0.3\"/></rfilter>",
                "B",
            ),
            (
                "<rfilter type=\"mitchell\"><float name=\"radius\" value=\"3\"/></rfilter>",
                "radius",
            ),
        ] {
            let e = parse(xml).unwrap_err().to_string();
            assert!(e.contains(needle) && e.contains(":1"), "{xml}: {e}");
        }
    }

    /// `eval_span` gives `eval`'s values: bit for bit, except for the
    /// Gaussian, whose span multiplies neighbours' ratios instead of
    /// taking an `exp` per pixel. Both are then within a relative
    /// (|αx²| + 2k + 4) · ε of exp(αx²) (the rounding of the argument, of
    /// `exp`, and of the k products up to pixel k), at most 44ε for the
    /// offsets below (|αx²| ≤ 24, k ≤ 8): they agree to 100ε of the value
    /// before the cut-off is subtracted.
    #[test]
    fn eval_span_equals_eval() {
        let filters = [
            ReconstructionFilter::Box,
            ReconstructionFilter::Tent { radius: 1.5 },
            ReconstructionFilter::gaussian(0.5),
            ReconstructionFilter::gaussian(1.3),
        ];
        for f in &filters {
            for (first, c) in [(-3i64, -1.37f32), (10, 12.01), (254, 255.999), (0, 0.5)] {
                let mut out = [0.0f32; 9];
                f.eval_span(first, c, &mut out);
                for (k, &v) in out.iter().enumerate() {
                    let want = f.eval((first + k as i64) as f32 + 0.5 - c);
                    let at = first + k as i64;
                    match f {
                        ReconstructionFilter::Gaussian { cut, .. } => assert!(
                            (v - want).abs() <= 100.0 * f32::EPSILON * (want + cut),
                            "{f:?} at pixel {at}: {v} against {want}"
                        ),
                        _ => assert_eq!(v.to_bits(), want.to_bits(), "{f:?} at pixel {at}"),
                    }
                }
            }
        }
    }

    /// `eval_span_lanes` gives `eval`'s values in each lane over the
    /// window of pixels a sample of pixel x reaches (x ± ⌊r + 0.5⌋, also
    /// past the radius: zero there), for samples anywhere in the pixel,
    /// its edges included: the Gaussian to `eval_span`'s precision (above),
    /// the others to the rounding of the offset (made from the first
    /// pixel's by adding whole pixels, where `eval` takes each pixel's
    /// own), a few ε of the value's scale.
    #[test]
    fn eval_span_lanes_equals_eval() {
        let filters = [
            ReconstructionFilter::Box,
            ReconstructionFilter::Tent { radius: 1.5 },
            ReconstructionFilter::gaussian(0.5),
            ReconstructionFilter::gaussian(0.125),
            ReconstructionFilter::gaussian(0.1),
            ReconstructionFilter::gaussian(0.8),
            ReconstructionFilter::Mitchell { b: 0.0, c: 0.5 },
            ReconstructionFilter::Lanczos { lobes: 3.0 },
        ];
        for f in &filters {
            let reach = (f.radius() + 0.5).floor() as i64;
            for x in [-3i64, 0, 253] {
                let c =
                    Lanes([0.37f32, 0.0, 0.5, 0.999, 1.0, 0.01, 0.75, 0.2].map(|u| x as f32 + u));
                let mut out = [Lanes::<8>::splat(0.0); 7];
                let out = &mut out[..(2 * reach + 1) as usize];
                f.eval_span_lanes(x - reach, c, out);
                for (d, v) in out.iter().enumerate() {
                    let at = x - reach + d as i64;
                    for k in 0..8 {
                        let want = f.eval(at as f32 + 0.5 - c.0[k]);
                        let scale = match f {
                            ReconstructionFilter::Gaussian { cut, .. } => 100.0 * (want + cut),
                            _ => 8.0 * (1.0 + want.abs()),
                        };
                        assert!(
                            (v.0[k] - want).abs() <= scale * f32::EPSILON,
                            "{f:?} at pixel {at} from {}: {} against {want}",
                            c.0[k],
                            v.0[k]
                        );
                    }
                }
            }
        }
    }
}
