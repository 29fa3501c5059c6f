//! The `cube` shape plugin: the cube [-1,1]³ as a mesh of 24 vertices (4
//! per face, with the face's outward normal as vertex normal) and 12
//! triangles; every face maps onto [0,1]² in uv. Vertex, normal, uv and
//! triangle tables follow Mitsuba 3's cube, so textures land alike.
//! Parameters: `to_world`, `flip_normals` (false).

use crate::error::Result;
use crate::geometry::mesh::{Mesh, MeshData, MeshOptions};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// Object-space data of the cube.
pub fn cube_data() -> MeshData {
    // per face: outward normal and its four corners (counter-clockwise
    // seen from outside), uvs (0,1) (1,1) (1,0) (0,0)
    const FACES: [([f32; 3], [[f32; 3]; 4]); 6] = [
        (
            [0., -1., 0.],
            [
                [1., -1., -1.],
                [1., -1., 1.],
                [-1., -1., 1.],
                [-1., -1., -1.],
            ],
        ),
        (
            [0., 1., 0.],
            [[1., 1., -1.], [-1., 1., -1.], [-1., 1., 1.], [1., 1., 1.]],
        ),
        (
            [1., 0., 0.],
            [[1., -1., -1.], [1., 1., -1.], [1., 1., 1.], [1., -1., 1.]],
        ),
        (
            [0., 0., 1.],
            [[1., -1., 1.], [1., 1., 1.], [-1., 1., 1.], [-1., -1., 1.]],
        ),
        (
            [-1., 0., 0.],
            [
                [-1., -1., 1.],
                [-1., 1., 1.],
                [-1., 1., -1.],
                [-1., -1., -1.],
            ],
        ),
        (
            [0., 0., -1.],
            [
                [1., 1., -1.],
                [1., -1., -1.],
                [-1., -1., -1.],
                [-1., 1., -1.],
            ],
        ),
    ];
    const UV: [[f32; 2]; 4] = [[0., 1.], [1., 1.], [1., 0.], [0., 0.]];
    let mut d = MeshData {
        normals: Some(Vec::new()),
        texcoords: Some(Vec::new()),
        ..Default::default()
    };
    for (f, (n, corners)) in FACES.iter().enumerate() {
        for (c, uv) in corners.iter().zip(UV) {
            d.positions.push(Vec3::from_array(*c));
            d.normals
                .as_mut()
                .expect("set above")
                .push(Vec3::from_array(*n));
            d.texcoords
                .as_mut()
                .expect("set above")
                .push(Vec2::from_array(uv));
        }
        let b = 4 * f as u32;
        d.faces.push([b, b + 1, b + 2]);
        d.faces.push([b + 3, b, b + 2]);
    }
    d
}

/// Builds the mesh of a `<shape type="cube">` node.
pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Mesh> {
    let to_world = node.transform("to_world")?;
    let opts = MeshOptions {
        face_normals: false,
        flip_normals: node.bool("flip_normals", false)?,
    };
    Mesh::new(
        "cube",
        &node.key,
        "cube",
        cube_data(),
        &to_world,
        opts,
        &mut ctx.store,
    )
    .map_err(|e| node.error(e))
}
