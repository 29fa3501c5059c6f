//! The `disk` shape plugin (analytic): the unit disk in the z = 0 plane,
//! normal +z, placed by `to_world` (any affine map: ellipses allowed),
//! `flip_normals` (false). uv is polar as in Mitsuba 3:
//! uv = (r, φ / 2π) of the hit point in the local frame.
//!
//! Parameter in the store: `<key>.to_world` (`[4, 4]`, row-major, geometry).
//! The normal is `to_world`'s normal transform of +z.

use super::{analytic_interaction, azimuth};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::{DiffRay, Hit, PositionSample, ShapeT, SurfaceInteraction};
use crate::math::{warp, Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// An analytic disk.
#[derive(Clone, Debug)]
pub struct Disk {
    pub key: String,
    /// `<key>.to_world`, 16 floats, row-major.
    pub to_world: ParamId,
    pub flip_normals: bool,
    /// Whether `to_world` mirrors (its 3×3 part has a negative determinant).
    mirror: bool,
    area: f32,
}

/// World-space frame of a disk: centre, images of local x and y.
#[derive(Clone, Copy, Debug)]
pub struct DiskFrame {
    pub c: Vec3,
    pub a0: Vec3,
    pub a1: Vec3,
}

impl Disk {
    /// Builds the disk of a `<shape type="disk">` node.
    pub fn load(node: &Node, ctx: &mut LoadContext) -> Result<Disk> {
        let t = node.transform("to_world")?;
        let flip_normals = node.bool("flip_normals", false)?;
        Self::new(&node.key, &t, flip_normals, &mut ctx.store).map_err(|e| node.error(e))
    }

    /// A disk placed by `to_world` (registers `<key>.to_world`).
    pub fn new(
        key: &str,
        to_world: &Transform,
        flip_normals: bool,
        store: &mut ParamStore,
    ) -> Result<Disk> {
        let rows: Vec<f32> = to_world.m.transpose().to_cols_array().to_vec();
        let id = store.add(
            format!("{key}.to_world"),
            rows,
            vec![4, 4],
            ParamFlags::GEOMETRY,
            Domain::Finite,
        )?;
        let mut d = Disk {
            key: key.to_string(),
            to_world: id,
            flip_normals,
            mirror: false,
            area: 0.0,
        };
        d.parameters_changed(store)?;
        Ok(d)
    }

    /// Current world frame (f32).
    pub fn frame(&self, store: &ParamStore) -> DiskFrame {
        let m = store.data(self.to_world);
        DiskFrame {
            c: Vec3::new(m[3], m[7], m[11]),
            a0: Vec3::new(m[0], m[4], m[8]),
            a1: Vec3::new(m[1], m[5], m[9]),
        }
    }

    /// Refreshes the cached area and orientation; errors if the disk
    /// became degenerate.
    pub fn parameters_changed(&mut self, store: &ParamStore) -> Result<()> {
        let m = store.data(self.to_world);
        let a2 = Vec3::new(m[2], m[6], m[10]);
        let f = self.frame(store);
        let nn = f.a0.cross(f.a1);
        self.area = PI * nn.length();
        self.mirror = nn.dot(a2) < 0.0;
        if self.area.is_nan() || self.area <= 0.0 {
            return Err(crate::error::Error::Param {
                key: store.get(self.to_world).key.clone(),
                msg: "the disk's to_world maps it to zero area".into(),
            });
        }
        Ok(())
    }

    /// Unit normal (before `flip_normals`).
    fn normal_sign(&self) -> f32 {
        if self.mirror {
            -1.0
        } else {
            1.0
        }
    }

    /// Ray–disk intersection in f32 on (tmin, tmax).
    #[inline]
    pub fn intersect_f32(f: &DiskFrame, o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> f32 {
        let n = f.a0.cross(f.a1);
        let den = n.dot(d);
        if den == 0.0 {
            return f32::INFINITY;
        }
        let t = n.dot(f.c - o) / den;
        if !(t > tmin && t < tmax) {
            return f32::INFINITY;
        }
        let q = o + d * t - f.c;
        let nn = n.dot(n);
        let x = q.cross(f.a1).dot(n) / nn;
        let y = f.a0.cross(q).dot(n) / nn;
        if x * x + y * y <= 1.0 {
            t
        } else {
            f32::INFINITY
        }
    }
}

impl ShapeT for Disk {
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let (c, a0, a1) = self.frame_r::<R>(store);
        let (o, d) = (ray.o, ray.d);
        let nv = a0.cross(a1);
        let den = nv.dot(d);
        let t = if den.val() != 0.0 {
            nv.dot(c - o) / den
        } else {
            R::cst(hit.t)
        };
        let p = o + d * t;
        let q = p - c;
        let nn = nv.dot(nv);
        let x = q.cross(a1).dot(nv) / nn;
        let y = a0.cross(q).dot(nv) / nn;
        let mut si = self.local_geometry(hit, a0, a1, p, t, x, y);
        si.set_wi(-d);
        si
    }

    /// The point with the primal point's local disk coordinates, moving
    /// with `to_world`.
    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        let f = self.frame(store);
        let nv = f.a0.cross(f.a1);
        let q = p - f.c;
        let (x, y) = (
            q.cross(f.a1).dot(nv) / nv.dot(nv),
            f.a0.cross(q).dot(nv) / nv.dot(nv),
        );
        let (c, a0, a1) = self.frame_r::<R>(store);
        let (x, y) = (R::cst(x), R::cst(y));
        let p = c + a0 * x + a1 * y;
        self.local_geometry(hit, a0, a1, p, R::cst(hit.t), x, y)
    }

    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        let f = self.frame(store);
        let l = Vec2::from(warp::square_to_uniform_disk_concentric(u.into()));
        let mut n = f.a0.cross(f.a1).normalize() * self.normal_sign();
        if self.flip_normals {
            n = -n;
        }
        let phi = azimuth(l.y, l.x);
        PositionSample {
            p: f.c + f.a0 * l.x + f.a1 * l.y,
            n,
            uv: Vec2::new(l.length(), phi / (2.0 * PI)),
            local: l,
            pdf: 1.0 / self.area,
            prim: 0,
        }
    }

    fn surface_area(&self) -> f32 {
        self.area
    }
}

