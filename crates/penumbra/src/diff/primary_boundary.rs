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
//! # Outlines of analytic shapes
//!
//! Spheres and disks have no edges; their images jump across their
//! outlines, which are curves in the world: a disk's rim (the unit circle
//! of its local z = 0 plane through `to_world`), and a sphere's silhouette,
//! the circle where the view ray is tangent to it (from a pinhole at e,
//! the points p with (p − c)·(p − e) = 0: centre c + r²/|e − c|² (e − c),
//! radius r √(1 − r²/|e − c|²), normal e − c; from an orthographic camera,
//! the great circle normal to the view direction). Both are
//! `p(φ) = c' + u cos φ + v sin φ` with c', u, v computed in the number
//! type of the pass from the shape's parameters (a sphere's centre and
//! radius as its surface reads them: from `to_world` when that carries
//! derivatives, else from `center` and `radius`) and the camera's, so a
//! point of fixed φ moves with all of them ([`outline`]).
//!
//! Each outline enters the segment machinery above as
//! `OUTLINE_CHORDS` = 128 chords between the points of angles 2πk/N: they
//! are projected, clipped, tested for motion, picked by projected length
//! and backpropagated exactly like edges. Only the sample itself differs:
//! at fraction s of chord k, the point is the outline's own point at
//! φ = 2π(k + s)/N, projected (not the chord's point, which lies inside
//! the curve by a sagitta of up to 3·10⁻⁴ of its radius: more than the
//! ±ε offset of the jump), with the normal of the outline's image there,
//! and the sample's weight is multiplied by |dx/dφ| Δφ / chord length, the
//! ratio of the density along the curve to the density along the chord,
//! so that the density is exactly that of arc length (no O(1/N²) length
//! error). The normal velocity is that normal dotted with the velocity
//! linearly interpolated between the chord's end points (which are true
//! outline points, moving in `Dual`/`Var`): the velocity is smooth in φ,
//! so its relative error is at most (2π/N)²/8 ≈ 3·10⁻⁴, far below the
//! tests' 1 % floor. Reverse mode sums the samples' weights times their
//! normal per chord end point (a vector, since the normal varies along a
//! chord) and backpropagates them into the chord's projected end points.
//! The visibility test asks that nothing be nearer than the outline point
//! along the camera ray. A disk seen exactly edge-on has an image of zero
//! area (both sides black, no jump); where its image does not turn
//! (|dx/dφ| = 0) the sample is dropped. Chords with an end point behind
//! the near plane are left out, and a pinhole inside a sphere sees no
//! silhouette.
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
//! aperture), edges and outlines cut by the near plane (the cut itself is
//! a moving edge of the image), and coincident edges of distinct meshes
//! (each is counted). Callers warn about the first
//! ([`super::warn_missing_boundary_terms`]). Two jumps
//! of smooth-shaded meshes off the edge table are handled only in part:
//! the curve where the view direction crosses the horizon of the
//! interpolated shading normal (BSDFs and area emitters are zero below it;
//! near the silhouettes of a coarse mesh it lines them inside the faces) is
//! merged into the silhouette when it is thinner than a pixel
//! ([`Context::beyond_horizon`]) and missing otherwise; a convex smooth
//! edge between a face that sees a light and a neighbour that shadows
//! itself from it (the terminator of a coarse smooth mesh, seen directly)
//! is not sampled.

use super::splat::{FilmSplatter, Region};
use crate::ad::reverse::{backward, clear_tape};
use crate::ad::{Dual, ScalarReal, Var};
use crate::error::Result;
use crate::geometry::edges::{Edge, EdgeKind, EdgeTable, Eye};
use crate::geometry::{DiffRay, Mesh, Shape};
use crate::integrator::{RenderOptions, Rendered};
use crate::math::{DiscreteDistribution, V2, V3};
use crate::params::ParamView;
use crate::scene::Scene;
use crate::sensor::projection::{Projector, Viewpoint};
use crate::sensor::Sensor;
use glam::{Vec2, Vec3};
use std::f32::consts::TAU;

/// Sample-stream keys of edge samples: far from the keys of film pixels.
const STREAM_KEY: u64 = 0xed6e_0000_0000_0000;

