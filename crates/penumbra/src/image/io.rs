//! Reading and writing images: OpenEXR (the `exr` crate) for linear float
//! data, PNG and JPEG (the `image` crate) for 8/16-bit data.

use super::{linear_to_srgb, Image};
use crate::error::{Error, Result};
use std::path::Path;

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
}

/// Reads an image. OpenEXR files (`.exr`, half or float samples) give RGB,
/// RGBA, Y or YA channels as stored (linear); PNG and JPEG (8 or 16 bit)
/// give 1–4 channels with values in [0, 1], still sRGB-encoded (decode
/// with [`super::srgb_to_linear`] where the data is colour). Row 0 is the
/// top row of the file. Errors name the path.
pub fn read_image(path: &Path) -> Result<Image> {
    if !path.is_file() {
        return Err(Error::file(path, "no such image file"));
    }
    match extension(path).as_str() {
        "exr" => read_exr(path),
        _ => read_ldr(path),
    }
}

fn read_exr(path: &Path) -> Result<Image> {
    let img = exr::prelude::read_first_flat_layer_from_file(path)
        .map_err(|e| Error::file(path, format!("cannot read OpenEXR image: {e}")))?;
    let layer = &img.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let chans = &layer.channel_data.list;
    let names: Vec<String> = chans.iter().map(|c| c.name.to_string()).collect();
    let find = |n: &str| names.iter().position(|x| x == n);
    let order: Vec<usize> = match (find("R"), find("G"), find("B"), find("Y"), find("A")) {
        (Some(r), Some(g), Some(b), _, a) => [Some(r), Some(g), Some(b), a]
            .into_iter()
            .flatten()
            .collect(),
        (_, _, _, Some(y), a) => [Some(y), a].into_iter().flatten().collect(),
        _ if names.len() == 1 => vec![0],
        _ => {
            return Err(Error::file(
                path,
                format!(
                    "OpenEXR image has channels [{}]; expected R,G,B[,A] or Y[,A]",
                    names.join(", ")
                ),
            ))
        }
    };
    let c = order.len();
    let mut data = vec![0.0f32; w * h * c];
    for (k, &ci) in order.iter().enumerate() {
        let samples = &chans[ci].sample_data;
        if samples.len() != w * h {
            return Err(Error::file(
                path,
                format!(
                    "channel '{}' has {} samples, expected {}",
                    names[ci],
                    samples.len(),
                    w * h
                ),
            ));
        }
        for (i, v) in samples.values_as_f32().enumerate() {
            data[i * c + k] = v;
        }
    }
    Ok(Image {
        width: w,
        height: h,
        channels: c,
        data,
    })
}

