//! Volumetric path tracing (Mitsuba's `volpath`, and under the names of
//! its other volumetric integrators `volpathmis` and `prbvolpath`: here
//! one estimator serves the primal and both derivative modes, as `path`
//! does for surfaces).
//!
//! Rays carry the medium they travel in: the sensor's at first, then, each
//! time a ray crosses a shape that bounds media, the shape's `interior`
//! or `exterior` on the side the ray goes to. Along each segment the
//! medium samples a free flight (`medium/`): the path either scatters in
//! the medium (next-event estimation through the phase function, then a
//! phase-function sample) or reaches the surface, where it goes on as in
//! `path`: emission with MIS, next-event estimation, BSDF sampling.
//! Surfaces with a `null` BSDF are passed through without counting as a
//! bounce. Next-event estimation from a vertex traces its shadow ray
//! through surfaces with a pass-through (`NULL`) lobe (null, thin
//! dielectric, mask) and multiplies the lobes' weights and the
//! transmittance of every medium segment on the way; the emitter-sampling
//! and the phase/BSDF-sampling strategies are weighted by the power
//! heuristic on their directional densities, transmittance being part of
//! the integrand (as in Mitsuba). A pass-through lobe is no bounce: a path
//! that samples it goes on even after its last scattering vertex.
//!
//! Derivatives: sampled distances, directions and decisions are constants
//! (detached sampling); the weights of free flights, phase functions,
//! BSDFs, emitters and transmittances carry the derivatives of the media,
//! materials and emitters. Geometry and camera derivatives through media
//! are not supported: the derivative calls refuse them for this
//! integrator.

use super::{mis_weight, survives_roulette, Budgets};
use crate::ad::ScalarReal;
use crate::bsdf::{Bsdf, BsdfContext, BsdfContextT, BsdfFlags};
use crate::emitter::{DirectionSample, EmitterSample, EmitterT};
use crate::error::Result;
use crate::geometry::{DiffRay, Hit, Ray, SurfaceInteraction, SurfacePoint};
use crate::math::{Spectrum, V3};
use crate::medium::FreeFlight;
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;
use glam::Vec3;

/// Shadow rays from points in media stop this fraction short of the
/// emitter point (so as not to hit the emitter's own surface), as those
/// from surfaces do (`SurfaceInteraction::spawn_ray_to`).
const SHADOW_EPSILON: f32 = 1e-4;

/// Volumetric path tracer settings.
#[derive(Clone, Debug)]
pub struct VolPathIntegrator {
    /// Longest path, in scattering vertices (surface or medium) plus one,
    /// as Mitsuba counts; `u32::MAX` for unbounded.
    pub max_depth: u32,
    /// Mitsuba's `rr_depth`: Russian roulette may end a path once its
    /// scattering events exceed it ([`VolPathIntegrator::roulette_from`]).
    pub rr_depth: u32,
    /// Directly visible emitters are not shown.
    pub hide_emitters: bool,
}

/// Where the path is: the state of the last scattering vertex, for the
/// MIS weight of an emitter the next ray reaches.
struct LastScatter {
    p: Vec3,
    /// Directional density of the sampled direction (phase or BSDF).
    pdf: f32,
    /// The direction came from a delta lobe, the camera, or a vertex
    /// without next-event estimation: emitters reached count with their
    /// whole weight.
    delta: bool,
}

impl VolPathIntegrator {
    /// The count of scattering events from which Russian roulette may end
    /// a path: Mitsuba's `volpath` and `prbvolpath` play it where the
    /// events so far exceed `rr_depth` (compared with `>`, where its `path`
    /// compares with `>=`).
    pub(crate) fn roulette_from(&self) -> u32 {
        self.rr_depth.saturating_add(1)
    }

    pub(crate) fn from_node(node: &Node, default_max_depth: i64) -> Result<VolPathIntegrator> {
        Ok(VolPathIntegrator {
            max_depth: super::max_depth(node, default_max_depth)?,
            rr_depth: node.int_min("rr_depth", 5, 1)? as u32,
            hide_emitters: node.bool("hide_emitters", false)?,
        })
    }

