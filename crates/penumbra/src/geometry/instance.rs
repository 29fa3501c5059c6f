//! Geometry instancing: Mitsuba 3's `shapegroup` and `instance` plugins.
//!
//! A shape group holds shapes (meshes, spheres, …, each with its own BSDF)
//! that are not rendered where they are declared; each instance renders
//! the whole group placed by its own `to_world`. The group's shapes are
//! ordinary shapes of the scene (they have shape indices, BSDFs, mesh
//! attributes and media like any other) kept out of the scene's top-level
//! acceleration structure: the group has an acceleration structure of
//! its own, built once, and an instance is one primitive of the top-level
//! structure whose box is the group's box transformed, and whose
//! intersection transforms the ray into the group's space and traverses
//! the group's structure (`geometry::accel`). Memory grows with the
//! number of distinct groups, not with the number of instances.
//!
//! A hit through an instance is re-evaluated in `R` like any other (the
//! attached local geometry of docs/architecture.md §1): the group's shape
//! re-evaluates it in the group's space along the ray transformed there,
//! and [`Instance`] maps the result to world space: points and tangents by
//! `to_world`, normals by its inverse transpose, the shading frame rebuilt
//! around the transformed shading normal with its first tangent along the
//! transformed ∂p/∂u (as Mitsuba 3.9 orients it), areas by Nanson's
//! formula.
//!
//! What Mitsuba 3.9 refuses is refused here too, with the same reasons:
//! shape groups inside shape groups, instances inside shape groups, area
//! emitters in shape groups, and an instance's own BSDF, emitter or media
//! (its materials are those of the group's shapes). An instance's
//! `to_world` is a parameter that can be updated but not differentiated,
//! as Mitsuba 3.9's `traverse` flags it; the parameters of the group's
//! shapes (their vertex positions, BSDFs, …) are differentiable, and
//! derivatives flow through every instance of the group.

use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::geometry::{DiffRay, Hit, Ray, Shape, ShapeT, SurfaceInteraction};
use crate::math::{Frame, Transform};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use glam::{Mat3, Mat4, Vec3, Vec4};

/// A `shapegroup`: shapes rendered only through [`Instance`]s.
#[derive(Clone, Debug)]
pub struct ShapeGroup {
    /// Parameter-key prefix of the group (its id); the keys of its shapes
    /// start with it (`<group>.<shape>.vertex_positions`, as Mitsuba's
    /// `traverse()` names them).
    pub key: String,
    /// The group's shapes: indices into the scene's shapes, none of which
    /// the top-level acceleration structure holds.
    pub members: Vec<u32>,
}

/// An `instance`: shape group `group` placed by `to_world`.
#[derive(Clone, Debug)]
pub struct Instance {
    /// Parameter-key prefix (the instance's id).
    pub key: String,
    /// Index of the instanced group in the scene's shape groups.
    pub group: u32,
    /// `<key>.to_world`, 16 floats, row-major; not differentiable.
    pub to_world: ParamId,
    /// The transform as last read from `to_world`.
    xf: Transform,
    /// |det| of the linear part of `to_world` (Nanson's formula).
    det: f32,
}

/// A ray in a group's space: `to_local` applied to the world ray, its
/// direction normalised (the group's shapes expect unit directions), the
/// interval scaled alike. `len` is the length of the transformed world
/// direction: a group-space distance is `len` times the world distance.
#[inline(always)]
pub(crate) fn ray_to_group_space(to_local: &Mat4, ray: &Ray) -> (Ray, f32) {
    let o = to_local.transform_point3(ray.o);
    let d = to_local.transform_vector3(ray.d);
    let len = d.length();
    (
        Ray {
            o,
            d: d / len,
            tmin: ray.tmin * len,
            tmax: ray.tmax * len,
        },
        len,
    )
}

