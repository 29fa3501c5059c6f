//! The orthographic camera (Mitsuba's `orthographic`): parallel rays over
//! the [-1,1] × [-1/aspect, 1/aspect] window, scaled by `to_world`.
//!
//! Parameter: `<key>.to_world`.

use super::{clip_range, ToWorld};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::DiffRay;
use crate::math::V3;
use crate::scene::description::Node;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Orthographic {
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
}

impl Orthographic {
    pub fn from_node(node: &Node, aspect: f32) -> Result<Orthographic> {
        let (near, far) = clip_range(node)?;
        Ok(Orthographic { aspect, near, far })
    }

    #[inline]
    pub(crate) fn ray<R: ScalarReal>(&self, to_world: &ToWorld<R>, pos: Vec2) -> DiffRay<R> {
        let local = Vec3::new(1.0 - 2.0 * pos.x, (1.0 - 2.0 * pos.y) / self.aspect, 0.0);
        let d = to_world.vector(V3::cst(Vec3::Z));
        // the clip range scales with to_world's z axis
        let len = d.length();
        DiffRay {
            o: to_world.point(V3::cst(local)),
            d: V3::new(d.x / len, d.y / len, d.z / len),
            tmin: self.near * len.val(),
            tmax: self.far * len.val(),
        }
    }
}
