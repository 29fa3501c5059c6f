//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic, Veach 1997 §9.2), Russian roulette
//! (Mitsuba's `path`, and under the names of its differentiable path
//! tracers `prb`, `prb_basic` and `prb_projective`: here one estimator
//! serves the primal and both derivative modes).

use super::{mis_weight, roulette, scatter, Budgets};
use crate::ad::ScalarReal;
use crate::bsdf::{BsdfContext, BsdfContextT, BsdfFlags};
use crate::emitter::EmitterT;
use crate::error::Result;
use crate::geometry::{DiffRay, Hit};
use crate::math::Spectrum;
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;

/// Path tracer settings.
#[derive(Clone, Debug)]
pub struct PathIntegrator {
    /// Longest path, in vertices (1: only directly visible emitters);
    /// `u32::MAX` for unbounded (`max_depth = -1`).
    pub max_depth: u32,
    /// Mitsuba's `rr_depth`, as the scene gives it.
    pub rr_depth: u32,
    /// The first vertex (0: where the camera ray lands) at which Russian
    /// roulette may end a path, from `rr_depth` as the plugin counts it
    /// ([`RouletteCount`]); `u32::MAX` for none.
    pub roulette_from: u32,
    /// Directly visible emitters are not shown.
    pub hide_emitters: bool,
    /// Sample budgets of the derivative passes (`prb_projective`).
    pub budgets: Budgets,
}

/// How one of Mitsuba's path tracers counts the depth it compares with
/// `rr_depth`, which decides the first vertex where Russian roulette may
/// end a path. Roulette changes no expected value, but a path that goes
/// one vertex further costs a bounce and a shadow ray more: counted as
/// Mitsuba counts it, a scene's render does the work Mitsuba's does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RouletteCount {
    /// Mitsuba's `path` (C++): the vertex just reached counts from 1 when
    /// roulette is decided there, so it starts at vertex `rr_depth − 1`
    /// (with `rr_depth = 1` a path may end at the first surface it sees,
    /// as its documentation describes).
    FromOne,
    /// `prb` and `prb_projective` (Python): the vertex counts from 0, so
    /// roulette starts at vertex `rr_depth`.
    FromZero,
    /// `prb_basic`: no roulette.
    Never,
}

impl PathIntegrator {
    /// Mitsuba's `path` with `max_depth` and `rr_depth`, no budgets.
    pub fn new(max_depth: u32, rr_depth: u32, hide_emitters: bool) -> PathIntegrator {
        PathIntegrator {
            max_depth,
            rr_depth,
            roulette_from: rr_depth - 1,
            hide_emitters,
            budgets: Budgets::default(),
        }
    }

    /// The settings of `node`, with `max_depth` defaulting to
    /// `default_max_depth` (Mitsuba's `path`: -1, its `prb*`: 6), the
    /// plugin's count of `rr_depth`, and the derivative `budgets` read by
    /// the caller.
    pub(crate) fn from_node(
        node: &Node,
        default_max_depth: i64,
        count: RouletteCount,
        budgets: Budgets,
    ) -> Result<PathIntegrator> {
        // (at least 1: `int_min`)
        let rr_depth = node.int_min("rr_depth", 5, 1)? as u32;
        Ok(PathIntegrator {
            max_depth: super::max_depth(node, default_max_depth)?,
            rr_depth,
            roulette_from: match count {
                RouletteCount::FromOne => rr_depth - 1,
                RouletteCount::FromZero => rr_depth,
                RouletteCount::Never => u32::MAX,
            },
            hide_emitters: node.bool("hide_emitters", false)?,
            budgets,
        })
    }

    /// Radiance arriving through the camera sample `cs`, estimated with one
    /// path, in `R`: the primal estimate for `f32`, with its derivatives for
    /// dual numbers (forward mode) and recorded variables (reverse mode).
    /// Every vertex is re-evaluated in `R` (attached local geometry): the
    /// first slides along the camera ray, the next ones follow
    /// [`super::scatter`]'s parameterisation, emitter samples move with
    /// their emitter. Also returns whether the camera ray reached a surface.
    pub fn sample<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> (Spectrum<R>, bool) {
        let camera_ray = cs.ray_if_moving::<R>(store);
        let hit = scene.intersect(&camera_ray.val());
        (
            self.trace(scene, store, camera_ray, hit.as_ref(), 0, rng),
            hit.is_some(),
        )
    }

