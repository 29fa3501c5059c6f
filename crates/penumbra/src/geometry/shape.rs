//! The shape family. One file per plugin (geometry/shapes/); the enum
//! dispatches. Mesh plugins (`ply`, `obj`, `rectangle`, `cube`) all become
//! [`Shape::Mesh`]; `sphere`, `disk` and `cylinder` are analytic.

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::mesh::Mesh;
use crate::geometry::shapes::{self, Cylinder, Disk, Sphere};
use crate::geometry::{DiffRay, Hit, PositionSample, SurfaceInteraction};
use crate::params::{ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// What every shape plugin provides.
pub trait ShapeT {
    /// Re-evaluates the hit reported by the acceleration structure, in `R`,
    /// from the shape's parameters, the point sliding along `ray` (the
    /// parameterisation of a point found by a ray whose direction is a
    /// constant or a function of the parameters: camera rays, delta
    /// bounces).
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R>;
    /// The point of the surface with the surface coordinates of the hit
    /// (`hit.uv` for triangles; analytic shapes take them from the primal
    /// point `p`), moving with the shape: the parameterisation of points
    /// sampled on a surface (Zhang et al. 2020, "Path-Space Differentiable
    /// Rendering", material form). `wi` is left zero.
    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R>;
    /// Samples a point uniformly with respect to surface area.
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample;
    /// Samples a point to light `ref_p` from (its density still per unit
    /// area). Default: [`ShapeT::sample_position`].
    fn sample_position_from(&self, store: &ParamStore, _ref_p: Vec3, u: Vec2) -> PositionSample {
        self.sample_position(store, u)
    }
    /// The area density with which [`ShapeT::sample_position_from`]
    /// samples point `p` (normal `n`) from `ref_p`. Default: uniform.
    fn pdf_position_from(&self, _store: &ParamStore, _ref_p: Vec3, _p: Vec3, _n: Vec3) -> f32 {
        1.0 / self.surface_area()
    }
    /// Total surface area.
    fn surface_area(&self) -> f32;
}

/// Names of the shape plugins, for messages.
pub const SHAPE_PLUGINS: [&str; 8] = [
    "ply",
    "obj",
    "serialized",
    "rectangle",
    "cube",
    "sphere",
    "disk",
    "cylinder",
];

/// All shape plugins.
// A scene holds a few shapes, once, in one array that every hit indexes:
// the unused bytes of the small variants cost nothing, a box per mesh would
// cost an indirection on every hit.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Shape {
    /// `ply`, `obj`, `serialized`, `rectangle`, `cube`.
    Mesh(Mesh),
    Sphere(Sphere),
    Disk(Disk),
    Cylinder(Cylinder),
}

impl Shape {
    /// Builds a shape from its scene node. Reads only the geometric
    /// properties (`filename`, `to_world`, `face_normals`, `flip_normals`,
    /// `flip_tex_coords`, `shape_index`, `center`, `radius`, `p0`, `p1`); the nested `bsdf`,
    /// `emitter`, `interior`, `exterior` are left to the scene builder.
    /// Registers the shape's parameters in `ctx.store` under `node.key`.
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Shape> {
        Ok(match node.plugin.as_str() {
            "ply" => Shape::Mesh(shapes::ply::load(node, ctx)?),
            "obj" => Shape::Mesh(shapes::obj::load(node, ctx)?),
            "serialized" => Shape::Mesh(shapes::serialized::load(node, ctx)?),
            "rectangle" => Shape::Mesh(shapes::rectangle::load(node, ctx)?),
            "cube" => Shape::Mesh(shapes::cube::load(node, ctx)?),
            "sphere" => Shape::Sphere(Sphere::load(node, ctx)?),
            "disk" => Shape::Disk(Disk::load(node, ctx)?),
            "cylinder" => Shape::Cylinder(Cylinder::load(node, ctx)?),
            other => {
                return Err(node.error(format!(
                    "unknown shape plugin '{other}'; supported: {}",
                    SHAPE_PLUGINS.join(", ")
                )))
            }
        })
    }

