//! Orthonormal frames (shading frames): local coordinates have the normal
//! along +z, as in pbrt and Mitsuba, so `cos θ = w.z`.

use crate::ad::{Float, Real, ScalarReal};
use crate::math::V3;

/// An orthonormal basis (s, t, n).
#[derive(Clone, Copy, Debug)]
pub struct Frame<R> {
    pub s: V3<R>,
    pub t: V3<R>,
    pub n: V3<R>,
}

impl<R: Real> Frame<R> {
    /// A frame around the unit normal `n`, with tangents by the branchless
    /// construction of Duff et al. 2017, "Building an Orthonormal Basis,
    /// Revisited" (JCGT 6(1)).
    #[inline(always)]
    pub fn from_normal(n: V3<R>) -> Self {
        let sign = R::Prim::select(n.z.val().ge(0.0), 1.0.into(), (-1.0).into());
        let a = -(n.z + sign).recip();
        let b = n.x * n.y * a;
        let s = V3::new(n.x * n.x * a * sign + 1.0, b * sign, -n.x * sign);
        let t = V3::new(b, n.y * n.y * a + sign, -n.y);
        Frame { s, t, n }
    }

    /// Whether no axis carries a derivative.
    #[inline(always)]
    pub fn is_const(&self) -> bool {
        self.s.is_const() && self.t.is_const() && self.n.is_const()
    }

    /// The primal frame.
    #[inline(always)]
    pub fn prim(&self) -> Frame<R::Prim> {
        Frame {
            s: self.s.prim(),
            t: self.t.prim(),
            n: self.n.prim(),
        }
    }

    #[inline(always)]
    pub fn to_local(&self, v: V3<R>) -> V3<R> {
        if R::DIFFERENTIABLE && v.is_const() && self.is_const() {
            // nothing carries a derivative (most vertices of a reverse-mode
            // path): the same values in f32, for a fraction of the cost
            return V3::from_prim(self.prim().to_local(v.prim()));
        }
        V3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    #[inline(always)]
    pub fn to_world(&self, v: V3<R>) -> V3<R> {
        if R::DIFFERENTIABLE && v.is_const() && self.is_const() {
            // as in `to_local`
            return V3::from_prim(self.prim().to_world(v.prim()));
        }
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

impl<R: ScalarReal> Frame<R> {
    /// A frame around unit normal `n` whose first tangent follows `dpdu`
    /// (Gram-Schmidt), so that anisotropic BSDFs align with the surface
    /// parametrisation. Falls back to [`Frame::from_normal`] when `dpdu` is
    /// degenerate or parallel to `n`.
    pub fn from_normal_tangent(n: V3<R>, dpdu: V3<R>) -> Self {
        let s = dpdu - n * n.dot(dpdu);
        let l2 = s.length_squared().val();
        if !(l2 > 1e-12) || !l2.is_finite() {
            return Self::from_normal(n);
        }
        let s = s.normalize();
        Frame {
            s,
            t: n.cross(s),
            n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal_for_all_normals() {
        for i in 0..200 {
            let a = i as f32 * 0.731;
            let b = i as f32 * 0.317 - 30.0;
            let n = V3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos()).normalize();
            let f = Frame::<f32>::from_normal(n);
            for (u, v) in [(f.s, f.t), (f.s, f.n), (f.t, f.n)] {
                assert!(u.dot(v).abs() < 1e-5);
            }
            for u in [f.s, f.t, f.n] {
                assert!((u.length() - 1.0).abs() < 1e-5);
            }
            // right-handed: s × t = n
            assert!((f.s.cross(f.t) - f.n).length() < 1e-5);
            let w = V3::new(0.3f32, -0.5, 0.8).normalize();
            assert!((f.to_world(f.to_local(w)) - w).length() < 1e-5);
        }
    }
}
