//! First and second moments of the samples of nested integrators
//! (Mitsuba's `moment`), for estimating the variance of a render.
//!
//! The image is the first nested integrator's. Each nested integrator
//! `name` adds, as Mitsuba 3.9 names them, its own extra channels
//! (`name.<channel>`, e.g. an `aov`'s) and its radiance converted to CIE
//! XYZ (`name.X`, `name.Y`, `name.Z`); then every one of those channels
//! has a twin `m2_<channel>` that accumulates the square of each sample.
//! The film averages samples, so the twin holds the second moment E[x²]
//! and E[x²] − E[x]² is the per-sample variance. A nested integrator
//! written without a name is `_arg_0`, `_arg_1`, … in file order.

use super::Integrator;
use crate::error::Result;
use crate::sampler::SampleStream;
use crate::scene::{Class, Node, Scene};
use crate::sensor::CameraSample;

/// Linear sRGB (Rec. 709 primaries, D65 white) to CIE 1931 XYZ, rows X, Y,
/// Z (IEC 61966-2-1).
const SRGB_TO_XYZ: [[f32; 3]; 3] = [
    [0.412453, 0.357580, 0.180423],
    [0.212671, 0.715160, 0.072169],
    [0.019334, 0.119193, 0.950227],
];

/// The moment integrator: nested integrators, each with its channel name
/// prefix.
#[derive(Clone, Debug)]
pub struct MomentIntegrator {
    pub nested: Vec<(String, Integrator)>,
}

impl MomentIntegrator {
    pub fn from_node(node: &Node) -> Result<MomentIntegrator> {
        let mut unnamed = 0;
        let mut nested = Vec::new();
        for (prop, child) in node.child_props(Class::Integrator) {
            let name = if prop.unnamed {
                unnamed += 1;
                format!("_arg_{}", unnamed - 1)
            } else {
                prop.name.clone()
            };
            nested.push((name, Integrator::from_node(&child)?));
        }
        if nested.is_empty() {
            return Err(node
                .error("needs at least one nested integrator, e.g. <integrator type=\"path\"/>"));
        }
        Ok(MomentIntegrator { nested })
    }

    /// The channels one nested integrator contributes besides its
    /// radiance (none for radiance integrators).
    fn extra_channels(integrator: &Integrator) -> Vec<String> {
        let names = integrator.channel_names();
        let skip = if integrator.has_radiance_channels() {
            3
        } else {
            0
        };
        names[skip..].to_vec()
    }

    /// Number of moment channels (the first moments; as many second).
    fn moment_count(&self) -> usize {
        self.nested
            .iter()
            .map(|(_, n)| Self::extra_channels(n).len() + 3)
            .sum()
    }

    /// R, G, B of the first nested integrator, the first moments, then
    /// their `m2_` twins.
    pub fn channel_names(&self) -> Vec<String> {
        let mut moments = Vec::new();
        for (name, n) in &self.nested {
            for c in Self::extra_channels(n) {
                moments.push(format!("{name}.{c}"));
            }
            for c in ["X", "Y", "Z"] {
                moments.push(format!("{name}.{c}"));
            }
        }
        let second: Vec<String> = moments.iter().map(|c| format!("m2_{c}")).collect();
        ["R", "G", "B"]
            .into_iter()
            .map(String::from)
            .chain(moments)
            .chain(second)
            .collect()
    }

    pub fn channel_count(&self) -> usize {
        3 + 2 * self.moment_count()
    }

