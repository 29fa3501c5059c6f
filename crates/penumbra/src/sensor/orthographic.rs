//! The orthographic camera (Mitsuba's `orthographic`): parallel rays over
//! the [-1,1] × [-1/aspect, 1/aspect] window, scaled by `to_world`.

use super::clip_range;
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::Transform;
use crate::scene::Node;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Orthographic {
    pub to_world: Transform,
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
}

impl Orthographic {
    pub fn from_node(node: &Node, aspect: f32) -> Result<Orthographic> {
        let (near, far) = clip_range(node)?;
        Ok(Orthographic {
            to_world: node.transform("to_world")?,
            aspect,
            near,
            far,
        })
    }

    #[inline]
    pub fn sample_ray(&self, pos: Vec2) -> Ray {
        let local = Vec3::new(1.0 - 2.0 * pos.x, (1.0 - 2.0 * pos.y) / self.aspect, 0.0);
        let d = self.to_world.vector(Vec3::Z);
        let len = d.length();
        Ray {
            o: self.to_world.point(local),
            d: d / len,
            tmin: self.near * len,
            tmax: self.far * len,
        }
    }
}
