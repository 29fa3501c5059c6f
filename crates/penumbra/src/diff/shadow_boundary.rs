//! The boundary term of the visibility seen from the first vertex of each
//! camera path: the edges of shadows (and, with path tracing beyond depth
//! 2, every edge that hides or reveals what lights that vertex), in
//! forward and reverse mode. Mitsuba's projective integrators call its
//! budget `sppi`.
//!
//! # What is estimated
//!
//! The first vertex x(film) receives `H(x) = ∫_S² g(x, ω) dω` with
//! `g = f(x, ω_cam, ω) |cos| L_i(x, ω)`. As x moves over a surface H is
//! continuous (an area light's shadow has a penumbra), but `L_i` jumps
//! across the directions of every edge of an occluder seen from x: a curve
//! C(x) on the sphere of directions. Reynolds' theorem on the sphere gives
//! the term the interior pass misses (Li et al. 2018, "Differentiable Monte
//! Carlo Ray Tracing through Edge Sampling", §5; in path space, Zhang et
//! al. 2020, "Path-Space Differentiable Rendering", whose boundary-segment
//! sampling this follows):
//!
//! `dH/dθ ∋ ∫_C [g(ω⁻) V⁻ − g(ω⁺) V⁺] dℓ(ω)`
//!
//! with n the unit normal of C at ω (in the tangent plane of the sphere),
//! ω± = ω ± ε n the two sides, and V± = ⟨v_C − v±, n⟩ the velocity of the
//! curve RELATIVE to the parameterisation the interior pass uses on that
//! side (`crate::integrator::scatter`): the point seen there moves with its
//! surface (emitter samples and points reached by a smooth bounce move
//! with their shapes), and a direction to the environment is a constant.
//! For an edge point m and a surface point y seen from x,
//! `v_C = (I − ωωᵀ)(ṁ − ẋ)/|m − x|`, `v± = (I − ωωᵀ)(ẏ± − ẋ)/|y± − x|`,
//! and x itself slides along the fixed camera ray. The side that sees the
//! occluder just beside a mesh edge moves with the edge (V = 0 there): the
//! term is then the light revealed or hidden, moving relative to the light.
//!
//! # How: boundary segments
//!
//! Samples are drawn in path space, not per pixel: a point m on an edge
//! (uniform by length over the candidate edges: every non-inert edge of
//! every mesh that is not itself an emitter), a direction d at m towards
//! an emitter (the scene's emitter sampling from m, density p(d) in solid
//! angle) or, when the integrator traces indirect light, with probability
//! ½ a uniform direction; the ray from m away from d finds x, which must be
//! what the camera sees at its film position. Changing variables from
//! (film position, point of C(x)) to (m, d) gives
//!
//! `d film · dℓ(ω) = J(x) |x − m| |ω × ê| / |cos θ_x| · ds dω(d)`
//!
//! with J(x) = d film / dA(x) (pixels per unit area, from the sensor's
//! projection), ê the unit edge direction and s the length along it; the
//! |cos θ_x| cancels the one in g. The sample's value
//! `J |x − m| |ω × ê| · total length / p(d) · [ĝ⁻ V⁻ − ĝ⁺ V⁺]`, with
//! `ĝ = g / |cos θ_x|`, is splatted at x's film position like a film
//! sample ([`super::splat`]). The two sides are traced from x through
//! `m ± ε n` with the same random numbers. Their densities are combined
//! per side by the balance heuristic over the strategies that could have
//! produced what that side sees (an emitter strategy counts only the
//! sides that reach its emitter): unbiased, and no direction is counted
//! twice when an area light is seen against an environment.
//!
//! The velocities are evaluated in the number type of the pass: forward
//! mode takes their tangents, reverse mode backpropagates each sample's
//! weight through them on a tape of a few dozen nodes, so that both modes
//! take the same samples and agree up to rounding.
//!
//! Not handled here: shadows of point, spot, projector and directional emitters (their
//! shadow edges are curves on the film, not on the sphere of directions),
//! visibility at the second and later vertices of a path, the silhouettes
//! of analytic shapes (spheres, disks, cylinders), an emitter's own outline against
//! what lies behind it, thin-lens cameras. Callers warn about them
//! ([`super::warn_missing_boundary_terms`]).

