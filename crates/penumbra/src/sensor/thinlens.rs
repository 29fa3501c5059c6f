//! The thin-lens camera with depth of field (Mitsuba's `thinlens`).

use super::{clip_range, fov_x, pinhole_direction};
use crate::error::Result;
use crate::geometry::Ray;
use crate::math::{warp, Transform};
use crate::scene::Node;
use glam::{Vec2, Vec3};

/// A thin lens of radius `aperture_radius` focused at `focus_distance`.
#[derive(Clone, Debug)]
pub struct ThinLens {
    pub to_world: Transform,
    pub tan_x: f32,
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
    pub aperture_radius: f32,
    pub focus_distance: f32,
}

impl ThinLens {
    pub fn from_node(node: &Node, aspect: f32) -> Result<ThinLens> {
        let fov = fov_x(node, aspect)?;
        let (near, far) = clip_range(node)?;
        let focus_distance = node.float_checked("focus_distance", 0.0, false)?;
        if !(focus_distance > 0.0) {
            return Err(node.error("thinlens needs a focus_distance > 0"));
        }
        Ok(ThinLens {
            to_world: node.transform("to_world")?,
            tan_x: (fov.to_radians() * 0.5).tan(),
            aspect,
            near,
            far,
            aperture_radius: node.float_checked("aperture_radius", 0.03, false)?,
            focus_distance,
        })
    }

    /// Rays from a point on the lens through the point of the focal plane
    /// that the pinhole ray through `pos` reaches.
    #[inline]
    pub fn sample_ray(&self, pos: Vec2, lens: Vec2) -> Ray {
        let d = pinhole_direction(pos, self.tan_x, self.aspect, Vec2::ZERO);
        let focus = d * self.focus_distance; // d.z == 1
        let l = warp::square_to_uniform_disk_concentric(lens) * self.aperture_radius;
        let o = Vec3::new(l.x, l.y, 0.0);
        let dir = (focus - o).normalize();
        Ray {
            o: self.to_world.point(o),
            d: self.to_world.vector(dir).normalize(),
            tmin: self.near / dir.z,
            tmax: self.far / dir.z,
        }
    }
}