impl Instance {
    /// An instance of group `group` placed by `to_world` (registers
    /// `<key>.to_world`). Errors if `to_world` is not an invertible
    /// affine map.
    pub fn new(
        key: &str,
        group: u32,
        to_world: &Transform,
        store: &mut ParamStore,
    ) -> Result<Instance> {
        let rows: Vec<f32> = to_world.m.transpose().to_cols_array().to_vec();
        let id = store.add(
            format!("{key}.to_world"),
            rows,
            vec![4, 4],
            ParamFlags::NON_DIFFERENTIABLE,
            Domain::Finite,
        )?;
        let mut inst = Instance {
            key: key.to_string(),
            group,
            to_world: id,
            xf: Transform::IDENTITY,
            det: 1.0,
        };
        inst.parameters_changed(store)?;
        Ok(inst)
    }

    /// The current `to_world` (and its inverse).
    #[inline(always)]
    pub fn transform(&self) -> &Transform {
        &self.xf
    }

    /// Re-reads `to_world` after an update; errors (naming the key) if it
    /// is not an invertible affine map.
    pub fn parameters_changed(&mut self, store: &ParamStore) -> Result<()> {
        let m = Mat4::from_cols_array(
            store
                .data(self.to_world)
                .try_into()
                .expect("to_world holds 16 values"),
        )
        .transpose();
        let key = || store.get(self.to_world).key.clone();
        if m.row(3) != Vec4::W {
            return Err(Error::Param {
                key: key(),
                msg: format!(
                    "an instance's to_world must be affine (last row 0, 0, 0, 1), found {}",
                    m.row(3)
                ),
            });
        }
        let xf = Transform::new(m).ok_or_else(|| Error::Param {
            key: key(),
            msg: "an instance's to_world must be invertible (it maps the group to zero volume)"
                .into(),
        })?;
        self.det = Mat3::from_mat4(m).determinant().abs();
        self.xf = xf;
        Ok(())
    }

    /// The hit `hit` (world distance, through this instance) as the
    /// group's acceleration structure reports it along `local` (group
    /// space, `len` as [`ray_to_group_space`] gives it).
    #[inline(always)]
    fn local_hit(hit: &Hit, len: f32) -> Hit {
        Hit {
            t: hit.t * len,
            instance: None,
            ..*hit
        }
    }

    /// Re-evaluates `hit` on `shape` (a shape of this instance's group), in
    /// `R`, the point sliding along the world ray `ray`: the group's shape
    /// re-evaluates it along the ray transformed into the group's space,
    /// and the result is mapped to world space.
    pub fn surface_interaction<R: ScalarReal>(
        &self,
        shape: &Shape,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let inv = Transform {
            m: self.xf.inv,
            inv: self.xf.m,
        };
        let d = inv.vector_r(ray.d);
        let len = d.length();
        let local_ray = DiffRay {
            o: inv.point_r(ray.o),
            d: d / len,
            tmin: ray.tmin * len.val(),
            tmax: ray.tmax * len.val(),
        };
        let local = shape.surface_interaction(store, &local_ray, &Self::local_hit(hit, len.val()));
        let mut si = self.to_world_interaction(local);
        si.t = local.t / len;
        si.wi = si.to_local(-ray.d);
        si
    }

    /// The point of `shape` (of this instance's group) with the surface
    /// coordinates of `hit`, moving with the shape (see
    /// [`ShapeT::point_at`]); `p` is the primal world point.
    pub fn point_at<R: ScalarReal>(
        &self,
        shape: &Shape,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        let local_p = self.xf.inv.transform_point3(p);
        let local = shape.point_at::<R>(store, &Self::local_hit(hit, 1.0), local_p);
        let mut si = self.to_world_interaction(local);
        si.t = R::cst(hit.t);
        si
    }

