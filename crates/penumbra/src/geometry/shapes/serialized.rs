//! The `serialized` shape plugin: one triangle mesh of a Mitsuba
//! `.serialized` file (format in [`crate::geometry::serialized`]).
//! Parameters: `filename`, `shape_index` (0: which shape of the file),
//! `face_normals` (false), `flip_normals` (false), `to_world`. Vertex
//! colours of the file are the mesh attribute `vertex_color` (for the
//! `mesh_attribute` texture), which Mitsuba 3.9.1 does not read.

use crate::error::Result;
use crate::geometry::mesh::Mesh;
use crate::geometry::serialized::load_serialized;
use crate::scene::description::{LoadContext, Node};

/// Builds the mesh of a `<shape type="serialized">` node.
pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Mesh> {
    let path = super::filename(node, ctx)?;
    let opts = super::mesh_options(node)?;
    let index = node.int_min("shape_index", 0, 0)?;
    let to_world = node.transform("to_world")?;
    let shape = load_serialized(&path, index as usize).map_err(|e| node.error(e))?;
    let source = format!("{}@{index}", path.display());
    Mesh::new(
        "serialized",
        &node.key,
        &source,
        shape.data,
        &to_world,
        opts,
        &mut ctx.store,
    )
    .map_err(|e| node.error(e))
}
