//! A constant value (Mitsuba's implicit uniform texture for plain values).

use super::{Channels, TextureT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::LoadContext;
use glam::Vec3;

/// A spatially constant value, stored as parameter `<key>.value` with one
/// (mono) or three (RGB) elements.
#[derive(Clone, Debug)]
pub struct Uniform {
    pub id: ParamId,
    pub channels: Channels,
}

impl Uniform {
    pub fn new(
        key: &str,
        channels: Channels,
        value: Vec3,
        domain: Domain,
        ctx: &mut LoadContext,
    ) -> Result<Uniform> {
        let data = match channels {
            Channels::Mono => vec![value.x],
            Channels::Rgb => vec![value.x, value.y, value.z],
        };
        let n = data.len();
        let id = ctx.store.add(
            format!("{key}.value"),
            data,
            vec![n],
            ParamFlags::DIFFERENTIABLE,
            domain,
        )?;
        Ok(Uniform { id, channels })
    }
}

impl Uniform {
    /// The value (a mono value on all three channels).
    #[inline]
    pub fn value<R: ScalarReal>(&self, store: &ParamView) -> Spectrum<R> {
        match self.channels {
            Channels::Mono => V3::splat(store.read(self.id, 0)),
            Channels::Rgb => store.read3(self.id, 0),
        }
    }
}

impl TextureT for Uniform {
    #[inline]
    fn eval<R: ScalarReal>(&self, store: &ParamView, _si: &SurfaceInteraction<R>) -> Spectrum<R> {
        self.value(store)
    }
    #[inline]
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, _si: &SurfaceInteraction<R>) -> R {
        match self.channels {
            Channels::Mono => store.read(self.id, 0),
            Channels::Rgb => store.read3::<R>(self.id, 0).mean(),
        }
    }
    fn mean(&self, store: &ParamStore) -> f32 {
        let d = store.data(self.id);
        d.iter().sum::<f32>() / d.len() as f32
    }
    fn max(&self, store: &ParamStore) -> f32 {
        store.data(self.id).iter().cloned().fold(f32::MIN, f32::max)
    }
}
