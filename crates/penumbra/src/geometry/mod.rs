//! Shapes, meshes, the acceleration structure, and hit re-evaluation.
//!
//! Traversal is plain f32; after the acceleration structure reports a
//! [`Hit`], the shape re-evaluates the hit in `R` from its parameters
//! (vertex positions, centre, radius), so geometry derivatives can flow.

pub mod accel;
pub mod edges;
mod huge_pages;
pub mod instance;
mod interaction;
pub mod mesh;
pub mod obj;
pub mod ply;
pub mod serialized;
pub mod shape;
pub mod shapes;

pub use accel::{Accel, TreeStats};
pub use instance::{Instance, ShapeGroup};
pub use interaction::{DiffRay, Hit, PositionSample, Ray, SurfaceInteraction, SurfacePoint};
pub use mesh::{Mesh, MeshData, MeshOptions, SkippedFaces};
pub use shape::{Shape, ShapeT, SHAPE_PLUGINS};
