//! A spatially constant volume (Mitsuba's `constvolume`, also what a plain
//! value given for a medium's `sigma_t` or `albedo` becomes).

use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::math::Spectrum;
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node, Value};
use crate::texture::{Channels, TextureT, Uniform};
use glam::Vec3;

/// The value lives in parameter `<key>.value.value` (one element for a
/// float, three for an RGB value), as Mitsuba's `traverse` names it: the
/// volume holds a uniform texture `value`.
#[derive(Clone, Debug)]
pub struct ConstVolume {
    value: Uniform,
}

impl ConstVolume {
    /// The volume `key` with the constant `value` (a float, spectrum
    /// constant or RGB value).
    pub fn new(key: &str, value: Value, domain: Domain, ctx: &mut LoadContext) -> Result<Self> {
        let (channels, v) = match value {
            Value::Float(v) => (Channels::Mono, Vec3::splat(v as f32)),
            Value::Spectrum(v) => (Channels::Mono, Vec3::splat(v)),
            Value::Rgb(v) => (Channels::Rgb, v),
            other => {
                return Err(Error::Invalid(format!(
                    "must be a float, rgb or spectrum, found {}",
                    other.kind()
                )))
            }
        };
        let value = Uniform::new(&format!("{key}.value"), channels, v, domain, ctx)?;
        Ok(ConstVolume { value })
    }

    /// `<volume type="constvolume">` with its `value` (default 1).
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Self> {
        let value = match node.prop("value") {
            None => Value::Float(1.0),
            Some(p) => match &p.value {
                v @ (Value::Float(_) | Value::Spectrum(_) | Value::Rgb(_)) => v.clone(),
                _ => return Err(node.prop_error(p, "must be a float, rgb or spectrum")),
            },
        };
        ConstVolume::new(&node.key, value, domain, ctx).map_err(|e| node.error(e))
    }

    #[inline]
    pub fn eval<R: ScalarReal>(&self, store: &ParamView) -> Spectrum<R> {
        self.value.value(store)
    }

    /// One value on all channels.
    pub fn is_mono(&self) -> bool {
        matches!(self.value.channels, Channels::Mono)
    }

    pub fn max(&self, store: &ParamStore) -> f32 {
        self.value.max(store)
    }
}
