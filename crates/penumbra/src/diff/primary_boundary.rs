//! The boundary term of primary visibility in forward mode: edge sampling
//! on the film (Li et al. 2018, "Differentiable Monte Carlo Ray Tracing
//! through Edge Sampling"; the sample budget and the projected-length
//! density follow the primary term of Zhang et al. 2023, "Projective
//! Sampling for Differentiable Rendering of Geometry", and Mitsuba's
//! `direct_projective`, whose `sppp` it is named after).
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
//! smooth edges that are silhouettes from the camera) whose image moves
//! along the tangent is projected onto the film in `Dual` (vertices read
//! through the store, so the positions' and `to_world`'s tangents and the
//! sensor's pose and field of view all move it), clipped to the near plane
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
//! ([`Context::beyond_horizon`]) and missing otherwise; a smooth edge
//! between a face that sees a light and a neighbour that shadows itself
//! from it (a shadow edge seen directly) is left to the shadow estimator
//! to come.

use crate::ad::{Dual, Real};
use crate::error::{Error, Result};
use crate::geometry::edges::{EdgeKind, EdgeTable};
use crate::geometry::{DiffRay, Shape};
use crate::image::{ImageBlock, ReconstructionFilter};
use crate::integrator::{RenderOptions, Rendered};
use crate::math::{DiscreteDistribution, V3};
use crate::params::ParamView;
use crate::scene::Scene;
use crate::sensor::{CameraSample, Projector, Sensor};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::Ordering;

/// Edge samples drawn from one sample stream key (one parallel task).
const CHUNK: u32 = 4096;
/// Chunks computed in parallel before their splats are added to the image
/// (bounds the memory of the splats in flight).
const CHUNKS_PER_BATCH: usize = 64;
/// Sample-stream keys of edge samples: far from the keys of film pixels.
const STREAM_KEY: u64 = 0xed6e_0000_0000_0000;

/// Whether this pass estimates the primary boundary term of the render
/// `opts` describes: the sensor is a pinhole or orthographic camera and
/// the budget is not zero.
pub(crate) fn applies(scene: &Scene, opts: &RenderOptions) -> Result<bool> {
    let sensor = scene.sensor(opts.sensor)?;
    Ok(opts.sppp != Some(0) && sensor.projector::<f32>(&scene.params.primal()).is_some())
}

/// One projected edge that moves along the tangent.
struct Segment {
    /// End points on the film (crop-window pixels), after clipping to the
    /// near plane, and their derivatives along the tangent.
    a: Vec2,
    b: Vec2,
    da: Vec2,
    db: Vec2,
    /// The part `a + s (b − a)`, s ∈ [s0, s1], inside the sampled region.
    s0: f32,
    s1: f32,
    /// The world-space end points (near-clipped), for the visibility test.
    p0: Vec3,
    p1: Vec3,
    /// The shape of the edge, if it is smooth-shaded (vertex normals): its
    /// silhouettes may be lined with a shading-horizon sliver (see
    /// [`Context::beyond_horizon`]).
    smooth_shape: Option<u32>,
}

impl Segment {
    fn length(&self) -> f32 {
        (self.b - self.a).length() * (self.s1 - self.s0)
    }
}

/// The film rectangle where samples are taken (crop-window pixels).
#[derive(Clone, Copy)]
struct Region {
    lo: Vec2,
    hi: Vec2,
}

