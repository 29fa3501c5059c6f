//! Integrators: estimators of the radiance arriving along camera rays, and
//! the tiled render loop that drives them.

mod aov;
mod direct;
pub(crate) mod path;
pub(crate) mod render;

pub use aov::{AovIntegrator, AovKind};
pub use direct::DirectIntegrator;
pub use path::PathIntegrator;
pub use render::{render, ProgressFn, RenderOptions, Rendered};

use crate::ad::Real;
use crate::error::Result;
use crate::math::Spectrum;
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;

/// All integrator plugins.
#[derive(Clone, Debug)]
pub enum Integrator {
    Path(PathIntegrator),
    Direct(DirectIntegrator),
    Aov(AovIntegrator),
}

impl Integrator {
    pub fn from_node(node: &Node) -> Result<Integrator> {
        let i = match node.plugin.as_str() {
            "path" => Integrator::Path(PathIntegrator::from_node(node)?),
            "direct" => Integrator::Direct(DirectIntegrator::from_node(node)?),
            "aov" => Integrator::Aov(AovIntegrator::from_node(node)?),
            other => {
                return Err(node.error(format!(
                    "unknown integrator plugin '{other}' (Penumbra has: path, direct, aov)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(i)
    }

    /// Names of the output channels (EXR channel names).
    pub fn channel_names(&self) -> Vec<String> {
        match self {
            Integrator::Aov(a) => a.channel_names(),
            _ => vec!["R".into(), "G".into(), "B".into()],
        }
    }

    pub fn channel_count(&self) -> usize {
        match self {
            Integrator::Aov(a) => a.channel_names().len(),
            _ => 3,
        }
    }

    /// Primal estimate along `ray`, written to `out` (`channel_count()`
    /// values).
    pub fn sample(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
        out: &mut [f32],
    ) {
        if let Integrator::Aov(a) = self {
            return a.sample(scene, cs, rng, out);
        }
        let rgb = self
            .radiance::<f32>(scene, cs, rng)
            .expect("path and direct integrators estimate radiance");
        out[..3].copy_from_slice(&rgb.val().to_array());
    }

    /// The radiance estimate along `ray` in `R` (primal for f32,
    /// derivatives for dual numbers); `None` for the AOV integrator, which
    /// estimates no radiance of its own.
    pub fn radiance<R: Real>(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> Option<Spectrum<R>> {
        match self {
            Integrator::Path(p) => Some(p.sample::<R>(scene, cs, rng)),
            Integrator::Direct(d) => Some(d.sample::<R>(scene, cs, rng)),
            Integrator::Aov(_) => None,
        }
    }
}

/// Balance of two sampling strategies by the power heuristic (β = 2).
#[inline(always)]
pub(crate) fn mis_weight(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    if a + b > 0.0 && a.is_finite() {
        a / (a + b)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// `max_depth` as Mitsuba defines it: -1 for unbounded, else ≥ 0.
pub(crate) fn max_depth(node: &Node) -> Result<u32> {
    let d = node.int("max_depth", -1)?;
    if d < -1 {
        let p = node
            .prop("max_depth")
            .expect("a non-default value came from a property");
        return Err(node.prop_error(p, format!("must be -1 (unbounded) or >= 0, found {d}")));
    }
    Ok(if d == -1 { u32::MAX } else { d as u32 })
}
