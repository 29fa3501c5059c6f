//! The acceleration structure: one compressed wide BVH (CWBVH, Ylitie et
//! al. 2017, "Efficient Incoherent Ray Traversal on GPUs Through Compressed
//! Wide BVHs"; built by PLOC with reinsertion, via the `obvhs` crate) over
//! all primitives of all shapes: every triangle of every mesh, and one
//! primitive per analytic shape (sphere, disk).
//!
//! Triangle data for traversal is stored in BVH primitive order in one
//! compact array (`v0`, `v0 - v1`, `v2 - v0`, their cross product: 64
//! bytes, one cache line each), so the hot loop has no indirection.
//! Triangles are two-sided (no backface culling). Analytic primitives sit
//! in the same array as a sentinel (zero edges, index in `v0.x`) handled
//! off the hot path.
//!
//! After vertex positions (or sphere/disk parameters) change, [`Accel::update`]
//! refits the binary BVH kept from the build (same topology, new boxes) and
//! re-derives the wide BVH from it, without a new PLOC build.

use crate::geometry::shapes::disk::DiskFrame;
use crate::geometry::shapes::{Disk, Sphere};
use crate::geometry::{Hit, Ray, Shape};
use crate::params::ParamStore;
use glam::{UVec2, Vec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::node::{extract_byte64, CwBvhNode};
use obvhs::cwbvh::CwBvh;
use obvhs::ploc::PlocBuilder;
use obvhs::BvhBuildParams;

/// A triangle laid out for intersection (as in madmann91's `bvh` library):
/// `e1 = v0 - v1`, `e2 = v2 - v0`, `ng = e1 × e2`.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C)]
struct PackedTri {
    v0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
    ng: Vec3A,
}

impl PackedTri {
    fn new(p0: Vec3, p1: Vec3, p2: Vec3) -> PackedTri {
        let (v0, v1, v2) = (Vec3A::from(p0), Vec3A::from(p1), Vec3A::from(p2));
        let e1 = v0 - v1;
        let e2 = v2 - v0;
        PackedTri {
            v0,
            e1,
            e2,
            ng: e1.cross(e2),
        }
    }
    fn analytic(index: u32) -> PackedTri {
        PackedTri {
            v0: Vec3A::new(f32::from_bits(index), 0.0, 0.0),
            ..Default::default()
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Analytic {
    Sphere { c: Vec3, r: f32 },
    Disk(DiskFrame),
}

impl Analytic {
    fn aabb(&self) -> Aabb {
        match self {
            Analytic::Sphere { c, r } => Aabb::new((*c - *r).into(), (*c + *r).into()),
            Analytic::Disk(f) => {
                let ext = (f.a0 * f.a0 + f.a1 * f.a1).powf(0.5);
                Aabb::new((f.c - ext).into(), (f.c + ext).into())
            }
        }
    }
    #[inline]
    fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> f32 {
        match self {
            Analytic::Sphere { c, r } => Sphere::intersect_f32(*c, *r, o, d, tmin, tmax),
            Analytic::Disk(f) => Disk::intersect_f32(f, o, d, tmin, tmax),
        }
    }
}

/// Which of the (up to) eight children of a CWBVH node the ray overlaps
/// on `[ray.tmin, ray.tmax]`, as the hit mask the `obvhs::traverse!` loop
/// expects (child-node bits in the high byte, leaf-primitive bits below).
///
/// Same semantics as obvhs' `CwBvhNode::intersect_ray`, but the eight
/// quantised child planes per axis are widened from bytes to floats with
/// SSE2 unpacks instead of scalar conversions, near/far planes are chosen
/// once per axis, and the ray's own `tmin` is honoured.
#[inline(always)]
fn intersect_node(node: &CwBvhNode, ray: &obvhs::ray::Ray, oct_inv4: u32) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        let e = node.compute_extent();
        let inv = e * ray.inv_direction;
        let org = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
        let d = ray.direction;
        let pick = |neg: bool, lo: &[u8; 8], hi: &[u8; 8]| -> ([u8; 8], [u8; 8]) {
            if neg {
                (*hi, *lo)
            } else {
                (*lo, *hi)
            }
        };
        let (xn, xf) = pick(d.x < 0.0, &node.child_min_x, &node.child_max_x);
        let (yn, yf) = pick(d.y < 0.0, &node.child_min_y, &node.child_max_y);
        let (zn, zf) = pick(d.z < 0.0, &node.child_min_z, &node.child_max_z);
        // SAFETY: SSE2 is part of the x86_64 baseline; the loads read 8
        // bytes from 8-byte arrays.
        let mask = unsafe {
            #[inline(always)]
            unsafe fn widen(v: &[u8; 8]) -> (__m128, __m128) {
                let z = _mm_setzero_si128();
                let b = _mm_loadl_epi64(v.as_ptr() as *const __m128i);
                let w = _mm_unpacklo_epi8(b, z);
                (
                    _mm_cvtepi32_ps(_mm_unpacklo_epi16(w, z)),
                    _mm_cvtepi32_ps(_mm_unpackhi_epi16(w, z)),
                )
            }
            let (ix, iy, iz) = (_mm_set1_ps(inv.x), _mm_set1_ps(inv.y), _mm_set1_ps(inv.z));
            let (ox, oy, oz) = (_mm_set1_ps(org.x), _mm_set1_ps(org.y), _mm_set1_ps(org.z));
            let slab = |q: __m128, i: __m128, o: __m128| _mm_add_ps(_mm_mul_ps(q, i), o);
            let (xn0, xn1) = widen(&xn);
            let (xf0, xf1) = widen(&xf);
            let (yn0, yn1) = widen(&yn);
            let (yf0, yf1) = widen(&yf);
            let (zn0, zn1) = widen(&zn);
            let (zf0, zf1) = widen(&zf);
            let tmin_r = _mm_set1_ps(ray.tmin);
            let tmax_r = _mm_set1_ps(ray.tmax);
            let near = |x: __m128, y: __m128, z: __m128| {
                _mm_max_ps(
                    _mm_max_ps(slab(x, ix, ox), slab(y, iy, oy)),
                    _mm_max_ps(slab(z, iz, oz), tmin_r),
                )
            };
            let far = |x: __m128, y: __m128, z: __m128| {
                _mm_min_ps(
                    _mm_min_ps(slab(x, ix, ox), slab(y, iy, oy)),
                    _mm_min_ps(slab(z, iz, oz), tmax_r),
                )
            };
            let m0 = _mm_movemask_ps(_mm_cmple_ps(near(xn0, yn0, zn0), far(xf0, yf0, zf0)));
            let m1 = _mm_movemask_ps(_mm_cmple_ps(near(xn1, yn1, zn1), far(xf1, yf1, zf1)));
            (m0 | (m1 << 4)) as u32
        };
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        let mut m = mask;
        while m != 0 {
            let j = m.trailing_zeros() as usize;
            m &= m - 1;
            hit_mask |= extract_byte64(child_bits8, j) << extract_byte64(bit_index8, j);
        }
        hit_mask
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        node.intersect_ray(ray, oct_inv4)
    }
}

/// Closest-hit and any-hit ray queries over all shapes of a scene.
#[derive(Clone, Default)]
pub struct Accel {
    bvh2: Bvh2,
    bvh: CwBvh,
    /// Traversal data, in BVH primitive order.
    tris: Vec<PackedTri>,
    /// (shape, primitive) in BVH primitive order.
    refs: Vec<[u32; 2]>,
    /// (shape, primitive) in build order.
    prims: Vec<[u32; 2]>,
    analytic: Vec<Analytic>,
    /// Shape index → index in `analytic` (u32::MAX for meshes).
    analytic_of_shape: Vec<u32>,
}

impl std::fmt::Debug for Accel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Accel")
            .field("primitives", &self.prims.len())
            .field("nodes", &self.bvh.nodes.len())
            .finish()
    }
}

