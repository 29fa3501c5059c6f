//! The pinhole camera (Mitsuba's `perspective`).
//!
//! Parameters: `<key>.to_world`, `<key>.x_fov`,
//! `<key>.principal_point_offset_x`, `<key>.principal_point_offset_y`.

use super::{Frustum, ToWorld};
use crate::ad::ScalarReal;
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
    pub(crate) fn ray<R: ScalarReal>(
        &self,
        to_world: &ToWorld<R>,
        lens: (R, [R; 2]),
        pos: Vec2,
    ) -> DiffRay<R> {
        // v has v.z = 1: the unit direction's view-axis component is
        // 1 / |v|, so the clip planes (along the view axis) lie at near ·
        // |v| and far · |v| along the ray. One normalisation, after
        // to_world (the same direction as normalising before it too): the
        // camera ray starts every sample, and its chain of square roots
        // and divisions was its latency.
        let v = self.frustum.direction::<R>(lens, [pos.x, pos.y]);
        let len = v.val().length();
        DiffRay {
            o: to_world.point(crate::math::V3::zero()),
            d: to_world.vector(v).normalize(),
            tmin: self.frustum.near * len,
            tmax: self.frustum.far * len,
        }
    }
}