fn read_ldr(path: &Path) -> Result<Image> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| Error::file(path, format!("cannot open image: {e}")))?
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("cannot read image: {e}")))?;
    let img = reader.decode().map_err(|e| {
        Error::file(
            path,
            format!("cannot decode image ({e}); supported formats: EXR, PNG, JPEG"),
        )
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let color = img.color();
    let (channels, data) = match (color.has_color(), color.has_alpha()) {
        (false, false) => (1, img.to_luma32f().into_raw()),
        (false, true) => (2, img.to_luma_alpha32f().into_raw()),
        (true, false) => (3, img.to_rgb32f().into_raw()),
        (true, true) => (4, img.to_rgba32f().into_raw()),
    };
    Ok(Image {
        width: w,
        height: h,
        channels,
        data,
    })
}

fn check_layout(path: &Path, img: &Image) -> Result<()> {
    if img.width == 0 || img.height == 0 || img.channels == 0 {
        return Err(Error::file(
            path,
            format!(
                "cannot write an empty image ({}x{}, {} channels)",
                img.width, img.height, img.channels
            ),
        ));
    }
    if img.data.len() != img.width * img.height * img.channels {
        return Err(Error::file(
            path,
            format!(
                "image data has {} values, expected {}x{}x{}",
                img.data.len(),
                img.width,
                img.height,
                img.channels
            ),
        ));
    }
    Ok(())
}

/// Writes a float32 OpenEXR image with the given channel names, one per
/// image channel (e.g. `["R", "G", "B"]`, or `["R", "G", "B", "depth.Y"]`
/// for AOVs).
pub fn write_exr(path: &Path, img: &Image, channel_names: &[&str]) -> Result<()> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, SmallVec,
        WritableImage,
    };
    check_layout(path, img)?;
    if channel_names.len() != img.channels {
        return Err(Error::file(
            path,
            format!(
                "{} channel names given for an image with {} channels",
                channel_names.len(),
                img.channels
            ),
        ));
    }
    for (i, n) in channel_names.iter().enumerate() {
        if n.is_empty() || channel_names[..i].contains(n) {
            return Err(Error::file(
                path,
                format!("channel names must be non-empty and unique, got {channel_names:?}"),
            ));
        }
    }
    let c = img.channels;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channel_names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let samples: Vec<f32> = img.data.iter().skip(k).step_by(c).copied().collect();
            AnyChannel::new(*n, FlatSamples::F32(samples))
        })
        .collect();
    let layer = Layer::new(
        (img.width, img.height),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(list),
    );
    exr::image::Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| Error::file(path, format!("cannot write OpenEXR image: {e}")))
}

/// Writes an 8-bit PNG: colour channels go through the sRGB transfer
/// function, everything is clamped to [0, 1] (NaN → 0). 1, 2, 3 or 4
/// channels (Y, YA, RGB, RGBA; alpha stays linear).
pub fn write_png(path: &Path, img: &Image) -> Result<()> {
    check_layout(path, img)?;
    let c = img.channels;
    let color = match c {
        1 => image::ExtendedColorType::L8,
        2 => image::ExtendedColorType::La8,
        3 => image::ExtendedColorType::Rgb8,
        4 => image::ExtendedColorType::Rgba8,
        _ => {
            return Err(Error::file(
                path,
                format!("PNG holds 1 to 4 channels, this image has {c}; write an EXR instead"),
            ))
        }
    };
    let is_alpha = |k: usize| (c == 2 && k == 1) || (c == 4 && k == 3);
    let bytes: Vec<u8> = img
        .data
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let v = if is_alpha(i % c) {
                v
            } else {
                linear_to_srgb(v)
            };
            let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
            (v * 255.0).round() as u8
        })
        .collect();
    image::save_buffer_with_format(
        path,
        &bytes,
        img.width as u32,
        img.height as u32,
        color,
        image::ImageFormat::Png,
    )
    .map_err(|e| Error::file(path, format!("cannot write PNG image: {e}")))
}

