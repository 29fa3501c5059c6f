//! Finite differences (identical random numbers) vs forward mode vs reverse
//! mode (path replay), for every kind of differentiable parameter: diffuse
//! reflectance, bitmap texels, mesh attributes, roughness, conductor η and
//! k, specular reflectance, area / constant / envmap / point emission,
//! every parameter of the principled and thin principled BSDFs, and the
//! normal map, height map and scale of `normalmap` and `bumpmap`.
//!
//! Forward and reverse mode differentiate the very same estimate, so they
//! must agree to rounding. Finite differences are an independent estimate
//! of the same derivative; they must agree within their combined Monte Carlo
//! standard error (over 12 independent batches). The same holds with every
//! sampler: path replay must regenerate the primal's samples.

use penumbra::diff::{check_gradient, CheckOptions, CheckReport};
use penumbra::image::{write_exr, Image};
use penumbra::sampler::{LowDiscrepancy, Multijitter, Orthogonal, Sampler};
use penumbra::scene::Scene;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const HEADER: &str = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 2.5, 4" target="0, 0.3, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="24"/><integer name="height" value="24"/>
            <rfilter type="box"/>
        </film>
    </sensor>"#;

fn surfaces_scene() -> Scene {
    let tex = repo().join("scenes/textures/texture.exr");
    let xml = format!(
        r#"{HEADER}
    <shape type="rectangle" id="floor">
        <transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse">
            <texture type="bitmap" name="reflectance">
                <string name="filename" value="{}"/>
            </texture>
        </bsdf>
    </shape>
    <shape type="sphere" id="ball">
        <point name="center" x="-0.6" y="0.5" z="0"/>
        <float name="radius" value="0.5"/>
        <bsdf type="roughconductor" id="metal">
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.25"/>
            <rgb name="eta" value="0.2, 0.9, 1.1"/>
            <rgb name="k" value="3.9, 2.4, 1.6"/>
            <rgb name="specular_reflectance" value="0.9, 0.8, 0.7"/>
        </bsdf>
    </shape>
    <shape type="sphere" id="matte">
        <point name="center" x="0.7" y="0.4" z="0.3"/>
        <float name="radius" value="0.4"/>
        <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="0.6, 0.3, 0.2"/></bsdf>
    </shape>
    <shape type="rectangle" id="light">
        <transform name="to_world"><scale value="0.5"/><lookat origin="1, 3, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
    <emitter type="point" id="bulb">
        <point name="position" x="-1.5" y="2" z="1.5"/>
        <rgb name="intensity" value="4, 5, 6"/>
    </emitter>
    <emitter type="constant" id="sky"><rgb name="radiance" value="0.3, 0.35, 0.4"/></emitter>
</scene>"#,
        tex.display()
    );
    Scene::load_str(&xml, Path::new("surfaces.xml"), &[]).unwrap()
}

fn envmap_scene() -> Scene {
    // a small synthetic environment map with a bright spot
    let (w, h) = (16, 8);
    let mut img = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let spot = if (x, y) == (5, 2) { 20.0 } else { 0.0 };
            for c in 0..3 {
                img.set(x, y, c, 0.2 + 0.05 * (x + c) as f32 / w as f32 + spot);
            }
        }
    }
    let path = std::env::temp_dir().join(format!("penumbra-envmap-{}.exr", std::process::id()));
    write_exr(&path, &img, &["R", "G", "B"]).unwrap();
    let xml = format!(
        r#"{HEADER}
    <shape type="sphere" id="ball">
        <float name="radius" value="0.8"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>
    </shape>
    <emitter type="envmap" id="sky"><string name="filename" value="{}"/></emitter>
</scene>"#,
        path.display()
    );
    Scene::load_str(&xml, Path::new("envmap.xml"), &[]).unwrap()
}

