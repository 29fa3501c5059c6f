//! The boundary term of primary visibility in forward and reverse mode:
//! edge sampling on the film (Li et al. 2018, "Differentiable Monte Carlo
//! Ray Tracing through Edge Sampling"; the sample budget and the
//! projected-length density follow the primary term of Zhang et al. 2023,
//! "Projective Sampling for Differentiable Rendering of Geometry", and
//! Mitsuba's `direct_projective`, whose `sppp` it is named after).
//!
//! # What is estimated
//!
//! Pixel p of the film is `I_p = ∫ k_p(x) L(x) dx / W_p` over the sampled
//! film region, with `k_p(x)` the reconstruction filter centred on p and
//! `W_p = ∫ k_p(x) dx` the normalisation the film applies (a pixel is the
//! weighted mean of its samples, and samples are uniform over the film).
//! `L(x)` jumps across the images of mesh edges (boundary, sharp and
//! silhouette edges, see [`crate::geometry::edges`]). Along a tangent of the
//! parameters θ, Reynolds' transport theorem gives, for each region A of
//! the film where L is smooth, `d/dθ ∫_A f = ∫_A ∂f/∂θ + ∮_∂A f v·n_A`,
//! with `n_A` the unit normal of ∂A pointing out of A and `v` the velocity
//! of the boundary. An edge separates two regions A and B with
//! `n_B = −n_A`, so it contributes `∫_edge (f_A − f_B) v·n_A dℓ`: the jump
//! measured FROM the side n points to (B), TO the side it points away
//! from (A), times the normal velocity. With n any unit normal of the
//! projected edge:
//!
//! `dI_p/dθ ∋ 1/W_p ∫_edges k_p(x) (L(x − εn) − L(x + εn)) ⟨dx/dθ, n⟩ dℓ(x)`.
//!
//! (Check: a bright triangle moving right (v = +x), its right edge with
//! n = +x: inside minus outside is positive, and the pixels right of the
//! edge do brighten.) The interior term (`forward.rs`) holds the film
//! samples fixed; this term is what it misses. Both are in film pixel
//! units, so `dℓ` and the velocity are in pixels.
//!
//! # How
//!
//! Per render, every candidate edge (boundary, sharp, non-manifold, and
//! smooth edges that are silhouettes from the camera or folds it looks
//! into, where one face may shadow the other) whose image moves
//! with the parameters is projected onto the film in the number type of
//! the pass (vertices read through the store, so the positions and
//! `to_world` and the sensor's pose and field of view all move it; in
//! `Dual`, an edge moves if its end points have a non-zero tangent, in
//! `Var` if they depend on a recorded parameter), clipped to the near plane
//! in camera space and to the sampled film region in the film. Edges are
//! picked with probability proportional to their clipped projected
//! length, then a point uniformly along it: density `1 / total length` on
//! the union of the projected edges. At the point x:
//! - the edge must be seen: the camera ray through x must not hit
//!   anything nearer than the edge;
//! - the jump is the primal radiance of the integrator at `x ∓ εn`, both
//!   sides with the same random numbers (their difference then has no
//!   noise where the two paths agree; on smooth-shaded meshes, beyond a
//!   thin shading-horizon sliver, see below);
//! - the normal velocity is `⟨dx/dθ, n⟩` with `x(θ)` the point at a fixed
//!   fraction between the moving projected end points (any point of the
//!   projected line gives the same normal component).
//!
//! The contribution `k_p(x) ΔL v_n · total length / W_p`, averaged over
//! the samples, is added to every pixel p the filter reaches from x.
//! `sppp × pixels` samples are taken (`RenderOptions::sppp`, default: the
//! samples per pixel of the pass). Samples are processed in chunks in
//! parallel and splatted in chunk order, so the image is identical for a
//! seed whatever the number of threads.
//!
//! Reverse mode ([`add_primary_boundary_gradients`]) takes the same
//! samples (the same edges for a generic tangent over the same keys, the
//! same positions for a seed) and contracts them with the adjoint image
//! instead of splatting them, so that both modes agree up to rounding.
//!
//! Not handled here: thin-lens cameras (the edge's image is blurred by the
//! aperture), the silhouettes of analytic shapes (spheres, disks), edges
//! cut by the near plane (the cut itself is a moving edge of the image),
//! and coincident edges of distinct meshes (each is counted). Callers warn
//! about the first two ([`super::warn_missing_boundary_terms`]). Two jumps
//! of smooth-shaded meshes off the edge table are handled only in part:
//! the curve where the view direction crosses the horizon of the
//! interpolated shading normal (BSDFs and area emitters are zero below it;
//! near the silhouettes of a coarse mesh it lines them inside the faces) is
//! merged into the silhouette when it is thinner than a pixel
//! ([`Context::beyond_horizon`]) and missing otherwise; a convex smooth
//! edge between a face that sees a light and a neighbour that shadows
//! itself from it (the terminator of a coarse smooth mesh, seen directly)
//! is not sampled.

