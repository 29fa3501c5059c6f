//! The `ply` shape plugin: a triangle mesh from a Stanford PLY file.
//! Parameters: `filename`, `face_normals` (false), `flip_normals` (false),
//! `to_world`.

use crate::error::Result;
use crate::geometry::mesh::Mesh;
use crate::scene::description::{LoadContext, Node};

/// Builds the mesh of a `<shape type="ply">` node.
pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Mesh> {
    let path = super::filename(node, ctx)?;
    let opts = super::mesh_options(node)?;
    let to_world = node.transform("to_world")?;
    let data = crate::geometry::ply::load_ply(&path).map_err(|e| node.error(e))?;
    Mesh::new(
        "ply",
        &node.key,
        &path.display().to_string(),
        data,
        &to_world,
        opts,
        &mut ctx.store,
    )
    .map_err(|e| node.error(e))
}
