//! The medium family: participating media (Mitsuba's `homogeneous` and
//! `heterogeneous`), which absorb and scatter light along rays between
//! surfaces. A medium has an extinction coefficient σ_t = scale · sigma_t
//! and a single-scattering albedo α, both volumes (`volume/`), and a phase
//! function (`phase/`); σ_s = α σ_t scatters, the rest absorbs.
//!
//! Media answer two questions for the volumetric path tracer
//! (`integrator/volpath.rs`), in the number type of the pass:
//! - a **free flight** along a ray: where the path scatters next, or that
//!   it passes to the end of the segment, with the weight of the estimate
//!   (transmittance and σ_s over the density of the sampled distance);
//! - the **transmittance** of a segment (shadow rays).
//!
//! Distances are sampled with densities that are constants of the
//! derivative (detached sampling, as for surfaces); the weights carry the
//! derivatives of σ_t and α at the sampled (fixed) points. The two plugins
//! differ in how they sample: in closed form (homogeneous) or by delta
//! tracking against a majorant (heterogeneous); see their files.

mod heterogeneous;
mod homogeneous;
mod majorant;

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::phase::PhaseFunction;
use crate::sampler::SampleStream;
use crate::scene::description::{Class, LoadContext, Node};
use crate::volume::Volume;
use glam::Vec3;
use majorant::{MajorantGrid, Walk};

/// How a medium samples distances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MediumKind {
    /// Constant coefficients: closed-form sampling and transmittance.
    Homogeneous,
    /// Coefficients from volumes: delta and ratio tracking.
    Heterogeneous,
}

/// A participating medium.
#[derive(Clone, Debug)]
pub struct Medium {
    pub kind: MediumKind,
    /// Extinction before `scale`.
    sigma_t: Volume,
    albedo: Volume,
    /// `<key>.scale`, multiplying `sigma_t`.
    scale: ParamId,
    pub phase: PhaseFunction,
    /// Whether next-event estimation is done from points in the medium
    /// (Mitsuba's `sample_emitters`).
    pub sample_emitters: bool,
    /// Where the medium's volumes are defined (a grid's box); outside it a
    /// heterogeneous medium is empty, as in Mitsuba.
    bbox: Option<(Vec3, Vec3)>,
    /// An upper bound of the extinction over space and channels (primal),
    /// for delta and ratio tracking; refreshed by `parameters_changed`.
    majorant: f32,
    /// Local upper bounds, over the cells of a grid extinction (see
    /// `majorant.rs`); refreshed by `parameters_changed`.
    majorant_grid: Option<MajorantGrid>,
    /// The least majorant of a cell while the extinction grid's values are
    /// differentiated (see `heterogeneous.rs`).
    tracked_floor: f32,
}

/// What a free flight found.
pub enum FreeFlight<R> {
    /// The path scatters at distance `t` along the ray (point `p`);
    /// `weight` = σ_s T / p(t) per channel.
    Scatter {
        t: f32,
        p: Vec3,
        weight: Spectrum<R>,
    },
    /// The path reaches the end of the segment; `weight` = T / P(pass).
    Pass { weight: Spectrum<R> },
}

impl Medium {
    /// Builds a `<medium>` node (and checks that all its parameters were
    /// used).
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Medium> {
        let kind = match node.plugin.as_str() {
            "homogeneous" => MediumKind::Homogeneous,
            "heterogeneous" => MediumKind::Heterogeneous,
            other => {
                return Err(node.error(format!(
                    "unknown medium plugin '{other}' (Penumbra has: homogeneous, heterogeneous)"
                )))
            }
        };
        if kind == MediumKind::Homogeneous {
            homogeneous::check_constant(node)?;
        }
        // Mitsuba's defaults: σ_t 1, albedo 0.75, scale 1
        let sigma_t = Volume::from_prop(node, "sigma_t", 1.0, Domain::NonNegative, ctx)?;
        let albedo = Volume::from_prop(node, "albedo", 0.75, Domain::UnitInterval, ctx)?;
        let scale = node.float("scale", 1.0)?;
        let scale = ctx
            .store
            .add(
                format!("{}.scale", node.key),
                vec![scale],
                vec![1],
                ParamFlags::DIFFERENTIABLE,
                Domain::NonNegative,
            )
            .map_err(|e| {
                node.prop("scale")
                    .map_or_else(|| node.error(&e), |p| node.prop_error(p, &e))
            })?;
        let phase_key = format!("{}.phase_function", node.key);
        let phase = match node.child_props(Class::Phase).as_slice() {
            [] => PhaseFunction::Isotropic,
            [(_, p)] => PhaseFunction::from_node(p, &phase_key, ctx)?,
            [_, (p, _), ..] => {
                return Err(node.prop_error(p, "a medium has one phase function; remove the others"))
            }
        };
        let sample_emitters = node.bool("sample_emitters", true)?;
        // Mitsuba bounds a medium by its extinction volume's box
        let bbox = sigma_t.bbox();
        node.check_all_used()?;
        let mut m = Medium {
            kind,
            sigma_t,
            albedo,
            scale,
            phase,
            sample_emitters,
            bbox,
            majorant: 0.0,
            majorant_grid: None,
            tracked_floor: 0.0,
        };
        if kind == MediumKind::Heterogeneous {
            m.majorant_grid = m.sigma_t.grid().and_then(MajorantGrid::new);
        }
        m.parameters_changed(&ctx.store);
        Ok(m)
    }

