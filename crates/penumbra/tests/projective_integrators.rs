//! Mitsuba's integrator names and their derivative budgets: `prb`,
//! `prb_basic` and `prb_projective` are the path integrator,
//! `direct_projective` the direct one with one emitter and one BSDF
//! sample; `sppc` and `sppp` are the budgets of the interior term and of
//! the boundary term of primary visibility, 0 turning a term off, and the
//! call's options override them.

use penumbra::diff::{render_backward, render_forward, translation_tangent};
use penumbra::integrator::{Budgets, Integrator, RenderOptions};
use penumbra::scene::Scene;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// A rectangle in front of a constant emitter, seen by a pinhole camera
/// (a 16² film, box filter, 4 samples per pixel), with `integrator`.
fn scene_xml(integrator: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
            {integrator}
            <sensor type="perspective">
                <float name="fov" value="40"/>
                <transform name="to_world">
                    <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
                </transform>
                <film type="hdrfilm">
                    <integer name="width" value="16"/>
                    <integer name="height" value="16"/>
                    <rfilter type="box"/>
                </film>
                <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
            </sensor>
            <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
            <shape type="rectangle" id="rect">
                <transform name="to_world">
                    <rotate z="1" angle="20"/>
                    <translate x="0.2" y="-0.1"/>
                </transform>
                <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.2, 0.2"/></bsdf>
            </shape>
        </scene>"#
    )
}

fn load(integrator: &str) -> penumbra::Result<Scene> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/inline-test.xml");
    Scene::load_str(&scene_xml(integrator), &path, &[])
}

fn integrator(xml: &str) -> Integrator {
    load(xml).unwrap_or_else(|e| panic!("{e}")).integrator
}

#[test]
fn mitsuba_names_load_with_mitsuba_defaults() {
    for name in ["prb", "prb_basic", "prb_projective"] {
        let Integrator::Path(p) = integrator(&format!(r#"<integrator type="{name}"/>"#)) else {
            panic!("{name} is the path integrator");
        };
        assert_eq!(p.max_depth, 6, "{name}: Mitsuba's default max_depth");
        assert_eq!(p.rr_depth, 5);
        assert_eq!(p.budgets, Budgets::default());
    }
    let Integrator::Path(p) = integrator(r#"<integrator type="path"/>"#) else {
        panic!("path");
    };
    assert_eq!(p.max_depth, u32::MAX, "Mitsuba's path is unbounded");

    let Integrator::Path(p) = integrator(
        r#"<integrator type="prb_projective">
            <integer name="max_depth" value="3"/>
            <integer name="rr_depth" value="2"/>
            <boolean name="hide_emitters" value="true"/>
            <integer name="sppc" value="8"/>
            <integer name="sppp" value="0"/>
            <integer name="sppi" value="0"/>
        </integrator>"#,
    ) else {
        panic!("prb_projective");
    };
    assert_eq!((p.max_depth, p.rr_depth, p.hide_emitters), (3, 2, true));
    assert_eq!(
        p.budgets,
        Budgets {
            sppc: Some(8),
            sppp: Some(0),
            sppi: Some(0)
        }
    );

    let Integrator::Direct(d) = integrator(
        r#"<integrator type="direct_projective">
            <integer name="sppp" value="16"/>
            <boolean name="hide_emitters" value="true"/>
        </integrator>"#,
    ) else {
        panic!("direct_projective is the direct integrator");
    };
    assert_eq!((d.emitter_samples, d.bsdf_samples), (1, 1));
    assert!(d.hide_emitters);
    assert_eq!(
        d.budgets,
        Budgets {
            sppc: None,
            sppp: Some(16),
            sppi: None
        }
    );
}

#[test]
fn unknown_and_invalid_properties_are_errors_naming_them() {
    let cases = [
        // a typo
        (
            r#"<integrator type="prb_projective"><integer name="spp_p" value="4"/></integrator>"#,
            "unknown parameter 'spp_p'",
        ),
        // Mitsuba's direct_projective has no per-hit sample counts
        (
            r#"<integrator type="direct_projective"><integer name="emitter_samples" value="2"/></integrator>"#,
            "unknown parameter 'emitter_samples'",
        ),
        // budgets belong to the projective integrators
        (
            r#"<integrator type="path"><integer name="sppp" value="4"/></integrator>"#,
            "unknown parameter 'sppp'",
        ),
        (
            r#"<integrator type="prb"><integer name="sppc" value="4"/></integrator>"#,
            "unknown parameter 'sppc'",
        ),
        (
            r#"<integrator type="direct_projective"><integer name="sppp" value="-1"/></integrator>"#,
            "parameter 'sppp': must be >= 0, found -1",
        ),
        (
            r#"<integrator type="prb_projective"><integer name="sppi" value="-2"/></integrator>"#,
            "parameter 'sppi': must be >= 0, found -2",
        ),
        (
            r#"<integrator type="prb_projective"><string name="guiding" value="tree"/></integrator>"#,
            "'tree' is not one of: octree, grid, none",
        ),
        (
            r#"<integrator type="direct_projective"><string name="project_seed" value="x"/></integrator>"#,
            "'x' is not one of: both, bsdf, emitter",
        ),
    ];
    for (xml, expected) in cases {
        let e = load(xml).unwrap_err().to_string();
        assert!(e.contains(expected), "{xml}: {e}");
    }
}

/// Accepted properties that change nothing are warned about once per
/// load, naming them: a positive `sppi` (the indirect term is not
/// implemented), the guiding options, and `max_depth` ≠ 2, `rr_depth`,
/// `project_seed` of `direct_projective`. Budgets that are honoured are
/// not.
#[test]
fn ignored_properties_are_warned_about() {
    let seen = Arc::new(Mutex::new(Vec::<String>::new()));
    let sink = seen.clone();
    penumbra::warn::set_warning_sink(Some(Arc::new(move |m: &str| {
        sink.lock().unwrap().push(m.to_string())
    })));
    let warnings_of = |xml: &str| -> Vec<String> {
        seen.lock().unwrap().clear();
        load(xml).unwrap_or_else(|e| panic!("{e}"));
        // other tests of this binary warn too (about their derivatives)
        seen.lock()
            .unwrap()
            .iter()
            .filter(|m| m.starts_with("integrator"))
            .cloned()
            .collect()
    };
    let w = warnings_of(
        r#"<integrator type="prb_projective"><integer name="sppi" value="64"/></integrator>"#,
    );
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("sppi = 64") && w[0].contains("indirect visibility"),
        "{w:?}"
    );
    assert!(w[0].contains("not implemented yet"), "{w:?}");

    let w = warnings_of(
        r#"<integrator type="direct_projective">
            <string name="guiding" value="grid"/>
            <integer name="guiding_rounds" value="2"/>
            <integer name="max_depth" value="4"/>
            <string name="project_seed" value="bsdf"/>
        </integrator>"#,
    );
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w[0].contains("guiding, guiding_rounds ignored"), "{w:?}");
    assert!(w[1].contains("max_depth, project_seed ignored"), "{w:?}");

    for quiet in [
        r#"<integrator type="prb_projective">
            <integer name="sppc" value="4"/><integer name="sppp" value="4"/>
            <integer name="sppi" value="0"/>
        </integrator>"#,
        r#"<integrator type="direct_projective"><integer name="max_depth" value="2"/></integrator>"#,
    ] {
        let w = warnings_of(quiet);
        assert!(w.is_empty(), "{quiet}: {w:?}");
    }
    penumbra::warn::set_warning_sink(None);
}

