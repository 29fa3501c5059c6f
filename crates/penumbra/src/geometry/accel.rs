//! The acceleration structure: a wide BVH over all primitives of all
//! shapes (every triangle of every mesh, and one primitive per analytic
//! shape: sphere, disk), laid out for SIMD traversal on the CPU in the
//! manner of Embree (Wald et al. 2014, "Embree: A Kernel Framework for
//! Efficient CPU Ray Tracing"): each node holds the boxes of its children
//! as structure-of-arrays, tested against one ray at once, and each leaf
//! holds up to four triangles as one packet (`v0`, `e1 = v0 - v1`, `e2 =
//! v2 - v0`, `ng = e1 × e2` per lane), also tested at once.
//!
//! Nodes are 8-wide (one 256-bit AVX box test per node) when the CPU has
//! AVX, detected at run time ([`Width::detect`]), else 4-wide (SSE on
//! x86-64, glam's portable `Vec4` elsewhere): one build runs on every
//! machine. Wider nodes halve the number of node visits per ray on
//! incoherent rays (Wald, Benthin, Boulos 2008, "Getting Rid of Packets";
//! Embree's BVH8).
//!
//! The tree is built as a binary BVH by PLOC with reinsertion (the `obvhs`
//! crate), then collapsed to wide nodes and leaves of at most three packets
//! by the surface-area-optimal collapse of Ylitie et al. 2017 (a dynamic
//! program over the binary tree, [`Collapse`]), and laid out so that a
//! node's child nodes sit side by side. Triangles are two-sided (no
//! backface culling). Analytic primitives sit in the packets as lanes
//! flagged in a mask (zero edges), handled off the hot path.
//!
//! After vertex positions (or sphere/disk parameters) change, [`Accel::update`]
//! refits the binary BVH kept from the build (same topology, new boxes) and
//! re-derives the wide BVH from it, without a new PLOC build.
//!
//! Instancing is two-level ([`Accel::build_instanced`]): each shape group
//! gets a structure of its own over its shapes, built once; the top-level
//! structure holds the other shapes and one analytic primitive per
//! instance (its box: the group's box transformed), whose intersection
//! transforms the ray into the group's space and traverses the group's
//! structure (`geometry::instance`).

use crate::geometry::huge_pages::HugePageArray;
use crate::geometry::instance::{ray_to_group_space, Instance, ShapeGroup};
use crate::geometry::shapes::cylinder::CylinderFrame;
use crate::geometry::shapes::disk::DiskFrame;
use crate::geometry::shapes::{Cylinder, Disk, Sphere};
use crate::geometry::{Hit, Ray, Shape};
use crate::params::ParamStore;
use glam::{Mat4, Vec2, Vec3, Vec4};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::PlocBuilder;
use obvhs::BvhBuildParams;
use rayon::prelude::*;
use std::mem::MaybeUninit;

mod packet;

#[derive(Clone, Copy, Debug)]
enum Analytic {
    Sphere {
        c: Vec3,
        r: f32,
    },
    Disk(DiskFrame),
    Cylinder(CylinderFrame),
    /// An instance: the world-to-group transform, the group (index into
    /// `Accel::groups`) and the world box.
    Instance {
        to_local: Mat4,
        group: u32,
        bounds: Aabb,
    },
}

impl Analytic {
    fn aabb(&self) -> Aabb {
        match self {
            Analytic::Sphere { c, r } => Aabb::new((*c - *r).into(), (*c + *r).into()),
            Analytic::Disk(f) => {
                let ext = (f.a0 * f.a0 + f.a1 * f.a1).powf(0.5);
                Aabb::new((f.c - ext).into(), (f.c + ext).into())
            }
            // the box of the two end circles bounds the cylinder
            Analytic::Cylinder(f) => {
                let ext = (f.a0 * f.a0 + f.a1 * f.a1).powf(0.5);
                let end = f.c + f.a2;
                Aabb::new((f.c.min(end) - ext).into(), (f.c.max(end) + ext).into())
            }
            Analytic::Instance { bounds, .. } => *bounds,
        }
    }
    #[inline]
    fn intersect(&self, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> f32 {
        match self {
            Analytic::Sphere { c, r } => Sphere::intersect_f32(*c, *r, o, d, tmin, tmax),
            Analytic::Disk(f) => Disk::intersect_f32(f, o, d, tmin, tmax),
            Analytic::Cylinder(f) => Cylinder::intersect_f32(f, o, d, tmin, tmax),
            // traversed by `Accel::analytic_hit` (a hit on another shape)
            Analytic::Instance { .. } => f32::INFINITY,
        }
    }
}

/// Child slot marker: the child is a leaf (index of its first packet in
/// the low bits).
const LEAF: u32 = 0x8000_0000;
/// Child slot marker: no child (its box is empty and never hit).
const EMPTY: u32 = u32::MAX;
/// The most primitives of a leaf (three packets; the collapse decides
/// which subtrees become leaves).
const MAX_LEAF: u32 = 12;
/// Traversal stack entries kept on the machine stack; a tree that needs
/// more (see [`Accel::stack_size`]) gets a heap stack of its exact size,
/// chosen once per ray.
const STACK: usize = 96;
/// Ize 2013 ("Robust BVH Ray Traversal", JCGT 2(2)): rounding the far slab
/// distance `(b - o) · (1/d)` up by this factor keeps the box test
/// conservative (no box a ray touches is missed, flat boxes included).
const FAR_ROUND_UP: f32 = 1.0 + 4.0 * f32::EPSILON;

/// Children per BVH node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum Width {
    #[default]
    Four,
    Eight,
}

impl Width {
    /// The widest the running CPU traverses with SIMD: eight with AVX.
    pub fn detect() -> Width {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            return Width::Eight;
        }
        Width::Four
    }
}

/// A `W`-wide BVH node: the boxes of its children as structure of arrays
/// (`b[0]`: minima, `b[1]`: maxima, per axis, one lane per child) and the
/// children (node index, `LEAF | packet index`, or `EMPTY`, whose box is
/// empty).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node<const W: usize> {
    b: [[[f32; W]; 3]; 2],
    child: [u32; W],
}

impl<const W: usize> Node<W> {
    const EMPTY: Node<W> = Node {
        b: [[[f32::INFINITY; W]; 3], [[f32::NEG_INFINITY; W]; 3]],
        child: [EMPTY; W],
    };

    /// Puts `child`, with box `bb`, in slot `slot`.
    fn set(&mut self, slot: usize, child: u32, bb: &Aabb) {
        self.child[slot] = child;
        self.set_box(slot, bb);
    }

    /// Gives the child in slot `slot` the box `bb`.
    fn set_box(&mut self, slot: usize, bb: &Aabb) {
        for a in 0..3 {
            self.b[0][a][slot] = bb.min[a];
            self.b[1][a][slot] = bb.max[a];
        }
    }

    /// The box of the child in slot `k`.
    fn child_box(&self, k: usize) -> Aabb {
        let side = |s: usize| Vec3::new(self.b[s][0][k], self.b[s][1][k], self.b[s][2][k]);
        Aabb::new(side(0).into(), side(1).into())
    }
}

/// The box test of a node against one ray.
trait BoxTest<const W: usize> {
    /// Which children the ray overlaps on `[tmin, tmax_far]` (bit k: child
    /// k), and the entry distances; see [`TRay::hit_node`].
    fn hit(&self, tr: &TRay, tmin: f32, tmax_far: f32) -> (u32, [f32; W]);
}

impl BoxTest<4> for Node<4> {
    #[inline(always)]
    fn hit(&self, tr: &TRay, tmin: f32, tmax_far: f32) -> (u32, [f32; 4]) {
        let (mask, t0) = tr.hit_node(self, tmin, tmax_far);
        (mask, t0.to_array())
    }
}

#[cfg(target_arch = "x86_64")]
impl BoxTest<8> for Node<8> {
    #[inline(always)]
    fn hit(&self, tr: &TRay, tmin: f32, tmax_far: f32) -> (u32, [f32; 8]) {
        // SAFETY: 8-wide trees exist only on CPUs with AVX
        // (`Accel::build_with_width` caps the width at `Width::detect`).
        unsafe { hit_node8(self, tr, tmin, tmax_far) }
    }
}

