//! Camera derivatives against finite differences, and pose updates through
//! the parameter store against loading the pose from XML.

use crate::ad::Dual;
use crate::geometry::DiffRay;
use crate::integrator::{render, RenderOptions};
use crate::params::Seeds;
use crate::scene::Scene;
use glam::{Mat3, Vec2, Vec3};
use std::path::Path;

/// A lit sphere on a floor, seen by `sensor` (an XML `<sensor>` element).
fn scene(sensor: &str) -> Scene {
    Scene::load_str(
        &format!(
            r#"<scene version="3.0.0">
                {sensor}
                <shape type="sphere"><float name="radius" value="0.5"/></shape>
                <shape type="rectangle">
                    <transform name="to_world">
                        <rotate x="1" angle="-90"/><scale value="3"/><translate y="-0.5"/>
                    </transform>
                </shape>
                <emitter type="constant"/>
            </scene>"#
        ),
        Path::new("t.xml"),
        &[],
    )
    .unwrap()
}

/// A `<sensor>` of plugin `plugin` at `origin`, looking at the sphere,
/// with the extra properties `extra`.
fn sensor(plugin: &str, origin: &str, extra: &str) -> String {
    format!(
        r#"<sensor type="{plugin}" id="cam">
            {extra}
            <transform name="to_world">
                <lookat origin="{origin}" target="0, 0.2, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="12"/>
                <integer name="height" value="9"/>
            </film>
            <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        </sensor>"#
    )
}

fn perspective() -> Scene {
    perspective_at("1, 2, 3")
}

fn perspective_at(origin: &str) -> Scene {
    scene(&sensor(
        "perspective",
        origin,
        r#"<float name="fov" value="40"/>
           <float name="principal_point_offset_x" value="0.05"/>
           <float name="principal_point_offset_y" value="-0.1"/>"#,
    ))
}

fn thinlens() -> Scene {
    scene(&sensor(
        "thinlens",
        "1, 2, 3",
        r#"<float name="fov" value="40"/>
           <float name="aperture_radius" value="0.2"/>
           <float name="focus_distance" value="2.5"/>"#,
    ))
}