use super::splat::{add_splat_gradients, add_splats, BoundarySamples, FilmSplatter};
use crate::ad::{Dual, ScalarReal, Var};
use crate::bsdf::BsdfContextT;
use crate::emitter::EmitterT;
use crate::error::Result;
use crate::geometry::edges::{EdgeKind, EdgeTable, Eye};
use crate::geometry::{DiffRay, Hit, Mesh, Ray, Shape};
use crate::integrator::{Integrator, RenderOptions, Rendered};
use crate::math::warp::square_to_uniform_sphere;
use crate::math::{DiscreteDistribution, V3};
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::Scene;
use crate::sensor::projection::Projector;
use glam::{Vec2, Vec3};

/// Angle (radians) between the two sides traced and the edge.
const SIDE_ANGLE: f32 = 1e-4;

/// Whether this pass estimates the term for the render `opts` describes:
/// a pinhole or orthographic camera, a radiance integrator whose first
/// vertex is lit, an emitter that is not a point, and a budget that is not
/// zero.
pub(crate) fn applies(scene: &Scene, opts: &RenderOptions) -> Result<bool> {
    Ok(first_vertex_is_lit(scene, opts)? && scene.emitters.iter().any(|e| !e.is_delta()))
}

/// Whether the boundary terms of the visibility seen from the first vertex
/// can apply to the render `opts` describes: a pinhole or orthographic
/// camera, a radiance integrator whose first vertex is lit, and a budget
/// `sppi` that is not zero.
pub(super) fn first_vertex_is_lit(scene: &Scene, opts: &RenderOptions) -> Result<bool> {
    let sensor = scene.sensor(opts.sensor)?;
    let lit = match &scene.integrator {
        Integrator::Path(p) => p.max_depth >= 2,
        Integrator::Direct(_) => true,
        // media refuse geometry derivatives
        Integrator::VolPath(_) | Integrator::Aov(_) | Integrator::Moment(_) => false,
    };
    Ok(opts.sppi != Some(0) && lit && sensor.projector::<f32>(&scene.params.primal()).is_some())
}

/// The edges that may cast shadows: every non-inert edge of every mesh
/// that is not itself an emitter, picked by length.
pub(super) struct CandidateEdges {
    /// (shape, edge index) and their lengths' distribution.
    edges: Vec<(u32, u32)>,
    dist: DiscreteDistribution,
    /// Total length: the inverse of the density per unit length.
    pub total: f32,
}

impl CandidateEdges {
    pub fn new(scene: &Scene) -> Option<CandidateEdges> {
        let primal = scene.params.primal();
        let mut edges = Vec::new();
        let mut lengths = Vec::new();
        for (s, shape) in scene.shapes.iter().enumerate() {
            let Shape::Mesh(mesh) = shape else { continue };
            // emitters cast no shadow edge here; a shape group's shapes
            // are in the group's space, and the edges of instances are
            // not sampled (named by `diff::warn_missing_boundary_terms`)
            if scene.shape_emitter(s as u32).is_some() || scene.in_group(s as u32) {
                continue;
            }
            for (i, e) in mesh.edges(&primal).edges.iter().enumerate() {
                if e.kind == EdgeKind::Inert {
                    continue;
                }
                let (p0, p1) = end_points::<f32>(mesh, &primal, i as u32);
                let len = (p1.val() - p0.val()).length();
                if len > 0.0 && len.is_finite() {
                    edges.push((s as u32, i as u32));
                    lengths.push(len);
                }
            }
        }
        let dist = DiscreteDistribution::new(&lengths)?;
        Some(CandidateEdges {
            edges,
            total: dist.sum() as f32,
            dist,
        })
    }

    /// The edge at `u` ∈ [0, 1) of the total length: (shape, edge, the
    /// fraction along it, its length).
    pub fn sample(&self, u: f32) -> (u32, u32, f32, f32) {
        let (i, pmf, t) = self.dist.sample_reuse(u);
        let (shape, edge) = self.edges[i];
        (shape, edge, t, pmf * self.total)
    }
}

