//! A small line plot (loss curves of optimisation jobs) drawn straight into
//! an RGB image, with a log-scale y axis and labelled ticks.

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

/// Plots `values` (e.g. a loss per iteration) against their index, y on a
/// log scale when all values are positive. Returns a linear-RGB image.
pub fn plot_curve(values: &[f64], width: usize, height: usize, title: &str) -> Image {
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
    if log {
        (lo, hi) = (lo.floor(), hi.ceil().max(lo.floor() + 1.0));
    } else if hi - lo < 1e-12 {
        hi = lo + 1.0;
    }
    let n = values.len().max(2) as f64 - 1.0;
    let px = |i: f64| left + ((right - left) as f64 * i / n).round() as i64;
    let py = |v: f64| bottom - ((bottom - top) as f64 * (tf(v) - lo) / (hi - lo)).round() as i64;
    // y ticks: decades (log) or 5 steps (linear)
    let ticks: Vec<f64> = if log {
        (lo as i64..=hi as i64)
            .map(|e| 10f64.powi(e as i32))
            .collect()
    } else {
        (0..=4).map(|k| lo + (hi - lo) * k as f64 / 4.0).collect()
    };
    for t in ticks {
        let y = py(t);
        c.line((left, y), (right, y), grey);
        let label = if log {
            format!("1e{}", t.log10().round() as i64)
        } else {
            format!("{t:.3}")
        };
        c.text(left - 8 - 6 * label.len() as i64, y - 3, &label, black);
    }
    // x ticks: 5 steps
    for k in 0..=4 {
        let i = (n * k as f64 / 4.0).round();
        let x = px(i);
        c.line((x, bottom), (x, bottom + 4), black);
        let label = format!("{}", i as i64);
        c.text(x - 3 * label.len() as i64, bottom + 8, &label, black);
    }
    c.line((left, top), (left, bottom), black);
    c.line((left, bottom), (right, bottom), black);
    c.text(right - 6 * 9, bottom + 18, "iteration", black);
    c.text(4, 4, title, black);
    let blue = [0.05, 0.2, 0.8];
    let mut prev: Option<(i64, i64)> = None;
    for (i, &v) in values.iter().enumerate() {
        if !v.is_finite() || (log && v <= 0.0) {
            prev = None;
            continue;
        }
        let p = (px(i as f64), py(v));
        if let Some(q) = prev {
            c.line(q, p, blue);
        } else {
            c.set(p.0, p.1, blue);
        }
        prev = Some(p);
    }
    Image {
        width,
        height,
        channels: 3,
        data: c.data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_is_drawn_inside_the_axes() {
        let loss: Vec<f64> = (0..50).map(|i| 0.5 * (-0.1 * i as f64).exp()).collect();
        let img = plot_curve(&loss, 320, 200, "loss");
        let blue = |x: usize, y: usize| {
            let o = (y * 320 + x) * 3;
            img.data[o + 2] > 0.7 && img.data[o] < 0.1
        };
        // the first point is near the top-left, the last near the bottom-right
        let col_has_blue = |x: usize| (0..200).any(|y| blue(x, y));
        assert!(col_has_blue(63) && col_has_blue(300));
        let first_y = (0..200).find(|&y| blue(62, y)).unwrap();
        let last_y = (0..200).find(|&y| blue(304, y)).unwrap();
        assert!(first_y < last_y, "{first_y} {last_y}");
    }
}
