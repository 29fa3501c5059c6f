//! Renders the bundled scenes and compares them with Mitsuba 3's high-spp
//! references (scenes/refs/, see scenes/README.md), with bounds derived from
//! the variance of our own estimator rather than tuned by hand.
//!

use crate::reference_check;
use crate::volume_scenes;

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

#[test]
fn volume_homogeneous_matches_mitsuba() {
    let excluded = volume_scenes::box_footprint_mask("volume_homog");
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
    let excluded = volume_scenes::box_footprint_mask("volume_hetero");
    check_excluding(
        "volume_hetero",
        "volume_hetero_ref256.exr",
        512,
        2,
        &excluded,
    );
}