/// [`TRay::hit_node`] for eight children: the same arithmetic in the same
/// order on 256-bit registers (`_mm256_max_ps(x, acc)` keeps `acc` when x
/// is NaN, as SSE does).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
fn hit_node8(n: &Node<8>, tr: &TRay, tmin: f32, tmax_far: f32) -> (u32, [f32; 8]) {
    use std::arch::x86_64::*;
    // SAFETY: each pointer is to an array of eight f32 (unaligned loads).
    let b = |side: usize, a: usize| unsafe { _mm256_loadu_ps(n.b[side][a].as_ptr()) };
    let near = |a: usize| {
        let o = _mm256_set1_ps(tr.o[a].x);
        let inv = _mm256_set1_ps(tr.inv[a].x);
        _mm256_mul_ps(_mm256_sub_ps(b(tr.near[a], a), o), inv)
    };
    let far = |a: usize| {
        let o = _mm256_set1_ps(tr.o[a].x);
        let inv = _mm256_set1_ps(tr.inv_far[a].x);
        _mm256_mul_ps(_mm256_sub_ps(b(1 - tr.near[a], a), o), inv)
    };
    let t0 = _mm256_max_ps(
        near(0),
        _mm256_max_ps(near(1), _mm256_max_ps(near(2), _mm256_set1_ps(tmin))),
    );
    let t1 = _mm256_min_ps(
        far(0),
        _mm256_min_ps(far(1), _mm256_min_ps(far(2), _mm256_set1_ps(tmax_far))),
    );
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    let mut out = [0.0; 8];
    // SAFETY: `out` holds eight f32 (unaligned store).
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), t0) };
    (mask, out)
}

/// The nodes of the tree, at the width chosen at build time; the root is
/// node 0.
#[derive(Clone, Debug)]
enum Nodes {
    Four(HugePageArray<Node<4>>),
    #[cfg(target_arch = "x86_64")]
    Eight(HugePageArray<Node<8>>),
}

impl Default for Nodes {
    fn default() -> Nodes {
        Nodes::Four(HugePageArray::default())
    }
}

impl Nodes {
    fn len(&self) -> usize {
        match self {
            Nodes::Four(n) => n.len(),
            #[cfg(target_arch = "x86_64")]
            Nodes::Eight(n) => n.len(),
        }
    }
}

/// Up to four primitives of a leaf, laid out for one SIMD intersection
/// test (as in madmann91's `bvh` library, per lane: `v0`, `e1 = v0 - v1`,
/// `e2 = v2 - v0`, `ng = e1 × e2`). Unused and analytic lanes have zero
/// edges, so the triangle test never reports them.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Tri4 {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    ng: [Vec4; 3],
    /// Per lane: shape index and primitive index within the shape (read
    /// from the packet, which is in cache, rather than from a table).
    shape: [u32; 4],
    prim: [u32; 4],
    /// Lanes (bit k: lane k) holding analytic primitives.
    analytic: u32,
    /// Another packet of the same leaf follows this one.
    more: bool,
}

impl Tri4 {
    /// The packet of the primitives `(shape[k], prim[k])` of its lanes
    /// (`u32::MAX`: an unused lane) at the current vertex positions.
    fn pack(
        shape: [u32; 4],
        prim: [u32; 4],
        more: bool,
        shapes: &[Shape],
        store: &ParamStore,
    ) -> Tri4 {
        let mut lanes = [[Vec3::ZERO; 4]; 4];
        let mut analytic = 0u32;
        for k in 0..4 {
            let (s, p) = (shape[k], prim[k] as usize);
            if s == u32::MAX {
                continue;
            }
            match shapes.get(s as usize) {
                // a zero-area face keeps zero edges, like an
                // unused lane: never hit (see geometry::mesh)
                Some(Shape::Mesh(m)) if m.face_is_degenerate(p) => {}
                Some(Shape::Mesh(m)) => {
                    let [p0, p1, p2] = m.triangle(store, p);
                    let (e1, e2) = (p0 - p1, p2 - p0);
                    lanes[k] = [p0, e1, e2, e1.cross(e2)];
                }
                _ => analytic |= 1 << k,
            }
        }
        let soa = |f: usize| {
            let axis = |a: usize| {
                Vec4::new(
                    lanes[0][f][a],
                    lanes[1][f][a],
                    lanes[2][f][a],
                    lanes[3][f][a],
                )
            };
            [axis(0), axis(1), axis(2)]
        };
        Tri4 {
            v0: soa(0),
            e1: soa(1),
            e2: soa(2),
            ng: soa(3),
            shape,
            prim,
            analytic,
            more,
        }
    }
}

/// The ray as traversal uses it: splatted origin and inverse direction
/// (for the far slab, rounded up once per ray, see [`FAR_ROUND_UP`]), and
/// which box side (min/max) is the near one per axis.
struct TRay {
    o: [Vec4; 3],
    d: [Vec4; 3],
    inv: [Vec4; 3],
    inv_far: [Vec4; 3],
    near: [usize; 3],
}

impl TRay {
    #[inline(always)]
    fn new(ray: &Ray) -> TRay {
        // -0.0 + 0.0 = +0.0: a zero component inverts to +inf and takes
        // the min side as near, consistently
        let d = ray.d + Vec3::ZERO;
        let inv = d.recip();
        let inv_far = inv * FAR_ROUND_UP;
        TRay {
            o: [
                Vec4::splat(ray.o.x),
                Vec4::splat(ray.o.y),
                Vec4::splat(ray.o.z),
            ],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            inv_far: [
                Vec4::splat(inv_far.x),
                Vec4::splat(inv_far.y),
                Vec4::splat(inv_far.z),
            ],
            near: [
                (inv.x < 0.0) as usize,
                (inv.y < 0.0) as usize,
                (inv.z < 0.0) as usize,
            ],
        }
    }

    /// Which children of `n` the ray overlaps on `[tmin, tmax_far]` (bit
    /// k: child k), and the entry distances; `tmax_far` is the ray's tmax
    /// rounded up by [`FAR_ROUND_UP`], as the far slabs are. Slab distances
    /// that are NaN (a zero direction component with the origin on a box
    /// plane) do not constrain the interval.
    ///
    /// The slabs are `(b - o) · inv`, not one FMA `b · inv - o · inv` with
    /// `o · inv` precomputed: the rounding of `o · inv` is relative to the
    /// origin's coordinates, not to the distance, and is not covered by a
    /// relative factor for rays that start near a box (shadow and bounce
    /// rays leave a surface 1e-4 away), so the FMA form is not
    /// conservative (Ize 2013, section 3).
    #[inline(always)]
    fn hit_node(&self, n: &Node<4>, tmin: f32, tmax_far: f32) -> (u32, Vec4) {
        let b = |side: usize, a: usize| Vec4::from_array(n.b[side][a]);
        let near = |a: usize, side: usize| (b(side, a) - self.o[a]) * self.inv[a];
        let far = |a: usize, side: usize| (b(side, a) - self.o[a]) * self.inv_far[a];
        let [nx, ny, nz] = self.near;
        // `max(x, acc)`/`min(x, acc)` keep `acc` when x is NaN (SSE order)
        let t0 = near(0, nx).max(near(1, ny).max(near(2, nz).max(Vec4::splat(tmin))));
        let t1 = far(0, 1 - nx).min(far(1, 1 - ny).min(far(2, 1 - nz).min(Vec4::splat(tmax_far))));
        (t0.cmple(t1).bitmask(), t0)
    }

    /// The triangle lanes of `p` hit on `(tmin, tmax)`: the lane mask and,
    /// per lane, the distance and barycentrics `(b1, b2)` (meaningful for
    /// lanes in the mask). Same arithmetic as a scalar sign-normalised
    /// Möller–Trumbore test (edge tests before any division, as Embree).
    #[inline(always)]
    fn hit_tris(&self, p: &Tri4, tmin: f32, tmax: f32) -> (u32, Vec4, Vec4, Vec4) {
        let dot = |a: &[Vec4; 3], b: &[Vec4; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let c = [
            p.v0[0] - self.o[0],
            p.v0[1] - self.o[1],
            p.v0[2] - self.o[2],
        ];
        let d = &self.d;
        let den = dot(&p.ng, d);
        let s = den.signum();
        let aden = den.abs();
        // r = d × c
        let r = [
            d[1] * c[2] - d[2] * c[1],
            d[2] * c[0] - d[0] * c[2],
            d[0] * c[1] - d[1] * c[0],
        ];
        let u = dot(&r, &p.e2) * s;
        let v = dot(&r, &p.e1) * s;
        let tn = dot(&p.ng, &c) * s;
        let zero = Vec4::ZERO;
        let ok = aden.cmpgt(zero)
            & u.cmpge(zero)
            & v.cmpge(zero)
            & (u + v).cmple(aden)
            & tn.cmpgt(aden * tmin)
            & tn.cmplt(aden * tmax);
        let mask = ok.bitmask();
        if mask == 0 {
            return (0, zero, zero, zero);
        }
        let inv = aden.recip();
        (mask, tn * inv, u * inv, v * inv)
    }
}

/// A traversal stack of entries `E` (a node and what the traversal keeps
/// of it: for one ray its entry distance) over a buffer of at least
/// [`Accel::stack_size`] entries (on the machine stack, or on the heap for
/// unusually deep trees: chosen once per traversal, not per push).
struct Stack<'a, E = (u32, f32)> {
    buf: &'a mut [MaybeUninit<E>],
    len: usize,
}

