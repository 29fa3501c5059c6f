//! The pinhole camera (Mitsuba's `perspective`).
//!
//! Parameters: `<key>.to_world`, `<key>.x_fov`,
//! `<key>.principal_point_offset_x`, `<key>.principal_point_offset_y`.

use super::{Frustum, ToWorld};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::DiffRay;
use crate::params::ParamStore;
use crate::scene::description::Node;
use glam::Vec2;

/// A pinhole camera looking down its local +z.
#[derive(Clone, Debug)]
pub struct Perspective {
    pub frustum: Frustum,
}

impl Perspective {
    pub fn from_node(node: &Node, aspect: f32, store: &mut ParamStore) -> Result<Perspective> {
        // Mitsuba accepts (and ignores) a focus distance on pinholes.
        node.float("focus_distance", 0.0)?;
        Ok(Perspective {
            frustum: Frustum::from_node(node, aspect, true, store)?,
        })
    }

    #[inline]
    pub(crate) fn ray<R: Real>(
        &self,
        to_world: &ToWorld<R>,
        lens: (R, [R; 2]),
        pos: Vec2,
    ) -> DiffRay<R> {
        let d = self.frustum.direction::<R>(lens, pos).normalize();
        // the clip distances are along the view axis
        let dz = d.z.val();
        DiffRay {
            o: to_world.point(crate::math::V3::zero()),
            d: to_world.vector(d).normalize(),
            tmin: self.frustum.near / dz,
            tmax: self.frustum.far / dz,
        }
    }
}
