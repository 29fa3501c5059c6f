//! Spectrum plugins (`<spectrum type="…" name="…"> … </spectrum>`) as
//! property values, the way Mitsuba 3.9's RGB variants load them (checked
//! against Mitsuba 3.9.1 with `mi.traverse` and renders):
//!
//! - `uniform` (`value`) and `d65` (`scale`, default 1) are the grey
//!   `value` or `scale`, also inside an emitter (unlike the constant
//!   `<spectrum value="v"/>`, which is a flat emission spectrum there); a
//!   `d65` with an `<rgb name="color">` is `color · scale`;
//! - `srgb` (`color`) is its colour, which must lie in [0, 1] for a
//!   reflectance;
//! - `blackbody` (`temperature`, `wavelength_min`/`_max`, default 360 and
//!   830 nm), `regular` (`wavelength_min`, `wavelength_max`, `values`) and
//!   `irregular` (`wavelengths`, `values`) are spectra that Mitsuba's RGB
//!   variants load but cannot render (their evaluation raises "not
//!   implemented"). Penumbra converts them to RGB as the parser converts
//!   `wavelength:value` lists ([`super::spectrum`]), which is the colour
//!   Mitsuba's spectral variants render for them: a blackbody is Planck's
//!   law in W/(m²·sr·nm), not normalised.

use super::props::{Node, Prop, Value};
use super::spectrum::{self, SpectrumUse};
use crate::error::Result;

/// The value of spectrum plugin `node` used as `usage`, and whether its
/// colour was clamped into range.
pub(super) fn to_value(node: &Node, usage: SpectrumUse) -> Result<(Value, bool)> {
    let value = match node.plugin.as_str() {
        "uniform" => (Value::Spectrum(node.float_req("value")?), false),
        "d65" => {
            let scale = node.float("scale", 1.0)?;
            match node.vec3_opt("color")? {
                Some(color) => (Value::Rgb(color * scale), false),
                None => (Value::Spectrum(scale), false),
            }
        }
        "srgb" => {
            let color = node
                .vec3_opt("color")?
                .ok_or_else(|| node.error("missing required parameter 'color'"))?;
            if usage == SpectrumUse::Reflectance
                && (color.min_element() < 0.0 || color.max_element() > 1.0)
            {
                let p = node.prop("color").expect("read above");
                return Err(node.prop_error(
                    p,
                    format!("a reflectance must lie in [0, 1], found {color}"),
                ));
            }
            (Value::Rgb(color), false)
        }
        "blackbody" => {
            let temperature = node.float_req("temperature")?;
            if temperature <= 0.0 {
                let p = node.prop("temperature").expect("read above");
                return Err(node.prop_error(p, format!("must be > 0 kelvin, found {temperature}")));
            }
            let (lo, hi) = range(node, 360.0, 830.0)?;
            let (rgb, clamped) = spectrum::to_rgb(
                |w| {
                    if (lo..=hi).contains(&w) {
                        spectrum::planck(temperature as f64, w)
                    } else {
                        0.0
                    }
                },
                usage,
            );
            (Value::Rgb(rgb), clamped)
        }
        "regular" => {
            let (lo, hi) = range(node, f64::NAN, f64::NAN)?;
            let values = numbers(node, "values")?;
            if values.len() < 2 {
                let p = node.prop("values").expect("read above");
                return Err(node.prop_error(
                    p,
                    format!("needs at least two values, found {}", values.len()),
                ));
            }
            let n = values.len() - 1;
            let wavelengths: Vec<f64> = (0..=n)
                .map(|i| lo + (hi - lo) * i as f64 / n as f64)
                .collect();
            sampled(&wavelengths, &values, usage)
        }
        "irregular" => {
            let wavelengths = numbers(node, "wavelengths")?;
            let values = numbers(node, "values")?;
            if wavelengths.len() != values.len() {
                let p = node.prop("values").expect("read above");
                return Err(node.prop_error(
                    p,
                    format!(
                        "{} values for {} wavelengths; give one value per wavelength",
                        values.len(),
                        wavelengths.len()
                    ),
                ));
            }
            spectrum::check_samples(&wavelengths)
                .map_err(|m| node.prop_error(node.prop("wavelengths").expect("read above"), m))?;
            sampled(&wavelengths, &values, usage)
        }
        other => {
            return Err(node.error(format!(
                "unknown spectrum plugin '{other}' (Penumbra has: uniform, d65, srgb, blackbody, \
                 regular, irregular)"
            )))
        }
    };
    node.check_all_used()?;
    Ok(value)
}

fn sampled(wavelengths: &[f64], values: &[f64], usage: SpectrumUse) -> (Value, bool) {
    let (rgb, clamped) = spectrum::samples_to_rgb(wavelengths, values, usage);
    (Value::Rgb(rgb), clamped)
}

/// `wavelength_min` and `wavelength_max` (nm; required where a default
/// is NaN), the first below the second.
fn range(node: &Node, default_min: f64, default_max: f64) -> Result<(f64, f64)> {
    let get = |name: &str, default: f64| -> Result<f64> {
        match node.float_opt(name)? {
            Some(v) => Ok(v as f64),
            None if default.is_nan() => {
                Err(node.error(format!("missing required parameter '{name}'")))
            }
            None => Ok(default),
        }
    };
    let (lo, hi) = (
        get("wavelength_min", default_min)?,
        get("wavelength_max", default_max)?,
    );
    if lo >= hi {
        let p = node
            .prop("wavelength_max")
            .or(node.prop("wavelength_min"))
            .expect("a default range is valid");
        return Err(node.prop_error(
            p,
            format!("wavelength_min ({lo}) must be below wavelength_max ({hi})"),
        ));
    }
    Ok((lo, hi))
}

/// A required `<string>` of numbers separated by commas or spaces, as
/// Mitsuba writes `values` and `wavelengths`.
fn numbers(node: &Node, name: &str) -> Result<Vec<f64>> {
    let text = node
        .string_opt(name)?
        .ok_or_else(|| node.error(format!("missing required parameter '{name}'")))?;
    let p: &Prop = node.prop(name).expect("read above");
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(node.prop_error(p, format!("'{t}' is not a number"))),
        })
        .collect()
}