impl<'a, E: Copy> Stack<'a, E> {
    #[inline(always)]
    fn new(buf: &'a mut [MaybeUninit<E>]) -> Stack<'a, E> {
        Stack { buf, len: 0 }
    }
    #[inline(always)]
    fn push(&mut self, e: E) {
        debug_assert!(self.len < self.buf.len());
        // SAFETY: the buffer holds `Accel::stack_size` entries, the most a
        // traversal of this tree can hold at once (bounded in
        // `Accel::finish` from the tree's depth), so `len` stays in bounds.
        unsafe { *self.buf.get_unchecked_mut(self.len) = MaybeUninit::new(e) };
        self.len += 1;
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.len = 0;
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<E> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: entries below `len` were written by `push`, and `len` is
        // within the buffer (see `push`).
        Some(unsafe { self.buf.get_unchecked(self.len).assume_init() })
    }
}

/// Runs `f` with a stack buffer of at least `size` entries: on the machine
/// stack when [`STACK`] suffices, else on the heap. `f` has one call site,
/// so that the traversal it runs is inlined here rather than called.
#[inline(always)]
fn with_stack<T>(size: usize, f: impl FnOnce(Stack) -> T) -> T {
    let mut local = [const { MaybeUninit::uninit() }; STACK];
    let mut heap = Vec::new();
    let buf: &mut [MaybeUninit<(u32, f32)>] = if size <= STACK {
        &mut local
    } else {
        heap.resize(size, MaybeUninit::uninit());
        &mut heap
    };
    f(Stack::new(buf))
}

/// Node `i` of `nodes`, a child index read from the tree.
#[inline(always)]
fn node<const W: usize>(nodes: &[Node<W>], i: u32) -> &Node<W> {
    debug_assert!((i as usize) < nodes.len());
    // SAFETY: `i` is node 0 (traversal starts only on a non-empty tree) or
    // a non-leaf, non-empty child slot, which `Collapse::fill` set to the
    // index of a node it pushed.
    unsafe { nodes.get_unchecked(i as usize) }
}

/// The closest hit so far of a closest-hit traversal.
struct Closest {
    tmax: f32,
    /// `tmax` rounded up as the far slabs are (see [`TRay::hit_node`]).
    tmax_far: f32,
    best: Option<Hit>,
}

impl Closest {
    #[inline(always)]
    fn new(tmax: f32) -> Closest {
        Closest {
            tmax,
            tmax_far: tmax * FAR_ROUND_UP,
            best: None,
        }
    }
    /// Keeps the hit at `t` of lane `j` of `p` if it is the closest yet.
    /// Of hits at the same distance (coplanar faces: a medium's boundary
    /// on the ground), the lowest (shape, primitive) wins, whatever order
    /// the tree visits them in: results do not depend on how the tree was
    /// built (a rebuild, a refit, 4- or 8-wide nodes), as the brute-force
    /// reference of the tests.
    #[inline(always)]
    fn offer(&mut self, t: f32, p: &Tri4, j: usize, uv: Vec2) {
        let first = |b: &Hit| t == b.t && (p.shape[j], p.prim[j]) < (b.shape, b.prim);
        if t < self.tmax || self.best.as_ref().is_some_and(first) {
            self.tmax = t;
            self.tmax_far = t * FAR_ROUND_UP;
            self.best = Some(Hit {
                t,
                shape: p.shape[j],
                prim: p.prim[j],
                uv,
                instance: None,
            });
        }
    }
    /// Keeps `h` (an analytic primitive's, or one found through an
    /// instance) if it is the closest yet.
    #[inline(always)]
    fn offer_hit(&mut self, h: Hit) {
        if h.t < self.tmax {
            self.tmax = h.t;
            self.tmax_far = h.t * FAR_ROUND_UP;
            self.best = Some(h);
        }
    }
}

/// How [`Collapse`] represents a binary subtree in at most `i` slots of a
/// wide node.
#[derive(Clone, Copy, Debug)]
enum Form {
    /// One leaf holding all its primitives.
    Leaf,
    /// One wide node over the roots of its two binary children.
    Node,
    /// The roots of its left child in at most `.0` slots and of its right
    /// child in at most `.1`.
    Split(u8, u8),
}

/// Collapses the binary BVH `bvh2` into `W`-wide nodes and leaf packets,
/// choosing the wide tree of least SAH cost among all that the binary tree
/// contains (Ylitie, Karras, Laine 2017, "Efficient Incoherent Ray
/// Traversal on GPUs Through Compressed Wide BVHs", section 4.1): a
/// dynamic program over the binary nodes that, for each and for each
/// number of slots `i` in `1..=W`, finds the cheapest way to represent its
/// subtree as at most `i` roots (leaves or wide nodes), so that nodes are
/// filled and leaves packed where the surface areas allow it.
struct Collapse<'a, const W: usize> {
    bvh2: &'a Bvh2,
    /// Per primitive (build-order index): whether it is analytic (tested
    /// on its own, not in a packet's SIMD lanes).
    analytic: &'a [bool],
    any_analytic: bool,
    /// Primitives below each binary node, and how many are analytic.
    count: Vec<u32>,
    analytic_count: Vec<u32>,
    /// Per binary node, for `i` slots (index `i - 1`): the least cost of
    /// its subtree in at most `i` roots, and its form.
    cost: Vec<[f32; W]>,
    form: Vec<[Form; W]>,
    /// Per binary node: how a wide node made of it splits its `W` slots
    /// between its children's roots (slots of the left child).
    node_split: Vec<u8>,
    nodes: Vec<Node<W>>,
    /// Per filled child slot: (wide node, slot, the binary node it holds),
    /// so that a refit can redo the slot's box.
    slot_sources: Vec<SlotSource>,
    leaves: Vec<[u32; 4]>,
    leaf_more: Vec<bool>,
    depth: usize,
}

/// Child slot `slot` of wide node `node` holds binary node `binary`.
#[derive(Clone, Copy, Debug)]
struct SlotSource {
    node: u32,
    slot: u8,
    binary: u32,
}

/// SAH cost, per unit of surface area, of visiting a wide node (its box
/// test, ordering the hit children, the stack) and of testing one leaf
/// packet. Measured on the 327k-triangle reference mesh against Embree's
/// rays (`scripts/bench_rays.py`, `scripts/ab_bench.py`,
/// docs/perf/traversal.md): a packet at 0.2 of a node with leaves of up
/// to three packets gives 8.5k nodes and 99.5k packets (13.8k and 110k at
/// 0.5 with two) and traverses 4–5 % faster; a packet costing as much as
/// a node makes the collapse split leaves into more slots.
const NODE_COST: f32 = 1.0;
const PACKET_COST: f32 = 0.2;
/// SAH cost of testing one analytic primitive of a leaf: a call, a square
/// root and a division (a sphere) for one primitive, where a packet tests
/// four triangles at once. Costed as a node, so that the collapse gives
/// analytic primitives leaves of their own where their boxes separate
/// them (docs/perf/traversal.md, "Analytic primitives in leaves").
const ANALYTIC_COST: f32 = 1.0;

/// SAH cost of a leaf of `count` primitives (in packets of four), of
/// which `analytic` are analytic, whose box has half area `area`.
fn leaf_cost(area: f32, count: u32, analytic: u32) -> f32 {
    area * (PACKET_COST * count.div_ceil(4) as f32 + ANALYTIC_COST * analytic as f32)
}

