//! A small line plot (loss curves of optimisation jobs) drawn straight into
//! an RGB image, with a log-scale y axis and labelled ticks. A stochastic
//! loss (a few samples per pixel per step) jumps from one iteration to the
//! next by more than it falls over the whole run; so the raw values are
//! drawn as faint dots and their trend (see [`trend`]) as a bold line.

use super::Image;

/// 5×7 glyphs (one row per byte, 5 low bits, MSB = left) of the characters
/// the labels need.
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        '.' => [0, 0, 0, 0, 0, 0x0c, 0x0c],
        '-' => [0, 0, 0, 0x1f, 0, 0, 0],
        'e' => [0, 0, 0x0e, 0x11, 0x1f, 0x10, 0x0e],
        ' ' => [0; 7],
        'm' => [0, 0, 0x1a, 0x15, 0x15, 0x11, 0x11],
        'x' => [0, 0, 0x11, 0x0a, 0x04, 0x0a, 0x11],
        'p' => [0, 0, 0x1e, 0x11, 0x1e, 0x10, 0x10],
        'b' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1e],
        'a' => [0, 0, 0x0e, 0x01, 0x0f, 0x11, 0x0f],
        'i' => [0x04, 0, 0x0c, 0x04, 0x04, 0x04, 0x0e],
        'l' => [0x0c, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e],
        'n' => [0, 0, 0x16, 0x19, 0x11, 0x11, 0x11],
        'o' => [0, 0, 0x0e, 0x11, 0x11, 0x11, 0x0e],
        'r' => [0, 0, 0x16, 0x19, 0x10, 0x10, 0x10],
        's' => [0, 0, 0x0e, 0x10, 0x0e, 0x01, 0x1e],
        't' => [0x08, 0x08, 0x1c, 0x08, 0x08, 0x09, 0x06],
        'c' => [0, 0, 0x0e, 0x10, 0x10, 0x11, 0x0e],
        'd' => [0x01, 0x01, 0x0d, 0x13, 0x11, 0x11, 0x0f],
        'f' => [0x06, 0x09, 0x08, 0x1c, 0x08, 0x08, 0x08],
        'g' => [0, 0, 0x0f, 0x11, 0x0f, 0x01, 0x0e],
        'h' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11],
        'u' => [0, 0, 0x11, 0x11, 0x11, 0x13, 0x0d],
        'v' => [0, 0, 0x11, 0x11, 0x11, 0x0a, 0x04],
        'w' => [0, 0, 0x11, 0x11, 0x15, 0x15, 0x0a],
        'y' => [0, 0, 0x11, 0x11, 0x0f, 0x01, 0x0e],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        ':' => [0, 0x0c, 0x0c, 0, 0x0c, 0x0c, 0],
        '|' => [0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        ',' => [0, 0, 0, 0, 0, 0x0c, 0x08],
        _ => [0; 7],
    }
}

struct Canvas {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Canvas {
    fn set(&mut self, x: i64, y: i64, rgb: [f32; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            let o = (y as usize * self.w + x as usize) * 3;
            self.data[o..o + 3].copy_from_slice(&rgb);
        }
    }

    /// A line by Bresenham's algorithm.
    fn line(&mut self, (mut x0, mut y0): (i64, i64), (x1, y1): (i64, i64), rgb: [f32; 3]) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let mut err = dx + dy;
        loop {
            self.set(x0, y0, rgb);
            if x0 == x1 && y0 == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x0 += sx;
            }
            if e2 <= dx {
                err += dx;
                y0 += sy;
            }
        }
    }

    /// A line three pixels wide.
    fn bold_line(&mut self, a: (i64, i64), b: (i64, i64), rgb: [f32; 3]) {
        for (dx, dy) in [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)] {
            self.line((a.0 + dx, a.1 + dy), (b.0 + dx, b.1 + dy), rgb);
        }
    }

    /// A 3×3 dot.
    fn dot(&mut self, (x, y): (i64, i64), rgb: [f32; 3]) {
        for dy in -1..=1 {
            for dx in -1..=1 {
                self.set(x + dx, y + dy, rgb);
            }
        }
    }

    /// Text with its top-left corner at (x, y).
    fn text(&mut self, x: i64, y: i64, s: &str, rgb: [f32; 3]) {
        for (k, c) in s.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        self.set(x + 6 * k as i64 + col, y + row as i64, rgb);
                    }
                }
            }
        }
    }
}