    /// One sample of every nested integrator, in order, from the same
    /// sample stream (as Mitsuba shares its sampler between them).
    pub fn sample(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
        out: &mut [f32],
    ) {
        let m = self.moment_count();
        let (image, moments) = out.split_at_mut(3);
        let (first, second) = moments.split_at_mut(m);
        let mut k = 0;
        for (i, (_, n)) in self.nested.iter().enumerate() {
            // the nested integrator writes [R, G, B,] extras… into its slot
            // of extras + 3 channels; the radiance moves behind the extras
            // as XYZ
            let c = n.channel_count();
            let has_rgb = n.has_radiance_channels();
            let slot = &mut first[k..k + c + if has_rgb { 0 } else { 3 }];
            n.sample(scene, cs, rng, &mut slot[..c]);
            let rgb = if has_rgb {
                let rgb = [slot[0], slot[1], slot[2]];
                slot.rotate_left(3);
                rgb
            } else {
                [0.0; 3]
            };
            if i == 0 {
                image.copy_from_slice(&rgb);
            }
            let len = slot.len();
            for (x, row) in slot[len - 3..].iter_mut().zip(SRGB_TO_XYZ) {
                *x = row[0] * rgb[0] + row[1] * rgb[1] + row[2] * rgb[2];
            }
            k += len;
        }
        for (s, f) in second.iter_mut().zip(first.iter()) {
            *s = f * f;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scene(integrator: &str) -> Scene {
        let xml = format!(
            r#"<scene version="3.0.0">
    {integrator}
    <sensor type="perspective">
        <film type="hdrfilm">
            <integer name="width" value="8"/><integer name="height" value="8"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="sphere">
        <point name="center" x="0" y="0" z="4"/>
        <bsdf type="diffuse"/>
    </shape>
    <emitter type="constant"><rgb name="radiance" value="0.5, 1, 2"/></emitter>
</scene>"#
        );
        Scene::load_str(&xml, Path::new("moment.xml"), &[]).unwrap()
    }

    /// Channel names as Mitsuba 3.9.1 reports them (its `aov_names()` of
    /// the same integrator, with R, G, B in front as its film writes).
    #[test]
    fn channels_are_named_as_mitsuba_names_them() {
        let s = scene(
            r#"<integrator type="moment">
        <integrator type="path" name="a"/>
        <integrator type="direct"/>
        <integrator type="direct"/>
    </integrator>"#,
        );
        let mut want = vec!["R", "G", "B"];
        let first = [
            "a.X", "a.Y", "a.Z", "_arg_0.X", "_arg_0.Y", "_arg_0.Z", "_arg_1.X", "_arg_1.Y",
            "_arg_1.Z",
        ];
        want.extend(first);
        let second: Vec<String> = first.iter().map(|c| format!("m2_{c}")).collect();
        want.extend(second.iter().map(String::as_str));
        assert_eq!(s.integrator.channel_names(), want);
    }

    /// On a constant environment seen directly, every sample is the same:
    /// the image is the radiance, the first moment its XYZ, the second
    /// moment the square of that (zero variance).
    #[test]
    fn moments_of_a_constant_are_its_value_and_square() {
        let s = scene(
            r#"<integrator type="moment">
        <integrator type="path"/>
        <integrator type="aov"><string name="aovs" value="dd:depth"/></integrator>
    </integrator>"#,
        );
        let names = s.integrator.channel_names();
        let img = crate::integrator::render(&s, &Default::default()).unwrap();
        let (r, g, b) = (0.5f32, 1.0, 2.0);
        let xyz = SRGB_TO_XYZ.map(|row| row[0] * r + row[1] * g + row[2] * b);
        // a corner pixel sees only the environment
        let px = &img.data[..img.channels()];
        let at = |c: &str| px[names.iter().position(|n| n == c).unwrap()];
        assert_eq!([at("R"), at("G"), at("B")], [r, g, b]);
        for (c, v) in ["X", "Y", "Z"].iter().zip(xyz) {
            assert!((at(&format!("_arg_0.{c}")) - v).abs() < 1e-5);
            assert!((at(&format!("m2__arg_0.{c}")) - v * v).abs() < 1e-4);
            // the aov integrator estimates no radiance
            assert_eq!(at(&format!("_arg_1.{c}")), 0.0);
        }
        assert_eq!(at("_arg_1.dd.T"), 0.0);
        assert_eq!(at("m2__arg_1.dd.T"), 0.0);
    }
}