impl<const W: usize> Collapse<'_, W> {
    /// `analytic[i]`: whether primitive `i` is analytic.
    fn new<'a>(bvh2: &'a Bvh2, analytic: &'a [bool]) -> Collapse<'a, W> {
        let n = bvh2.nodes.len();
        let mut c = Collapse {
            bvh2,
            analytic,
            any_analytic: analytic.contains(&true),
            count: vec![0; n],
            analytic_count: vec![0; n],
            cost: vec![[0.0; W]; n],
            form: vec![[Form::Leaf; W]; n],
            node_split: vec![0; n],
            nodes: Vec::new(),
            slot_sources: Vec::new(),
            leaves: Vec::new(),
            leaf_more: Vec::new(),
            depth: 0,
        };
        // children after their parents (`Accel::build_over` orders the
        // tree so): one sweep from the last node plans children first
        debug_assert!(bvh2.children_are_ordered_after_parents || n < 2);
        for i in (0..n).rev() {
            c.plan(i);
        }
        c
    }

    /// Collapses the whole tree: the root is node 0.
    fn run(mut self) -> Self {
        // (a binary leaf is always planned as a leaf)
        if matches!(self.form[0][0], Form::Leaf) {
            // a root leaf: one node with one child
            let leaf = self.leaf(0);
            self.nodes.push(Node::EMPTY);
            self.set_slot(0, 0, leaf, 0);
            self.depth = 1;
        } else {
            self.nodes.push(Node::EMPTY);
            self.fill(0, 0, 0);
        }
        self
    }

    /// Puts `child`, made of binary node `b`, in slot `slot` of wide node
    /// `idx`, with `b`'s box.
    fn set_slot(&mut self, idx: usize, slot: usize, child: u32, b: usize) {
        self.nodes[idx].set(slot, child, self.bvh2.nodes[b].aabb());
        self.slot_sources.push(SlotSource {
            node: idx as u32,
            slot: slot as u8,
            binary: b as u32,
        });
    }

    /// The most entries a traversal stack holds: each level pushes at
    /// most `W - 1`.
    fn stack_size(&self) -> usize {
        (W - 1) * self.depth + 2
    }

    /// Fills `count`, `cost`, `form` and `node_split` of binary node `i`
    /// from those of its children.
    fn plan(&mut self, i: usize) {
        let n = &self.bvh2.nodes[i];
        let area = n.aabb().half_area();
        if n.is_leaf() {
            let count = n.prim_count;
            let first = n.first_index as usize;
            let ids = &self.bvh2.primitive_indices[first..first + count as usize];
            // (read only where there are analytic primitives: the reads
            // are scattered, one cache miss per primitive of a large mesh)
            let analytic = if self.any_analytic {
                ids.iter().filter(|&&p| self.analytic[p as usize]).count() as u32
            } else {
                0
            };
            self.count[i] = count;
            self.analytic_count[i] = analytic;
            self.cost[i] = [leaf_cost(area, count, analytic); W];
            self.form[i] = [Form::Leaf; W];
            return;
        }
        let (l, r) = (n.first_index as usize, n.first_index as usize + 1);
        let count = self.count[l] + self.count[r];
        let analytic = self.analytic_count[l] + self.analytic_count[r];
        self.count[i] = count;
        self.analytic_count[i] = analytic;
        // best[j]: the cheapest split of j + 1 slots between the children,
        // and how many of them go to the left one (k; j + 1 - k right)
        let mut best = [(f32::INFINITY, 0u8); W];
        for (j, b) in best.iter_mut().enumerate().skip(1) {
            for k in 1..=j {
                let c = self.cost[l][k - 1] + self.cost[r][j - k];
                if c < b.0 {
                    *b = (c, k as u8);
                }
            }
        }
        let leaf = if count <= MAX_LEAF {
            leaf_cost(area, count, analytic)
        } else {
            f32::INFINITY
        };
        let node = area * NODE_COST + best[W - 1].0;
        self.node_split[i] = best[W - 1].1;
        let (mut cost, mut form) = if leaf <= node {
            (leaf, Form::Leaf)
        } else {
            (node, Form::Node)
        };
        self.cost[i][0] = cost;
        self.form[i][0] = form;
        for (j, &(c, k)) in best.iter().enumerate().skip(1) {
            if c < cost {
                cost = c;
                form = Form::Split(k, (j + 1) as u8 - k);
            }
            self.cost[i][j] = cost;
            self.form[i][j] = form;
        }
    }

    /// The roots representing binary node `i` in at most `slots` slots:
    /// `(binary node, is a leaf)`.
    fn roots(&self, i: usize, slots: usize, out: &mut Vec<(usize, bool)>) {
        match self.form[i][slots - 1] {
            Form::Leaf => out.push((i, true)),
            Form::Node => out.push((i, false)),
            Form::Split(k, m) => {
                let l = self.bvh2.nodes[i].first_index as usize;
                self.roots(l, k as usize, out);
                self.roots(l + 1, m as usize, out);
            }
        }
    }

    /// Build-order primitive indices below binary node `i`.
    fn gather(&self, i: usize, out: &mut Vec<u32>) {
        let n = &self.bvh2.nodes[i];
        let f = n.first_index as usize;
        if n.is_leaf() {
            out.extend_from_slice(&self.bvh2.primitive_indices[f..f + n.prim_count as usize]);
        } else {
            self.gather(f, out);
            self.gather(f + 1, out);
        }
    }

    /// A leaf of the primitives below binary node `i`, in packets of four:
    /// its child slot.
    fn leaf(&mut self, i: usize) -> u32 {
        let mut ids = Vec::new();
        self.gather(i, &mut ids);
        let first = self.leaves.len() as u32;
        for (k, chunk) in ids.chunks(4).enumerate() {
            let mut lanes = [u32::MAX; 4];
            lanes[..chunk.len()].copy_from_slice(chunk);
            if k > 0 {
                *self.leaf_more.last_mut().expect("a packet precedes") = true;
            }
            self.leaves.push(lanes);
            self.leaf_more.push(false);
        }
        LEAF | first
    }

    /// The wide node `idx` (already pushed) for the interior binary node
    /// `i`, over the roots of its children as planned. Its leaves' packets
    /// are laid out together, then its child nodes side by side, then
    /// their subtrees: what one visit of the node may touch next is close
    /// together in memory.
    fn fill(&mut self, idx: usize, i: usize, depth: usize) {
        self.depth = self.depth.max(depth + 1);
        let l = self.bvh2.nodes[i].first_index as usize;
        let k = self.node_split[i] as usize;
        let mut kids = Vec::with_capacity(W);
        self.roots(l, k, &mut kids);
        self.roots(l + 1, W - k, &mut kids);
        let mut inner = Vec::with_capacity(W);
        for (slot, &(b, is_leaf)) in kids.iter().enumerate() {
            let c = if is_leaf {
                self.leaf(b)
            } else {
                self.nodes.push(Node::EMPTY);
                inner.push((self.nodes.len() - 1, b));
                (self.nodes.len() - 1) as u32
            };
            self.set_slot(idx, slot, c, b);
        }
        for (n, b) in inner {
            self.fill(n, b, depth + 1);
        }
    }
}

/// Size and fill of an [`Accel`]'s wide tree.
#[derive(Clone, Debug, Default)]
pub struct TreeStats {
    pub width: usize,
    pub nodes: usize,
    /// Non-empty child slots of all nodes.
    pub children: usize,
    pub leaves: usize,
    /// Leaf packets and the lanes of them that hold a primitive.
    pub packets: usize,
    pub lanes: usize,
    /// Sum over node children of their surface area relative to the
    /// root's: the expected node visits (interior children) and leaf
    /// visits of a ray crossing the root box (the surface-area heuristic).
    pub sah_nodes: f32,
    pub sah_leaves: f32,
}

/// Closest-hit and any-hit ray queries over all shapes of a scene.
#[derive(Clone, Default)]
pub struct Accel {
    bvh2: Bvh2,
    width: Width,
    nodes: Nodes,
    /// The binary node each child slot of `nodes` was made of (for refits).
    slot_sources: Vec<SlotSource>,
    /// Leaf packets.
    tris: HugePageArray<Tri4>,
    /// Traversal stack size the tree needs.
    stack_size: usize,
    /// (shape, primitive) in build order.
    prims: Vec<[u32; 2]>,
    analytic: Vec<Analytic>,
    /// Shape index → index in `analytic` (u32::MAX for meshes); instance
    /// `i` is shape index `n_shapes + i`.
    analytic_of_shape: Vec<u32>,
    /// The shapes this structure holds (`None`: all): a shape group's, or
    /// the shapes outside every group.
    selection: Option<Vec<u32>>,
    /// The structure of each shape group (two-level instancing).
    groups: Vec<Accel>,
    /// Number of shapes of the scene: instances come after them.
    n_shapes: u32,
}

impl std::fmt::Debug for Accel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Accel")
            .field("primitives", &self.prims.len())
            .field("nodes", &self.nodes.len())
            .finish()
    }
}

impl Accel {
    /// Builds the acceleration structure over all primitives of `shapes`
    /// (positions read from `store`), as wide as the CPU allows.
    pub fn build(shapes: &[Shape], store: &ParamStore) -> Accel {
        Accel::build_with_width(shapes, store, Width::detect())
    }

    /// [`Accel::build`] with nodes of at most `width` children (capped at
    /// [`Width::detect`]): for tests and benchmarks of the narrower
    /// kernel.
    pub fn build_with_width(shapes: &[Shape], store: &ParamStore, width: Width) -> Accel {
        Accel::build_over(shapes, None, Vec::new(), &[], store, width)
    }