/// Writes `.exr` (float32; channels named Y, YA, RGB or RGBA by count,
/// else C0, C1, …) or `.png` (8-bit sRGB), chosen by the extension.
pub fn write_image(path: &Path, img: &Image) -> Result<()> {
    match extension(path).as_str() {
        "exr" => {
            let generic: Vec<String> = (0..img.channels).map(|i| format!("C{i}")).collect();
            let names: Vec<&str> = match img.channels {
                1 => vec!["Y"],
                2 => vec!["Y", "A"],
                3 => vec!["R", "G", "B"],
                4 => vec!["R", "G", "B", "A"],
                _ => generic.iter().map(|s| s.as_str()).collect(),
            };
            write_exr(path, img, &names)
        }
        "png" => write_png(path, img),
        e => Err(Error::file(
            path,
            format!("unknown image extension '{e}': use .exr (linear float) or .png (8-bit sRGB)"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::srgb_to_linear;
    use std::path::PathBuf;

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("penumbra-image-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    fn ramp(w: usize, h: usize, c: usize) -> Image {
        let mut img = Image::new(w, h, c);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i as f32 * 0.37).sin() * 3.0 + 0.25 * i as f32;
        }
        img
    }

    #[test]
    fn exr_rgb_round_trip_is_exact() {
        let p = tmp("rgb.exr");
        let img = ramp(5, 3, 3);
        write_image(&p, &img).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!(back, img);
    }

    #[test]
    fn exr_five_named_channels_round_trip() {
        let p = tmp("aov.exr");
        let img = ramp(4, 2, 5);
        write_exr(&p, &img, &["R", "G", "B", "A", "depth.Y"]).unwrap();
        // all five channels are in the file under their names
        let raw = exr::prelude::read_first_flat_layer_from_file(&p).unwrap();
        let chans = &raw.layer_data.channel_data.list;
        assert_eq!(chans.len(), 5);
        let depth = chans
            .iter()
            .find(|c| c.name.to_string() == "depth.Y")
            .unwrap();
        let d: Vec<f32> = depth.sample_data.values_as_f32().collect();
        let want: Vec<f32> = img.data.iter().skip(4).step_by(5).copied().collect();
        assert_eq!(d, want);
        // read_image returns RGBA in that order
        let back = read_image(&p).unwrap();
        assert_eq!(back.channels, 4);
        assert_eq!(back.data, img.take_channels(4).data);
        // wrong name count and duplicates are errors naming the path
        let e = write_exr(&p, &img, &["R", "G"]).unwrap_err().to_string();
        assert!(
            e.contains("aov.exr") && e.contains("2 channel names"),
            "{e}"
        );
        let e = write_exr(&p, &img, &["R", "R", "B", "A", "Z"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("unique"), "{e}");
    }

    #[test]
    fn png_round_trip_through_srgb() {
        let p = tmp("rgb.png");
        let mut img = Image::new(3, 2, 3);
        let vals = [0.0, 0.01, 0.2, 0.5, 0.8, 1.0, 2.0, -1.0, 0.3];
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = vals[i % vals.len()];
        }
        write_image(&p, &img).unwrap();
        let back = read_image(&p).unwrap();
        assert_eq!((back.width, back.height, back.channels), (3, 2, 3));
        for (a, b) in img.data.iter().zip(&back.data) {
            let want = a.clamp(0.0, 1.0);
            let got = srgb_to_linear(*b);
            // half an 8-bit step in the encoded domain, times the largest
            // slope of the sRGB decoding curve (2.4 / 1.055 · (1.055/1.055)^1.4 < 2.4)
            let tol = 0.5 / 255.0 * 2.4;
            assert!((got - want).abs() <= tol, "{a} -> {b} -> {got}");
        }
    }

    #[test]
    fn unknown_extension_and_missing_file_are_errors_naming_the_path() {
        let img = ramp(2, 2, 3);
        let e = write_image(Path::new("/tmp/x.tiff"), &img)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/tmp/x.tiff") && e.contains("unknown image extension"),
            "{e}"
        );
        let e = read_image(Path::new("/nonexistent/a.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/a.exr"), "{e}");
        let p = tmp("garbage.png");
        std::fs::write(&p, b"not an image").unwrap();
        let e = read_image(&p).unwrap_err().to_string();
        assert!(e.contains("garbage.png") && e.contains("cannot"), "{e}");
    }

    #[test]
    fn reads_the_bundled_exr_files() {
        let museum = crate::testing::repo_file("scenes/textures/museum.exr");
        let img = read_image(&museum).unwrap();
        assert!(img.width >= 2 && img.height >= 3 && img.channels >= 3);
        assert!(img.data.iter().all(|v| v.is_finite()));
        assert!(img.data.iter().any(|&v| v > 0.0));
        let tex = crate::testing::repo_file("scenes/textures/texture.exr");
        let img = read_image(&tex).unwrap();
        assert!(img.width > 0 && img.height > 0);
        assert!(img.data.iter().all(|v| v.is_finite()));
    }
}
