//! Penumbra's side of the native ray benchmark (`scripts/bench_rays.py`):
//! the closest hits (`Accel::intersect`) or occlusion (`Accel::occluded`)
//! of a file of rays, on rayon's threads, without Python. The counterpart
//! of `scripts/embree_bench/bench.c`, over the same files:
//!
//! ```text
//! cargo run --release -p penumbra --example trace_rays -- DIR KIND QUERY THREADS REPS
//! ```
//!
//! - `DIR/mesh.bin`: `u32` shapes; per shape `u32` vertices, `u32` faces,
//!   `f32` positions `[nv][3]` (world space), `u32` faces `[nf][3]`; each
//!   shape becomes a [`Mesh`] (shape index = its position in the file);
//! - `DIR/rays_KIND.bin`: `f32` `[n][8]`: origin, direction, tmin, tmax;
//! - `QUERY`: `closest` or `occluded`; `THREADS`: the size of the rayon
//!   pool, whose tasks are chunks of [`CHUNK`] consecutive rays, each its
//!   own unit of work stealing (as the Python `ray_intersect`; the C program
//!   hands out chunks of as many rays from a counter); `REPS`: timed traces
//!   (after one untimed warm-up trace).
//!
//! With `PACKET=P` (4, 8 or 16) in the environment, each `P` consecutive
//! rays go as one packet ([`Accel::intersect_packet`],
//! [`Accel::occluded_packet`]: SIMD over the rays, as the render loop
//! traces a pixel's camera rays and shadow rays; the C program's
//! `PACKET=16` is Embree's `rtcIntersect16` and `rtcOccluded16`).
//!
//! The tree is built once, untimed (its time is reported). Writes the hits
//! of the last trace to `DIR/penumbra_KIND_tTHREADS.bin` (closest: per ray
//! `f32` t, `inf` on a miss, `i32` shape, `i32` triangle, −1 on a miss;
//! occluded: one byte per ray) and prints `RESULT {json}` (with the
//! tree's size and fill, [`Accel::stats`]).

use glam::Vec3;
use penumbra::geometry::{Accel, Mesh, MeshData, MeshOptions, Ray, Shape};
use penumbra::math::Transform;
use penumbra::params::ParamStore;
use penumbra::scene::RAYS_PER_TASK;
use rayon::prelude::*;
use std::path::Path;
use std::process::exit;
use std::time::Instant;

/// Rays per rayon task (as the C program's chunks).
const CHUNK: usize = RAYS_PER_TASK;

fn fail(msg: &str) -> ! {
    eprintln!("trace_rays: {msg}");
    exit(1)
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())))
}

/// Little-endian 32-bit words of a byte slice.
fn words(b: &[u8]) -> impl Iterator<Item = [u8; 4]> + '_ {
    b.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]])
}