    /// The two-level structure of a scene with shape groups: one structure
    /// per group over its shapes, and the top level over the shapes in no
    /// group and one primitive per instance of a non-empty group.
    /// `instances[i].group` indexes `groups`.
    pub fn build_instanced(
        shapes: &[Shape],
        groups: &[ShapeGroup],
        instances: &[Instance],
        store: &ParamStore,
    ) -> Accel {
        if groups.is_empty() {
            return Accel::build(shapes, store);
        }
        let width = Width::detect();
        let sub = groups
            .iter()
            .map(|g| {
                Accel::build_over(
                    shapes,
                    Some(g.members.clone()),
                    Vec::new(),
                    &[],
                    store,
                    width,
                )
            })
            .collect();
        let mut grouped = vec![false; shapes.len()];
        for &m in groups.iter().flat_map(|g| &g.members) {
            grouped[m as usize] = true;
        }
        let top = (0..shapes.len() as u32)
            .filter(|&s| !grouped[s as usize])
            .collect();
        Accel::build_over(shapes, Some(top), sub, instances, store, width)
    }

    /// Builds over the shapes `selection` (all if `None`) and `instances`
    /// of the structures `groups`.
    fn build_over(
        shapes: &[Shape],
        selection: Option<Vec<u32>>,
        groups: Vec<Accel>,
        instances: &[Instance],
        store: &ParamStore,
        width: Width,
    ) -> Accel {
        let mut a = Accel {
            width: width.min(Width::detect()),
            selection,
            groups,
            n_shapes: shapes.len() as u32,
            ..Default::default()
        };
        a.prims = a.collect_prims(shapes, instances);
        a.refresh_analytic(shapes, instances, store);
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
        bvh2.reorder_in_stack_traversal_order();
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
        self.update_instanced(shapes, &[], store);
    }

    /// [`Accel::update`] of a structure from [`Accel::build_instanced`]:
    /// refits the groups' structures, then the top level with the
    /// instances' current transforms.
    pub fn update_instanced(
        &mut self,
        shapes: &[Shape],
        instances: &[Instance],
        store: &ParamStore,
    ) {
        for g in &mut self.groups {
            g.update_instanced(shapes, &[], store);
        }
        if self.collect_prims(shapes, instances) != self.prims || self.bvh2.nodes.is_empty() {
            let (selection, groups) = (self.selection.take(), std::mem::take(&mut self.groups));
            *self = Accel::build_over(shapes, selection, groups, instances, store, self.width);
            return;
        }
        self.refresh_analytic(shapes, instances, store);
        let aabbs = self.aabbs(shapes, store);
        let idx = &self.bvh2.primitive_indices;
        // (on all cores: a leaf's primitives are scattered over `aabbs`)
        self.bvh2
            .nodes
            .par_iter_mut()
            .with_min_len(1024)
            .filter(|node| node.is_leaf())
            .for_each(|node| {
                let first = node.first_index as usize;
                let mut b = Aabb::empty();
                for &i in &idx[first..first + node.prim_count as usize] {
                    b = b.union(&aabbs[i as usize]);
                }
                node.set_aabb(b);
            });
        self.bvh2.refit_all();
        self.refit_wide(shapes, store);
    }

    /// Primitives in build order: those of the selected shapes, then one
    /// per instance of a non-empty group (shape index `n_shapes + i`).
    fn collect_prims(&self, shapes: &[Shape], instances: &[Instance]) -> Vec<[u32; 2]> {
        let mut prims = Vec::new();
        let mut add = |s: u32| {
            for p in 0..shapes[s as usize].prim_count() {
                prims.push([s, p as u32]);
            }
        };
        match &self.selection {
            Some(sel) => sel.iter().for_each(|&s| add(s)),
            None => (0..shapes.len() as u32).for_each(add),
        }
        for (i, inst) in instances.iter().enumerate() {
            if !self.groups[inst.group as usize].prims.is_empty() {
                prims.push([self.n_shapes + i as u32, 0]);
            }
        }
        prims
    }