    /// Refreshes the majorants after parameter updates.
    pub fn parameters_changed(&mut self, store: &ParamStore) {
        let scale = store.value(self.scale, 0);
        let max = scale * self.sigma_t.max(store);
        self.majorant = heterogeneous::MAJORANT_FACTOR * max;
        self.tracked_floor = heterogeneous::TRACKED_FLOOR * max;
        if let (Some(m), Some(grid)) = (&mut self.majorant_grid, self.sigma_t.grid()) {
            m.update(grid, store, heterogeneous::MAJORANT_FACTOR * scale);
        }
    }

    /// σ_t at `p`, in `R`; one number on all channels for a one-channel
    /// extinction (one product, one tape node in reverse mode).
    #[inline]
    fn extinction<R: ScalarReal>(&self, store: &ParamView, p: Vec3) -> Spectrum<R> {
        let scale: R = store.read(self.scale, 0);
        let s = self.sigma_t.eval::<R>(store, p);
        if self.sigma_t.is_mono() {
            Spectrum::splat(s.x * scale)
        } else {
            s * scale
        }
    }

    /// σ_t and α at `p`, in `R`.
    #[inline]
    fn coefficients<R: ScalarReal>(
        &self,
        store: &ParamView,
        p: Vec3,
    ) -> (Spectrum<R>, Spectrum<R>) {
        (self.extinction(store, p), self.albedo.eval(store, p))
    }

    /// The parts of `ray` (unit direction) over `[0, t_max]` in the
    /// medium, with their majorants (primal, whatever the number type).
    fn segments(&self, store: &ParamView, ray: &Ray, t_max: f32) -> Walk<'_> {
        let Some((t0, t1)) = self.clip(ray, t_max) else {
            return Walk::empty();
        };
        let (Some(m), Some(grid)) = (&self.majorant_grid, self.sigma_t.grid()) else {
            return Walk::uniform(t0, t1, self.majorant);
        };
        if let Some(single) = m.single() {
            // at least the whole medium's bound, for the parts outside
            // the cube (the floor is a tenth of it)
            return Walk::uniform(t0, t1, single.max(self.majorant));
        }
        let floor = if store.has_tangent(grid.data) || store.is_recorded(grid.data) {
            self.tracked_floor
        } else {
            0.0
        };
        m.walk(ray, t0, t1, self.majorant, floor)
    }

    /// The range of `t` in `[0, t_max]` where `ray` is inside the medium's
    /// box (all of it for a medium without one), or `None`.
    fn clip(&self, ray: &Ray, t_max: f32) -> Option<(f32, f32)> {
        let Some((lo, hi)) = self.bbox else {
            return Some((0.0, t_max));
        };
        let inv = ray.d.recip();
        let (a, b) = ((lo - ray.o) * inv, (hi - ray.o) * inv);
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(t_max);
        (t0 < t1).then_some((t0, t1))
    }

    /// Samples where a path travelling along `ray` (unit direction) in
    /// this medium scatters before distance `t_max` (the next surface, or
    /// infinity), consuming random numbers from `rng`.
    pub fn sample_free_flight<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &Ray,
        t_max: f32,
        rng: &mut SampleStream,
    ) -> FreeFlight<R> {
        match self.kind {
            MediumKind::Homogeneous => {
                homogeneous::sample_free_flight(self, store, ray, t_max, rng)
            }
            MediumKind::Heterogeneous => {
                heterogeneous::sample_free_flight(self, store, ray, t_max, rng)
            }
        }
    }

    /// An estimate of the transmittance along `ray` (unit direction) from
    /// 0 to `t_max`, in `R`.
    pub fn transmittance<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &Ray,
        t_max: f32,
        rng: &mut SampleStream,
    ) -> Spectrum<R> {
        match self.kind {
            MediumKind::Homogeneous => homogeneous::transmittance(self, store, ray, t_max),
            MediumKind::Heterogeneous => heterogeneous::transmittance(self, store, ray, t_max, rng),
        }
    }

    /// The phase function's value for scattering from `wi` to `wo`.
    #[inline]
    pub fn phase_eval<R: ScalarReal>(&self, store: &ParamView, wi: Vec3, wo: V3<R>) -> R {
        self.phase.eval(store, wi, wo)
    }
}
