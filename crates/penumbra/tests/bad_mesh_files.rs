//! Mesh files that cannot be read fail with a message naming the scene
//! file and line, the mesh file, and what is wrong with it
//! (tests/bad_scenes/serialized_*.xml); mesh attributes a texture needs
//! and the mesh lacks.

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

/// A `mesh_attribute` texture on a shape without the attribute, or on a
/// shape that is not a mesh, fails at load at the texture's line (Mitsuba
/// would only fail while rendering).
#[test]
fn mesh_attribute_needs_a_mesh_with_the_attribute() {
    let ply = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes/conformance/assets/vertex_color.ply");
    for (shape, name, needle) in [
        (
            format!(
                r#"type="ply"><string name="filename" value="{}"/>"#,
                ply.display()
            ),
            "vertex_foo",
            "shape 'a' has no attribute 'vertex_foo' (it has: vertex_color)",
        ),
        (
            r#"type="sphere">"#.to_string(),
            "vertex_color",
            "used on shape 'a', which is not a mesh",
        ),
    ] {
        let xml = format!(
            r#"<scene version="3.0.0">
    <sensor type="perspective"/>
    <shape id="a" {shape}
        <bsdf type="diffuse">
            <texture type="mesh_attribute" name="reflectance">
                <string name="name" value="{name}"/>
            </texture>
        </bsdf>
    </shape>
</scene>"#
        );
        let e = Scene::load_str(&xml, Path::new("attr.xml"), &[])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("attr.xml:5: ") && e.contains(needle), "{e}");
    }
}