/// Two principled spheres (one with every reflection lobe, one
/// transmitting) and a thin principled sheet behind them, in the surfaces
/// scene's light.
fn principled_scene() -> Scene {
    let xml = format!(
        r#"{HEADER}
    <shape type="rectangle" id="floor">
        <transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"/>
    </shape>
    <shape type="sphere" id="ball">
        <point name="center" x="-0.6" y="0.5" z="0"/>
        <float name="radius" value="0.5"/>
        <bsdf type="principled" id="lobes">
            <rgb name="base_color" value="0.8, 0.4, 0.2"/>
            <float name="roughness" value="0.4"/>
            <float name="metallic" value="0.3"/>
            <float name="specular" value="0.6"/>
            <float name="spec_tint" value="0.5"/>
            <float name="anisotropic" value="0.5"/>
            <float name="sheen" value="0.7"/>
            <float name="sheen_tint" value="0.4"/>
            <float name="clearcoat" value="0.6"/>
            <float name="clearcoat_gloss" value="0.3"/>
            <float name="flatness" value="0.3"/>
        </bsdf>
    </shape>
    <shape type="sphere" id="glass">
        <point name="center" x="0.7" y="0.4" z="0.3"/>
        <float name="radius" value="0.4"/>
        <bsdf type="principled" id="clear">
            <rgb name="base_color" value="0.6, 0.8, 0.9"/>
            <float name="roughness" value="0.3"/>
            <float name="spec_trans" value="0.7"/>
            <float name="eta" value="1.45"/>
        </bsdf>
    </shape>
    <shape type="rectangle" id="sheet">
        <transform name="to_world"><scale x="0.6" y="0.4"/><translate y="0.5" z="-0.9"/></transform>
        <bsdf type="principledthin" id="thin">
            <rgb name="base_color" value="0.9, 0.6, 0.3"/>
            <float name="roughness" value="0.35"/>
            <float name="anisotropic" value="0.4"/>
            <float name="spec_trans" value="0.4"/>
            <float name="diff_trans" value="0.8"/>
            <float name="eta" value="1.4"/>
            <float name="spec_tint" value="0.5"/>
            <float name="sheen" value="0.6"/>
            <float name="sheen_tint" value="0.5"/>
            <float name="flatness" value="0.3"/>
        </bsdf>
    </shape>
    <shape type="rectangle" id="light">
        <transform name="to_world"><scale value="0.5"/><lookat origin="1, 3, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
    <emitter type="constant" id="sky"><rgb name="radiance" value="0.3, 0.35, 0.4"/></emitter>
</scene>"#
    );
    Scene::load_str(&xml, Path::new("principled.xml"), &[]).unwrap()
}

