//! Images: an in-memory float image, reading and writing EXR / PNG / JPEG,
//! the sRGB transfer function, films and reconstruction filters, plots.

pub mod film;
mod io;
pub mod plot;
pub mod rfilter;

pub use film::{Film, ImageBlock};
pub use io::{read_image, write_exr, write_image, write_png};
pub use rfilter::ReconstructionFilter;

/// A float image: `height` rows of `width` pixels of `channels` values,
/// row-major, channel-interleaved. Row 0 is the top row of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Image {
    /// An image filled with zeros.
    pub fn new(width: usize, height: usize, channels: usize) -> Image {
        Image {
            width,
            height,
            channels,
            data: vec![0.0; width * height * channels],
        }
    }

    /// Value of channel `c` of pixel (`x`, `y`), `y = 0` at the top.
    #[inline]
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.width + x) * self.channels + c]
    }

    /// Sets channel `c` of pixel (`x`, `y`).
    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: usize, v: f32) {
        self.data[(y * self.width + x) * self.channels + c] = v;
    }

    /// The first `n` channels of every pixel (e.g. RGB of an RGBA image).
    /// `n` must not exceed `channels`.
    pub fn take_channels(&self, n: usize) -> Image {
        assert!(n <= self.channels, "take_channels: {n} > {}", self.channels);
        if n == self.channels {
            return self.clone();
        }
        let data = self
            .data
            .chunks_exact(self.channels)
            .flat_map(|px| px[..n].iter().copied())
            .collect();
        Image {
            width: self.width,
            height: self.height,
            channels: n,
            data,
        }
    }
}

/// The sRGB electro-optical transfer function (IEC 61966-2-1): an encoded
/// value in [0, 1] to linear.
#[inline]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v * (1.0 / 12.92)
    } else {
        ((v + 0.055) * (1.0 / 1.055)).powf(2.4)
    }
}

/// The inverse sRGB transfer function: linear to encoded (not clamped).
#[inline]
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_transfer_round_trips_and_matches_known_values() {
        // 8-bit 128 decodes to 0.21586 (the value Mitsuba's bitmap returns)
        assert!((srgb_to_linear(128.0 / 255.0) - 0.215_861).abs() < 1e-5);
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-5);
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn take_channels_drops_trailing_channels() {
        let mut img = Image::new(2, 1, 4);
        img.data = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
        let rgb = img.take_channels(3);
        assert_eq!(rgb.data, vec![1.0, 2.0, 3.0, 5.0, 6.0, 7.0]);
        assert_eq!(rgb.get(1, 0, 2), 7.0);
    }
}
