//! Shape plugins, one file each. Mesh plugins (`ply`, `obj`, `rectangle`,
//! `cube`) produce a [`Mesh`](crate::geometry::mesh::Mesh); `sphere` and
//! `disk` are analytic.

pub mod cube;
pub mod disk;
pub mod obj;
pub mod ply;
pub mod rectangle;
pub mod sphere;

pub use disk::Disk;
pub use sphere::Sphere;

use crate::error::Result;
use crate::geometry::mesh::MeshOptions;
use crate::scene::Node;

/// `face_normals` and `flip_normals` of a mesh plugin.
pub(crate) fn mesh_options(node: &Node) -> Result<MeshOptions> {
    Ok(MeshOptions {
        face_normals: node.bool("face_normals", false)?,
        flip_normals: node.bool("flip_normals", false)?,
    })
}

/// The required `filename` parameter, resolved relative to the scene file.
pub(crate) fn filename(node: &Node, ctx: &crate::scene::LoadContext) -> Result<std::path::PathBuf> {
    let f = node
        .string_opt("filename")?
        .ok_or_else(|| node.error("missing required parameter 'filename'"))?;
    ctx.resolve_path(node, "filename", &f)
}