    fn refresh_analytic(&mut self, shapes: &[Shape], instances: &[Instance], store: &ParamStore) {
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
                Shape::Cylinder(c) => Some(Analytic::Cylinder(c.frame(store))),
            };
            match a {
                Some(a) => {
                    self.analytic_of_shape.push(self.analytic.len() as u32);
                    self.analytic.push(a);
                }
                None => self.analytic_of_shape.push(u32::MAX),
            }
        }
        for inst in instances {
            let bounds = match self.groups[inst.group as usize].bvh2.nodes.first() {
                Some(root) => {
                    let b = root.aabb();
                    let (lo, hi) = inst.bounds(b.min.into(), b.max.into());
                    Aabb::new(lo.into(), hi.into())
                }
                None => Aabb::empty(),
            };
            self.analytic_of_shape.push(self.analytic.len() as u32);
            self.analytic.push(Analytic::Instance {
                to_local: inst.transform().inv,
                group: inst.group,
                bounds,
            });
        }
    }

    fn aabbs(&self, shapes: &[Shape], store: &ParamStore) -> Vec<Aabb> {
        self.prims
            .par_iter()
            .with_min_len(4096)
            .map(|&[s, p]| match shapes.get(s as usize) {
                Some(Shape::Mesh(m)) => {
                    let [p0, p1, p2] = m.triangle(store, p as usize);
                    Aabb::new(p0.min(p1).min(p2).into(), p0.max(p1).max(p2).into())
                }
                _ => self.analytic[self.analytic_of_shape[s as usize] as usize].aabb(),
            })
            .collect()
    }

    /// Per primitive (build order): whether it is analytic (an analytic
    /// shape's, or an instance's: those `analytic_of_shape` indexes).
    fn analytic_prims(&self) -> Vec<bool> {
        self.prims
            .iter()
            .map(|&[s, _]| self.analytic_of_shape[s as usize] != u32::MAX)
            .collect()
    }

    /// Derives the wide BVH from the binary one and packs the primitives
    /// of each leaf.
    fn finish(&mut self, shapes: &[Shape], store: &ParamStore) {
        let analytic = self.analytic_prims();
        let (leaves, more) = match self.width {
            Width::Four => {
                let c = Collapse::<4>::new(&self.bvh2, &analytic).run();
                self.stack_size = c.stack_size();
                self.nodes = Nodes::Four(c.nodes.into());
                self.slot_sources = c.slot_sources;
                (c.leaves, c.leaf_more)
            }
            #[cfg(target_arch = "x86_64")]
            Width::Eight => {
                let c = Collapse::<8>::new(&self.bvh2, &analytic).run();
                self.stack_size = c.stack_size();
                self.nodes = Nodes::Eight(c.nodes.into());
                self.slot_sources = c.slot_sources;
                (c.leaves, c.leaf_more)
            }
            #[cfg(not(target_arch = "x86_64"))]
            Width::Eight => unreachable!("Width::detect gives Four off x86-64"),
        };
        // the leaves' triangles are scattered over the meshes' arrays:
        // packed on all cores, so that their cache misses overlap
        let prims = &self.prims;
        self.tris = HugePageArray::from_fn_par(leaves.len(), |i| {
            let (mut shape, mut prim) = ([u32::MAX; 4], [u32::MAX; 4]);
            for (k, &id) in leaves[i].iter().enumerate() {
                if id != u32::MAX {
                    [shape[k], prim[k]] = prims[id as usize];
                }
            }
            Tri4::pack(shape, prim, more[i], shapes, store)
        });
    }

    /// [`Accel::finish`] after a refit of the binary tree: the wide tree
    /// keeps its shape (the collapse is not planned again), its boxes are
    /// those of the refitted binary nodes its slots hold, and the leaf
    /// packets are packed again in place from the current positions.
    fn refit_wide(&mut self, shapes: &[Shape], store: &ParamStore) {
        fn refit_boxes<const W: usize>(nodes: &mut [Node<W>], sources: &[SlotSource], bvh2: &Bvh2) {
            for src in sources {
                let b = bvh2.nodes[src.binary as usize].aabb();
                nodes[src.node as usize].set_box(src.slot as usize, b);
            }
        }
        match &mut self.nodes {
            Nodes::Four(n) => refit_boxes(n, &self.slot_sources, &self.bvh2),
            #[cfg(target_arch = "x86_64")]
            Nodes::Eight(n) => refit_boxes(n, &self.slot_sources, &self.bvh2),
        }
        self.tris
            .par_iter_mut()
            .with_min_len(256)
            .for_each(|t| *t = Tri4::pack(t.shape, t.prim, t.more, shapes, store));
    }

    /// Size and fill of the wide tree (for benchmarks beside other
    /// libraries' statistics).
    pub fn stats(&self) -> TreeStats {
        fn walk<const W: usize>(nodes: &[Node<W>], st: &mut TreeStats) {
            let root = nodes.first().map_or(0.0, |n| {
                (0..W)
                    .filter(|&k| n.child[k] != EMPTY)
                    .fold(Aabb::empty(), |b, k| b.union(&n.child_box(k)))
                    .half_area()
            });
            st.nodes = nodes.len();
            st.width = W;
            for n in nodes {
                for k in 0..W {
                    if n.child[k] == EMPTY {
                        continue;
                    }
                    st.children += 1;
                    let a = n.child_box(k).half_area() / root;
                    if n.child[k] & LEAF == 0 {
                        st.sah_nodes += a;
                    } else {
                        st.leaves += 1;
                        st.sah_leaves += a;
                    }
                }
            }
        }
        let mut st = TreeStats::default();
        match &self.nodes {
            Nodes::Four(n) => walk(n, &mut st),
            #[cfg(target_arch = "x86_64")]
            Nodes::Eight(n) => walk(n, &mut st),
        }
        st.packets = self.tris.len();
        st.lanes = self
            .tris
            .iter()
            .map(|p| p.shape.iter().filter(|&&s| s != u32::MAX).count())
            .sum();
        st
    }

    /// Number of primitives (triangles, analytic shapes and instances) of
    /// the top level.
    pub fn prim_count(&self) -> usize {
        self.prims.len()
    }

    /// Number of primitives of each shape group's structure (held once,
    /// whatever the number of instances).
    pub fn group_prim_counts(&self) -> Vec<usize> {
        self.groups.iter().map(Accel::prim_count).collect()
    }

    /// The hit on `(tmin, tmax)` of the analytic primitive of shape
    /// `shape` (lane primitive `prim`): an analytic shape's, or the
    /// closest hit in an instance's group (its `t` a world distance).
    #[inline(never)]
    fn analytic_hit(&self, shape: u32, prim: u32, ray: &Ray, tmin: f32, tmax: f32) -> Option<Hit> {
        let a = &self.analytic[self.analytic_of_shape[shape as usize] as usize];
        if let Analytic::Instance {
            to_local, group, ..
        } = a
        {
            let (local, len) = ray_to_group_space(to_local, &Ray { tmin, tmax, ..*ray });
            let h = self.groups[*group as usize].intersect(&local)?;
            return Some(Hit {
                t: h.t / len,
                instance: Some(shape - self.n_shapes),
                ..h
            });
        }
        let t = a.intersect(ray.o, ray.d, tmin, tmax);
        (t < tmax).then_some(Hit {
            t,
            shape,
            prim,
            uv: Vec2::ZERO,
            instance: None,
        })
    }

    /// Whether the analytic primitive of shape `shape` blocks `(tmin,
    /// tmax)`.
    #[inline(never)]
    fn analytic_occludes(&self, shape: u32, ray: &Ray, tmin: f32, tmax: f32) -> bool {
        let a = &self.analytic[self.analytic_of_shape[shape as usize] as usize];
        if let Analytic::Instance {
            to_local, group, ..
        } = a
        {
            let (local, _) = ray_to_group_space(to_local, &Ray { tmin, tmax, ..*ray });
            return self.groups[*group as usize].occluded(&local);
        }
        a.intersect(ray.o, ray.d, tmin, tmax) < tmax
    }

    /// Starts loading a child that a closest-hit traversal puts on the
    /// stack into the cache (its four lines: a node or a leaf's first
    /// packet), so that it is there when the traversal comes back to it
    /// after the nearer subtree. Incoherent rays find most nodes of a large
    /// tree outside the L1 and L2 caches; measured on mesh_heavy's bounce
    /// rays, 7–12 % faster on one thread, 4 % on two. Not done for
    /// occlusion rays, which often stop before popping what they pushed
    /// (−2.5 %, 7 of 12 rounds: no clear gain).
    #[inline(always)]
    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
    fn prefetch<const W: usize>(&self, nodes: &[Node<W>], child: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p: *const u8 = if child & LEAF != 0 {
                self.tris
                    .as_ptr()
                    .wrapping_add((child & !LEAF) as usize)
                    .cast()
            } else {
                nodes.as_ptr().wrapping_add(child as usize).cast()
            };
            for line in 0..4 {
                // SAFETY: a prefetch reads nothing and cannot fault
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * line).cast()) };
            }
        }
    }

    /// Leaf packet `i`: the first of a leaf (its child slot without the
    /// `LEAF` bit) or one after a packet with `more` set.
    #[inline(always)]
    fn packet(&self, i: usize) -> &Tri4 {
        debug_assert!(i < self.tris.len());
        // SAFETY: `Collapse::child` pushes a leaf's packets consecutively
        // and stores the index of its first one; `more` is set on all but
        // the last, so every index reached is below `tris.len()`.
        unsafe { self.tris.get_unchecked(i) }
    }

    /// The closest hit on the open interval `(ray.tmin, ray.tmax)`.
    /// For triangles, `Hit::uv` holds the barycentrics `(b1, b2)` of
    /// `p = (1 - b1 - b2) p0 + b1 p1 + b2 p2`.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        match &self.nodes {
            Nodes::Four(nodes) if nodes.is_empty() => None,
            Nodes::Four(nodes) => {
                with_stack(self.stack_size, |s| self.intersect_with(nodes, ray, s))
            }
            // SAFETY: 8-wide trees exist only on CPUs with AVX.
            #[cfg(target_arch = "x86_64")]
            Nodes::Eight(nodes) => unsafe { self.intersect_avx(nodes, ray) },
        }
    }

    /// The 8-wide traversal, compiled for AVX (with the triangle tests).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn intersect_avx(&self, nodes: &[Node<8>], ray: &Ray) -> Option<Hit> {
        with_stack(self.stack_size, |s| self.intersect_with(nodes, ray, s))
    }

    #[inline(always)]
    fn intersect_with<const W: usize>(
        &self,
        nodes: &[Node<W>],
        ray: &Ray,
        mut stack: Stack,
    ) -> Option<Hit>
    where
        Node<W>: BoxTest<W>,
    {
        let tr = TRay::new(ray);
        let mut c = Closest::new(ray.tmax);
        self.closest_below(nodes, ray, &tr, (0, ray.tmin), &mut c, &mut stack);
        c.best
    }

    /// The closest-hit walk of [`Accel::intersect`] below `root` (a node
    /// and the ray's entry distance into it), improving on `c`; `stack`
    /// is empty and left so. Packets finish each of their rays here where
    /// few of them agree (`walk_packet`).
    #[inline(always)]
    fn closest_below<const W: usize>(
        &self,
        nodes: &[Node<W>],
        ray: &Ray,
        tr: &TRay,
        root: (u32, f32),
        c: &mut Closest,
        stack: &mut Stack,
    ) where
        Node<W>: BoxTest<W>,
    {
        let tmin = ray.tmin;
        stack.push(root);
        while let Some((mut cur, t_enter)) = stack.pop() {
            if t_enter > c.tmax {
                continue;
            }
            // descend, nearest child first, the others onto the stack
            while cur & LEAF == 0 {
                let n = node(nodes, cur);
                let (mask, t0) = n.hit(tr, tmin, c.tmax_far);
                if mask == 0 {
                    cur = EMPTY;
                    break;
                }
                let first = mask.trailing_zeros() as usize;
                let rest = mask & (mask - 1);
                if rest == 0 {
                    cur = n.child[first];
                    continue;
                }
                if rest & (rest - 1) == 0 {
                    // two children, the common case: no sort
                    let second = rest.trailing_zeros() as usize;
                    let (near, far) = if t0[second] < t0[first] {
                        (second, first)
                    } else {
                        (first, second)
                    };
                    stack.push((n.child[far], t0[far]));
                    self.prefetch(nodes, n.child[far]);
                    cur = n.child[near];
                    continue;
                }
                let mut hits = [(0u32, 0f32); W];
                let mut k = 0;
                let mut m = mask;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    // insertion by decreasing entry distance
                    let e = (n.child[j], t0[j]);
                    let mut q = k;
                    while q > 0 && hits[q - 1].1 < e.1 {
                        hits[q] = hits[q - 1];
                        q -= 1;
                    }
                    hits[q] = e;
                    k += 1;
                }
                for &h in &hits[..k - 1] {
                    stack.push(h);
                    self.prefetch(nodes, h.0);
                }
                cur = hits[k - 1].0;
            }
            if cur == EMPTY {
                continue;
            }
            let mut pi = (cur & !LEAF) as usize;
            loop {
                let p = self.packet(pi);
                // up to `tmax_far`: a hit at `tmax` itself (a tie, see
                // `Closest::offer`) is not lost to the test's rounding
                let (mask, t, u, v) = tr.hit_tris(p, tmin, c.tmax_far);
                if mask != 0 {
                    let (t, u, v) = (t.to_array(), u.to_array(), v.to_array());
                    let mut m = mask;
                    while m != 0 {
                        let j = m.trailing_zeros() as usize;
                        m &= m - 1;
                        c.offer(t[j], p, j, Vec2::new(u[j], v[j]));
                    }
                }
                let mut m = p.analytic;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if let Some(h) = self.analytic_hit(p.shape[j], p.prim[j], ray, tmin, c.tmax) {
                        c.offer_hit(h);
                    }
                }
                if !p.more {
                    break;
                }
                pi += 1;
            }
        }
    }

    /// Whether anything blocks the ray on `(ray.tmin, ray.tmax)` (shadow
    /// rays): stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        match &self.nodes {
            Nodes::Four(nodes) if nodes.is_empty() => false,
            Nodes::Four(nodes) => {
                with_stack(self.stack_size, |s| self.occluded_with(nodes, ray, s))
            }
            // SAFETY: 8-wide trees exist only on CPUs with AVX.
            #[cfg(target_arch = "x86_64")]
            Nodes::Eight(nodes) => unsafe { self.occluded_avx(nodes, ray) },
        }
    }

    /// The 8-wide any-hit traversal, compiled for AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn occluded_avx(&self, nodes: &[Node<8>], ray: &Ray) -> bool {
        with_stack(self.stack_size, |s| self.occluded_with(nodes, ray, s))
    }

    #[inline(always)]
    fn occluded_with<const W: usize>(&self, nodes: &[Node<W>], ray: &Ray, mut stack: Stack) -> bool
    where
        Node<W>: BoxTest<W>,
    {
        self.occluded_below(nodes, ray, &TRay::new(ray), 0, &mut stack)
    }

    /// The any-hit walk of [`Accel::occluded`] below node `root`; `stack`
    /// is empty and left so.
    #[inline(always)]
    fn occluded_below<const W: usize>(
        &self,
        nodes: &[Node<W>],
        ray: &Ray,
        tr: &TRay,
        root: u32,
        stack: &mut Stack,
    ) -> bool
    where
        Node<W>: BoxTest<W>,
    {
        let (tmin, tmax) = (ray.tmin, ray.tmax);
        let tmax_far = tmax * FAR_ROUND_UP;
        stack.push((root, tmin));
        while let Some((mut cur, _)) = stack.pop() {
            while cur & LEAF == 0 {
                let n = node(nodes, cur);
                let (mut mask, _) = n.hit(tr, tmin, tmax_far);
                if mask == 0 {
                    cur = EMPTY;
                    break;
                }
                let j = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                while mask != 0 {
                    let q = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    stack.push((n.child[q], 0.0));
                }
                cur = n.child[j];
            }
            if cur == EMPTY {
                continue;
            }
            let mut pi = (cur & !LEAF) as usize;
            loop {
                let p = self.packet(pi);
                if tr.hit_tris(p, tmin, tmax).0 != 0 {
                    stack.clear();
                    return true;
                }
                let mut m = p.analytic;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    if self.analytic_occludes(p.shape[j], ray, tmin, tmax) {
                        stack.clear();
                        return true;
                    }
                }
                if !p.more {
                    break;
                }
                pi += 1;
            }
        }
        false
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
                    Shape::Cylinder(c) => {
                        Cylinder::intersect_f32(&c.frame(store), ray.o, ray.d, ray.tmin, tmax)
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

    /// The widths this CPU traverses: the portable 4-wide kernel, and the
    /// 8-wide one where AVX is present.
    fn widths() -> Vec<Width> {
        let mut w = vec![Width::Four];
        if Width::detect() != Width::Four {
            w.push(Width::detect());
        }
        w
    }

    /// Whether the ray overlaps `bb` on `[tmin, tmax]` by more than the
    /// rounding of an f64 slab test (f32 inputs: the differences `b - o`
    /// are exact in f64).
    fn overlaps_clearly(bb: &Aabb, ray: &Ray) -> bool {
        let (mut t0, mut t1) = (ray.tmin as f64, ray.tmax as f64);
        for a in 0..3 {
            let (o, d) = (ray.o[a] as f64, ray.d[a] as f64);
            let (lo, hi) = (bb.min[a] as f64, bb.max[a] as f64);
            let (n, f) = ((lo - o) / d, (hi - o) / d);
            t0 = t0.max(n.min(f));
            t1 = t1.min(n.max(f));
        }
        t0 < t1 - 1e-12 * t1.abs()
    }

    /// Neither box test misses a box the ray clearly overlaps, for rays
    /// that start far from the world's origin just before small boxes (a
    /// bounce ray leaving a surface at 10⁴): there the FMA form
    /// `b · inv - o · inv` with `o · inv` rounded to nearest misses boxes
    /// (its error scales with the origin, not with the distance; checked:
    /// this test fails with it), and `(b - o) · inv` must not.
    #[test]
    fn box_tests_are_conservative_far_from_the_origin() {
        let mut rng = Rng(5);
        let mut overlapping = 0;
        for _ in 0..20000 {
            let o = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 2e4;
            let ray = Ray::new(o, rng.dir());
            let tr = TRay::new(&ray);
            let boxes: Vec<Aabb> = (0..8)
                .map(|_| {
                    // centred 1e-4 to 1e-2 ahead, half-widths up to 2e-3
                    // (f32 spacing at 1e4: 1e-3)
                    let c = ray.at(1e-4 * 100f32.powf(rng.f()));
                    let h = Vec3::new(rng.f(), rng.f(), rng.f()) * 2e-3;
                    Aabb::new((c - h).into(), (c + h).into())
                })
                .collect();
            let mut n4 = [Node::<4>::EMPTY; 2];
            for (k, bb) in boxes.iter().enumerate() {
                n4[k / 4].set(k % 4, k as u32, bb);
            }
            let mask4 = n4[0].hit(&tr, ray.tmin, f32::INFINITY).0
                | n4[1].hit(&tr, ray.tmin, f32::INFINITY).0 << 4;
            #[cfg(target_arch = "x86_64")]
            let mask8 = (Width::detect() == Width::Eight).then(|| {
                let mut n8 = Node::<8>::EMPTY;
                for (k, bb) in boxes.iter().enumerate() {
                    n8.set(k, k as u32, bb);
                }
                n8.hit(&tr, ray.tmin, f32::INFINITY).0
            });
            #[cfg(not(target_arch = "x86_64"))]
            let mask8: Option<u32> = None;
            for (k, bb) in boxes.iter().enumerate() {
                if overlaps_clearly(bb, &ray) {
                    overlapping += 1;
                    assert!(mask4 & 1 << k != 0, "4-wide misses {bb:?} ({ray:?})");
                    if let Some(m) = mask8 {
                        assert!(m & 1 << k != 0, "8-wide misses {bb:?} ({ray:?})");
                    }
                }
            }
        }
        assert!(
            overlapping > 10000,
            "too few overlapping boxes ({overlapping})"
        );
    }

    /// A tree deeper than the machine-stack buffer allows gets a heap
    /// buffer of its size.
    #[test]
    fn stacks_fit_the_tree() {
        assert_eq!(with_stack(3, |s| s.buf.len()), STACK);
        assert_eq!(with_stack(STACK + 7, |s| s.buf.len()), STACK + 7);
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
                    let si = shapes[h.shape as usize].surface_interaction::<f32>(
                        &store.primal(),
                        &crate::geometry::DiffRay::cst(&ray),
                        &h,
                    );
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
        for w in widths() {
            let accel = Accel::build_with_width(&shapes, &store, w);
            assert_eq!(accel.prim_count(), 2 * 24 * 24);
            check_against_brute(&shapes, &store, &accel, 7, 3000);
        }
    }

    /// Two copies of a mesh in the same place (coplanar faces, as a
    /// medium's boundary on the ground): every ray reports the copy that
    /// comes first in scene order, at both widths.
    #[test]
    fn ties_go_to_the_first_shape() {
        let mut store = ParamStore::new();
        let shapes = vec![
            grid(16, "a", 0.0, &mut store),
            grid(16, "b", 0.0, &mut store),
        ];
        let mut rng = Rng(11);
        for w in widths() {
            let accel = Accel::build_with_width(&shapes, &store, w);
            let mut hits = 0;
            for _ in 0..2000 {
                let o = Vec3::new(2.0 * rng.f() - 1.0, 2.0 * rng.f() - 1.0, 2.0);
                let ray = Ray::new(o, rng.dir() * 0.5 - Vec3::Z);
                if let Some(h) = accel.intersect(&ray) {
                    assert_eq!(h.shape, 0, "{ray:?} ({w:?})");
                    hits += 1;
                }
            }
            assert!(hits > 500, "{hits} hits");
        }
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
        for w in widths() {
            let accel = Accel::build_with_width(&shapes, &store, w);
            check_against_brute(&shapes, &store, &accel, 11, 3000);
        }
    }

    /// Packets of `N` rays find the hits that the rays find one by one, bit
    /// for bit, and the same rays blocked: packets of nearly parallel rays from nearly one point (one
    /// pixel's camera rays), of rays from one point to the neighbourhood
    /// of another, of unrelated rays, with some lanes inactive and some
    /// rays cut short, through triangles and an analytic sphere. (On a
    /// processor without AVX-512 both sides trace ray by ray.)
    fn check_packets<const N: usize>(shapes: &[Shape], store: &ParamStore, seed: u64) {
        let mut rng = Rng(seed);
        for w in widths() {
            let accel = Accel::build_with_width(shapes, store, w);
            let (mut hits, mut open) = (0, 0);
            for i in 0..600 {
                let o = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 6.0;
                let target = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5) * 2.0;
                let spread = [1e-3, 0.1, 2.0][i % 3];
                let mut rays = [Ray::new(o, Vec3::Z); N];
                for ray in &mut rays {
                    let jitter = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5);
                    let to = target + jitter * spread;
                    *ray = Ray::new(o + jitter * 1e-3, (to - o).normalize());
                    if i % 4 == 1 {
                        // ends short of its target
                        ray.tmax = (to - ray.o).length() * (1.0 - 1e-4);
                    }
                    if i % 7 == 0 {
                        ray.d = rng.dir();
                    }
                }
                let active = if i % 5 == 0 {
                    (rng.f() * (1u64 << N) as f32) as u32
                } else {
                    u32::MAX >> (32 - N)
                };
                // the kernels `intersect_packet` and `occluded_packet`
                // pick, and the AVX2 ones also where the processor would
                // pick AVX-512's
                let mut kernels = vec![("dispatched", accel.intersect_packet(&rays, active))];
                let mut blocked = vec![("dispatched", accel.occluded_packet(&rays, active))];
                #[cfg(target_arch = "x86_64")]
                if let Some(nodes) = accel.packet_tree() {
                    if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                        // SAFETY: the processor has AVX2 and FMA.
                        let got = unsafe { accel.intersect_packet_avx2(nodes, &rays, active) };
                        kernels.push(("avx2", got));
                        // SAFETY: as above
                        let got = unsafe { accel.occluded_packet_avx2(nodes, &rays, active) };
                        blocked.push(("avx2", got));
                    }
                }
                for (k, ray) in rays.iter().enumerate() {
                    let want = active >> k & 1 != 0 && accel.occluded(ray);
                    for (kernel, got) in &blocked {
                        let at = format!("{kernel}, packet {i}, lane {k}: {ray:?}");
                        assert_eq!(got >> k & 1 != 0, want, "occlusion, {at}");
                    }
                    open += (active >> k & 1 != 0 && !want) as usize;
                }
                for k in 0..N {
                    let want = (active >> k & 1 != 0)
                        .then(|| accel.intersect(&rays[k]))
                        .flatten();
                    let key = |h: Option<Hit>| h.map(|h| (h.t, h.shape, h.prim, h.uv));
                    for (kernel, got) in &kernels {
                        assert_eq!(
                            key(got[k]),
                            key(want),
                            "{kernel}, packet {i}, lane {k}: {:?}",
                            rays[k]
                        );
                    }
                    hits += want.is_some() as usize;
                }
            }
            assert!(hits > 600 * N / 5, "{hits} hits");
            // the short rays, and rays that miss, are not blocked
            assert!(open > 600 * N / 10, "{open} rays not blocked");
        }
    }

    #[test]
    fn packets_find_the_hits_of_single_rays() {
        let mut store = ParamStore::new();
        let rot = Mat3::from_rotation_x(0.4);
        let mut shapes = vec![
            grid(24, "g", -0.5, &mut store),
            grid(8, "g2", 0.6, &mut store),
        ];
        shapes.push(Shape::Sphere(
            Sphere::new("s", Vec3::new(0.3, 0.2, 0.1), 0.4, rot, false, &mut store).unwrap(),
        ));
        check_packets::<4>(&shapes, &store, 3);
        check_packets::<8>(&shapes, &store, 4);
        check_packets::<16>(&shapes, &store, 5);
    }

    /// The SAH cost of the wide tree `Collapse` built: interior nodes
    /// (the root included) at `NODE_COST`, leaves at `PACKET_COST` per
    /// packet and `ANALYTIC_COST` per analytic lane, each weighted by its
    /// box's half area.
    fn built_cost<const W: usize>(c: &Collapse<W>) -> f32 {
        let half_area = |n: &Node<W>, k: usize| n.child_box(k).half_area();
        let mut cost = c.bvh2.nodes[0].aabb().half_area() * NODE_COST;
        for n in &c.nodes {
            for k in 0..W {
                match n.child[k] {
                    EMPTY => {}
                    ch if ch & LEAF == 0 => cost += half_area(n, k) * NODE_COST,
                    ch => {
                        let (mut packets, mut analytic) = (0, 0);
                        let mut i = (ch & !LEAF) as usize;
                        loop {
                            packets += 1;
                            analytic += c.leaves[i]
                                .iter()
                                .filter(|&&id| id != u32::MAX && c.analytic[id as usize])
                                .count();
                            if !c.leaf_more[i] {
                                break;
                            }
                            i += 1;
                        }
                        cost += half_area(n, k)
                            * (PACKET_COST * packets as f32 + ANALYTIC_COST * analytic as f32);
                    }
                }
            }
        }
        cost
    }

    /// The collapse builds the wide tree its dynamic program planned (same
    /// SAH cost), with every primitive in exactly one lane and no leaf
    /// above `MAX_LEAF`, at both widths, with and without analytic
    /// primitives.
    #[test]
    fn collapse_builds_the_planned_tree() {
        fn check<const W: usize>(bvh2: &Bvh2, analytic: &[bool]) {
            let prims = analytic.len();
            let c = Collapse::<W>::new(bvh2, analytic).run();
            assert!(matches!(c.form[0][0], Form::Node));
            let (planned, built) = (c.cost[0][0], built_cost(&c));
            assert!(
                (planned - built).abs() <= 1e-4 * planned,
                "W = {W}: planned {planned}, built {built}"
            );
            let mut seen = vec![0u32; prims];
            for id in c.leaves.iter().flatten().filter(|&&id| id != u32::MAX) {
                seen[*id as usize] += 1;
            }
            assert!(
                seen.iter().all(|&n| n == 1),
                "W = {W}: primitives not once each"
            );
            for n in &c.nodes {
                for &ch in n.child.iter().filter(|&&ch| ch != EMPTY && ch & LEAF != 0) {
                    let (mut i, mut lanes) = ((ch & !LEAF) as usize, 0);
                    loop {
                        lanes += c.leaves[i].iter().filter(|&&id| id != u32::MAX).count();
                        if !c.leaf_more[i] {
                            break;
                        }
                        i += 1;
                    }
                    assert!(lanes as u32 <= MAX_LEAF && lanes > 0);
                }
            }
        }
        let mut store = ParamStore::new();
        let mut shapes = vec![
            grid(40, "a", 0.0, &mut store),
            grid(7, "b", 0.5, &mut store),
        ];
        let accel = Accel::build_with_width(&shapes, &store, Width::Four);
        let analytic = accel.analytic_prims();
        check::<4>(&accel.bvh2, &analytic);
        check::<8>(&accel.bvh2, &analytic);
        for (k, (x, y)) in [(0.1, 0.2), (0.5, 0.5), (0.52, 0.5), (0.9, 0.1)]
            .into_iter()
            .enumerate()
        {
            let c = Vec3::new(x, y, 0.25);
            let s = Sphere::new(&format!("s{k}"), c, 0.03, Mat3::IDENTITY, false, &mut store);
            shapes.push(Shape::Sphere(s.unwrap()));
        }
        let accel = Accel::build_with_width(&shapes, &store, Width::Four);
        let analytic = accel.analytic_prims();
        assert_eq!(analytic.iter().filter(|&&a| a).count(), 4);
        check::<4>(&accel.bvh2, &analytic);
        check::<8>(&accel.bvh2, &analytic);
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
        let mut accels: Vec<Accel> = widths()
            .into_iter()
            .map(|w| Accel::build_with_width(&shapes, &store, w))
            .collect();
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
        for accel in &mut accels {
            accel.update(&shapes, &store);
            check_against_brute(&shapes, &store, accel, 3, 2000);
        }
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
