//! Rays, hits and surface interactions.

use crate::ad::ScalarReal;
use crate::math::{Frame, RAY_EPSILON, V2, V3};
use glam::{Vec2, Vec3};

/// A ray with unit direction, valid on `(tmin, tmax)`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

impl Ray {
    pub fn new(o: Vec3, d: Vec3) -> Ray {
        Ray {
            o,
            d,
            tmin: 0.0,
            tmax: f32::INFINITY,
        }
    }
    #[inline(always)]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// A ray whose origin and direction are differentiable: the camera ray
/// (a function of the sensor's parameters) and rays leaving a delta
/// bounce (functions of the hit point and its normal). The acceleration
/// structure traces its primal value ([`DiffRay::val`]); the hit is then
/// re-evaluated in `R` along it, so the point slides along the ray as the
/// surface or the ray moves.
#[derive(Clone, Copy, Debug)]
pub struct DiffRay<R> {
    pub o: V3<R>,
    /// Unit direction.
    pub d: V3<R>,
    pub tmin: f32,
    pub tmax: f32,
}

impl<R: ScalarReal> DiffRay<R> {
    /// A ray with constant origin and direction.
    #[inline(always)]
    pub fn cst(ray: &Ray) -> Self {
        DiffRay {
            o: V3::cst(ray.o),
            d: V3::cst(ray.d),
            tmin: ray.tmin,
            tmax: ray.tmax,
        }
    }
    /// Whether neither origin nor direction carries a derivative.
    #[inline(always)]
    pub fn is_const(&self) -> bool {
        self.o.is_const() && self.d.is_const()
    }
    /// The primal ray.
    #[inline(always)]
    pub fn val(&self) -> Ray {
        Ray {
            o: self.o.val(),
            d: self.d.val(),
            tmin: self.tmin,
            tmax: self.tmax,
        }
    }
}

/// What the acceleration structure reports: which primitive was hit, where
/// along the ray, and the primitive's own surface coordinates (barycentrics
/// `(b1, b2)` for triangles). Everything else is re-evaluated, in `R`, by
/// the shape (so that geometry derivatives flow).
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub shape: u32,
    pub prim: u32,
    pub uv: Vec2,
    /// The instance (index into the scene's instances) through which a
    /// shape of a shape group was hit; `shape` is then the group's shape
    /// and `t` the world distance (see `geometry::instance`).
    pub instance: Option<u32>,
}

/// A point on a surface with its local differential geometry.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction<R> {
    /// Distance along the ray.
    pub t: R,
    pub p: V3<R>,
    /// Geometric normal (unit), oriented as the shape defines it (not
    /// flipped towards the ray).
    pub n: V3<R>,
    /// Shading frame (shading normal in `sh_frame.n`).
    pub sh_frame: Frame<R>,
    pub uv: V2<R>,
    /// Surface tangents ∂p/∂u and ∂p/∂v with respect to `uv`, as the
    /// shape parametrises its surface (not unit, not orthogonal). Where the
    /// shape has no uv parametrisation (a mesh without texture
    /// coordinates, or a degenerate uv triangle) they are the tangents of
    /// the geometric normal's coordinate system, as in Mitsuba.
    pub dp_du: V3<R>,
    pub dp_dv: V3<R>,
    /// Direction towards the previous path vertex (the ray origin), in
    /// the shading frame.
    pub wi: V3<R>,
    /// Surface area per unit area of the shape's own surface coordinates
    /// (twice the triangle area for barycentrics): its ratio to its primal
    /// value is the Jacobian of a point that moves with the surface.
    pub area_scale: R,
    pub shape: u32,
    pub prim: u32,
    /// On a triangle: its vertex indices and the barycentrics `(b1, b2)`
    /// of the point (for mesh attributes); zero on other shapes.
    pub vertices: [u32; 3],
    pub bary: V2<R>,
}

