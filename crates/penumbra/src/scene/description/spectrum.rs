//! Spectra in an RGB renderer: `<spectrum>` values (a constant, a
//! `wavelength:value` list, an `.spd` file) become linear sRGB the way
//! Mitsuba 3's RGB variants convert them when they load a scene, so that a
//! scene written for Mitsuba renders with the same colours.
//!
//! A sampled spectrum s(λ) (linear between its samples, zero outside
//! them) is integrated against the CIE 1931 colour matching functions
//! x̄, ȳ, z̄ over 360–830 nm, scaled so that a unit spectrum has
//! luminance Y = 1, and the XYZ result is mapped to linear sRGB
//! (Rec. 709 primaries, D65 white):
//! - a reflectance (or another bounded quantity) is lit by the D65
//!   illuminant, which is the white of sRGB: XYZ = ∫ s·D65·(x̄, ȳ, z̄) dλ,
//!   so a flat reflectance of 1 becomes (almost exactly) RGB (1, 1, 1);
//!   the result is clamped to [0, 1];
//! - an emitter's spectrum is an illuminant already: XYZ = ∫ s·(x̄, ȳ, z̄) dλ,
//!   so a flat emission spectrum becomes the slightly purple
//!   `xyz_to_srgb(1, 1, 1)` (equal energy is not the sRGB white);
//!   negative components are clamped to 0;
//! - unbounded quantities (`eta`, `k`, `int_ior`, `ext_ior`, `sigma_t`)
//!   are weighted by D65 like a reflectance but only clamped at 0.
//!
//! A constant `<spectrum value="v"/>` stays the plain value v (a grey),
//! except directly inside an `<emitter>`, where it is the flat emission
//! spectrum v, i.e. `v · xyz_to_srgb(1, 1, 1)`.
//!
//! The integral is the Riemann sum over 1000 evenly spaced wavelengths
//! that Mitsuba 3 uses, with the 5 nm CIE tables interpolated linearly
//! (tables: `cie1931_d65.csv` beside this file, CIE 015:2004).

use glam::Vec3;
use std::sync::OnceLock;

/// Shortest and longest wavelengths of the CIE tables (nm).
const CIE_MIN: f64 = 360.0;
const CIE_MAX: f64 = 830.0;
/// Wavelengths at which a spectrum is evaluated for the integral.
const STEPS: usize = 1000;
/// Scale of the colour matching functions that gives a unit spectrum a
/// luminance of 1: 1/∫ȳ by the sum above (Mitsuba 3's constant).
const Y_NORMALIZATION: f64 = 1.0 / 106.750_259_399_414_06;
/// Scale of the D65 table that gives D65 a luminance of about 1 (Mitsuba
/// 3's constant: 106.75026 / 10568).
const D65_NORMALIZATION: f64 = 1.0 / 98.997_417_518_762_55;

/// How a spectrum is converted, by where it is used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpectrumUse {
    /// A reflectance or another quantity in [0, 1]: under D65, clamped.
    Reflectance,
    /// An index of refraction, absorption or extinction: under D65,
    /// negative components clamped.
    Unbounded,
    /// Emitted radiance (a direct property of an `<emitter>`): no
    /// illuminant, negative components clamped.
    Emission,
}

impl SpectrumUse {
    /// The use of property `name` of an object: Mitsuba's rule, by the
    /// property's name and whether the object is an emitter.
    pub fn of(name: &str, in_emitter: bool) -> SpectrumUse {
        if matches!(name, "eta" | "k" | "int_ior" | "ext_ior" | "sigma_t") {
            SpectrumUse::Unbounded
        } else if in_emitter {
            SpectrumUse::Emission
        } else {
            SpectrumUse::Reflectance
        }
    }
}

/// A constant spectrum `value` as RGB: `value` itself, or, for an
/// emitter, the flat emission spectrum's colour.
pub fn constant_to_rgb(value: f32, usage: SpectrumUse) -> Vec3 {
    match usage {
        SpectrumUse::Emission => value * xyz_to_srgb([1.0; 3]).as_vec3(),
        _ => Vec3::splat(value),
    }
}