fn collect_prims(shapes: &[Shape]) -> Vec<[u32; 2]> {
    let mut prims = Vec::with_capacity(shapes.iter().map(|s| s.prim_count()).sum());
    for (s, shape) in shapes.iter().enumerate() {
        for p in 0..shape.prim_count() {
            prims.push([s as u32, p as u32]);
        }
    }
    prims
}

impl Accel {
    /// Builds the acceleration structure over all primitives of `shapes`
    /// (positions read from `store`).
    pub fn build(shapes: &[Shape], store: &ParamStore) -> Accel {
        let mut a = Accel {
            prims: collect_prims(shapes),
            ..Default::default()
        };
        a.refresh_analytic(shapes, store);
        let aabbs = a.aabbs(shapes, store);
        if aabbs.is_empty() {
            return a;
        }
        // obvhs' "slow" preset without spatial splits (which need
        // triangles and would break refitting): ~15% faster traversal than
        // "medium" on the 327k-triangle reference mesh, ~0.35 s build.
        let p = BvhBuildParams::slow_build();
        let mut bvh2 = PlocBuilder::with_capacity(aabbs.len()).build(
            p.ploc_search_distance,
            &aabbs,
            (0..aabbs.len() as u32).collect(),
            p.sort_precision,
            p.search_depth_threshold,
        );
        ReinsertionOptimizer::default().run(&mut bvh2, p.reinsertion_batch_ratio, None);
        a.bvh2 = bvh2;
        a.finish(shapes, store);
        a
    }

