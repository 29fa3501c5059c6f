//! The `rectangle` shape plugin: the square [-1,1]² in the z = 0 plane,
//! normal +z, uv = ((x+1)/2, (y+1)/2), placed by `to_world` (Mitsuba 3's
//! conventions). Realised as a two-triangle mesh, so its parameters are
//! `<key>.vertex_positions` and `<key>.vertex_texcoords` (Mitsuba exposes
//! `to_world` instead). The normal is `to_world`'s normal transform of +z,
//! also for transforms that mirror (the winding is reversed then).
//! Parameters: `to_world`, `flip_normals` (false).

use crate::error::Result;
use crate::geometry::mesh::{Mesh, MeshData, MeshOptions};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Object-space data of the rectangle (counter-clockwise seen from +z).
pub fn rectangle_data(mirror: bool) -> MeshData {
    let faces = if mirror {
        vec![[0, 2, 1], [0, 3, 2]]
    } else {
        vec![[0, 1, 2], [0, 2, 3]]
    };
    MeshData {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: None,
        texcoords: Some(vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ]),
        faces,
        attributes: Vec::new(),
    }
}

/// Builds the mesh of a `<shape type="rectangle">` node.
pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Mesh> {
    let to_world = node.transform("to_world")?;
    let opts = MeshOptions {
        face_normals: true,
        flip_normals: node.bool("flip_normals", false)?,
    };
    let data = rectangle_data(to_world.flips_handedness());
    Mesh::new(
        "rectangle",
        &node.key,
        "rectangle",
        data,
        &to_world,
        opts,
        &mut ctx.store,
    )
    .map_err(|e| node.error(e))
}