/// The RGB colour of a sampled spectrum (`wavelengths` increasing, in
/// nm, at least two), and whether it had to be clamped into range.
pub fn samples_to_rgb(wavelengths: &[f64], values: &[f64], usage: SpectrumUse) -> (Vec3, bool) {
    debug_assert!(wavelengths.len() == values.len() && wavelengths.len() >= 2);
    let (first, last) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    let linear = |w: f64| {
        if w < first || w > last {
            return 0.0;
        }
        // the segment [w0, w1] of the spectrum that holds w
        let k = wavelengths[1..wavelengths.len() - 1].partition_point(|&x| x <= w);
        let (w0, w1, v0, v1) = (wavelengths[k], wavelengths[k + 1], values[k], values[k + 1]);
        v0 + (v1 - v0) * (w - w0) / (w1 - w0)
    };
    to_rgb(linear, usage)
}

/// Planck's law: the spectral radiance of a black body at `temperature`
/// kelvin, at wavelength `w` nm, in W/(m²·sr·nm), as Mitsuba 3's
/// `blackbody` spectrum evaluates it (its constants c, h, k, CODATA 2014).
pub fn planck(temperature: f64, w: f64) -> f64 {
    const C: f64 = 2.997_924_58e8;
    const H: f64 = 6.626_070_04e-34;
    const K: f64 = 1.380_648_52e-23;
    let lambda = w * 1e-9;
    let per_metre =
        2.0 * H * C * C / (lambda.powi(5) * ((H * C / (lambda * K * temperature)).exp() - 1.0));
    per_metre * 1e-9
}

/// The RGB colour of the spectrum `s(λ)` (λ in nm), and whether it had to
/// be clamped into range: the integral of the module comment.
pub fn to_rgb(s: impl Fn(f64) -> f64, usage: SpectrumUse) -> (Vec3, bool) {
    let tables = tables();
    let mut xyz = [0.0f64; 3];
    for i in 0..STEPS {
        let w = CIE_MIN + i as f64 / (STEPS - 1) as f64 * (CIE_MAX - CIE_MIN);
        let v = s(w);
        if v == 0.0 {
            continue;
        }
        let (cmf, d65) = tables.at(w);
        let illuminant = match usage {
            SpectrumUse::Emission => 1.0,
            _ => d65 * D65_NORMALIZATION,
        };
        for c in 0..3 {
            xyz[c] += cmf[c] * v * Y_NORMALIZATION * illuminant;
        }
    }
    let xyz = xyz.map(|c| c * (CIE_MAX - CIE_MIN) / STEPS as f64);
    let rgb = xyz_to_srgb(xyz);
    let hi = if usage == SpectrumUse::Reflectance {
        1.0
    } else {
        f64::INFINITY
    };
    let clamped = rgb.clamp(glam::DVec3::ZERO, glam::DVec3::splat(hi));
    (clamped.as_vec3(), clamped != rgb)
}

/// Reads the text of an `.spd` file: one `wavelength value` pair per
/// line, `#` starts a comment. Errors are plain messages.
pub fn parse_spd(text: &str) -> Result<(Vec<f64>, Vec<f64>), String> {
    let (mut wavelengths, mut values) = (Vec::new(), Vec::new());
    for (i, line) in text.lines().enumerate() {
        let data = line.split('#').next().unwrap_or("");
        let nums: Vec<&str> = data.split_whitespace().collect();
        match nums.as_slice() {
            [] => continue,
            [w, v] => {
                let parse = |s: &str| {
                    s.parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| format!("line {}: '{s}' is not a number", i + 1))
                };
                wavelengths.push(parse(w)?);
                values.push(parse(v)?);
            }
            _ => {
                return Err(format!(
                    "line {}: expected 'wavelength value', found '{}'",
                    i + 1,
                    line.trim()
                ))
            }
        }
    }
    Ok((wavelengths, values))
}

/// Checks a sampled spectrum: at least two samples, wavelengths
/// increasing.
pub fn check_samples(wavelengths: &[f64]) -> Result<(), String> {
    if wavelengths.len() < 2 {
        return Err(format!(
            "a sampled spectrum needs at least two wavelength:value pairs, found {}",
            wavelengths.len()
        ));
    }
    match wavelengths.windows(2).find(|p| p[1] <= p[0]) {
        Some(p) => Err(format!(
            "wavelengths must increase, found {} after {}",
            p[1], p[0]
        )),
        None => Ok(()),
    }
}

/// CIE XYZ to linear sRGB (Rec. 709 primaries, D65 white; IEC 61966-2-1).
fn xyz_to_srgb(xyz: [f64; 3]) -> glam::DVec3 {
    let [x, y, z] = xyz;
    glam::DVec3::new(
        3.240479 * x - 1.537150 * y - 0.498535 * z,
        -0.969256 * x + 1.875991 * y + 0.041556 * z,
        0.055648 * x - 0.204043 * y + 1.057311 * z,
    )
}