    /// Centre and radius of a sphere enclosing all shapes (placing
    /// environment and directional emitters); the unit sphere when empty.
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        match self.bvh2.nodes.first() {
            Some(root) => {
                let b = root.aabb();
                let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
                ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
            }
            None => (Vec3::ZERO, 1.0),
        }
    }

    /// Updates the structure after geometry parameters changed: refits the
    /// boxes of the existing tree (rebuilds only if the primitive set
    /// changed).
    pub fn update(&mut self, shapes: &[Shape], store: &ParamStore) {
        if collect_prims(shapes) != self.prims || self.bvh2.nodes.is_empty() {
            *self = Accel::build(shapes, store);
            return;
        }
        self.refresh_analytic(shapes, store);
        let aabbs = self.aabbs(shapes, store);
        let idx = &self.bvh2.primitive_indices;
        for node in self.bvh2.nodes.iter_mut() {
            if node.is_leaf() {
                let first = node.first_index as usize;
                let mut b = Aabb::empty();
                for &i in &idx[first..first + node.prim_count as usize] {
                    b = b.union(&aabbs[i as usize]);
                }
                node.set_aabb(b);
            }
        }
        self.bvh2.refit_all();
        self.finish(shapes, store);
    }

    fn refresh_analytic(&mut self, shapes: &[Shape], store: &ParamStore) {
        self.analytic.clear();
        self.analytic_of_shape.clear();
        for s in shapes {
            let a = match s {
                Shape::Mesh(_) => None,
                Shape::Sphere(sp) => {
                    let (c, r) = sp.center_radius(store);
                    Some(Analytic::Sphere { c, r })
                }
                Shape::Disk(d) => Some(Analytic::Disk(d.frame(store))),
            };
            match a {
                Some(a) => {
                    self.analytic_of_shape.push(self.analytic.len() as u32);
                    self.analytic.push(a);
                }
                None => self.analytic_of_shape.push(u32::MAX),
            }
        }
    }

    fn aabbs(&self, shapes: &[Shape], store: &ParamStore) -> Vec<Aabb> {
        self.prims
            .iter()
            .map(|&[s, p]| match &shapes[s as usize] {
                Shape::Mesh(m) => {
                    let [p0, p1, p2] = m.triangle(store, p as usize);
                    Aabb::new(p0.min(p1).min(p2).into(), p0.max(p1).max(p2).into())
                }
                _ => self.analytic[self.analytic_of_shape[s as usize] as usize].aabb(),
            })
            .collect()
    }

    /// Derives the wide BVH from the binary one and packs the primitives
    /// in its order.
    fn finish(&mut self, shapes: &[Shape], store: &ParamStore) {
        self.bvh = bvh2_to_cwbvh(&self.bvh2, 3, true, false);
        self.refs = self
            .bvh
            .primitive_indices
            .iter()
            .map(|&i| self.prims[i as usize])
            .collect();
        self.tris = self
            .refs
            .iter()
            .map(|&[s, p]| match &shapes[s as usize] {
                Shape::Mesh(m) => {
                    let [p0, p1, p2] = m.triangle(store, p as usize);
                    PackedTri::new(p0, p1, p2)
                }
                _ => PackedTri::analytic(self.analytic_of_shape[s as usize]),
            })
            .collect();
    }

    /// Number of primitives (triangles and analytic shapes).
    pub fn prim_count(&self) -> usize {
        self.prims.len()
    }

    /// The traversal ray. Negative zeros in the direction are made
    /// positive (`-0.0 + 0.0 = +0.0`): obvhs picks slab sides with `d < 0`
    /// but inverts `-0.0` to a negative number, which would make
    /// axis-aligned rays miss.
    #[inline(always)]
    fn bvh_ray(ray: &Ray) -> obvhs::ray::Ray {
        let d = Vec3A::from(ray.d) + Vec3A::ZERO;
        obvhs::ray::Ray::new(ray.o.into(), d, ray.tmin, ray.tmax)
    }

    /// The closest hit on the open interval `(ray.tmin, ray.tmax)`.
    /// For triangles, `Hit::uv` holds the barycentrics `(b1, b2)` of
    /// `p = (1 - b1 - b2) p0 + b1 p1 + b2 p2`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if self.bvh.nodes.is_empty() {
            return None;
        }
        let mut bray = Self::bvh_ray(ray);
        let o = bray.origin;
        let d = bray.direction;
        let mut best = u32::MAX;
        let (mut bu, mut bv) = (0.0f32, 0.0f32);
        let tris = &self.tris[..];
        let mut state = self.bvh.new_traversal(d);
        let mut node;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            intersect_node(node, &bray, state.oct_inv4),
            {
                let id = state.primitive_id as usize;
                let tri = &tris[id];
                let c = tri.v0 - o;
                let den = tri.ng.dot(d);
                if den != 0.0 {
                    // sign-normalised edge tests before any division
                    // (as Embree's Möller–Trumbore intersector)
                    let sgn = den.to_bits() & 0x8000_0000;
                    let flip = |x: f32| f32::from_bits(x.to_bits() ^ sgn);
                    let aden = den.abs();
                    let r = d.cross(c);
                    let u = flip(r.dot(tri.e2));
                    let v = flip(r.dot(tri.e1));
                    if u >= 0.0 && v >= 0.0 && u + v <= aden {
                        let tn = flip(tri.ng.dot(c));
                        if tn > bray.tmin * aden && tn < bray.tmax * aden {
                            let inv = 1.0 / aden;
                            bray.tmax = tn * inv;
                            best = id as u32;
                            bu = u * inv;
                            bv = v * inv;
                        }
                    }
                } else if tri.ng == Vec3A::ZERO {
                    let a = &self.analytic[tri.v0.x.to_bits() as usize];
                    let t = a.intersect(ray.o, ray.d, bray.tmin, bray.tmax);
                    if t < bray.tmax {
                        bray.tmax = t;
                        best = id as u32;
                        bu = 0.0;
                        bv = 0.0;
                    }
                }
            }
        );
        if best == u32::MAX {
            return None;
        }
        let [shape, prim] = self.refs[best as usize];
        Some(Hit {
            t: bray.tmax,
            shape,
            prim,
            uv: Vec2::new(bu, bv),
        })
    }

    /// Whether anything blocks the ray on `(ray.tmin, ray.tmax)` (shadow
    /// rays): stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        if self.bvh.nodes.is_empty() {
            return false;
        }
        let bray = Self::bvh_ray(ray);
        let o = bray.origin;
        let d = bray.direction;
        let tris = &self.tris[..];
        let mut state = self.bvh.new_traversal(d);
        let mut node;
        let mut hit = false;
        'outer: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                intersect_node(node, &bray, state.oct_inv4),
                {
                    let tri = &tris[state.primitive_id as usize];
                    let c = tri.v0 - o;
                    let den = tri.ng.dot(d);
                    if den != 0.0 {
                        let sgn = den.to_bits() & 0x8000_0000;
                        let flip = |x: f32| f32::from_bits(x.to_bits() ^ sgn);
                        let aden = den.abs();
                        let r = d.cross(c);
                        let u = flip(r.dot(tri.e2));
                        let v = flip(r.dot(tri.e1));
                        if u >= 0.0 && v >= 0.0 && u + v <= aden {
                            let tn = flip(tri.ng.dot(c));
                            if tn > bray.tmin * aden && tn < bray.tmax * aden {
                                hit = true;
                                break 'outer;
                            }
                        }
                    } else if tri.ng == Vec3A::ZERO {
                        let a = &self.analytic[tri.v0.x.to_bits() as usize];
                        if a.intersect(ray.o, ray.d, bray.tmin, bray.tmax) < bray.tmax {
                            hit = true;
                            break 'outer;
                        }
                    }
                }
            );
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::{Mesh, MeshData, MeshOptions};
    use crate::geometry::ShapeT;
    use crate::math::Transform;
    use glam::Mat3;

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn dir(&mut self) -> Vec3 {
            crate::math::warp::square_to_uniform_sphere(Vec2::new(self.f(), self.f()))
        }
    }

    /// A bumpy grid mesh of 2·n² triangles over [-1,1]², with a bump.
    fn grid(n: usize, key: &str, z: f32, store: &mut ParamStore) -> Shape {
        let mut d = MeshData::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (
                    -1.0 + 2.0 * i as f32 / n as f32,
                    -1.0 + 2.0 * j as f32 / n as f32,
                );
                d.positions
                    .push(Vec3::new(x, y, z + 0.3 * (3.0 * x).sin() * (2.0 * y).cos()));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                d.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                d.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        Shape::Mesh(
            Mesh::new(
                "ply",
                key,
                key,
                d,
                &Transform::IDENTITY,
                MeshOptions::default(),
                store,
            )
            .unwrap(),
        )
    }

    /// Reference closest hit: every primitive, no BVH.
    fn brute(shapes: &[Shape], store: &ParamStore, ray: &Ray) -> Option<(f32, u32, u32)> {
        let mut best: Option<(f32, u32, u32)> = None;
        let mut tmax = ray.tmax;
        for (s, shape) in shapes.iter().enumerate() {
            for p in 0..shape.prim_count() {
                let t = match shape {
                    Shape::Mesh(m) => {
                        let [p0, p1, p2] = m.triangle(store, p);
                        // independent formulation (Möller–Trumbore, f64)
                        let (o, d) = (ray.o.as_dvec3(), ray.d.as_dvec3());
                        let (a, b, c) = (p0.as_dvec3(), p1.as_dvec3(), p2.as_dvec3());
                        let (e1, e2) = (b - a, c - a);
                        let pv = d.cross(e2);
                        let det = e1.dot(pv);
                        if det.abs() < 1e-14 {
                            continue;
                        }
                        let tv = o - a;
                        let u = tv.dot(pv) / det;
                        let q = tv.cross(e1);
                        let v = d.dot(q) / det;
                        if u < 0.0 || v < 0.0 || u + v > 1.0 {
                            continue;
                        }
                        (e2.dot(q) / det) as f32
                    }
                    Shape::Sphere(sp) => {
                        let (c, r) = sp.center_radius(store);
                        Sphere::intersect_f32(c, r, ray.o, ray.d, ray.tmin, tmax)
                    }
                    Shape::Disk(d) => {
                        Disk::intersect_f32(&d.frame(store), ray.o, ray.d, ray.tmin, tmax)
                    }
                };
                if t > ray.tmin && t < tmax {
                    tmax = t;
                    best = Some((t, s as u32, p as u32));
                }
            }
        }
        best
    }

    fn check_against_brute(
        shapes: &[Shape],
        store: &ParamStore,
        accel: &Accel,
        seed: u64,
        n: usize,
    ) {
        let mut rng = Rng(seed);
        let mut hits = 0;
        for i in 0..n {
            let o = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 6.0;
            let target = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 2.0;
            let mut ray = Ray::new(o, (target - o).normalize());
            if i % 5 == 0 {
                ray.d = rng.dir();
            }
            if i % 7 == 0 {
                ray.tmax = 2.0 + rng.f() * 3.0;
            }
            if i % 11 == 0 {
                // axis-aligned, with negative zeros (-Vec3::X = (-1, -0, -0))
                let axes = [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z];
                ray.d = axes[(i / 11) % 6];
                ray.o = target - ray.d * 4.0;
            }
            let want = brute(shapes, store, &ray);
            let got = accel.intersect(&ray);
            assert_eq!(accel.occluded(&ray), want.is_some(), "ray {i}: {ray:?}");
            match (want, got) {
                (None, None) => {}
                (Some((t, s, p)), Some(h)) => {
                    hits += 1;
                    assert!(
                        (h.t - t).abs() <= 1e-4 * (1.0 + t),
                        "ray {i}: t {} vs {t}",
                        h.t
                    );
                    // the same primitive, unless two are hit at the same t
                    if (h.shape, h.prim) != (s, p) {
                        assert!(
                            (h.t - t).abs() < 1e-5,
                            "ray {i}: ({},{}) vs ({s},{p})",
                            h.shape,
                            h.prim
                        );
                    }
                    // barycentrics reproduce the hit point
                    let si = shapes[h.shape as usize].surface_interaction::<f32>(store, &ray, &h);
                    assert!((si.p.val() - ray.at(h.t)).length() < 1e-3, "ray {i}");
                    assert!((si.t - h.t).abs() < 1e-3 * (1.0 + h.t), "ray {i}");
                    if let Shape::Mesh(m) = &shapes[h.shape as usize] {
                        let [p0, p1, p2] = m.triangle(store, h.prim as usize);
                        let p = p0 * (1.0 - h.uv.x - h.uv.y) + p1 * h.uv.x + p2 * h.uv.y;
                        assert!((p - ray.at(h.t)).length() < 1e-4, "ray {i}");
                    }
                }
                (w, g) => {
                    // allow misses/hits only for grazing rays at an edge
                    panic!("ray {i}: brute {w:?} vs bvh {g:?} ({ray:?})");
                }
            }
        }
        assert!(hits > n / 5, "too few hits ({hits}) for a meaningful test");
    }

    #[test]
    fn closest_hit_equals_brute_force_on_a_mesh() {
        let mut store = ParamStore::new();
        let shapes = vec![grid(24, "g", 0.0, &mut store)];
        let accel = Accel::build(&shapes, &store);
        assert_eq!(accel.prim_count(), 2 * 24 * 24);
        check_against_brute(&shapes, &store, &accel, 7, 3000);
    }

    #[test]
    fn closest_hit_equals_brute_force_on_a_mixed_scene() {
        let mut store = ParamStore::new();
        let rot = Mat3::from_rotation_x(0.4);
        let mut shapes = vec![grid(10, "g", -0.5, &mut store)];
        for (k, (c, r)) in [
            (Vec3::new(0.3, 0.2, 0.4), 0.5),
            (Vec3::new(-0.6, -0.4, 0.1), 0.3),
        ]
        .into_iter()
        .enumerate()
        {
            shapes.push(Shape::Sphere(
                Sphere::new(&format!("s{k}"), c, r, rot, false, &mut store).unwrap(),
            ));
        }
        let t = Transform::translate(Vec3::new(0.0, 0.5, 0.8))
            .after(&Transform::rotate(Vec3::new(1.0, 0.3, 0.0), 50.0))
            .after(&Transform::new(glam::Mat4::from_scale(Vec3::new(0.8, 0.5, 1.0))).unwrap());
        shapes.push(Shape::Disk(Disk::new("d", &t, false, &mut store).unwrap()));
        shapes.push(grid(6, "g2", 0.9, &mut store));
        let accel = Accel::build(&shapes, &store);
        check_against_brute(&shapes, &store, &accel, 11, 3000);
    }

    #[test]
    fn update_refits_after_moving_vertices() {
        let mut store = ParamStore::new();
        let mut shapes = vec![grid(12, "g", 0.0, &mut store)];
        shapes.push(Shape::Sphere(
            Sphere::new(
                "s",
                Vec3::new(0.0, 0.0, 1.0),
                0.3,
                Mat3::IDENTITY,
                false,
                &mut store,
            )
            .unwrap(),
        ));
        let mut accel = Accel::build(&shapes, &store);
        let mut p = store.data(store.id("g.vertex_positions").unwrap()).to_vec();
        for (i, v) in p.iter_mut().enumerate() {
            if i % 3 == 2 {
                *v += 0.7;
            } else {
                *v *= 1.3;
            }
        }
        store.set("g.vertex_positions", &p).unwrap();
        store.set("s.center", &[0.5, -0.2, -0.6]).unwrap();
        let changed = store.take_dirty();
        for s in shapes.iter_mut() {
            s.parameters_changed(&mut store, &changed).unwrap();
        }
        accel.update(&shapes, &store);
        check_against_brute(&shapes, &store, &accel, 3, 2000);
    }

    #[test]
    fn empty_and_single_primitive() {
        let store = ParamStore::new();
        let a = Accel::build(&[], &store);
        let r = Ray::new(Vec3::ZERO, Vec3::Z);
        assert!(a.intersect(&r).is_none() && !a.occluded(&r));
        let mut store = ParamStore::new();
        let shapes = vec![Shape::Sphere(
            Sphere::new(
                "s",
                Vec3::new(0.0, 0.0, 3.0),
                1.0,
                Mat3::IDENTITY,
                false,
                &mut store,
            )
            .unwrap(),
        )];
        let a = Accel::build(&shapes, &store);
        let h = a.intersect(&r).unwrap();
        assert!((h.t - 2.0).abs() < 1e-6);
        // from inside: the far side
        let h = a
            .intersect(&Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::Z))
            .unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        let mut short = r;
        short.tmax = 1.9;
        assert!(a.intersect(&short).is_none() && !a.occluded(&short));
    }
}
