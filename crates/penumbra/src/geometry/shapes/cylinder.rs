//! The `cylinder` shape plugin (analytic): the open cylinder (no caps)
//! around the segment from `p0` (default origin) to `p1` (default +z),
//! `radius` (> 0, default 1), placed by `to_world` (rotation, uniform
//! scale, translation, as Mitsuba 3 permits), `flip_normals` (false).
//!
//! As in Mitsuba 3, the cylinder is the unit cylinder (radius 1 around the
//! z axis, 0 ≤ z ≤ 1) placed by `to_world · translate(p0) · to_frame(p1 −
//! p0) · scale(radius, radius, |p1 − p0|)`, where `to_frame` is the
//! orthonormal basis around the axis of Duff et al. 2017 (Mitsuba's
//! `Frame3f`): that basis orients φ. uv = (φ / 2π, z) in the local
//! frame; the normal is ∂p/∂u × ∂p/∂v normalised (outward; inward with
//! `flip_normals`, or when `to_world` mirrors, as in Mitsuba).
//!
//! Parameter in the store: `<key>.to_world` (`[4, 4]`, row-major,
//! geometry): the whole placement above, p0, p1 and radius folded in (so
//! it moves, turns and scales the cylinder).

use super::{analytic_interaction, azimuth};
use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::geometry::{DiffRay, Hit, PositionSample, ShapeT, SurfaceInteraction};
use crate::math::{Frame, Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{DVec3, Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// An analytic open cylinder.
#[derive(Clone, Debug)]
pub struct Cylinder {
    pub key: String,
    /// `<key>.to_world`, 16 floats, row-major: the unit cylinder's placement.
    pub to_world: ParamId,
    pub flip_normals: bool,
    area: f32,
}

/// World-space frame of a cylinder: the centre of its `p0` end and the
/// images of the local axes (x and y of length `radius`, z from `p0` to
/// `p1`).
#[derive(Clone, Copy, Debug)]
pub struct CylinderFrame {
    pub c: Vec3,
    pub a0: Vec3,
    pub a1: Vec3,
    pub a2: Vec3,
}

const NOT_SIMILAR: &str = "to_world must be a rotation, uniform scale and translation for a \
                           cylinder (no shear, no non-uniform scale); use a mesh for others";

impl Cylinder {
    /// Builds the cylinder of a `<shape type="cylinder">` node.
    pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Cylinder> {
        let p0 = node.vec3("p0", Vec3::ZERO)?;
        let p1 = node.vec3("p1", Vec3::Z)?;
        let radius = node.float_checked("radius", 1.0, true)?;
        let to_world = node.transform("to_world")?;
        let flip_normals = node.bool("flip_normals", false)?;
        let axis = p1 - p0;
        let length = axis.length();
        if !(length > 0.0) || !length.is_finite() {
            return Err(node.error("parameter 'p1': p0 and p1 must be distinct finite points"));
        }
        let f = Frame::<f32>::from_normal(V3::cst(axis / length));
        let frame = Mat4::from_cols(
            f.s.val().extend(0.0),
            f.t.val().extend(0.0),
            f.n.val().extend(0.0),
            glam::Vec4::W,
        );
        let placed = to_world.m
            * Mat4::from_translation(p0)
            * frame
            * Mat4::from_scale(Vec3::new(radius, radius, length));
        let t = Transform::new(placed).ok_or_else(|| node.error(NOT_SIMILAR))?;
        Self::new(&node.key, &t, flip_normals, &mut ctx.store).map_err(|e| node.error(e))
    }

    /// A cylinder: the unit cylinder placed by `to_world` (registers
    /// `<key>.to_world`).
    pub fn new(
        key: &str,
        to_world: &Transform,
        flip_normals: bool,
        store: &mut ParamStore,
    ) -> Result<Cylinder> {
        let rows: Vec<f32> = to_world.m.transpose().to_cols_array().to_vec();
        let id = store.add(
            format!("{key}.to_world"),
            rows,
            vec![4, 4],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        let mut c = Cylinder {
            key: key.to_string(),
            to_world: id,
            flip_normals,
            area: 0.0,
        };
        c.parameters_changed(store)?;
        Ok(c)
    }

    /// Current world frame (f32).
    pub fn frame(&self, store: &ParamStore) -> CylinderFrame {
        let m = store.data(self.to_world);
        CylinderFrame {
            c: Vec3::new(m[3], m[7], m[11]),
            a0: Vec3::new(m[0], m[4], m[8]),
            a1: Vec3::new(m[1], m[5], m[9]),
            a2: Vec3::new(m[2], m[6], m[10]),
        }
    }

    /// Refreshes the cached area; errors if `to_world` is not a
    /// similarity (the intersection and the area assume a circular
    /// cross-section perpendicular to the axis) or is degenerate.
    pub fn parameters_changed(&mut self, store: &ParamStore) -> Result<()> {
        let f = self.frame(store);
        let (r, l) = (f.a0.length(), f.a2.length());
        let tol = 1e-4 * r.max(l);
        let similar = (f.a1.length() - r).abs() <= 1e-4 * r
            && f.a0.dot(f.a1).abs() <= tol * r
            && f.a0.dot(f.a2).abs() <= tol * r
            && f.a1.dot(f.a2).abs() <= tol * r;
        self.area = 2.0 * PI * r * l;
        if !similar || !f.c.is_finite() || !(self.area > 0.0) || !self.area.is_finite() {
            return Err(Error::Param {
                key: store.get(self.to_world).key.clone(),
                msg: NOT_SIMILAR.into(),
            });
        }
        Ok(())
    }

    /// Ray–cylinder intersection in f32 on the open interval (tmin, tmax):
    /// the ray in the unit cylinder's frame (an affine map keeps the ray
    /// parameter t), the quadratic solved in f64 in the cancellation-free
    /// form (as Mitsuba does on the CPU), the nearer root whose point lies
    /// between the two ends.
    #[inline]
    pub fn intersect_f32(f: &CylinderFrame, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> f32 {
        let (c, a0, a1, a2) = (
            f.c.as_dvec3(),
            f.a0.as_dvec3(),
            f.a1.as_dvec3(),
            f.a2.as_dvec3(),
        );
        let local = |v: DVec3| {
            DVec3::new(
                v.dot(a0) / a0.length_squared(),
                v.dot(a1) / a1.length_squared(),
                v.dot(a2) / a2.length_squared(),
            )
        };
        let (ol, dl) = (local(o.as_dvec3() - c), local(d.as_dvec3()));
        let Some((t0, t1)) = unit_cylinder_roots(ol, dl) else {
            return f32::INFINITY;
        };
        for t in [t0, t1] {
            let z = ol.z + dl.z * t;
            let tf = t as f32;
            if tf > tmin && tf < tmax && (0.0..=1.0).contains(&z) {
                return tf;
            }
        }
        f32::INFINITY
    }
}

/// The roots t0 ≤ t1 of |(o + t d)_xy|² = 1 (the infinite unit cylinder
/// around z), or `None` when the ray misses it or runs along its axis.
fn unit_cylinder_roots(o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let a = d.x * d.x + d.y * d.y;
    let b = 2.0 * (d.x * o.x + d.y * o.y);
    let c = o.x * o.x + o.y * o.y - 1.0;
    let disc = b * b - 4.0 * a * c;
    if !(a > 0.0) || disc < 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (t0, t1) = if q == 0.0 {
        // b = 0 and disc = 0 (c = 0): the ray grazes the cylinder
        (0.0, 0.0)
    } else {
        (q / a, c / q)
    };
    Some(if t0 <= t1 { (t0, t1) } else { (t1, t0) })
}

impl ShapeT for Cylinder {
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let [c, a0, a1, a2] = self.frame_r::<R>(store);
        let (o, d) = (ray.o, ray.d);
        let local = |v: V3<R>| {
            V3::new(
                v.dot(a0) / a0.dot(a0),
                v.dot(a1) / a1.dot(a1),
                v.dot(a2) / a2.dot(a2),
            )
        };
        let (ol, dl) = (local(o - c), local(d));
        // both roots in R; keep the one the traversal found
        let qa = dl.x * dl.x + dl.y * dl.y;
        let qb = (dl.x * ol.x + dl.y * ol.y) * 2.0;
        let qc = ol.x * ol.x + ol.y * ol.y - R::cst(1.0);
        let disc = qb * qb - qa * qc * 4.0;
        let t = if qa.val() > 0.0 && disc.val() >= 0.0 {
            let s = disc.safe_sqrt();
            let (ta, tb) = ((-qb - s) / (qa * 2.0), (-qb + s) / (qa * 2.0));
            if (ta.val() - hit.t).abs() <= (tb.val() - hit.t).abs() {
                ta
            } else {
                tb
            }
        } else if qa.val() > 0.0 {
            // grazing hit lost to rounding: the ray's closest approach
            -qb / (qa * 2.0)
        } else {
            R::cst(hit.t)
        };
        let p = o + d * t;
        let l = ol + dl * t;
        let mut si = self.local_geometry(hit, [a0, a1, a2], p, t, l.x, l.y, l.z);
        si.set_wi(-d);
        si
    }

    /// The point with the primal point's local angle and height, moving
    /// with `to_world`.
    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        let f = self.frame(store);
        let q = p - f.c;
        let xy = Vec2::new(
            q.dot(f.a0) / f.a0.length_squared(),
            q.dot(f.a1) / f.a1.length_squared(),
        );
        // back onto the unit circle (the primal point carries rounding)
        let xy = if xy.length() > 0.0 {
            xy / xy.length()
        } else {
            Vec2::X
        };
        let z = q.dot(f.a2) / f.a2.length_squared();
        let [c, a0, a1, a2] = self.frame_r::<R>(store);
        let (x, y, z) = (R::cst(xy.x), R::cst(xy.y), R::cst(z));
        let p = c + a0 * x + a1 * y + a2 * z;
        self.local_geometry(hit, [a0, a1, a2], p, R::cst(hit.t), x, y, z)
    }

    /// Uniform by area: height from `u.x`, angle from `u.y` (Mitsuba's
    /// assignment, so the same samples land on the same points).
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        let f = self.frame(store);
        let phi = 2.0 * PI * u.y;
        let (s, c) = phi.sin_cos();
        let dpdu = f.a1 * c - f.a0 * s;
        let mut n = dpdu.cross(f.a2).normalize();
        if self.flip_normals {
            n = -n;
        }
        let uv = Vec2::new(u.y, u.x);
        PositionSample {
            p: f.c + f.a0 * c + f.a1 * s + f.a2 * u.x,
            n,
            uv,
            local: uv,
            pdf: 1.0 / self.area,
            prim: 0,
        }
    }

    fn surface_area(&self) -> f32 {
        self.area
    }
}

impl Cylinder {
    /// The `p0` end's centre and the images of the local x, y, z axes, in
    /// `R`.
    pub(crate) fn frame_r<R: ScalarReal>(&self, store: &ParamView) -> [V3<R>; 4] {
        let id = self.to_world;
        let m = |r: usize, c: usize| -> R { store.read(id, 4 * r + c) };
        let col = |c: usize| V3::new(m(0, c), m(1, c), m(2, c));
        [col(3), col(0), col(1), col(2)]
    }

    /// Normal, uv and shading frame at local point (x, y, z) (x² + y² = 1),
    /// world point `p`; the area scale is |∂p/∂φ × ∂p/∂z|.
    #[allow(clippy::too_many_arguments)]
    fn local_geometry<R: ScalarReal>(
        &self,
        hit: &Hit,
        [a0, a1, a2]: [V3<R>; 3],
        p: V3<R>,
        t: R,
        x: R,
        y: R,
        z: R,
    ) -> SurfaceInteraction<R> {
        let phi = azimuth(y, x);
        let uv = V2::new(phi * (0.5 / PI), z);
        // ∂p/∂φ; ∂p/∂u is 2π times it
        let dpdphi = a1 * x - a0 * y;
        let cross = dpdphi.cross(a2);
        let area_scale = cross.length();
        let mut n = cross / area_scale;
        if self.flip_normals {
            n = -n;
        }
        // v is the local height, which spans the axis a2
        let dp_du = dpdphi * R::cst(2.0 * PI);
        analytic_interaction(hit, t, p, n, [dp_du, a2], uv, area_scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::geometry::{Accel, Ray, Shape};
    use crate::params::Seeds;

    /// A tilted cylinder: axis from `p0` along unit `axis`, radius `r`,
    /// length `l`, with the local x axis `x` (⟂ axis).
    struct Setup {
        shape: Shape,
        store: ParamStore,
        p0: Vec3,
        axis: Vec3,
        x: Vec3,
        r: f32,
        l: f32,
    }

    fn setup(flip_normals: bool) -> Setup {
        let mut store = ParamStore::default();
        let axis = Vec3::new(0.3, -0.4, 1.0).normalize();
        let x = axis.any_orthonormal_vector();
        let y = axis.cross(x);
        let (p0, r, l) = (Vec3::new(0.2, 0.5, -0.7), 0.6, 1.8);
        let m = Mat4::from_cols(
            (x * r).extend(0.0),
            (y * r).extend(0.0),
            (axis * l).extend(0.0),
            p0.extend(1.0),
        );
        let t = Transform::new(m).unwrap();
        let c = Cylinder::new("cyl", &t, flip_normals, &mut store).unwrap();
        Setup {
            shape: Shape::Cylinder(c),
            store,
            p0,
            axis,
            x,
            r,
            l,
        }
    }

    impl Setup {
        /// The first hit of `ray` on (tmin, ∞) from the analytic solution
        /// in f64: the roots of the distance to the axis equal to r,
        /// limited to the length.
        fn analytic_t(&self, o: Vec3, d: Vec3) -> Option<f64> {
            let (o, d) = ((o - self.p0).as_dvec3(), d.as_dvec3());
            let a = self.axis.as_dvec3();
            let (op, dp) = (o - a * o.dot(a), d - a * d.dot(a));
            let (qa, qb, qc) = (
                dp.dot(dp),
                2.0 * op.dot(dp),
                op.dot(op) - (self.r as f64).powi(2),
            );
            let disc = qb * qb - 4.0 * qa * qc;
            if disc < 0.0 || qa == 0.0 {
                return None;
            }
            let s = disc.sqrt();
            [(-qb - s) / (2.0 * qa), (-qb + s) / (2.0 * qa)]
                .into_iter()
                .find(|&t| {
                    let h = (o + d * t).dot(a);
                    t > 1e-4 && (0.0..=self.l as f64).contains(&h)
                })
        }

        fn hit(&self, ray: &Ray) -> Option<Hit> {
            let accel = Accel::build(std::slice::from_ref(&self.shape), &self.store);
            accel.intersect(ray)
        }
    }

    #[test]
    fn hits_match_the_analytic_solution() {
        let s = setup(false);
        let mut rng = crate::testing::Pcg32::new(3);
        let centre = s.p0 + s.axis * (0.5 * s.l);
        let (mut hits, mut inside) = (0, 0);
        for i in 0..2000 {
            // origins outside and inside, directions all over the sphere
            let o = if i % 2 == 0 {
                centre + (rng.next_2d().extend(rng.next_f32()) - 0.5) * 6.0
            } else {
                centre + (rng.next_2d().extend(rng.next_f32()) - 0.5) * 0.5
            };
            let d = crate::math::warp::square_to_uniform_sphere(rng.next_2d());
            let ray = Ray::new(o, d);
            let want = s.analytic_t(o, d);
            match (s.hit(&ray), want) {
                (Some(h), Some(t)) => {
                    assert!((h.t as f64 - t).abs() < 1e-4 * (1.0 + t), "{} vs {t}", h.t);
                    hits += 1;
                    inside += i % 2;
                }
                (None, None) => {}
                (got, want) => {
                    // only a hit within rounding of a rim may disagree
                    let t = got.map(|h| h.t as f64).or(want).unwrap();
                    let h = ((o - s.p0).as_dvec3() + d.as_dvec3() * t).dot(s.axis.as_dvec3());
                    assert!(
                        h.abs() < 1e-4 || (h - s.l as f64).abs() < 1e-4,
                        "{got:?} vs {want:?}"
                    );
                }
            }
        }
        assert!(hits > 500 && inside > 400, "{hits} {inside}");
    }

    #[test]
    fn grazing_parallel_behind_and_open_ends() {
        let s = setup(false);
        let y = s.axis.cross(s.x);
        let mid = s.p0 + s.axis * (0.5 * s.l);
        // tangent to the side: touches at distance 3 (or misses by rounding)
        let graze = Ray::new(mid + s.x * s.r - y * 3.0, y);
        if let Some(h) = s.hit(&graze) {
            assert!((h.t - 3.0).abs() < 1e-2, "{}", h.t);
        }
        // just outside the radius: a miss
        assert!(s
            .hit(&Ray::new(mid + s.x * (s.r * 1.001) - y * 3.0, y))
            .is_none());
        // the cylinder behind the origin: a miss
        assert!(s.hit(&Ray::new(mid + y * 3.0, y)).is_none());
        // along the axis, through the open ends: a miss
        assert!(s.hit(&Ray::new(s.p0 - s.axis * 2.0, s.axis)).is_none());
        // parallel to the axis on the surface's outside: a miss
        assert!(s
            .hit(&Ray::new(mid + s.x * (2.0 * s.r) - s.axis * 5.0, s.axis))
            .is_none());
        // from inside, the far wall
        let h = s.hit(&Ray::new(mid, s.x)).unwrap();
        assert!((h.t - s.r).abs() < 1e-5);
        // beyond the end: misses the side, and from past the end through
        // the open end it meets the inside of the far wall
        assert!(s
            .hit(&Ray::new(s.p0 + s.axis * (s.l + 0.1) - y * 3.0, y))
            .is_none());
        let o = s.p0 + s.axis * (s.l + 1.0);
        let d = (s.p0 + s.axis * (0.5 * s.l) + s.x * s.r - o).normalize();
        let h = s.hit(&Ray::new(o, d)).unwrap();
        assert!((h.t as f64 - s.analytic_t(o, d).unwrap()).abs() < 1e-4);
    }

    #[test]
    fn uv_and_normals_follow_mitsuba() {
        for flip in [false, true] {
            let s = setup(flip);
            let y = s.axis.cross(s.x);
            // the point at φ = 120°, height 0.25 of the length
            let (phi, h) = (120f32.to_radians(), 0.25);
            let radial = s.x * phi.cos() + y * phi.sin();
            let p = s.p0 + s.axis * (h * s.l) + radial * s.r;
            let ray = Ray::new(p + radial * 2.0, -radial);
            let hit = s.hit(&ray).unwrap();
            let si =
                s.shape
                    .surface_interaction::<f32>(&s.store.primal(), &DiffRay::cst(&ray), &hit);
            assert!((si.p.val() - p).length() < 1e-5);
            let n = if flip { -radial } else { radial };
            assert!((si.n.val() - n).length() < 1e-5, "{:?}", si.n);
            assert!((si.uv.val() - Vec2::new(phi / (2.0 * PI), h)).length() < 1e-5);
            // the shading frame's first tangent follows increasing φ
            assert!(si.sh_frame.s.val().dot(s.axis.cross(radial)) > 0.999);
            assert!((si.area_scale - s.r * s.l).abs() < 1e-5);
            // φ < 0 wraps to [0, 2π); the same point sampled by area
            let ps = s.shape.sample_position(&s.store, Vec2::new(h, 0.8));
            let phi = 0.8 * 2.0 * PI;
            let radial = s.x * phi.cos() + y * phi.sin();
            let want = s.p0 + s.axis * (h * s.l) + radial * s.r;
            assert!((ps.p - want).length() < 1e-5);
            assert!((ps.n - if flip { -radial } else { radial }).length() < 1e-5);
            let ray = Ray::new(ps.p + radial * 2.0, -radial);
            let si = s.shape.surface_interaction::<f32>(
                &s.store.primal(),
                &DiffRay::cst(&ray),
                &s.hit(&ray).unwrap(),
            );
            assert!((si.uv.val() - ps.uv).length() < 1e-5, "{:?}", si.uv);
            let at = s
                .shape
                .point_at::<f32>(&s.store.primal(), &si_hit(&ps), ps.p);
            assert!((at.p.val() - ps.p).length() < 1e-5);
            assert!((at.n.val() - ps.n).length() < 1e-5);
        }
    }

    fn si_hit(ps: &PositionSample) -> Hit {
        Hit {
            t: 0.0,
            shape: 0,
            prim: ps.prim,
            uv: ps.local,
            instance: None,
        }
    }

    /// Points sampled by area, seen from a point inside, are distributed
    /// over directions as the reported area density says: the histogram
    /// of the sampled directions' z against the density in solid angle
    /// (pdf · t² / |n · d| where the ray meets the wall, zero through the
    /// open ends) integrated over each band; the density integrates to
    /// one, so it is 1 / area.
    #[test]
    fn area_sampling_matches_its_density() {
        let s = setup(false);
        let area = 2.0 * PI * s.r * s.l;
        assert!((s.shape.surface_area() - area).abs() < 1e-5 * area);
        let y = s.axis.cross(s.x);
        let ref_p = s.p0 + s.axis * (0.35 * s.l) + s.x * (0.3 * s.r) - y * (0.2 * s.r);
        let band = |d: Vec3| ((d.z + 1.0) * 5.0).clamp(0.0, 9.0) as usize;
        let mut rng = crate::testing::Pcg32::new(1);
        let n = 200_000;
        let mut observed = [0f64; 10];
        for _ in 0..n {
            let ps = s.shape.sample_position(&s.store, rng.next_2d());
            assert_eq!(ps.pdf, 1.0 / s.shape.surface_area());
            observed[band((ps.p - ref_p).normalize())] += 1.0 / n as f64;
        }
        let accel = Accel::build(std::slice::from_ref(&s.shape), &s.store);
        let (m, tau) = (400, 2.0 * std::f64::consts::PI);
        let mut expected = [0f64; 10];
        for i in 0..m {
            let z = -1.0 + (i as f64 + 0.5) * 2.0 / m as f64;
            let sin = (1.0 - z * z).sqrt();
            for j in 0..m {
                let phi = (j as f64 + 0.5) * tau / m as f64;
                let d = Vec3::new((sin * phi.cos()) as f32, (sin * phi.sin()) as f32, z as f32);
                let Some(h) = accel.intersect(&Ray::new(ref_p, d)) else {
                    continue;
                };
                let q = ref_p + d * h.t - s.p0;
                let nrm = (q - s.axis * q.dot(s.axis)).normalize();
                let pdf = h.t * h.t / (area * nrm.dot(d).abs());
                expected[band(d)] += pdf as f64 * (2.0 / m as f64) * (tau / m as f64);
            }
        }
        let total: f64 = expected.iter().sum();
        assert!((total - 1.0).abs() < 1e-2, "{total}");
        for (o, e) in observed.iter().zip(expected) {
            // 5 standard errors of the band's frequency, and the rule's error
            let tol = 5.0 * (e / n as f64).sqrt() + 2e-3;
            assert!((o - e).abs() < tol, "{observed:?} vs {expected:?}");
        }
    }

    #[test]
    fn to_world_derivatives_match_finite_differences() {
        let mut s = setup(false);
        let y = s.axis.cross(s.x);
        let mid = s.p0 + s.axis * (0.4 * s.l);
        let ray = Ray::new(mid + (s.x + y) * 3.0, -(s.x + y * 0.9).normalize());
        let hit = s.hit(&ray).unwrap();
        let key = "cyl.to_world";
        let base = s.store.data(s.store.id(key).unwrap()).to_vec();
        // translation, a radius change and an axis tilt
        for k in [3, 0, 6] {
            let mut tan = vec![0.0; 16];
            tan[k] = 1.0;
            let seeds = Seeds::tangents(&s.store, &[(key, &tan)]).unwrap();
            let sd = s.shape.surface_interaction::<Dual>(
                &s.store.view(&seeds),
                &DiffRay::cst(&ray),
                &hit,
            );
            let eps = 1e-3;
            let shape = s.shape.clone();
            let store = &mut s.store;
            let mut ev = |delta: f32| {
                let mut v = base.clone();
                v[k] += delta;
                store.set(key, &v).unwrap();
                shape.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &hit)
            };
            let (sp, sm) = (ev(eps), ev(-eps));
            store.set(key, &base).unwrap();
            let fd = (sp.t - sm.t) / (2.0 * eps);
            assert!(
                (sd.t.d - fd).abs() < 2e-3 * (1.0 + fd.abs()),
                "[{k}]: {} vs {fd}",
                sd.t.d
            );
            let fdn = (sp.n.val() - sm.n.val()) / (2.0 * eps);
            let dn = Vec3::new(sd.n.x.d, sd.n.y.d, sd.n.z.d);
            assert!(
                (dn - fdn).length() < 5e-3 * (1.0 + fdn.length()),
                "[{k}]: {dn} vs {fdn}"
            );
        }
    }

    #[test]
    fn sheared_or_degenerate_placements_are_errors() {
        let mut store = ParamStore::default();
        let t = Transform::new(Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0))).unwrap();
        let e = Cylinder::new("c", &t, false, &mut store)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("c.to_world") && e.contains("uniform scale"),
            "{e}"
        );
    }
}
