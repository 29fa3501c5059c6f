//! The thin-lens camera with depth of field (Mitsuba's `thinlens`).
//!
//! Parameters: `<key>.to_world`, `<key>.x_fov`, `<key>.aperture_radius`
//! and `<key>.focus_distance`. As in Mitsuba, `aperture_radius` is
//! required, `focus_distance` defaults to `far_clip`, and there is no
//! principal point offset.

use super::{add_scalar, Frustum, ToWorld};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::DiffRay;
use crate::math::{warp, V3};
use crate::params::{Domain, ParamId, ParamStore, ParamView};
use crate::scene::description::Node;
use glam::Vec2;

/// A thin lens of radius `aperture_radius` focused at `focus_distance`.
#[derive(Clone, Debug)]
pub struct ThinLens {
    pub frustum: Frustum,
    pub aperture_radius: ParamId,
    pub focus_distance: ParamId,
}

impl ThinLens {
    pub fn from_node(node: &Node, aspect: f32, store: &mut ParamStore) -> Result<ThinLens> {
        let frustum = Frustum::from_node(node, aspect, false, store)?;
        let focus_distance = node.float_checked("focus_distance", frustum.far, true)?;
        let aperture_radius = node.float_req("aperture_radius")?;
        if aperture_radius < 0.0 {
            let p = node.prop("aperture_radius").expect("a required parameter");
            return Err(node.prop_error(p, format!("must be >= 0, found {aperture_radius}")));
        }
        Ok(ThinLens {
            frustum,
            aperture_radius: add_scalar(
                node,
                "aperture_radius",
                aperture_radius,
                Domain::NonNegative,
                store,
            )?,
            focus_distance: add_scalar(
                node,
                "focus_distance",
                focus_distance,
                Domain::Positive,
                store,
            )?,
        })
    }

    /// Rays from a point on the lens through the point of the focal plane
    /// that the pinhole ray through `pos` reaches.
    #[inline]
    pub(crate) fn ray<R: ScalarReal>(
        &self,
        store: &ParamView,
        to_world: &ToWorld<R>,
        lens_params: (R, [R; 2]),
        pos: Vec2,
        lens: Vec2,
    ) -> DiffRay<R> {
        // d.z == 1
        let focus = self.frustum.direction::<R>(lens_params, [pos.x, pos.y])
            * store.read::<R>(self.focus_distance, 0);
        let l = Vec2::from(warp::square_to_uniform_disk_concentric(lens.into()));
        let r = store.read::<R>(self.aperture_radius, 0);
        let o = V3::new(r * l.x, r * l.y, R::cst(0.0));
        let dir = (focus - o).normalize();
        let dz = dir.z.val();
        DiffRay {
            o: to_world.point(o),
            d: to_world.vector(dir).normalize(),
            tmin: self.frustum.near / dz,
            tmax: self.frustum.far / dz,
        }
    }
}