/// Colour of the raw values (faint) and of their trend (bold).
pub const RAW_RGB: [f32; 3] = [0.5, 0.62, 0.92];
/// See [`RAW_RGB`].
pub const SMOOTH_RGB: [f32; 3] = [0.05, 0.2, 0.8];

/// The median of the finite values (NaN if there are none).
pub fn median(values: &[f64]) -> f64 {
    let mut w: Vec<f64> = values.iter().cloned().filter(|v| v.is_finite()).collect();
    if w.is_empty() {
        return f64::NAN;
    }
    w.sort_by(f64::total_cmp);
    let m = w.len() / 2;
    if w.len() % 2 == 1 {
        w[m]
    } else {
        0.5 * (w[m - 1] + w[m])
    }
}

/// The trend of a noisy sequence (a loss per iteration): at each
/// iteration, the value at that iteration of the Theil–Sen line (Sen 1968,
/// "Estimates of the regression coefficient based on Kendall's tau": the
/// median of the slopes between all pairs of points, and the median
/// intercept) through the values of a window of [`smoothing_window`]
/// iterations centred on it, cut at the ends of the run. Fitted to the
/// logarithms when all finite values are positive. A median line ignores
/// the odd outlier (a firefly in a low-sample render) like a moving median,
/// but unlike a moving median it follows a steady fall without lagging,
/// also at the ends of the run. Non-finite values are left out.
pub fn trend(values: &[f64]) -> Vec<f64> {
    let finite = || values.iter().filter(|v| v.is_finite());
    let log = finite().all(|&v| v > 0.0);
    let tf = |v: f64| if log { v.ln() } else { v };
    let inv = |v: f64| if log { v.exp() } else { v };
    let half = smoothing_window(values.len()) / 2;
    let n = values.len();
    (0..n)
        .map(|i| {
            let pts: Vec<(f64, f64)> = (i.saturating_sub(half)..(i + half + 1).min(n))
                .filter(|&j| values[j].is_finite())
                .map(|j| (j as f64, tf(values[j])))
                .collect();
            let mut slopes = Vec::with_capacity(pts.len() * pts.len() / 2);
            for (a, p) in pts.iter().enumerate() {
                for q in &pts[a + 1..] {
                    slopes.push((q.1 - p.1) / (q.0 - p.0));
                }
            }
            let slope = if slopes.is_empty() {
                0.0
            } else {
                median(&slopes)
            };
            let intercepts: Vec<f64> = pts.iter().map(|p| p.1 - slope * p.0).collect();
            inv(median(&intercepts) + slope * i as f64)
        })
        .collect()
}

/// The window of [`trend`] for `n` values: about a fifth of the run (a loss
/// at a few samples per pixel sits mostly on its noise floor, so its trend
/// is small against its jumps), odd, at least 1.
pub fn smoothing_window(n: usize) -> usize {
    (n / 5) | 1
}

