//! Samples with a NaN or infinite value are left out of images and
//! gradients, counted, and reported once per pass, in the primal render,
//! forward mode and reverse mode.
//!
//! The scene makes them: a white diffuse sphere in an environment of
//! radiance 3e38 (the largest f32 is 3.4e38). A camera ray that escapes
//! carries 3e38, finite; one that hits the sphere gets, from next-event
//! estimation, Le · f · cos / pdf = 3e38 · (1/π) · cos · 4π, which
//! overflows f32 for cos > 0.28.

use crate::common;

use penumbra::diff::{render_backward, render_forward};
use penumbra::integrator::{render, RenderOptions};
use penumbra::scene::Scene;
use std::path::Path;

fn scene(radiance: &str) -> Scene {
    let sensor = common::sensor_xml("0, 0, 4", 30.0, 16, 4, None);
    let xml = format!(
        r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="2"/></integrator>
            {sensor}
            <bsdf type="diffuse" id="white"><rgb name="reflectance" value="1, 1, 1"/></bsdf>
            <shape type="sphere"><ref id="white"/></shape>
            <emitter type="constant" id="env"><rgb name="radiance" value="{radiance}"/></emitter>
        </scene>"#
    );
    Scene::load_str(&xml, Path::new("non_finite.xml"), &[]).unwrap()
}

/// (primal, forward, reverse) counts of non-finite samples, with checks
/// that what was kept is finite.
fn counts(radiance: &str) -> (usize, usize, usize) {
    let s = scene(radiance);
    let opts = RenderOptions {
        seed: 5,
        ..Default::default()
    };
    let img = render(&s, &opts).unwrap();
    assert!(img.data.iter().all(|v| v.is_finite()));
    let key = "white.reflectance.value";
    let fwd = render_forward(&s, &[(key, &[1.0, 1.0, 1.0])], &opts).unwrap();
    assert!(fwd.data.iter().all(|v| v.is_finite()));
    // a small adjoint, so that the sum of the kept (finite, up to 1e38)
    // contributions stays within f32
    let adjoint = vec![1e-30f32; img.width * img.height * 3];
    let g = render_backward(&s, &adjoint, Some(&[key]), &opts).unwrap();
    assert!(g.get(key).unwrap().iter().all(|v| v.is_finite()));
    // (reverse mode by the radiance, in lanes too: the same samples left
    // out)
    let env = "env.radiance.value";
    let g_env = render_backward(&s, &adjoint, Some(&[env]), &opts).unwrap();
    assert!(g_env.get(env).unwrap().iter().all(|v| v.is_finite()));
    assert_eq!(g_env.non_finite_samples, g.non_finite_samples);
    (
        img.non_finite_samples,
        fwd.non_finite_samples,
        g.non_finite_samples,
    )
}

#[test]
fn non_finite_samples_are_counted_in_every_pass() {
    let (primal, forward, reverse) = counts("3e38, 3e38, 3e38");
    eprintln!("non-finite samples: primal {primal}, forward {forward}, reverse {reverse}");
    // the sphere covers about a third of the 16×16×4 samples
    for n in [primal, forward, reverse] {
        assert!(n > 50 && n < 1024, "{primal} {forward} {reverse}");
    }
    assert_eq!(counts("1, 1, 1"), (0, 0, 0));
}
