//! The conformance set: small scenes written as a user's file would use a
//! Mitsuba 3 feature (scenes/conformance/*.xml, one feature each, see
//! scenes/conformance/README.md), each rendered by Penumbra and compared
//! with Mitsuba 3's render of the same unchanged file
//! (scenes/conformance/refs/<name>.exr, [`REF_SPP`] samples per pixel,
//! made by scripts/mitsuba/make_conformance_refs.py) at the tolerance
//! reference_check/mod.rs derives from our estimator's variance. Every
//! scene runs in batches of its own sampler's sample count; one test
//! reports every scene that fails. `PENUMBRA_CONFORMANCE=name,name` runs
//! only those scenes (while working on a feature).

use crate::reference_check;

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
    if let Ok(only) = std::env::var("PENUMBRA_CONFORMANCE") {
        let names: Vec<&str> = only.split(',').map(str::trim).collect();
        for n in &names {
            assert!(
                scenes
                    .iter()
                    .any(|s| s.file_stem().is_some_and(|f| f == *n)),
                "PENUMBRA_CONFORMANCE names '{n}', which is not a scene of {}",
                dir.display()
            );
        }
        scenes.retain(|s| s.file_stem().is_some_and(|f| names.iter().any(|n| f == *n)));
    }
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

/// Scenes whose reference is Mitsuba's render of a twin file (the same
/// scene in a form Mitsuba 3.9.1 renders, see
/// scripts/mitsuba/make_conformance_refs.py): the twin must be the same
/// scene, so Penumbra must load both into the same parameters, values
/// included.
#[test]
fn reference_twins_are_the_same_scenes() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/conformance");
    for (scene, twin) in [(
        "serialized_vertex_color.xml",
        "assets/serialized_vertex_color_twin.xml",
    )] {
        let load = |f: &str| penumbra::scene::Scene::load_file(&dir.join(f), &[]).unwrap();
        let (a, b) = (load(scene), load(twin));
        let params = |s: &penumbra::scene::Scene| {
            let mut v: Vec<(String, Vec<f32>)> = s
                .params
                .iter()
                .map(|(_, p)| (p.key.clone(), p.data.clone()))
                .collect();
            v.sort_by(|x, y| x.0.cmp(&y.0));
            v
        };
        let (pa, pb) = (params(&a), params(&b));
        let keys = |p: &[(String, Vec<f32>)]| p.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
        assert_eq!(keys(&pa), keys(&pb), "{scene} and {twin}: other parameters");
        for ((key, x), (_, y)) in pa.iter().zip(&pb) {
            assert_eq!(x, y, "{scene} and {twin}: {key} differs");
        }
        assert!(
            pa.iter().any(|(k, _)| k == "gem.vertex_color"),
            "{scene}: the colours are parameters"
        );
    }
}
