//! The boundary term of primary visibility (forward mode; reverse mode
//! against it and against one analytic case): derivatives of images whose
//! silhouettes and sharp edges move, where the interior term alone is
//! wrong (zero, in these scenes: every surface and the background have
//! constant radiance, so the whole derivative is the boundary term).
//!
//! Tolerances come from the estimators' own noise: every quantity is
//! estimated over `BATCHES` independent batches (different seeds), giving
//! a mean and a standard error.
//! - Against an analytic answer (a triangle's projected area): the mean
//!   must be within 4 standard errors of it, plus a floor of 0.2 % of the
//!   answer (the edge offset of the jump estimate and f32 rounding), and
//!   the standard error must be below 1 % of the answer (so that the test
//!   could fail).
//! - Against finite differences of the rendered image (the same seeds at
//!   θ ± h, 256 stratified samples per pixel), per pixel (channels
//!   summed). The finite difference is exactly the derivative AVERAGED over
//!   [θ − h, θ + h]; where an edge crosses a pixel corner within the step
//!   (a nearly vertical edge's crossing with a pixel column slides fast
//!   along it), that average differs from the derivative at θ by a large
//!   part of the pixel's value. So the forward-mode side is averaged over
//!   the same interval: the midpoint rule over `STEPS` parameter values,
//!   each with its own seed. h moves the edges by about 0.1 pixel. Then
//!   z_p = |fwd_p − fd_p| / √(σ²_fwd,p + σ²_fd,p + floor²), floor = 1 % of
//!   the largest |fd_p|. Over the pixels where either is above the floor,
//!   the mean of z_p² must be ≤ 2 (about 1.15 expected without the floor:
//!   standard errors from 16 batches, a Student t with 15 degrees of
//!   freedom), and at most 1 % of them may have z_p > 4. At least 50
//!   pixels must have a finite difference above 4 of its standard errors
//!   (the test sees edges), and the image sums must agree within 4
//!   standard errors plus 1 %.
//!
//! The box filter makes each pixel the plain integral over its square.

use crate::common;

use penumbra::diff::{render_backward, render_forward, translation_tangent};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

const BATCHES: u64 = 16;

fn load(xml: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/inline-test.xml");
    Scene::load_str(xml, &path, &[]).unwrap_or_else(|e| panic!("{e}\n{xml}"))
}

/// A pinhole camera `camera` at (0, 0, 5) looking at the origin (+y up),
/// fov 40°, a square `size`² film with a box filter, a stratified sampler.
fn sensor(size: u32, spp: u32) -> String {
    format!(
        r#"<sensor type="perspective" id="camera">
            <float name="fov" value="40"/>
            <transform name="to_world">
                <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="{size}"/>
                <integer name="height" value="{size}"/>
                <rfilter type="box"/>
            </film>
            <sampler type="stratified"><integer name="sample_count" value="{spp}"/></sampler>
        </sensor>"#
    )
}

