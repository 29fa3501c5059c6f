//! The pinhole camera (Mitsuba's `perspective`).

use super::{clip_range, fov_x, pinhole_direction};
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::Transform;
use crate::scene::Node;
use glam::Vec2;

/// A pinhole camera looking down its local +z.
#[derive(Clone, Debug)]
pub struct Perspective {
    pub to_world: Transform,
    /// tan of half the horizontal field of view.
    pub tan_x: f32,
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
    /// Principal point offset, in units of the film size.
    pub offset: Vec2,
}

impl Perspective {
    pub fn from_node(node: &Node, aspect: f32) -> Result<Perspective> {
        let fov = fov_x(node, aspect)?;
        let (near, far) = clip_range(node)?;
        // Mitsuba accepts (and ignores) a focus distance on pinholes.
        node.float("focus_distance", 0.0)?;
        Ok(Perspective {
            to_world: node.transform("to_world")?,
            tan_x: (fov.to_radians() * 0.5).tan(),
            aspect,
            near,
            far,
            offset: Vec2::new(
                node.float("principal_point_offset_x", 0.0)?,
                node.float("principal_point_offset_y", 0.0)?,
            ),
        })
    }

    #[inline]
    pub fn sample_ray(&self, pos: Vec2) -> Ray {
        let d = pinhole_direction(pos, self.tan_x, self.aspect, self.offset).normalize();
        Ray {
            o: self.to_world.point(glam::Vec3::ZERO),
            d: self.to_world.vector(d).normalize(),
            tmin: self.near / d.z,
            tmax: self.far / d.z,
        }
    }
}
