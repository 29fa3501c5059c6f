//! The shape family. One file per plugin; the enum dispatches.

use crate::ad::Real;
use crate::geometry::{Hit, PositionSample, Ray, SurfaceInteraction};
use crate::params::ParamStore;
use glam::Vec2;

/// What every shape plugin provides.
pub trait ShapeT {
    /// Re-evaluates the hit reported by the acceleration structure, in `R`,
    /// from the shape's parameters.
    fn surface_interaction<R: Real>(
        &self,
        store: &ParamStore,
        ray: &Ray,
        hit: &Hit,
    ) -> SurfaceInteraction<R>;
    /// Samples a point uniformly with respect to surface area.
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample;
    /// Total surface area.
    fn surface_area(&self) -> f32;
}

/// All shape plugins.
#[derive(Clone, Debug)]
pub enum Shape {}

impl ShapeT for Shape {
    fn surface_interaction<R: Real>(
        &self,
        _store: &ParamStore,
        _ray: &Ray,
        _hit: &Hit,
    ) -> SurfaceInteraction<R> {
        match *self {}
    }
    fn sample_position(&self, _store: &ParamStore, _u: Vec2) -> PositionSample {
        match *self {}
    }
    fn surface_area(&self) -> f32 {
        match *self {}
    }
}
