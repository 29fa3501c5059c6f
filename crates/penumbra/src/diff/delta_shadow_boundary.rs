//! The boundary term of the shadows of point, spot, projector and directional
//! emitters, in forward and reverse mode (budget `sppi`, with the term of
//! [`super::shadow_boundary`]).
//!
//! # What is estimated
//!
//! A delta emitter lights a surface point x along one direction, so the
//! radiance the camera sees jumps where x crosses the shadow of an edge:
//! the curve on the receiver where the ray from the light grazes the edge,
//! seen by the camera as a curve C on the film. Unlike the shadows of area
//! lights (continuous over the film, with jumps on the sphere of
//! directions at x), this is a discontinuity of the film integrand, and
//! its term has the form of the primary one (`primary_boundary.rs`):
//!
//! `dI_p/dθ ∋ 1/W_p ∫_C k_p(x) (L(x − εn) − L(x + εn)) ⟨dx/dθ, n⟩ dℓ(x)`
//!
//! with x(θ) the film point of the shadow of a point m at a fixed
//! fraction of the edge: the ray from the light (position or direction in
//! R) through m(θ) meets the receiver (re-intersected in R, the point
//! sliding along that ray), which is projected onto the film by the
//! sensor's projection in R. Film samples are the interior pass's
//! constants, so this motion is the relative one.
//!
//! # How
//!
//! A point m on a candidate edge (uniform by length, the edges of
//! [`super::shadow_boundary`]) and a delta emitter (uniformly); the ray
//! from the light through m finds the receiver x, which the camera must
//! see. The film curve's tangent `d x / dt` along the edge comes from the
//! same map in dual numbers seeded along the edge, so that the sample's
//! weight is `|dx/dt| · total length / edge length · lights` (the density
//! of the curve's arc length) and n is its normal. The jump is traced on
//! both sides through the camera with the same random numbers, and the
//! sample splatted at x. Reverse mode backpropagates each sample's weight
//! through `⟨x(θ), n⟩` on a small tape, as the shadow term does.

use super::shadow_boundary::{end_points, CandidateEdges};
use super::splat::{add_splat_gradients, add_splats, BoundarySamples, FilmSplatter};
use crate::ad::{Dual, ScalarReal, Var};
use crate::emitter::DeltaOrigin;
use crate::error::Result;
use crate::geometry::edges::{EdgeTable, Eye};
use crate::geometry::{DiffRay, Hit, Ray};
use crate::integrator::{RenderOptions, Rendered};
use crate::math::{V2, V3};
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// Whether this pass estimates the term: a pinhole or orthographic camera,
/// a point, spot, projector or directional emitter, a lit first vertex and a budget
/// that is not zero (as [`super::shadow_boundary::applies`]).
pub(crate) fn applies(scene: &Scene, opts: &RenderOptions) -> Result<bool> {
    let primal = scene.params.primal();
    Ok(super::shadow_boundary::first_vertex_is_lit(scene, opts)?
        && scene
            .emitters
            .iter()
            .any(|e| e.delta_origin::<f32>(&primal).is_some()))
}

/// One sample on a shadow's film curve.
struct Sample {
    /// Film position (crop-window pixels) and unit normal of the curve.
    x: Vec2,
    n: Vec2,
    /// The emitter, the edge (shape, index) and m's fraction along it.
    light: u32,
    shape: u32,
    edge: u32,
    t: f32,
    /// Where the ray from m away from the light meets the receiver.
    hit: Hit,
    /// The jump times the sample's weight (module documentation).
    value: Vec3,
}

struct Context<'a> {
    scene: &'a Scene,
    film: FilmSplatter<'a>,
    edges: CandidateEdges,
    lights: Vec<u32>,
    /// Offset (pixels) from the curve to either side.
    eps: f32,
    seed: u64,
}