    /// The plugin name.
    pub fn plugin(&self) -> &'static str {
        match self {
            Shape::Mesh(m) => m.plugin,
            Shape::Sphere(_) => "sphere",
            Shape::Disk(_) => "disk",
            Shape::Cylinder(_) => "cylinder",
        }
    }

    /// The parameter-key prefix.
    pub fn key(&self) -> &str {
        match self {
            Shape::Mesh(m) => &m.key,
            Shape::Sphere(s) => &s.key,
            Shape::Disk(d) => &d.key,
            Shape::Cylinder(c) => &c.key,
        }
    }

    /// Number of primitives (triangles; 1 for analytic shapes).
    pub fn prim_count(&self) -> usize {
        match self {
            Shape::Mesh(m) => m.faces.len(),
            _ => 1,
        }
    }

    pub fn as_mesh(&self) -> Option<&Mesh> {
        match self {
            Shape::Mesh(m) => Some(m),
            _ => None,
        }
    }

    /// Whether the shape flips its normals.
    pub fn flip_normals(&self) -> bool {
        match self {
            Shape::Mesh(m) => m.flip_normals,
            Shape::Sphere(s) => s.flip_normals,
            Shape::Disk(d) => d.flip_normals,
            Shape::Cylinder(c) => c.flip_normals,
        }
    }

    /// Ids of the parameters that move this shape's surface (for the
    /// scene to know when the acceleration structure needs an update).
    pub fn geometry_params(&self) -> Vec<ParamId> {
        match self {
            Shape::Mesh(m) => vec![m.positions, m.to_world_id],
            Shape::Sphere(s) => vec![s.center, s.radius, s.to_world],
            Shape::Disk(d) => vec![d.to_world],
            Shape::Cylinder(c) => vec![c.to_world],
        }
    }

    /// Whether reads of this shape's surface carry derivatives in `R` (a
    /// parameter that moves it is tracked): if not, its points are
    /// constants.
    pub fn moves<R: ScalarReal>(&self, store: &ParamView) -> bool {
        match self {
            Shape::Mesh(m) => R::tracks(store, m.positions) || R::tracks(store, m.to_world_id),
            Shape::Sphere(s) => {
                R::tracks(store, s.center)
                    || R::tracks(store, s.radius)
                    || R::tracks(store, s.to_world)
            }
            Shape::Disk(d) => R::tracks(store, d.to_world),
            Shape::Cylinder(c) => R::tracks(store, c.to_world),
        }
    }

    /// Whether any parameter that a re-evaluated hit of this shape reads
    /// carries derivatives in `R` (those that move it, and a mesh's vertex
    /// normals and texture coordinates): if none does, the hit can be
    /// re-evaluated in f32 and lifted as constants.
    pub fn reads_tracked<R: ScalarReal>(&self, store: &ParamView) -> bool {
        if !R::DIFFERENTIABLE {
            return false;
        }
        self.moves::<R>(store)
            || match self {
                Shape::Mesh(m) => {
                    m.normals.is_some_and(|id| R::tracks(store, id))
                        || m.texcoords.is_some_and(|id| R::tracks(store, id))
                }
                Shape::Sphere(_) | Shape::Disk(_) | Shape::Cylinder(_) => false,
            }
    }

    /// Refreshes derived data after the parameters `changed` were updated
    /// (areas, sampling tables, recomputed vertex normals). Call
    /// [`crate::geometry::Accel::update`] afterwards if any geometry
    /// parameter changed.
    pub fn parameters_changed(
        &mut self,
        store: &mut ParamStore,
        changed: &[ParamId],
    ) -> Result<()> {
        match self {
            Shape::Mesh(m) => m.parameters_changed(store, changed),
            Shape::Sphere(s) => {
                s.parameters_changed(store, changed)?;
                Ok(())
            }
            Shape::Disk(d) => d.parameters_changed(store),
            Shape::Cylinder(c) => c.parameters_changed(store),
        }
    }
}

