//! The `sphere` shape plugin (analytic): `center` (point, default origin),
//! `radius` (float > 0, default 1), and/or `to_world` (a similarity: the
//! sphere is `to_world · translate(center) · scale(radius)` applied to the
//! unit sphere, as in Mitsuba 3), `flip_normals` (false).
//!
//! Parameters in the store: `<key>.center` (`[3]`, world space) and
//! `<key>.radius` (`[1]`, > 0), both geometry. The rotation part of
//! `to_world` is a constant that orients the uv parametrisation:
//! uv = (φ / 2π, θ / π) of the hit point in the sphere's local frame
//! (Mitsuba's convention), normal outward (inward with `flip_normals`).

use super::{analytic_interaction, azimuth};
use crate::ad::Real;
use crate::error::Result;
use crate::geometry::{DiffRay, Hit, PositionSample, ShapeT, SurfaceInteraction};
use crate::math::{warp, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore};
use crate::scene::{LoadContext, Node};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// An analytic sphere.
#[derive(Clone, Debug)]
pub struct Sphere {
    pub key: String,
    pub center: ParamId,
    pub radius: ParamId,
    /// Local-to-world rotation (orthonormal columns): orients uv.
    pub rot: Mat3,
    pub flip_normals: bool,
    area: f32,
}

impl Sphere {
    /// Builds the sphere of a `<shape type="sphere">` node.
    pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Sphere> {
        let center = node.vec3("center", Vec3::ZERO)?;
        let radius = node.float_checked("radius", 1.0, true)?;
        let to_world = node.transform("to_world")?;
        let flip_normals = node.bool("flip_normals", false)?;
        let m = to_world.m;
        let c = to_world.point(center);
        let cols = [
            m.transform_vector3(Vec3::X) * radius,
            m.transform_vector3(Vec3::Y) * radius,
            m.transform_vector3(Vec3::Z) * radius,
        ];
        let r = cols[0].length();
        let similar = cols.iter().all(|v| (v.length() - r).abs() <= 1e-4 * r)
            && cols[0].dot(cols[1]).abs() <= 1e-4 * r * r
            && cols[0].dot(cols[2]).abs() <= 1e-4 * r * r
            && cols[1].dot(cols[2]).abs() <= 1e-4 * r * r;
        if !similar || r.is_nan() || r <= 0.0 || !c.is_finite() {
            return Err(node.error(
                "to_world must be a similarity (rotation, uniform scale, translation) for a sphere; use a mesh for ellipsoids",
            ));
        }
        let mut rot = Mat3::from_cols(cols[0] / r, cols[1] / r, cols[2] / r);
        if rot.determinant() < 0.0 {
            rot = Mat3::from_cols(rot.x_axis, rot.y_axis, -rot.z_axis);
        }
        Self::new(&node.key, c, r, rot, flip_normals, &mut ctx.store).map_err(|e| node.error(e))
    }

