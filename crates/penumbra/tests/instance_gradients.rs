//! Derivatives through instances (`shapegroup` / `instance`): finite
//! differences with identical random numbers vs forward mode vs reverse
//! mode, as tests/check_grad.rs checks every other parameter kind.
//!
//! - A material of a group's shape, seen through two instances (one
//!   turned and scaled unevenly): both instances' contributions sum.
//! - A group's mesh moved along its normal (its vertex positions): the
//!   interior term, through an instance that fills the view, where no
//!   edge moves in the image; the warning names the boundary terms of
//!   instanced edges, which are not estimated.
//! - An instance's `to_world` is not differentiable (as Mitsuba 3.9's
//!   traverse flags it): a clear error, never a silent zero.

use penumbra::diff::{check_gradient, translation_tangent, CheckOptions, CheckReport};
use penumbra::scene::Scene;
use std::path::Path;
use std::sync::{Arc, Mutex};

const HEADER: &str = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="16"/><integer name="height" value="16"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <emitter type="point" id="bulb">
        <point name="position" x="1" y="1.5" z="3"/>
        <rgb name="intensity" value="8, 8, 8"/>
    </emitter>"#;

/// A group of a backdrop panel and a rough metal ball, instanced twice.
fn materials_scene() -> Scene {
    let xml = format!(
        r#"{HEADER}
    <emitter type="constant"><rgb name="radiance" value="0.3, 0.35, 0.4"/></emitter>
    <shape type="shapegroup" id="g">
        <shape type="rectangle" id="panel">
            <transform name="to_world"><scale value="0.8"/></transform>
            <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="0.6, 0.3, 0.2"/></bsdf>
        </shape>
        <shape type="sphere" id="ball">
            <point name="center" x="0" y="0" z="0.5"/>
            <float name="radius" value="0.4"/>
            <bsdf type="roughconductor" id="metal"><float name="alpha" value="0.3"/></bsdf>
        </shape>
    </shape>
    <shape type="instance" id="left"><ref id="g"/>
        <transform name="to_world"><translate x="-0.8"/></transform>
    </shape>
    <shape type="instance" id="right"><ref id="g"/>
        <transform name="to_world"><scale x="0.7" y="1.2"/><rotate z="1" angle="30"/>
            <translate x="0.8" z="-0.3"/></transform>
    </shape>
</scene>"#
    );
    Scene::load_str(&xml, Path::new("instance_materials.xml"), &[]).unwrap()
}

/// One instance of a group's panel that fills the view (turned and scaled
/// unevenly), lit by a point light: moving the panel along its normal
/// moves no edge in the image.
fn panel_scene() -> Scene {
    let xml = format!(
        r#"{HEADER}
    <shape type="shapegroup" id="g">
        <shape type="rectangle" id="panel">
            <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="0.6, 0.3, 0.2"/></bsdf>
        </shape>
    </shape>
    <shape type="instance" id="wall"><ref id="g"/>
        <transform name="to_world"><scale x="4" y="2"/><rotate z="1" angle="20"/>
            <rotate x="1" angle="15"/></transform>
    </shape>
</scene>"#
    );
    Scene::load_str(&xml, Path::new("instance_panel.xml"), &[]).unwrap()
}

/// Checks `key` at `spp` samples per pixel as tests/check_grad.rs does: forward and reverse mode
/// differentiate the same estimate (agree to rounding), finite
/// differences agree within 4.5 combined standard errors (12 batches).
fn check(scene: &mut Scene, key: &str, spp: u32, tangent: Option<Vec<f32>>) -> CheckReport {
    let opts = CheckOptions {
        spp,
        batches: 12,
        eps: 1e-2,
        tangent,
        ..Default::default()
    };
    let r = check_gradient(scene, key, &opts).unwrap();
    let (fd, fw, rv) = (r.finite_differences, r.forward, r.reverse);
    eprintln!(
        "{key}: fd {:.5e} ± {:.1e}, forward {:.5e} ± {:.1e}, reverse {:.5e}",
        fd.mean, fd.std_err, fw.mean, fw.std_err, rv.mean
    );
    assert!(fw.mean != 0.0, "{key}: zero derivative (proves nothing)");
    assert!(
        (fw.mean - rv.mean).abs() <= 1e-3 * fw.mean.abs(),
        "{key}: forward {} and reverse {} differentiate the same estimate",
        fw.mean,
        rv.mean
    );
    let z = fw.z_score(&fd);
    assert!(
        z < 4.5,
        "{key}: forward {fw:?} vs finite differences {fd:?} (z = {z:.2})"
    );
    r
}

#[test]
fn materials_of_group_shapes_through_instances() {
    let mut scene = materials_scene();
    for key in ["paint.reflectance.value", "metal.alpha.value"] {
        check(&mut scene, key, 16, None);
    }
}

#[test]
fn group_geometry_has_its_interior_term_and_a_named_warning() {
    let warnings = Arc::new(Mutex::new(Vec::<String>::new()));
    let sink = warnings.clone();
    penumbra::warn::set_warning_sink(Some(Arc::new(move |m: &str| {
        sink.lock().unwrap().push(m.to_string())
    })));
    let mut scene = panel_scene();
    // along the panel's normal in the group's space (+z)
    let t = translation_tangent(&scene, "g.panel.vertex_positions", [0.0, 0.0, 0.3]).unwrap();
    check(&mut scene, "g.panel.vertex_positions", 4, Some(t));
    penumbra::warn::set_warning_sink(None);
    let w = warnings.lock().unwrap();
    assert!(
        w.iter()
            .any(|m| m.contains("g.panel.vertex_positions") && m.contains("instanced shapes")),
        "{w:?}"
    );

    // an instance's to_world is not differentiable, as in Mitsuba 3.9
    let e = check_gradient(&mut scene, "wall.to_world", &CheckOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("wall.to_world") && e.contains("not differentiable"),
        "{e}"
    );
    let e = penumbra::diff::render_forward(
        &scene,
        &[("wall.to_world", &[1.0f32; 16][..])],
        &Default::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("wall.to_world") && e.contains("not differentiable"),
        "{e}"
    );
}