impl Disk {
    /// Centre and images of the local x and y axes, in `R`.
    pub(crate) fn frame_r<R: ScalarReal>(&self, store: &ParamView) -> (V3<R>, V3<R>, V3<R>) {
        let id = self.to_world;
        let m = |r: usize, c: usize| -> R { store.read(id, 4 * r + c) };
        (
            V3::new(m(0, 3), m(1, 3), m(2, 3)),
            V3::new(m(0, 0), m(1, 0), m(2, 0)),
            V3::new(m(0, 1), m(1, 1), m(2, 1)),
        )
    }

    /// Normal, polar uv and shading frame at local coordinates (x, y),
    /// world point `p`; the area scale is |a0 × a1|.
    #[allow(clippy::too_many_arguments)]
    fn local_geometry<R: ScalarReal>(
        &self,
        hit: &Hit,
        a0: V3<R>,
        a1: V3<R>,
        p: V3<R>,
        t: R,
        x: R,
        y: R,
    ) -> SurfaceInteraction<R> {
        let nv = a0.cross(a1);
        let rr = (x * x + y * y).safe_sqrt();
        let phi = azimuth(y, x);
        let uv = V2::new(rr, phi * (0.5 / PI));
        // p = a0 r cos 2πv + a1 r sin 2πv (plus the centre), with the
        // local x direction at the centre, as Mitsuba's disk.cpp
        let (cos_phi, sin_phi) = if rr.val() > 0.0 {
            (x / rr, y / rr)
        } else {
            (R::cst(1.0), R::cst(0.0))
        };
        let dp_du = a0 * cos_phi + a1 * sin_phi;
        let dp_dv = (a1 * cos_phi - a0 * sin_phi) * (rr * (2.0 * PI));
        let mut n = nv.normalize() * R::cst(self.normal_sign());
        if self.flip_normals {
            n = -n;
        }
        let area_scale = nv.length();
        analytic_interaction(hit, t, p, n, [dp_du, dp_dv], uv, area_scale)
    }
}