fn load_shapes(bytes: &[u8], store: &mut ParamStore) -> Vec<Shape> {
    let mut at = 0;
    let mut take = |n: usize| {
        let s = bytes
            .get(at..at + n)
            .unwrap_or_else(|| fail("mesh.bin: shorter than its counts"));
        at += n;
        s
    };
    let u32_of = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
    let shapes = u32_of(take(4));
    let mut out = Vec::with_capacity(shapes);
    for s in 0..shapes {
        let (nv, nf) = (u32_of(take(4)), u32_of(take(4)));
        let pos: Vec<f32> = words(take(12 * nv)).map(f32::from_le_bytes).collect();
        let faces: Vec<u32> = words(take(12 * nf)).map(u32::from_le_bytes).collect();
        let data = MeshData {
            positions: pos.chunks_exact(3).map(Vec3::from_slice).collect(),
            faces: faces.chunks_exact(3).map(|f| [f[0], f[1], f[2]]).collect(),
            ..Default::default()
        };
        let key = format!("shape{s}");
        let opts = MeshOptions {
            face_normals: true,
            flip_normals: false,
        };
        let mesh = Mesh::new(
            "ply",
            &key,
            "mesh.bin",
            data,
            &Transform::IDENTITY,
            opts,
            store,
        )
        .unwrap_or_else(|e| fail(&e.to_string()));
        out.push(Shape::Mesh(mesh));
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 5 {
        fail("usage: trace_rays DIR KIND QUERY THREADS REPS");
    }
    let dir = Path::new(&args[0]);
    let kind = &args[1];
    let occluded = match args[2].as_str() {
        "closest" => false,
        "occluded" => true,
        _ => fail("QUERY is closest or occluded"),
    };
    let threads: usize = args[3]
        .parse()
        .unwrap_or_else(|_| fail("THREADS: a number"));
    let reps: usize = args[4].parse().unwrap_or_else(|_| fail("REPS: a number"));
    if threads == 0 || reps == 0 {
        fail("THREADS and REPS must be >= 1");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap_or_else(|e| fail(&e.to_string()));

    let mut store = ParamStore::new();
    let t0 = Instant::now();
    let shapes = load_shapes(&read(&dir.join("mesh.bin")), &mut store);
    let accel = Accel::build(&shapes, &store);
    let build = t0.elapsed().as_secs_f64();

    let floats: Vec<f32> = words(&read(&dir.join(format!("rays_{kind}.bin"))))
        .map(f32::from_le_bytes)
        .collect();
    let rays: Vec<Ray> = floats
        .chunks_exact(8)
        .map(|r| Ray {
            o: Vec3::new(r[0], r[1], r[2]),
            d: Vec3::new(r[3], r[4], r[5]),
            tmin: r[6],
            tmax: r[7],
        })
        .collect();

    let packet = match std::env::var("PACKET").as_deref() {
        Err(_) => 1,
        Ok(v @ ("4" | "8" | "16")) => v.parse().unwrap(),
        Ok(v) => fail(&format!("PACKET={v}: 4, 8 or 16")),
    };
    // per ray: (t, shape, triangle) or occluded
    let mut hits = vec![(f32::INFINITY, -1i32, -1i32); rays.len()];
    let mut blocked = vec![false; rays.len()];
    let mut times = Vec::with_capacity(reps);
    // one untimed trace first (warm-up), then REPS timed ones
    for rep in 0..=reps {
        let t = Instant::now();
        pool.install(|| {
            if occluded && packet == 16 {
                test_packets::<16>(&accel, &mut blocked, &rays);
            } else if occluded && packet == 8 {
                test_packets::<8>(&accel, &mut blocked, &rays);
            } else if occluded && packet == 4 {
                test_packets::<4>(&accel, &mut blocked, &rays);
            } else if occluded {
                blocked
                    .par_chunks_mut(CHUNK)
                    .zip(rays.par_chunks(CHUNK))
                    .with_max_len(1)
                    .for_each(|(out, rays)| {
                        for (o, r) in out.iter_mut().zip(rays) {
                            *o = accel.occluded(r);
                        }
                    });
            } else if packet == 16 {
                trace_packets::<16>(&accel, &mut hits, &rays);
            } else if packet == 8 {
                trace_packets::<8>(&accel, &mut hits, &rays);
            } else if packet == 4 {
                trace_packets::<4>(&accel, &mut hits, &rays);
            } else {
                hits.par_chunks_mut(CHUNK)
                    .zip(rays.par_chunks(CHUNK))
                    .with_max_len(1)
                    .for_each(|(out, rays)| {
                        for (o, r) in out.iter_mut().zip(rays) {
                            *o = accel.intersect(r).map_or((f32::INFINITY, -1, -1), |h| {
                                (h.t, h.shape as i32, h.prim as i32)
                            });
                        }
                    });
            }
        });
        if rep > 0 {
            times.push(t.elapsed().as_secs_f64());
        }
    }

    let mut bytes = Vec::with_capacity(12 * rays.len());
    if occluded {
        bytes.extend(blocked.iter().map(|&b| b as u8));
    } else {
        for (t, s, p) in &hits {
            bytes.extend_from_slice(&t.to_le_bytes());
            bytes.extend_from_slice(&s.to_le_bytes());
            bytes.extend_from_slice(&p.to_le_bytes());
        }
    }
    let out = dir.join(format!("penumbra_{kind}_t{threads}.bin"));
    std::fs::write(&out, bytes).unwrap_or_else(|e| fail(&format!("{}: {e}", out.display())));
    let times: Vec<String> = times.iter().map(|t| format!("{t:.6}")).collect();
    let st = accel.stats();
    println!(
        "RESULT {{\"side\": \"penumbra\", \"kind\": \"{kind}\", \"threads\": {threads}, \"rays\": {}, \
         \"triangles\": {}, \"build_s\": {build:.6}, \"times\": [{}], \"tree\": {{\"width\": {}, \
         \"nodes\": {}, \"children\": {}, \"leaves\": {}, \"packets\": {}, \"lanes\": {}, \
         \"sah_nodes\": {:.4}, \"sah_leaves\": {:.4}}}}}",
        rays.len(),
        accel.prim_count(),
        times.join(", "),
        st.width,
        st.nodes,
        st.children,
        st.leaves,
        st.packets,
        st.lanes,
        st.sah_nodes,
        st.sah_leaves,
    );
}

/// The closest hits of `rays`, `P` consecutive rays at a time as one
/// packet ([`Accel::intersect_packet`]), in chunks of [`CHUNK`] rays on
/// rayon's threads.
fn trace_packets<const P: usize>(accel: &Accel, hits: &mut [(f32, i32, i32)], rays: &[Ray]) {
    hits.par_chunks_mut(CHUNK)
        .zip(rays.par_chunks(CHUNK))
        .with_max_len(1)
        .for_each(|(out, rays)| {
            for (o, r) in out.chunks_mut(P).zip(rays.chunks(P)) {
                // a last, short packet repeats its first ray in the lanes
                // it leaves inactive
                let mut packet = [r[0]; P];
                packet[..r.len()].copy_from_slice(r);
                let h = accel.intersect_packet(&packet, (1u32 << r.len()) - 1);
                for (o, h) in o.iter_mut().zip(h) {
                    *o = h.map_or((f32::INFINITY, -1, -1), |h| {
                        (h.t, h.shape as i32, h.prim as i32)
                    });
                }
            }
        });
}

/// Which of `rays` are blocked, `P` consecutive rays at a time as one
/// packet ([`Accel::occluded_packet`]), in chunks of [`CHUNK`] rays on
/// rayon's threads.
fn test_packets<const P: usize>(accel: &Accel, blocked: &mut [bool], rays: &[Ray]) {
    blocked
        .par_chunks_mut(CHUNK)
        .zip(rays.par_chunks(CHUNK))
        .with_max_len(1)
        .for_each(|(out, rays)| {
            for (o, r) in out.chunks_mut(P).zip(rays.chunks(P)) {
                let mut packet = [r[0]; P];
                packet[..r.len()].copy_from_slice(r);
                let b = accel.occluded_packet(&packet, (1u32 << r.len()) - 1);
                for (i, o) in o.iter_mut().enumerate() {
                    *o = b >> i & 1 != 0;
                }
            }
        });
}
