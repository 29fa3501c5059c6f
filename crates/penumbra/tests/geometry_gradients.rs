//! Interior derivatives of geometry parameters (vertex positions and
//! normals, shape transforms, sphere centre and radius) against finite
//! differences, in scenes where no visibility edge moves in the image (the
//! surfaces seen fill the view): there the interior term is the whole
//! derivative.
//!
//! Two kinds of checks:
//! - Same samples, pixel by pixel: forward mode against central
//!   differences rendered with the same random numbers. This is exact up
//!   to O(ε²) only where the finite difference moves the path the way the
//!   derivative's parameterisation does: the camera vertex slides along its
//!   ray, emitter samples (next-event estimation) move with the emitter,
//!   delta bounces follow the attached direction. A vertex found by a
//!   sampled direction after a smooth bounce moves with its surface in the
//!   derivative (material form) but slides along the fixed direction in a
//!   re-render, so these checks use direct illumination by emitter
//!   sampling (the `direct` integrator without BSDF samples, or paths that
//!   end before such a vertex contributes). Error measure as in Mitsuba 3's
//!   AD integrator tests: per pixel and channel |fwd − fd| / max(|fd|,
//!   floor), floor at 10 % of the largest |fd|; mean ≤ 2 %, and at most
//!   1 % of the entries above 50 % (a sample whose discrete choice flips
//!   between θ ± ε breaks the difference quotient).
//! - Full path tracing, in expectation: the image sum's derivative by
//!   finite differences and by forward and reverse mode over independent
//!   batches (`diff::check_gradient`); the estimates must agree within 4
//!   standard errors (and the forward and reverse means within 1 %: they
//!   differentiate the same samples).
//!
//! The last test checks that forward and reverse mode give the same
//! derivative: for a random tangent v and a random adjoint image δI,
//! ⟨δI, dI/dθ·v⟩ = ⟨∂L/∂θ, v⟩ with the same samples, up to f32 rounding.

use crate::common;

use common::sensor_xml;
use penumbra::diff::{check_gradient, render_backward, render_forward, CheckOptions};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::path::PathBuf;

const SIZE: u32 = 24;
const SPP: u32 = 8;

/// Scenes are loaded as if they sat in the repository's `scenes/` folder,
/// so they can use its textures.
fn load(xml: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/inline-test.xml");
    Scene::load_str(xml, &path, &[]).unwrap_or_else(|e| panic!("{e}\n{xml}"))
}

fn opts() -> RenderOptions {
    RenderOptions {
        spp: Some(SPP),
        seed: 11,
        ..Default::default()
    }
}