impl<'a> Context<'a> {
    fn new(scene: &'a Scene, opts: &RenderOptions) -> Result<Option<Self>> {
        let sensor = scene.sensor(opts.sensor)?;
        let primal = scene.params.primal();
        let lights: Vec<u32> = (0..scene.emitters.len() as u32)
            .filter(|&i| {
                scene.emitters[i as usize]
                    .delta_origin::<f32>(&primal)
                    .is_some()
            })
            .collect();
        let Some(edges) = CandidateEdges::new(scene) else {
            return Ok(None);
        };
        if lights.is_empty() || sensor.projector::<f32>(&primal).is_none() {
            return Ok(None);
        }
        let spp = opts.spp.unwrap_or_else(|| sensor.sampler.sample_count());
        let film = FilmSplatter::new(sensor, opts.sppi.unwrap_or(spp), opts)?;
        Ok(Some(Context {
            scene,
            // larger than the primary term's: the integrator's shadow rays
            // leave from an offset origin, which moves the shadow edge it
            // renders by about 1e-3 pixel in these tests
            eps: 2e-2 * (film.scale.max_element() / 1000.0).max(1.0),
            film,
            edges,
            lights,
            seed: opts.seed,
        }))
    }

    /// The film position (crop-window pixels) of the shadow of `m` cast by
    /// `origin` on the surface of `hit`, in `R`.
    fn shadow_on_film<R: ScalarReal>(
        &self,
        store: &ParamView,
        m: V3<R>,
        origin: DeltaOrigin<R>,
        hit: &Hit,
    ) -> Option<V2<R>> {
        let d = match origin {
            DeltaOrigin::Point(p) => (m - p).normalize(),
            DeltaOrigin::Direction(d) => V3::cst(d),
        };
        let ray = DiffRay {
            o: m,
            d,
            tmin: 0.0,
            tmax: f32::INFINITY,
        };
        let x = self.scene.surface_interaction::<R>(store, &ray, hit).p;
        let proj = self.film.sensor.projector::<R>(store)?;
        let f = proj.film(proj.to_local(x));
        let off = self.film.crop_off;
        Some(V2::new(
            f.x * self.film.scale.x - off.x,
            f.y * self.film.scale.y - off.y,
        ))
    }

    /// `⟨x(θ), n⟩` of sample `s` in `R`: its derivative is the normal
    /// velocity of the film curve.
    fn normal_position<R: ScalarReal>(&self, store: &ParamView, s: &Sample) -> Option<R> {
        let scene = self.scene;
        let mesh = scene.shapes[s.shape as usize].as_mesh()?;
        let (p0, p1) = end_points::<R>(mesh, store, s.edge);
        let m = p0 + (p1 - p0) * R::cst(s.t);
        let origin = scene.emitters[s.light as usize].delta_origin::<R>(store)?;
        let f = self.shadow_on_film::<R>(store, m, origin, &s.hit)?;
        Some(f.x * s.n.x + f.y * s.n.y)
    }
}