    /// No boundary terms: geometry derivatives through media are refused.
    pub fn budgets(&self) -> Budgets {
        Budgets::default()
    }

    /// Radiance arriving through the camera sample `cs`, estimated with one
    /// path in `R`, and whether the camera ray reached a surface.
    pub fn sample<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> (Spectrum<R>, bool) {
        let ray = cs.ray::<f32>(store).val();
        let hit = scene.intersect(&ray);
        let radiance = self.trace(scene, store, ray, hit, cs.sensor.medium, rng);
        (radiance, hit.is_some())
    }

    /// The radiance arriving along `ray`, which first reaches `hit`, from
    /// a path that starts in `medium`.
    fn trace<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        mut ray: Ray,
        mut hit: Option<Hit>,
        mut medium: Option<u32>,
        rng: &mut SampleStream,
    ) -> Spectrum<R> {
        let mut result = Spectrum::<R>::zero();
        let mut throughput = Spectrum::<R>::splat(R::cst(1.0));
        let mut eta = 1.0f32;
        let mut depth = 0u32;
        let mut last = LastScatter {
            p: ray.o,
            pdf: 1.0,
            delta: true,
        };
        let mut bsdf_ctx = BsdfContext::empty();
        loop {
            // ------------------------- the medium --------------------------
            if let Some(m) = medium {
                let t_max = hit.map_or(f32::INFINITY, |h| h.t);
                let m = &scene.media[m as usize];
                match m.sample_free_flight::<R>(store, &ray, t_max, rng) {
                    FreeFlight::Scatter { p, weight, .. } => {
                        throughput = throughput.mul_elem(weight);
                        depth += 1;
                        if depth >= self.max_depth {
                            return result;
                        }
                        let wi = -ray.d;
                        if m.sample_emitters {
                            let u = rng.next_2d();
                            let from = Vertex::Medium(p);
                            if let Some((es, tr)) =
                                self.sample_emitter::<R>(scene, store, from, medium, u, rng)
                            {
                                let f = m.phase_eval(store, wi, es.d);
                                let w = if es.ds.delta {
                                    1.0
                                } else {
                                    mis_weight(es.ds.pdf, m.phase.pdf(&scene.params, wi, es.ds.d))
                                };
                                result += throughput.mul_elem(es.weight).mul_elem(tr) * (f * w);
                            }
                        }
                        let (wo, pdf) = m.phase.sample(&scene.params, wi, rng.next_2d());
                        // value 1: the phase function is sampled exactly
                        let f = m.phase_eval::<R>(store, wi, V3::cst(wo));
                        throughput *= f * (1.0 / pdf);
                        // without next-event estimation here, an emitter the
                        // phase sample reaches counts with its whole weight
                        last = LastScatter {
                            p,
                            pdf,
                            delta: !m.sample_emitters,
                        };
                        // the roulette first: a path it ends traces no ray
                        if !survives_roulette(
                            &mut throughput,
                            eta,
                            depth,
                            self.roulette_from(),
                            rng,
                        ) {
                            return result;
                        }
                        ray = Ray::new(p, wo);
                        hit = scene.intersect(&ray);
                        continue;
                    }
                    FreeFlight::Pass { weight } => throughput = throughput.mul_elem(weight),
                }
            }

            // ------------------------- the surface -------------------------
            let Some(h) = hit else {
                if let Some(env) = scene.environment {
                    if !(self.hide_emitters && depth == 0) {
                        let le = scene.emitters[env as usize]
                            .eval_environment::<R>(store, V3::cst(ray.d));
                        let w = if last.delta {
                            1.0
                        } else {
                            let em_pdf =
                                scene.pdf_emitter_direction(env, last.p, ray.d, ray.d, ray.d);
                            mis_weight(last.pdf, em_pdf)
                        };
                        result += throughput.mul_elem(le) * R::cst(w);
                    }
                }
                return result;
            };
            let bsdf = scene.shape_bsdf(h.shape);
            let emitter = scene.shape_emitter(h.shape);
            // an index-matched boundary is no bounce; one that emits
            // nothing needs only its point, not its local geometry
            let crossing = matches!(bsdf, Bsdf::Null(_));
            let si = (emitter.is_some() || !crossing)
                .then(|| scene.surface_interaction::<R>(store, &DiffRay::cst(&ray), &h));
            if let (Some(em), Some(si)) = (emitter, &si) {
                if !(self.hide_emitters && depth == 0) {
                    let le = scene.emitters[em as usize].eval_surface(store, si);
                    if !le.is_zero() {
                        let w = if last.delta {
                            1.0
                        } else {
                            let em_pdf = scene.pdf_emitter_direction(
                                em,
                                last.p,
                                ray.d,
                                si.p.val(),
                                si.n.val(),
                            );
                            mis_weight(last.pdf, em_pdf)
                        };
                        result += throughput.mul_elem(le) * R::cst(w);
                    }
                }
            }
            if crossing {
                let sp = si
                    .as_ref()
                    .map_or_else(|| scene.hit_point(store, &ray, &h), |si| si.point());
                medium = next_medium(scene, &h, sp.n, ray.d, medium);
                ray = sp.spawn_ray(ray.d);
                hit = scene.intersect(&ray);
                continue;
            }
            let si = si.expect("every surface that is not crossed has its interaction");
            // At the last bounce only a pass-through (`NULL` lobe, which is
            // no bounce) can go on, as in Mitsuba: a path leaving a medium
            // through a thin dielectric or a mask still reaches what lies
            // behind it.
            let last_bounce = depth + 1 >= self.max_depth;
            let flags = scene.shape_bsdf_flags(h.shape);
            if last_bounce && !flags.has(BsdfFlags::NULL) {
                return result;
            }
            bsdf_ctx.set(bsdf, store, &si);

            if !last_bounce && flags.has(BsdfFlags::SMOOTH) {
                let u = rng.next_2d();
                let from = Vertex::Surface(&h, &si);
                if let Some((es, tr)) = self.sample_emitter(scene, store, from, medium, u, rng) {
                    let wo = si.to_local(es.d);
                    let f = bsdf_ctx.eval(wo);
                    let w = if es.ds.delta {
                        1.0
                    } else {
                        mis_weight(es.ds.pdf, bsdf_ctx.pdf(wo.val()))
                    };
                    result += throughput.mul_elem(f).mul_elem(es.weight).mul_elem(tr) * R::cst(w);
                }
            }

            let u1 = rng.next_1d();
            let u2 = rng.next_2d();
            let Some(bs) = bsdf_ctx.sample(u1, u2) else {
                return result;
            };
            throughput = throughput.mul_elem(bs.weight);
            eta *= bs.eta;
            let d = si.to_world(bs.wo).val().normalize();
            medium = next_medium(scene, &h, si.n.val(), d, medium);
            if !bs.lobe.has(BsdfFlags::NULL) {
                if last_bounce {
                    return result;
                }
                depth += 1;
                last = LastScatter {
                    p: si.p.val(),
                    pdf: bs.pdf,
                    delta: bs.lobe.has(BsdfFlags::DELTA),
                };
            }
            if !survives_roulette(&mut throughput, eta, depth, self.roulette_from(), rng) {
                return result;
            }
            ray = si.spawn_ray(d);
            hit = scene.intersect(&ray);
        }
    }

    /// Next-event estimation from a vertex where the path travels in
    /// `medium`: an emitter sample and the transmittance towards it
    /// (through null surfaces and media; `None` if an opaque surface is in
    /// the way).
    fn sample_emitter<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        from: Vertex<R>,
        medium: Option<u32>,
        u: glam::Vec2,
        rng: &mut SampleStream,
    ) -> Option<(EmitterSample<R>, Spectrum<R>)> {
        // The shadow ray aims at the emitter point from its own origin (off
        // the surface), and stops short of it: aimed along the sampled
        // direction from an offset origin instead, it can meet a curved
        // emitter (a sphere near its outline) just before the point. So
        // does every segment after a surface it passes through.
        let (mut ray, mut medium, es) = match from {
            Vertex::Surface(h, si) => {
                let es = scene.sample_emitter::<R>(store, si.p, u)?;
                let ray = shadow_ray(&si.point(), &es.ds);
                // leave the surface on the emitter's side, into the medium
                // there
                let medium = next_medium(scene, h, si.n.val(), ray.d, medium);
                (ray, medium, es)
            }
            Vertex::Medium(p) => {
                let es = scene.sample_emitter::<R>(store, V3::cst(p), u)?;
                let mut ray = Ray::new(p, es.ds.d);
                ray.tmax = es.ds.dist * (1.0 - SHADOW_EPSILON);
                (ray, medium, es)
            }
        };
        let mut tr = Spectrum::<R>::splat(R::cst(1.0));
        loop {
            let hit = scene.intersect(&ray);
            let segment = hit.map_or(ray.tmax, |h| h.t);
            if let Some(m) = medium {
                tr = tr.mul_elem(scene.media[m as usize].transmittance(store, &ray, segment, rng));
                if !R::DIFFERENTIABLE && tr.is_zero() {
                    return None;
                }
            }
            let Some(h) = hit else {
                return Some((es, tr));
            };
            // surfaces with a pass-through lobe (null, the transmission of
            // a thin dielectric, a mask's transparency) let the shadow ray
            // through with that lobe's weight, as Mitsuba's volpath does;
            // the others stop it
            let bsdf = scene.shape_bsdf(h.shape);
            if !scene.shape_bsdf_flags(h.shape).has(BsdfFlags::NULL) {
                return None;
            }
            let sp = if matches!(bsdf, Bsdf::Null(_)) {
                // lets all light through, with no derivative: only the
                // point is needed, not the local geometry
                scene.hit_point(store, &ray, &h)
            } else {
                let si = scene.surface_interaction::<R>(store, &DiffRay::cst(&ray), &h);
                let mut ctx = BsdfContext::empty();
                ctx.set(bsdf, store, &si);
                tr = tr.mul_elem(ctx.null_transmission());
                if !R::DIFFERENTIABLE && tr.is_zero() {
                    return None;
                }
                si.point()
            };
            medium = next_medium(scene, &h, sp.n, ray.d, medium);
            ray = shadow_ray(&sp, &es.ds);
        }
    }
}