/// One sample that found a first vertex behind an edge: what both modes
/// need to evaluate its motion, and its value without the motion.
struct Sample {
    /// Film position of x (crop-window pixels) and the camera's hit there.
    x: Vec2,
    hit: Hit,
    /// The edge (shape, index in its table) and the fraction of the way
    /// from its first to its second end point where m lies.
    shape: u32,
    edge: u32,
    t: f32,
    /// Unit normal of the edge's curve on the sphere of directions at x.
    n: Vec3,
    /// What each side (−n, +n) sees: a surface point (hit, primal point)
    /// or the environment.
    sides: [Option<(Hit, Vec3)>; 2],
    /// `ĝ± · J |x − m| |ω × ê| · total length / p±(d)` per side: the
    /// sample is `value[0] V⁻ − value[1] V⁺`.
    value: [Vec3; 2],
}

/// The samples of one derivative call.
struct Context<'a> {
    scene: &'a Scene,
    film: FilmSplatter<'a>,
    /// The camera's projection, with constant parameters.
    proj: Projector<f32>,
    proj_dual: Projector<Dual>,
    edges: CandidateEdges,
    /// Probability of a uniform direction at m instead of an emitter's.
    uniform: f32,
    seed: u64,
}

impl<'a> Context<'a> {
    fn new(scene: &'a Scene, opts: &RenderOptions) -> Result<Option<Self>> {
        let sensor = scene.sensor(opts.sensor)?;
        let primal = scene.params.primal();
        let (Some(proj), Some(proj_dual)) = (
            sensor.projector::<f32>(&primal),
            sensor.projector::<Dual>(&primal),
        ) else {
            return Ok(None);
        };
        let spp = opts.spp.unwrap_or_else(|| sensor.sampler.sample_count());
        let film = FilmSplatter::new(sensor, opts.sppi.unwrap_or(spp), opts)?;
        let Some(edges) = CandidateEdges::new(scene) else {
            return Ok(None);
        };
        Ok(Some(Context {
            scene,
            film,
            proj,
            proj_dual,
            edges,
            uniform: if scene.integrator.traces_indirect_light() {
                0.5
            } else {
                0.0
            },
            seed: opts.seed,
        }))
    }

    /// The density by which the strategies that can produce what `side`
    /// (the ray `ray` from x) reaches produce direction `d` at m, by the
    /// balance heuristic, or `None` if the strategy `picked` (an emitter,
    /// `None` for the uniform one) cannot have produced it.
    fn density(
        &self,
        m: Vec3,
        d: Vec3,
        picked: Option<u32>,
        side: Option<&Hit>,
        ray: &Ray,
    ) -> Option<f32> {
        let scene = self.scene;
        let (seen, emitter_pdf) = match side {
            Some(h) => match scene.shape_emitter(h.shape) {
                Some(em) => {
                    let p = ray.at(h.t);
                    let si = scene.surface_interaction::<f32>(
                        &scene.params.primal(),
                        &DiffRay::cst(ray),
                        h,
                    );
                    (
                        Some(em),
                        scene.pdf_emitter_direction(em, m, d, p, si.n.val()),
                    )
                }
                None => (None, 0.0),
            },
            None => match scene.environment {
                Some(env) => (Some(env), scene.pdf_emitter_direction(env, m, d, d, d)),
                None => (None, 0.0),
            },
        };
        let p = self.uniform / (4.0 * std::f32::consts::PI) + (1.0 - self.uniform) * emitter_pdf;
        let produced = picked.is_none() || picked == seen;
        (produced && p > 0.0).then_some(p)
    }