use super::splat::{FilmSplatter, Region, CHUNK};
use crate::ad::reverse::{backward, clear_tape};
use crate::ad::{Dual, Real, Var};
use crate::error::Result;
use crate::geometry::edges::{Edge, EdgeKind, EdgeTable, Eye};
use crate::geometry::{DiffRay, Mesh, Shape};
use crate::integrator::{RenderOptions, Rendered};
use crate::math::{DiscreteDistribution, V2, V3};
use crate::params::ParamView;
use crate::scene::Scene;
use crate::sensor::Sensor;
use glam::{Vec2, Vec3};

/// Sample-stream keys of edge samples: far from the keys of film pixels.
const STREAM_KEY: u64 = 0xed6e_0000_0000_0000;

/// Whether this pass estimates the primary boundary term of the render
/// `opts` describes: the sensor is a pinhole or orthographic camera and
/// the budget is not zero.
pub(crate) fn applies(scene: &Scene, opts: &RenderOptions) -> Result<bool> {
    let sensor = scene.sensor(opts.sensor)?;
    Ok(opts.sppp != Some(0) && sensor.projector::<f32>(&scene.params.primal()).is_some())
}

/// The number type of a boundary pass: how it tells that the image of an
/// edge moves with the parameters, and what a segment keeps of that
/// motion. Forward mode (`Dual`) keeps the tangents of the end points;
/// reverse mode (`Var`) keeps nothing, since a tape holds one edge at a
/// time: it records the edge again to backpropagate its samples' weight.
trait EdgeMotion: Real {
    type Motion: Sync;
    /// Runs `project`, which computes the film end points of one edge in
    /// `Self` and something primal, and returns the end points' values and
    /// their motion (`scale` turns film units into pixels) with the primal
    /// part, or `None` if the edge is not projected or does not move.
    fn motion<T>(
        project: impl FnOnce() -> Option<(V2<Self>, V2<Self>, T)>,
        scale: Vec2,
    ) -> Option<(Vec2, Vec2, Self::Motion, T)>;
}

impl EdgeMotion for Dual {
    /// The derivatives of the two end points along the tangent (pixels).
    type Motion = (Vec2, Vec2);

    fn motion<T>(
        project: impl FnOnce() -> Option<(V2<Dual>, V2<Dual>, T)>,
        scale: Vec2,
    ) -> Option<(Vec2, Vec2, (Vec2, Vec2), T)> {
        let (f0, f1, t) = project()?;
        let d = |f: V2<Dual>| Vec2::new(f.x.d, f.y.d) * scale;
        let (da, db) = (d(f0), d(f1));
        let moves = (da != Vec2::ZERO || db != Vec2::ZERO) && da.is_finite() && db.is_finite();
        moves.then(|| (f0.val(), f1.val(), (da, db), t))
    }
}

impl EdgeMotion for Var {
    type Motion = ();

    fn motion<T>(
        project: impl FnOnce() -> Option<(V2<Var>, V2<Var>, T)>,
        _scale: Vec2,
    ) -> Option<(Vec2, Vec2, (), T)> {
        clear_tape();
        let projected = project();
        // the edge was recorded only to see whether it depends on a
        // recorded parameter: the tape would otherwise grow with the mesh
        clear_tape();
        let (f0, f1, t) = projected?;
        let moves = [f0.x, f0.y, f1.x, f1.y].iter().any(|v| v.is_attached());
        moves.then(|| (f0.val(), f1.val(), (), t))
    }
}

