//! Loader gaps found by running public Mitsuba scenes (scenes/corpus/,
//! scripts/corpus_check.py, docs/corpus.md): each test restates the part of
//! a public scene that Penumbra refused although Mitsuba 3 renders it, and
//! checks that it now loads as Mitsuba loads it.

use std::path::Path;

use penumbra::scene::Scene;

fn load(xml: &str) -> penumbra::Result<Scene> {
    Scene::load_str(xml, Path::new("corpus_gap.xml"), &[])
}

/// mitsuba-data scenes/cbox/mts1-fragments/base.xml (a Mitsuba 0.6 scene):
/// `<boolean name="banner" value="false"/>` in its hdrfilm. Mitsuba 3's
/// hdrfilm accepts `banner` in scenes of every version and ignores it.
#[test]
fn hdrfilm_accepts_and_ignores_banner() {
    for version in ["0.6.0", "2.1.0", "3.0.0"] {
        let xml = format!(
            r#"<scene version="{version}">
                <sensor type="perspective">
                    <film type="hdrfilm">
                        <integer name="width" value="8"/>
                        <integer name="height" value="6"/>
                        <boolean name="banner" value="false"/>
                    </film>
                </sensor>
            </scene>"#
        );
        let scene = load(&xml).unwrap_or_else(|e| panic!("version {version}: {e}"));
        let film = &scene.sensor(0).unwrap().film;
        assert_eq!((film.width, film.height), (8, 6));
    }
    // a parameter Mitsuba does not know is still an error naming it
    let e = load(
        r#"<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">
            <boolean name="bannerx" value="false"/></film></sensor></scene>"#,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("bannerx"), "{e}");
}

/// mitsuba-data docs/scenes/integrator_depth_2.xml and
/// variants_cbox_spectral.xml: the luminaire references an area emitter
/// declared at the top level after it (`<ref id="area-emitter"/>` in the
/// shape, `<emitter type="area" id="area-emitter">` at the end). Mitsuba 3
/// attaches it to the shape that references it and renders the same image
/// as with the emitter nested; an area emitter that no shape references is
/// dropped (a warning here).
#[test]
fn top_level_area_emitter_referenced_by_a_shape() {
    let scene = |light: &str, extra: &str| {
        format!(
            r#"<scene version="2.0.0">
                <sensor type="perspective"><film type="hdrfilm">
                    <integer name="width" value="4"/><integer name="height" value="4"/>
                </film></sensor>
                <shape type="rectangle"><bsdf type="diffuse"/></shape>
                <shape type="sphere" id="light">
                    <transform name="to_world"><translate z="2"/></transform>
                    {light}
                </shape>
                {extra}
            </scene>"#
        )
    };
    let emitter = r#"<emitter type="area" id="area-emitter">
        <spectrum name="radiance" value="400:0, 500:8, 600:15.6, 700:18.4"/></emitter>"#;
    let nested = load(&scene(emitter, "")).unwrap();
    let referenced = load(&scene(r#"<ref id="area-emitter"/>"#, emitter)).unwrap();
    assert_eq!(nested.emitters.len(), 1);
    assert_eq!(referenced.emitters.len(), 1);
    assert_eq!(
        format!("{:?}", nested.emitters[0]),
        format!("{:?}", referenced.emitters[0])
    );
    // declared at the top level and referenced by no shape: ignored
    let dangling = load(&scene(emitter, &emitter.replace("area-emitter", "unused"))).unwrap();
    assert_eq!(dangling.emitters.len(), 1);
}