    /// A sphere from world-space centre and radius (registers
    /// `<key>.center` and `<key>.radius`).
    pub fn new(
        key: &str,
        center: Vec3,
        radius: f32,
        rot: Mat3,
        flip_normals: bool,
        store: &mut ParamStore,
    ) -> Result<Sphere> {
        let cid = store.add(
            format!("{key}.center"),
            center.to_array().to_vec(),
            vec![3],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        let rid = store.add(
            format!("{key}.radius"),
            vec![radius],
            vec![1],
            ParamFlags::GEOMETRY,
            Domain::Positive,
        )?;
        Ok(Sphere {
            key: key.to_string(),
            center: cid,
            radius: rid,
            rot,
            flip_normals,
            area: 4.0 * PI * radius * radius,
        })
    }

    /// Current centre and radius (f32).
    pub fn center_radius(&self, store: &ParamStore) -> (Vec3, f32) {
        (
            Vec3::from_slice(store.data(self.center)),
            store.value(self.radius, 0),
        )
    }

    /// Refreshes the cached area.
    pub fn parameters_changed(&mut self, store: &ParamStore) {
        let r = store.value(self.radius, 0);
        self.area = 4.0 * PI * r * r;
    }

    /// Ray–sphere intersection in f32 on the open interval (tmin, tmax);
    /// the discriminant is formed as in Haines et al. 2019 ("Precision
    /// Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7).
    #[inline]
    pub fn intersect_f32(c: Vec3, r: f32, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> f32 {
        let oc = o - c;
        let b = oc.dot(d);
        let f = oc - d * b;
        let disc = r * r - f.dot(f);
        if disc < 0.0 {
            return f32::INFINITY;
        }
        let s = disc.sqrt();
        let q = if b > 0.0 { -b - s } else { -b + s };
        let cc = oc.dot(oc) - r * r;
        let (t0, t1) = if b > 0.0 { (q, cc / q) } else { (cc / q, q) };
        let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        if t0 > tmin && t0 < tmax {
            t0
        } else if t1 > tmin && t1 < tmax {
            t1
        } else {
            f32::INFINITY
        }
    }
}

impl ShapeT for Sphere {
    fn surface_interaction<R: Real>(
        &self,
        store: &ParamStore,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let c: V3<R> = store.read3(self.center, 0);
        let r: R = store.read(self.radius, 0);
        let (o, d) = (ray.o, ray.d);
        // both roots in R; keep the one the traversal found
        let oc = o - c;
        let b = oc.dot(d);
        let f = oc - d * b;
        let disc = r * r - f.dot(f);
        let t = if disc.val() >= 0.0 {
            let s = disc.safe_sqrt();
            let (ta, tb) = (-b - s, -b + s);
            if (ta.val() - hit.t).abs() <= (tb.val() - hit.t).abs() {
                ta
            } else {
                tb
            }
        } else {
            // grazing hit lost to rounding: closest point on the ray
            -b
        };
        let p = o + d * t;
        let mut si = self.local_geometry(hit, c, r, p, t);
        si.set_wi(-d);
        si
    }

    /// The point at the primal point's direction from the centre, in the
    /// sphere's local frame: it moves with the centre and scales with the
    /// radius.
    fn point_at<R: Real>(&self, store: &ParamStore, hit: &Hit, p: Vec3) -> SurfaceInteraction<R> {
        let c: V3<R> = store.read3(self.center, 0);
        let r: R = store.read(self.radius, 0);
        let dir = (p - c.val()).normalize();
        let p = c + V3::cst(dir) * r;
        self.local_geometry(hit, c, r, p, R::cst(hit.t))
    }

    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        let (c, r) = self.center_radius(store);
        let local = warp::square_to_uniform_sphere(u);
        let nw = self.rot * local;
        let theta = local.z.clamp(-1.0, 1.0).acos();
        let phi = azimuth(local.y, local.x);
        PositionSample {
            p: c + nw * r,
            n: if self.flip_normals { -nw } else { nw },
            uv: Vec2::new(phi / (2.0 * PI), theta / PI),
            local: Vec2::ZERO,
            pdf: 1.0 / self.area,
            prim: 0,
        }
    }

    fn surface_area(&self) -> f32 {
        self.area
    }
}

impl Sphere {
    /// Normal, uv and shading frame at point `p` of the sphere (centre `c`,
    /// radius `r`); the area scale is r² (area per unit solid angle seen
    /// from the centre).
    fn local_geometry<R: Real>(
        &self,
        hit: &Hit,
        c: V3<R>,
        r: R,
        p: V3<R>,
        t: R,
    ) -> SurfaceInteraction<R> {
        let mut n = (p - c) / r;
        // local frame (rotation is a constant)
        let (cx, cy, cz) = (self.rot.x_axis, self.rot.y_axis, self.rot.z_axis);
        let lx = n.dot(V3::cst(cx));
        let ly = n.dot(V3::cst(cy));
        let lz = n.dot(V3::cst(cz));
        let theta = lz.clamp(-1.0, 1.0).acos();
        let phi = azimuth(ly, lx);
        let uv = V2::new(phi * (0.5 / PI), theta * (1.0 / PI));
        // dp/du = 2π r (-ly, lx, 0) in the local frame
        let dpdu = (V3::cst(cy) * lx - V3::cst(cx) * ly) * (r * (2.0 * PI));
        if self.flip_normals {
            n = -n;
        }
        analytic_interaction(hit, t, p, n, dpdu, uv, r * r)
    }
}