fn check(scene: &mut Scene, key: &str) -> CheckReport {
    let opts = CheckOptions {
        spp: 4,
        batches: 12,
        eps: 1e-2,
        ..Default::default()
    };
    let r = check_gradient(scene, key, &opts).unwrap();
    let (fd, fw, rv) = (r.finite_differences, r.forward, r.reverse);
    eprintln!(
        "{key}: fd {:.5e} ± {:.1e}, forward {:.5e} ± {:.1e}, reverse {:.5e}",
        fd.mean, fd.std_err, fw.mean, fw.std_err, rv.mean
    );
    assert!(
        fw.mean != 0.0,
        "{key}: zero derivative (the test would prove nothing)"
    );
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
fn surface_and_emitter_parameters() {
    let mut scene = surfaces_scene();
    for key in [
        "paint.reflectance.value",
        "floor.bsdf.reflectance.data",
        "metal.alpha.value",
        "metal.eta.value",
        "metal.k.value",
        "metal.specular_reflectance.value",
        "light.emitter.radiance.value",
        "bulb.intensity.value",
        "sky.radiance.value",
    ] {
        check(&mut scene, key);
    }
}

/// A scene the path tracer renders in lanes (cbox: meshes, `diffuse`
/// BSDFs, an area light), whose reverse mode by these parameters runs in
/// lanes too: `check_gradient` puts its finite differences, forward and
/// reverse mode on the one scalar loop, so that forward and reverse mode
/// differentiate the same estimate (the loop in lanes estimates the image
/// with other directions for the same random numbers).
#[test]
fn scenes_in_lanes_are_checked_on_one_loop() {
    let defines = [
        ("res".to_string(), "24".to_string()),
        ("max_depth".to_string(), "4".to_string()),
    ];
    let mut scene = Scene::load_file(&repo().join("scenes/cbox.xml"), &defines).unwrap();
    for key in ["red.reflectance.value", "light.emitter.radiance.value"] {
        check(&mut scene, key);
    }
}

/// A `pplastic` sphere (anisotropic roughness) and a rectangle (a
/// textured diffuse reflectance) under an area light and a point light.
fn pplastic_scene() -> Scene {
    let tex = repo().join("scenes/textures/texture.exr");
    let xml = format!(
        r#"{HEADER}
    <shape type="sphere">
        <point name="center" x="-0.4" y="0.5" z="0"/>
        <float name="radius" value="0.6"/>
        <bsdf type="pplastic" id="coat">
            <string name="distribution" value="ggx"/>
            <float name="alpha_u" value="0.15"/>
            <float name="alpha_v" value="0.3"/>
            <rgb name="diffuse_reflectance" value="0.3, 0.5, 0.7"/>
            <rgb name="specular_reflectance" value="0.9, 0.8, 0.7"/>
            <float name="int_ior" value="1.6"/>
        </bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.6"/><translate x="0.8" y="0.5" z="-0.3"/></transform>
        <bsdf type="pplastic" id="tile">
            <texture type="bitmap" name="diffuse_reflectance">
                <string name="filename" value="{}"/>
            </texture>
            <float name="alpha" value="0.2"/>
        </bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.5"/><lookat origin="1, 3, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
    <emitter type="point">
        <point name="position" x="-1.5" y="2" z="1.5"/>
        <rgb name="intensity" value="4, 5, 6"/>
    </emitter>
</scene>"#,
        tex.display()
    );
    Scene::load_str(&xml, Path::new("pplastic.xml"), &[]).unwrap()
}

#[test]
fn pplastic_parameters() {
    let mut scene = pplastic_scene();
    for key in [
        "coat.alpha_u",
        "coat.alpha_v",
        "coat.eta",
        "coat.diffuse_reflectance.value",
        "coat.specular_reflectance.value",
        "tile.diffuse_reflectance.data",
        "tile.alpha",
    ] {
        check(&mut scene, key);
    }
}

/// A floor coloured by its PLY vertex colours and an octahedron by its
/// per-face colours (the conformance set's meshes), through
/// `mesh_attribute` textures.
fn mesh_attribute_scene() -> Scene {
    let assets = repo().join("scenes/conformance/assets");
    let xml = format!(
        r#"{HEADER}
    <shape type="ply" id="floor">
        <string name="filename" value="{}"/>
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
        <bsdf type="diffuse">
            <texture type="mesh_attribute" name="reflectance">
                <string name="name" value="vertex_color"/>
            </texture>
        </bsdf>
    </shape>
    <shape type="ply" id="gem">
        <string name="filename" value="{}"/>
        <transform name="to_world"><scale value="0.6"/><translate y="0.6"/></transform>
        <bsdf type="diffuse">
            <texture type="mesh_attribute" name="reflectance">
                <string name="name" value="face_color"/>
            </texture>
        </bsdf>
    </shape>
    <emitter type="constant" id="sky"><rgb name="radiance" value="0.8, 0.85, 0.9"/></emitter>
</scene>"#,
        assets.join("vertex_color.ply").display(),
        assets.join("face_color.ply").display()
    );
    Scene::load_str(&xml, Path::new("mesh_attribute.xml"), &[]).unwrap()
}

#[test]
fn mesh_attributes() {
    let mut scene = mesh_attribute_scene();
    for key in ["floor.vertex_color", "gem.face_color"] {
        check(&mut scene, key);
    }
}

#[test]
fn envmap_texels() {
    let mut scene = envmap_scene();
    check(&mut scene, "sky.data");
}

#[test]
fn principled_parameters() {
    let mut scene = principled_scene();
    for key in [
        "lobes.base_color.value",
        "lobes.roughness.value",
        "lobes.metallic.value",
        "lobes.specular",
        "lobes.spec_tint.value",
        "lobes.anisotropic.value",
        "lobes.sheen.value",
        "lobes.sheen_tint.value",
        "lobes.clearcoat.value",
        "lobes.clearcoat_gloss.value",
        "lobes.flatness.value",
        "clear.spec_trans.value",
        "clear.eta",
        "thin.base_color.value",
        "thin.roughness.value",
        "thin.anisotropic.value",
        "thin.spec_trans.value",
        "thin.diff_trans.value",
        "thin.eta.value",
        "thin.spec_tint.value",
        "thin.sheen.value",
        "thin.sheen_tint.value",
        "thin.flatness.value",
    ] {
        check(&mut scene, key);
    }
}

/// A normal-mapped roughconductor sphere and a bump-mapped diffuse floor
/// (the conformance set's textures), in the surfaces scene's light.
fn perturbed_normals_scene() -> Scene {
    let assets = repo().join("scenes/conformance/assets");
    let xml = format!(
        r#"{HEADER}
    <shape type="rectangle" id="floor">
        <transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="bumpmap" id="bumps">
            <texture type="bitmap" name="height">
                <string name="filename" value="{}"/>
                <boolean name="raw" value="true"/>
            </texture>
            <float name="scale" value="0.05"/>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf>
        </bsdf>
    </shape>
    <shape type="sphere" id="ball">
        <point name="center" x="0" y="0.6" z="0"/>
        <float name="radius" value="0.6"/>
        <bsdf type="normalmap" id="dents">
            <texture type="bitmap" name="normalmap">
                <string name="filename" value="{}"/>
                <boolean name="raw" value="true"/>
            </texture>
            <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf>
        </bsdf>
    </shape>
    <shape type="rectangle" id="light">
        <transform name="to_world"><scale value="0.5"/><lookat origin="1, 3, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
    <emitter type="constant" id="sky"><rgb name="radiance" value="0.3, 0.35, 0.4"/></emitter>
</scene>"#,
        assets.join("heightmap.png").display(),
        assets.join("normalmap.png").display()
    );
    Scene::load_str(&xml, Path::new("perturbed_normals.xml"), &[]).unwrap()
}

#[test]
fn normal_and_bump_map_parameters() {
    let mut scene = perturbed_normals_scene();
    for key in [
        "dents.normalmap.data",
        "dents.nested_bsdf.alpha.value",
        "bumps.nested_texture.data",
        "bumps.scale",
        "bumps.nested_bsdf.reflectance.value",
    ] {
        check(&mut scene, key);
    }
}

/// Path replay with the stratified samplers: reverse mode regenerates the
/// primal's samples (forward and reverse agree), and the derivative is
/// unbiased (finite differences agree). Roughness also moves the sampled
/// directions' weights, so the deeper dimensions are exercised.
#[test]
fn stratified_samplers_replay_their_samples() {
    let mut scene = surfaces_scene();
    for sampler in [
        Sampler::Multijitter(Multijitter {
            sample_count: 4,
            seed: 0,
            jitter: true,
        }),
        Sampler::LowDiscrepancy(LowDiscrepancy {
            sample_count: 4,
            seed: 0,
        }),
        Sampler::Orthogonal(Orthogonal {
            sample_count: 4,
            seed: 0,
            jitter: true,
        }),
    ] {
        eprintln!("sampler {}", sampler.plugin_name());
        scene.sensors[0].sampler = sampler;
        for key in ["paint.reflectance.value", "metal.alpha.value"] {
            check(&mut scene, key);
        }
    }
}
