//! The shape family. One file per plugin (geometry/shapes/); the enum
//! dispatches. Mesh plugins (`ply`, `obj`, `rectangle`, `cube`) all become
//! [`Shape::Mesh`]; `sphere` and `disk` are analytic.

use crate::ad::Real;
use crate::error::Result;
use crate::geometry::mesh::Mesh;
use crate::geometry::shapes::{self, Disk, Sphere};
use crate::geometry::{Hit, PositionSample, Ray, SurfaceInteraction};
use crate::params::{ParamId, ParamStore};
use crate::scene::{LoadContext, Node};
use glam::Vec2;

/// What every shape plugin provides.
pub trait ShapeT {
    /// Re-evaluates the hit reported by the acceleration structure, in `R`,
    /// from the shape's parameters.
    fn surface_interaction<R: Real>(
        &self,
        store: &ParamStore,
        ray: &Ray,
        hit: &Hit,
    ) -> SurfaceInteraction<R>;
    /// Samples a point uniformly with respect to surface area.
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample;
    /// Total surface area.
    fn surface_area(&self) -> f32;
}

/// Names of the shape plugins, for messages.
pub const SHAPE_PLUGINS: [&str; 6] = ["ply", "obj", "rectangle", "cube", "sphere", "disk"];

/// All shape plugins.
#[derive(Clone, Debug)]
pub enum Shape {
    /// `ply`, `obj`, `rectangle`, `cube`.
    Mesh(Mesh),
    Sphere(Sphere),
    Disk(Disk),
}

impl Shape {
    /// Builds a shape from its scene node. Reads only the geometric
    /// properties (`filename`, `to_world`, `face_normals`, `flip_normals`,
    /// `flip_tex_coords`, `center`, `radius`); the nested `bsdf`,
    /// `emitter`, `interior`, `exterior` are left to the scene builder.
    /// Registers the shape's parameters in `ctx.store` under `node.key`.
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Shape> {
        Ok(match node.plugin.as_str() {
            "ply" => Shape::Mesh(shapes::ply::load(node, ctx)?),
            "obj" => Shape::Mesh(shapes::obj::load(node, ctx)?),
            "rectangle" => Shape::Mesh(shapes::rectangle::load(node, ctx)?),
            "cube" => Shape::Mesh(shapes::cube::load(node, ctx)?),
            "sphere" => Shape::Sphere(Sphere::load(node, ctx)?),
            "disk" => Shape::Disk(Disk::load(node, ctx)?),
            other => {
                return Err(node.error(format!(
                    "unknown shape plugin '{other}'; supported: {}",
                    SHAPE_PLUGINS.join(", ")
                )))
            }
        })
    }

    /// The plugin name.
    pub fn plugin(&self) -> &'static str {
        match self {
            Shape::Mesh(m) => m.plugin,
            Shape::Sphere(_) => "sphere",
            Shape::Disk(_) => "disk",
        }
    }

    /// The parameter-key prefix.
    pub fn key(&self) -> &str {
        match self {
            Shape::Mesh(m) => &m.key,
            Shape::Sphere(s) => &s.key,
            Shape::Disk(d) => &d.key,
        }
    }

    /// Number of primitives (triangles; 1 for analytic shapes).
    pub fn prim_count(&self) -> usize {
        match self {
            Shape::Mesh(m) => m.faces.len(),
            _ => 1,
        }
    }

    pub fn as_mesh(&self) -> Option<&Mesh> {
        match self {
            Shape::Mesh(m) => Some(m),
            _ => None,
        }
    }

    /// Whether the shape flips its normals.
    pub fn flip_normals(&self) -> bool {
        match self {
            Shape::Mesh(m) => m.flip_normals,
            Shape::Sphere(s) => s.flip_normals,
            Shape::Disk(d) => d.flip_normals,
        }
    }

    /// Ids of the parameters that move this shape's surface (for the
    /// scene to know when the acceleration structure needs an update).
    pub fn geometry_params(&self) -> Vec<ParamId> {
        match self {
            Shape::Mesh(m) => vec![m.positions],
            Shape::Sphere(s) => vec![s.center, s.radius],
            Shape::Disk(d) => vec![d.to_world],
        }
    }

    /// Refreshes derived data after the parameters `changed` were updated
    /// (areas, sampling tables, recomputed vertex normals). Call
    /// [`crate::geometry::Accel::update`] afterwards if any geometry
    /// parameter changed.
    pub fn parameters_changed(
        &mut self,
        store: &mut ParamStore,
        changed: &[ParamId],
    ) -> Result<()> {
        match self {
            Shape::Mesh(m) => m.parameters_changed(store, changed),
            Shape::Sphere(s) => {
                s.parameters_changed(store);
                Ok(())
            }
            Shape::Disk(d) => d.parameters_changed(store),
        }
    }
}

impl ShapeT for Shape {
    #[inline]
    fn surface_interaction<R: Real>(
        &self,
        store: &ParamStore,
        ray: &Ray,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        match self {
            Shape::Mesh(m) => m.surface_interaction(store, ray, hit),
            Shape::Sphere(s) => s.surface_interaction(store, ray, hit),
            Shape::Disk(d) => d.surface_interaction(store, ray, hit),
        }
    }
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        match self {
            Shape::Mesh(m) => m.sample_position(store, u),
            Shape::Sphere(s) => s.sample_position(store, u),
            Shape::Disk(d) => d.sample_position(store, u),
        }
    }
    fn surface_area(&self) -> f32 {
        match self {
            Shape::Mesh(m) => m.surface_area(),
            Shape::Sphere(s) => s.surface_area(),
            Shape::Disk(d) => d.surface_area(),
        }
    }
}