/// Plots `values` (e.g. a loss per iteration) against their index, y on a
/// log scale when all values are positive. With `noisy` (a stochastic
/// estimate, like a loss), each value is a faint dot and their [`trend`] a
/// bold line; otherwise (a parameter error, exact for its iterate) the
/// values themselves are the bold line.
/// Returns a linear-RGB image.
pub fn plot_curve(values: &[f64], width: usize, height: usize, title: &str, noisy: bool) -> Image {
    let mut c = Canvas {
        w: width,
        h: height,
        data: vec![1.0; width * height * 3],
    };
    let (left, right, top, bottom) = (62i64, width as i64 - 16, 16i64, height as i64 - 30);
    let black = [0.0; 3];
    let grey = [0.8; 3];
    let finite: Vec<f64> = values.iter().cloned().filter(|v| v.is_finite()).collect();
    let log = !finite.is_empty() && finite.iter().all(|&v| v > 0.0);
    let tf = |v: f64| if log { v.log10() } else { v };
    let (mut lo, mut hi) = finite
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(tf(v)), b.max(tf(v)))
        });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    // a margin of 5 % of the range (of a tenth of a decade at least on a
    // log scale), so that the data fill the height: a loss that falls by
    // less than a decade still shows its shape
    let pad = if log {
        (0.05 * (hi - lo)).max(0.05)
    } else {
        (0.05 * (hi - lo)).max(1e-12)
    };
    (lo, hi) = (lo - pad, hi + pad);
    let n = values.len().max(2) as f64 - 1.0;
    let px = |i: f64| left + ((right - left) as f64 * i / n).round() as i64;
    let py = |v: f64| bottom - ((bottom - top) as f64 * (tf(v) - lo) / (hi - lo)).round() as i64;
    // y ticks: 1, 2, 5 × 10^k (only the decades over more than three;
    // every digit when the range holds fewer than two of those), or 5
    // steps (linear)
    let ticks: Vec<f64> = if log {
        let in_range = |mantissas: &[f64]| -> Vec<f64> {
            (lo.floor() as i32..=hi.ceil() as i32)
                .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
                .filter(|v| (lo..=hi).contains(&v.log10()))
                .collect()
        };
        let mut t = in_range(if hi - lo > 3.0 {
            &[1.0]
        } else {
            &[1.0, 2.0, 5.0]
        });
        if t.len() < 2 {
            t = in_range(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        }
        t
    } else {
        (0..=4).map(|k| lo + (hi - lo) * k as f64 / 4.0).collect()
    };
    for t in ticks {
        let y = py(t);
        c.line((left, y), (right, y), grey);
        let label = if log {
            let e = t.log10().floor();
            format!("{}e{}", (t / 10f64.powf(e)).round() as i64, e as i64)
        } else {
            format!("{t:.3}")
        };
        c.text(left - 8 - 6 * label.len() as i64, y - 3, &label, black);
    }
    // x ticks: multiples of a round step (1, 2 or 5 × 10^k), about four
    let rough = (n / 4.0).max(1.0);
    let decade = 10f64.powf(rough.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|&s| s >= rough)
        .unwrap_or(10.0 * decade);
    for k in 0..=(n / step).floor() as usize {
        let i = k as f64 * step;
        let x = px(i);
        c.line((x, bottom), (x, bottom + 4), black);
        let label = format!("{}", i as i64);
        c.text(x - 3 * label.len() as i64, bottom + 8, &label, black);
    }
    c.line((left, top), (left, bottom), black);
    c.line((left, bottom), (right, bottom), black);
    c.text(right - 6 * 9, bottom + 18, "iteration", black);
    c.text(4, 4, title, black);
    let plotted = |v: f64| v.is_finite() && !(log && v <= 0.0);
    if noisy {
        for (i, &v) in values.iter().enumerate() {
            if plotted(v) {
                c.dot((px(i as f64), py(v)), RAW_RGB);
            }
        }
    }
    let smooth = if noisy {
        trend(values)
    } else {
        values.to_vec()
    };
    let mut prev: Option<(i64, i64)> = None;
    for (i, &v) in smooth.iter().enumerate() {
        if !plotted(v) {
            prev = None;
            continue;
        }
        let p = (px(i as f64), py(v));
        c.bold_line(prev.unwrap_or(p), p, SMOOTH_RGB);
        prev = Some(p);
    }
    // legend, top right: what the dots and the line are, and the last
    // value of the line
    let last = smooth.iter().rev().find(|v| plotted(**v));
    let trend_label = format!("trend over {}", smoothing_window(values.len()));
    let legend: &[(&str, [f32; 3])] = if noisy {
        &[("each iteration", RAW_RGB), (&trend_label, SMOOTH_RGB)]
    } else {
        &[("each iteration", SMOOTH_RGB)]
    };
    for (k, (label, rgb)) in legend.iter().enumerate() {
        let y = top + 4 + 12 * k as i64;
        let x = right - 6 * 16 - 14;
        c.bold_line((x, y + 3), (x + 8, y + 3), *rgb);
        c.text(x + 12, y, label, black);
    }
    if let Some(v) = last {
        let label = format!("last: {v:.3e}");
        let y = top + 4 + 12 * legend.len() as i64;
        c.text(right - 6 * label.len() as i64, y, &label, black);
    }
    Image {
        width,
        height,
        channels: 3,
        data: c.data,
    }
}

