//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic, Veach 1997 §9.2), Russian roulette
//! (Mitsuba's `path`).

use super::mis_weight;
use crate::ad::Real;
use crate::bsdf::{BsdfFlags, BsdfT};
use crate::emitter::EmitterT;
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::{Spectrum, V3};
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;

/// Path tracer settings.
#[derive(Clone, Debug)]
pub struct PathIntegrator {
    /// Longest path, in vertices (1: only directly visible emitters);
    /// `u32::MAX` for unbounded (`max_depth = -1`).
    pub max_depth: u32,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    /// Directly visible emitters are not shown.
    pub hide_emitters: bool,
}

impl PathIntegrator {
    pub fn from_node(node: &Node) -> Result<PathIntegrator> {
        Ok(PathIntegrator {
            max_depth: super::max_depth(node)?,
            rr_depth: node.int_min("rr_depth", 5, 1)? as u32,
            hide_emitters: node.bool("hide_emitters", false)?,
        })
    }

    /// Radiance arriving along `ray`, estimated with one path.
    pub fn sample<R: Real>(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> Spectrum<R> {
        let ray = cs.ray::<R>(&scene.params).val();
        let mut sink = Accumulate(Spectrum::zero());
        self.trace(scene, ray, rng, &mut sink);
        sink.0
    }

    /// Traces one path, reporting its radiance contributions and scattering
    /// weights to `sink` vertex by vertex. The primal and forward-mode
    /// estimates ([`Accumulate`]) and path replay
    /// (`crate::diff::prb`) share this one loop, so they sample the very
    /// same paths.
    pub(crate) fn trace<R: Real, S: PathSink<R>>(
        &self,
        scene: &Scene,
        ray: Ray,
        rng: &mut SampleStream,
        sink: &mut S,
    ) {
        let store = &scene.params;
        let mut ray = ray;
        let mut throughput = Spectrum::<R>::splat(R::cst(1.0));
        let mut eta = 1.0f32;
        // state of the previous vertex, for MIS of emitters hit by BSDF sampling
        let mut prev_p = ray.o;
        let mut prev_pdf = 1.0f32;
        let mut prev_delta = true;
        let mut depth = 0u32;
        loop {
            let Some(hit) = scene.intersect(&ray) else {
                // escaped: environment emission
                if let Some(env) = scene.environment {
                    if !(self.hide_emitters && depth == 0) {
                        let le = scene.emitters[env as usize].eval_environment::<R>(store, ray.d);
                        let w = if prev_delta {
                            1.0
                        } else {
                            let em_pdf =
                                scene.pdf_emitter_direction(env, prev_p, ray.d, ray.d, ray.d);
                            mis_weight(prev_pdf, em_pdf)
                        };
                        sink.add(throughput.mul_elem(le) * R::cst(w));
                    }
                }
                sink.end_vertex(None);
                return;
            };
            let si = scene.surface_interaction::<R>(&ray, &hit);

            // emission of a surface hit by the previous BSDF sample
            if let Some(em) = scene.shape_emitter(hit.shape) {
                if !(self.hide_emitters && depth == 0) {
                    let le = scene.emitters[em as usize].eval_surface(store, &si);
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
                        sink.add(throughput.mul_elem(le) * R::cst(w));
                    }
                }
            }

            if depth + 1 >= self.max_depth {
                sink.end_vertex(None);
                return;
            }
            let bsdf = scene.shape_bsdf(hit.shape);

            // next-event estimation
            let u_light = rng.next_2d();
            if bsdf.flags().has(BsdfFlags::SMOOTH) {
                if let Some((ds, em_weight)) = scene.sample_emitter_direction::<R>(&si, u_light) {
                    let wo = si.to_local(V3::cst(ds.d)).val();
                    let f = bsdf.eval(store, &si, V3::cst(wo));
                    if !f.is_zero() {
                        let w = if ds.delta {
                            1.0
                        } else {
                            mis_weight(ds.pdf, bsdf.pdf(store, &si, wo))
                        };
                        sink.add(throughput.mul_elem(f).mul_elem(em_weight) * R::cst(w));
                    }
                }
            }

            // continue the path by BSDF sampling
            let u1 = rng.next_1d();
            let u2 = rng.next_2d();
            let Some(bs) = bsdf.sample::<R>(store, &si, u1, u2) else {
                sink.end_vertex(None);
                return;
            };
            throughput = sink.next_throughput(throughput, bs.weight);
            sink.end_vertex(Some(bs.weight));
            eta *= bs.eta;
            let d = si.to_world(V3::cst(bs.wo.val())).val().normalize();
            ray = si.spawn_ray(d);
            prev_p = si.p.val();
            prev_pdf = bs.pdf;
            prev_delta = bs.lobe.has(BsdfFlags::DELTA);

            // Russian roulette on the throughput (times η² so that
            // refraction does not end paths early)
            let u_rr = rng.next_1d();
            let t_max = throughput.val().max_element() * eta * eta;
            if !(t_max > 0.0) {
                return;
            }
            if depth >= self.rr_depth {
                let q = t_max.min(0.95);
                if u_rr >= q {
                    return;
                }
                throughput *= R::cst(1.0 / q);
            }
            depth += 1;
        }
    }
}

/// Receives what a path contributes, vertex by vertex.
pub(crate) trait PathSink<R: Real> {
    /// A radiance contribution, already weighted by the path throughput.
    fn add(&mut self, l: Spectrum<R>);
    /// The throughput after scattering with BSDF-sample weight `w`.
    fn next_throughput(&mut self, throughput: Spectrum<R>, w: Spectrum<R>) -> Spectrum<R>;
    /// The current vertex is complete; `w` is the weight of the scattering
    /// that continues the path from it (`None`: the path ends there).
    fn end_vertex(&mut self, w: Option<Spectrum<R>>);
}

/// The ordinary estimator: sums the contributions (primal in f32,
/// derivatives carried along for dual numbers).
pub(crate) struct Accumulate<R>(pub Spectrum<R>);

impl<R: Real> PathSink<R> for Accumulate<R> {
    #[inline(always)]
    fn add(&mut self, l: Spectrum<R>) {
        self.0 += l;
    }
    #[inline(always)]
    fn next_throughput(&mut self, throughput: Spectrum<R>, w: Spectrum<R>) -> Spectrum<R> {
        throughput.mul_elem(w)
    }
    #[inline(always)]
    fn end_vertex(&mut self, _w: Option<Spectrum<R>>) {}
}
