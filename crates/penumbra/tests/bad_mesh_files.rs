//! Mesh files that cannot be read fail with a message naming the scene
//! file and line, the mesh file, and what is wrong with it
//! (tests/bad_scenes/serialized_*.xml).

use penumbra::scene::Scene;
use std::path::Path;

#[test]
fn bad_serialized_files_name_scene_line_file_and_problem() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_scenes");
    let cases = [
        (
            "serialized_truncated.xml",
            "serialized_truncated.serialized",
            "truncated",
        ),
        (
            "serialized_bad_magic.xml",
            "serialized_bad_magic.serialized",
            "wrong format identifier 0x041D",
        ),
        (
            "serialized_index.xml",
            "two_shapes.serialized",
            "shape_index 2 is out of range: the file holds 2 shapes",
        ),
    ];
    for (scene, file, needle) in cases {
        let e = Scene::load_file(&dir.join(scene), &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("{scene}:4")) && e.contains(file) && e.contains(needle),
            "{scene}: {e}"
        );
    }
}