    /// `si` (in the group's space) mapped to world space; `t` and `wi`
    /// are left as they were.
    fn to_world_interaction<R: ScalarReal>(
        &self,
        si: SurfaceInteraction<R>,
    ) -> SurfaceInteraction<R> {
        let m = &self.xf;
        let n = m.normal_r(si.n);
        // Nanson's formula: an area element of unit normal n' becomes
        // |det A| |A^{-T} n'| times larger under the linear part A
        let area = n.length();
        let dp_du = m.vector_r(si.dp_du);
        let ns = m.normal_r(si.sh_frame.n).normalize();
        SurfaceInteraction {
            p: m.point_r(si.p),
            n: n / area,
            sh_frame: Frame::from_normal_tangent(ns, dp_du),
            dp_du,
            dp_dv: m.vector_r(si.dp_dv),
            area_scale: si.area_scale * area * self.det,
            ..si
        }
    }

    /// The world box of this instance, given the box `(lo, hi)` of its
    /// group: the box of the group box's eight transformed corners.
    pub fn bounds(&self, lo: Vec3, hi: Vec3) -> (Vec3, Vec3) {
        let (mut a, mut b) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for k in 0..8 {
            let c = Vec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let w = self.xf.m.transform_point3(c);
            a = a.min(w);
            b = b.max(w);
        }
        (a, b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::Path;

    fn scene(body: &str) -> Scene {
        Scene::load_str(
            &format!("<scene version=\"3.0.0\"><sensor type=\"perspective\"/>{body}</scene>"),
            Path::new("/nonexistent/instances.xml"),
            &[],
        )
        .unwrap()
    }

    fn load_err(body: &str) -> String {
        Scene::load_str(
            &format!("<scene version=\"3.0.0\">\n<sensor type=\"perspective\"/>\n{body}</scene>"),
            Path::new("/nonexistent/instances.xml"),
            &[],
        )
        .unwrap_err()
        .to_string()
    }

    const TURNED: &str = "<transform name=\"to_world\"><rotate z=\"1\" angle=\"90\"/>\
                          <scale x=\"3\" y=\"1\" z=\"1\"/></transform>";

    /// The local geometry of hits through an instance whose `to_world` is
    /// not a similarity (a scale along x, then a quarter turn about z),
    /// against Mitsuba 3.9.1's `scene.ray_intersect` on the same scenes
    /// (scalar_rgb; the ray from (0.1, 0.2, 5) along −z): the point, the
    /// geometric and shading normals by the inverse transpose, the shading
    /// frame's first tangent along the world ∂p/∂u, the tangents, uv, t.
    /// Mitsuba prints 6 digits; 1e-4 relative covers them and our f32.
    #[test]
    fn hits_through_an_instance_match_mitsuba() {
        let cases = [
            (
                "<shape type=\"rectangle\"/>",
                // p, n, s, dp_du, dp_dv, uv, t
                [
                    [0.1, 0.2, 0.0],
                    [0.0, 0.0, 1.0],
                    [0.0, 1.0, 0.0],
                    [0.0, 2.0, 0.0],
                    [-6.0, 0.0, 0.0],
                ],
                [0.6, 0.483333],
                5.0,
            ),
            (
                "<shape type=\"sphere\"/>",
                [
                    [0.1, 0.2, 0.979229],
                    [0.0111166, 0.200099, 0.979713],
                    [-0.99846, 0.05547, 0.0],
                    [-3.76991, 0.20944, 0.0],
                    [1.51724, 3.03448, -0.636985],
                ],
                [0.973716, 0.0649907],
                4.020_771_5,
            ),
            (
                "<shape type=\"rectangle\"><transform name=\"to_world\"><scale x=\"2\"/>\
                 </transform></shape>",
                [
                    [0.1, 0.2, 0.0],
                    [0.0, 0.0, 1.0],
                    [0.0, 1.0, 0.0],
                    [0.0, 4.0, 0.0],
                    [-6.0, 0.0, 0.0],
                ],
                [0.55, 0.483333],
                5.0,
            ),
        ];
        for (inner, vecs, uv, t) in cases {
            let s = scene(&format!(
                "<shape type=\"shapegroup\" id=\"g\">{inner}</shape>\
                 <shape type=\"instance\" id=\"i\"><ref id=\"g\"/>{TURNED}</shape>"
            ));
            let ray = Ray::new(Vec3::new(0.1, 0.2, 5.0), -Vec3::Z);
            let hit = s.intersect(&ray).expect("the ray hits the instance");
            assert_eq!(hit.instance, Some(0));
            let si = s.surface_interaction::<f32>(&s.params.primal(), &DiffRay::cst(&ray), &hit);
            let close = |a: Vec3, b: [f32; 3], what: &str| {
                let b = Vec3::from(b);
                assert!(
                    (a - b).length() <= 1e-4 * (1.0 + b.length()),
                    "{inner}: {what} {a}, Mitsuba {b}"
                );
            };
            close(si.p.val(), vecs[0], "p");
            close(si.n.val(), vecs[1], "n");
            close(si.sh_frame.n.val(), vecs[1], "shading n");
            close(si.sh_frame.s.val(), vecs[2], "s");
            close(si.dp_du.val(), vecs[3], "dp_du");
            close(si.dp_dv.val(), vecs[4], "dp_dv");
            close(si.uv.val().extend(0.0), [uv[0], uv[1], 0.0], "uv");
            assert!((si.t - t).abs() < 1e-4 * t, "{inner}: t {}", si.t);
            assert!((hit.t - t).abs() < 1e-4 * t, "{inner}: hit t {}", hit.t);
            // wi is the world direction back to the origin, in the frame
            assert!((si.to_world(si.wi).val() - Vec3::Z).length() < 1e-5);
        }
    }

    /// Nanson's formula: the area scale of a hit through an instance is
    /// the group-space one times the area ratio of `to_world` at that
    /// normal, so that integrating it over a group's shape gives the
    /// instance's area: a unit rectangle (area 4) scaled by 3 along x and
    /// turned has area 12, and its barycentric area scale is twice a
    /// triangle's area, 12.
    #[test]
    fn area_scale_follows_the_transform() {
        let s = scene(&format!(
            "<shape type=\"shapegroup\" id=\"g\"><shape type=\"rectangle\"/></shape>\
             <shape type=\"instance\"><ref id=\"g\"/>{TURNED}</shape>"
        ));
        let ray = Ray::new(Vec3::new(0.1, 0.2, 5.0), -Vec3::Z);
        let hit = s.intersect(&ray).unwrap();
        let si = s.surface_interaction::<f32>(&s.params.primal(), &DiffRay::cst(&ray), &hit);
        assert!((si.area_scale - 12.0).abs() < 1e-4, "{}", si.area_scale);
        let pa = s.point_at::<f32>(&s.params.primal(), &hit, si.p.val());
        assert!((pa.p.val() - si.p.val()).length() < 1e-5);
        assert!((pa.area_scale - 12.0).abs() < 1e-4);
        assert!((pa.n.val() - si.n.val()).length() < 1e-6);
    }

    /// Every instance of a group is hit where its transform puts it, the
    /// group's shapes are not hit where they are declared, and the hit
    /// names the group's shape (for its BSDF) and the instance.
    #[test]
    fn instances_place_the_group_and_the_group_is_not_rendered() {
        let s = scene(
            "<shape type=\"shapegroup\" id=\"g\">\
               <shape type=\"sphere\" id=\"ball\"><float name=\"radius\" value=\"0.5\"/>\
                 <bsdf type=\"diffuse\" id=\"red\"/></shape>\
               <shape type=\"cube\"><transform name=\"to_world\"><scale value=\"0.5\"/>\
                 <translate y=\"3\"/></transform></shape>\
             </shape>\
             <shape type=\"instance\" id=\"a\"><ref id=\"g\"/>\
               <transform name=\"to_world\"><translate x=\"4\"/></transform></shape>\
             <shape type=\"instance\" id=\"b\"><ref id=\"g\"/>\
               <transform name=\"to_world\"><translate x=\"-4\"/></transform></shape>",
        );
        assert_eq!(s.groups.len(), 1);
        assert_eq!(s.instances.len(), 2);
        // two instances of two shapes: the top level holds two primitives
        assert_eq!(s.accel.prim_count(), 2);
        let down = |x: f32, y: f32| s.intersect(&Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z));
        assert!(down(0.0, 0.0).is_none(), "the group itself is not rendered");
        for (x, inst) in [(4.0, 0), (-4.0, 1)] {
            let h = down(x, 0.0).expect("the sphere of each instance");
            assert_eq!(h.instance, Some(inst));
            assert!((h.t - 4.5).abs() < 1e-5);
            assert_eq!(s.shape_info[h.shape as usize].key, "g.ball");
            let h = down(x, 3.0).expect("the cube of each instance");
            assert!((h.t - 4.5).abs() < 1e-5);
            assert_eq!(s.shape_info[h.shape as usize].key, "g.shape");
        }
        assert!(s.occluded(&Ray::new(Vec3::new(4.0, 3.0, 5.0), -Vec3::Z)));
        assert!(!s.occluded(&Ray::new(Vec3::new(0.0, 3.0, 5.0), -Vec3::Z)));
        // keys as Mitsuba's traverse() names them
        for key in [
            "g.ball.center",
            "g.shape.vertex_positions",
            "red.reflectance.value",
        ] {
            assert!(s.params.id(key).is_some(), "{key}");
        }
        let id = s.params.require("a.to_world").unwrap();
        assert!(!s.params.get(id).flags.differentiable);
    }

    /// Moving an instance (its `to_world`) or a shape of its group
    /// (`vertex_positions`) and updating the scene moves what rays hit.
    #[test]
    fn updates_move_instances_and_groups() {
        let mut s = scene(
            "<shape type=\"shapegroup\" id=\"g\"><shape type=\"rectangle\" id=\"r\"/></shape>\
             <shape type=\"instance\" id=\"a\"><ref id=\"g\"/></shape>",
        );
        let ray = Ray::new(Vec3::new(5.0, 0.0, 5.0), -Vec3::Z);
        assert!(s.intersect(&ray).is_none());
        let mut m = Mat4::from_translation(Vec3::new(5.0, 0.0, 1.0))
            .transpose()
            .to_cols_array()
            .to_vec();
        s.params.set("a.to_world", &m).unwrap();
        s.update().unwrap();
        let h = s.intersect(&ray).expect("the moved instance");
        assert!((h.t - 4.0).abs() < 1e-5);
        let mut p = s
            .params
            .data(s.params.require("g.r.vertex_positions").unwrap())
            .to_vec();
        for z in p.iter_mut().skip(2).step_by(3) {
            *z = -1.0;
        }
        s.params.set("g.r.vertex_positions", &p).unwrap();
        s.update().unwrap();
        let h = s.intersect(&ray).expect("the moved group shape");
        assert!((h.t - 5.0).abs() < 1e-5, "{}", h.t);
        // a singular to_world is refused, naming the key
        m[0] = 0.0;
        s.params.set("a.to_world", &m).unwrap();
        let e = s.update().unwrap_err().to_string();
        assert!(e.contains("a.to_world") && e.contains("invertible"), "{e}");
    }

    /// What Mitsuba 3.9.1 refuses (its messages in the comments) is
    /// refused, naming the file, the line and what to do.
    #[test]
    fn mitsuba_refusals_are_errors() {
        let group = "<shape type=\"shapegroup\" id=\"g\"><shape type=\"sphere\"/></shape>\n";
        for (body, line, needle) in [
            // "Instancing of emitters is not supported"
            (
                "<shape type=\"shapegroup\" id=\"g\">\n<shape type=\"sphere\"><emitter \
                 type=\"area\"/></shape></shape>\n",
                4,
                "emitters cannot be instanced",
            ),
            // "Nested ShapeGroup is not permitted"
            (
                "<shape type=\"shapegroup\" id=\"g\">\n<shape type=\"shapegroup\" id=\"h\">\
                 <shape type=\"sphere\"/></shape></shape>\n",
                4,
                "shape groups cannot be nested",
            ),
            // "Nested instancing is not permitted"
            (
                "<shape type=\"shapegroup\" id=\"h\"><shape type=\"sphere\"/></shape>\n\
                 <shape type=\"shapegroup\" id=\"g\">\n<shape type=\"instance\"><ref \
                 id=\"h\"/></shape></shape>\n",
                5,
                "instances cannot be nested",
            ),
            // "Only a shapegroup can be specified in an instance."
            (
                &format!(
                    "{group}<shape type=\"instance\"><ref id=\"g\"/>\n<bsdf \
                     type=\"diffuse\"/></shape>\n"
                ),
                5,
                "an instance has no BSDF of its own",
            ),
            (
                &format!(
                    "{group}<shape type=\"instance\"><ref id=\"g\"/>\n<emitter \
                     type=\"area\"/></shape>\n"
                ),
                5,
                "emitters cannot be instanced",
            ),
            (
                "<shape type=\"sphere\" id=\"g\"/>\n<shape type=\"instance\">\n<ref \
                 id=\"g\"/></shape>\n",
                5,
                "references a shape group, found shape 'sphere'",
            ),
            // "A reference to a 'shapegroup' must be specified!"
            ("<shape type=\"instance\"/>\n", 3, "needs a shape group"),
            // "Only a single shapegroup can be specified per instance."
            (
                &format!(
                    "{group}<shape type=\"shapegroup\" id=\"h\"><shape \
                     type=\"sphere\"/></shape>\n<shape type=\"instance\"><ref id=\"g\"/>\n\
                     <ref id=\"h\"/></shape>\n"
                ),
                6,
                "one shape group",
            ),
            // "Tried to add an unsupported object of type SmoothDiffuse"
            (
                "<shape type=\"shapegroup\" id=\"g\"><shape type=\"sphere\"/>\n<bsdf \
                 type=\"diffuse\"/></shape>\n",
                4,
                "a shape group holds only shapes",
            ),
            (
                &format!(
                    "{group}<shape type=\"instance\"><ref id=\"g\"/>\n<float name=\"foo\" \
                     value=\"1\"/></shape>\n"
                ),
                5,
                "unknown parameter 'foo'",
            ),
        ] {
            let e = load_err(body);
            let prefix = format!("/nonexistent/instances.xml:{line}: ");
            assert!(
                e.starts_with(&prefix) && e.contains(needle),
                "{body}\n→ {e}"
            );
        }
    }

    /// The bad-input corpus's instancing files (also run through the
    /// command line by crates/penumbra-cli/tests/cli.rs).
    #[test]
    fn bad_scene_files_name_file_line_and_reason() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_scenes");
        for (file, line, needle) in [
            ("shapegroup_emitter.xml", 9, "emitters cannot be instanced"),
            ("shapegroup_nested.xml", 7, "shape groups cannot be nested"),
        ] {
            let p = dir.join(file);
            let e = Scene::load_file(&p, &[]).unwrap_err().to_string();
            let prefix = format!("{}:{line}: ", p.display());
            assert!(e.starts_with(&prefix) && e.contains(needle), "{e}");
        }
    }

