//! The conformance set: small scenes written as a user's file would use a
//! Mitsuba 3 feature (scenes/conformance/*.xml, one feature each, see
//! scenes/conformance/README.md), each rendered by Penumbra and compared
//! with Mitsuba 3's render of the same unchanged file
//! (scenes/conformance/refs/<name>.exr, [`REF_SPP`] samples per pixel,
//! made by scripts/mitsuba/make_conformance_refs.py) at the tolerance
//! reference_check/mod.rs derives from our estimator's variance. Every
//! scene runs in batches of its own sampler's sample count; one test
//! reports every scene that fails.

mod reference_check;

use std::path::PathBuf;

/// Samples per pixel of every conformance reference.
const REF_SPP: u32 = 4096;

#[test]
fn conformance_scenes_match_mitsuba() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/conformance");
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "xml"))
        .collect();
    scenes.sort();
    assert!(!scenes.is_empty(), "no scenes in {}", dir.display());
    let mut failures = Vec::new();
    for scene in &scenes {
        let name = scene.file_stem().unwrap().to_string_lossy();
        let reference = dir.join("refs").join(format!("{name}.exr"));
        if !reference.is_file() {
            failures.push(format!(
                "{}: no reference {} (make it with scripts/mitsuba/make_conformance_refs.py)",
                scene.display(),
                reference.display()
            ));
            continue;
        }
        if let Err(e) = reference_check::compare(scene, &reference, REF_SPP, None) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
