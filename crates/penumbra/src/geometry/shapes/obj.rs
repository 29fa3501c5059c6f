//! The `obj` shape plugin: a triangle mesh from a Wavefront OBJ file.
//! Parameters: `filename`, `face_normals` (false), `flip_normals` (false),
//! `flip_tex_coords` (true, as Mitsuba 3: v = 1 - v), `to_world`.

use crate::error::Result;
use crate::geometry::mesh::Mesh;
use crate::scene::description::{LoadContext, Node};

/// Builds the mesh of a `<shape type="obj">` node.
pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Mesh> {
    let path = super::filename(node, ctx)?;
    let opts = super::mesh_options(node)?;
    let flip_tex = node.bool("flip_tex_coords", true)?;
    let to_world = node.transform("to_world")?;
    let data = crate::geometry::obj::load_obj(&path, flip_tex).map_err(|e| node.error(e))?;
    Mesh::new(
        "obj",
        &node.key,
        &path.display().to_string(),
        data,
        &to_world,
        opts,
        &mut ctx.store,
    )
    .map_err(|e| node.error(e))
}