const KEY: &str = "rect.vertex_positions";
const REFLECTANCE: &str = "rect.bsdf.reflectance.value";

/// The derivative image along a translation of the rectangle and a change
/// of its reflectance (so that both terms are non-zero).
fn derivative(scene: &Scene, opts: &RenderOptions) -> Vec<f32> {
    let t = translation_tangent(scene, KEY, [1.0, 0.5, 0.0]).unwrap();
    let r = [1.0f32, 1.0, 1.0];
    render_forward(scene, &[(KEY, &t), (REFLECTANCE, &r)], opts)
        .unwrap()
        .data
}

fn projective(budgets: &str) -> Scene {
    load(&format!(
        r#"<integrator type="direct_projective">{budgets}</integrator>"#
    ))
    .unwrap()
}

/// `sppp = 0` on the integrator leaves exactly the interior term, `sppc =
/// 0` exactly the boundary term, and the two add up to the default; the
/// call's `spp` and `sppp` override the integrator's budgets.
#[test]
fn budgets_turn_terms_off_and_calls_override_them() {
    let opts = RenderOptions {
        seed: 7,
        ..Default::default()
    };
    let full = derivative(&projective(""), &opts);
    let interior = derivative(&projective(r#"<integer name="sppp" value="0"/>"#), &opts);
    let boundary = derivative(&projective(r#"<integer name="sppc" value="0"/>"#), &opts);

    // the interior-only image: the same estimator without its boundary
    // term, asked for by the call
    let direct = load(
        r#"<integrator type="direct">
            <integer name="emitter_samples" value="1"/>
            <integer name="bsdf_samples" value="1"/>
        </integrator>"#,
    )
    .unwrap();
    let no_boundary = RenderOptions {
        sppp: Some(0),
        ..opts.clone()
    };
    assert_eq!(interior, derivative(&direct, &no_boundary));
    assert_eq!(full, derivative(&direct, &opts));

    let max = |v: &[f32]| v.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    assert!(max(&interior) > 0.0 && max(&boundary) > 0.0);
    assert_ne!(interior, full, "the boundary term contributes");
    let tol = 1e-5 * max(&full);
    for ((f, i), b) in full.iter().zip(&interior).zip(&boundary) {
        assert!((f - (i + b)).abs() <= tol, "{f} != {i} + {b}");
    }

    // the call's budgets win over the integrator's
    let with_sppp = RenderOptions {
        sppp: Some(4),
        ..opts.clone()
    };
    let off = projective(r#"<integer name="sppp" value="0"/>"#);
    assert_eq!(derivative(&off, &with_sppp), full);
    let with_spp = RenderOptions {
        spp: Some(4),
        ..opts.clone()
    };
    let no_interior = projective(r#"<integer name="sppc" value="0"/>"#);
    assert_eq!(derivative(&no_interior, &with_spp), full);
    // sppc sets the interior samples when the call gives none
    let sppc8 = projective(r#"<integer name="sppc" value="8"/><integer name="sppp" value="0"/>"#);
    let spp8 = RenderOptions {
        spp: Some(8),
        sppp: Some(0),
        ..opts.clone()
    };
    assert_eq!(derivative(&sppc8, &opts), derivative(&direct, &spp8));
}

/// Reverse mode honours `sppc = 0` too: no interior term, zero gradients.
#[test]
fn sppc_zero_leaves_reverse_mode_gradients_zero() {
    let scene = projective(r#"<integer name="sppc" value="0"/>"#);
    let ones = vec![1.0f32; 16 * 16 * 3];
    let g = render_backward(&scene, &ones, Some(&[REFLECTANCE]), &Default::default()).unwrap();
    assert_eq!(g.get(REFLECTANCE).unwrap(), &[0.0; 3]);
    let scene = projective("");
    let g = render_backward(&scene, &ones, Some(&[REFLECTANCE]), &Default::default()).unwrap();
    assert!(g.get(REFLECTANCE).unwrap().iter().all(|&v| v > 0.0));
}
