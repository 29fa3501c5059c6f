//! Mitsuba's `area` emitter: a shape that emits radiance from the side its
//! normal points to.

use super::{surface_si, DirectionSample, EmitterT};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::{PositionSample, Shape, ShapeT, SurfaceInteraction};
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamStore};
use crate::scene::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Radiance `radiance` (a value or a texture over the shape's uv, key
/// `<shape key>.emitter.radiance.value` for a value) leaving shape `shape`
/// on the side of its normal; nothing leaves the back side. Sampled by
/// the shape's uniform-area position sampling, converted to solid angle.
#[derive(Clone, Debug)]
pub struct Area {
    pub radiance: Texture,
    /// Index of the shape in the scene's shape list.
    pub shape: u32,
}

impl Area {
    pub fn from_node(node: &Node, shape: u32, ctx: &mut LoadContext) -> Result<Area> {
        let radiance = Texture::from_prop(
            node,
            "radiance",
            Some(1.0),
            Channels::Rgb,
            Domain::NonNegative,
            ctx,
        )?;
        Ok(Area { radiance, shape })
    }

    /// The direction sample towards position sample `ps` (area density)
    /// seen from `ref_p`: solid-angle density `pdf_A · dist² / |cos θ_e|`
    /// and weight `L / pdf`. `None` when `ref_p` is behind the emitting
    /// side or coincides with the sample.
    pub fn sample_from_position<R: Real>(
        &self,
        store: &ParamStore,
        ps: &PositionSample,
        ref_p: Vec3,
    ) -> Option<(DirectionSample, Spectrum<R>)> {
        let to = ps.p - ref_p;
        let dist2 = to.length_squared();
        if !(dist2 > 0.0) || !(ps.pdf > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let d = to / dist;
        // cosine at the emitter between its normal and the direction to ref_p
        let cos_e = -d.dot(ps.n);
        if !(cos_e > 0.0) {
            return None;
        }
        let pdf = ps.pdf * dist2 / cos_e;
        let si = surface_si::<R>(ps.p, ps.n, ps.uv, -d, self.shape, ps.prim);
        let l = self.radiance.eval(store, &si);
        let ds = DirectionSample {
            p: ps.p,
            n: ps.n,
            d,
            dist,
            pdf,
            delta: false,
        };
        Some((ds, l.scale(1.0 / pdf)))
    }

    /// Solid-angle density of reaching emitter point `p` (normal `n`) along
    /// `d` from `ref_p`, when positions are sampled with area density
    /// `pdf_area`.
    pub fn pdf_from_area(pdf_area: f32, ref_p: Vec3, d: Vec3, p: Vec3, n: Vec3) -> f32 {
        let cos_e = -d.dot(n);
        if !(cos_e > 0.0) {
            return 0.0;
        }
        pdf_area * (p - ref_p).length_squared() / cos_e
    }
}

impl EmitterT for Area {
    fn sample_direction<R: Real>(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        u: Vec2,
    ) -> Option<(DirectionSample, Spectrum<R>)> {
        let shape = shapes.get(self.shape as usize)?;
        let ps = shape.sample_position(store, u);
        self.sample_from_position(store, &ps, ref_p)
    }

    /// Assumes the shape's `sample_position` is uniform by area (density
    /// `1 / surface_area`), as `ShapeT` specifies.
    fn pdf_direction(
        &self,
        _store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        d: Vec3,
        p: Vec3,
        n: Vec3,
    ) -> f32 {
        let Some(shape) = shapes.get(self.shape as usize) else {
            return 0.0;
        };
        let area = shape.surface_area();
        if !(area > 0.0) {
            return 0.0;
        }
        Area::pdf_from_area(1.0 / area, ref_p, d, p, n)
    }

    /// Radiance towards `si.wi` if it is on the front side (shading frame
    /// cos θ > 0, as Mitsuba), else zero.
    fn eval_surface<R: Real>(&self, store: &ParamStore, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        if !(si.wi.z.val() > 0.0) {
            return V3::zero();
        }
        self.radiance.eval(store, si)
    }

    fn eval_environment<R: Real>(&self, _store: &ParamStore, _d: Vec3) -> Spectrum<R> {
        V3::zero()
    }
    fn is_delta(&self) -> bool {
        false
    }
    fn is_environment(&self) -> bool {
        false
    }
}
