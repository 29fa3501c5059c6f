//! Shape plugins, one file each. Mesh plugins (`ply`, `obj`, `serialized`,
//! `rectangle`, `cube`) produce a [`Mesh`](crate::geometry::mesh::Mesh); `sphere`,
//! `disk` and `cylinder` are analytic.

pub mod cube;
pub mod cylinder;
pub mod disk;
pub mod obj;
pub mod ply;
pub mod rectangle;
pub mod serialized;
pub mod sphere;

pub use cylinder::Cylinder;
pub use disk::Disk;
pub use sphere::Sphere;

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::mesh::MeshOptions;
use crate::geometry::{Hit, SurfaceInteraction};
use crate::math::{Frame, V2, V3};
use crate::scene::description::Node;
use std::f32::consts::PI;

/// `face_normals` and `flip_normals` of a mesh plugin.
pub(crate) fn mesh_options(node: &Node) -> Result<MeshOptions> {
    Ok(MeshOptions {
        face_normals: node.bool("face_normals", false)?,
        flip_normals: node.bool("flip_normals", false)?,
    })
}

/// The required `filename` parameter, resolved relative to the scene file.
pub(crate) fn filename(
    node: &Node,
    ctx: &crate::scene::description::LoadContext,
) -> Result<std::path::PathBuf> {
    let f = node
        .string_opt("filename")?
        .ok_or_else(|| node.error("missing required parameter 'filename'"))?;
    ctx.resolve_path(node, "filename", &f)
}

/// The azimuth `atan2(y, x)` wrapped to [0, 2π) (the φ of the analytic
/// shapes' uv parametrisations).
pub(crate) fn azimuth<R: ScalarReal>(y: R, x: R) -> R {
    let mut phi = y.atan2(x);
    if phi.val() < 0.0 {
        phi += R::cst(2.0 * PI);
    }
    phi
}

/// The local geometry of an analytic shape at distance `t`, point `p`,
/// with unit normal `n` (as oriented after `flip_normals`), tangents
/// `[∂p/∂u, ∂p/∂v]`, surface coordinates `uv` and area scale `area_scale`
/// (see [`SurfaceInteraction::area_scale`]): the shading frame from `n`
/// and ∂p/∂u; `wi` zero.
#[allow(clippy::too_many_arguments)]
pub(crate) fn analytic_interaction<R: ScalarReal>(
    hit: &Hit,
    t: R,
    p: V3<R>,
    n: V3<R>,
    [dp_du, dp_dv]: [V3<R>; 2],
    uv: V2<R>,
    area_scale: R,
) -> SurfaceInteraction<R> {
    SurfaceInteraction {
        t,
        p,
        n,
        sh_frame: Frame::from_normal_tangent(n, dp_du),
        uv,
        dp_du,
        dp_dv,
        wi: V3::zero(),
        area_scale,
        shape: hit.shape,
        prim: hit.prim,
        vertices: [0; 3],
        bary: V2::zero(),
    }
}