fn scene_xml(integrator: &str, sensor: &str, body: &str) -> String {
    format!(r#"<scene version="3.0.0">{integrator}{sensor}{body}</scene>"#)
}

/// Direct illumination by emitter sampling only (every emitter sample
/// moves with its emitter, in the derivative and in a re-render alike).
const EMITTER_SAMPLING: &str = r#"<integrator type="direct">
    <integer name="emitter_samples" value="2"/>
    <integer name="bsdf_samples" value="0"/>
</integrator>"#;

fn path_integrator(max_depth: u32) -> String {
    format!(
        r#"<integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>"#
    )
}

/// The diffuse BSDF textured with `textures/texture.exr` that the test
/// surfaces wear.
macro_rules! textured_diffuse {
    () => {
        r#"<bsdf type="diffuse">
            <texture type="bitmap" name="reflectance">
                <string name="filename" value="textures/texture.exr"/>
            </texture>
        </bsdf>"#
    };
}

/// A 20 × 20 textured diffuse plane at z = 0 (id `plane`), normal +z.
const PLANE: &str = concat!(
    r#"<shape type="rectangle" id="plane">
        <transform name="to_world"><scale value="10"/></transform>"#,
    textured_diffuse!(),
    "</shape>"
);

/// A 1 × 1 area light (id `light`) at height 2 facing down, with a
/// constant or textured radiance.
fn light(radiance: &str) -> String {
    format!(
        r#"<shape type="rectangle" id="light">
            <transform name="to_world">
                <scale value="0.5"/>
                <rotate x="1" angle="180"/>
                <translate value="0.3, 0.2, 2"/>
            </transform>
            <emitter type="area">{radiance}</emitter>
        </shape>"#
    )
}

const CONSTANT_RADIANCE: &str = r#"<rgb name="radiance" value="6, 5, 4"/>"#;
const TEXTURED_RADIANCE: &str = r#"<texture type="bitmap" name="radiance">
        <string name="filename" value="textures/texture.exr"/>
    </texture>"#;

/// The camera above the plane, looking at it obliquely (the light is out
/// of view).
fn oblique_sensor() -> String {
    sensor_xml("0, -2, 3", 30.0, SIZE, SPP, Some("box"))
}

/// Adds `t` to every vertex (a translation of the whole mesh).
fn translation(n_values: usize, t: [f32; 3]) -> Vec<f32> {
    (0..n_values).map(|i| t[i % 3]).collect()
}

/// The velocity of every vertex under a rotation about the axis `w`
/// through `c`: w × (v − c).
fn rotation(positions: &[f32], w: [f32; 3], c: [f32; 3]) -> Vec<f32> {
    positions
        .chunks_exact(3)
        .flat_map(|v| {
            let r = [v[0] - c[0], v[1] - c[1], v[2] - c[2]];
            [
                w[1] * r[2] - w[2] * r[1],
                w[2] * r[0] - w[0] * r[2],
                w[0] * r[1] - w[1] * r[0],
            ]
        })
        .collect()
}

/// Forward-mode derivative image and the central difference with step
/// `eps` along `tangent`, same seed.
fn derivative_and_fd(
    scene: &mut Scene,
    key: &str,
    tangent: &[f32],
    eps: f32,
) -> (Vec<f32>, Vec<f32>) {
    let o = opts();
    let fwd = render_forward(scene, &[(key, tangent)], &o).unwrap().data;
    let id = scene.params.require(key).unwrap();
    let base = scene.params.data(id).to_vec();
    let mut at = |h: f32| {
        let v: Vec<f32> = base.iter().zip(tangent).map(|(b, t)| b + h * t).collect();
        scene.params.set(key, &v).unwrap();
        scene.update().unwrap();
        render(scene, &o).unwrap().data
    };
    let plus = at(eps);
    let minus = at(-eps);
    at(0.0);
    let fd = plus
        .iter()
        .zip(&minus)
        .map(|(p, m)| (p - m) / (2.0 * eps))
        .collect();
    (fwd, fd)
}

/// The error measure of the module documentation; panics with the
/// numbers if it fails.
fn assert_matches_fd(name: &str, fwd: &[f32], fd: &[f32]) {
    let scale = fd.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(
        scale > 1e-3,
        "{name}: the finite difference is {scale} everywhere: the test would prove nothing"
    );
    let floor = 0.1 * scale;
    let errs: Vec<f32> = fwd
        .iter()
        .zip(fd)
        .map(|(a, b)| (a - b).abs() / b.abs().max(floor))
        .collect();
    let mean = errs.iter().sum::<f32>() / errs.len() as f32;
    let outliers = errs.iter().filter(|&&e| e > 0.5).count() as f32 / errs.len() as f32;
    let sum_fwd: f32 = fwd.iter().sum();
    let sum_fd: f32 = fd.iter().sum();
    eprintln!(
        "{name}: mean relative error {mean:.4}, outliers {:.2}%, Σ fwd {sum_fwd:.4}, Σ fd {sum_fd:.4}",
        100.0 * outliers
    );
    assert!(
        mean < 0.02 && outliers <= 0.01,
        "{name}: mean relative error {mean} (≤ 0.02), {:.2}% of entries above 0.5 (≤ 1%); \
         Σ fwd {sum_fwd}, Σ fd {sum_fd}",
        100.0 * outliers
    );
}

fn check(name: &str, xml: &str, key: &str, tangent: impl Fn(&[f32]) -> Vec<f32>, eps: f32) {
    let mut scene = load(xml);
    let id = scene.params.require(key).unwrap();
    let t = tangent(scene.params.data(id));
    let (fwd, fd) = derivative_and_fd(&mut scene, key, &t, eps);
    assert_matches_fd(name, &fwd, &fd);
}

/// The statistical check of the module documentation, for full path
/// tracing.
fn check_in_expectation(name: &str, xml: &str, key: &str, tangent: impl Fn(&[f32]) -> Vec<f32>) {
    let mut scene = load(xml);
    let id = scene.params.require(key).unwrap();
    let t = tangent(scene.params.data(id));
    let opts = CheckOptions {
        spp: 8,
        batches: 16,
        eps: 1e-2,
        tangent: Some(t),
        ..Default::default()
    };
    let r = check_gradient(&mut scene, key, &opts).unwrap();
    let (fd, fw, rv) = (r.finite_differences, r.forward, r.reverse);
    let z = fw.z_score(&fd);
    eprintln!(
        "{name}: fd {:.5} ± {:.5}, forward {:.5} ± {:.5}, reverse {:.5}, z {z:.2}",
        fd.mean, fd.std_err, fw.mean, fw.std_err, rv.mean
    );
    assert!(
        fw.mean.abs() > 10.0 * fw.std_err,
        "{name}: no signal: {fw:?}"
    );
    assert!(
        z < 4.0,
        "{name}: forward {fw:?} and finite differences {fd:?} disagree (z = {z})"
    );
    assert!(
        (rv.mean - fw.mean).abs() <= 1e-2 * fw.mean.abs(),
        "{name}: reverse {rv:?} and forward {fw:?} differ"
    );
}

fn area_light_scene(integrator: &str, radiance: &str) -> String {
    scene_xml(
        integrator,
        &oblique_sensor(),
        &format!("{PLANE}{}", light(radiance)),
    )
}

fn up(p: &[f32]) -> Vec<f32> {
    translation(p.len(), [0.0, 0.0, 1.0])
}

#[test]
fn plane_translated_under_an_area_light() {
    let key = "plane.vertex_positions";
    let xml = area_light_scene(EMITTER_SAMPLING, CONSTANT_RADIANCE);
    check("plane ⟂ (area light)", &xml, key, up, 1e-3);
    check(
        "plane ∥ (area light)",
        &xml,
        key,
        |p| translation(p.len(), [1.0, 0.5, 0.0]),
        1e-3,
    );
    let xml = area_light_scene(&path_integrator(4), CONSTANT_RADIANCE);
    check_in_expectation("plane ⟂ (area light, paths)", &xml, key, up);
}

#[test]
fn plane_translated_under_an_environment_map() {
    let envmap =
        r#"<emitter type="envmap"><string name="filename" value="textures/museum.exr"/></emitter>"#;
    // two vertices: the environment is reached by emitter and BSDF
    // sampling along directions that do not move
    let xml = scene_xml(
        &path_integrator(2),
        &oblique_sensor(),
        &format!("{PLANE}{envmap}"),
    );
    check("plane ⟂ (envmap)", &xml, "plane.vertex_positions", up, 1e-3);
}

const ENVMAP: &str =
    r#"<emitter type="envmap"><string name="filename" value="textures/museum.exr"/></emitter>"#;

/// A smooth environment (the test texture, about a texel per pixel of
/// the views below): the museum's sharp highlights make the finite
/// differences of a turning view depend on the step (the image sum's
/// difference quotient changes by 20 % from ε = 3e-4 to 1e-2).
const SMOOTH_ENVMAP: &str =
    r#"<emitter type="envmap"><string name="filename" value="textures/texture.exr"/></emitter>"#;

/// Environment lookups follow the direction looked along: the camera
/// turning in front of the environment alone, and a mirror tilted under
/// it (the direction after a delta bounce is attached).
#[test]
fn environment_seen_by_a_turning_camera_and_in_a_tilting_mirror() {
    let fov = r#"<float name="fov" value="40"/>"#;
    let sky = scene_xml(
        EMITTER_SAMPLING,
        &camera_sensor("perspective", fov),
        SMOOTH_ENVMAP,
    );
    check(
        "camera turned (envmap)",
        &sky,
        "camera.to_world",
        |m| turn_about_local_axis(m, 1),
        1e-3,
    );
    let mirror = r#"<shape type="rectangle" id="mirror">
            <transform name="to_world"><scale value="10"/></transform>
            <bsdf type="conductor"/>
        </shape>"#;
    let xml = scene_xml(
        &path_integrator(2),
        &camera_sensor("perspective", fov),
        &format!("{mirror}{SMOOTH_ENVMAP}"),
    );
    check(
        "mirror tilted (envmap)",
        &xml,
        "mirror.vertex_positions",
        |p| rotation(p, [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        1e-3,
    );
}

/// Shading normals turning under an environment map, by full path
/// tracing: emitter samples and BSDF samples reach the environment along
/// world directions that do not move (the same map for both MIS
/// strategies, see `integrator::scatter`).
#[test]
fn vertex_normals_rotated_under_an_environment_map() {
    let xml = ply_plane_scene()
        .replace(EMITTER_SAMPLING, &path_integrator(2))
        .replace(&light(CONSTANT_RADIANCE), ENVMAP);
    check_in_expectation(
        "vertex normals (envmap, paths)",
        &xml,
        "plane.vertex_normals",
        |n| translation(n.len(), [0.3, 0.0, 0.0]),
    );
}

#[test]
fn plane_translated_under_a_textured_area_emitter() {
    let xml = area_light_scene(EMITTER_SAMPLING, TEXTURED_RADIANCE);
    check(
        "plane ⟂ (textured light)",
        &xml,
        "plane.vertex_positions",
        up,
        1e-3,
    );
}

#[test]
fn textured_area_emitter_translated_and_rotated() {
    let key = "light.vertex_positions";
    let moved = |p: &[f32]| translation(p.len(), [0.5, 1.0, 0.5]);
    let xml = area_light_scene(EMITTER_SAMPLING, TEXTURED_RADIANCE);
    check("light moved", &xml, key, moved, 1e-3);
    let rotated = |p: &[f32]| rotation(p, [1.0, 0.0, 0.0], [0.3, 0.2, 2.0]);
    check("light rotated", &xml, key, rotated, 1e-3);
    let xml = area_light_scene(&path_integrator(4), TEXTURED_RADIANCE);
    check_in_expectation("light moved (paths)", &xml, key, moved);
}

/// The area-light scene with emitter sampling, the plane being a PLY mesh
/// with vertex normals (in the file: the xz plane, normal +y).
fn ply_plane_scene() -> String {
    let plane = PLANE
        .replace(
            r#"<shape type="rectangle" id="plane">"#,
            r#"<shape type="ply" id="plane"><string name="filename" value="meshes/plane_uv.ply"/>"#,
        )
        .replace(
            r#"<scale value="10"/>"#,
            r#"<scale value="10"/><rotate x="1" angle="90"/>"#,
        );
    scene_xml(
        EMITTER_SAMPLING,
        &oblique_sensor(),
        &format!("{plane}{}", light(CONSTANT_RADIANCE)),
    )
}

#[test]
fn rotated_vertex_normals() {
    let xml = ply_plane_scene();
    // tilt every vertex normal towards +x (interpolated, then normalised)
    check(
        "vertex normals",
        &xml,
        "plane.vertex_normals",
        |n| translation(n.len(), [0.3, 0.0, 0.0]),
        1e-3,
    );
    // positions rotated without the normals: Mitsuba recomputes the normals
    // from the positions, so their derivative follows the positions'
    check(
        "positions rotated, normals follow",
        &xml,
        "plane.vertex_positions",
        |p| rotation(p, [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        1e-3,
    );
}

#[test]
fn glass_plate_rotated_in_front_of_a_thin_lens() {
    let sensor = format!(
        r#"<sensor type="thinlens">
            <float name="fov" value="30"/>
            <float name="aperture_radius" value="0.05"/>
            <float name="focus_distance" value="5"/>
            <transform name="to_world">
                <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="{SIZE}"/>
                <integer name="height" value="{SIZE}"/>
                <rfilter type="box"/>
            </film>
        </sensor>"#
    );
    let body = format!(
        r#"{PLANE}
        <shape type="rectangle" id="glass">
            <transform name="to_world">
                <scale value="3"/>
                <translate value="0, 0, 2.6"/>
            </transform>
            <bsdf type="dielectric"/>
        </shape>
        <shape type="rectangle" id="glass_back">
            <transform name="to_world">
                <scale value="3"/>
                <rotate x="1" angle="180"/>
                <translate value="0, 0, 2.4"/>
            </transform>
            <bsdf type="dielectric"/>
        </shape>
        <emitter type="point">
            <point name="position" value="0.2, 0.1, 1"/>
            <rgb name="intensity" value="4"/>
        </emitter>"#
    );
    // glass (depth 0, 1), plane (2): next-event estimation at the plane is
    // the last contribution
    let xml = scene_xml(&path_integrator(4), &sensor, &body);
    check(
        "glass rotated",
        &xml,
        "glass.vertex_positions",
        |p| rotation(p, [0.0, 1.0, 0.0], [0.0, 0.0, 2.6]),
        1e-3,
    );
}

/// The camera inside a sphere (normals flipped inwards) lit by a point
/// light: the sphere fills the view whatever its centre and radius.
fn inside_sphere_xml(integrator: &str) -> String {
    let body = concat!(
        r#"<shape type="sphere" id="ball">
            <point name="center" value="0.1, 0.2, 0.3"/>
            <float name="radius" value="6"/>
            <boolean name="flip_normals" value="true"/>"#,
        textured_diffuse!(),
        r#"</shape>
        <emitter type="point">
            <point name="position" value="0.5, 0.5, 1"/>
            <rgb name="intensity" value="30"/>
        </emitter>"#
    );
    scene_xml(
        integrator,
        &sensor_xml("0, -1, 1", 40.0, SIZE, SPP, Some("box")),
        body,
    )
}

#[test]
fn sphere_centre_and_radius() {
    let xml = inside_sphere_xml(EMITTER_SAMPLING);
    check(
        "sphere centre",
        &xml,
        "ball.center",
        |_| vec![1.0, 0.5, -0.5],
        1e-3,
    );
    check("sphere radius", &xml, "ball.radius", |_| vec![1.0], 1e-3);
    let key = "ball.to_world";
    check(
        "sphere to_world moved",
        &xml,
        key,
        |_| moved([0.5, -0.5, 1.0]),
        1e-3,
    );
    check(
        "sphere to_world turned",
        &xml,
        key,
        |m| turn_about_local_axis(m, 2),
        1e-4,
    );
    let xml = inside_sphere_xml(&path_integrator(4));
    let centre = |_: &[f32]| vec![1.0, 0.5, -0.5];
    check_in_expectation("sphere centre (paths)", &xml, "ball.center", centre);
    check_in_expectation("sphere radius (paths)", &xml, "ball.radius", |_| vec![1.0]);
}

#[test]
fn disk_to_world() {
    let body = concat!(
        r#"<shape type="disk" id="floor">
            <transform name="to_world"><scale value="20"/></transform>"#,
        textured_diffuse!(),
        r#"</shape>
        <emitter type="point">
            <point name="position" value="0.5, 0.5, 2"/>
            <rgb name="intensity" value="10"/>
        </emitter>"#
    );
    let xml = scene_xml(EMITTER_SAMPLING, &oblique_sensor(), body);
    // row-major 4×4: translation in x and z, and a small shear of the z axis
    let mut t = vec![0.0f32; 16];
    t[3] = 1.0;
    t[11] = 0.5;
    t[1] = 0.5;
    check("disk to_world", &xml, "floor.to_world", |_| t.clone(), 1e-3);
}

/// A wide cylinder whose side is the floor (its outline far outside the
/// image: only the interior term), moved, and turned about its own axis
/// (the surface stays in place, its uv and texture slide).
#[test]
fn cylinder_to_world() {
    let body = concat!(
        r#"<shape type="cylinder" id="floor">
            <point name="p0" x="-20" y="0" z="-20"/>
            <point name="p1" x="20" y="0" z="-20"/>
            <float name="radius" value="20"/>"#,
        textured_diffuse!(),
        r#"</shape>
        <emitter type="point">
            <point name="position" value="0.5, 0.5, 2"/>
            <rgb name="intensity" value="10"/>
        </emitter>"#
    );
    let xml = scene_xml(EMITTER_SAMPLING, &oblique_sensor(), body);
    let key = "floor.to_world";
    check(
        "cylinder to_world moved",
        &xml,
        key,
        |_| moved([0.5, -0.5, 1.0]),
        1e-3,
    );
    check(
        "cylinder to_world turned",
        &xml,
        key,
        |m| turn_about_local_axis(m, 2),
        1e-4,
    );
}

/// ⟨δI, dI/dθ·v⟩ (forward mode) against ⟨∂L/∂θ, v⟩ (reverse mode) with
/// L = ⟨δI, I⟩, same samples.
fn assert_forward_matches_reverse(name: &str, xml: &str, key: &str) {
    let scene = load(xml);
    let id = scene.params.require(key).unwrap();
    let n = scene.params.data(id).len();
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    let v: Vec<f32> = (0..n).map(|_| next()).collect();
    let pixels = (SIZE * SIZE * 3) as usize;
    let adjoint: Vec<f32> = (0..pixels).map(|_| next()).collect();
    let o = opts();
    let fwd = render_forward(&scene, &[(key, &v)], &o).unwrap().data;
    let lhs: f64 = fwd.iter().zip(&adjoint).map(|(a, b)| (a * b) as f64).sum();
    let grads = render_backward(&scene, &adjoint, Some(&[key]), &o).unwrap();
    let g = grads.get(key).unwrap();
    let rhs: f64 = g.iter().zip(&v).map(|(a, b)| (a * b) as f64).sum();
    let scale: f64 = fwd
        .iter()
        .zip(&adjoint)
        .map(|(a, b)| (a * b).abs() as f64)
        .sum();
    eprintln!("{name}: forward {lhs:.6}, reverse {rhs:.6} (scale {scale:.4})");
    assert!(scale > 1e-3, "{name}: no derivative at all");
    assert!(
        (lhs - rhs).abs() <= 1e-3 * scale,
        "{name}: forward {lhs}, reverse {rhs}, scale {scale}"
    );
}

#[test]
fn forward_and_reverse_mode_agree_for_every_geometry_parameter_kind() {
    let area = area_light_scene(&path_integrator(4), TEXTURED_RADIANCE);
    for key in [
        "plane.vertex_positions",
        "plane.vertex_texcoords",
        "light.vertex_positions",
        "light.emitter.radiance.data",
    ] {
        assert_forward_matches_reverse(key, &area, key);
    }
    let sphere = inside_sphere_xml(&path_integrator(4));
    for key in ["ball.center", "ball.radius", "ball.to_world"] {
        assert_forward_matches_reverse(key, &sphere, key);
    }
    let camera = camera_scene("perspective", "");
    for key in [
        "camera.to_world",
        "camera.x_fov",
        "plane.to_world",
        "lamp.position",
    ] {
        assert_forward_matches_reverse(key, &camera, key);
    }
}

/// The tangent of a row-major `to_world` M turning about its own (local)
/// axis `axis`: M · G, G the generator of rotations about that axis.
fn turn_about_local_axis(m: &[f32], axis: usize) -> Vec<f32> {
    let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut g = [[0.0f32; 3]; 3];
    g[b][a] = 1.0;
    g[a][b] = -1.0;
    let mut t = vec![0.0f32; 16];
    for r in 0..3 {
        for c in 0..3 {
            t[4 * r + c] = (0..3).map(|k| m[4 * r + k] * g[k][c]).sum();
        }
    }
    t
}

/// The tangent of a row-major `to_world` translating by `v`.
fn moved(v: [f32; 3]) -> Vec<f32> {
    let mut t = vec![0.0f32; 16];
    (t[3], t[7], t[11]) = (v[0], v[1], v[2]);
    t
}

#[test]
fn mesh_to_world() {
    let xml = area_light_scene(EMITTER_SAMPLING, CONSTANT_RADIANCE);
    let key = "plane.to_world";
    check(
        "plane to_world moved",
        &xml,
        key,
        |_| moved([0.3, 0.2, 1.0]),
        1e-3,
    );
    check(
        "plane to_world turned",
        &xml,
        key,
        |m| turn_about_local_axis(m, 0),
        1e-4,
    );
    let key = "light.to_world";
    check(
        "light to_world turned",
        &xml,
        key,
        |m| turn_about_local_axis(m, 1),
        1e-3,
    );
    // a mesh with vertex normals: they turn with the transform
    let xml = ply_plane_scene();
    check(
        "ply to_world turned",
        &xml,
        "plane.to_world",
        |m| turn_about_local_axis(m, 0),
        1e-4,
    );
}

/// A camera (id `camera`) of type `kind` at (0, −1.5, 3) looking at the
/// origin, over the textured plane lit by a point light (id `lamp`).
fn camera_scene(kind: &str, extra: &str) -> String {
    let light = r#"<emitter type="point" id="lamp">
            <point name="position" value="0.5, -0.5, 1.5"/>
            <rgb name="intensity" value="6"/>
        </emitter>"#;
    scene_xml(
        EMITTER_SAMPLING,
        &camera_sensor(kind, extra),
        &format!("{PLANE}{light}"),
    )
}

/// A camera (id `camera`) of type `kind` at (0, −1.5, 3) looking at the
/// origin.
fn camera_sensor(kind: &str, extra: &str) -> String {
    format!(
        r#"<sensor type="{kind}" id="camera">
            {extra}
            <transform name="to_world">
                <lookat origin="0, -1.5, 3" target="0, 0, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="{SIZE}"/>
                <integer name="height" value="{SIZE}"/>
                <rfilter type="box"/>
            </film>
        </sensor>"#
    )
}

#[test]
fn point_light_moved_over_a_plane() {
    let xml = camera_scene("perspective", r#"<float name="fov" value="40"/>"#);
    check(
        "point light moved",
        &xml,
        "lamp.position",
        |_| vec![0.3, 0.2, -0.4],
        1e-3,
    );
}

#[test]
fn camera_moved_in_front_of_a_plane_that_fills_the_view() {
    // row-major to_world: translation (x, y, z) and a rotation about the
    // camera's local y axis (d/dα of R_y(α) at 0, applied on the right)
    let translate = |_: &[f32]| {
        let mut t = vec![0.0f32; 16];
        (t[3], t[7], t[11]) = (0.7, 0.3, -0.5);
        t
    };
    let turn = |m: &[f32]| turn_about_local_axis(m, 1);
    let perspective = camera_scene("perspective", r#"<float name="fov" value="40"/>"#);
    check(
        "perspective moved",
        &perspective,
        "camera.to_world",
        translate,
        1e-3,
    );
    check(
        "perspective turned",
        &perspective,
        "camera.to_world",
        turn,
        1e-3,
    );
    check(
        "perspective x_fov",
        &perspective,
        "camera.x_fov",
        |_| vec![1.0],
        1e-2,
    );
    let thinlens = camera_scene(
        "thinlens",
        r#"<float name="fov" value="40"/>
           <float name="aperture_radius" value="0.1"/>
           <float name="focus_distance" value="3"/>"#,
    );
    check(
        "thin lens moved",
        &thinlens,
        "camera.to_world",
        translate,
        1e-3,
    );
    let ortho = camera_scene("orthographic", "");
    check(
        "orthographic moved",
        &ortho,
        "camera.to_world",
        translate,
        1e-3,
    );
}