/// One projected edge that moves with the parameters.
struct Segment<M> {
    /// End points on the film (crop-window pixels), after clipping to the
    /// near plane, and their unit normal (the jump and the normal velocity
    /// are measured along it).
    a: Vec2,
    b: Vec2,
    n: Vec2,
    motion: M,
    /// The part `a + s (b − a)`, s ∈ [s0, s1], inside the sampled region.
    s0: f32,
    s1: f32,
    /// The world-space end points (near-clipped), for the visibility test.
    p0: Vec3,
    p1: Vec3,
    /// The shape and its edge (index in its edge table).
    shape: u32,
    edge: u32,
    /// Whether the shape is smooth-shaded (vertex normals): its
    /// silhouettes may be lined with a shading-horizon sliver (see
    /// [`Context::beyond_horizon`]).
    smooth: bool,
}

impl<M> Segment<M> {
    fn length(&self) -> f32 {
        (self.b - self.a).length() * (self.s1 - self.s0)
    }
}

/// The film end points (full-film units, in `R`) of the edge `e` of `mesh`
/// seen by `sensor`, clipped to the near plane in camera space, and their
/// world positions (primal); `None` if the edge is wholly behind the near
/// plane or the camera has no projection. Forward and reverse mode both
/// run this, so the motion they differentiate is the same.
fn project_edge<R: Real>(
    sensor: &Sensor,
    store: &ParamView,
    mesh: &Mesh,
    e: &Edge,
) -> Option<(V2<R>, V2<R>, [Vec3; 2])> {
    let proj = sensor.projector::<R>(store)?;
    let near = proj.near * (1.0 + 1e-4);
    let (_, tri) = mesh.triangle_r::<R>(store, e.face);
    let k = e.corner as usize;
    let (w0, w1) = (tri[k], tri[(k + 1) % 3]);
    let (q0, q1) = (proj.to_local(w0), proj.to_local(w1));
    let (z0, z1) = (q0.z.val(), q1.z.val());
    if !(z0 >= near || z1 >= near) {
        return None;
    }
    // the points where the edge enters the visible half-space, at fixed
    // fractions of the edge (points that move with it)
    let t0 = if z0 < near {
        (near - z0) / (z1 - z0)
    } else {
        0.0
    };
    let t1 = if z1 < near {
        (near - z1) / (z0 - z1)
    } else {
        0.0
    };
    let lerp = |a: V3<R>, b: V3<R>, t: f32| a + (b - a) * R::cst(t);
    let (q0, q1) = (lerp(q0, q1, t0), lerp(q1, q0, t1));
    let lerp = |a: Vec3, b: Vec3, t: f32| a + (b - a) * t;
    let (w0, w1) = (w0.val(), w1.val());
    Some((
        proj.film(q0),
        proj.film(q1),
        [lerp(w0, w1, t0), lerp(w1, w0, t1)],
    ))
}

/// The clipped segments of every candidate edge of every mesh whose image
/// moves with the parameters `store` seeds in `R`.
fn segments<R: EdgeMotion>(
    scene: &Scene,
    sensor: &Sensor,
    store: &ParamView,
    eye: Eye,
    to_pixels: &dyn Fn(Vec2) -> Vec2,
    region: Region,
    scale: Vec2,
) -> Vec<Segment<R::Motion>> {
    let mut out = Vec::new();
    for (shape_index, shape) in scene.shapes.iter().enumerate() {
        let Shape::Mesh(mesh) = shape else {
            continue;
        };
        let positions = store.data(mesh.positions);
        for (edge_index, e) in mesh.edges.edges.iter().enumerate() {
            match e.kind {
                EdgeKind::Inert => continue,
                EdgeKind::Smooth
                    if !EdgeTable::is_silhouette(e, &mesh.faces, positions, eye)
                        && !EdgeTable::is_concave(e, &mesh.faces, positions, eye) =>
                {
                    continue
                }
                _ => {}
            }
            let Some((f0, f1, motion, [p0, p1])) =
                R::motion(|| project_edge::<R>(sensor, store, mesh, e), scale)
            else {
                continue;
            };
            let (a, b) = (to_pixels(f0), to_pixels(f1));
            let Some((s0, s1)) = clip(a, b, region) else {
                continue;
            };
            let dir = b - a;
            let seg = Segment {
                a,
                b,
                n: Vec2::new(-dir.y, dir.x).normalize(),
                motion,
                s0,
                s1,
                p0,
                p1,
                shape: shape_index as u32,
                edge: edge_index as u32,
                smooth: mesh.normals.is_some(),
            };
            let len = seg.length();
            if len > 0.0 && len.is_finite() {
                out.push(seg);
            }
        }
    }
    out
}

