//! Affine and projective transforms (4×4 matrices with their inverses).

use crate::ad::ScalarReal;
use crate::math::V3;
use glam::{Mat3, Mat4, Vec3};

/// A 4×4 transform and its inverse, applied to points, vectors and normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    pub m: Mat4,
    pub inv: Mat4,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    pub const IDENTITY: Transform = Transform {
        m: Mat4::IDENTITY,
        inv: Mat4::IDENTITY,
    };

    /// A transform from its matrix; `None` if the matrix is singular.
    pub fn new(m: Mat4) -> Option<Transform> {
        let det = m.determinant();
        if !det.is_finite() || det.abs() < 1e-20 {
            return None;
        }
        Some(Transform {
            m,
            inv: m.inverse(),
        })
    }

    pub fn translate(t: Vec3) -> Transform {
        Transform {
            m: Mat4::from_translation(t),
            inv: Mat4::from_translation(-t),
        }
    }

    /// Scaling by `s` along the axes.
    pub fn scale(s: Vec3) -> Transform {
        Transform {
            m: Mat4::from_scale(s),
            inv: Mat4::from_scale(s.recip()),
        }
    }

    /// Rotation by `angle_deg` degrees about `axis` (right-handed).
    pub fn rotate(axis: Vec3, angle_deg: f32) -> Transform {
        let m = Mat4::from_axis_angle(axis.normalize(), angle_deg.to_radians());
        Transform {
            m,
            inv: m.transpose(),
        }
    }

    /// Mitsuba's look-at: maps local +z to `target - origin`, local +y
    /// towards `up`, and local +x to `up × dir` ("left" in the image).
    pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Option<Transform> {
        let dir = (target - origin).normalize();
        let left = up.normalize().cross(dir);
        if !(left.length_squared() > 1e-12) || !dir.is_finite() {
            return None;
        }
        let left = left.normalize();
        let new_up = dir.cross(left);
        let m = Mat4::from_cols(
            left.extend(0.0),
            new_up.extend(0.0),
            dir.extend(0.0),
            origin.extend(1.0),
        );
        Transform::new(m)
    }

    /// `self` applied after `first`: `(self ∘ first)(x) = self(first(x))`.
    pub fn after(&self, first: &Transform) -> Transform {
        Transform {
            m: self.m * first.m,
            inv: first.inv * self.inv,
        }
    }

    pub fn inverse(&self) -> Transform {
        Transform {
            m: self.inv,
            inv: self.m,
        }
    }

    #[inline(always)]
    pub fn point(&self, p: Vec3) -> Vec3 {
        let r = self.m * p.extend(1.0);
        if r.w == 1.0 {
            r.truncate()
        } else {
            r.truncate() / r.w
        }
    }
    #[inline(always)]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.m.transform_vector3(v)
    }
    /// Transforms a normal by the inverse transpose (not normalised).
    #[inline(always)]
    pub fn normal(&self, n: Vec3) -> Vec3 {
        Mat3::from_mat4(self.inv).transpose() * n
    }

    /// [`Transform::point`] for differentiable points (the matrix itself is
    /// a constant here).
    #[inline(always)]
    pub fn point_r<R: ScalarReal>(&self, p: V3<R>) -> V3<R> {
        let c = |i: usize| self.m.col(i);
        let (c0, c1, c2, c3) = (c(0), c(1), c(2), c(3));
        let row = |k: usize| -> R { p.x * c0[k] + p.y * c1[k] + p.z * c2[k] + c3[k] };
        let w = row(3);
        let r = V3::new(row(0), row(1), row(2));
        if w.val() == 1.0 {
            r
        } else {
            r / w
        }
    }
    #[inline(always)]
    pub fn vector_r<R: ScalarReal>(&self, v: V3<R>) -> V3<R> {
        let (c0, c1, c2) = (self.m.col(0), self.m.col(1), self.m.col(2));
        let row = |k: usize| -> R { v.x * c0[k] + v.y * c1[k] + v.z * c2[k] };
        V3::new(row(0), row(1), row(2))
    }
    #[inline(always)]
    pub fn normal_r<R: ScalarReal>(&self, n: V3<R>) -> V3<R> {
        // (inv^T n)_k = column k of inv, dotted with n
        let c = |k: usize| -> R {
            let ck = self.inv.col(k);
            n.x * ck.x + n.y * ck.y + n.z * ck.z
        };
        V3::new(c(0), c(1), c(2))
    }

    /// True if the upper 3×3 part flips orientation (negative determinant).
    pub fn flips_handedness(&self) -> bool {
        Mat3::from_mat4(self.m).determinant() < 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_maps_z_to_view_direction() {
        let t = Transform::look_at(Vec3::new(0.0, 0.0, 3.9), Vec3::ZERO, Vec3::Y).unwrap();
        assert!((t.vector(Vec3::Z) - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        assert!((t.point(Vec3::ZERO) - Vec3::new(0.0, 0.0, 3.9)).length() < 1e-6);
        // local +x is "left" = up × dir = y × (-z) = -x
        assert!((t.vector(Vec3::X) - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-6);
    }

    #[test]
    fn generic_versions_agree_with_glam() {
        let t = Transform::rotate(Vec3::new(1.0, 2.0, 0.5), 33.0)
            .after(&Transform::translate(Vec3::new(0.2, -1.0, 3.0)));
        let s = Transform::new(Mat4::from_scale(Vec3::new(2.0, 0.5, 1.5))).unwrap();
        let t = s.after(&t);
        let p = Vec3::new(0.3, -0.7, 1.1);
        assert!((t.point_r(V3::<f32>::from(p)).val() - t.point(p)).length() < 1e-5);
        assert!((t.vector_r(V3::<f32>::from(p)).val() - t.vector(p)).length() < 1e-5);
        assert!((t.normal_r(V3::<f32>::from(p)).val() - t.normal(p)).length() < 1e-5);
        // normals stay perpendicular to transformed tangents
        let (u, n) = (Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0));
        assert!(t.vector(u).dot(t.normal(n)).abs() < 1e-5);
    }
}
