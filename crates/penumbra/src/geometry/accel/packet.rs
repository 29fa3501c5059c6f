//! Packet traversal: `N` rays through the 8-wide tree together, each
//! operation one instruction across the rays, sixteen of them in an
//! AVX-512 register or eight in an AVX2 one (Wald et al. 2001,
//! "Interactive Rendering with Coherent Ray Tracing"; Embree's packet
//! kernels). A node's box is tested against all the rays that reached it
//! at once, and a triangle likewise, until no more than [`SWITCH`] of them
//! enter a node, below which each goes on alone. It pays for rays that
//! take the same way through the tree: the path tracer in lanes traces
//! each pixel's camera rays as one packet (`integrator::lanes`, up to
//! sixteen rays: one origin, nearly one direction), and its shadow rays of
//! one depth as one occlusion packet (docs/perf/traversal.md, "Camera
//! rays in packets" and "Hybrid packets").
//!
//! The arithmetic per ray is that of the single-ray kernel ([`TRay`]),
//! operation for operation, so that every hit is the same bit for bit;
//! only the order of the visits differs, which [`Closest::offer`] makes
//! irrelevant.

#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code, unused_imports))]

use super::*;
use crate::ad::lanes::widest_lanes;

/// A packet's rays that still enter a node, at or below which each of them
/// is walked on alone (Embree's hybrid traversal, Benthin et al. 2012,
/// "Combining Single and Packet-Ray Tracing for Arbitrary Ray
/// Distributions on the Intel MIC Architecture").
const SWITCH: u32 = 4;

/// The rays of a packet as structure of arrays (see [`TRay`]): the near
/// side of a box per axis is the max side where `neg`.
struct PacketRays<const N: usize> {
    o: [[f32; N]; 3],
    d: [[f32; N]; 3],
    inv: [[f32; N]; 3],
    inv_far: [[f32; N]; 3],
    neg: [[bool; N]; 3],
    tmin: [f32; N],
}

impl<const N: usize> PacketRays<N> {
    #[inline(always)]
    fn new(rays: &[Ray; N]) -> PacketRays<N> {
        let mut r = PacketRays {
            o: [[0.0; N]; 3],
            d: [[0.0; N]; 3],
            inv: [[0.0; N]; 3],
            inv_far: [[0.0; N]; 3],
            neg: [[false; N]; 3],
            tmin: [0.0; N],
        };
        for (i, ray) in rays.iter().enumerate() {
            // as `TRay::new`
            let d = ray.d + Vec3::ZERO;
            let inv = d.recip();
            let inv_far = inv * FAR_ROUND_UP;
            for a in 0..3 {
                r.o[a][i] = ray.o[a];
                r.d[a][i] = d[a];
                r.inv[a][i] = inv[a];
                r.inv_far[a][i] = inv_far[a];
                r.neg[a][i] = inv[a] < 0.0;
            }
            r.tmin[i] = ray.tmin;
        }
        r
    }

    /// Which of the rays in `active` overlap the box of child `k` of `n`
    /// on `[tmin, tmax_far]` (bit i: ray i), and their entry distances:
    /// [`TRay::hit_node`] per ray.
    #[inline(always)]
    fn hit_box<B: RayBits>(
        &self,
        n: &Node<8>,
        k: usize,
        tmax_far: &[f32; N],
        active: u32,
    ) -> (u32, [f32; N]) {
        let mut t0 = self.tmin;
        let mut t1 = *tmax_far;
        for a in 0..3 {
            let (lo, hi) = (n.b[0][a][k], n.b[1][a][k]);
            for i in 0..N {
                let (bn, bf) = if self.neg[a][i] { (hi, lo) } else { (lo, hi) };
                let near = (bn - self.o[a][i]) * self.inv[a][i];
                let far = (bf - self.o[a][i]) * self.inv_far[a][i];
                // a NaN slab leaves the interval as it is
                t0[i] = if near > t0[i] { near } else { t0[i] };
                t1[i] = if far < t1[i] { far } else { t1[i] };
            }
        }
        (B::bits::<N>(|i| t0[i] <= t1[i]) & active, t0)
    }