/// The parameter range of the segment `a + s (b − a)`, s ∈ [0, 1], inside
/// `region` (Liang–Barsky clipping), if not empty.
fn clip(a: Vec2, b: Vec2, region: Region) -> Option<(f32, f32)> {
    let d = b - a;
    let (mut s0, mut s1) = (0.0f32, 1.0f32);
    for (p, q) in [
        (-d.x, a.x - region.lo.x),
        (d.x, region.hi.x - a.x),
        (-d.y, a.y - region.lo.y),
        (d.y, region.hi.y - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                s0 = s0.max(r);
            } else {
                s1 = s1.min(r);
            }
        }
    }
    (s0 < s1).then_some((s0, s1))
}

/// The closest point of the line through `p0`, `p1` to the ray, as a
/// distance along the ray (`None` if they are parallel).
fn distance_along(o: Vec3, d: Vec3, p0: Vec3, p1: Vec3) -> Option<f32> {
    let e = p1 - p0;
    let w = o - p0;
    let (b, c) = (d.dot(e), e.dot(e));
    let denom = d.dot(d) * c - b * b;
    (denom > 1e-12 * c).then(|| (b * e.dot(w) - c * d.dot(w)) / denom)
}

/// Adds the primary boundary term along the tangents of `store` to the
/// derivative image `image` of the render `opts` describes.
pub(crate) fn add_primary_boundary(
    scene: &Scene,
    store: &ParamView,
    opts: &RenderOptions,
    image: &mut Rendered,
) -> Result<()> {
    let Some(ctx) = Context::<(Vec2, Vec2)>::new::<Dual>(scene, store, opts)? else {
        return Ok(());
    };
    let mut acc = vec![0.0f64; image.data.len()];
    image.non_finite_samples += ctx.run(opts, |seg, splat, pixel, w| {
        let (da, db) = seg.motion;
        let v_n = seg.n.dot(da + (db - da) * splat.s);
        for c in 0..3 {
            acc[3 * pixel + c] += w * (splat.value[c] * v_n) as f64;
        }
    })?;
    for (d, a) in image.data.iter_mut().zip(&acc) {
        *d += *a as f32;
    }
    Ok(())
}

/// Adds the primary boundary term of the gradient of a loss, given its
/// adjoint image `d_image` (crop-window height × width × 3), to `sums`
/// (per parameter, per element, for the parameters `store` records) of
/// the render `opts` describes; returns the number of non-finite edge
/// samples left out.
///
/// The term is `Σ_samples Σ_p δI_p k_p(x)/W_p · ΔL/pdf · ⟨dx/dθ, n⟩`, the
/// forward mode estimate of the same samples (same edges, same positions)
/// contracted with δI. Only x moves with θ, and it is the point at the
/// fixed fraction s between the projected end points: `⟨x, n⟩ = (1 − s)
/// ⟨a, n⟩ + s ⟨b, n⟩` with n held fixed. So the samples' weights (without
/// the motion) are summed per segment and end point, and each segment is
/// recorded once more on the tape and `⟨a, n⟩`, `⟨b, n⟩` are
/// backpropagated with those sums, in segment order (the result does not
/// depend on the thread count).
pub(crate) fn add_primary_boundary_gradients(
    scene: &Scene,
    store: &ParamView,
    d_image: &[f32],
    opts: &RenderOptions,
    sums: &mut [Vec<f64>],
) -> Result<usize> {
    let Some(ctx) = Context::<()>::new::<Var>(scene, store, opts)? else {
        return Ok(0);
    };
    let mut weights = vec![[0.0f64; 2]; ctx.segs.len()];
    let non_finite = ctx.run(opts, |_, splat, pixel, w| {
        let adjoint: f32 = (0..3)
            .map(|c| d_image[3 * pixel + c] * splat.value[c])
            .sum();
        let a = w * adjoint as f64;
        let s = splat.s as f64;
        let ws = &mut weights[splat.seg as usize];
        ws[0] += a * (1.0 - s);
        ws[1] += a * s;
    })?;
    for (seg, [wa, wb]) in ctx.segs.iter().zip(weights) {
        if wa == 0.0 && wb == 0.0 {
            continue;
        }
        clear_tape();
        let projected = scene.shapes[seg.shape as usize].as_mesh().and_then(|mesh| {
            project_edge::<Var>(
                ctx.film.sensor,
                store,
                mesh,
                &mesh.edges.edges[seg.edge as usize],
            )
        });
        let Some((f0, f1, _)) = projected else {
            continue;
        };
        // ⟨to_pixels(f), n⟩ up to a constant
        let n = seg.n * ctx.film.scale;
        let normal = |f: V2<Var>| f.x * n.x + f.y * n.y;
        backward(
            &[(normal(f0), wa as f32), (normal(f1), wb as f32)],
            |id, i, g| sums[id.0 as usize][i] += g as f64,
        );
    }
    Ok(non_finite)
}

