//! Arbitrary output variables (Mitsuba's `aov`): depth, position, normals,
//! albedo, uv, … per pixel, optionally beside the image of a nested
//! integrator.

use super::Integrator;
use crate::bsdf::BsdfContextT;
use crate::error::Result;
use crate::geometry::DiffRay;
use crate::sampler::SampleStream;
use crate::scene::{Class, Node, Scene};
use crate::sensor::CameraSample;

/// One output variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AovKind {
    /// Distance along the camera ray.
    Depth,
    Position,
    GeometricNormal,
    ShadingNormal,
    /// The BSDF's albedo-like colour.
    Albedo,
    Uv,
    ShapeIndex,
    PrimIndex,
}

impl AovKind {
    fn parse(s: &str) -> Option<AovKind> {
        Some(match s {
            "depth" => AovKind::Depth,
            "position" => AovKind::Position,
            "geo_normal" => AovKind::GeometricNormal,
            "sh_normal" => AovKind::ShadingNormal,
            "albedo" => AovKind::Albedo,
            "uv" => AovKind::Uv,
            "shape_index" => AovKind::ShapeIndex,
            "prim_index" => AovKind::PrimIndex,
            _ => return None,
        })
    }

    /// Channel-name suffixes in the EXR output.
    fn suffixes(self) -> &'static [&'static str] {
        match self {
            AovKind::Depth | AovKind::ShapeIndex | AovKind::PrimIndex => &["T"],
            AovKind::Position | AovKind::GeometricNormal | AovKind::ShadingNormal => {
                &["X", "Y", "Z"]
            }
            AovKind::Albedo => &["R", "G", "B"],
            AovKind::Uv => &["U", "V"],
        }
    }
}

/// The AOV integrator: named output variables, and optionally a nested
/// integrator whose RGB comes first.
#[derive(Clone, Debug)]
pub struct AovIntegrator {
    pub aovs: Vec<(String, AovKind)>,
    pub nested: Option<Box<Integrator>>,
}

impl AovIntegrator {
    pub fn from_node(node: &Node) -> Result<AovIntegrator> {
        let spec = node.string_opt("aovs")?.ok_or_else(|| {
            node.error(
                "missing 'aovs', e.g. <string name=\"aovs\" value=\"dd:depth,nn:sh_normal\"/>",
            )
        })?;
        let mut aovs = Vec::new();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, kind) = item
                .split_once(':')
                .ok_or_else(|| node.error(format!("aov '{item}' must be written name:type")))?;
            let kind = AovKind::parse(kind.trim()).ok_or_else(|| {
                node.error(format!(
                    "unknown aov type '{kind}' (Penumbra has: depth, position, geo_normal, sh_normal, albedo, uv, shape_index, prim_index)"
                ))
            })?;
            aovs.push((name.trim().to_string(), kind));
        }
        let nested = match node.children(Class::Integrator).as_slice() {
            [] => None,
            [n] => Some(Box::new(Integrator::from_node(n)?)),
            _ => return Err(node.error("at most one nested integrator")),
        };
        Ok(AovIntegrator { aovs, nested })
    }

    pub fn channel_names(&self) -> Vec<String> {
        let mut names = match &self.nested {
            Some(n) => n.channel_names(),
            None => Vec::new(),
        };
        for (name, kind) in &self.aovs {
            names.extend(kind.suffixes().iter().map(|s| format!("{name}.{s}")));
        }
        names
    }

    pub fn sample(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
        out: &mut [f32],
    ) {
        let mut k = 0;
        if let Some(n) = &self.nested {
            let c = n.channel_count();
            n.sample(scene, cs, rng, &mut out[..c]);
            k = c;
        }
        let store = scene.params.primal();
        let ray = cs.ray::<f32>(&store).val();
        let hit = scene.intersect(&ray);
        let si = hit.map(|h| {
            (
                h,
                scene.surface_interaction::<f32>(&store, &DiffRay::cst(&ray), &h),
            )
        });
        for (_, kind) in &self.aovs {
            let vals: [f32; 3] = match &si {
                None => [0.0; 3],
                Some((h, si)) => match kind {
                    AovKind::Depth => [si.t, 0.0, 0.0],
                    AovKind::Position => si.p.val().to_array(),
                    AovKind::GeometricNormal => si.n.val().to_array(),
                    AovKind::ShadingNormal => si.sh_frame.n.val().to_array(),
                    AovKind::Albedo => scene
                        .shape_bsdf(h.shape)
                        .context(&store, si)
                        .albedo()
                        .val()
                        .to_array(),
                    AovKind::Uv => [si.uv.x, si.uv.y, 0.0],
                    AovKind::ShapeIndex => [h.shape as f32, 0.0, 0.0],
                    AovKind::PrimIndex => [h.prim as f32, 0.0, 0.0],
                },
            };
            let n = kind.suffixes().len();
            out[k..k + n].copy_from_slice(&vals[..n]);
            k += n;
        }
    }
}
