//! Degenerate meshes that Mitsuba renders render here too: zero-area and
//! duplicate faces are skipped (and counted), and the image is the one of
//! the mesh without them; a NaN vertex position stays an error that names
//! the file and the vertex.

use crate::common;

use penumbra::geometry::{Shape, SkippedFaces};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::path::{Path, PathBuf};

/// Vertices of a 1×1 light at y = 2 facing down, and a fifth vertex on the
/// line through the first two.
const VERTICES: &str = "v -0.5 2 -0.5\nv 0.5 2 -0.5\nv 0.5 2 0.5\nv -0.5 2 0.5\nv 1.5 2 -0.5\n";
const FACES: &str = "f 1 2 3\nf 1 3 4\n";
/// A duplicate of face 1 (other orientation), a flat face, a face with a
/// repeated vertex.
const BAD_FACES: &str = "f 3 2 1\nf 1 2 5\nf 2 2 3\n";

fn scene_with_light(dir: &Path, name: &str, obj: &str) -> Scene {
    let obj_path = dir.join(format!("{name}.obj"));
    std::fs::write(&obj_path, obj).unwrap();
    let sensor = common::sensor_xml("0, 1, 3", 60.0, 16, 4, None);
    let xml = format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="3"/></integrator>
            {sensor}
            <shape type="rectangle">
                <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
            </shape>
            <shape type="obj" id="light">
                <string name="filename" value="{}"/>
                <emitter type="area"><rgb name="radiance" value="5, 5, 5"/></emitter>
            </shape>
        </scene>"#,
        obj_path.display()
    );
    Scene::load_str(&xml, &dir.join(format!("{name}.xml")), &[]).unwrap()
}

fn temp_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("penumbra-degenerate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn zero_area_and_duplicate_faces_render_as_nothing() {
    let dir = temp_dir();
    let clean = scene_with_light(&dir, "clean", &format!("{VERTICES}{FACES}"));
    let bad = scene_with_light(&dir, "bad", &format!("{VERTICES}{FACES}{BAD_FACES}"));
    let Shape::Mesh(m) = &bad.shapes[1] else {
        panic!("the light is a mesh")
    };
    assert_eq!(
        m.skipped,
        SkippedFaces {
            zero_area: 2,
            duplicate: 1
        }
    );
    assert_eq!(m.vertex_count(&bad.params), 5);
    let opts = RenderOptions {
        seed: 7,
        ..Default::default()
    };
    let (a, b) = (render(&clean, &opts).unwrap(), render(&bad, &opts).unwrap());
    let mean = a.data.iter().map(|&v| v as f64).sum::<f64>() / a.data.len() as f64;
    assert!(mean > 0.01, "the light must reach the ground: mean {mean}");
    // same samples, same emitter sampling (the flat face has zero weight):
    // the same image up to the rounding of a different BVH
    for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
        assert!(
            (x - y).abs() <= 1e-5 * x.abs().max(1.0),
            "value {i}: {x} without the bad faces, {y} with them"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn nan_vertex_position_is_an_error_naming_file_and_vertex() {
    let xml = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_scenes/nan_vertex.xml");
    let e = Scene::load_file(&xml, &[]).unwrap_err().to_string();
    assert!(
        e.contains("nan_vertex.xml:4")
            && e.contains("nan_vertex.obj")
            && e.contains("vertex 2")
            && e.contains("non-finite"),
        "{e}"
    );
}