/// One edge sample's contribution before filtering and motion: `ΔL / pdf`
/// at film position `x` (crop-window pixels), the point at fraction `s`
/// of segment `seg`.
struct Splat {
    x: Vec2,
    seg: u32,
    s: f32,
    value: [f32; 3],
}

/// The edge samples of one render: what every sample reads, and the
/// per-pixel normalisation of the splats.
struct Context<'a, M> {
    scene: &'a Scene,
    film: FilmSplatter<'a>,
    segs: Vec<Segment<M>>,
    dist: DiscreteDistribution,
    /// Total projected length (pixels): the inverse of the density.
    total: f32,
    /// Offset (pixels) from the edge to either side.
    eps: f32,
    seed: u64,
}

impl<'a, M: Sync> Context<'a, M> {
    /// The segments moving with the parameters `store` seeds in `R` and
    /// the sampling of the render `opts` describes, or `None` if there is
    /// nothing to sample.
    fn new<R: EdgeMotion<Motion = M>>(
        scene: &'a Scene,
        store: &ParamView,
        opts: &RenderOptions,
    ) -> Result<Option<Self>> {
        let sensor = scene.sensor(opts.sensor)?;
        let Some(proj) = sensor.projector::<f32>(store) else {
            return Ok(None);
        };
        let spp = opts.spp.unwrap_or_else(|| sensor.sampler.sample_count());
        let film = FilmSplatter::new(sensor, opts.sppp.unwrap_or(spp), opts)?;
        let to_pixels = |f: Vec2| film.to_pixels(f);
        let segs = segments::<R>(
            scene,
            sensor,
            store,
            proj.eye(),
            &to_pixels,
            film.region,
            film.scale,
        );
        let lengths: Vec<f32> = segs.iter().map(Segment::length).collect();
        let Some(dist) = DiscreteDistribution::new(&lengths) else {
            return Ok(None);
        };
        Ok(Some(Context {
            scene,
            segs,
            total: dist.sum() as f32,
            dist,
            eps: 1e-3 * (film.scale.max_element() / 1000.0).max(1.0),
            seed: opts.seed,
            film,
        }))
    }

    /// Draws the `sppp × pixels` edge samples and calls `visit(segment,
    /// sample, pixel, weight)` for every pixel p (index in the crop window)
    /// the filter reaches from every non-zero sample, with weight
    /// `k_p(x) / (W_p · samples)`, in a fixed order (see
    /// [`FilmSplatter::run`]). Returns the number of non-finite samples
    /// left out (and warns about them).
    fn run(
        &self,
        opts: &RenderOptions,
        mut visit: impl FnMut(&Segment<M>, &Splat, usize, f64),
    ) -> Result<usize> {
        self.film.run(
            opts,
            "primary visibility boundary term",
            |c, count| self.chunk(c, count),
            |batch| {
                for s in batch.iter().flatten() {
                    let seg = &self.segs[s.seg as usize];
                    self.film.footprint(s.x, |p, w| visit(seg, s, p, w));
                }
            },
        )
    }

