//! Direct illumination with multiple importance sampling of emitters and
//! the BSDF (Mitsuba's `direct`, and its `direct_projective`).

use super::{mis_weight, scatter, Budgets};
use crate::ad::ScalarReal;
use crate::bsdf::{BsdfContextT, BsdfFlags};
use crate::emitter::EmitterT;
use crate::error::Result;
use crate::math::Spectrum;
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;

/// Direct lighting: `emitter_samples` emitter samples and `bsdf_samples`
/// BSDF samples per hit, combined with the power heuristic.
#[derive(Clone, Debug)]
pub struct DirectIntegrator {
    pub emitter_samples: u32,
    pub bsdf_samples: u32,
    pub hide_emitters: bool,
    /// Sample budgets of the derivative passes (`direct_projective`).
    pub budgets: Budgets,
}

impl DirectIntegrator {
    pub(crate) fn from_node(node: &Node) -> Result<DirectIntegrator> {
        let shading = node.int_min("shading_samples", 1, 0)? as u32;
        let emitter_samples = node.int_min("emitter_samples", shading as i64, 0)? as u32;
        let bsdf_samples = node.int_min("bsdf_samples", shading as i64, 0)? as u32;
        Ok(DirectIntegrator {
            emitter_samples,
            bsdf_samples,
            hide_emitters: node.bool("hide_emitters", false)?,
            budgets: Budgets::default(),
        })
    }

    /// Mitsuba's `direct_projective`: its estimator is this one with one
    /// emitter and one BSDF sample per hit, plus the derivative budgets.
    /// Mitsuba reads `max_depth` and `rr_depth` there but always traces
    /// depth 2, and `project_seed` chooses the seed rays of its indirect
    /// term (Penumbra samples that term from the edges towards the
    /// emitters); all three are accepted (so that its scenes load) and
    /// warned about when they would change something.
    pub(crate) fn projective_from_node(node: &Node) -> Result<DirectIntegrator> {
        let budgets = Budgets::from_projective_node(node)?;
        let mut ignored = Vec::new();
        if super::max_depth(node, 2)? != 2 {
            ignored.push("max_depth");
        }
        for name in ["rr_depth", "project_seed"] {
            if node.has(name) {
                ignored.push(name);
            }
        }
        node.int_min("rr_depth", 5, 1)?;
        node.choice("project_seed", &["both", "bsdf", "emitter"])?;
        if !ignored.is_empty() {
            crate::warn(format!(
                "{node} at {}: {} ignored: direct illumination always traces depth 2, and \
                 Penumbra samples the indirect visibility term that project_seed steers in \
                 Mitsuba from the edges towards the emitters",
                node.loc,
                ignored.join(", ")
            ));
        }
        Ok(DirectIntegrator {
            emitter_samples: 1,
            bsdf_samples: 1,
            hide_emitters: node.bool("hide_emitters", false)?,
            budgets,
        })
    }

    /// Radiance through the camera sample `cs`, in `R`, with every vertex
    /// re-evaluated in `R` as the path integrator does, and whether the
    /// camera ray reached a surface.
    pub fn sample<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> (Spectrum<R>, bool) {
        let camera_ray = cs.ray_if_moving::<R>(store);
        let ray = camera_ray.val();
        let Some(hit) = scene.intersect(&ray) else {
            let le = match scene.environment {
                Some(env) if !self.hide_emitters => {
                    scene.emitters[env as usize].eval_environment(store, camera_ray.d)
                }
                _ => Spectrum::zero(),
            };
            return (le, false);
        };
        let si = scene.surface_interaction::<R>(store, &camera_ray, &hit);
        let mut result = Spectrum::<R>::zero();
        if let Some(em) = scene.shape_emitter(hit.shape) {
            if !self.hide_emitters {
                result += scene.emitters[em as usize].eval_surface(store, &si);
            }
        }
        let bsdf = scene.shape_bsdf(hit.shape);
        // its textures read once for all the samples below
        let bsdf_ctx = bsdf.context(store, &si);
        let (ne, nb) = (self.emitter_samples as f32, self.bsdf_samples as f32);
        if scene.shape_bsdf_flags(hit.shape).has(BsdfFlags::SMOOTH) {
            for _ in 0..self.emitter_samples {
                let u = rng.next_2d();
                if let Some(es) = scene.sample_emitter::<R>(store, si.p, u) {
                    let wo = si.to_local(es.d);
                    let f = bsdf_ctx.eval(wo);
                    // a value of zero without a derivative adds nothing
                    // (one with a derivative does, for forward mode)
                    if (f.is_zero() && f.is_const()) || !scene.emitter_visible(&si, &es) {
                        continue;
                    }
                    let w = if es.ds.delta {
                        1.0 / ne
                    } else {
                        let pb = bsdf_ctx.pdf(wo.val());
                        mis_weight(ne * es.ds.pdf, nb * pb) / ne
                    };
                    result += f.mul_elem(es.weight) * R::cst(w);
                }
            }
        }
        let mut next = None;
        for _ in 0..self.bsdf_samples {
            let u1 = rng.next_1d();
            let u2 = rng.next_2d();
            let Some(bs) = bsdf_ctx.sample(u1, u2) else {
                continue;
            };
            let b = scatter(scene, store, &bsdf_ctx, &si, &bs, &mut next);
            let d = b.ray.d;
            let (le, em_pdf) = match (b.hit, &next) {
                (Some(h2), Some(si2)) => match scene.shape_emitter(h2.shape) {
                    Some(em) => {
                        let le = scene.emitters[em as usize].eval_surface(store, si2);
                        let pdf = if b.delta {
                            0.0
                        } else {
                            scene.pdf_emitter_direction(em, si.p.val(), d, si2.p.val(), si2.n.val())
                        };
                        (le, pdf)
                    }
                    None => continue,
                },
                _ => match scene.environment {
                    Some(env) => {
                        let le = scene.emitters[env as usize].eval_environment(store, b.d);
                        let pdf = if b.delta {
                            0.0
                        } else {
                            scene.pdf_emitter_direction(env, si.p.val(), d, d, d)
                        };
                        (le, pdf)
                    }
                    None => continue,
                },
            };
            let w = if b.delta {
                1.0 / nb
            } else {
                mis_weight(nb * bs.pdf, ne * em_pdf) / nb
            };
            result += b.weight.mul_elem(le) * R::cst(w);
        }
        (result, true)
    }
}