/// The CIE tables, every 5 nm from [`CIE_MIN`] to [`CIE_MAX`].
struct Tables {
    /// x̄, ȳ, z̄, D65 per wavelength.
    rows: Vec<[f64; 4]>,
}

impl Tables {
    /// Colour matching functions and D65 at `w`, linearly interpolated.
    fn at(&self, w: f64) -> ([f64; 3], f64) {
        let t = (w - CIE_MIN) / 5.0;
        let i = (t.max(0.0) as usize).min(self.rows.len() - 2);
        let f = t - i as f64;
        let (a, b) = (self.rows[i], self.rows[i + 1]);
        let lerp = |k: usize| a[k] + (b[k] - a[k]) * f;
        ([lerp(0), lerp(1), lerp(2)], lerp(3))
    }
}

fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let rows: Vec<[f64; 4]> = include_str!("cie1931_d65.csv")
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
                [v[1], v[2], v[3], v[4]]
            })
            .collect();
        assert_eq!(
            rows.len(),
            95,
            "cie1931_d65.csv: 360..=830 nm in 5 nm steps"
        );
        Tables { rows }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(v: f64) -> (Vec<f64>, Vec<f64>) {
        (vec![CIE_MIN, CIE_MAX], vec![v, v])
    }

    #[test]
    fn flat_reflectance_is_white_and_flat_emission_is_the_equal_energy_colour() {
        let (w, v) = flat(1.0);
        let (white, clamped) = samples_to_rgb(&w, &v, SpectrumUse::Reflectance);
        // D65 is the white of sRGB: a flat reflectance is grey, Y ≈ 1
        assert!((white - Vec3::ONE).abs().max_element() < 3e-3, "{white}");
        assert!(clamped || white.max_element() <= 1.0);
        let (v, _) = (v.iter().map(|x| x * 2.0).collect::<Vec<_>>(), ());
        let (e, clamped) = samples_to_rgb(&w, &v, SpectrumUse::Emission);
        let expected = constant_to_rgb(2.0, SpectrumUse::Emission);
        assert!(!clamped);
        assert!(
            (e - expected).abs().max_element() < 2e-3 * 2.0,
            "{e} vs {expected}"
        );
        assert!((expected - Vec3::new(2.409588, 1.896582, 1.817832)).length() < 1e-5);
        assert_eq!(
            constant_to_rgb(0.3, SpectrumUse::Reflectance),
            Vec3::splat(0.3)
        );
    }

    #[test]
    fn narrow_band_reflectances_are_clamped_into_gamut() {
        // a green band: outside the sRGB gamut (negative red and blue)
        let w = [500.0, 510.0, 520.0, 530.0];
        let v = [0.0, 1.0, 1.0, 0.0];
        let (rgb, clamped) = samples_to_rgb(&w, &v, SpectrumUse::Reflectance);
        assert!(clamped && rgb.min_element() >= 0.0 && rgb.max_element() <= 1.0);
        assert!(rgb.y > rgb.x && rgb.y > rgb.z, "{rgb}");
        // the same as an index of refraction: only the negatives go
        let (rgb_u, _) = samples_to_rgb(&w, &v, SpectrumUse::Unbounded);
        assert_eq!(rgb_u.x, 0.0);
        assert_eq!(SpectrumUse::of("eta", true), SpectrumUse::Unbounded);
        assert_eq!(SpectrumUse::of("radiance", true), SpectrumUse::Emission);
        assert_eq!(
            SpectrumUse::of("reflectance", false),
            SpectrumUse::Reflectance
        );
    }

    #[test]
    fn spd_files_and_sample_checks() {
        let (w, v) = parse_spd("# measured\n400 0.1\n\n500\t0.5 # peak\r\n600 0.9\n").unwrap();
        assert_eq!(
            (w.as_slice(), v.as_slice()),
            (&[400.0, 500.0, 600.0][..], &[0.1, 0.5, 0.9][..])
        );
        assert!(parse_spd("400 0.1 7\n").unwrap_err().contains("line 1"));
        assert!(parse_spd("400 0.1\n500 x\n")
            .unwrap_err()
            .contains("line 2: 'x'"));
        assert!(check_samples(&[400.0])
            .unwrap_err()
            .contains("at least two"));
        assert!(check_samples(&[400.0, 390.0])
            .unwrap_err()
            .contains("must increase"));
        assert!(check_samples(&[400.0, 500.0]).is_ok());
    }
}