    /// The radiance arriving along `camera_ray`, which reaches `hit` (what
    /// the scene's `intersect` gives for it), whose end is a vertex of
    /// depth `depth` (0: the first one the camera sees), estimated by
    /// continuing the path from there;
    /// what it reaches first counts with its whole emission (as after a
    /// delta bounce: no MIS with the vertex the ray leaves).
    pub(crate) fn trace<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        camera_ray: DiffRay<R>,
        hit: Option<&Hit>,
        mut depth: u32,
        rng: &mut SampleStream,
    ) -> Spectrum<R> {
        let mut result = Spectrum::<R>::zero();
        let mut throughput = Spectrum::<R>::splat(R::cst(1.0));
        let mut eta = 1.0f32;
        // the ray that reached the current vertex (primal), and the state of
        // the vertex it left, for MIS of emitters hit by BSDF sampling
        let mut ray = camera_ray.val();
        // its direction in R, for environment lookups
        let mut ray_d = camera_ray.d;
        let mut prev_p = ray.o;
        let mut prev_pdf = 1.0f32;
        let mut prev_delta = true;
        // the current vertex and the next one, in two slots that swap
        // roles at each bounce (`scatter` writes the next vertex in place:
        // a surface interaction is a few hundred bytes)
        let mut slots = [None, None];
        // assigned into its slot: built inside an array literal, the
        // first vertex was copied into place, a copy that waits on the
        // stores just made (docs/perf/render_loop.md)
        if let Some(h) = hit {
            slots[0] = Some(scene.surface_interaction::<R>(store, &camera_ray, h));
        }
        let mut current = 0;
        // the BSDF at the current vertex, its textures read once for all
        // its uses there; set in place at each vertex
        let mut bsdf_ctx = BsdfContext::empty();
        loop {
            let [a, b] = &mut slots;
            let (vertex, next) = if current == 0 { (a, b) } else { (b, a) };
            // a vertex where the ray reached a surface (its shape is the
            // hit's); the hit itself is not kept from bounce to bounce: a
            // copy of it read back whole, right after the traversal wrote
            // it field by field, waited for the stores (docs/perf/render_loop.md)
            let Some(si) = vertex.as_ref() else {
                // escaped: environment emission
                if let Some(env) = scene.environment {
                    if !(self.hide_emitters && depth == 0) {
                        let le = scene.emitters[env as usize].eval_environment::<R>(store, ray_d);
                        let w = if prev_delta {
                            1.0
                        } else {
                            let em_pdf =
                                scene.pdf_emitter_direction(env, prev_p, ray.d, ray.d, ray.d);
                            mis_weight(prev_pdf, em_pdf)
                        };
                        result += throughput.mul_elem(le) * R::cst(w);
                    }
                }
                return result;
            };

            // emission of a surface hit by the previous BSDF sample
            if let Some(em) = scene.shape_emitter(si.shape) {
                if !(self.hide_emitters && depth == 0) {
                    let le = scene.emitters[em as usize].eval_surface(store, si);
                    if !le.is_zero() {
                        let w = if prev_delta {
                            1.0
                        } else {
                            let em_pdf = scene.pdf_emitter_direction(
                                em,
                                prev_p,
                                ray.d,
                                si.p.val(),
                                si.n.val(),
                            );
                            mis_weight(prev_pdf, em_pdf)
                        };
                        result += throughput.mul_elem(le) * R::cst(w);
                    }
                }
            }

            if depth + 1 >= self.max_depth {
                return result;
            }
            let bsdf = scene.shape_bsdf(si.shape);
            bsdf_ctx.set(bsdf, store, si);

            // next-event estimation
            let u_light = rng.next_2d();
            if scene.shape_bsdf_flags(si.shape).has(BsdfFlags::SMOOTH) {
                if let Some(es) = scene.sample_emitter::<R>(store, si.p, u_light) {
                    let wo = si.to_local(es.d);
                    let f = bsdf_ctx.eval(wo);
                    if !f.is_zero() && scene.emitter_visible(si, &es) {
                        let w = if es.ds.delta {
                            1.0
                        } else {
                            mis_weight(es.ds.pdf, bsdf_ctx.pdf(wo.val()))
                        };
                        result += throughput.mul_elem(f).mul_elem(es.weight) * R::cst(w);
                    }
                }
            }

            // continue the path by BSDF sampling
            let u1 = rng.next_1d();
            let u2 = rng.next_2d();
            let Some(bs) = bsdf_ctx.sample(u1, u2) else {
                return result;
            };
            eta *= bs.eta;
            // Russian roulette before the bounce's ray is traced (as
            // Mitsuba): a path it ends costs no traversal and no vertex.
            // It sees the throughput after the bounce, whose primal value
            // is that of the sample's weight (`scatter`'s weight carries
            // the derivatives of attached geometry; its value may differ
            // in the last bit, which only moves the survival probability
            // by as much).
            let Some(survival) = roulette(
                throughput.val() * bs.weight.val(),
                eta,
                depth,
                self.roulette_from,
                rng,
            ) else {
                return result;
            };
            let bounce = scatter(scene, store, &bsdf_ctx, si, &bs, next);
            throughput = throughput.mul_elem(bounce.weight);
            survival.apply(&mut throughput);
            ray = bounce.ray;
            ray_d = bounce.d;
            prev_p = si.p.val();
            current = 1 - current;
            prev_pdf = bs.pdf;
            prev_delta = bounce.delta;
            depth += 1;
        }
    }
}