    /// Rays through instances hit what rays through the same shapes
    /// declared in place (their `to_world` composed with the instance's)
    /// hit: the same distances, shapes and points, and the same
    /// occlusion, over random rays (a uniform scale, so that the sphere
    /// stays a sphere in place).
    #[test]
    fn instances_trace_as_the_same_shapes_in_place() {
        let inner = |outer: &str| {
            format!(
                "<shape type=\"cube\"><transform name=\"to_world\"><scale x=\"0.5\" y=\"0.3\" \
                 z=\"0.4\"/><rotate y=\"1\" angle=\"20\"/>{outer}</transform></shape>\
                 <shape type=\"sphere\"><transform name=\"to_world\"><scale value=\"0.4\"/>\
                 <translate x=\"1\"/>{outer}</transform></shape>\
                 <shape type=\"disk\"><transform name=\"to_world\"><scale x=\"0.6\"/>\
                 <rotate x=\"1\" angle=\"70\"/><translate y=\"-0.8\"/>{outer}</transform></shape>"
            )
        };
        let placements = [
            "<scale value=\"1.7\"/><rotate x=\"1\" y=\"2\" z=\"0.5\" angle=\"40\"/>\
             <translate x=\"0.3\" y=\"-0.2\" z=\"0.4\"/>",
            "<scale value=\"0.6\"/><rotate z=\"1\" angle=\"-75\"/><translate x=\"-1.5\" z=\"1\"/>",
        ];
        let instanced = scene(&format!(
            "<shape type=\"shapegroup\" id=\"g\">{}</shape>{}",
            inner(""),
            placements
                .iter()
                .map(|p| format!(
                    "<shape type=\"instance\"><ref id=\"g\"/><transform \
                     name=\"to_world\">{p}</transform></shape>"
                ))
                .collect::<String>()
        ));
        let flat = scene(&placements.iter().map(|p| inner(p)).collect::<String>());
        let mut rng = crate::testing::Pcg32::new(3);
        let mut hits = 0;
        for i in 0..4000 {
            let o = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * 8.0;
            let target = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * 3.0;
            let mut ray = Ray::new(o, (target - o).normalize());
            if i % 3 == 0 {
                ray.tmax = 2.0 + 4.0 * rng.next_f32();
            }
            let (a, b) = (instanced.intersect(&ray), flat.intersect(&ray));
            assert_eq!(instanced.occluded(&ray), b.is_some(), "ray {i}");
            match (a, b) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!(
                        (a.t - b.t).abs() <= 1e-4 * (1.0 + b.t),
                        "ray {i}: {a:?} vs {b:?}"
                    );
                    let sa = instanced.surface_interaction::<f32>(
                        &instanced.params.primal(),
                        &DiffRay::cst(&ray),
                        &a,
                    );
                    let sb = flat.surface_interaction::<f32>(
                        &flat.params.primal(),
                        &DiffRay::cst(&ray),
                        &b,
                    );
                    assert!((sa.p.val() - sb.p.val()).length() < 1e-3, "ray {i}");
                    assert!((sa.n.val() - sb.n.val()).length() < 1e-3, "ray {i}");
                    assert!(
                        (sa.area_scale / sb.area_scale - 1.0).abs() < 1e-3,
                        "ray {i}"
                    );
                }
                (a, b) => panic!("ray {i}: instanced {a:?}, in place {b:?}"),
            }
        }
        assert!(hits > 400, "only {hits} hits");
    }

    /// Memory does not grow with the number of instances beyond one
    /// top-level primitive each: a thousand instances of a 2-triangle
    /// group keep one copy of the triangles.
    #[test]
    fn instances_share_the_group_structure() {
        let mut body =
            String::from("<shape type=\"shapegroup\" id=\"g\"><shape type=\"rectangle\"/></shape>");
        for i in 0..1000 {
            body += &format!(
                "<shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\">\
                 <translate x=\"{}\" y=\"{}\"/></transform></shape>",
                3 * (i % 40),
                3 * (i / 40)
            );
        }
        let s = scene(&body);
        assert_eq!(s.accel.prim_count(), 1000);
        assert_eq!(s.accel.group_prim_counts(), vec![2]);
        let h = s
            .intersect(&Ray::new(Vec3::new(3.0 * 7.0, 3.0 * 11.0, 2.0), -Vec3::Z))
            .unwrap();
        assert_eq!(h.instance, Some(11 * 40 + 7));
    }
}