    /// Which of the rays in `active` hit triangle lane `j` of `p` on
    /// `(tmin, tmax)`, with the distance and barycentrics of each:
    /// [`TRay::hit_tris`] per ray.
    #[inline(always)]
    fn hit_tri<B: RayBits>(
        &self,
        p: &Tri4,
        j: usize,
        tmax: &[f32; N],
        active: u32,
    ) -> (u32, [f32; N], [f32; N], [f32; N]) {
        let v0 = [p.v0[0][j], p.v0[1][j], p.v0[2][j]];
        let e1 = [p.e1[0][j], p.e1[1][j], p.e1[2][j]];
        let e2 = [p.e2[0][j], p.e2[1][j], p.e2[2][j]];
        let ng = [p.ng[0][j], p.ng[1][j], p.ng[2][j]];
        let (mut t, mut u, mut v) = ([0.0; N], [0.0; N], [0.0; N]);
        let mut ok = [false; N];
        for i in 0..N {
            let d = [self.d[0][i], self.d[1][i], self.d[2][i]];
            let c = [
                v0[0] - self.o[0][i],
                v0[1] - self.o[1][i],
                v0[2] - self.o[2][i],
            ];
            let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let den = dot(ng, d);
            // the sign of `den` as ±1 (a NaN `den` fails `aden > 0` below)
            let s = f32::from_bits(den.to_bits() & 0x8000_0000 | 1.0f32.to_bits());
            let aden = den.abs();
            let r = [
                d[1] * c[2] - d[2] * c[1],
                d[2] * c[0] - d[0] * c[2],
                d[0] * c[1] - d[1] * c[0],
            ];
            let ui = dot(r, e2) * s;
            let vi = dot(r, e1) * s;
            let tn = dot(ng, c) * s;
            ok[i] = aden > 0.0
                && ui >= 0.0
                && vi >= 0.0
                && ui + vi <= aden
                && tn > aden * self.tmin[i]
                && tn < aden * tmax[i];
            let inv = 1.0 / aden;
            (t[i], u[i], v[i]) = (tn * inv, ui * inv, vi * inv);
        }
        (B::bits::<N>(|i| ok[i]) & active, t, u, v)
    }
}

/// How a kernel turns a condition per ray into bits (bit i: ray i), by
/// the instructions of the processor it is compiled for: LLVM otherwise
/// assembles the bits one shift at a time, which was a quarter of the
/// AVX-512 kernel's time (docs/perf/traversal.md).
trait RayBits {
    /// The rays `i < N` for which `f(i)` holds.
    fn bits<const N: usize>(f: impl Fn(usize) -> bool) -> u32;
}

/// The condition of each ray as a bit, one at a time.
#[inline(always)]
fn bits_by_shifts<const N: usize>(f: impl Fn(usize) -> bool) -> u32 {
    let mut m = 0;
    for i in 0..N {
        m |= (f(i) as u32) << i;
    }
    m
}

/// Sixteen rays: one compare into a mask register and one move.
#[cfg(target_arch = "x86_64")]
struct Avx512Bits;

#[cfg(target_arch = "x86_64")]
impl RayBits for Avx512Bits {
    #[inline(always)]
    fn bits<const N: usize>(f: impl Fn(usize) -> bool) -> u32 {
        use std::arch::x86_64::*;
        if N != 16 {
            return bits_by_shifts::<N>(f);
        }
        let mut v = [0i32; 16];
        for (i, v) in v.iter_mut().enumerate() {
            *v = if f(i) { -1 } else { 0 };
        }
        // SAFETY: `Avx512Bits` runs only inside `intersect_packet_avx512`,
        // which `Accel::intersect_packet` enters only where AVX-512 (F,
        // DQ) is; `v` holds sixteen i32.
        unsafe { _mm512_movepi32_mask(_mm512_loadu_si512(v.as_ptr().cast())) as u32 }
    }
}

/// Eight rays at a time: the sign bits of eight lanes in one move.
#[cfg(target_arch = "x86_64")]
struct Avx2Bits;

