//! The emitter family. Radiance is RGB; sampling is detached (f32), the
//! returned weights (`radiance / pdf`) are differentiable in `R`.

use crate::ad::Real;
use crate::error::Result;
use crate::geometry::{Shape, SurfaceInteraction};
use crate::math::Spectrum;
use crate::params::ParamStore;
use crate::scene::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// A direction sampled towards an emitter from a reference point.
#[derive(Clone, Copy, Debug)]
pub struct DirectionSample {
    /// Point on the emitter (for environment emitters: far away along `d`).
    pub p: Vec3,
    /// Emitter surface normal at `p` (zero for point-like and environment
    /// emitters).
    pub n: Vec3,
    /// Unit direction from the reference point to `p`.
    pub d: Vec3,
    /// Distance to `p` (infinite for environment/directional emitters).
    pub dist: f32,
    /// Solid-angle density (for delta emitters: 1).
    pub pdf: f32,
    /// True for emitters that cannot be hit by rays (point, spot,
    /// directional): no MIS with BSDF sampling.
    pub delta: bool,
}

/// What every emitter plugin provides.
pub trait EmitterT {
    /// Samples a direction from `ref_p` towards the emitter. Returns the
    /// sample and `radiance / pdf` (visibility not included).
    fn sample_direction<R: Real>(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        u: Vec2,
    ) -> Option<(DirectionSample, Spectrum<R>)>;
    /// Solid-angle density of sampling the emitter point hit along `d` from
    /// `ref_p` (`p`, `n`: the hit point and its normal; unused by
    /// environment emitters).
    fn pdf_direction(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        d: Vec3,
        p: Vec3,
        n: Vec3,
    ) -> f32;
    /// Radiance leaving a surface emitter at `si` towards `si.wi`.
    fn eval_surface<R: Real>(&self, store: &ParamStore, si: &SurfaceInteraction<R>) -> Spectrum<R>;
    /// Radiance arriving from infinity along ray direction `d` (environment
    /// emitters; zero for others).
    fn eval_environment<R: Real>(&self, store: &ParamStore, d: Vec3) -> Spectrum<R>;
    /// True for point, spot and directional emitters.
    fn is_delta(&self) -> bool;
    /// True for constant and envmap emitters.
    fn is_environment(&self) -> bool;
}

/// All emitter plugins.
#[derive(Clone, Debug)]
pub enum Emitter {}

impl EmitterT for Emitter {
    fn sample_direction<R: Real>(
        &self,
        _store: &ParamStore,
        _shapes: &[Shape],
        _ref_p: Vec3,
        _u: Vec2,
    ) -> Option<(DirectionSample, Spectrum<R>)> {
        match *self {}
    }
    fn pdf_direction(
        &self,
        _store: &ParamStore,
        _shapes: &[Shape],
        _ref_p: Vec3,
        _d: Vec3,
        _p: Vec3,
        _n: Vec3,
    ) -> f32 {
        match *self {}
    }
    fn eval_surface<R: Real>(
        &self,
        _store: &ParamStore,
        _si: &SurfaceInteraction<R>,
    ) -> Spectrum<R> {
        match *self {}
    }
    fn eval_environment<R: Real>(&self, _store: &ParamStore, _d: Vec3) -> Spectrum<R> {
        match *self {}
    }
    fn is_delta(&self) -> bool {
        match *self {}
    }
    fn is_environment(&self) -> bool {
        match *self {}
    }
}

impl Emitter {
    /// Builds an `<emitter>` node. `shape` is the index of the shape an area
    /// emitter is attached to (`None` at scene level).
    pub fn from_node(node: &Node, shape: Option<u32>, _ctx: &mut LoadContext) -> Result<Emitter> {
        let _ = shape;
        Err(node.error(format!("unknown emitter plugin '{}'", node.plugin)))
    }
}