/// Stacks images of the same width top to bottom (the panels of a plot).
pub fn stack(panels: &[Image]) -> Image {
    let width = panels.first().map_or(0, |p| p.width);
    debug_assert!(panels.iter().all(|p| p.width == width && p.channels == 3));
    Image {
        width,
        height: panels.iter().map(|p| p.height).sum(),
        channels: 3,
        data: panels.iter().flat_map(|p| p.data.iter().copied()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_is_drawn_inside_the_axes() {
        let loss: Vec<f64> = (0..50).map(|i| 0.5 * (-0.1 * i as f64).exp()).collect();
        let img = plot_curve(&loss, 320, 200, "loss", false);
        let blue = |x: usize, y: usize| {
            let o = (y * 320 + x) * 3;
            img.data[o + 2] > 0.7 && img.data[o] < 0.1
        };
        // the first point is near the top-left, the last near the bottom-right
        // (below the legend, top right)
        let col_has_blue = |x: usize, y0: usize| (y0..200).any(|y| blue(x, y));
        assert!(col_has_blue(63, 0) && col_has_blue(300, 50));
        let first_y = (0..200).find(|&y| blue(62, y)).unwrap();
        let last_y = (50..200).find(|&y| blue(304, y)).unwrap();
        assert!(first_y < last_y, "{first_y} {last_y}");
    }

    /// The trend line follows a noisy decreasing loss: it is much closer to
    /// the noise-free curve than the raw values, and drawn bold over the
    /// faint raw dots; without noise, it is the curve itself, ends included.
    #[test]
    fn trend_of_a_noisy_loss() {
        let n = 80;
        let truth: Vec<f64> = (0..n).map(|i| 1e-2 * (-0.05 * i as f64).exp()).collect();
        // multiplicative noise of ±60 % from a fixed xorshift sequence
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let noisy: Vec<f64> = truth
            .iter()
            .map(|t| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let u = (state >> 11) as f64 / (1u64 << 53) as f64;
                t * (1.0 + 1.2 * (u - 0.5))
            })
            .collect();
        let smooth = trend(&noisy);
        let log_err = |a: &[f64]| -> f64 {
            a.iter()
                .zip(&truth)
                .map(|(a, t)| (a / t).ln().abs())
                .sum::<f64>()
                / n as f64
        };
        let (raw_err, smooth_err) = (log_err(&noisy), log_err(&smooth));
        // a line fitted to k = 17 points is off at the window's centre by
        // about 1/√k (0.24) of their spread, up to twice that at a cut end:
        // 0.5 leaves room for the median's inefficiency and the ends
        assert!(smooth_err < 0.5 * raw_err, "{smooth_err} vs {raw_err}");
        for (a, b) in trend(&truth).iter().zip(&truth) {
            assert!((a / b - 1.0).abs() < 1e-9, "{a} vs {b}");
        }
        assert_eq!(
            (median(&[3.0, 1.0, 2.0, 5.0]), median(&[3.0, f64::NAN, 1.0])),
            (2.5, 2.0)
        );

        let img = plot_curve(&noisy, 640, 400, "loss", true);
        let count = |rgb: [f32; 3]| {
            img.data
                .chunks_exact(3)
                .filter(|p| p.iter().zip(&rgb).all(|(a, b)| (a - b).abs() < 1e-6))
                .count()
        };
        // 80 dots of 9 pixels (some overdrawn by the line), and a line
        // three pixels wide across ~560 columns
        assert!(count(RAW_RGB) > 80, "{}", count(RAW_RGB));
        assert!(count(SMOOTH_RGB) > 3 * 500, "{}", count(SMOOTH_RGB));
    }
}