impl ShapeT for Shape {
    #[inline]
    fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        match self {
            Shape::Mesh(m) => m.surface_interaction(store, ray, hit),
            Shape::Sphere(s) => s.surface_interaction(store, ray, hit),
            Shape::Disk(d) => d.surface_interaction(store, ray, hit),
            Shape::Cylinder(c) => c.surface_interaction(store, ray, hit),
        }
    }
    #[inline]
    fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        match self {
            Shape::Mesh(m) => m.point_at(store, hit, p),
            Shape::Sphere(s) => s.point_at(store, hit, p),
            Shape::Disk(d) => d.point_at(store, hit, p),
            Shape::Cylinder(c) => c.point_at(store, hit, p),
        }
    }
    fn sample_position(&self, store: &ParamStore, u: Vec2) -> PositionSample {
        match self {
            Shape::Mesh(m) => m.sample_position(store, u),
            Shape::Sphere(s) => s.sample_position(store, u),
            Shape::Disk(d) => d.sample_position(store, u),
            Shape::Cylinder(c) => c.sample_position(store, u),
        }
    }
    #[inline]
    fn sample_position_from(&self, store: &ParamStore, ref_p: Vec3, u: Vec2) -> PositionSample {
        match self {
            Shape::Mesh(m) => m.sample_position_from(store, ref_p, u),
            Shape::Sphere(s) => s.sample_position_from(store, ref_p, u),
            Shape::Disk(d) => d.sample_position_from(store, ref_p, u),
            Shape::Cylinder(c) => c.sample_position_from(store, ref_p, u),
        }
    }
    fn pdf_position_from(&self, store: &ParamStore, ref_p: Vec3, p: Vec3, n: Vec3) -> f32 {
        match self {
            Shape::Mesh(m) => m.pdf_position_from(store, ref_p, p, n),
            Shape::Sphere(s) => s.pdf_position_from(store, ref_p, p, n),
            Shape::Disk(d) => d.pdf_position_from(store, ref_p, p, n),
            Shape::Cylinder(c) => c.pdf_position_from(store, ref_p, p, n),
        }
    }
    fn surface_area(&self) -> f32 {
        match self {
            Shape::Mesh(m) => m.surface_area(),
            Shape::Sphere(s) => s.surface_area(),
            Shape::Disk(d) => d.surface_area(),
            Shape::Cylinder(c) => c.surface_area(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::error::SrcLoc;
    use crate::geometry::{DiffRay, Ray};
    use crate::math::Transform;
    use crate::params::Seeds;
    use crate::scene::description::{Class, Prop, Value};
    use glam::{Mat4, Vec3};
    use std::f32::consts::PI;
    use std::rc::Rc;

    fn loc() -> SrcLoc {
        SrcLoc {
            file: "/nonexistent/s.xml".into(),
            line: 3,
        }
    }

    fn node(plugin: &str, id: &str, props: Vec<(&str, Value)>) -> Node {
        let mut n = Node::new(Class::Shape, plugin, Some(id.into()), id.into(), loc());
        for (k, v) in props {
            n.props.push(Prop::new(k, v, loc()));
        }
        n
    }

    fn hit_of(s: &Shape, store: &ParamStore, ray: &Ray) -> Hit {
        let a = crate::geometry::Accel::build(std::slice::from_ref(s), store);
        a.intersect(ray).expect("ray must hit")
    }

    #[test]
    fn unknown_plugin_lists_supported_ones() {
        let mut ctx = LoadContext::default();
        let e = Shape::from_node(&node("torus", "t", vec![]), &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.xml:3")
                && e.contains("'torus'")
                && e.contains("ply, obj, serialized, rectangle, cube, sphere, disk, cylinder"),
            "{e}"
        );
    }

    #[test]
    fn nested_objects_are_left_to_the_scene_builder() {
        let mut ctx = LoadContext::default();
        let bsdf = Rc::new(Node::new(
            Class::Bsdf,
            "diffuse",
            None,
            "r.bsdf".into(),
            loc(),
        ));
        let n = node(
            "rectangle",
            "r",
            vec![
                ("bsdf", Value::Node(bsdf)),
                ("flip_normals", Value::Bool(false)),
            ],
        );
        Shape::from_node(&n, &mut ctx).unwrap();
        // bsdf untouched: check_all_used reports it
        let e = n.check_all_used().unwrap_err().to_string();
        assert!(e.contains("'bsdf'"), "{e}");
    }

    #[test]
    fn rectangle_follows_mitsuba_conventions() {
        let mut ctx = LoadContext::default();
        let t = Transform::translate(Vec3::new(0.0, 0.0, 1.0))
            .after(&Transform::new(Mat4::from_scale(Vec3::new(2.0, 1.0, 1.0))).unwrap());
        let s = Shape::from_node(
            &node("rectangle", "r", vec![("to_world", Value::Transform(t))]),
            &mut ctx,
        )
        .unwrap();
        assert!((s.surface_area() - 8.0).abs() < 1e-5);
        let store = &ctx.store;
        let ray = Ray::new(Vec3::new(1.0, 0.5, 5.0), -Vec3::Z);
        let h = hit_of(&s, store, &ray);
        let si = s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h);
        assert!((si.n.val() - Vec3::Z).length() < 1e-6);
        // local (0.5, 0.5) -> uv (0.75, 0.75)
        assert!(
            (si.uv.val() - Vec2::new(0.75, 0.75)).length() < 1e-5,
            "{:?}",
            si.uv
        );
        assert!((si.sh_frame.s.val() - Vec3::X).length() < 1e-5);
        // a mirroring transform keeps the normal = normal transform of +z
        let mut ctx = LoadContext::default();
        let m = Transform::new(Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0))).unwrap();
        let s = Shape::from_node(
            &node("rectangle", "r", vec![("to_world", Value::Transform(m))]),
            &mut ctx,
        )
        .unwrap();
        let ray = Ray::new(Vec3::new(0.5, 0.5, 5.0), -Vec3::Z);
        let h = hit_of(&s, &ctx.store, &ray);
        let si = s.surface_interaction::<f32>(&ctx.store.primal(), &DiffRay::cst(&ray), &h);
        assert!((si.n.val() - Vec3::Z).length() < 1e-6);
        // world x = 0.5 is local x = -0.5
        assert!(
            (si.uv.val() - Vec2::new(0.25, 0.75)).length() < 1e-5,
            "{:?}",
            si.uv
        );
    }

    /// ∂p/∂u and ∂p/∂v are the derivatives of the surface point in uv:
    /// for hits a small step ε = 5e-4 away (two rays offset across the
    /// surface), p − p₀ = ∂p/∂u Δu + ∂p/∂v Δv to first order. The
    /// remainder is second order, ≲ ε / ρ relative to |p − p₀| where ρ is
    /// the smallest radius of curvature of the surface or of its uv lines
    /// (≥ 0.25 here: the cylinder's radius, the disk's hits off centre); the
    /// rounding of the f32 points (~3e-7 at |p| ≤ 3) is ≲ 1e-3 relative:
    /// 2e-2 bounds both. A mesh without uvs gets the
    /// tangents of its normal's coordinate system (uv are barycentrics
    /// there, so no difference applies), as in Mitsuba.
    #[test]
    fn tangents_are_the_position_derivatives_in_uv() {
        let turn = Transform::rotate(Vec3::new(1.0, 2.0, 0.5), 35.0)
            .after(&Transform::new(Mat4::from_scale(Vec3::new(1.5, 0.8, 1.0))).unwrap());
        let shapes = [
            node(
                "sphere",
                "s",
                vec![
                    ("center", Value::Point(Vec3::new(0.1, -0.2, 0.3))),
                    ("radius", Value::Float(0.7)),
                ],
            ),
            // off centre, where its polar uv lines curve little
            node(
                "disk",
                "d",
                vec![(
                    "to_world",
                    Value::Transform(Transform::translate(Vec3::new(-0.4, -0.3, 0.0)).after(&turn)),
                )],
            ),
            node("rectangle", "r", vec![("to_world", Value::Transform(turn))]),
            node("cube", "c", vec![("to_world", Value::Transform(turn))]),
            node(
                "cylinder",
                "y",
                vec![
                    ("p0", Value::Point(Vec3::new(0.0, -1.0, 0.2))),
                    ("p1", Value::Point(Vec3::new(0.3, 1.0, -0.1))),
                    ("radius", Value::Float(0.3)),
                ],
            ),
        ];
        let eps = 5e-4;
        for n in &shapes {
            let mut ctx = LoadContext::default();
            let s = Shape::from_node(n, &mut ctx).unwrap();
            let store = &ctx.store;
            let at = |o: Vec3, d: Vec3| {
                let ray = Ray::new(o, d);
                let h = hit_of(&s, store, &ray);
                s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h)
            };
            let mut checked = 0;
            for (o, target) in [
                (Vec3::new(3.0, 1.0, 2.0), Vec3::new(0.05, 0.1, 0.1)),
                (Vec3::new(-2.0, 2.5, 1.0), Vec3::new(0.1, 0.05, -0.05)),
                (Vec3::new(0.5, -3.0, -2.0), Vec3::new(0.0, 0.1, 0.05)),
            ] {
                let d = (target - o).normalize();
                let ray = Ray::new(o, d);
                let a = crate::geometry::Accel::build(std::slice::from_ref(&s), store);
                if a.intersect(&ray).is_none() {
                    continue;
                }
                let si = at(o, d);
                let (p0, uv0) = (si.p.val(), si.uv.val());
                let (du, dv) = (si.dp_du.val(), si.dp_dv.val());
                for offset in [
                    d.any_orthonormal_vector(),
                    d.cross(d.any_orthonormal_vector()),
                ] {
                    let sj = at(o + offset * eps, d);
                    let (dp, duv) = (sj.p.val() - p0, sj.uv.val() - uv0);
                    if sj.prim != si.prim || duv.abs().max_element() > 0.5 {
                        continue; // another face, or across the uv seam
                    }
                    let err = dp - (du * duv.x + dv * duv.y);
                    assert!(
                        err.length() <= 2e-2 * dp.length(),
                        "{}: p − p₀ = {dp}, ∂p/∂u {du} Δu {} + ∂p/∂v {dv} Δv {}",
                        n.plugin,
                        duv.x,
                        duv.y
                    );
                    checked += 1;
                }
            }
            assert!(
                checked >= 2,
                "{}: only {checked} differences checked",
                n.plugin
            );
        }

        let mut store = ParamStore::default();
        let triangle = crate::geometry::mesh::MeshData {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(1.0, 0.2, 0.0),
                Vec3::new(0.3, 1.0, 0.4),
            ],
            normals: None,
            texcoords: None,
            faces: vec![[0, 1, 2]],
            attributes: Vec::new(),
        };
        let opts = crate::geometry::mesh::MeshOptions {
            face_normals: true,
            flip_normals: false,
        };
        let m = Mesh::new(
            "ply",
            "m",
            "t.ply",
            triangle,
            &Transform::IDENTITY,
            opts,
            &mut store,
        )
        .unwrap();
        let s = Shape::Mesh(m);
        let ray = Ray::new(Vec3::new(0.4, 0.4, 3.0), -Vec3::Z);
        let h = hit_of(&s, &store, &ray);
        let si = s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h);
        let f = crate::math::Frame::from_normal(si.n);
        assert_eq!((si.dp_du.val(), si.dp_dv.val()), (f.s.val(), f.t.val()));
    }

    #[test]
    fn cube_normals_point_outward() {
        let mut ctx = LoadContext::default();
        let s = Shape::from_node(&node("cube", "c", vec![]), &mut ctx).unwrap();
        assert_eq!(s.prim_count(), 12);
        assert!((s.surface_area() - 24.0).abs() < 1e-5);
        let store = &ctx.store;
        for d in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
            let ray = Ray::new(d * 5.0 + d.any_orthonormal_vector() * 0.3, -d);
            let h = hit_of(&s, store, &ray);
            let si = s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h);
            assert!((si.n.val() - d).length() < 1e-6, "{d}");
            assert!((si.sh_frame.n.val() - d).length() < 1e-6, "{d}");
            assert!((h.t - 4.0).abs() < 1e-5);
            assert!(si.uv.x >= 0.0 && si.uv.x <= 1.0 && si.uv.y >= 0.0 && si.uv.y <= 1.0);
        }
    }

    #[test]
    fn sphere_uv_and_normal_conventions() {
        let mut ctx = LoadContext::default();
        let s = Shape::from_node(
            &node(
                "sphere",
                "s",
                vec![
                    ("center", Value::Point(Vec3::new(1.0, 2.0, 3.0))),
                    ("radius", Value::Float(0.5)),
                ],
            ),
            &mut ctx,
        )
        .unwrap();
        let store = &ctx.store;
        assert!((s.surface_area() - PI).abs() < 1e-5);
        let c = Vec3::new(1.0, 2.0, 3.0);
        // direction (θ, φ) = (60°, 120°) from the centre
        let (th, ph) = (60f32.to_radians(), 120f32.to_radians());
        let dir = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
        let ray = Ray::new(c + dir * 3.0, -dir);
        let h = hit_of(&s, store, &ray);
        let si = s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h);
        assert!((si.t - 2.5).abs() < 1e-5);
        assert!((si.n.val() - dir).length() < 1e-5);
        assert!((si.uv.val() - Vec2::new(ph / (2.0 * PI), th / PI)).length() < 1e-5);
        assert!(si.wi.z > 0.99);
        // φ < 0 wraps to [0, 2π)
        let dir2 = Vec3::new(0.0, -1.0, 0.0);
        let r2 = Ray::new(c + dir2 * 3.0, -dir2);
        let si2 = s.surface_interaction::<f32>(
            &store.primal(),
            &DiffRay::cst(&r2),
            &hit_of(&s, store, &r2),
        );
        assert!((si2.uv.x - 0.75).abs() < 1e-5, "{:?}", si2.uv);
        // flip_normals: inward
        let mut ctx = LoadContext::default();
        let s = Shape::from_node(
            &node("sphere", "s", vec![("flip_normals", Value::Bool(true))]),
            &mut ctx,
        )
        .unwrap();
        let r3 = Ray::new(Vec3::new(0.0, 0.0, 4.0), -Vec3::Z);
        let si3 = s.surface_interaction::<f32>(
            &ctx.store.primal(),
            &DiffRay::cst(&r3),
            &hit_of(&s, &ctx.store, &r3),
        );
        assert!((si3.n.val() + Vec3::Z).length() < 1e-6);
        let ps = s.sample_position(&ctx.store, Vec2::new(0.3, 0.8));
        assert!((ps.p.length() - 1.0).abs() < 1e-5 && (ps.n + ps.p).length() < 1e-5);
        // non-similarity to_world is rejected
        let mut ctx = LoadContext::default();
        let t = Transform::new(Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0))).unwrap();
        let e = Shape::from_node(
            &node("sphere", "s", vec![("to_world", Value::Transform(t))]),
            &mut ctx,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("similarity"), "{e}");
    }

    #[test]
    fn sphere_derivatives_match_finite_differences() {
        let mut ctx = LoadContext::default();
        let s = Shape::from_node(
            &node("sphere", "s", vec![("radius", Value::Float(0.7))]),
            &mut ctx,
        )
        .unwrap();
        let ray = Ray::new(
            Vec3::new(0.3, -0.2, 3.0),
            Vec3::new(-0.05, 0.1, -1.0).normalize(),
        );
        let h = hit_of(&s, &ctx.store, &ray);
        for (key, n, k) in [("s.center", 3, 0), ("s.center", 3, 1), ("s.radius", 1, 0)] {
            let store = &mut ctx.store;
            let base = store.data(store.id(key).unwrap()).to_vec();
            let mut tan = vec![0.0; n];
            tan[k] = 1.0;
            let seeds = Seeds::tangents(store, &[(key, &tan)]).unwrap();
            let sd = s.surface_interaction::<Dual>(&store.view(&seeds), &DiffRay::cst(&ray), &h);
            let eps = 1e-3;
            let mut ev = |delta: f32| {
                let mut v = base.clone();
                v[k] += delta;
                store.set(key, &v).unwrap();
                s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h)
            };
            let (sp, sm) = (ev(eps), ev(-eps));
            store.set(key, &base).unwrap();
            let fd = (sp.t - sm.t) / (2.0 * eps);
            assert!(
                (sd.t.d - fd).abs() < 2e-3 * (1.0 + fd.abs()),
                "{key}[{k}]: {} vs {fd}",
                sd.t.d
            );
            let fdn = (sp.n.val() - sm.n.val()) / (2.0 * eps);
            let dn = Vec3::new(sd.n.x.d, sd.n.y.d, sd.n.z.d);
            assert!(
                (dn - fdn).length() < 5e-3 * (1.0 + fdn.length()),
                "{key}[{k}]: {dn} vs {fdn}"
            );
        }
    }

    /// A sphere lit from outside samples the cone it subtends uniformly
    /// (the mean cosine to its axis), on the side that
    /// faces the lit point, with the density `pdf_position_from` reports;
    /// from inside it samples by area.
    #[test]
    fn sphere_samples_the_cone_it_subtends() {
        let mut ctx = LoadContext::default();
        let c = Vec3::new(0.3, -0.2, 0.5);
        let s = Shape::from_node(
            &node(
                "sphere",
                "s",
                vec![("center", Value::Point(c)), ("radius", Value::Float(0.8))],
            ),
            &mut ctx,
        )
        .unwrap();
        let store = &ctx.store;
        for ref_p in [Vec3::new(1.5, 0.4, -0.3), Vec3::new(40.0, -25.0, 10.0)] {
            let axis = (c - ref_p).normalize();
            let sin2 = 0.64 / (c - ref_p).length_squared();
            let cos_max = (1.0 - sin2).sqrt();
            let cone_pdf = 1.0 / (2.0 * PI * (1.0 - cos_max));
            // uniform over the cone: cos θ from the axis is uniform on
            // [cos θ_max, 1], of mean (1 + cos θ_max) / 2 and variance
            // (1 − cos θ_max)² / 12
            let mut rng = crate::testing::Pcg32::new(7);
            let n = 100_000;
            let mut sum = 0.0f64;
            for _ in 0..n {
                let ps = s.sample_position_from(store, ref_p, rng.next_2d());
                let to = ps.p - ref_p;
                let d = to.normalize();
                assert!(((ps.p - c).length() - 0.8).abs() < 1e-4);
                assert!(ps.n.dot(d) < 1e-3, "the sample faces away");
                assert!(d.dot(axis) >= cos_max - 1e-4, "outside the cone");
                // the area density is the cone's, converted
                let sa = ps.pdf * to.length_squared() / ps.n.dot(-d).max(1e-6);
                assert!((sa / cone_pdf - 1.0).abs() < 2e-2 || ps.n.dot(-d) < 1e-2);
                let again = s.pdf_position_from(store, ref_p, ps.p, ps.n);
                assert!((again - ps.pdf).abs() <= 1e-5 * ps.pdf);
                sum += d.dot(axis) as f64;
            }
            let mean = sum / n as f64;
            let want = (1.0 + cos_max as f64) / 2.0;
            let stderr = (1.0 - cos_max as f64) / (12.0f64 * n as f64).sqrt();
            assert!(
                (mean - want).abs() < 4.0 * stderr + 1e-6,
                "{mean} vs {want}"
            );
        }
        let inside = s.sample_position_from(store, c + Vec3::X * 0.1, Vec2::new(0.3, 0.6));
        assert!((inside.pdf - 1.0 / s.surface_area()).abs() < 1e-6);
    }

    #[test]
    fn disk_uv_normal_and_sampling() {
        let mut ctx = LoadContext::default();
        let t = Transform::translate(Vec3::new(0.0, 0.0, 2.0))
            .after(&Transform::new(Mat4::from_scale(Vec3::splat(2.0))).unwrap());
        let s = Shape::from_node(
            &node("disk", "d", vec![("to_world", Value::Transform(t))]),
            &mut ctx,
        )
        .unwrap();
        let store = &ctx.store;
        assert!((s.surface_area() - 4.0 * PI).abs() < 1e-4);
        let ray = Ray::new(Vec3::new(0.0, -1.0, 5.0), -Vec3::Z);
        let h = hit_of(&s, store, &ray);
        let si = s.surface_interaction::<f32>(&store.primal(), &DiffRay::cst(&ray), &h);
        assert!((si.n.val() - Vec3::Z).length() < 1e-6);
        assert!(
            (si.uv.val() - Vec2::new(0.5, 0.75)).length() < 1e-5,
            "{:?}",
            si.uv
        );
        assert!((si.t - 3.0).abs() < 1e-5);
        // misses outside the radius
        let a = crate::geometry::Accel::build(std::slice::from_ref(&s), store);
        assert!(a
            .intersect(&Ray::new(Vec3::new(2.1, 0.0, 5.0), -Vec3::Z))
            .is_none());
        let ps = s.sample_position(store, Vec2::new(0.9, 0.2));
        assert!((ps.p.z - 2.0).abs() < 1e-6 && ps.p.truncate().length() <= 2.0 + 1e-5);
        assert!((ps.pdf - 1.0 / (4.0 * PI)).abs() < 1e-6);
    }

    #[test]
    fn ply_plugin_errors_carry_the_scene_location() {
        let dir = std::env::temp_dir().join(format!("penumbra-shape-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("bad.ply");
        std::fs::write(
            &f,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n",
        )
        .unwrap();
        let mut ctx = LoadContext::default();
        let n = node(
            "ply",
            "m",
            vec![("filename", Value::Str(f.display().to_string()))],
        );
        let e = Shape::from_node(&n, &mut ctx).unwrap_err().to_string();
        assert!(
            e.contains("s.xml:3") && e.contains("bad.ply") && e.contains("zero area"),
            "{e}"
        );
        let n = node("ply", "m", vec![]);
        let e = Shape::from_node(&n, &mut ctx).unwrap_err().to_string();
        assert!(e.contains("filename"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
