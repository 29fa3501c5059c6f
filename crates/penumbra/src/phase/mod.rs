//! The phase-function family: how light scatters at a point of a medium
//! (Mitsuba's `isotropic` and `hg`). Directions follow Mitsuba's
//! convention: `wi` points back along the incoming ray (towards where the
//! light goes after scattering, seen from the camera), `wo` is the
//! scattered direction; both are unit world-space vectors. Every phase
//! function here is sampled exactly in proportion to its value, so its
//! sampling weight is 1 and its density equals its value.

mod hg;
mod isotropic;

pub use hg::HenyeyGreenstein;

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::math::V3;
use crate::params::{ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};

/// All phase-function plugins.
#[derive(Clone, Debug)]
pub enum PhaseFunction {
    Isotropic,
    HenyeyGreenstein(HenyeyGreenstein),
}

impl PhaseFunction {
    /// Builds a `<phase>` node whose parameters are keyed `<key>.<name>`
    /// (Mitsuba's `<medium>.phase_function`).
    pub fn from_node(node: &Node, key: &str, ctx: &mut LoadContext) -> Result<PhaseFunction> {
        let p = match node.plugin.as_str() {
            "isotropic" => PhaseFunction::Isotropic,
            "hg" => PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::from_node(node, key, ctx)?),
            other => {
                return Err(node.error(format!(
                    "unknown phase function plugin '{other}' (Penumbra has: isotropic, hg)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(p)
    }

    /// The phase function's value (= its sampling density, per steradian)
    /// for scattering from `wi` to `wo`, in `R`.
    #[inline]
    pub fn eval<R: ScalarReal>(&self, store: &ParamView, wi: Vec3, wo: V3<R>) -> R {
        match self {
            PhaseFunction::Isotropic => R::cst(isotropic::DENSITY),
            PhaseFunction::HenyeyGreenstein(p) => p.eval(store, wi, wo),
        }
    }

    /// The density of [`PhaseFunction::sample`] (primal).
    #[inline]
    pub fn pdf(&self, store: &ParamStore, wi: Vec3, wo: Vec3) -> f32 {
        match self {
            PhaseFunction::Isotropic => isotropic::DENSITY,
            PhaseFunction::HenyeyGreenstein(p) => p.pdf(store, wi, wo),
        }
    }

    /// A scattered direction for `wi` from the uniform point `u`, and its
    /// density (primal; detached sampling).
    #[inline]
    pub fn sample(&self, store: &ParamStore, wi: Vec3, u: Vec2) -> (Vec3, f32) {
        match self {
            PhaseFunction::Isotropic => isotropic::sample(u),
            PhaseFunction::HenyeyGreenstein(p) => p.sample(store, wi, u),
        }
    }
}
