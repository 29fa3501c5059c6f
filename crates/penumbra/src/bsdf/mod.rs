//! The BSDF family. Conventions (as in Mitsuba 3): directions are in the
//! local shading frame (normal = +z); `si.wi` points towards the viewer;
//! `eval` includes the cosine foreshortening `|cos θo|`; sampling is
//! detached (the sampled direction and its pdf are f32 constants) while the
//! sample weight `eval / pdf` is differentiated in `R`.

use crate::ad::Real;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::Spectrum;
use crate::params::ParamStore;
use crate::scene::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Which lobes a BSDF has, or which lobe a sample came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BsdfFlags(pub u8);

impl BsdfFlags {
    pub const DIFFUSE_REFLECTION: BsdfFlags = BsdfFlags(1);
    pub const GLOSSY_REFLECTION: BsdfFlags = BsdfFlags(2);
    pub const DELTA_REFLECTION: BsdfFlags = BsdfFlags(4);
    pub const GLOSSY_TRANSMISSION: BsdfFlags = BsdfFlags(8);
    pub const DELTA_TRANSMISSION: BsdfFlags = BsdfFlags(16);
    /// Index-matched pass-through (null BSDF, transparent parts of `mask`).
    pub const NULL: BsdfFlags = BsdfFlags(32);
    /// Both sides of the surface reflect (twosided wrapper, thin dielectric).
    pub const TWO_SIDED: BsdfFlags = BsdfFlags(64);

    pub const DELTA: BsdfFlags = BsdfFlags(4 | 16 | 32);
    pub const SMOOTH: BsdfFlags = BsdfFlags(1 | 2 | 8);
    pub const TRANSMISSION: BsdfFlags = BsdfFlags(8 | 16 | 32);

    #[inline(always)]
    pub fn has(self, f: BsdfFlags) -> bool {
        self.0 & f.0 != 0
    }
    #[inline(always)]
    pub fn union(self, f: BsdfFlags) -> BsdfFlags {
        BsdfFlags(self.0 | f.0)
    }
}

/// A sampled direction with its weight.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample<R> {
    /// Sampled direction, local frame (a constant: detached sampling).
    pub wo: Vec3,
    /// Solid-angle density of `wo` (for delta lobes: the discrete
    /// probability of choosing the lobe).
    pub pdf: f32,
    /// `eval(wo) / pdf`, differentiable.
    pub weight: Spectrum<R>,
    /// Relative index of refraction along the sampled path (1 for
    /// reflection).
    pub eta: f32,
    /// The lobe the sample came from.
    pub lobe: BsdfFlags,
}

/// What every BSDF plugin provides.
pub trait BsdfT {
    /// The lobes this BSDF has (may depend on textures, so it takes the
    /// store).
    fn flags(&self) -> BsdfFlags;
    /// `f(wi, wo) · |cos θo|` for the smooth lobes (zero for delta lobes).
    fn eval<R: Real>(
        &self,
        store: &ParamStore,
        si: &SurfaceInteraction<R>,
        wo: Vec3,
    ) -> Spectrum<R>;
    /// Solid-angle density with which `sample` returns `wo` (smooth lobes).
    fn pdf<R: Real>(&self, store: &ParamStore, si: &SurfaceInteraction<R>, wo: Vec3) -> f32;
    /// Samples an outgoing direction; `u1` picks a lobe, `u2` the direction.
    fn sample<R: Real>(
        &self,
        store: &ParamStore,
        si: &SurfaceInteraction<R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>>;
    /// The surface's albedo-like colour (for the AOV integrator).
    fn albedo<R: Real>(&self, store: &ParamStore, si: &SurfaceInteraction<R>) -> Spectrum<R>;
}

/// All BSDF plugins.
#[derive(Clone, Debug)]
pub enum Bsdf {}

impl BsdfT for Bsdf {
    fn flags(&self) -> BsdfFlags {
        match *self {}
    }
    fn eval<R: Real>(
        &self,
        _store: &ParamStore,
        _si: &SurfaceInteraction<R>,
        _wo: Vec3,
    ) -> Spectrum<R> {
        match *self {}
    }
    fn pdf<R: Real>(&self, _store: &ParamStore, _si: &SurfaceInteraction<R>, _wo: Vec3) -> f32 {
        match *self {}
    }
    fn sample<R: Real>(
        &self,
        _store: &ParamStore,
        _si: &SurfaceInteraction<R>,
        _u1: f32,
        _u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        match *self {}
    }
    fn albedo<R: Real>(&self, _store: &ParamStore, _si: &SurfaceInteraction<R>) -> Spectrum<R> {
        match *self {}
    }
}

impl Bsdf {
    /// Builds a `<bsdf>` node.
    pub fn from_node(node: &Node, _ctx: &mut LoadContext) -> Result<Bsdf> {
        Err(node.error(format!("unknown BSDF plugin '{}'", node.plugin)))
    }
}
