//! The volume family: fields over 3D space that media read their extinction
//! and albedo from (Mitsuba's `constvolume` and `gridvolume`). A volume is
//! evaluated at world-space points in the number type of the pass; the
//! points themselves are primal (sampled collision points do not move with
//! the parameters: detached sampling).

mod constvolume;
mod gridvolume;

pub use constvolume::ConstVolume;
pub use gridvolume::{GridVolume, VolFile};

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::math::Spectrum;
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node, Value};
use glam::Vec3;

/// All volume plugins.
#[derive(Clone, Debug)]
pub enum Volume {
    Const(ConstVolume),
    Grid(GridVolume),
}

impl Volume {
    /// The volume for property `name` of `node`: a nested `<volume>` (or a
    /// reference to one), or a plain value (`<float>`, `<rgb>`,
    /// `<spectrum>`), which becomes a constant volume with parameter key
    /// `<node key>.<name>.value.value`, as Mitsuba names it; `default`
    /// when the property is absent. Values must lie in `domain`.
    pub fn from_prop(
        node: &Node,
        name: &str,
        default: f32,
        domain: Domain,
        ctx: &mut LoadContext,
    ) -> Result<Volume> {
        let key = format!("{}.{}", node.key, name);
        let Some(p) = node.prop(name) else {
            return ConstVolume::new(&key, Value::Float(default as f64), domain, ctx)
                .map(Volume::Const);
        };
        match &p.value {
            Value::Node(n) => Volume::from_node(n, domain, ctx),
            v @ (Value::Float(_) | Value::Spectrum(_) | Value::Rgb(_)) => {
                ConstVolume::new(&key, v.clone(), domain, ctx)
                    .map(Volume::Const)
                    .map_err(|e| node.prop_error(p, e))
            }
            _ => Err(node.prop_error(p, "must be a float, rgb, spectrum or volume")),
        }
    }

    /// Builds a `<volume>` node and checks that all its parameters were used.
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Volume> {
        let v = match node.plugin.as_str() {
            "constvolume" => Volume::Const(ConstVolume::from_node(node, domain, ctx)?),
            "gridvolume" => Volume::Grid(GridVolume::from_node(node, domain, ctx)?),
            other => {
                return Err(node.error(format!(
                    "unknown volume plugin '{other}' (Penumbra has: constvolume, gridvolume)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(v)
    }

    /// The value at world-space point `p` (a one-channel volume on all
    /// three channels).
    #[inline]
    pub fn eval<R: ScalarReal>(&self, store: &ParamView, p: Vec3) -> Spectrum<R> {
        match self {
            Volume::Const(v) => v.eval(store),
            Volume::Grid(v) => v.eval(store, p),
        }
    }

    /// The largest value over space and channels (primal): what a
    /// majorant of the extinction is built from.
    pub fn max(&self, store: &ParamStore) -> f32 {
        match self {
            Volume::Const(v) => v.max(store),
            Volume::Grid(v) => v.max(store),
        }
    }

    /// One value on all channels (a float constant, a one-channel grid):
    /// [`Volume::eval`] gives the same number thrice.
    pub fn is_mono(&self) -> bool {
        match self {
            Volume::Const(v) => v.is_mono(),
            Volume::Grid(v) => v.channels == 1,
        }
    }

    /// The grid, for a grid volume.
    pub fn grid(&self) -> Option<&GridVolume> {
        match self {
            Volume::Const(_) => None,
            Volume::Grid(v) => Some(v),
        }
    }

    /// The world-space box outside which the volume is not defined (a
    /// grid's), or `None` for a volume that fills space.
    pub fn bbox(&self) -> Option<(Vec3, Vec3)> {
        match self {
            Volume::Const(_) => None,
            Volume::Grid(v) => Some(v.bbox()),
        }
    }
}
