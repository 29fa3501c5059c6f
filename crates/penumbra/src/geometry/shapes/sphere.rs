//! The `sphere` shape plugin (analytic): `center` (point, default origin),
//! `radius` (float > 0, default 1), and/or `to_world` (a similarity: the
//! sphere is `to_world · translate(center) · scale(radius)` applied to the
//! unit sphere, as in Mitsuba 3), `flip_normals` (false).
//!
//! Parameters in the store, all geometry: `<key>.center` (`[3]`, world
//! space), `<key>.radius` (`[1]`, > 0) and `<key>.to_world` (`[4, 4]`,
//! row-major: translate(center) · rotation · scale(radius), Mitsuba's
//! parameter of the sphere). Setting one updates the others; a `to_world`
//! that is not a similarity is an error. The rotation orients the uv
//! parametrisation: uv = (φ / 2π, θ / π) of the hit point in the sphere's
//! local frame (Mitsuba's convention), normal outward (inward with
//! `flip_normals`).

use super::{analytic_interaction, azimuth};
use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::geometry::{DiffRay, Hit, PositionSample, ShapeT, SurfaceInteraction};
use crate::math::{warp, Frame, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// An analytic sphere.
#[derive(Clone, Debug)]
pub struct Sphere {
    pub key: String,
    pub center: ParamId,
    pub radius: ParamId,
    pub to_world: ParamId,
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
        let placed =
            to_world.m * Mat4::from_translation(center) * Mat4::from_scale(Vec3::splat(radius));
        let (c, r, rot) = similarity(&placed).ok_or_else(|| node.error(NOT_SIMILAR))?;
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
        let tid = store.add(
            format!("{key}.to_world"),
            placement(center, radius, rot),
            vec![4, 4],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        Ok(Sphere {
            key: key.to_string(),
            center: cid,
            radius: rid,
            to_world: tid,
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

    /// Keeps `center`, `radius` and `to_world` in agreement after an update
    /// (a new `to_world` wins over the other two), and refreshes the area.
    pub fn parameters_changed(
        &mut self,
        store: &mut ParamStore,
        changed: &[ParamId],
    ) -> Result<()> {
        if changed.contains(&self.to_world) {
            let rows = store.data(self.to_world);
            let m = Mat4::from_cols_slice(rows).transpose();
            let (c, r, rot) = similarity(&m).ok_or_else(|| Error::Param {
                key: store.get(self.to_world).key.clone(),
                msg: NOT_SIMILAR.into(),
            })?;
            self.rot = rot;
            let (ck, rk) = (
                store.get(self.center).key.clone(),
                store.get(self.radius).key.clone(),
            );
            store.set(&ck, &c.to_array())?;
            store.set(&rk, &[r])?;
        } else if changed.contains(&self.center) || changed.contains(&self.radius) {
            let (c, r) = self.center_radius(store);
            let key = store.get(self.to_world).key.clone();
            store.set(&key, &placement(c, r, self.rot))?;
        }
        let r = store.value(self.radius, 0);
        self.area = 4.0 * PI * r * r;
        Ok(())
    }

    /// Centre, radius and the images of the local axes (unit), in `R`:
    /// from `to_world` when its reads carry derivatives, else from
    /// `center` and `radius` with the rotation a constant.
    pub(crate) fn frame_r<R: ScalarReal>(&self, store: &ParamView) -> (V3<R>, R, [V3<R>; 3]) {
        if R::tracks(store, self.to_world) {
            let m = |r: usize, c: usize| -> R { store.read(self.to_world, 4 * r + c) };
            let col = |c: usize| V3::new(m(0, c), m(1, c), m(2, c));
            let r = col(0).length();
            let axes = [col(0) / r, col(1) / r, col(2) / r];
            return (col(3), r, axes);
        }
        let axes = [self.rot.x_axis, self.rot.y_axis, self.rot.z_axis].map(V3::cst);
        (
            store.read3(self.center, 0),
            store.read(self.radius, 0),
            axes,
        )
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

const NOT_SIMILAR: &str = "to_world must be a similarity (rotation, uniform scale, translation) for a sphere; use a mesh for ellipsoids";

/// Centre, radius and rotation (right-handed) of the unit sphere placed by
/// `m`, if `m` is a similarity.
fn similarity(m: &Mat4) -> Option<(Vec3, f32, Mat3)> {
    let c = m.transform_point3(Vec3::ZERO);
    let cols = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| m.transform_vector3(a));
    let r = cols[0].length();
    let similar = cols.iter().all(|v| (v.length() - r).abs() <= 1e-4 * r)
        && cols[0].dot(cols[1]).abs() <= 1e-4 * r * r
        && cols[0].dot(cols[2]).abs() <= 1e-4 * r * r
        && cols[1].dot(cols[2]).abs() <= 1e-4 * r * r;
    if !similar || r.is_nan() || r <= 0.0 || !c.is_finite() {
        return None;
    }
    let mut rot = Mat3::from_cols(cols[0] / r, cols[1] / r, cols[2] / r);
    if rot.determinant() < 0.0 {
        rot = Mat3::from_cols(rot.x_axis, rot.y_axis, -rot.z_axis);
    }
    Some((c, r, rot))
}

/// The row-major `to_world` of centre `c`, radius `r`, rotation `rot`.
fn placement(c: Vec3, r: f32, rot: Mat3) -> Vec<f32> {
    let m = Mat4::from_translation(c) * Mat4::from_mat3(rot) * Mat4::from_scale(Vec3::splat(r));
    m.transpose().to_cols_array().to_vec()
}

impl ShapeT for Sphere {
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let (c, r, axes) = self.frame_r::<R>(store);
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
        let mut si = self.local_geometry(hit, c, r, axes, p, t);
        si.set_wi(-d);
        si
    }

    /// The point at the primal point's direction from the centre, in the
    /// sphere's local frame: it moves with the centre and scales with the
    /// radius.
    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        let (c, r, axes) = self.frame_r::<R>(store);
        let local = self.rot.transpose() * (p - c.val()).normalize();
        let dir = axes[0] * R::cst(local.x) + axes[1] * R::cst(local.y) + axes[2] * R::cst(local.z);
        let p = c + dir * r;
        self.local_geometry(hit, c, r, axes, p, R::cst(hit.t))
    }

    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        let (c, r) = self.center_radius(store);
        let mut ps = self.position_at(c, r, self.rot * warp::square_to_uniform_sphere(u));
        ps.pdf = 1.0 / self.area;
        ps
    }

    /// Seen from outside: uniform over the cone of directions the sphere
    /// subtends at `ref_p`, as Mitsuba's sphere samples (Shirley and Wang
    /// 1996, "Monte Carlo techniques for direct lighting calculations";
    /// the point on the sphere is found from the angle at the centre, as
    /// in Pharr et al., "Physically Based Rendering", 4th ed., §6.2.4,
    /// which stays accurate for small and distant spheres). The density
    /// per unit solid angle is `1 / (2π (1 − cos θ_max))`. From inside:
    /// uniform by area.
    fn sample_position_from(&self, store: &ParamStore, ref_p: Vec3, u: Vec2) -> PositionSample {
        let (c, r) = self.center_radius(store);
        let Some(cone) = Cone::new(c, r, ref_p) else {
            return self.sample_position(store, u);
        };
        // the angle θ from the cone's axis; 1 − cos θ is formed directly
        let one_minus_cos = u.y * cone.one_minus_cos_max;
        let cos_theta = 1.0 - one_minus_cos;
        let sin2_theta = one_minus_cos * (2.0 - one_minus_cos);
        // the angle α at the centre between the axis (towards ref_p) and
        // the point where that direction first meets the sphere
        let cos_alpha = sin2_theta / cone.sin_max
            + cos_theta
                * (1.0 - sin2_theta / (cone.sin_max * cone.sin_max))
                    .max(0.0)
                    .sqrt();
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
        let phi = 2.0 * PI * u.x;
        let frame = Frame::<f32>::from_normal(V3::cst(cone.axis));
        let local = Vec3::new(sin_alpha * phi.cos(), sin_alpha * phi.sin(), cos_alpha);
        // α is measured from the axis towards ref_p: the visible cap
        let nw = frame.to_world(V3::cst(local)).val();
        let mut ps = self.position_at(c, r, nw);
        ps.pdf = self.pdf_position_from(store, ref_p, ps.p, ps.n);
        ps
    }

    fn pdf_position_from(&self, store: &ParamStore, ref_p: Vec3, p: Vec3, n: Vec3) -> f32 {
        let (c, r) = self.center_radius(store);
        let Some(cone) = Cone::new(c, r, ref_p) else {
            return 1.0 / self.area;
        };
        // solid angle to area at p
        let to = ref_p - p;
        let dist2 = to.length_squared();
        let cos = n.dot(to).abs() / dist2.sqrt();
        cos / (dist2 * 2.0 * PI * cone.one_minus_cos_max)
    }

    fn surface_area(&self) -> f32 {
        self.area
    }
}

/// The cone of directions a sphere subtends at a point outside it.
struct Cone {
    /// Unit vector from the sphere's centre towards the point.
    axis: Vec3,
    /// sin θ_max = r / distance.
    sin_max: f32,
    /// 1 − cos θ_max, accurate for narrow cones.
    one_minus_cos_max: f32,
}

impl Cone {
    /// The cone of the sphere (`c`, `r`) seen from `ref_p`; `None` from
    /// inside or on the sphere.
    fn new(c: Vec3, r: f32, ref_p: Vec3) -> Option<Cone> {
        let to = ref_p - c;
        let dist2 = to.length_squared();
        if !(dist2 > r * r) {
            return None;
        }
        let sin2_max = r * r / dist2;
        let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
        Some(Cone {
            axis: to / dist2.sqrt(),
            sin_max: sin2_max.sqrt(),
            one_minus_cos_max: sin2_max / (1.0 + cos_max),
        })
    }
}

impl Sphere {
    /// The position sample at unit direction `nw` from the centre `c` of
    /// the sphere of radius `r` (density left zero for the caller).
    fn position_at(&self, c: Vec3, r: f32, nw: Vec3) -> PositionSample {
        let local = self.rot.transpose() * nw;
        let theta = local.z.clamp(-1.0, 1.0).acos();
        let phi = azimuth(local.y, local.x);
        PositionSample {
            p: c + nw * r,
            n: if self.flip_normals { -nw } else { nw },
            uv: Vec2::new(phi / (2.0 * PI), theta / PI),
            local: Vec2::ZERO,
            pdf: 0.0,
            prim: 0,
        }
    }

    /// Normal, uv and shading frame at point `p` of the sphere (centre `c`,
    /// radius `r`); the area scale is r² (area per unit solid angle seen
    /// from the centre).
    fn local_geometry<R: ScalarReal>(
        &self,
        hit: &Hit,
        c: V3<R>,
        r: R,
        axes: [V3<R>; 3],
        p: V3<R>,
        t: R,
    ) -> SurfaceInteraction<R> {
        let mut n = (p - c) / r;
        let [cx, cy, cz] = axes;
        let lx = n.dot(cx);
        let ly = n.dot(cy);
        let lz = n.dot(cz);
        let theta = lz.clamp(-1.0, 1.0).acos();
        let phi = azimuth(ly, lx);
        let uv = V2::new(phi * (0.5 / PI), theta * (1.0 / PI));
        // In the local frame (Mitsuba's sphere.cpp): ∂p/∂u = 2π r (−ly, lx,
        // 0) and ∂p/∂v = π r (lz cos φ, lz sin φ, −sin θ), the latter the
        // local x axis at the poles, where φ is undefined.
        let dp_du = (cy * lx - cx * ly) * (r * (2.0 * PI));
        let rd = (lx * lx + ly * ly).safe_sqrt();
        let dp_dv = if rd.val() > 0.0 {
            (cx * (lx * lz / rd) + cy * (ly * lz / rd) - cz * rd) * (r * PI)
        } else {
            cx * (r * PI)
        };
        if self.flip_normals {
            n = -n;
        }
        analytic_interaction(hit, t, p, n, [dp_du, dp_dv], uv, r * r)
    }
}
