//! Wavefront OBJ mesh loading with the `tobj` crate: positions, normals and
//! texture coordinates, polygons triangulated, all objects and groups of
//! the file merged into one mesh.
//!
//! Like Mitsuba 3's `obj` plugin (parameter `flip_tex_coords`, default
//! true), the vertical texture coordinate is flipped on load: `v = 1 - v`.
//!
//! Vertex colours (the common `v x y z r g b` extension) load and are not
//! used, as in Mitsuba 3.9.1, whose `obj` plugin reads only positions,
//! normals and texture coordinates: an OBJ mesh has no `vertex_color`
//! attribute there (a `mesh_attribute` texture naming it fails to render),
//! nor here (naming it is an error at load).

use crate::error::{Error, Result};
use crate::geometry::mesh::MeshData;
use glam::{Vec2, Vec3};
use std::path::Path;

/// Reads an OBJ file into object-space mesh data (not yet validated).
/// Normals (texture coordinates) are kept only if every object has them.
pub fn load_obj(path: &Path, flip_tex_coords: bool) -> Result<MeshData> {
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) = tobj::load_obj(path, &opts)
        .map_err(|e| Error::file(path, format!("invalid OBJ file: {e}")))?;
    let mut data = MeshData::default();
    let all_normals = models
        .iter()
        .all(|m| !m.mesh.normals.is_empty() && m.mesh.normals.len() == m.mesh.positions.len());
    let all_uvs = models.iter().all(|m| {
        !m.mesh.texcoords.is_empty() && m.mesh.texcoords.len() / 2 == m.mesh.positions.len() / 3
    });
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for m in &models {
        let base = data.positions.len() as u32;
        let mesh = &m.mesh;
        data.positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        if all_normals {
            normals.extend(
                mesh.normals
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2])),
            );
        }
        if all_uvs {
            uvs.extend(
                mesh.texcoords
                    .chunks_exact(2)
                    .map(|t| Vec2::new(t[0], if flip_tex_coords { 1.0 - t[1] } else { t[1] })),
            );
        }
        data.faces.extend(
            mesh.indices
                .chunks_exact(3)
                .map(|f| [f[0] + base, f[1] + base, f[2] + base]),
        );
    }
    if all_normals && !models.is_empty() {
        data.normals = Some(normals);
    }
    if all_uvs && !models.is_empty() {
        data.texcoords = Some(uvs);
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_quad_is_triangulated_and_v_flipped() {
        let dir = std::env::temp_dir().join(format!("penumbra-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("quad.obj");
        std::fs::write(
            &p,
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 0.25\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n",
        )
        .unwrap();
        let d = load_obj(&p, true).unwrap();
        assert_eq!(d.faces.len(), 2);
        assert_eq!(d.positions.len(), 4);
        assert!(d.normals.as_ref().unwrap().iter().all(|n| *n == Vec3::Z));
        let uv = d.texcoords.as_ref().unwrap();
        // vertex 4 has vt (0, 0.25) -> (0, 0.75)
        let i = d
            .positions
            .iter()
            .position(|p| *p == Vec3::new(0.0, 1.0, 0.0))
            .unwrap();
        assert!((uv[i] - Vec2::new(0.0, 0.75)).length() < 1e-6);
        let d = load_obj(&p, false).unwrap();
        assert!((d.texcoords.unwrap()[i] - Vec2::new(0.0, 0.25)).length() < 1e-6);
        assert!(load_obj(&dir.join("none.obj"), true).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// `v x y z r g b` lines (vertex colours) load as positions; the
    /// colours are not kept, as Mitsuba 3.9.1 keeps none.
    #[test]
    fn vertex_colours_load_and_are_not_kept() {
        let dir = std::env::temp_dir().join(format!("penumbra-objc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("coloured.obj");
        std::fs::write(
            &p,
            "v -1 -1 0 1 0 0\nv 1 -1 0 0 1 0\nv 1 1 0 0 0 1\nv -1 1 0 1 1 0\nf 1 2 3\nf 1 3 4\n",
        )
        .unwrap();
        let d = load_obj(&p, true).unwrap();
        assert_eq!(d.faces.len(), 2);
        assert_eq!(d.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert!(d.attributes.is_empty());
        std::fs::remove_dir_all(&dir).ok();
    }
}