/// The camera of [`sensor`] made orthographic, its view window scaled to
/// [-1.6, 1.6]² in the world.
fn orthographic_sensor(size: u32, spp: u32) -> String {
    sensor(size, spp)
        .replace(r#"type="perspective""#, r#"type="orthographic""#)
        .replace(r#"<float name="fov" value="40"/>"#, "")
        .replace("<lookat", r#"<scale x="1.6" y="1.6"/><lookat"#)
}

/// `sppp` is the budget of both boundary terms (primary and shadows).
fn opts(seed: u64, spp: u32, sppp: u32) -> RenderOptions {
    RenderOptions {
        spp: Some(spp),
        sppp: Some(sppp),
        sppi: Some(sppp),
        seed,
        ..Default::default()
    }
}

/// A world point's film position (pixels) in the camera of [`sensor`]:
/// looking down −z from z = 5, film x towards world +x, film y down.
fn project(p: [f64; 3], size: f64) -> [f64; 2] {
    let t = (20f64).to_radians().tan();
    let z = 5.0 - p[2];
    [
        0.5 * size * (1.0 + p[0] / (z * t)),
        0.5 * size * (1.0 - p[1] / (z * t)),
    ]
}

/// Its derivative along the world velocity `v`.
fn project_d(p: [f64; 3], v: [f64; 3], size: f64) -> [f64; 2] {
    let t = (20f64).to_radians().tan();
    let z = 5.0 - p[2];
    [
        0.5 * size * (v[0] * z + p[0] * v[2]) / (z * z * t),
        -0.5 * size * (v[1] * z + p[1] * v[2]) / (z * z * t),
    ]
}

/// The derivative of the projected area (pixels²) of triangle `tri` when
/// it moves with velocity `v`: the shoelace formula differentiated.
fn projected_area_derivative(tri: [[f64; 3]; 3], v: [f64; 3], size: f64) -> f64 {
    let x = tri.map(|p| project(p, size));
    let dx = tri.map(|p| project_d(p, v, size));
    let mut area = 0.0;
    let mut d_area = 0.0;
    for i in 0..3 {
        let j = (i + 1) % 3;
        area += 0.5 * (x[i][0] * x[j][1] - x[j][0] * x[i][1]);
        d_area += 0.5
            * (dx[i][0] * x[j][1] + x[i][0] * dx[j][1] - dx[j][0] * x[i][1] - x[j][0] * dx[i][1]);
    }
    d_area * area.signum()
}

/// Writes a one-triangle OBJ file for a test and returns its path.
fn triangle_obj(name: &str, tri: [[f64; 3]; 3]) -> PathBuf {
    let path = std::env::temp_dir().join(format!(
        "penumbra-visibility-{}-{name}.obj",
        std::process::id()
    ));
    let mut text = String::new();
    for p in tri {
        text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    text += "f 1 2 3\n";
    std::fs::write(&path, text).unwrap();
    path
}

/// The triangle `tri` emitting (1, 2, 3) over black, seen by [`sensor`]
/// (one sample per pixel): with a box filter, the image sum is radiance ×
/// projected area.
fn triangle_scene(name: &str, tri: [[f64; 3]; 3], size: u32) -> Scene {
    let obj = triangle_obj(name, tri);
    let xml = format!(
        r#"<scene version="3.0.0">
            <integrator type="direct"/>
            {}
            <shape type="obj" id="tri">
                <string name="filename" value="{}"/>
                <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter>
            </shape>
        </scene>"#,
        sensor(size, 1),
        obj.display()
    );
    let scene = load(&xml);
    let _ = std::fs::remove_file(&obj);
    scene
}

/// (a) An emitting triangle over black: with a box filter, the image sum
/// is radiance × projected area, whose derivative is known in closed form.
#[test]
fn triangle_area_derivative_matches_the_analytic_one() {
    const SIZE: u32 = 64;
    // tilted, so that a translation parallel to the film changes the area
    let tri = [[-1.0, -0.8, 0.3], [1.2, -0.5, -0.4], [0.1, 1.0, 0.2]];
    let scene = triangle_scene("area", tri, SIZE);
    for v in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
        let t = translation_tangent(&scene, "tri.vertex_positions", v.map(|x| x as f32)).unwrap();
        let sums: Vec<f64> = (0..BATCHES)
            .map(|b| {
                let d = render_forward(
                    &scene,
                    &[("tri.vertex_positions", &t)],
                    &opts(100 + b, 1, 4),
                )
                .unwrap();
                d.data.iter().map(|&x| x as f64).sum()
            })
            .collect();
        let (mean, se) = common::mean_se(&sums);
        let exact = 6.0 * projected_area_derivative(tri, v, SIZE as f64);
        eprintln!("triangle moved by {v:?}: {mean:.3} ± {se:.3}, analytic {exact:.3}");
        assert!(
            se < 0.01 * exact.abs(),
            "{v:?}: standard error {se} too large for {exact}"
        );
        assert!(
            (mean - exact).abs() <= 4.0 * se + 2e-3 * exact.abs(),
            "{v:?}: {mean} ± {se}, analytic {exact}"
        );
    }
}

/// Samples per pixel of the finite differences (stratified: the number of
/// samples that cross an edge between θ − h and θ + h varies little).
const FD_SPP: u32 = 256;
/// Points of the midpoint rule that averages the forward-mode derivative
/// over the step of the finite differences.
const STEPS: u32 = 8;

/// The per-pixel comparison of the module documentation, for the
/// derivative along `tangent` of parameter `key`, finite differences with
/// step `h`; forward mode with `spp` interior and `sppp` edge samples per
/// pixel. Pixel values are summed over the channels.
fn compare_with_finite_differences(
    name: &str,
    xml: &str,
    key: &str,
    tangent: impl Fn(&Scene) -> Vec<f32>,
    h: f32,
    budgets: (u32, u32),
) {
    compare_moves_with_finite_differences(name, xml, &[(key, &tangent)], h, budgets)
}

/// [`compare_with_finite_differences`] for several parameters moving at
/// once, each along its own tangent.
#[allow(clippy::type_complexity)]
fn compare_moves_with_finite_differences(
    name: &str,
    xml: &str,
    moves: &[(&str, &dyn Fn(&Scene) -> Vec<f32>)],
    h: f32,
    (spp, sppp): (u32, u32),
) {
    let mut scene = load(xml);
    // per key: the tangent, the value, and the vertex normals to keep
    let moves: Vec<(&str, Vec<f32>, Vec<f32>, Option<(String, Vec<f32>)>)> = moves
        .iter()
        .map(|(key, tangent)| {
            let id = scene.params.require(key).unwrap();
            // a mesh's vertex normals are recomputed from moved positions
            // unless they are set in the same update (as in Mitsuba): keep
            // them, they are right for a translation
            let normals_key = key.replace("vertex_positions", "vertex_normals");
            let normals = scene
                .params
                .id(&normals_key)
                .filter(|_| normals_key != *key)
                .map(|id| (normals_key.clone(), scene.params.data(id).to_vec()));
            (
                *key,
                tangent(&scene),
                scene.params.data(id).to_vec(),
                normals,
            )
        })
        .collect();
    let tangents: Vec<(&str, &[f32])> = moves
        .iter()
        .map(|(k, t, _, _)| (*k, t.as_slice()))
        .collect();
    let pixels = |data: &[f32], scale: f64| -> Vec<f64> {
        data.chunks_exact(3)
            .map(|c| c.iter().map(|&v| v as f64).sum::<f64>() * scale)
            .collect()
    };
    let (mut fwd, mut fd) = (Vec::new(), Vec::new());
    let set = |scene: &mut Scene, s: f32| {
        for (key, t, base, normals) in &moves {
            let v: Vec<f32> = base.iter().zip(t).map(|(b, t)| b + s * t).collect();
            scene.params.set(key, &v).unwrap();
            if let Some((k, n)) = normals {
                scene.params.set(k, n).unwrap();
            }
        }
        scene.update().unwrap();
    };
    for b in 0..BATCHES {
        let o = opts(1000 + b, FD_SPP, 0);
        set(&mut scene, h);
        let plus = render(&scene, &o).unwrap().data;
        set(&mut scene, -h);
        let minus = render(&scene, &o).unwrap().data;
        let diff: Vec<f32> = plus.iter().zip(&minus).map(|(p, m)| p - m).collect();
        fd.push(pixels(&diff, 1.0 / (2.0 * h as f64)));
        // the derivative averaged over [θ − h, θ + h] (midpoint rule)
        let mut mean = vec![0.0; diff.len() / 3];
        for k in 0..STEPS {
            set(
                &mut scene,
                h * (2.0 * (k as f32 + 0.5) / STEPS as f32 - 1.0),
            );
            let o = opts(2000 + b * STEPS as u64 + k as u64, spp, sppp);
            let d = render_forward(&scene, &tangents, &o).unwrap();
            let d = pixels(&d.data, 1.0 / STEPS as f64);
            mean.iter_mut().zip(d).for_each(|(m, d)| *m += d);
        }
        set(&mut scene, 0.0);
        fwd.push(mean);
    }
    let n = fd[0].len();
    let per_pixel = |images: &[Vec<f64>], i: usize| {
        common::mean_se(&images.iter().map(|im| im[i]).collect::<Vec<_>>())
    };
    let scale = (0..n)
        .map(|i| per_pixel(&fd, i).0.abs())
        .fold(0.0, f64::max);
    let floor = 0.01 * scale;
    let mut z2 = Vec::new();
    let mut worst = Vec::new();
    for i in 0..n {
        let (mf, sf) = per_pixel(&fwd, i);
        let (md, sd) = per_pixel(&fd, i);
        if mf.abs().max(md.abs()) > floor {
            let z = (mf - md).powi(2) / (sf * sf + sd * sd + floor * floor);
            z2.push(z);
            worst.push((z, i, mf, sf, md, sd));
        }
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    let width = (n as f64).sqrt() as usize;
    for (z, p, mf, sf, md, sd) in worst.iter().take(3) {
        eprintln!(
            "{name}: pixel ({}, {}): z² {z:.1}, fwd {mf:.3} ± {sf:.3}, fd {md:.3} ± {sd:.3}",
            p % width,
            p / width
        );
    }
    let mean_z2 = z2.iter().sum::<f64>() / z2.len() as f64;
    let outliers = z2.iter().filter(|&&z| z > 16.0).count();
    let sums = |images: &[Vec<f64>]| {
        common::mean_se(
            &images
                .iter()
                .map(|im| im.iter().sum())
                .collect::<Vec<f64>>(),
        )
    };
    let ((sf, ef), (sd, ed)) = (sums(&fwd), sums(&fd));
    eprintln!(
        "{name}: {} pixels compared, mean z² {mean_z2:.3}, {outliers} with z > 4; \
         Σ fwd {sf:.3} ± {ef:.3}, Σ fd {sd:.3} ± {ed:.3}",
        z2.len()
    );
    assert!(
        z2.len() > 50,
        "{name}: only {} pixels see the edges",
        z2.len()
    );
    assert!(
        mean_z2 <= 2.0 && outliers as f64 <= 0.01 * z2.len() as f64,
        "{name}: mean z² {mean_z2} (≤ 2), {outliers} of {} pixels with z > 4 (≤ 1 %)",
        z2.len()
    );
    let signal = (0..n)
        .filter(|&i| {
            let (m, se) = per_pixel(&fd, i);
            m.abs() > 4.0 * se
        })
        .count();
    assert!(
        signal >= 50,
        "{name}: only {signal} pixels have a finite difference above 4 standard errors"
    );
    assert!(
        (sf - sd).abs() <= 4.0 * (ef * ef + ed * ed).sqrt() + 0.01 * sd.abs(),
        "{name}: Σ fwd {sf} ± {ef}, Σ fd {sd} ± {ed}"
    );
}

/// A dark diffuse rectangle in front of a constant emitter (seen as the
/// background), lit by it: with BSDF sampling only, both sides of every
/// edge have a constant radiance (0.2 and 1).
fn rectangle_scene(size: u32) -> String {
    rectangle_scene_with(&sensor(size, 4))
}

fn rectangle_scene_with(sensor: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct">
                <integer name="emitter_samples" value="0"/>
                <integer name="bsdf_samples" value="1"/>
            </integrator>
            {sensor}
            <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
            <shape type="rectangle" id="rect">
                <transform name="to_world">
                    <scale x="1.2" y="0.8"/>
                    <rotate z="1" angle="20"/>
                    <rotate y="1" angle="30"/>
                    <translate x="0.2" y="-0.1"/>
                </transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.2, 0.2"/></bsdf>
            </shape>
        </scene>"#
    )
}

/// (b) A rectangle translated in front of a constant background.
#[test]
fn rectangle_translation_matches_finite_differences() {
    let key = "rect.vertex_positions";
    compare_with_finite_differences(
        "rectangle moved",
        &rectangle_scene(32),
        key,
        |s| translation_tangent(s, key, [1.0, 0.5, 0.3]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// The tangent of `key` (a `[4, 4]` to_world, row-major) when its object
/// turns about its own origin, about its local `axis` (radians per unit):
/// `d/dθ M·R(θ)` at θ = 0, that is `M·[axis]×`.
fn local_rotation_tangent(scene: &Scene, key: &str, axis: [f32; 3]) -> Vec<f32> {
    let m = scene.params.data(scene.params.require(key).unwrap());
    let [x, y, z] = axis;
    let k = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]];
    let mut t = vec![0.0; 16];
    for i in 0..4 {
        for j in 0..3 {
            t[4 * i + j] = (0..3).map(|l| m[4 * i + l] * k[l][j]).sum();
        }
    }
    t
}

/// (b) The camera turned about its position (about an oblique local axis:
/// a pan, a tilt and a roll at once), the rectangle fixed; perspective,
/// then orthographic.
#[test]
fn camera_rotation_matches_finite_differences() {
    let key = "camera.to_world";
    for (name, xml) in [
        ("perspective camera turned", rectangle_scene(32)),
        (
            "orthographic camera turned",
            rectangle_scene_with(&orthographic_sensor(32, 4)),
        ),
    ] {
        compare_with_finite_differences(
            name,
            &xml,
            key,
            |s| local_rotation_tangent(s, key, [0.3, -0.5, 0.8]),
            0.01,
            (1, 16),
        );
    }
}

/// (b) The camera translated, the rectangle fixed.
#[test]
fn camera_translation_matches_finite_differences() {
    let key = "camera.to_world";
    compare_with_finite_differences(
        "camera moved",
        &rectangle_scene(32),
        key,
        |s| translation_tangent(s, key, [0.5, -1.0, 0.2]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// (b) The rectangle translated, seen through Mitsuba's default Gaussian
/// filter with the film border sampled: the boundary term is splatted
/// through the filter and normalised by each pixel's filter weight.
#[test]
fn gaussian_filter_matches_finite_differences() {
    let sensor = sensor(32, 4).replace(
        r#"<rfilter type="box"/>"#,
        r#"<rfilter type="gaussian"/><boolean name="sample_border" value="true"/>"#,
    );
    let key = "rect.vertex_positions";
    compare_with_finite_differences(
        "rectangle moved (gaussian filter)",
        &rectangle_scene_with(&sensor),
        key,
        |s| translation_tangent(s, key, [1.0, 0.5, 0.3]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// (b) The field of view widened: every edge moves towards the centre.
#[test]
fn field_of_view_matches_finite_differences() {
    compare_with_finite_differences(
        "fov widened",
        &rectangle_scene(32),
        "camera.x_fov",
        |_| vec![1.0],
        0.3,
        (1, 16),
    );
}

/// (b) An orthographic camera: the rectangle translated, then the camera.
#[test]
fn orthographic_camera_matches_finite_differences() {
    let xml = rectangle_scene_with(&orthographic_sensor(32, 4));
    let key = "rect.vertex_positions";
    compare_with_finite_differences(
        "rectangle moved (orthographic)",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, 0.5, 0.3]).unwrap(),
        0.01,
        (1, 16),
    );
    let key = "camera.to_world";
    compare_with_finite_differences(
        "orthographic camera moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [0.5, -1.0, 0.2]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// (c) A cube (one normal per face: flat shading with normal seams at its
/// edges) under a directional light over black, translated: its silhouette
/// and the sharp edges between its visible faces move.
#[test]
fn flat_shaded_cube_translation_matches_finite_differences() {
    let key = "cube.vertex_positions";
    compare_with_finite_differences(
        "cube moved",
        &cube_scene(),
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.5]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// The cube of [`flat_shaded_cube_translation_matches_finite_differences`].
fn cube_scene() -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct">
                <integer name="emitter_samples" value="1"/>
                <integer name="bsdf_samples" value="0"/>
            </integrator>
            {}
            <emitter type="directional">
                <vector name="direction" value="-1, -2, -3"/>
                <rgb name="irradiance" value="3, 3, 3"/>
            </emitter>
            <shape type="cube" id="cube">
                <transform name="to_world">
                    <scale value="0.8"/>
                    <rotate y="1" angle="35"/>
                    <rotate x="1" angle="25"/>
                </transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
            </shape>
        </scene>"#,
        sensor(32, 4)
    )
}

/// The welded icosphere of `scenes/meshes` (id `ball`, diffuse) over
/// black, lit by a directional light shining along `light`, with the
/// extra shape properties `props`, seen by the 32² test camera.
fn icosphere_scene(light: &str, props: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct">
                <integer name="emitter_samples" value="1"/>
                <integer name="bsdf_samples" value="0"/>
            </integrator>
            {}
            <emitter type="directional">
                <vector name="direction" value="{light}"/>
                <rgb name="irradiance" value="3, 3, 3"/>
            </emitter>
            <shape type="ply" id="ball">
                <string name="filename" value="meshes/icosphere3.ply"/>
                {props}
                <transform name="to_world"><translate y="-0.6"/><scale value="2"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
            </shape>
        </scene>"#,
        sensor(32, 4)
    )
}

/// The icosphere flat-shaded (`face_normals`), translated: its outline and
/// every edge between two visible faces carry a jump (a convex polyhedron
/// does not shadow itself, so no shadow edge moves).
#[test]
fn flat_shaded_sphere_translation_matches_finite_differences() {
    let xml = icosphere_scene(
        "-1, -2, -3",
        r#"<boolean name="face_normals" value="true"/>"#,
    );
    let key = "ball.vertex_positions";
    compare_with_finite_differences(
        "flat-shaded sphere moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.5]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// The icosphere smooth-shaded with its exact sphere normals, lit from
/// near the camera (no face shadows a neighbour): its silhouette is lined
/// by a thin sliver where the view crosses the shading normals' horizon,
/// whose border moves too; the estimator merges it into the silhouette's
/// jump (see `diff/primary_boundary.rs`).
#[test]
fn smooth_sphere_silhouette_matches_finite_differences() {
    let xml = icosphere_scene("-0.3, -0.4, -1", "");
    let key = "ball.vertex_positions";
    compare_with_finite_differences(
        "smooth sphere moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.5]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// A smooth-shaded closed mesh: an octahedron whose vertex normals all
/// face the camera (so shading is uniform and never cut off by the view
/// direction), lit by a directional light from near the camera (every face
/// seen faces the light: no face shadows a neighbour), over black. Its
/// edges are all smooth; only the four around its equator are silhouettes
/// from the camera, and they alone carry the boundary term.
#[test]
fn smooth_octahedron_silhouette_matches_finite_differences() {
    let path = std::env::temp_dir().join(format!(
        "penumbra-visibility-{}-octahedron.obj",
        std::process::id()
    ));
    let mut obj = String::new();
    for v in [
        [1.0, 0.1, 0.0],
        [-0.1, 1.0, 0.0],
        [-1.0, -0.1, 0.0],
        [0.1, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ] {
        obj += &format!("v {} {} {}\nvn 0 0 1\n", v[0], v[1], v[2]);
    }
    for f in [
        [1, 2, 5],
        [2, 3, 5],
        [3, 4, 5],
        [4, 1, 5],
        [2, 1, 6],
        [3, 2, 6],
        [4, 3, 6],
        [1, 4, 6],
    ] {
        obj += &format!("f {0}//{0} {1}//{1} {2}//{2}\n", f[0], f[1], f[2]);
    }
    std::fs::write(&path, obj).unwrap();
    let xml = format!(
        r#"<scene version="3.0.0">
            <integrator type="direct">
                <integer name="emitter_samples" value="1"/>
                <integer name="bsdf_samples" value="0"/>
            </integrator>
            {}
            <emitter type="directional">
                <vector name="direction" value="-0.1, -0.2, -1"/>
                <rgb name="irradiance" value="3, 3, 3"/>
            </emitter>
            <shape type="obj" id="octa">
                <string name="filename" value="{}"/>
                <transform name="to_world"><rotate x="1" angle="20"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
            </shape>
        </scene>"#,
        sensor(32, 4),
        path.display()
    );
    let scene = load(&xml);
    let mesh = scene.shapes[0].as_mesh().unwrap();
    assert_eq!(
        mesh.edges(&scene.params).counts(),
        [0, 0, 12, 0, 0],
        "all edges smooth"
    );
    let key = "octa.vertex_positions";
    compare_with_finite_differences(
        "smooth octahedron moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.5]).unwrap(),
        0.01,
        (1, 16),
    );
    let _ = std::fs::remove_file(&path);
}

/// Flipped, degenerate (collinear, two corners at one position) and
/// intersecting triangles: the derivative image stays finite, along
/// translations and random perturbations of every vertex.
#[test]
fn degenerate_and_intersecting_triangles_give_finite_derivatives() {
    let path = std::env::temp_dir().join(format!(
        "penumbra-visibility-{}-degenerate.obj",
        std::process::id()
    ));
    let obj = "\
        v -1.5 -1 0\nv -0.5 -1 0\nv -1 0 0\n\
        v 0.5 -1 0\nv 1 0 0\nv 1.5 -1 0\n\
        v -1 0.5 0\nv 0 0.5 0\nv 1 0.5 0\n\
        v -1 1 0\nv -1 1 0\nv 0 1.5 0\n\
        v -0.5 -0.5 -0.5\nv 0.5 0.5 0.5\nv 0.5 -0.5 0.2\n\
        v -0.5 0.5 0.5\nv 0.5 -0.5 -0.5\nv -0.3 -0.6 0.1\n\
        f 1 2 3\nf 4 5 6\nf 7 8 9\nf 10 11 12\nf 13 14 15\nf 16 17 18\n";
    std::fs::write(&path, obj).unwrap();
    let xml = rectangle_scene(24).replace(
        r#"<shape type="rectangle" id="rect">"#,
        &format!(
            r#"<shape type="obj" id="bad"><string name="filename" value="{}"/></shape>
            <shape type="rectangle" id="rect">"#,
            path.display()
        ),
    );
    let scene = load(&xml);
    let _ = std::fs::remove_file(&path);
    let key = "bad.vertex_positions";
    let tangents = [
        translation_tangent(&scene, key, [1.0, 0.3, -0.2]).unwrap(),
        penumbra::diff::perturbation_tangent(&scene, key, 7).unwrap(),
    ];
    for t in tangents {
        let d = render_forward(&scene, &[(key, &t)], &opts(3, 2, 8)).unwrap();
        assert!(d.data.iter().all(|v| v.is_finite()));
        assert_eq!(d.non_finite_samples, 0);
        assert!(d.data.iter().any(|&v| v != 0.0));
    }
}

/// The warning names only the boundary terms that are missing: none for
/// meshes seen directly and lit by area or environment emitters (the
/// primary and shadow terms are estimated, for a point light too),
/// indirect visibility for a path tracer beyond depth 2, the shadows cast
/// by a sphere (forward and reverse mode alike).
#[test]
fn warnings_name_only_the_missing_terms() {
    let seen = Arc::new(Mutex::new(Vec::<String>::new()));
    let sink = seen.clone();
    penumbra::warn::set_warning_sink(Some(Arc::new(move |m: &str| {
        sink.lock().unwrap().push(m.to_string())
    })));
    let key = "rect.vertex_positions";
    let run = |xml: &str| {
        let scene = load(xml);
        let t = translation_tangent(&scene, key, [1.0, 0.0, 0.0]).unwrap();
        let d = render_forward(&scene, &[(key, &t)], &opts(1, 1, 1)).unwrap();
        let ones = vec![1.0f32; d.data.len()];
        render_backward(&scene, &ones, Some(&[key]), &opts(1, 1, 1)).unwrap();
    };
    let ours = |seen: &Arc<Mutex<Vec<String>>>| -> Vec<String> {
        let mut seen = seen.lock().unwrap();
        let ours = seen
            .iter()
            .filter(|m| m.starts_with(key))
            .cloned()
            .collect();
        seen.clear();
        ours
    };
    let scene = rectangle_scene(8);
    run(&scene);
    assert_eq!(ours(&seen), Vec::<String>::new());
    let point = r#"<emitter type="point"><point name="position" x="0" y="3" z="3"/></emitter>"#;
    run(&scene.replace("<shape", &format!("{point}<shape")));
    assert_eq!(ours(&seen), Vec::<String>::new());
    // one message from forward mode, one from reverse mode
    let only = |messages: Vec<String>| -> String {
        assert_eq!(messages.len(), 2, "{messages:?}");
        assert_eq!(messages[0], messages[1]);
        assert!(messages[0].contains("are missing"), "{}", messages[0]);
        assert!(
            !messages[0].contains("primary visibility"),
            "{}",
            messages[0]
        );
        messages[0].clone()
    };
    let path = r#"<integrator type="path"><integer name="max_depth" value="4"/></integrator>"#;
    let direct = scene[scene.find("<integrator").unwrap()..]
        .split("</integrator>")
        .next()
        .unwrap()
        .to_string()
        + "</integrator>";
    run(&scene.replace(&direct, path));
    let m = only(ours(&seen));
    assert!(
        m.contains("indirect visibility") && !m.contains("shadows"),
        "{m}"
    );
    let sphere = r#"<shape type="sphere"><point name="center" x="0" y="0" z="1"/><float name="radius" value="0.2"/></shape>"#;
    run(&scene.replace("<shape", &format!("{sphere}<shape")));
    let m = only(ours(&seen));
    assert!(
        m.contains("shadows cast by spheres") && !m.contains("indirect"),
        "{m}"
    );
    // a cylinder's outline is not estimated: named when the cylinder
    // moves, not when another shape does
    let cylinder = r#"<shape type="cylinder" id="cyl"><float name="radius" value="0.2"/></shape>"#;
    let with_cylinder = scene.replace("<shape", &format!("{cylinder}<shape"));
    run(&with_cylinder);
    let m = only(ours(&seen));
    assert!(!m.contains("outlines of cylinders"), "{m}");
    let cyl_scene = load(&with_cylinder);
    let cyl_key = "cyl.to_world";
    let mut t = vec![0.0f32; 16];
    t[3] = 1.0;
    let d = render_forward(&cyl_scene, &[(cyl_key, &t)], &opts(1, 1, 1)).unwrap();
    let ones = vec![1.0f32; d.data.len()];
    render_backward(&cyl_scene, &ones, Some(&[cyl_key]), &opts(1, 1, 1)).unwrap();
    let mut all = seen.lock().unwrap();
    let cyl: Vec<&String> = all.iter().filter(|m| m.starts_with(cyl_key)).collect();
    assert_eq!(cyl.len(), 2, "{all:?}");
    assert!(
        cyl[0].contains("the outlines of cylinders")
            && cyl[0].contains("shadows cast by spheres, disks and cylinders")
            && !cyl[0].contains("primary visibility"),
        "{}",
        cyl[0]
    );
    all.clear();
    drop(all);
    penumbra::warn::set_warning_sink(None);
}

/// Uniform pseudo-random numbers in [−1, 1) (a fixed LCG: the test's
/// directions are the same on every run).
fn uniform(seed: u64, n: usize) -> Vec<f32> {
    let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    (0..n)
        .map(|_| {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((x >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

/// Forward and reverse mode take the same samples (film and edges), so
/// for a tangent v and an adjoint image δI, ⟨δI, dI/dθ·v⟩ from forward
/// mode equals ⟨∂L/∂θ, v⟩ from reverse mode up to rounding, boundary term
/// included. Rounding: both sum the same products in different orders,
/// in f32 per sample and f64 across samples, so the difference is a few
/// f32 ulps of the sum of the absolute terms, bounded here by 1e-4 of
/// Σ_p |δI_p (dI/dθ·v)_p| (measured: below 1e-7 of it). The boundary
/// term must be a large part of those terms (without it the test would
/// only check the interior term). The gradient does not depend on the
/// number of threads.
fn assert_modes_agree(name: &str, scene: &Scene, key: &str, seed: u64) {
    let n = scene
        .params
        .get(scene.params.require(key).unwrap())
        .data
        .len();
    let mut v = uniform(seed, n);
    if key.ends_with(".to_world") {
        // the affine part only: the last row stays (0, 0, 0, 1), as a
        // pose's does
        v[12..].fill(0.0);
    }
    let o = opts(seed, 2, 2);
    let fwd = render_forward(scene, &[(key, &v)], &o).unwrap();
    let adjoint = uniform(seed + 1, fwd.data.len());
    let dot = |img: &[f32]| -> (f64, f64) {
        img.iter()
            .zip(&adjoint)
            .fold((0.0, 0.0), |(s, a), (&d, &w)| {
                (s + d as f64 * w as f64, a + (d as f64 * w as f64).abs())
            })
    };
    let (lhs, scale) = dot(&fwd.data);
    let interior = render_forward(scene, &[(key, &v)], &opts(seed, 2, 0)).unwrap();
    let boundary: Vec<f32> = fwd
        .data
        .iter()
        .zip(&interior.data)
        .map(|(f, i)| f - i)
        .collect();
    let (_, boundary_scale) = dot(&boundary);
    let g = render_backward(scene, &adjoint, Some(&[key]), &o).unwrap();
    let one_thread = RenderOptions {
        threads: Some(1),
        ..o.clone()
    };
    let g1 = render_backward(scene, &adjoint, Some(&[key]), &one_thread).unwrap();
    assert_eq!(g.get(key), g1.get(key), "{name}: depends on the threads");
    let rhs: f64 = g
        .get(key)
        .unwrap()
        .iter()
        .zip(&v)
        .map(|(&g, &v)| g as f64 * v as f64)
        .sum();
    eprintln!(
        "{name}: forward {lhs:.6e}, reverse {rhs:.6e}, relative difference {:.2e} of \
         Σ|terms| {scale:.4e} (boundary term: {boundary_scale:.4e})",
        (lhs - rhs).abs() / scale
    );
    assert!(
        (lhs - rhs).abs() <= 1e-4 * scale,
        "{name}: forward {lhs}, reverse {rhs}"
    );
    assert!(
        boundary_scale > 0.25 * scale,
        "{name}: the boundary term is too small to test ({boundary_scale} of {scale})"
    );
}

/// Forward/reverse agreement (see [`assert_modes_agree`]) for vertex
/// positions, a mesh's `to_world`, the camera's `to_world` and its field
/// of view on the rectangle scene, and the vertex positions of a cube
/// under a directional light (whose shading, unlike the rectangle's, also
/// has an interior term) and of the smooth icosphere of `scenes/geom.xml`.
#[test]
fn forward_and_reverse_mode_agree_with_the_boundary_term() {
    let rect = load(&rectangle_scene(32));
    for key in [
        "rect.vertex_positions",
        "rect.to_world",
        "camera.to_world",
        "camera.x_fov",
    ] {
        assert_modes_agree(key, &rect, key, 11);
    }
    let cube = load(&cube_scene());
    assert_modes_agree("cube", &cube, "cube.vertex_positions", 12);
    // the shadow term: an occluder, the receiver, the camera
    let shadow = load(&shadow_scene(
        32,
        OCCLUDER,
        r#"<scale value="1.5"/>"#,
        "1.2, 0.6, 3",
    ));
    for key in [
        "occluder.vertex_positions",
        "receiver.vertex_positions",
        "camera.to_world",
    ] {
        assert_modes_agree(&format!("shadow, {key}"), &shadow, key, 14);
    }
    // a path tracer's noisy jumps across a smooth mesh's silhouette
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/geom.xml");
    let geom = Scene::load_file(&path, &[("res".into(), "32".into())]).unwrap();
    assert_modes_agree("geom", &geom, "obj.vertex_positions", 13);
}

/// The reverse-mode gradient of the image sum of an emitting triangle
/// (adjoint image 1): its dot product with a translation is the analytic
/// derivative of radiance × projected area, as in forward mode
/// ([`triangle_area_derivative_matches_the_analytic_one`], same
/// tolerances).
#[test]
fn reverse_mode_triangle_area_derivative_matches_the_analytic_one() {
    const SIZE: u32 = 64;
    let tri = [[-1.0, -0.8, 0.3], [1.2, -0.5, -0.4], [0.1, 1.0, 0.2]];
    let scene = triangle_scene("reverse", tri, SIZE);
    let key = "tri.vertex_positions";
    let v = [1.0, 0.0, 0.0];
    let t = translation_tangent(&scene, key, v.map(|x| x as f32)).unwrap();
    let ones = vec![1.0f32; (SIZE * SIZE * 3) as usize];
    let sums: Vec<f64> = (0..BATCHES)
        .map(|b| {
            let g = render_backward(&scene, &ones, Some(&[key]), &opts(100 + b, 1, 4)).unwrap();
            g.get(key)
                .unwrap()
                .iter()
                .zip(&t)
                .map(|(&g, &t)| g as f64 * t as f64)
                .sum()
        })
        .collect();
    let (mean, se) = common::mean_se(&sums);
    let exact = 6.0 * projected_area_derivative(tri, v, SIZE as f64);
    eprintln!("reverse mode, triangle moved by {v:?}: {mean:.3} ± {se:.3}, analytic {exact:.3}");
    assert!(
        se < 0.01 * exact.abs(),
        "standard error {se} too large for {exact}"
    );
    assert!(
        (mean - exact).abs() <= 4.0 * se + 2e-3 * exact.abs(),
        "{mean} ± {se}, analytic {exact}"
    );
}

/// A receiver (a diffuse square facing the camera), an occluder between it
/// and a small area light off to the side, direct illumination. `occluder`
/// and `receiver` are the shapes' transforms.
fn shadow_scene(size: u32, occluder: &str, receiver: &str, light: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct"/>
            {sensor}
            <shape type="rectangle" id="receiver">
                <transform name="to_world">{receiver}</transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
            </shape>
            <shape type="rectangle" id="occluder">
                <transform name="to_world">{occluder}</transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.3, 0.3"/></bsdf>
            </shape>
            <shape type="rectangle" id="light">
                <transform name="to_world">
                    <scale value="0.25"/>
                    <lookat origin="{light}" target="0, 0, 0" up="0, 1, 0"/>
                </transform>
                <emitter type="area"><rgb name="radiance" value="40, 40, 40"/></emitter>
            </shape>
        </scene>"#,
        sensor = sensor(size, 4)
    )
}

/// An occluder moving between an area light and a receiver: its shadow
/// moves (and its silhouette, seen in front of the receiver).
#[test]
fn occluder_between_light_and_receiver_matches_finite_differences() {
    let key = "occluder.vertex_positions";
    compare_with_finite_differences(
        "occluder moved",
        &shadow_scene(32, OCCLUDER, r#"<scale value="1.5"/>"#, "1.2, 0.6, 3"),
        key,
        |s| translation_tangent(s, key, [1.0, 0.4, 0.0]).unwrap(),
        0.005,
        (16, 16),
    );
}

/// The same with the occluder and the light outside the view: the whole
/// derivative is the shadow's boundary term.
#[test]
fn shadow_of_an_unseen_occluder_matches_finite_differences() {
    let key = "occluder.vertex_positions";
    compare_with_finite_differences(
        "unseen occluder moved",
        &shadow_scene(
            32,
            r#"<scale value="0.3"/><rotate z="1" angle="25"/><translate x="-1.75" y="0.1" z="1"/>"#,
            r#"<scale value="2"/>"#,
            "-3.5, 0.6, 3",
        ),
        key,
        |s| translation_tangent(s, key, [1.0, 0.4, 0.0]).unwrap(),
        0.005,
        (16, 16),
    );
}

/// The occluder of [`occluder_between_light_and_receiver_matches_finite_differences`]
/// fixed, the receiver moving towards the camera and sideways: the shadow
/// slides over it and grows.
#[test]
fn moving_shadow_receiver_matches_finite_differences() {
    let key = "receiver.vertex_positions";
    compare_with_finite_differences(
        "receiver moved",
        &shadow_scene(32, OCCLUDER, r#"<scale value="1.5"/>"#, "1.2, 0.6, 3"),
        key,
        |s| translation_tangent(s, key, [0.3, -0.2, 1.0]).unwrap(),
        0.01,
        (16, 16),
    );
}

/// The receiver and the light moving together (the occluder fixed).
#[test]
fn plane_and_its_emitter_moving_together_match_finite_differences() {
    let (receiver, light) = ("receiver.vertex_positions", "light.vertex_positions");
    let along =
        |key: &'static str| move |s: &Scene| translation_tangent(s, key, [1.0, 0.5, 0.0]).unwrap();
    compare_moves_with_finite_differences(
        "plane and emitter moved",
        &shadow_scene(32, OCCLUDER, r#"<scale value="1.5"/>"#, "1.2, 0.6, 3"),
        &[(receiver, &along(receiver)), (light, &along(light))],
        0.01,
        (16, 16),
    );
}

/// The camera moving over the shadow: the first vertices slide across the
/// shadow's edges.
#[test]
fn camera_moving_over_a_shadow_matches_finite_differences() {
    let key = "camera.to_world";
    compare_with_finite_differences(
        "camera moved over a shadow",
        &shadow_scene(32, OCCLUDER, r#"<scale value="1.5"/>"#, "1.2, 0.6, 3"),
        key,
        |s| translation_tangent(s, key, [1.0, 0.5, 0.0]).unwrap(),
        0.005,
        (16, 16),
    );
}

/// The occluder of the shadow tests: a small square tilted in its plane,
/// between the receiver and the light.
const OCCLUDER: &str =
    r#"<scale value="0.3"/><rotate z="1" angle="25"/><translate x="0.1" y="0.1" z="1"/>"#;

/// A floor and a wall meeting at a right angle, one flat-shaded mesh (an
/// OBJ written for the test), tilted towards the camera and lit from
/// behind the wall: the wall shadows the floor.
fn right_angle_scene() -> String {
    let path = std::env::temp_dir().join(format!(
        "penumbra-visibility-{}-right-angle.obj",
        std::process::id()
    ));
    std::fs::write(
        &path,
        "v -1 -1 0\nv 1 -1 0\nv 1 0 0\nv -1 0 0\nv 1 0 0.8\nv -1 0 0.8\n\
         f 1 2 3\nf 1 3 4\nf 4 3 5\nf 4 5 6\n",
    )
    .unwrap();
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct"/>
            {sensor}
            <shape type="obj" id="pair">
                <string name="filename" value="{path}"/>
                <transform name="to_world"><rotate x="1" angle="-35"/><translate y="0.3"/></transform>
                <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf></bsdf>
            </shape>
            <shape type="rectangle" id="light">
                <transform name="to_world">
                    <scale value="0.3"/>
                    <lookat origin="0.6, 2.5, 2.2" target="0, -0.4, 0" up="0, 0, 1"/>
                </transform>
                <emitter type="area"><rgb name="radiance" value="30, 30, 30"/></emitter>
            </shape>
        </scene>"#,
        sensor = sensor(32, 4),
        path = path.display()
    )
}

/// The right-angle pair moved: its own shadow (the wall's on the floor)
/// moves with it, and so do its outline and the fold between the faces.
#[test]
fn right_angle_self_shadowing_pair_matches_finite_differences() {
    let key = "pair.vertex_positions";
    compare_with_finite_differences(
        "right-angle pair moved",
        &right_angle_scene(),
        key,
        |s| translation_tangent(s, key, [1.0, 0.5, 0.3]).unwrap(),
        0.01,
        (16, 16),
    );
}

/// `shape` (with id `caster`) above a ground plane, lit by a small area
/// light: the caster's shadow falls on the ground.
fn caster_scene(shape: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct"/>
            {sensor}
            <shape type="rectangle" id="ground">
                <transform name="to_world"><scale value="2.5"/><translate z="-1.2"/></transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>
            </shape>
            {shape}
            <shape type="rectangle" id="light">
                <transform name="to_world">
                    <scale value="0.4"/>
                    <lookat origin="2, 1.5, 3" target="0, 0, 0" up="0, 1, 0"/>
                </transform>
                <emitter type="area"><rgb name="radiance" value="30, 30, 30"/></emitter>
            </shape>
        </scene>"#,
        sensor = sensor(32, 4)
    )
}

/// A welded smooth-shaded sphere (the icosphere with its exact normals)
/// casting a shadow on the ground, moved: its silhouette and its shadow's
/// edge (cast by the edges where its faces turn from the light) move.
#[test]
fn smooth_sphere_shadow_matches_finite_differences() {
    let xml = caster_scene(
        r#"<shape type="ply" id="caster">
            <string name="filename" value="meshes/icosphere3.ply"/>
            <transform name="to_world"><translate y="-0.6"/><scale value="1.6"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
        </shape>"#,
    );
    let key = "caster.vertex_positions";
    compare_with_finite_differences(
        "smooth sphere and its shadow moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.3]).unwrap(),
        0.01,
        (16, 16),
    );
}

/// A flat-shaded cube (normal seams at its edges) casting a shadow on the
/// ground, moved.
#[test]
fn flat_shaded_cube_shadow_matches_finite_differences() {
    let xml = caster_scene(
        r#"<shape type="cube" id="caster">
            <transform name="to_world">
                <scale value="0.5"/><rotate y="1" angle="35"/><rotate x="1" angle="25"/>
            </transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
        </shape>"#,
    );
    let key = "caster.vertex_positions";
    compare_with_finite_differences(
        "flat-shaded cube and its shadow moved",
        &xml,
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.3]).unwrap(),
        0.01,
        (16, 16),
    );
}

/// An emitting analytic shape (`shape`, the body of a `<shape>` element
/// with id `id`) over black, seen by `sensor`: every derivative is the
/// boundary term of its outline (the sphere's silhouette, the disk's rim).
fn analytic_scene(sensor: &str, kind: &str, id: &str, body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            <integrator type="direct"/>
            {sensor}
            <shape type="{kind}" id="{id}">
                {body}
                <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter>
            </shape>
        </scene>"#
    )
}

/// A tilted disk (its rim an ellipse on the film).
fn disk_scene(sensor: &str) -> String {
    analytic_scene(
        sensor,
        "disk",
        "disk",
        r#"<transform name="to_world">
            <scale x="1.1" y="0.8"/>
            <rotate z="1" angle="25"/>
            <rotate x="1" angle="40"/>
            <translate x="0.15" y="-0.1" z="0.3"/>
        </transform>"#,
    )
}

/// A sphere off the optical axis (its silhouette is not centred on the
/// projection of its centre).
fn sphere_scene(sensor: &str) -> String {
    analytic_scene(
        sensor,
        "sphere",
        "ball",
        r#"<point name="center" x="0.3" y="-0.2" z="0.4"/>
           <float name="radius" value="0.9"/>"#,
    )
}

/// (1) An emitting disk moved through its `to_world` (a translation): the
/// rim's boundary term.
#[test]
fn disk_translation_matches_finite_differences() {
    let key = "disk.to_world";
    compare_with_finite_differences(
        "disk moved",
        &disk_scene(&sensor(32, 4)),
        key,
        |s| translation_tangent(s, key, [1.0, -0.5, 0.5]).unwrap(),
        0.01,
        (1, 16),
    );
}

/// (2) An emitting sphere translated (`center`) and scaled (`radius`): the
/// silhouette circle's boundary term, seen by a pinhole.
#[test]
fn sphere_translation_and_scaling_match_finite_differences() {
    let xml = sphere_scene(&sensor(32, 4));
    compare_with_finite_differences(
        "sphere moved",
        &xml,
        "ball.center",
        |_| vec![1.0, -0.5, 0.5],
        0.01,
        (1, 16),
    );
    compare_with_finite_differences(
        "sphere scaled",
        &xml,
        "ball.radius",
        |_| vec![1.0],
        0.01,
        (1, 16),
    );
}

/// The sphere seen by an orthographic camera (its silhouette is a great
/// circle), translated.
#[test]
fn orthographic_sphere_translation_matches_finite_differences() {
    compare_with_finite_differences(
        "orthographic sphere moved",
        &sphere_scene(&orthographic_sensor(32, 4)),
        "ball.center",
        |_| vec![1.0, -0.5, 0.5],
        0.01,
        (1, 16),
    );
}

/// (3) Forward/reverse agreement (see [`assert_modes_agree`]) on the
/// outlines of analytic shapes: the sphere's `center`, `radius` and
/// `to_world`, the camera's pose in front of it (pinhole and
/// orthographic), and the disk's `to_world`.
#[test]
fn forward_and_reverse_mode_agree_on_analytic_outlines() {
    let ball = load(&sphere_scene(&sensor(32, 4)));
    for key in [
        "ball.center",
        "ball.radius",
        "ball.to_world",
        "camera.to_world",
    ] {
        assert_modes_agree(key, &ball, key, 21);
    }
    let ortho = load(&sphere_scene(&orthographic_sensor(32, 4)));
    for key in ["ball.center", "camera.to_world"] {
        assert_modes_agree(&format!("orthographic {key}"), &ortho, key, 22);
    }
    let disk = load(&disk_scene(&sensor(32, 4)));
    assert_modes_agree("disk.to_world", &disk, "disk.to_world", 23);
}

/// Moving spheres and disks seen by a pinhole no longer warn about their
/// silhouettes; their shadows are still named.
#[test]
fn analytic_silhouettes_are_not_named_missing() {
    let seen = Arc::new(Mutex::new(Vec::<String>::new()));
    let sink = seen.clone();
    penumbra::warn::set_warning_sink(Some(Arc::new(move |m: &str| {
        sink.lock().unwrap().push(m.to_string())
    })));
    // an id of its own: the sink also sees the other tests' warnings
    let xml = analytic_scene(&sensor(8, 1), "sphere", "warned", "");
    let scene = load(&xml);
    let key = "warned.center";
    let d = render_forward(&scene, &[(key, &[1.0, 0.0, 0.0])], &opts(1, 1, 1)).unwrap();
    let ones = vec![1.0f32; d.data.len()];
    render_backward(&scene, &ones, Some(&[key]), &opts(1, 1, 1)).unwrap();
    penumbra::warn::set_warning_sink(None);
    let seen = seen.lock().unwrap();
    let ours: Vec<&String> = seen.iter().filter(|m| m.starts_with(key)).collect();
    assert_eq!(ours.len(), 2, "{seen:?}");
    for m in ours {
        assert!(!m.contains("silhouettes"), "{m}");
        assert!(m.contains("shadows"), "{m}");
    }
}

/// The receiver and occluder of the shadow tests lit by `light` (a delta
/// emitter) and a dim constant environment.
fn delta_light_scene(light: &str, occluder_scale: f32) -> String {
    let occluder = OCCLUDER.replace(
        r#"<scale value="0.3"/>"#,
        &format!(r#"<scale value="{occluder_scale}"/>"#),
    );
    let scene = shadow_scene(32, &occluder, r#"<scale value="1.5"/>"#, "1.2, 0.6, 3");
    let area_light = &scene[scene
        .find(r#"<shape type="rectangle" id="light">"#)
        .unwrap()..]
        .split("</shape>")
        .next()
        .unwrap()
        .to_string();
    scene.replace(
        &format!("{area_light}</shape>"),
        &format!(
            r#"{light}<emitter type="constant"><rgb name="radiance" value="0.05, 0.05, 0.05"/></emitter>"#
        ),
    )
}

const POINT_LIGHT: &str = r#"<emitter type="point" id="bulb">
        <point name="position" x="1.2" y="0.6" z="3"/>
        <rgb name="intensity" value="20, 20, 20"/>
    </emitter>"#;

/// The occluder moving between a point light and the receiver: the hard
/// shadow's edge is a curve on the film (`diff/delta_shadow_boundary.rs`).
#[test]
fn point_light_shadow_matches_finite_differences() {
    let key = "occluder.vertex_positions";
    compare_with_finite_differences(
        "occluder moved under a point light",
        &delta_light_scene(POINT_LIGHT, 0.45),
        key,
        |s| translation_tangent(s, key, [1.0, 0.4, 0.0]).unwrap(),
        0.005,
        (16, 16),
    );
}

/// The point light itself moving: its shadow moves.
#[test]
fn moving_point_light_matches_finite_differences() {
    let key = "bulb.position";
    compare_with_finite_differences(
        "point light moved",
        &delta_light_scene(POINT_LIGHT, 0.45),
        key,
        |_| vec![1.0, -0.5, 0.0],
        0.01,
        (16, 16),
    );
}

/// A spot light and a directional light casting the occluder's shadow.
#[test]
fn spot_and_directional_shadows_match_finite_differences() {
    let key = "occluder.vertex_positions";
    for (name, light, scale) in [
        (
            "occluder moved under a spot light",
            r#"<emitter type="spot">
                <transform name="to_world"><lookat origin="1.2, 0.6, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
                <float name="cutoff_angle" value="40"/>
                <rgb name="intensity" value="20, 20, 20"/>
            </emitter>"#,
            0.45,
        ),
        (
            "occluder moved under a directional light",
            r#"<emitter type="directional">
                <vector name="direction" value="-0.4, -0.2, -1"/>
                <rgb name="irradiance" value="5, 5, 5"/>
            </emitter>"#,
            // its shadow is the occluder's size (a point light's is larger)
            0.65,
        ),
    ] {
        compare_with_finite_differences(
            name,
            &delta_light_scene(light, scale),
            key,
            |s| translation_tangent(s, key, [1.0, 0.4, 0.0]).unwrap(),
            0.005,
            (16, 16),
        );
    }
}

/// Forward and reverse mode agree on the delta-light shadow term.
#[test]
fn forward_and_reverse_mode_agree_on_point_light_shadows() {
    let scene = load(&delta_light_scene(POINT_LIGHT, 0.45));
    for key in ["occluder.vertex_positions", "bulb.position"] {
        assert_modes_agree(&format!("point light, {key}"), &scene, key, 31);
    }
}
