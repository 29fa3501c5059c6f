//! Renders the bundled scenes and compares them with Mitsuba 3's high-spp
//! references (scenes/refs/, see scenes/README.md), with bounds derived from
//! the variance of our own estimator rather than tuned by hand.
//!

mod reference_check;

use std::path::PathBuf;

/// Renders `scenes/<name>.xml` in batches of `spp` samples per pixel and
/// compares it with `scenes/refs/<reference>`, rendered by Mitsuba with
/// `ref_spp` samples per pixel (reference_check/mod.rs has the statistics).
fn check(name: &str, reference: &str, ref_spp: u32, spp: u32) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let scene = dir.join(format!("{name}.xml"));
    if let Err(e) = reference_check::compare(
        &scene,
        &dir.join("refs").join(reference),
        ref_spp,
        Some(spp),
    ) {
        panic!("{e}");
    }
}

/// [`check`] without the pixels `excluded` says.
fn check_excluding(
    name: &str,
    reference: &str,
    ref_spp: u32,
    spp: u32,
    excluded: &dyn Fn(usize, usize) -> bool,
) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let scene = dir.join(format!("{name}.xml"));
    if let Err(e) = reference_check::compare_excluding(
        &scene,
        &dir.join("refs").join(reference),
        ref_spp,
        Some(spp),
        excluded,
    ) {
        panic!("{e}");
    }
}

// Reference spp from scenes/refs/index.json.

#[test]
fn cbox_matches_mitsuba() {
    check("cbox", "cbox_ref256.exr", 2048, 1);
}

#[test]
fn mesh_heavy_matches_mitsuba() {
    check("mesh_heavy", "mesh_heavy_ref256.exr", 1024, 1);
}

#[test]
fn textured_matches_mitsuba() {
    check("textured", "textured_ref256.exr", 1024, 1);
}

#[test]
fn bsdfs_matches_mitsuba() {
    check("bsdfs", "bsdfs_ref256.exr", 2048, 1);
}

#[test]
fn direct_integrator_matches_mitsuba() {
    check("direct", "direct_ref96.exr", 16384, 16);
}

#[test]
fn thinlens_matches_mitsuba() {
    check("thinlens", "thinlens_ref96.exr", 16384, 16);
}

#[test]
fn orthographic_matches_mitsuba() {
    check("orthographic", "orthographic_ref96.exr", 16384, 16);
}

/// The pixels of the volume scenes whose camera rays (any of 4×4 points
/// in the pixel) reach the ground inside the medium box's footprint
/// (|x|, |z| ≤ 0.5 + a margin). The box's bottom face lies in the
/// ground's plane, so which of the two coplanar surfaces a ray meets
/// first (and whether the path is then inside the medium) is decided by
/// rounding: Mitsuba's reference shows it changing from one triangle of
/// the face to the other. Those pixels are left out.
fn volume_box_footprint(scene_path: &str) -> impl Fn(usize, usize) -> bool {
    use penumbra::bsdf::Bsdf;
    use penumbra::geometry::Ray;
    use penumbra::scene::Scene;
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(scene_path);
    let scene = Scene::load_file(&path, &[]).unwrap();
    let sensor = &scene.sensors[0];
    let (w, h) = sensor.film.crop_size;
    let store = scene.params.primal();
    let margin = 0.02;
    let mut mask = vec![false; w * h];
    for (p, m) in mask.iter_mut().enumerate() {
        let (x, y) = (p % w, p / w);
        *m = (0..16).any(|k| {
            let film = glam::Vec2::new(
                (x as f32 + (k % 4) as f32 / 3.0) / w as f32,
                (y as f32 + (k / 4) as f32 / 3.0) / h as f32,
            );
            let mut ray: Ray = sensor.ray::<f32>(&store, film, glam::Vec2::ZERO).val();
            while let Some(hit) = scene.intersect(&ray) {
                let q = ray.at(hit.t);
                if q.y.abs() < 1e-3 && q.x.abs() < 0.5 + margin && q.z.abs() < 0.5 + margin {
                    return true;
                }
                if !matches!(scene.shape_bsdf(hit.shape), Bsdf::Null(_)) {
                    return false;
                }
                ray = Ray::new(q + ray.d * 1e-3, ray.d);
            }
            false
        });
    }
    move |x, y| mask[y * w + x]
}

#[test]
fn volume_homogeneous_matches_mitsuba() {
    let excluded = volume_box_footprint("../../scenes/volume_homog.xml");
    check_excluding(
        "volume_homog",
        "volume_homog_ref256.exr",
        1024,
        2,
        &excluded,
    );
}

#[test]
fn volume_heterogeneous_matches_mitsuba() {
    let excluded = volume_box_footprint("../../scenes/volume_hetero.xml");
    check_excluding(
        "volume_hetero",
        "volume_hetero_ref256.exr",
        512,
        2,
        &excluded,
    );
}