#[cfg(target_arch = "x86_64")]
impl RayBits for Avx2Bits {
    #[inline(always)]
    fn bits<const N: usize>(f: impl Fn(usize) -> bool) -> u32 {
        use std::arch::x86_64::*;
        if !N.is_multiple_of(8) {
            return bits_by_shifts::<N>(f);
        }
        let mut v = [0i32; N];
        for (i, v) in v.iter_mut().enumerate() {
            *v = if f(i) { -1 } else { 0 };
        }
        let mut m = 0;
        for (h, eight) in v.chunks_exact(8).enumerate() {
            // SAFETY: `Avx2Bits` runs only inside `intersect_packet_avx2`,
            // which `Accel::intersect_packet` enters only where AVX2 is;
            // `eight` holds eight i32.
            let half = unsafe {
                _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_loadu_si256(
                    eight.as_ptr().cast(),
                )))
            };
            m |= (half as u32) << (8 * h);
        }
        m
    }
}

impl Accel {
    /// The closest hits of the rays `rays[i]` for each bit `i` of `active`
    /// (`None` for the others): those of [`Accel::intersect`] ray by ray,
    /// bit for bit. Traced as one packet on an 8-wide tree where the
    /// processor has AVX-512 or AVX2, else one by one.
    pub fn intersect_packet<const N: usize>(
        &self,
        rays: &[Ray; N],
        active: u32,
    ) -> [Option<Hit>; N] {
        const { assert!(N <= 32) };
        #[cfg(target_arch = "x86_64")]
        if let Some(nodes) = self.packet_tree() {
            match widest_lanes() {
                // SAFETY: `widest_lanes` is 16 only where the processor
                // has AVX-512 (F, VL, DQ, BW), AVX2 and FMA, and 8 only
                // where it has AVX2 and FMA.
                16 => return unsafe { self.intersect_packet_avx512(nodes, rays, active) },
                8 => return unsafe { self.intersect_packet_avx2(nodes, rays, active) },
                _ => {}
            }
        }
        let mut hits = [None; N];
        for (i, h) in hits.iter_mut().enumerate() {
            if active >> i & 1 != 0 {
                *h = self.intersect(&rays[i]);
            }
        }
        hits
    }

    /// The tree, where packets walk it: 8 wide, not empty, and shallow
    /// enough for the packet kernels' stacks on the machine stack (else
    /// the rays go one by one).
    #[cfg(target_arch = "x86_64")]
    pub(super) fn packet_tree(&self) -> Option<&[Node<8>]> {
        match &self.nodes {
            Nodes::Eight(nodes) if self.stack_size <= STACK && !nodes.is_empty() => Some(nodes),
            _ => None,
        }
    }

    /// Which of the rays `rays[i]` for each bit `i` of `active` are
    /// blocked (bit i set): [`Accel::occluded`] ray by ray. Traced as one
    /// packet on an 8-wide tree where the processor has AVX-512 or AVX2,
    /// else one by one.
    pub fn occluded_packet<const N: usize>(&self, rays: &[Ray; N], active: u32) -> u32 {
        const { assert!(N <= 32) };
        #[cfg(target_arch = "x86_64")]
        if let Some(nodes) = self.packet_tree() {
            match widest_lanes() {
                // SAFETY: as in `intersect_packet`
                16 => return unsafe { self.occluded_packet_avx512(nodes, rays, active) },
                8 => return unsafe { self.occluded_packet_avx2(nodes, rays, active) },
                _ => {}
            }
        }
        let mut blocked = 0;
        for (i, ray) in rays.iter().enumerate() {
            if active >> i & 1 != 0 && self.occluded(ray) {
                blocked |= 1 << i;
            }
        }
        blocked
    }