    /// `V⁻`, `V⁺` of `s` in `R` (module documentation): normal components
    /// of the relative velocities, whose values are (near) zero and whose
    /// derivatives are the velocities.
    fn velocities<R: ScalarReal>(&self, store: &ParamView, s: &Sample) -> [R; 2] {
        let scene = self.scene;
        let cs = self.film.camera_sample(s.x);
        let ray = cs.ray::<R>(store);
        let x = scene.surface_interaction::<R>(store, &ray, &s.hit).p;
        let mesh = scene.shapes[s.shape as usize]
            .as_mesh()
            .expect("candidate edges belong to meshes");
        let (p0, p1) = end_points::<R>(mesh, store, s.edge);
        let m = p0 + (p1 - p0) * R::cst(s.t);
        let n = V3::cst(s.n);
        let normal = |p: V3<R>| {
            let to = p - x;
            to.dot(n) / to.val().length()
        };
        let v_edge = normal(m);
        s.sides.map(|side| match side {
            Some((hit, p)) => v_edge - normal(scene.point_at::<R>(store, &hit, p).p),
            None => v_edge,
        })
    }
}

impl BoundarySamples for Context<'_> {
    type Sample = Sample;
    const TERM: &'static str = "shadow boundary term";
    /// Far from the keys of film pixels and of the other terms' samples.
    const STREAM_KEY: u64 = 0x5d0e_0000_0000_0000;

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
        s.value.iter().all(|v| v.is_finite())
    }

    /// One boundary segment (module documentation), if it reaches a first
    /// vertex the camera sees and its value is not zero.
    fn sample(&self, u: f32, rng: &mut SampleStream) -> Option<Sample> {
        let scene = self.scene;
        let primal = scene.params.primal();
        let (shape, edge, t, _) = self.edges.sample(u);
        let mesh = scene.shapes[shape as usize].as_mesh()?;
        let (p0, p1) = end_points::<f32>(mesh, &primal, edge);
        let (p0, p1) = (p0.val(), p1.val());
        let m = p0 + (p1 - p0) * t;
        let e_unit = (p1 - p0).normalize();

        // a direction at m towards the light
        let u_dir = rng.next_2d();
        let u_pick = rng.next_1d();
        let (d, picked) = if u_pick < self.uniform {
            (square_to_uniform_sphere(u_dir), None)
        } else {
            let dist = scene.emitter_distribution.as_ref()?;
            let (j, _, ux) = dist.sample_reuse(u_dir.x);
            let em = &scene.emitters[j];
            if em.is_delta() {
                return None;
            }
            let es = em.sample_direction::<f32>(
                &primal,
                &scene.shapes,
                V3::cst(m),
                Vec2::new(ux, u_dir.y),
            )?;
            (es.ds.d, Some(j as u32))
        };
        // a smooth edge matters only where it is a silhouette from the light
        let faces = &mesh.faces;
        let e = &mesh.edges(&primal).edges[edge as usize];
        if !EdgeTable::is_silhouette(e, faces, primal.data(mesh.positions), Eye::Direction(d)) {
            return None;
        }

        // the first vertex behind the edge, seen from the camera
        let scale = 1.0 + m.abs().max_element();
        let back = Ray {
            o: m,
            d: -d,
            tmin: 1e-4 * scale,
            tmax: f32::INFINITY,
        };
        let hx = scene.intersect(&back)?;
        // a face of the edge itself (grazed) is no receiver
        if hx.shape == shape && (hx.prim == e.face || hx.prim == e.other_face) {
            return None;
        }
        let xp = back.at(hx.t);
        let q = self.proj.to_local(V3::cst(xp));
        if !(q.z > self.proj.near) {
            return None;
        }
        let x = self.film.to_pixels(self.proj.film(q).val());
        if !self.film.region.contains(x) {
            return None;
        }
        let cs = self.film.camera_sample(x);
        let cam_ray = cs.ray::<f32>(&primal).val();
        let hit = scene.intersect(&cam_ray)?;
        if hit.shape != hx.shape || (cam_ray.at(hit.t) - xp).length() > 1e-3 * hit.t {
            return None;
        }
        let si = scene.surface_interaction::<f32>(&primal, &DiffRay::cst(&cam_ray), &hit);
        let x3 = si.p.val();
        let to_m = m - x3;
        let r_m = to_m.length();
        let w = to_m / r_m;
        let cross = w.cross(e_unit);
        let sin_e = cross.length();
        let cos_x = si.n.val().dot(w).abs();
        if !(sin_e > 1e-6 && cos_x > 1e-6) {
            return None;
        }
        let n = cross / sin_e;
        let jac = film_jacobian(&self.proj_dual, x3, si.n.val(), self.film.scale);
        let common = jac * r_m * sin_e * self.edges.total / cos_x;

        let bsdf = scene.shape_bsdf(hit.shape);
        let ctx = bsdf.context(&primal, &si);
        let mut sides = [None; 2];
        let mut value = [Vec3::ZERO; 2];
        for (k, sign) in [-1.0f32, 1.0].into_iter().enumerate() {
            // aimed from the offset origin, so that the side is the one
            // meant whatever the offset (it is of the order of SIDE_ANGLE)
            let target = m + n * (sign * SIDE_ANGLE * r_m);
            let o = si.point().offset_origin(target - x3);
            let dir = (target - o).normalize();
            let ray = Ray::new(o, dir);
            let side_hit = scene.intersect(&ray);
            let density = self.density(m, d, picked, side_hit.as_ref(), &ray);
            sides[k] = side_hit.map(|h| (h, ray.at(h.t)));
            let Some(p) = density else { continue };
            let f = ctx.eval(si.to_local(V3::cst(dir))).val();
            if f == Vec3::ZERO {
                continue;
            }
            let l = scene
                .integrator
                .incident_radiance(scene, &ray, &mut rng.clone());
            value[k] = f * l * (common / p);
        }
        if value == [Vec3::ZERO; 2] {
            return None;
        }
        Some(Sample {
            x,
            hit,
            shape,
            edge,
            t,
            n,
            sides,
            value,
        })
    }
}

