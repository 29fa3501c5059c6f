//! Whole-renderer throughput: the bundled Cornell box (path tracer, max
//! depth 8, gaussian filter) at 64×64 pixels, 4 samples per pixel, on one
//! thread, so that regressions anywhere on the primal rendering path
//! (traversal, hit re-evaluation, BSDFs, emitter sampling, film) show.
//!
//! Run: `cargo bench -p penumbra --bench render`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::hint::black_box;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cbox.xml");
    let defines = [("res".to_string(), "64".to_string())];
    let scene = Scene::load_file(&path, &defines).expect("the bundled Cornell box loads");
    let opts = RenderOptions {
        spp: Some(4),
        threads: Some(1),
        ..Default::default()
    };
    let mut g = c.benchmark_group("render");
    g.sample_size(20);
    g.throughput(Throughput::Elements(64 * 64 * 4));
    g.bench_function("cbox_64x64_4spp", |b| {
        b.iter(|| black_box(render(&scene, &opts).expect("renders")))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
