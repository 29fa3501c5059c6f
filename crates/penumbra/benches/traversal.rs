//! Ray traversal throughput (rays per second, one thread) on the 327,680-
//! triangle displaced sphere of the reference scenes, with camera-like
//! rays: a pinhole camera at distance 4 looking at the mesh, 256×256
//! pixel grid, jittered. Closest hit (`Accel::intersect`) and occlusion
//! (`Accel::occluded`, shadow rays from the hit points towards a light),
//! with the widest nodes the CPU traverses and with the 4-wide fallback.
//!
//! Run: `cargo bench -p penumbra --bench traversal`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::Vec3;
use penumbra::geometry::accel::Width;
use penumbra::geometry::{ply, Accel, Mesh, MeshOptions, Ray, Shape};
use penumbra::math::Transform;
use penumbra::params::ParamStore;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

/// The bundled mesh (scenes/meshes/), relative to the repository root.
const MESH: &str = "scenes/meshes/displaced_sphere.ply";

fn camera_rays(n_side: usize) -> Vec<Ray> {
    let eye = Vec3::new(0.3, 1.5, 3.5);
    let fwd = (Vec3::new(0.0, 1.0, 0.0) - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tan = (30f32.to_radians() * 0.5).tan();
    let mut rays = Vec::with_capacity(n_side * n_side);
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    for j in 0..n_side {
        for i in 0..n_side {
            let x = ((i as f32 + rnd()) / n_side as f32 * 2.0 - 1.0) * tan;
            let y = ((j as f32 + rnd()) / n_side as f32 * 2.0 - 1.0) * tan;
            rays.push(Ray::new(eye, (fwd + right * x + up * y).normalize()));
        }
    }
    rays
}

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(MESH);
    let t0 = Instant::now();
    let data = ply::load_ply(&path).unwrap_or_else(|e| panic!("{MESH}: {e}"));
    let mut store = ParamStore::new();
    let mesh = Mesh::new(
        "ply",
        "mesh",
        MESH,
        data,
        &Transform::IDENTITY,
        MeshOptions {
            face_normals: true,
            flip_normals: false,
        },
        &mut store,
    )
    .expect("reference mesh is valid");
    let t1 = Instant::now();
    let shapes = vec![Shape::Mesh(mesh)];
    let accel = Accel::build(&shapes, &store);
    let t2 = Instant::now();
    eprintln!(
        "load {:.0} ms, build {:.0} ms ({} triangles)",
        (t1 - t0).as_secs_f64() * 1e3,
        (t2 - t1).as_secs_f64() * 1e3,
        accel.prim_count()
    );
    let mut accel_u = accel.clone();
    let t3 = Instant::now();
    accel_u.update(&shapes, &store);
    eprintln!("refit {:.0} ms", t3.elapsed().as_secs_f64() * 1e3);

    let rays = camera_rays(256);
    let light = Vec3::new(2.0, 4.0, 3.0);
    let shadow: Vec<Ray> = rays
        .iter()
        .filter_map(|r| accel.intersect(r))
        .zip(rays.iter())
        .map(|(h, r)| {
            let p = r.at(h.t);
            let n = shapes[0]
                .as_mesh()
                .expect("a mesh")
                .face_normal(&store, h.prim as usize);
            let o = p + n * (if n.dot(-r.d) > 0.0 { 1e-4 } else { -1e-4 });
            let d = light - o;
            let dist = d.length();
            Ray {
                o,
                d: d / dist,
                tmin: 0.0,
                tmax: dist * (1.0 - 1e-4),
            }
        })
        .collect();
    eprintln!("{} camera rays, {} shadow rays", rays.len(), shadow.len());

    let mut widths = vec![(Width::detect(), accel)];
    if Width::detect() != Width::Four {
        widths.push((
            Width::Four,
            Accel::build_with_width(&shapes, &store, Width::Four),
        ));
    }
    let mut g = c.benchmark_group("displaced_sphere");
    for (w, accel) in &widths {
        let wide = if *w == Width::Four { "4" } else { "8" };
        g.throughput(Throughput::Elements(rays.len() as u64));
        g.bench_function(format!("closest_hit_{wide}wide"), |b| {
            b.iter(|| {
                let mut n = 0u32;
                for r in &rays {
                    n += accel.intersect(black_box(r)).is_some() as u32;
                }
                n
            })
        });
        g.throughput(Throughput::Elements(shadow.len() as u64));
        g.bench_function(format!("occluded_{wide}wide"), |b| {
            b.iter(|| {
                let mut n = 0u32;
                for r in &shadow {
                    n += accel.occluded(black_box(r)) as u32;
                }
                n
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