/// The world end points of edge `edge` of `mesh`, in `R`.
pub(super) fn end_points<R: ScalarReal>(
    mesh: &Mesh,
    store: &ParamView,
    edge: u32,
) -> (V3<R>, V3<R>) {
    let e = &mesh.edges(store).edges[edge as usize];
    let (_, tri) = mesh.triangle_r::<R>(store, e.face);
    let k = e.corner as usize;
    (tri[k], tri[(k + 1) % 3])
}

/// Film area (pixels²) per unit surface area at the point `p` with normal
/// `n`: the determinant of the projection's derivative along two tangents.
fn film_jacobian(proj: &Projector<Dual>, p: Vec3, n: Vec3, scale: Vec2) -> f32 {
    let (t1, t2) = n.any_orthonormal_pair();
    let column = |t: Vec3| {
        let q = proj.to_local(V3::new(
            Dual::new(p.x, t.x),
            Dual::new(p.y, t.y),
            Dual::new(p.z, t.z),
        ));
        let f = proj.film(q);
        Vec2::new(f.x.d, f.y.d) * scale
    };
    let (a, b) = (column(t1), column(t2));
    (a.x * b.y - a.y * b.x).abs()
}

/// Adds the term along the tangents of `store` to the derivative image
/// `image` of the render `opts` describes.
pub(crate) fn add_shadow_boundary(
    scene: &Scene,
    store: &ParamView,
    opts: &RenderOptions,
    image: &mut Rendered,
) -> Result<()> {
    let Some(ctx) = Context::new(scene, opts)? else {
        return Ok(());
    };
    add_splats(&ctx, opts, image, |s| {
        let [vm, vp] = ctx.velocities::<Dual>(store, s);
        let v = s.value[0] * vm.d - s.value[1] * vp.d;
        (v != Vec3::ZERO).then_some(v)
    })
}

/// Adds the term of the gradient of a loss, given its adjoint image
/// `d_image` (crop window × 3), to `sums` (per parameter, per element, for
/// the parameters `store` records); returns the number of non-finite
/// samples left out. Each sample's weight `Σ_p δI_p k_p(x)/(W_p N) ·
/// value±` is backpropagated through its velocities.
pub(crate) fn add_shadow_boundary_gradients(
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
        let weight = |v: Vec3| (0..3).map(|c| a[c] * v[c] as f64).sum::<f64>();
        let (wm, wp) = (weight(s.value[0]), weight(s.value[1]));
        if wm == 0.0 && wp == 0.0 {
            return None;
        }
        let [vm, vp] = ctx.velocities::<Var>(store, s);
        Some(vec![(vm, wm as f32), (vp, -wp as f32)])
    })
}