fn orthographic() -> Scene {
    // the scale makes the ray origins depend on every column of to_world
    let sensor = sensor("orthographic", "1, 2, 3", "");
    scene(&sensor.replace("<lookat", r#"<scale x="1.5" y="2" z="0.5"/><lookat"#))
}

/// Tangents of `<key>.to_world` (row-major 4×4): a translation, and the
/// first-order change of an infinitesimal rotation about an oblique axis
/// through the camera (W·M on the linear part, W skew-symmetric).
fn to_world_tangents(scene: &Scene) -> [Vec<f32>; 2] {
    let m = scene
        .params
        .data(scene.params.require("cam.to_world").unwrap());
    let mut translation = vec![0.0; 16];
    (translation[3], translation[7], translation[11]) = (1.0, -0.5, 0.25);
    let linear = Mat3::from_cols_array(&[m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10]]);
    let (ax, ay, az) = (0.3, 1.0, -0.2);
    let w = Mat3::from_cols(
        Vec3::new(0.0, az, -ay),
        Vec3::new(-az, 0.0, ax),
        Vec3::new(ay, -ax, 0.0),
    );
    let d = w * linear;
    let mut rotation = vec![0.0; 16];
    for r in 0..3 {
        for c in 0..3 {
            rotation[4 * r + c] = d.col(c)[r];
        }
    }
    [translation, rotation]
}

/// Film and lens positions spread over the film and the aperture.
const SAMPLES: [(Vec2, Vec2); 3] = [
    (Vec2::new(0.1, 0.2), Vec2::new(0.3, 0.8)),
    (Vec2::new(0.5, 0.5), Vec2::new(0.5, 0.5)),
    (Vec2::new(0.93, 0.71), Vec2::new(0.9, 0.15)),
];

/// Checks the forward-mode derivative of the rays of sensor 0 along
/// `tangent` of parameter `key` against central differences of the f32
/// rays, with step `h` (in units of the tangent).
///
/// Tolerance 1e-3 · max(1, |fd|): the truncation error of a central
/// difference is h²/6 · f''' ≈ 2e-5 for h = 1e-2 and ray components of
/// order one with O(1) curvature; f32 rounding adds about
/// ε·|f| / h ≈ 6e-8 · 4 / 1e-2 ≈ 2.5e-5. The bound leaves a factor of
/// ten over both, and a wrong chain rule (a dropped or doubled term) is
/// off by the size of the derivative itself, far above it.
fn check(scene: Scene, key: &str, tangent: &[f32], h: f32) {
    let id = scene.params.require(key).unwrap();
    let base = scene.params.data(id).to_vec();
    let seeds = Seeds::tangents(&scene.params, &[(key, tangent)]).unwrap();
    let shifted = |s: f32| {
        let mut store = scene.params.clone();
        let v: Vec<f32> = base.iter().zip(tangent).map(|(b, t)| b + s * t).collect();
        store.set(key, &v).unwrap();
        store
    };
    let (plus, minus) = (shifted(h), shifted(-h));
    let sensor = &scene.sensors[0];
    let mut largest = 0.0f32;
    for (film, lens) in SAMPLES {
        let ad: DiffRay<Dual> = sensor.ray(&scene.params.view(&seeds), film, lens);
        let primal = sensor.ray::<f32>(&scene.params.primal(), film, lens);
        assert_eq!(
            ad.val().o,
            primal.o.val(),
            "{key}: Dual and f32 primal differ"
        );
        assert_eq!(
            ad.val().d,
            primal.d.val(),
            "{key}: Dual and f32 primal differ"
        );
        // through Dual (no tangent): f32 rays read the sensor's copy of
        // the values of the last update, not a shifted store
        let (p, m) = (
            sensor.ray::<Dual>(&plus.primal(), film, lens).val(),
            sensor.ray::<Dual>(&minus.primal(), film, lens).val(),
        );
        for (what, a, p, m) in [("origin", ad.o, p.o, m.o), ("direction", ad.d, p.d, m.d)] {
            for (k, (a, (p, m))) in [a.x, a.y, a.z]
                .into_iter()
                .zip([p.x, p.y, p.z].into_iter().zip([m.x, m.y, m.z]))
                .enumerate()
            {
                let fd = (p - m) / (2.0 * h);
                let tol = 1e-3 * fd.abs().max(1.0);
                assert!(
                    (a.d - fd).abs() <= tol,
                    "{key} {tangent:?}: d {what}[{k}] at film {film}, lens {lens}: \
                     forward mode {}, central difference {fd}",
                    a.d
                );
                largest = largest.max(a.d.abs());
            }
        }
    }
    // the parameter does move the rays: the comparison is not 0 = 0
    assert!(largest > 1e-2, "{key}: derivatives all ~0 ({largest})");
}

#[test]
fn perspective_ray_derivatives_match_finite_differences() {
    let [translation, rotation] = to_world_tangents(&perspective());
    check(perspective(), "cam.to_world", &translation, 1e-2);
    check(perspective(), "cam.to_world", &rotation, 1e-2);
    check(perspective(), "cam.x_fov", &[10.0], 1e-2);
    check(perspective(), "cam.principal_point_offset_x", &[1.0], 1e-2);
    check(perspective(), "cam.principal_point_offset_y", &[1.0], 1e-2);
}

#[test]
fn thinlens_ray_derivatives_match_finite_differences() {
    let [translation, rotation] = to_world_tangents(&thinlens());
    check(thinlens(), "cam.to_world", &translation, 1e-2);
    check(thinlens(), "cam.to_world", &rotation, 1e-2);
    check(thinlens(), "cam.x_fov", &[10.0], 1e-2);
    check(thinlens(), "cam.aperture_radius", &[1.0], 1e-2);
    check(thinlens(), "cam.focus_distance", &[1.0], 1e-2);
}

#[test]
fn orthographic_ray_derivatives_match_finite_differences() {
    let [translation, rotation] = to_world_tangents(&orthographic());
    check(orthographic(), "cam.to_world", &translation, 1e-2);
    check(orthographic(), "cam.to_world", &rotation, 1e-2);
}

#[test]
fn sensor_keys_flags_and_domains() {
    let expect = |scene: &Scene, keys: &[(&str, &[usize])]| {
        let listed: Vec<&str> = scene
            .params
            .iter()
            .map(|(_, p)| p.key.as_str())
            .filter(|k| k.starts_with("cam."))
            .collect();
        let want: Vec<&str> = keys.iter().map(|(k, _)| *k).collect();
        assert_eq!(listed, want);
        for (key, shape) in keys {
            let p = scene.params.get(scene.params.require(key).unwrap());
            assert_eq!(p.shape, *shape, "{key}");
            assert!(p.flags.differentiable && p.flags.discontinuous, "{key}");
        }
    };
    let pinhole: &[(&str, &[usize])] = &[
        ("cam.to_world", &[4, 4]),
        ("cam.x_fov", &[1]),
        ("cam.principal_point_offset_x", &[1]),
        ("cam.principal_point_offset_y", &[1]),
    ];
    expect(&perspective(), pinhole);
    let lens = [
        &pinhole[..2],
        &[("cam.aperture_radius", &[1]), ("cam.focus_distance", &[1])],
    ]
    .concat();
    expect(&thinlens(), &lens);
    expect(&orthographic(), &[("cam.to_world", &[4, 4])]);
    let s = perspective();
    assert_eq!(
        s.params.data(s.params.require("cam.x_fov").unwrap()),
        [40.0]
    );
    // an unnamed sensor is keyed like other unnamed top-level objects
    let unnamed = scene(&sensor("perspective", "0, 0, 3", "").replace(r#" id="cam""#, ""));
    assert!(unnamed.params.id("_unnamed_0.x_fov").is_some());
}

#[test]
fn invalid_updates_name_the_key() {
    let mut s = perspective();
    s.params.set("cam.x_fov", &[180.0]).unwrap();
    let e = s.update().unwrap_err().to_string();
    assert!(e.contains("cam.x_fov") && e.contains("(0, 180)"), "{e}");
    let e = s.params.set("cam.x_fov", &[0.0]).unwrap_err().to_string();
    assert!(e.contains("cam.x_fov") && e.contains("> 0"), "{e}");
    let mut s = orthographic();
    let mut flat = s
        .params
        .data(s.params.require("cam.to_world").unwrap())
        .to_vec();
    flat[2] = 0.0;
    flat[6] = 0.0;
    flat[10] = 0.0;
    s.params.set("cam.to_world", &flat).unwrap();
    let e = s.update().unwrap_err().to_string();
    assert!(
        e.contains("cam.to_world") && e.contains("invertible"),
        "{e}"
    );
    let e = s
        .params
        .set("cam.to_world", &[f32::INFINITY; 16])
        .unwrap_err()
        .to_string();
    assert!(e.contains("cam.to_world"), "{e}");
}

/// Renders sensor 0 of `scene` at 4 spp, single-threaded, fixed seed.
fn image(scene: &Scene) -> Vec<f32> {
    let opts = RenderOptions {
        spp: Some(4),
        seed: 7,
        threads: Some(1),
        ..Default::default()
    };
    render(scene, &opts).unwrap().data
}

#[test]
fn setting_to_world_renders_as_loading_that_pose() {
    for plugin in ["perspective", "thinlens", "orthographic"] {
        let extra = if plugin == "thinlens" {
            r#"<float name="focus_distance" value="3"/>
               <float name="aperture_radius" value="0.03"/>"#
        } else {
            ""
        };
        let there = scene(&sensor(plugin, "-1, 1.5, 2.5", extra));
        let mut moved = scene(&sensor(plugin, "1, 2, 3", extra));
        let pose = there
            .params
            .data(there.params.require("cam.to_world").unwrap());
        assert_ne!(
            image(&moved),
            image(&there),
            "{plugin}: the poses look alike"
        );
        moved.params.set("cam.to_world", pose).unwrap();
        moved.update().unwrap();
        assert_eq!(image(&moved), image(&there), "{plugin}");
    }
}

#[test]
fn with_to_world_places_a_copy_that_ignores_the_parameter() {
    let mut s = perspective();
    let there = perspective_at("-1, 1.5, 2.5");
    let t = crate::math::Transform::look_at(
        Vec3::new(-1.0, 1.5, 2.5),
        Vec3::new(0.0, 0.2, 0.0),
        Vec3::Y,
    )
    .unwrap();
    s.sensors[0] = s.sensors[0].with_to_world(t);
    let seeds = Seeds::tangents(&s.params, &[("cam.to_world", &[1.0; 16])]).unwrap();
    let (film, lens) = SAMPLES[0];
    let ray: DiffRay<Dual> = s.sensors[0].ray(&s.params.view(&seeds), film, lens);
    let want = there.sensors[0].ray::<f32>(&there.params.primal(), film, lens);
    assert_eq!(ray.val().o, want.o.val());
    assert_eq!(ray.val().d, want.d.val());
    for c in [ray.o, ray.d] {
        assert_eq!([c.x.d, c.y.d, c.z.d], [0.0; 3]);
    }
}

/// The horizontal field of view of a 64 × 48 film for the `<sensor>`
/// properties `props`, or the load error.
fn x_fov(plugin: &str, props: &str) -> Result<f32, String> {
    let xml = format!(
        r#"<scene version="3.0.0">
            <sensor type="{plugin}" id="cam">
                {props}
                <film type="hdrfilm">
                    <integer name="width" value="64"/>
                    <integer name="height" value="48"/>
                </film>
            </sensor>
        </scene>"#
    );
    let s = Scene::load_str(&xml, Path::new("t.xml"), &[]).map_err(|e| e.to_string())?;
    Ok(s.params.data(s.params.require("cam.x_fov").unwrap())[0])
}

/// Mitsuba 3.9.1's `x_fov` for the same properties (read from `traverse()`
/// of a 64 × 48 film).
#[test]
fn field_of_view_matches_mitsuba() {
    for (props, want) in [
        // neither fov nor focal_length: a 50 mm lens on 35 mm film
        ("", 38.184_84),
        (r#"<string name="focal_length" value="35mm"/>"#, 52.622_543),
        (r#"<string name="focal_length" value="35"/>"#, 52.622_543),
        (r#"<float name="fov" value="40"/>"#, 40.0),
        (
            r#"<float name="fov" value="40"/><string name="fov_axis" value="Y"/>"#,
            51.774_01,
        ),
        (
            r#"<float name="fov" value="40"/><string name="fov_axis" value="smaller"/>"#,
            51.774_01,
        ),
        (
            r#"<float name="fov" value="40"/><string name="fov_axis" value="larger"/>"#,
            40.0,
        ),
    ] {
        for plugin in ["perspective", "thinlens"] {
            let props = if plugin == "thinlens" {
                format!(r#"{props}<float name="aperture_radius" value="0.1"/>"#)
            } else {
                props.to_string()
            };
            let got = x_fov(plugin, &props).unwrap();
            assert!(
                (got - want).abs() < 1e-4,
                "{plugin} {props}: {got} vs {want}"
            );
        }
    }
    // diagonal: the half-angle tangent of the diagonal is the x one
    // stretched by the diagonal over the width (5/4 for 4:3)
    let diag = x_fov(
        "perspective",
        r#"<float name="fov" value="60"/><string name="fov_axis" value="diagonal"/>"#,
    )
    .unwrap();
    let want = 2.0 * ((30f32.to_radians().tan()) * 0.8).atan().to_degrees();
    assert!((diag - want).abs() < 1e-4, "{diag} vs {want}");
}

/// What Mitsuba refuses is a clear error naming the parameter.
#[test]
fn field_of_view_errors_name_the_parameter() {
    for (plugin, props, words) in [
        (
            "perspective",
            r#"<float name="fov" value="40"/><string name="focal_length" value="35mm"/>"#,
            "not both",
        ),
        (
            "perspective",
            r#"<string name="focal_length" value="35mm"/><string name="fov_axis" value="y"/>"#,
            "'fov_axis'",
        ),
        (
            "perspective",
            r#"<string name="focal_length" value="long"/>"#,
            "'long'",
        ),
        (
            "perspective",
            r#"<float name="fov" value="190"/><string name="fov_axis" value="y"/>"#,
            "(0, 180)",
        ),
        (
            "perspective",
            r#"<string name="fov_axis" value="z"/><float name="fov" value="4"/>"#,
            "'z'",
        ),
        ("thinlens", "", "'aperture_radius'"),
        (
            "thinlens",
            r#"<float name="aperture_radius" value="0.1"/><float name="principal_point_offset_x" value="0.1"/>"#,
            "'principal_point_offset_x'",
        ),
    ] {
        let e = x_fov(plugin, props).unwrap_err();
        assert!(e.starts_with("t.xml:") && e.contains(words), "{props}: {e}");
    }
}

/// A thin lens without `focus_distance` focuses at `far_clip`, as
/// Mitsuba's does.
#[test]
fn thinlens_focuses_at_the_far_clip_by_default() {
    let xml = r#"<scene version="3.0.0">
            <sensor type="thinlens" id="cam">
                <float name="aperture_radius" value="0.1"/>
                <float name="far_clip" value="50"/>
            </sensor>
        </scene>"#;
    let s = Scene::load_str(xml, Path::new("t.xml"), &[]).unwrap();
    assert_eq!(
        s.params
            .data(s.params.require("cam.focus_distance").unwrap()),
        [50.0]
    );
}

/// A pixel's camera rays made in lanes are the f32 rays of each sample bit
/// for bit (the loop in lanes and the scalar loop start from the same
/// rays); other cameras do not make them.
#[test]
fn pinhole_rays_in_lanes_are_the_f32_rays() {
    let scene = perspective();
    let sensor = &scene.sensors[0];
    let store = scene.params.primal();
    let mut rng = crate::sampler::SampleStream::PLACEHOLDER;
    for _ in 0..64 {
        let film: [Vec2; 16] = std::array::from_fn(|_| rng.next_2d() * 1.2 - Vec2::splat(0.1));
        let mut rays = [crate::geometry::Ray::new(Vec3::ZERO, Vec3::Z); 16];
        assert!(sensor.pinhole_rays(&film, &mut rays));
        for (ray, film) in rays.iter().zip(film) {
            let expected = sensor.ray::<f32>(&store, film, Vec2::ZERO).val();
            assert_eq!(
                ray.o.to_array().map(f32::to_bits),
                expected.o.to_array().map(f32::to_bits)
            );
            assert_eq!(
                ray.d.to_array().map(f32::to_bits),
                expected.d.to_array().map(f32::to_bits)
            );
            assert_eq!(ray.tmin.to_bits(), expected.tmin.to_bits());
            assert_eq!(ray.tmax.to_bits(), expected.tmax.to_bits());
        }
    }
    let mut rays = [crate::geometry::Ray::new(Vec3::ZERO, Vec3::Z); 4];
    assert!(!thinlens().sensors[0].pinhole_rays(&[Vec2::ZERO; 4], &mut rays));
}
