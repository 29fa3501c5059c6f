//! Helpers shared by the integration tests: small scenes written inline,
//! batch statistics. Each test file uses a part of them.
#![allow(dead_code)]

/// A perspective sensor looking from `origin` at the world origin (+y up)
/// with a square `size`² `hdrfilm` (the default filter unless `rfilter`
/// names one) and an independent sampler of `spp` samples, as Mitsuba 3 XML.
pub fn sensor_xml(origin: &str, fov: f32, size: u32, spp: u32, rfilter: Option<&str>) -> String {
    let rfilter = rfilter
        .map(|f| format!(r#"<rfilter type="{f}"/>"#))
        .unwrap_or_default();
    format!(
        r#"<sensor type="perspective">
            <float name="fov" value="{fov}"/>
            <transform name="to_world">
                <lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="{size}"/>
                <integer name="height" value="{size}"/>
                {rfilter}
            </film>
            <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
        </sensor>"#
    )
}

/// Mean of independent batch results and its standard error.
pub fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}