impl BoundarySamples for Context<'_> {
    type Sample = Sample;
    const TERM: &'static str = "delta-light shadow boundary term";
    /// Far from the keys of film pixels and of the other terms' samples.
    const STREAM_KEY: u64 = 0xde17_0000_0000_0000;

    fn film(&self) -> &FilmSplatter<'_> {
        &self.film
    }
    fn seed(&self) -> u64 {
        self.seed
    }
    fn position(s: &Sample) -> Vec2 {
        s.x
    }
    fn is_finite(s: &Sample) -> bool {
        s.value.is_finite()
    }

    fn sample(&self, u: f32, rng: &mut SampleStream) -> Option<Sample> {
        let scene = self.scene;
        let primal = scene.params.primal();
        let (shape, edge, t, len) = self.edges.sample(u);
        let mesh = scene.shapes[shape as usize].as_mesh()?;
        let pick = ((rng.next_1d() * self.lights.len() as f32) as usize).min(self.lights.len() - 1);
        let light = self.lights[pick];
        let origin = scene.emitters[light as usize].delta_origin::<f32>(&primal)?;
        let (p0, p1) = end_points::<f32>(mesh, &primal, edge);
        let (p0, p1) = (p0.val(), p1.val());
        let m = p0 + (p1 - p0) * t;
        let (d, eye) = match origin {
            DeltaOrigin::Point(p) => ((m - p.val()).normalize(), Eye::Point(p.val())),
            DeltaOrigin::Direction(d) => (d, Eye::Direction(d)),
        };
        let e = &mesh.edges(&primal).edges[edge as usize];
        // only an edge the light grazes casts a shadow edge (a sharp edge
        // seen from the light between two faces is shadowed on both sides)
        if !EdgeTable::is_silhouette(e, &mesh.faces, primal.data(mesh.positions), eye) {
            return None;
        }
        let scale = 1.0 + m.abs().max_element();
        let ray = Ray {
            o: m,
            d,
            tmin: 1e-4 * scale,
            tmax: f32::INFINITY,
        };
        let hit = scene.intersect(&ray)?;
        // a face of the edge itself (grazed at the terminator of a flat
        // mesh) is no receiver: that jump is the primary term's
        if hit.shape == shape && (hit.prim == e.face || hit.prim == e.other_face) {
            return None;
        }
        let xp = ray.at(hit.t);
        // the curve and its tangent along the edge: the same map in dual
        // numbers whose tangent is d m / d t
        let seed_along = |v: Vec3, dv: Vec3| {
            V3::new(
                Dual::new(v.x, dv.x),
                Dual::new(v.y, dv.y),
                Dual::new(v.z, dv.z),
            )
        };
        let origin_dual = match origin {
            DeltaOrigin::Point(p) => DeltaOrigin::Point(V3::cst(p.val())),
            DeltaOrigin::Direction(d) => DeltaOrigin::Direction(d),
        };
        let f = self.shadow_on_film::<Dual>(&primal, seed_along(m, p1 - p0), origin_dual, &hit)?;
        let x = Vec2::new(f.x.v, f.y.v);
        let tangent = Vec2::new(f.x.d, f.y.d);
        let speed = tangent.length();
        if !self.film.region.contains(x) || !(speed > 0.0) {
            return None;
        }
        // the camera must see the receiver point
        let cam_ray = self.film.camera_sample(x).ray::<f32>(&primal).val();
        let seen = scene.intersect(&cam_ray)?;
        if seen.shape != hit.shape || (cam_ray.at(seen.t) - xp).length() > 1e-3 * seen.t {
            return None;
        }
        let n = Vec2::new(-tangent.y, tangent.x) / speed;
        let radiance = |side: f32| {
            let cs = self.film.camera_sample(x + n * (side * self.eps));
            scene
                .integrator
                .radiance::<f32>(scene, &primal, &cs, &mut rng.clone())
                .map_or(Vec3::ZERO, |l| l.val())
        };
        let jump = radiance(-1.0) - radiance(1.0);
        if jump == Vec3::ZERO {
            return None;
        }
        let weight = speed * self.edges.total / len * self.lights.len() as f32;
        Some(Sample {
            x,
            n,
            light,
            shape,
            edge,
            t,
            hit,
            value: jump * weight,
        })
    }
}

/// Adds the term along the tangents of `store` to the derivative image.
pub(crate) fn add_delta_shadow_boundary(
    scene: &Scene,
    store: &ParamView,
    opts: &RenderOptions,
    image: &mut Rendered,
) -> Result<()> {
    let Some(ctx) = Context::new(scene, opts)? else {
        return Ok(());
    };
    add_splats(&ctx, opts, image, |s| {
        let v = ctx.normal_position::<Dual>(store, s)?.d;
        (v != 0.0 && v.is_finite()).then(|| s.value * v)
    })
}

/// Adds the term of the gradient of a loss with adjoint image `d_image` to
/// `sums`; returns the number of non-finite samples left out.
pub(crate) fn add_delta_shadow_boundary_gradients(
    scene: &Scene,
    store: &ParamView,
    d_image: &[f32],
    opts: &RenderOptions,
    sums: &mut [Vec<f64>],
) -> Result<usize> {
    let Some(ctx) = Context::new(scene, opts)? else {
        return Ok(0);
    };
    add_splat_gradients(&ctx, opts, d_image, sums, |s, a| {
        let w: f64 = (0..3).map(|c| a[c] * s.value[c] as f64).sum();
        if w == 0.0 {
            return None;
        }
        Some(vec![(ctx.normal_position::<Var>(store, s)?, w as f32)])
    })
}