/// A shadow ray from the surface point `sp` towards the emitter sample
/// `ds`: to its point, stopping just short, or along its direction for an
/// emitter at infinity.
fn shadow_ray(sp: &SurfacePoint, ds: &DirectionSample) -> Ray {
    if ds.dist.is_finite() {
        sp.spawn_ray_to(ds.p)
    } else {
        sp.spawn_ray(ds.d)
    }
}

/// Where next-event estimation starts.
enum Vertex<'a, R> {
    /// A surface point (and the hit it came from).
    Surface(&'a Hit, &'a SurfaceInteraction<R>),
    /// A scattering point in a medium.
    Medium(Vec3),
}

/// The medium a ray leaving the surface hit `h` (geometric normal `n`) in
/// direction `d` travels in: the shape's exterior on the side the normal
/// points to, its interior on the other, or `current` if the shape bounds
/// no media (Mitsuba's `SurfaceInteraction::target_medium`).
fn next_medium(scene: &Scene, h: &Hit, n: Vec3, d: Vec3, current: Option<u32>) -> Option<u32> {
    let info = &scene.shape_info[h.shape as usize];
    if info.interior.is_none() && info.exterior.is_none() {
        return current;
    }
    if n.dot(d) > 0.0 {
        info.exterior
    } else {
        info.interior
    }
}