/// The clipped segments of every candidate edge of every mesh that moves
/// on the film along the tangents of `store`.
fn segments(
    scene: &Scene,
    store: &ParamView,
    proj: &Projector<Dual>,
    to_pixels: &dyn Fn(Vec2) -> Vec2,
    region: Region,
    scale: Vec2,
) -> Vec<Segment> {
    let eye = proj.eye();
    let near = proj.near * (1.0 + 1e-4);
    let mut out = Vec::new();
    for (shape_index, shape) in scene.shapes.iter().enumerate() {
        let Shape::Mesh(mesh) = shape else {
            continue;
        };
        let smooth_shape = mesh.normals.map(|_| shape_index as u32);
        let positions = store.data(mesh.positions);
        for e in &mesh.edges.edges {
            match e.kind {
                EdgeKind::Inert => continue,
                EdgeKind::Smooth if !EdgeTable::is_silhouette(e, &mesh.faces, positions, eye) => {
                    continue
                }
                _ => {}
            }
            let (_, tri) = mesh.triangle_r::<Dual>(store, e.face);
            let k = e.corner as usize;
            let (w0, w1) = (tri[k], tri[(k + 1) % 3]);
            let (q0, q1) = (proj.to_local(w0), proj.to_local(w1));
            let (z0, z1) = (q0.z.val(), q1.z.val());
            if !(z0 >= near || z1 >= near) {
                continue;
            }
            // the points where the edge enters the visible half-space, at
            // fixed fractions of the edge (points that move with it)
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
            let lerp = |a: V3<Dual>, b: V3<Dual>, t: f32| a + (b - a) * Dual::cst(t);
            let (q0, q1) = (lerp(q0, q1, t0), lerp(q1, q0, t1));
            let (f0, f1) = (proj.film(q0), proj.film(q1));
            let px =
                |f: crate::math::V2<Dual>| (to_pixels(f.val()), Vec2::new(f.x.d, f.y.d) * scale);
            let ((a, da), (b, db)) = (px(f0), px(f1));
            if da == Vec2::ZERO && db == Vec2::ZERO {
                continue;
            }
            let Some((s0, s1)) = clip(a, b, region) else {
                continue;
            };
            let lerp = |a: Vec3, b: Vec3, t: f32| a + (b - a) * t;
            let (w0, w1) = (w0.val(), w1.val());
            let seg = Segment {
                a,
                b,
                da,
                db,
                s0,
                s1,
                p0: lerp(w0, w1, t0),
                p1: lerp(w1, w0, t1),
                smooth_shape,
            };
            let len = seg.length();
            if len > 0.0 && len.is_finite() && da.is_finite() && db.is_finite() {
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

/// `∫_lo^hi k(u) du` of the 1D filter `k` (offsets in pixels), by
/// Simpson's rule on each side of 0 (the filters are smooth there but for
/// the tent's kink at 0 and the cut at the radius).
fn filter_integral(filter: &ReconstructionFilter, lo: f32, hi: f32) -> f64 {
    let r = filter.radius();
    let (lo, hi) = (lo.max(-r), hi.min(r));
    let simpson = |a: f32, b: f32| -> f64 {
        if !(b > a) {
            return 0.0;
        }
        const N: usize = 64;
        let h = (b - a) as f64 / N as f64;
        let f = |i: usize| filter.eval((a as f64 + h * i as f64) as f32) as f64;
        let mut s = f(0) + f(N);
        for i in 1..N {
            s += f(i) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    };
    simpson(lo, hi.min(0.0)) + simpson(lo.max(0.0), hi)
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
    let sensor = scene.sensor(opts.sensor)?;
    let Some(proj) = sensor.projector::<Dual>(store) else {
        return Ok(());
    };
    let film = &sensor.film;
    let (cw, ch) = film.crop_size;
    let border = if film.sample_border {
        film.rfilter.border() as f32
    } else {
        0.0
    };
    let region = Region {
        lo: Vec2::splat(-border),
        hi: Vec2::new(cw as f32 + border, ch as f32 + border),
    };
    let size = Vec2::new(film.width as f32, film.height as f32);
    let crop_off = Vec2::new(film.crop_offset.0 as f32, film.crop_offset.1 as f32);
    let to_pixels = |f: Vec2| f * size - crop_off;
    let segs = segments(scene, store, &proj, &to_pixels, region, size);
    let lengths: Vec<f32> = segs.iter().map(Segment::length).collect();
    let Some(dist) = DiscreteDistribution::new(&lengths) else {
        return Ok(());
    };
    let spp = opts.spp.unwrap_or_else(|| sensor.sampler.sample_count());
    let sppp = opts.sppp.unwrap_or(spp) as u64;
    let n_samples = sppp * (cw * ch) as u64;
    let n_chunks = n_samples.div_ceil(CHUNK as u64) as usize;
    let ctx = Context {
        scene,
        sensor,
        segs: &segs,
        dist: &dist,
        total: dist.sum() as f32,
        eps: 1e-3 * (size.max_element() / 1000.0).max(1.0),
        crop_off,
        inv_size: size.recip(),
        seed: opts.seed,
        n_samples,
    };
    // per-pixel normalisation: W_p = Wx(i) · Wy(j) (separable filter,
    // rectangular region)
    let filter = &film.rfilter;
    let wx: Vec<f64> = (0..cw)
        .map(|i| {
            filter_integral(
                filter,
                region.lo.x - i as f32 - 0.5,
                region.hi.x - i as f32 - 0.5,
            )
        })
        .collect();
    let wy: Vec<f64> = (0..ch)
        .map(|j| {
            filter_integral(
                filter,
                region.lo.y - j as f32 - 0.5,
                region.hi.y - j as f32 - 0.5,
            )
        })
        .collect();
    let bounds = ImageBlock::new(0, 0, cw, ch, 0);
    let mut acc = vec![0.0f64; cw * ch * 3];
    let mut non_finite = 0usize;
    let run = |chunks: std::ops::Range<usize>| -> Vec<Option<(Vec<Splat>, usize)>> {
        chunks
            .into_par_iter()
            .map(|c| {
                if opts
                    .cancel
                    .as_ref()
                    .is_some_and(|c| c.load(Ordering::Relaxed))
                {
                    return None;
                }
                Some(ctx.chunk(c))
            })
            .collect()
    };
    let pool = match opts.threads {
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| Error::Invalid(format!("cannot start {n} threads: {e}")))?,
        ),
        None => None,
    };
    for first in (0..n_chunks).step_by(CHUNKS_PER_BATCH) {
        let chunks = first..(first + CHUNKS_PER_BATCH).min(n_chunks);
        let results = match &pool {
            Some(p) => p.install(|| run(chunks)),
            None => run(chunks),
        };
        for r in results {
            let (splats, bad) = r.ok_or(Error::Interrupted)?;
            non_finite += bad;
            for s in splats {
                bounds.footprint(filter, s.x.x, s.x.y, |i, j, w| {
                    let (i, j) = (i as usize, j as usize);
                    let w = w / (wx[i] * wy[j]);
                    let o = 3 * (j * cw + i);
                    for c in 0..3 {
                        acc[o + c] += w * s.value[c] as f64;
                    }
                });
            }
        }
    }
    image.non_finite_samples += non_finite;
    if non_finite > 0 {
        crate::warn(format!(
            "primary visibility boundary term: {non_finite} edge sample(s) had a NaN or infinite \
             value and were left out"
        ));
    }
    let n = n_samples as f64;
    for (d, a) in image.data.iter_mut().zip(&acc) {
        *d += (a / n) as f32;
    }
    Ok(())
}

/// One edge sample's contribution before filtering: `ΔL v_n / pdf` at film
/// position `x` (crop-window pixels).
struct Splat {
    x: Vec2,
    value: [f32; 3],
}

/// What every edge sample reads.
struct Context<'a> {
    scene: &'a Scene,
    sensor: &'a Sensor,
    segs: &'a [Segment],
    dist: &'a DiscreteDistribution,
    /// Total projected length (pixels): the inverse of the density.
    total: f32,
    /// Offset (pixels) from the edge to either side.
    eps: f32,
    crop_off: Vec2,
    inv_size: Vec2,
    seed: u64,
    n_samples: u64,
}

impl Context<'_> {
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

    fn camera_sample(&self, x: Vec2) -> CameraSample<'_> {
        CameraSample {
            sensor: self.sensor,
            film: (x + self.crop_off) * self.inv_size,
            lens: Vec2::ZERO,
        }
    }

    /// The non-zero splats of chunk `c` and the number of non-finite ones.
    fn chunk(&self, c: usize) -> (Vec<Splat>, usize) {
        let scene = self.scene;
        let first = c as u64 * CHUNK as u64;
        let count = (self.n_samples - first).min(CHUNK as u64) as u32;
        let mut out = Vec::new();
        let mut non_finite = 0;
        for k in 0..count {
            let mut rng = self
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
            let dir = seg.b - seg.a;
            let n = Vec2::new(-dir.y, dir.x).normalize();
            let x = seg.a + dir * s;
            let v_n = n.dot(seg.da + (seg.db - seg.da) * s);
            if v_n == 0.0 {
                continue;
            }
            // the edge must be what the camera sees at x
            let ray = self
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
                let cs = self.camera_sample(self.beyond_horizon(x, n * side, seg.smooth_shape));
                let mut r = rng.clone();
                scene
                    .integrator
                    .radiance::<f32>(scene, &scene.params.primal(), &cs, &mut r)
                    .map_or(Vec3::ZERO, |l| l.val())
            };
            // the jump from the side n points to, to the side it points
            // away from (module documentation)
            let jump = radiance(-1.0) - radiance(1.0);
            let value = jump * (v_n * self.total);
            if !value.is_finite() {
                non_finite += 1;
            } else if value != Vec3::ZERO {
                out.push(Splat {
                    x,
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
    fn filter_integrals() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        let bx = ReconstructionFilter::Box;
        assert!(close(filter_integral(&bx, -10.0, 10.0), 1.0));
        assert!(close(filter_integral(&bx, 0.0, 10.0), 0.5));
        assert!(close(filter_integral(&bx, -0.2, 0.1), 0.3));
        let tent = ReconstructionFilter::Tent { radius: 1.0 };
        assert!(close(filter_integral(&tent, -5.0, 5.0), 1.0));
        assert!(close(filter_integral(&tent, 0.5, 5.0), 0.125));
        let g = ReconstructionFilter::Gaussian {
            stddev: 0.5,
            radius: 2.0,
        };
        // a fine midpoint sum
        let n = 200_000;
        let sum: f64 = (0..n)
            .map(|i| g.eval(-0.7 + 2.0 * (i as f32 + 0.5) / n as f32) as f64)
            .sum::<f64>()
            * 2.0
            / n as f64;
        assert!((filter_integral(&g, -0.7, 1.3) - sum).abs() < 1e-5);
    }

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