/// Chords per outline of an analytic shape (sphere silhouette, disk rim):
/// they only pick the angle to sample (see the module documentation), so
/// the estimate does not depend on them beyond the linear interpolation of
/// the velocity, whose relative error is below (2π/N)²/8 ≈ 3·10⁻⁴.
const OUTLINE_CHORDS: u32 = 128;

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
trait EdgeMotion: ScalarReal {
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
    /// The shape and its edge (index in its edge table), or for an
    /// analytic shape the index of the chord of its outline.
    shape: u32,
    edge: u32,
    /// The outline a chord of an analytic shape approximates (primal):
    /// samples are taken on it, not on the chord.
    outline: Option<Outline>,
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
fn project_edge<R: ScalarReal>(
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

/// The outline of an analytic shape seen by the camera, in world space:
/// the curve `p(φ) = c + u cos φ + v sin φ`, φ ∈ [0, 2π).
#[derive(Clone, Copy)]
struct Outline {
    c: Vec3,
    u: Vec3,
    v: Vec3,
}

impl Outline {
    /// The point at angle `phi` and its derivative along the angle.
    fn at(&self, phi: f32) -> (Vec3, Vec3) {
        let (sin, cos) = phi.sin_cos();
        (
            self.c + self.u * cos + self.v * sin,
            self.v * cos - self.u * sin,
        )
    }
}

/// The outline of the analytic `shape` seen through `proj`, as `[c, u, v]`
/// of [`Outline`] in `R` (moving with the shape's and the camera's
/// parameters); `None` for a mesh, a cylinder (its outline, two rims and
/// two view-dependent lines, is not estimated: the derivative pass warns
/// so), or a sphere around a pinhole.
///
/// - A sphere (centre c, radius r, read as its own surface reads them:
///   from `to_world` when that is tracked, else from `center`, `radius`)
///   seen from the eye e: the circle of the points p with (p − c)·(p − e)
///   = 0, centre c + r²/|e − c|² (e − c), radius r √(1 − r²/|e − c|²), in
///   the plane normal to e − c; from an orthographic camera with view
///   direction d, the great circle normal to d.
/// - A disk: its rim, the image of the unit circle of the z = 0 plane
///   under `to_world` (u, v the images of the local x and y axes).
///
/// The angle's origin is a fixed (primal) function of the view, so a
/// point of fixed angle moves smoothly with the parameters; only the
/// normal component of its velocity matters.
fn outline<R: ScalarReal>(
    proj: &Projector<R>,
    store: &ParamView,
    shape: &Shape,
) -> Option<[V3<R>; 3]> {
    match shape {
        Shape::Mesh(_) | Shape::Cylinder(_) => None,
        Shape::Disk(d) => {
            let (c, a0, a1) = d.frame_r::<R>(store);
            Some([c, a0, a1])
        }
        Shape::Sphere(s) => {
            let (c, r, _) = s.frame_r::<R>(store);
            let (centre, rho, w) = match proj.viewpoint() {
                Viewpoint::Point(e) => {
                    let w = e - c;
                    let k = r * r / w.length_squared();
                    if !(k.val() < 1.0) {
                        return None;
                    }
                    (c + w * k, r * (R::cst(1.0) - k).sqrt(), w)
                }
                Viewpoint::Direction(d) => (c, r, d),
            };
            // an orthonormal basis of the plane normal to w, from the
            // world axis least aligned with it
            let a = w.val().abs();
            let helper = if a.x <= a.y && a.x <= a.z {
                Vec3::X
            } else if a.y <= a.z {
                Vec3::Y
            } else {
                Vec3::Z
            };
            let u = V3::cst(helper).cross(w).normalize();
            let v = w.cross(u).normalize();
            Some([centre, u * rho, v * rho])
        }
    }
}

/// A projected segment: film end points (full-film units, in `R`), world
/// end points and, for a chord, its outline (primal).
type Projected<R> = (V2<R>, V2<R>, ([Vec3; 2], Option<Outline>));

/// The film end points (full-film units, in `R`) of chord `k` of the
/// outline of the analytic `shape` seen by `sensor`, between the outline's
/// points at angles 2πk/N and 2π(k + 1)/N, their world positions and the
/// outline (primal); `None` if either end point is behind the near plane.
fn project_chord<R: ScalarReal>(
    sensor: &Sensor,
    store: &ParamView,
    shape: &Shape,
    k: u32,
) -> Option<Projected<R>> {
    let proj = sensor.projector::<R>(store)?;
    let [c, u, v] = outline(&proj, store, shape)?;
    let point = |j: u32| {
        let (sin, cos) = (TAU * j as f32 / OUTLINE_CHORDS as f32).sin_cos();
        c + u * R::cst(cos) + v * R::cst(sin)
    };
    let (w0, w1) = (point(k), point(k + 1));
    let (q0, q1) = (proj.to_local(w0), proj.to_local(w1));
    let near = proj.near * (1.0 + 1e-4);
    if !(q0.z.val() >= near && q1.z.val() >= near) {
        return None;
    }
    let outline = Outline {
        c: c.val(),
        u: u.val(),
        v: v.val(),
    };
    Some((
        proj.film(q0),
        proj.film(q1),
        ([w0.val(), w1.val()], Some(outline)),
    ))
}

/// [`project_edge`] for edge `index` of a mesh, [`project_chord`] for
/// chord `index` of the outline of an analytic shape.
fn project_segment<R: ScalarReal>(
    sensor: &Sensor,
    store: &ParamView,
    shape: &Shape,
    index: u32,
) -> Option<Projected<R>> {
    match shape {
        Shape::Mesh(mesh) => {
            let (f0, f1, p) = project_edge::<R>(
                sensor,
                store,
                mesh,
                &mesh.edges(store).edges[index as usize],
            )?;
            Some((f0, f1, (p, None)))
        }
        _ => project_chord::<R>(sensor, store, shape, index),
    }
}

/// The clipped segments of every candidate edge of every mesh, and of the
/// chords of the outlines of analytic shapes, whose image moves with the
/// parameters `store` seeds in `R`.
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
        // a shape group's shapes are in the group's space, seen only
        // through instances, whose edges are not sampled (named by
        // `diff::warn_missing_boundary_terms`)
        if scene.in_group(shape_index as u32) {
            continue;
        }
        let candidates: Vec<u32> = match shape {
            Shape::Mesh(mesh) => {
                let positions = store.data(mesh.positions);
                let edges = &mesh.edges(store).edges;
                (0..edges.len() as u32)
                    .filter(|&i| {
                        let e = &edges[i as usize];
                        match e.kind {
                            EdgeKind::Inert => false,
                            EdgeKind::Smooth => {
                                EdgeTable::is_silhouette(e, &mesh.faces, positions, eye)
                                    || EdgeTable::is_concave(e, &mesh.faces, positions, eye)
                            }
                            _ => true,
                        }
                    })
                    .collect()
            }
            _ => (0..OUTLINE_CHORDS).collect(),
        };
        let smooth = shape.as_mesh().is_some_and(|m| m.normals.is_some());
        for edge_index in candidates {
            let Some((f0, f1, motion, ([p0, p1], outline))) = R::motion(
                || project_segment::<R>(sensor, store, shape, edge_index),
                scale,
            ) else {
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
                edge: edge_index,
                outline,
                smooth,
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
        let v_n = splat.n.dot(da + (db - da) * splat.s);
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
/// contracted with δI. Only x moves with θ, and its velocity is that of
/// the point at the fixed fraction s between the projected end points:
/// `⟨dx, n⟩ = (1 − s) ⟨da, n⟩ + s ⟨db, n⟩` with n held fixed (the edge's
/// normal, or the outline's at the sample). So the samples' weights
/// (without the motion) times n are summed per segment and end point (2D
/// vectors), and each segment is recorded once more on the tape and its
/// end points are backpropagated with those sums, in segment order (the
/// result does not depend on the thread count).
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
    // per segment, Σ weight · (1 − s) n and Σ weight · s n (x, y): the
    // normal is the segment's for an edge, the outline's at the sample for
    // a chord
    let mut weights = vec![[0.0f64; 4]; ctx.segs.len()];
    let non_finite = ctx.run(opts, |_, splat, pixel, w| {
        let adjoint: f32 = (0..3)
            .map(|c| d_image[3 * pixel + c] * splat.value[c])
            .sum();
        let a = w * adjoint as f64;
        let s = splat.s as f64;
        let (nx, ny) = (splat.n.x as f64, splat.n.y as f64);
        let ws = &mut weights[splat.seg as usize];
        ws[0] += a * (1.0 - s) * nx;
        ws[1] += a * (1.0 - s) * ny;
        ws[2] += a * s * nx;
        ws[3] += a * s * ny;
    })?;
    for (seg, ws) in ctx.segs.iter().zip(weights) {
        if ws.iter().all(|&w| w == 0.0) {
            continue;
        }
        clear_tape();
        let projected = project_segment::<Var>(
            ctx.film.sensor,
            store,
            &scene.shapes[seg.shape as usize],
            seg.edge,
        );
        let Some((f0, f1, _)) = projected else {
            continue;
        };
        // ⟨to_pixels(f), n⟩ up to a constant, per coordinate
        let k = ctx.film.scale;
        backward(
            &[
                (f0.x, (ws[0] * k.x as f64) as f32),
                (f0.y, (ws[1] * k.y as f64) as f32),
                (f1.x, (ws[2] * k.x as f64) as f32),
                (f1.y, (ws[3] * k.y as f64) as f32),
            ],
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
    /// The unit normal the jump and the velocity are measured along.
    n: Vec2,
    value: [f32; 3],
}

/// The edge samples of one render: what every sample reads, and the
/// per-pixel normalisation of the splats.
struct Context<'a, M> {
    scene: &'a Scene,
    film: FilmSplatter<'a>,
    /// The camera's projection (primal values, in `Dual` to differentiate
    /// the image of an outline along its angle).
    proj: Projector<Dual>,
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
        let Some(proj) = sensor.projector::<Dual>(&scene.params.primal()) else {
            return Ok(None);
        };
        Ok(Some(Context {
            scene,
            proj,
            segs,
            total: dist.sum() as f32,
            dist,
            // small, because the faces next to a silhouette can be seen
            // nearly edge-on: on a flat-shaded icosphere, at 1e-3 pixels
            // the side samples landed on the next face beyond the thin one
            // and the boundary term came out 10–15 % high at those pixels;
            // growing with the film so as to stay ≥ 13 ulps of its
            // coordinates
            eps: 1e-4 * (film.scale.max_element() / 100.0).max(1.0),
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

    /// The sample at fraction `s` of the chord `seg` of `outline`: the film
    /// position (crop-window pixels) of the outline's point at the same
    /// fraction of the chord's angle range, the unit normal of the
    /// outline's image there (on the side of the chord's normal), the
    /// ratio of the density to sample it by (arc length over the whole
    /// outline) to the density it was sampled by (chord length), and the
    /// world point; `None` where the image does not turn (a disk seen
    /// edge-on at the ends of its image).
    fn outline_point(
        &self,
        seg: &Segment<M>,
        outline: &Outline,
        s: f32,
    ) -> Option<(Vec2, Vec2, f32, Vec3)> {
        let dphi = TAU / OUTLINE_CHORDS as f32;
        let (p, dp) = outline.at((seg.edge as f32 + s) * dphi);
        let q = V3::new(
            Dual::new(p.x, dp.x),
            Dual::new(p.y, dp.y),
            Dual::new(p.z, dp.z),
        );
        let f = self.proj.film(self.proj.to_local(q));
        let x = self.film.to_pixels(Vec2::new(f.x.v, f.y.v));
        let dx = Vec2::new(f.x.d, f.y.d) * self.film.scale;
        let speed = dx.length();
        let chord = (seg.b - seg.a).length();
        if !(speed > 0.0 && speed.is_finite() && x.is_finite() && chord > 0.0) {
            return None;
        }
        let n = Vec2::new(-dx.y, dx.x) / speed;
        Some((x, n, speed * dphi / chord, p))
    }

    /// The non-zero splats of chunk `c` and the number of non-finite ones.
    fn chunk(&self, c: usize, count: u32) -> (Vec<Splat>, usize) {
        let scene = self.scene;
        let mut out = Vec::new();
        let mut non_finite = 0;
        // jittered strata of the total length
        self.film
            .jittered(self.seed, STREAM_KEY, c, count, |u, rng| {
                let (i, _, u) = self.dist.sample_reuse(u);
                let seg = &self.segs[i];
                let s = seg.s0 + u * (seg.s1 - seg.s0);
                // the point, its normal, the ratio of the true density to the
                // sampled one, and the world point seen there (for an edge,
                // the line it lies on)
                let (x, n, ratio, point) = match &seg.outline {
                    None => (seg.a + (seg.b - seg.a) * s, seg.n, 1.0, None),
                    Some(outline) => {
                        let Some((x, n, ratio, p)) = self.outline_point(seg, outline, s) else {
                            return;
                        };
                        (x, n, ratio, Some(p))
                    }
                };
                // the edge must be what the camera sees at x
                let ray = self
                    .film
                    .camera_sample(x)
                    .ray::<f32>(&scene.params.primal())
                    .val();
                let t_edge = match point {
                    None => distance_along(ray.o, ray.d, seg.p0, seg.p1),
                    Some(p) => Some((p - ray.o).dot(ray.d) / ray.d.dot(ray.d)),
                };
                if let (Some(hit), Some(t_edge)) = (scene.intersect(&ray), t_edge) {
                    if hit.t < t_edge * (1.0 - 1e-3) {
                        return;
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
                let value = jump * (self.total * ratio);
                if !value.is_finite() {
                    non_finite += 1;
                } else if value != Vec3::ZERO {
                    out.push(Splat {
                        x,
                        seg: i as u32,
                        s,
                        n,
                        value: value.to_array(),
                    });
                }
            });
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
