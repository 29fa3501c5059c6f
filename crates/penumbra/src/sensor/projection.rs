//! The inverse of [`Sensor::ray`]: where a world point appears on the film,
//! in `R`, so that the boundary estimators can differentiate the motion of
//! an edge's image with respect to the scene and the sensor's parameters.
//! Pinhole and orthographic cameras (a thin lens spreads a point over a
//! disk of the film: it has no single image point).

use super::{Camera, Sensor, ToWorld};
use crate::ad::ScalarReal;
use crate::geometry::edges::Eye;
use crate::math::{V2, V3};
use crate::params::ParamView;

/// What the boundary estimators need to know about a camera.
pub(crate) struct Projector<R> {
    to_world: ToWorld<R>,
    kind: Kind<R>,
    /// Points nearer than this (camera-space z) are clipped.
    pub near: f32,
}

/// [`Projector::viewpoint`]: the eye point (pinhole) or the unit view
/// direction (orthographic), in `R`.
pub(crate) enum Viewpoint<R> {
    Point(V3<R>),
    Direction(V3<R>),
}

enum Kind<R> {
    /// `tan(x_fov / 2)`, the principal point offset, the aspect ratio.
    Pinhole {
        tan_x: R,
        offset: [R; 2],
        aspect: f32,
    },
    Orthographic {
        aspect: f32,
    },
}

impl Sensor {
    /// The projection of this sensor in `R`, or `None` for a thin lens.
    pub(crate) fn projector<R: ScalarReal>(&self, store: &ParamView) -> Option<Projector<R>> {
        let to_world = ToWorld::read(&self.pose, store);
        let (kind, near) = match &self.camera {
            Camera::Perspective(c) => {
                let f = &c.frustum;
                let (tan_x, offset) = f.read::<R>(store);
                let aspect = f.aspect;
                (
                    Kind::Pinhole {
                        tan_x,
                        offset,
                        aspect,
                    },
                    f.near,
                )
            }
            Camera::Orthographic(c) => (Kind::Orthographic { aspect: c.aspect }, c.near),
            Camera::ThinLens(_) => return None,
        };
        Some(Projector {
            to_world,
            kind,
            near,
        })
    }
}

impl<R: ScalarReal> Projector<R> {
    /// Camera-space coordinates of the world point `p`: `to_world⁻¹ p`
    /// for the affine `to_world` (its last row is taken as (0, 0, 0, 1), as
    /// for every camera pose Mitsuba accepts), the inverse of the linear
    /// part by cofactors so that it is differentiable in `R`.
    pub fn to_local(&self, p: V3<R>) -> V3<R> {
        let m = &self.to_world.0;
        let a = |r: usize, c: usize| m[4 * r + c];
        let q = V3::new(p.x - a(0, 3), p.y - a(1, 3), p.z - a(2, 3));
        // rows of the cofactor matrix = columns of the adjugate
        let c0 = V3::new(a(0, 0), a(1, 0), a(2, 0));
        let c1 = V3::new(a(0, 1), a(1, 1), a(2, 1));
        let c2 = V3::new(a(0, 2), a(1, 2), a(2, 2));
        let (r0, r1, r2) = (c1.cross(c2), c2.cross(c0), c0.cross(c1));
        let det = c0.dot(r0);
        V3::new(r0.dot(q) / det, r1.dot(q) / det, r2.dot(q) / det)
    }

    /// Film position in [0,1]² (over the full film, (0,0) = top-left) of
    /// the camera-space point `q` (in front of the camera): the position
    /// whose ray [`Sensor::ray`] passes through `q`.
    pub fn film(&self, q: V3<R>) -> V2<R> {
        match &self.kind {
            // ray direction ∝ ((1 − 2x − 2ox)·tan, (1 − 2y − 2oy)·tan / aspect, 1)
            Kind::Pinhole {
                tan_x,
                offset,
                aspect,
            } => {
                let zt = q.z * *tan_x;
                V2::new(
                    (R::cst(1.0) - q.x / zt) * 0.5 - offset[0],
                    (R::cst(1.0) - q.y * *aspect / zt) * 0.5 - offset[1],
                )
            }
            // ray origin = to_world (1 − 2x, (1 − 2y) / aspect, 0)
            Kind::Orthographic { aspect } => V2::new(
                (R::cst(1.0) - q.x) * 0.5,
                (R::cst(1.0) - q.y * *aspect) * 0.5,
            ),
        }
    }