    /// The film position `eps` from `x` towards `dir` (a unit vector) or,
    /// if the camera sees there the back of the shading normals of the
    /// smooth-shaded `shape` through its front faces, the first position
    /// beyond that sliver (offsets growing 4× up to a pixel).
    ///
    /// Why: where a coarse smooth-shaded mesh turns away from the camera,
    /// the interpolated shading normal faces away before the geometry does,
    /// and BSDFs and emitters are zero below the shading horizon, so a thin
    /// black sliver lines the silhouette inside the faces. Its inner
    /// border (the horizon curve) is a discontinuity too, which the edge
    /// table does not hold. For a sliver thinner than the filter it moves
    /// with the silhouette, and the two jumps add up to the jump from the
    /// outside to the surface beyond the sliver, which is what this
    /// measures across the silhouette. A sliver wider than a pixel is left
    /// as it is (its horizon term is then missing).
    fn beyond_horizon(&self, x: Vec2, dir: Vec2, smooth_shape: Option<u32>) -> Vec2 {
        let mut off = self.eps;
        let Some(shape) = smooth_shape else {
            return x + dir * off;
        };
        let scene = self.scene;
        loop {
            let xs = x + dir * off;
            if off >= 1.0 {
                return xs;
            }
            let ray = self
                .film
                .camera_sample(xs)
                .ray::<f32>(&scene.params.primal())
                .val();
            let in_sliver = scene.intersect(&ray).is_some_and(|hit| {
                hit.shape == shape && {
                    let si = scene.surface_interaction::<f32>(
                        &scene.params.primal(),
                        &DiffRay::cst(&ray),
                        &hit,
                    );
                    si.n.val().dot(ray.d) < 0.0 && !(si.wi.z > 0.0)
                }
            });
            if !in_sliver {
                return xs;
            }
            off = (off * 4.0).min(1.0);
        }
    }

    /// The non-zero splats of chunk `c` and the number of non-finite ones.
    fn chunk(&self, c: usize, count: u32) -> (Vec<Splat>, usize) {
        let scene = self.scene;
        let mut out = Vec::new();
        let mut non_finite = 0;
        for k in 0..count {
            let mut rng =
                self.film
                    .sensor
                    .sampler
                    .stream(self.seed, STREAM_KEY | c as u64, k, CHUNK);
            // jittered strata of the total length within the chunk: the
            // chunk's samples are summed with equal weights, so the sum is
            // unbiased, and the opposite contributions of the two sides of
            // a moving shape cancel out much better than with independent
            // positions
            let u = (k as f32 + rng.next_1d()) / count as f32;
            let (i, _, u) = self.dist.sample_reuse(u.min(1.0 - f32::EPSILON));
            let seg = &self.segs[i];
            let s = seg.s0 + u * (seg.s1 - seg.s0);
            let (x, n) = (seg.a + (seg.b - seg.a) * s, seg.n);
            // the edge must be what the camera sees at x
            let ray = self
                .film
                .camera_sample(x)
                .ray::<f32>(&scene.params.primal())
                .val();
            if let (Some(hit), Some(t_edge)) = (
                scene.intersect(&ray),
                distance_along(ray.o, ray.d, seg.p0, seg.p1),
            ) {
                if hit.t < t_edge * (1.0 - 1e-3) {
                    continue;
                }
            }
            let radiance = |side: f32| {
                let cs = self.film.camera_sample(self.beyond_horizon(
                    x,
                    n * side,
                    seg.smooth.then_some(seg.shape),
                ));
                let mut r = rng.clone();
                scene
                    .integrator
                    .radiance::<f32>(scene, &scene.params.primal(), &cs, &mut r)
                    .map_or(Vec3::ZERO, |l| l.val())
            };
            // the jump from the side n points to, to the side it points
            // away from (module documentation)
            let jump = radiance(-1.0) - radiance(1.0);
            let value = jump * self.total;
            if !value.is_finite() {
                non_finite += 1;
            } else if value != Vec3::ZERO {
                out.push(Splat {
                    x,
                    seg: i as u32,
                    s,
                    value: value.to_array(),
                });
            }
        }
        (out, non_finite)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_to_the_film() {
        let r = Region {
            lo: Vec2::ZERO,
            hi: Vec2::new(10.0, 5.0),
        };
        let (a, b) = (Vec2::new(-5.0, 1.0), Vec2::new(15.0, 1.0));
        assert_eq!(clip(a, b, r), Some((0.25, 0.75)));
        assert_eq!(clip(Vec2::new(1.0, 6.0), Vec2::new(9.0, 7.0), r), None);
        assert_eq!(
            clip(Vec2::new(1.0, 1.0), Vec2::new(2.0, 2.0), r),
            Some((0.0, 1.0))
        );
    }
}
