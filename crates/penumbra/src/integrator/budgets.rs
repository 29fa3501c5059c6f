//! The sample budgets of the derivative terms, configured on the
//! integrator as Mitsuba's projective-sampling integrators
//! (`direct_projective`, `prb_projective`) configure them, so that their
//! scenes and scripts port: `sppc` (interior term), `sppp` (boundary term
//! of primary visibility) and `sppi` (boundary term of indirect
//! visibility: shadows and edges seen after a bounce), each in samples per
//! pixel, 0 turning its term off.
//!
//! Precedence, per term: the budget of the call ([`RenderOptions::spp`]
//! for the interior term, [`RenderOptions::sppp`], [`RenderOptions::sppi`]) over the integrator's,
//! over the pass's samples per pixel (the call's `spp`, else the scene
//! sampler's). Unlike Mitsuba, where a runtime `spp` replaces all three
//! budgets, a call's `spp` replaces `sppc` only: a boundary term turned off
//! on the integrator stays off whatever the pass's sample count.

use super::RenderOptions;
use crate::error::Result;
use crate::scene::Node;

/// The budgets an integrator gives its derivative passes; `None` follows
/// the pass's samples per pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Budgets {
    /// Samples per pixel of the interior term (Mitsuba's `sppc`).
    pub sppc: Option<u32>,
    /// Edge samples per pixel of the boundary term of primary visibility
    /// (Mitsuba's `sppp`).
    pub sppp: Option<u32>,
    /// Samples per pixel of the boundary term of the visibility seen from
    /// the first vertex: shadows, and the edges seen there after a bounce
    /// (Mitsuba's `sppi`).
    pub sppi: Option<u32>,
}

impl Budgets {
    /// Reads the properties of Mitsuba's projective integrators: the
    /// budgets and the guiding options. The guiding options (which steer
    /// Mitsuba's samples of the indirect term) are accepted so that
    /// Mitsuba scenes load, and warned about: Penumbra samples that term
    /// from the edges towards the emitters, without guiding.
    pub(crate) fn from_projective_node(node: &Node) -> Result<Budgets> {
        let budget = |name: &str| -> Result<Option<u32>> {
            Ok(match node.prop(name) {
                Some(_) => Some(node.int_min(name, 0, 0)? as u32),
                None => None,
            })
        };
        let budgets = Budgets {
            sppc: budget("sppc")?,
            sppp: budget("sppp")?,
            sppi: budget("sppi")?,
        };
        let guiding: Vec<&str> = ["guiding", "guiding_proj", "guiding_rounds"]
            .into_iter()
            .filter(|name| node.has(name))
            .collect();
        node.choice("guiding", &["octree", "grid", "none"])?;
        node.bool("guiding_proj", true)?;
        node.int_min("guiding_rounds", 1, 1)?;
        if !guiding.is_empty() {
            crate::warn(format!(
                "{node} at {}: {} ignored: Penumbra samples the indirect visibility \
                 term from the edges towards the emitters, without guiding",
                node.loc,
                guiding.join(", ")
            ));
        }
        Ok(budgets)
    }

    /// `opts` of a derivative pass with these budgets filled in where the
    /// call sets none (module documentation): `spp` becomes the interior
    /// term's samples per pixel (0: no interior term), `sppp` is always
    /// set, and so is `sppi`. `sampler_spp`: the scene sampler's sample count.
    pub(crate) fn resolve(&self, opts: &RenderOptions, sampler_spp: u32) -> RenderOptions {
        let pass_spp = opts.spp.unwrap_or(sampler_spp);
        RenderOptions {
            spp: Some(opts.spp.or(self.sppc).unwrap_or(pass_spp)),
            sppp: Some(opts.sppp.or(self.sppp).unwrap_or(pass_spp)),
            sppi: Some(opts.sppi.or(self.sppi).unwrap_or(pass_spp)),
            ..opts.clone()
        }
    }
}