    /// Where the rays come from, in `R` (moving with the pose): the eye
    /// point of a pinhole, the unit direction the rays travel for an
    /// orthographic camera. Silhouettes of analytic shapes depend on it.
    pub fn viewpoint(&self) -> Viewpoint<R> {
        let m = &self.to_world.0;
        match self.kind {
            Kind::Pinhole { .. } => Viewpoint::Point(self.to_world.point(V3::zero())),
            Kind::Orthographic { .. } => {
                Viewpoint::Direction(V3::new(m[2], m[6], m[10]).normalize())
            }
        }
    }

    /// Where the rays come from (primal), for silhouette tests.
    pub fn eye(&self) -> Eye {
        let m = &self.to_world.0;
        match self.kind {
            Kind::Pinhole { .. } => Eye::Point(self.to_world.point(V3::zero()).val()),
            Kind::Orthographic { .. } => {
                Eye::Direction(glam::Vec3::new(m[2].val(), m[6].val(), m[10].val()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::ad::Dual;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::Scene;
    use glam::Vec2;
    use std::path::Path;

    /// A `sensor` camera (perspective ones with a principal point offset).
    fn scene(sensor: &str) -> Scene {
        let offset = if sensor == "perspective" {
            r#"<float name="principal_point_offset_x" value="0.1"/>
               <float name="principal_point_offset_y" value="-0.05"/>"#
        } else {
            ""
        };
        let xml = format!(
            r#"<scene version="3.0.0">
                <sensor type="{sensor}" id="cam">
                    {offset}
                    <transform name="to_world">
                        <lookat origin="1, 2, -3" target="0.2, 0, 0.5" up="0, 1, 0"/>
                        <scale value="1.5"/>
                    </transform>
                    <film type="hdrfilm">
                        <integer name="width" value="40"/>
                        <integer name="height" value="30"/>
                    </film>
                </sensor>
                <shape type="sphere"/>
            </scene>"#
        );
        Scene::load_str(&xml, Path::new("inline.xml"), &[]).unwrap()
    }

    /// A point on the ray of a film position projects back onto it.
    #[test]
    fn projection_inverts_the_camera_ray() {
        for kind in ["perspective", "orthographic"] {
            let s = scene(kind);
            let sensor = &s.sensors[0];
            let proj = sensor.projector::<f32>(&s.params.primal()).unwrap();
            for film in [
                Vec2::new(0.5, 0.5),
                Vec2::new(0.1, 0.8),
                Vec2::new(0.93, 0.2),
            ] {
                let ray = sensor
                    .ray::<f32>(&s.params.primal(), film, Vec2::ZERO)
                    .val();
                let p = ray.at(ray.tmin + 4.0);
                let q = proj.to_local(V3::cst(p));
                assert!(q.z > proj.near, "{kind}: {q:?}");
                let back = proj.film(q).val();
                assert!((back - film).length() < 1e-5, "{kind}: {film} → {back}");
            }
        }
    }

    /// The derivative of the film position of a fixed world point with
    /// respect to the camera's translation and field of view matches
    /// finite differences.
    #[test]
    fn projection_derivatives_match_finite_differences() {
        for (kind, key, index) in [
            ("perspective", "cam.to_world", 3),
            ("perspective", "cam.to_world", 5),
            ("perspective", "cam.x_fov", 0),
            ("perspective", "cam.principal_point_offset_x", 0),
            ("perspective", "cam.principal_point_offset_y", 0),
            ("orthographic", "cam.to_world", 11),
            ("orthographic", "cam.to_world", 0),
        ] {
            let mut s = scene(kind);
            let id = s.params.require(key).unwrap();
            let base = s.params.data(id).to_vec();
            let mut t = vec![0.0; base.len()];
            t[index] = 1.0;
            let p = V3::cst(glam::Vec3::new(0.3, 0.1, 0.4));
            let d = {
                let seeds = Seeds::tangents(&s.params, &[(key, &t)]).unwrap();
                let proj = s.sensors[0]
                    .projector::<Dual>(&s.params.view(&seeds))
                    .unwrap();
                let f = proj.film(proj.to_local(p));
                Vec2::new(f.x.d, f.y.d)
            };
            let h = 1e-3;
            let mut at = |e: f32| {
                let v: Vec<f32> = base.iter().zip(&t).map(|(b, t)| b + e * t).collect();
                s.params.set(key, &v).unwrap();
                let proj = s.sensors[0].projector::<f32>(&s.params.primal()).unwrap();
                let p = V3::cst(p.val());
                proj.film(proj.to_local(p)).val()
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            assert!(
                (d - fd).length() < 2e-3 * fd.length().max(0.1),
                "{kind} {key}[{index}]: {d} vs {fd}"
            );
            assert!(fd.length() > 1e-4, "{kind} {key}[{index}]: no motion");
        }
    }
}