impl<R: ScalarReal> SurfaceInteraction<R> {
    /// An interaction whose every quantity is a constant (the f32
    /// re-evaluation of a surface that does not move).
    #[inline(always)]
    pub fn cst(si: &SurfaceInteraction<f32>) -> Self {
        let v3 = |v: V3<f32>| V3::cst(v.val());
        let v2 = |v: V2<f32>| V2::new(R::cst(v.x), R::cst(v.y));
        SurfaceInteraction {
            t: R::cst(si.t),
            p: v3(si.p),
            n: v3(si.n),
            sh_frame: Frame {
                s: v3(si.sh_frame.s),
                t: v3(si.sh_frame.t),
                n: v3(si.sh_frame.n),
            },
            uv: v2(si.uv),
            dp_du: v3(si.dp_du),
            dp_dv: v3(si.dp_dv),
            wi: v3(si.wi),
            area_scale: R::cst(si.area_scale),
            shape: si.shape,
            prim: si.prim,
            vertices: si.vertices,
            bary: v2(si.bary),
        }
    }

    /// Sets `wi` to the world direction `d` (unit, pointing away from the
    /// surface towards the previous vertex).
    #[inline(always)]
    pub fn set_wi(&mut self, d: V3<R>) {
        self.wi = self.to_local(d);
    }

    #[inline(always)]
    pub fn to_world(&self, v: V3<R>) -> V3<R> {
        self.sh_frame.to_world(v)
    }
    #[inline(always)]
    pub fn to_local(&self, v: V3<R>) -> V3<R> {
        self.sh_frame.to_local(v)
    }

    /// The point and geometric normal (primal), which rays leaving the
    /// surface start from.
    #[inline(always)]
    pub fn point(&self) -> SurfacePoint {
        SurfacePoint {
            p: self.p.val(),
            n: self.n.val(),
        }
    }

    /// A ray leaving the surface in world direction `d`.
    #[inline(always)]
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        self.point().spawn_ray(d)
    }

    /// A shadow ray from the surface to point `target` (stops just short).
    #[inline(always)]
    pub fn spawn_ray_to(&self, target: Vec3) -> Ray {
        self.point().spawn_ray_to(target)
    }
}

/// A point on a surface with its geometric normal (oriented as the shape
/// defines it), primal: all a ray passing through the surface needs (the
/// side it leaves on, its offset origin), without the shading frame,
/// texture coordinates and tangents of a [`SurfaceInteraction`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub p: Vec3,
    pub n: Vec3,
}

impl SurfacePoint {
    /// Origin offset for rays leaving the surface towards `d` (side chosen
    /// by the geometric normal), scaled with the position's magnitude.
    #[inline(always)]
    pub fn offset_origin(&self, d: Vec3) -> Vec3 {
        let (p, n) = (self.p, self.n);
        let mag = (1.0 + p.abs().max_element()) * RAY_EPSILON;
        if n.dot(d) >= 0.0 {
            p + n * mag
        } else {
            p - n * mag
        }
    }

    /// A ray leaving the surface in world direction `d`.
    #[inline(always)]
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        Ray::new(self.offset_origin(d), d)
    }

    /// A shadow ray from the surface to point `target` (stops just short).
    #[inline(always)]
    pub fn spawn_ray_to(&self, target: Vec3) -> Ray {
        let o = self.offset_origin(target - self.p);
        let d = target - o;
        let dist = d.length();
        Ray {
            o,
            d: d / dist,
            tmin: 0.0,
            tmax: dist * (1.0 - 1e-4),
        }
    }
}

/// A point sampled on a surface (for emitter sampling). Sampling is
/// detached: the point, normal and density are constants; the point is
/// re-evaluated in `R` from `prim` and `local` (see
/// [`crate::geometry::ShapeT::point_at`]).
#[derive(Clone, Copy, Debug)]
pub struct PositionSample {
    pub p: Vec3,
    /// Unit surface normal at `p` (oriented as the shape defines it).
    pub n: Vec3,
    pub uv: Vec2,
    /// The shape's own surface coordinates of `p` (as [`Hit::uv`]:
    /// barycentrics `(b1, b2)` for triangles), so the point can be
    /// re-evaluated in `R`, moving with the shape.
    pub local: Vec2,
    /// Density with respect to surface area.
    pub pdf: f32,
    pub prim: u32,
}