    /// [`Accel::walk_packet_occluded`] compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    fn occluded_packet_avx512<const N: usize>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> u32 {
        self.walk_packet_occluded::<N, Avx512Bits>(nodes, rays, active)
    }

    /// [`Accel::walk_packet_occluded`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn occluded_packet_avx2<const N: usize>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> u32 {
        self.walk_packet_occluded::<N, Avx2Bits>(nodes, rays, active)
    }

    /// [`Accel::walk_packet`] compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    fn intersect_packet_avx512<const N: usize>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> [Option<Hit>; N] {
        self.walk_packet::<N, Avx512Bits>(nodes, rays, active)
    }

    /// [`Accel::walk_packet`] compiled for AVX2: sixteen rays are two
    /// registers per operation.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn intersect_packet_avx2<const N: usize>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> [Option<Hit>; N] {
        self.walk_packet::<N, Avx2Bits>(nodes, rays, active)
    }

    /// [`Accel::intersect_with`] for a packet: a stack entry is a node and
    /// the entry distances of the rays that reached it (NaN for the
    /// others). Inlined into the entry points above, which carry the
    /// target features its operations are compiled with.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn walk_packet<const N: usize, B: RayBits>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> [Option<Hit>; N] {
        let pr = PacketRays::new(rays);
        let mut c: [Closest; N] = std::array::from_fn(|i| Closest::new(rays[i].tmax));
        let mut tmax = [0.0; N];
        let mut tmax_far = [0.0; N];
        for i in 0..N {
            (tmax[i], tmax_far[i]) = (c[i].tmax, c[i].tmax_far);
        }
        let mut buf = [const { MaybeUninit::<(u32, [f32; N])>::uninit() }; STACK];
        let mut stack = Stack::new(&mut buf);
        // NaN: a ray that did not enter the node (fails `t_enter <= tmax`)
        let root: [f32; N] = std::array::from_fn(|i| {
            if active >> i & 1 != 0 {
                pr.tmin[i]
            } else {
                f32::NAN
            }
        });
        let mut single_buf = [const { MaybeUninit::uninit() }; STACK];
        let mut single = Stack::new(&mut single_buf);
        stack.push((0, root));
        'pop: while let Some((mut cur, mut t_enter)) = stack.pop() {
            // the rays that entered the node and found nothing nearer since
            let mut act = B::bits::<N>(|i| t_enter[i] <= tmax[i]);
            if act == 0 {
                continue;
            }
            // descend, nearest child first (by its first ray's entry),
            // the others onto the stack
            while cur & LEAF == 0 {
                if act.count_ones() <= SWITCH {
                    // too few rays left to share the node's tests: each
                    // goes on alone below it
                    let mut m = act;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let tr = TRay::new(&rays[i]);
                        let root = (cur, t_enter[i]);
                        self.closest_below(nodes, &rays[i], &tr, root, &mut c[i], &mut single);
                        (tmax[i], tmax_far[i]) = (c[i].tmax, c[i].tmax_far);
                    }
                    continue 'pop;
                }
                let n = node(nodes, cur);
                let mut hits = [(0u32, 0u32, 0f32); 8];
                let mut entries = [[0f32; N]; 8];
                let mut count = 0;
                for k in 0..8 {
                    if n.child[k] == EMPTY {
                        continue;
                    }
                    let (mask, t0) = pr.hit_box::<B>(n, k, &tmax_far, act);
                    if mask == 0 {
                        continue;
                    }
                    // insertion by decreasing nearest entry
                    let e = (n.child[k], mask, t0[mask.trailing_zeros() as usize]);
                    let mut q = count;
                    while q > 0 && hits[q - 1].2 < e.2 {
                        hits[q] = hits[q - 1];
                        entries[q] = entries[q - 1];
                        q -= 1;
                    }
                    hits[q] = e;
                    for i in 0..N {
                        entries[q][i] = if mask >> i & 1 != 0 { t0[i] } else { f32::NAN };
                    }
                    count += 1;
                }
                if count == 0 {
                    cur = EMPTY;
                    break;
                }
                for q in 0..count - 1 {
                    stack.push((hits[q].0, entries[q]));
                }
                (cur, act) = (hits[count - 1].0, hits[count - 1].1);
                t_enter = entries[count - 1];
            }
            if cur == EMPTY {
                continue;
            }
            let mut pi = (cur & !LEAF) as usize;
            loop {
                let p = self.packet(pi);
                for j in 0..4 {
                    if p.shape[j] == u32::MAX || p.analytic >> j & 1 != 0 {
                        continue;
                    }
                    let (mask, t, u, v) = pr.hit_tri::<B>(p, j, &tmax_far, act);
                    let mut m = mask;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        c[i].offer(t[i], p, j, Vec2::new(u[i], v[i]));
                        (tmax[i], tmax_far[i]) = (c[i].tmax, c[i].tmax_far);
                    }
                }
                let mut m = p.analytic;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let mut a = act;
                    while a != 0 {
                        let i = a.trailing_zeros() as usize;
                        a &= a - 1;
                        let hit =
                            self.analytic_hit(p.shape[j], p.prim[j], &rays[i], pr.tmin[i], tmax[i]);
                        if let Some(h) = hit {
                            c[i].offer_hit(h);
                            (tmax[i], tmax_far[i]) = (c[i].tmax, c[i].tmax_far);
                        }
                    }
                }
                if !p.more {
                    break;
                }
                pi += 1;
            }
        }
        c.map(|c| c.best)
    }

    /// [`Accel::occluded_with`] for a packet: the rays still unblocked
    /// walk the tree together, a stack entry being a node and the rays that
    /// entered it (no entry distances: an occlusion query does not shorten
    /// its rays, and takes the children in any order), until too few of
    /// them enter a node to share its tests; each ray leaves the packet at
    /// its first hit.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn walk_packet_occluded<const N: usize, B: RayBits>(
        &self,
        nodes: &[Node<8>],
        rays: &[Ray; N],
        active: u32,
    ) -> u32 {
        let pr = PacketRays::new(rays);
        let tmax: [f32; N] = std::array::from_fn(|i| rays[i].tmax);
        let tmax_far = tmax.map(|t| t * FAR_ROUND_UP);
        // the rays not yet found blocked
        let mut open = active;
        let mut buf = [const { MaybeUninit::<(u32, u32)>::uninit() }; STACK];
        let mut stack = Stack::new(&mut buf);
        let mut single_buf = [const { MaybeUninit::uninit() }; STACK];
        let mut single = Stack::new(&mut single_buf);
        stack.push((0, active));
        'pop: while let Some((mut cur, entered)) = stack.pop() {
            let mut act = entered & open;
            while cur & LEAF == 0 {
                if act.count_ones() <= SWITCH {
                    let mut m = act;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let tr = TRay::new(&rays[i]);
                        if self.occluded_below(nodes, &rays[i], &tr, cur, &mut single) {
                            open &= !(1 << i);
                        }
                    }
                    if open == 0 {
                        break 'pop;
                    }
                    continue 'pop;
                }
                let n = node(nodes, cur);
                let mut next = None;
                for k in 0..8 {
                    if n.child[k] == EMPTY {
                        continue;
                    }
                    let (mask, _) = pr.hit_box::<B>(n, k, &tmax_far, act);
                    if mask == 0 {
                        continue;
                    }
                    match next {
                        None => next = Some((n.child[k], mask)),
                        Some(_) => stack.push((n.child[k], mask)),
                    }
                }
                let Some((child, mask)) = next else {
                    continue 'pop;
                };
                (cur, act) = (child, mask);
            }
            let reached = act;
            let mut pi = (cur & !LEAF) as usize;
            loop {
                let p = self.packet(pi);
                for j in 0..4 {
                    if p.shape[j] == u32::MAX || p.analytic >> j & 1 != 0 {
                        continue;
                    }
                    act &= !pr.hit_tri::<B>(p, j, &tmax, act).0;
                }
                let mut m = p.analytic;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let mut a = act;
                    while a != 0 {
                        let i = a.trailing_zeros() as usize;
                        a &= a - 1;
                        let (tmin, ray) = (pr.tmin[i], &rays[i]);
                        if self.analytic_occludes(p.shape[j], ray, tmin, tmax[i]) {
                            act &= !(1 << i);
                        }
                    }
                }
                if !p.more || act == 0 {
                    break;
                }
                pi += 1;
            }
            // the rays that reached the leaf and were blocked in it
            open &= !(reached & !act);
            if open == 0 {
                break;
            }
        }
        active & !open
    }
}
