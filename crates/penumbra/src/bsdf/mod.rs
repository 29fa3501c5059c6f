//! The BSDF family. Conventions (as in Mitsuba 3): directions are in the
//! local shading frame (normal = +z); `si.wi` points towards the viewer;
//! `eval` includes the cosine foreshortening `|cos θo|`. Values are
//! differentiable in both directions (`si.wi` and `wo` are in `R`, so
//! derivatives with respect to geometry flow through the shading frame).
//! Sampling of smooth lobes is detached: the sampled direction is a
//! constant of the integral and its pdf an f32, while the weight
//! `eval / pdf` is differentiated in `R`. A delta lobe has no density to
//! integrate against: its direction is a function of `si.wi`, computed in
//! `R` like its weight.

mod blendbsdf;
mod bumpmap;
mod conductor;
mod dielectric;
mod diffuse;
pub mod fresnel;
pub(crate) mod lanes;
mod mask;
pub mod microfacet;
mod normalmap;
mod null;
mod plastic;
mod pplastic;
mod principled;
mod principledthin;
mod roughconductor;
mod roughdielectric;
mod roughplastic;
#[cfg(test)]
mod test_util;
mod thindielectric;
mod twosided;

pub use blendbsdf::{BlendBsdf, BlendBsdfContext};
pub use bumpmap::BumpMap;
pub use conductor::{Conductor, ConductorContext};
pub use dielectric::{Dielectric, DielectricContext};
pub(crate) use diffuse::{lambert_eval, lambert_pdf, lambert_sample};
pub use diffuse::{Diffuse, DiffuseContext};
pub use mask::{Mask, MaskContext};
pub use normalmap::{NormalMap, PerturbedFrameContext};
pub use null::{Null, NullContext};
pub use plastic::{Plastic, PlasticContext};
pub use pplastic::{PPlastic, PPlasticContext};
pub use principled::{Ior, Principled, PrincipledContext};
pub use principledthin::{PrincipledThin, PrincipledThinContext};
pub use roughconductor::{RoughConductor, RoughConductorContext};
pub use roughdielectric::{RoughDielectric, RoughDielectricContext};
pub use roughplastic::{RoughPlastic, RoughPlasticContext};
pub use thindielectric::{ThinDielectric, ThinDielectricContext};
pub use twosided::{TwoSided, TwoSidedContext};

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Spectrum, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{Class, LoadContext, Node, Prop, Value};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::rc::Rc;

/// Which lobes a BSDF has, or which lobe a sample came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BsdfFlags(pub u8);

impl BsdfFlags {
    pub const DIFFUSE_REFLECTION: BsdfFlags = BsdfFlags(1);
    pub const GLOSSY_REFLECTION: BsdfFlags = BsdfFlags(2);
    pub const DELTA_REFLECTION: BsdfFlags = BsdfFlags(4);
    pub const GLOSSY_TRANSMISSION: BsdfFlags = BsdfFlags(8);
    pub const DELTA_TRANSMISSION: BsdfFlags = BsdfFlags(16);
    /// Index-matched pass-through (null BSDF, transparent parts of `mask`).
    pub const NULL: BsdfFlags = BsdfFlags(32);
    /// Both sides of the surface reflect (twosided wrapper, thin dielectric).
    pub const TWO_SIDED: BsdfFlags = BsdfFlags(64);
    /// Lambertian transmission (the thin principled BSDF).
    pub const DIFFUSE_TRANSMISSION: BsdfFlags = BsdfFlags(128);

    pub const DELTA: BsdfFlags = BsdfFlags(4 | 16 | 32);
    pub const SMOOTH: BsdfFlags = BsdfFlags(1 | 2 | 8 | 128);
    pub const TRANSMISSION: BsdfFlags = BsdfFlags(8 | 16 | 32 | 128);

    #[inline(always)]
    pub fn has(self, f: BsdfFlags) -> bool {
        self.0 & f.0 != 0
    }
    #[inline(always)]
    pub fn union(self, f: BsdfFlags) -> BsdfFlags {
        BsdfFlags(self.0 | f.0)
    }
}

/// A sampled direction with its weight.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample<R> {
    /// Sampled direction, local frame: a constant for smooth lobes
    /// (detached sampling), a function of `si.wi` for delta lobes.
    pub wo: V3<R>,
    /// Solid-angle density of `wo` (for delta lobes: the discrete
    /// probability of choosing the lobe).
    pub pdf: f32,
    /// `eval(wo) / pdf`, differentiable.
    pub weight: Spectrum<R>,
    /// Relative index of refraction along the sampled path (1 for
    /// reflection).
    pub eta: f32,
    /// The lobe the sample came from.
    pub lobe: BsdfFlags,
}

impl<R: ScalarReal> BsdfSample<R> {
    /// A delta reflection about the normal (`wo` = `wi` mirrored, `eta`
    /// 1) chosen with probability `pdf`.
    pub(crate) fn specular_reflection(wi: V3<R>, pdf: f32, weight: Spectrum<R>) -> Self {
        BsdfSample {
            wo: V3::new(-wi.x, -wi.y, wi.z),
            pdf,
            weight,
            eta: 1.0,
            lobe: BsdfFlags::DELTA_REFLECTION,
        }
    }

    /// An index-matched pass-through (`NULL` lobe: `wo = −wi`, `eta` 1)
    /// chosen with probability `pdf`.
    pub(crate) fn pass_through(wi: V3<R>, pdf: f32, weight: Spectrum<R>) -> Self {
        BsdfSample {
            wo: -wi,
            pdf,
            weight,
            eta: 1.0,
            lobe: BsdfFlags::NULL,
        }
    }
}

/// What every BSDF plugin provides.
pub trait BsdfT {
    /// The lobes this BSDF has.
    fn flags(&self) -> BsdfFlags;
    /// The most nodes its context takes in a [`BsdfContext`]: one, plus
    /// those of the nested BSDFs a wrapper uses at one vertex.
    fn context_len(&self) -> usize {
        1
    }
    /// Evaluates every texture and parameter of the BSDF at `si`, in `R`,
    /// and writes its context to `nodes[0]`; a wrapper writes those of the
    /// nested BSDFs it uses at `si` after its own (pre-order). Returns how
    /// many nodes it wrote.
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize;
}

/// A BSDF at one surface vertex, its textures already evaluated there.
/// Conventions as in the module documentation: `wi` is the vertex's
/// incident direction; `eval` is `f(wi, wo) · |cos θo|` for the smooth
/// lobes (zero for delta lobes), differentiable in `wi` and `wo`.
pub trait BsdfContextT<R: ScalarReal> {
    /// `f(wi, wo) · |cos θo|` for the smooth lobes.
    fn eval(&self, wo: V3<R>) -> Spectrum<R>;
    /// Solid-angle density with which `sample` returns `wo` (smooth lobes).
    fn pdf(&self, wo: Vec3) -> f32;
    /// Samples an outgoing direction; `u1` picks a lobe, `u2` the direction.
    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>>;
    /// The surface's albedo-like colour (for the AOV integrator).
    fn albedo(&self) -> Spectrum<R>;
    /// The weight of the `NULL` lobe, the light passing straight through
    /// (Mitsuba's `eval_null_transmission`): what the shadow rays of the
    /// volumetric path tracer carry through the surface. Their MIS weights
    /// assume an emitter seen through such a surface can be sampled from
    /// the vertex before it, as a path sampling the lobe reaches it from
    /// there. Zero for BSDFs without that lobe.
    fn null_transmission(&self) -> Spectrum<R> {
        V3::zero()
    }
}

/// The context of one BSDF node at a vertex (mirrors [`Bsdf`]): its
/// texture values in `R` and what else its methods read.
#[derive(Clone, Copy, Debug)]
pub enum NodeContext<'a, R: ScalarReal> {
    Diffuse(DiffuseContext<R>),
    Conductor(ConductorContext<R>),
    RoughConductor(RoughConductorContext<R>),
    Dielectric(DielectricContext<R>),
    ThinDielectric(ThinDielectricContext<R>),
    RoughDielectric(RoughDielectricContext<R>),
    Plastic(PlasticContext<'a, R>),
    RoughPlastic(RoughPlasticContext<'a, R>),
    PPlastic(PPlasticContext<R>),
    Principled(PrincipledContext<'a, R>),
    PrincipledThin(PrincipledThinContext<'a, R>),
    TwoSided(TwoSidedContext),
    Null(NullContext<R>),
    BlendBsdf(BlendBsdfContext<R>),
    Mask(MaskContext<R>),
    /// `normalmap` and `bumpmap`, which differ only in how they build the
    /// frame.
    PerturbedFrame(PerturbedFrameContext<R>),
}

/// The most nodes a [`BsdfContext`] holds. The contexts of nested BSDFs
/// live in one fixed array beside their wrapper's, not boxed inside it (a
/// recursive enum would need a box per wrapper and vertex): building a
/// context allocates nothing, and a plain BSDF costs one node and empty
/// slots. Eight holds three levels of blends (seven nodes) or a mask of a
/// twosided blend of a BSDF and a blend (seven); [`Bsdf::from_node`]
/// refuses BSDFs that need more.
pub const MAX_CONTEXT_NODES: usize = 8;

/// A BSDF at one surface vertex ([`Bsdf::context`]): every texture of the
/// BSDF and of the nested BSDFs it uses there evaluated once, in `R` (so
/// derivatives reach the texture parameters), shared by sampling, the MIS
/// densities, the evaluation for emitter samples and the re-evaluation
/// along a scattered path.
#[derive(Clone, Copy, Debug)]
pub struct BsdfContext<'a, R: ScalarReal> {
    /// The nodes in pre-order (a wrapper, then its nested BSDFs' nodes),
    /// `None` past the last.
    nodes: [Option<NodeContext<'a, R>>; MAX_CONTEXT_NODES],
}

impl<'a, R: ScalarReal> BsdfContext<'a, R> {
    /// Storage for [`set`](Self::set): a context of no BSDF yet (using it
    /// panics).
    pub fn empty() -> Self {
        BsdfContext {
            nodes: [None; MAX_CONTEXT_NODES],
        }
    }

    /// Makes this the context of `bsdf` at the vertex `si`, in place: a
    /// loop over vertices that keeps one context copies none (a returned
    /// context is moved, a few hundred bytes, per vertex).
    pub fn set(&mut self, bsdf: &'a Bsdf, store: &ParamView, si: &SurfaceInteraction<R>) {
        bsdf.write_context(store, si, &mut self.nodes);
    }

    fn root(&self) -> NestedContext<'_, 'a, R> {
        NestedContext { nodes: &self.nodes }
    }
}

impl<R: ScalarReal> BsdfContextT<R> for BsdfContext<'_, R> {
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        self.root().eval(wo)
    }
    fn pdf(&self, wo: Vec3) -> f32 {
        self.root().pdf(wo)
    }
    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        self.root().sample(u1, u2)
    }
    fn albedo(&self) -> Spectrum<R> {
        self.root().albedo()
    }
    fn null_transmission(&self) -> Spectrum<R> {
        self.root().null_transmission()
    }
}

/// One node of a [`BsdfContext`] and the nodes after it, which begin with
/// those of its nested BSDFs: how a wrapper reaches its nested contexts.
#[derive(Clone, Copy, Debug)]
pub struct NestedContext<'c, 'a, R: ScalarReal> {
    nodes: &'c [Option<NodeContext<'a, R>>],
}

impl<'c, 'a, R: ScalarReal> NestedContext<'c, 'a, R> {
    /// The node `offset` places after this one (a wrapper's first nested
    /// BSDF is at 1).
    pub(crate) fn at(self, offset: usize) -> Self {
        NestedContext {
            nodes: &self.nodes[offset..],
        }
    }

    fn node(&self) -> &'c NodeContext<'a, R> {
        self.nodes[0]
            .as_ref()
            .expect("a wrapper writes the nodes of its nested BSDFs")
    }
}

/// Calls `method` on the node's context: leaves take the arguments,
/// wrappers also the view of their node (to reach their nested BSDFs).
macro_rules! dispatch_context {
    ($this:expr, $method:ident($($arg:expr),*)) => {
        match $this.node() {
            NodeContext::Diffuse(c) => c.$method($($arg),*),
            NodeContext::Conductor(c) => c.$method($($arg),*),
            NodeContext::RoughConductor(c) => c.$method($($arg),*),
            NodeContext::Dielectric(c) => c.$method($($arg),*),
            NodeContext::ThinDielectric(c) => c.$method($($arg),*),
            NodeContext::RoughDielectric(c) => c.$method($($arg),*),
            NodeContext::Plastic(c) => c.$method($($arg),*),
            NodeContext::RoughPlastic(c) => c.$method($($arg),*),
            NodeContext::PPlastic(c) => c.$method($($arg),*),
            NodeContext::Principled(c) => c.$method($($arg),*),
            NodeContext::PrincipledThin(c) => c.$method($($arg),*),
            NodeContext::Null(c) => c.$method($($arg),*),
            NodeContext::TwoSided(c) => c.$method($this, $($arg),*),
            NodeContext::BlendBsdf(c) => c.$method($this, $($arg),*),
            NodeContext::Mask(c) => c.$method($this, $($arg),*),
            NodeContext::PerturbedFrame(c) => c.$method($this, $($arg),*),
        }
    };
}

impl<R: ScalarReal> BsdfContextT<R> for NestedContext<'_, '_, R> {
    #[inline]
    fn eval(&self, wo: V3<R>) -> Spectrum<R> {
        dispatch_context!(*self, eval(wo))
    }
    #[inline]
    fn pdf(&self, wo: Vec3) -> f32 {
        dispatch_context!(*self, pdf(wo))
    }
    #[inline]
    fn sample(&self, u1: f32, u2: Vec2) -> Option<BsdfSample<R>> {
        dispatch_context!(*self, sample(u1, u2))
    }
    #[inline]
    fn albedo(&self) -> Spectrum<R> {
        dispatch_context!(*self, albedo())
    }
    #[inline]
    fn null_transmission(&self) -> Spectrum<R> {
        dispatch_context!(*self, null_transmission())
    }
}

/// All BSDF plugins.
#[derive(Clone, Debug)]
pub enum Bsdf {
    Diffuse(Diffuse),
    Conductor(Conductor),
    RoughConductor(RoughConductor),
    Dielectric(Dielectric),
    ThinDielectric(ThinDielectric),
    RoughDielectric(RoughDielectric),
    Plastic(Plastic),
    RoughPlastic(RoughPlastic),
    PPlastic(PPlastic),
    Principled(Principled),
    PrincipledThin(PrincipledThin),
    TwoSided(TwoSided),
    Null(Null),
    BlendBsdf(BlendBsdf),
    Mask(Mask),
    NormalMap(NormalMap),
    BumpMap(BumpMap),
}

/// The BSDFs built from nodes with an id while a scene loads, which may
/// be referenced from several places: built once, then shared (their
/// parameters exist once in the store).
#[derive(Default)]
struct SharedBsdfs(HashMap<*const Node, Bsdf>);

/// The plugin names [`Bsdf::from_node`] knows.
pub const BSDF_PLUGINS: &[&str] = &[
    "diffuse",
    "conductor",
    "roughconductor",
    "dielectric",
    "thindielectric",
    "roughdielectric",
    "plastic",
    "roughplastic",
    "pplastic",
    "principled",
    "principledthin",
    "twosided",
    "null",
    "blendbsdf",
    "mask",
    "normalmap",
    "bumpmap",
];

macro_rules! dispatch {
    ($self:expr, $b:ident => $e:expr) => {
        match $self {
            Bsdf::Diffuse($b) => $e,
            Bsdf::Conductor($b) => $e,
            Bsdf::RoughConductor($b) => $e,
            Bsdf::Dielectric($b) => $e,
            Bsdf::ThinDielectric($b) => $e,
            Bsdf::RoughDielectric($b) => $e,
            Bsdf::Plastic($b) => $e,
            Bsdf::RoughPlastic($b) => $e,
            Bsdf::PPlastic($b) => $e,
            Bsdf::Principled($b) => $e,
            Bsdf::PrincipledThin($b) => $e,
            Bsdf::TwoSided($b) => $e,
            Bsdf::Null($b) => $e,
            Bsdf::BlendBsdf($b) => $e,
            Bsdf::Mask($b) => $e,
            Bsdf::NormalMap($b) => $e,
            Bsdf::BumpMap($b) => $e,
        }
    };
}

impl BsdfT for Bsdf {
    #[inline]
    fn flags(&self) -> BsdfFlags {
        dispatch!(self, b => b.flags())
    }
    fn context_len(&self) -> usize {
        dispatch!(self, b => b.context_len())
    }
    #[inline]
    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        dispatch!(self, b => b.write_context(store, si, nodes))
    }
}

impl Bsdf {
    /// Builds a `<bsdf>` node (nested BSDFs recursively) and checks that
    /// every parameter of every node it built was used.
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Bsdf> {
        let shared = node.id.is_some().then_some(node as *const Node);
        if let Some(b) = shared.and_then(|p| ctx.state::<SharedBsdfs>().0.get(&p)) {
            return Ok(b.clone());
        }
        let mut b = match node.plugin.as_str() {
            "diffuse" => Bsdf::Diffuse(Diffuse::from_node(node, ctx)?),
            "conductor" => Bsdf::Conductor(Conductor::from_node(node, ctx)?),
            "roughconductor" => Bsdf::RoughConductor(RoughConductor::from_node(node, ctx)?),
            "dielectric" => Bsdf::Dielectric(Dielectric::from_node(node, ctx)?),
            "thindielectric" => Bsdf::ThinDielectric(ThinDielectric::from_node(node, ctx)?),
            "roughdielectric" => Bsdf::RoughDielectric(RoughDielectric::from_node(node, ctx)?),
            "plastic" => Bsdf::Plastic(Plastic::from_node(node, ctx)?),
            "roughplastic" => Bsdf::RoughPlastic(RoughPlastic::from_node(node, ctx)?),
            "pplastic" => Bsdf::PPlastic(PPlastic::from_node(node, ctx)?),
            "principled" => Bsdf::Principled(Principled::from_node(node, ctx)?),
            "principledthin" => Bsdf::PrincipledThin(PrincipledThin::from_node(node, ctx)?),
            "twosided" => Bsdf::TwoSided(TwoSided::from_node(node, ctx)?),
            "null" => Bsdf::Null(Null::from_node(node, ctx)?),
            "blendbsdf" => Bsdf::BlendBsdf(BlendBsdf::from_node(node, ctx)?),
            "mask" => Bsdf::Mask(Mask::from_node(node, ctx)?),
            "normalmap" => Bsdf::NormalMap(NormalMap::from_node(node, ctx)?),
            "bumpmap" => Bsdf::BumpMap(BumpMap::from_node(node, ctx)?),
            other => {
                return Err(node.error(format!(
                    "unknown BSDF plugin '{other}' (Penumbra has: {})",
                    BSDF_PLUGINS.join(", ")
                )))
            }
        };
        node.check_all_used()?;
        if b.context_len() > MAX_CONTEXT_NODES {
            return Err(node.error(format!(
                "nests {} BSDFs (wrappers included, one side of a twosided) where a surface can use at most {MAX_CONTEXT_NODES}",
                b.context_len()
            )));
        }
        b.parameters_changed(&ctx.store);
        if let Some(p) = shared {
            ctx.state::<SharedBsdfs>().0.insert(p, b.clone());
        }
        Ok(b)
    }

    /// The BSDF at the surface vertex `si` (see [`BsdfContext`]): build it
    /// once per vertex and use it for everything the BSDF does there.
    pub fn context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> BsdfContext<'a, R> {
        let mut context = BsdfContext::empty();
        context.set(self, store, si);
        context
    }

    /// Recomputes what a BSDF derives from its parameters (sampling
    /// weights from texture means, roughplastic's transmittance table), as
    /// Mitsuba's `parameters_changed`. Call after updating the store.
    pub fn parameters_changed(&mut self, store: &ParamStore) {
        match self {
            Bsdf::Plastic(b) => b.parameters_changed(store),
            Bsdf::RoughPlastic(b) => b.parameters_changed(store),
            Bsdf::PPlastic(b) => b.parameters_changed(store),
            Bsdf::TwoSided(b) => b.parameters_changed(store),
            Bsdf::BlendBsdf(b) => b.parameters_changed(store),
            Bsdf::Mask(b) => b.parameters_changed(store),
            Bsdf::NormalMap(b) => b.parameters_changed(store),
            Bsdf::BumpMap(b) => b.parameters_changed(store),
            _ => {}
        }
    }
}

// ---------------------------------------------------------------------------
// Helpers shared by the plugins

/// Mitsuba's optional `specular_reflectance` / `specular_transmittance`:
/// an RGB factor in [0, 1] (value or texture) that modulates a specular
/// lobe, present only when given.
pub(crate) fn specular_factor(
    node: &Node,
    name: &str,
    ctx: &mut LoadContext,
) -> Result<Option<Texture>> {
    if node.has(name) {
        Texture::from_prop(node, name, None, Channels::Rgb, Domain::UnitInterval, ctx).map(Some)
    } else {
        Ok(None)
    }
}

/// Both optional specular factors of the dielectric plugins, in the order
/// Mitsuba registers them: (`specular_reflectance`,
/// `specular_transmittance`).
pub(crate) fn specular_factors(
    node: &Node,
    ctx: &mut LoadContext,
) -> Result<(Option<Texture>, Option<Texture>)> {
    let reflectance = specular_factor(node, "specular_reflectance", ctx)?;
    let transmittance = specular_factor(node, "specular_transmittance", ctx)?;
    Ok((reflectance, transmittance))
}

/// An optional specular factor's value at `si` (`None` when the factor
/// was not given).
pub(crate) fn eval_factor<R: ScalarReal>(
    factor: &Option<Texture>,
    store: &ParamView,
    si: &SurfaceInteraction<R>,
) -> Option<Spectrum<R>> {
    factor.as_ref().map(|t| t.eval(store, si))
}

/// `value` times the optional specular factor's value (unchanged when the
/// factor was not given).
pub(crate) fn modulate<R: ScalarReal>(
    value: Spectrum<R>,
    factor: Option<Spectrum<R>>,
) -> Spectrum<R> {
    match factor {
        Some(t) => value.mul_elem(t),
        None => value,
    }
}

/// An index of refraction given as a number or a material name
/// (`"bk7"`, `"water"`, …; see [`fresnel::IOR_TABLE`]).
pub(crate) fn ior_prop(node: &Node, name: &str, default: f32) -> Result<f32> {
    let Some(p) = node.prop(name) else {
        return Ok(default);
    };
    let v = match &p.value {
        Value::Float(v) => *v as f32,
        Value::Int(v) => *v as f32,
        Value::Str(s) => fresnel::lookup_ior(s).ok_or_else(|| {
            let names: Vec<&str> = fresnel::IOR_TABLE.iter().map(|e| e.0).collect();
            node.prop_error(
                p,
                format!("unknown material '{s}'; known: {}", names.join(", ")),
            )
        })?,
        _ => return Err(node.prop_error(p, "must be a number or a material name")),
    };
    if !(v > 0.0) || !v.is_finite() {
        return Err(node.prop_error(p, format!("must be > 0, found {v}")));
    }
    Ok(v)
}

/// The relative index of refraction `int_ior / ext_ior` (defaults as
/// Mitsuba's dielectric plugins: bk7 and air unless given).
pub(crate) fn eta_props(node: &Node, int_default: f32, ext_default: f32) -> Result<f32> {
    let int_ior = ior_prop(node, "int_ior", int_default)?;
    let ext_ior = ior_prop(node, "ext_ior", ext_default)?;
    Ok(int_ior / ext_ior)
}

/// Registers a scalar (non-texture) parameter `<node key>.<name>`, as
/// Mitsuba exposes `eta` of dielectrics and `alpha` of roughplastic.
pub(crate) fn scalar_param(
    node: &Node,
    name: &str,
    value: f32,
    flags: ParamFlags,
    domain: Domain,
    ctx: &mut LoadContext,
) -> Result<ParamId> {
    ctx.store.add(
        format!("{}.{}", node.key, name),
        vec![value],
        vec![1],
        flags,
        domain,
    )
}

/// The nested BSDFs of a wrapper plugin, in file order, each re-keyed to
/// the name Mitsuba's `traverse()` gives it (`brdf_0`, `bsdf_1`,
/// `nested_bsdf`, …) unless it has an id of its own.
pub(crate) fn nested_bsdfs(node: &Node, names: &[&str]) -> Result<Vec<Node>> {
    let kids = node.children(Class::Bsdf);
    if kids.len() > names.len() || kids.is_empty() {
        return Err(node.error(format!(
            "expects {} nested BSDF(s), found {}",
            if names.len() == 1 {
                "one".to_string()
            } else {
                format!("1 to {}", names.len())
            },
            kids.len()
        )));
    }
    Ok(kids
        .iter()
        .zip(names)
        .map(|(k, name)| {
            let key = if k.id.is_some() {
                k.key.clone()
            } else {
                format!("{}.{}", node.key, name)
            };
            rekey(k, &key)
        })
        .collect())
}

/// A copy of `node` whose parameter keys start with `key` instead of its
/// own prefix (nested objects without an id follow).
pub(crate) fn rekey(node: &Node, key: &str) -> Node {
    let mut n = Node::new(
        node.class,
        &node.plugin,
        node.id.clone(),
        key.to_string(),
        node.loc.clone(),
    );
    for p in &node.props {
        let value = match &p.value {
            Value::Node(c) if c.id.is_none() => {
                let suffix = c
                    .key
                    .strip_prefix(&node.key)
                    .map(str::to_string)
                    .unwrap_or_else(|| format!(".{}", p.name));
                Value::Node(Rc::new(rekey(c, &format!("{key}{suffix}"))))
            }
            v => v.clone(),
        };
        n.props
            .push(Prop::new(p.name.clone(), value, p.loc.clone()));
    }
    n
}

/// The sample of a smooth lobe at the already chosen direction `wo`: its
/// density is the BSDF's `pdf(wo)` (all lobes, as the lobe choice is
/// random) and its weight `eval(wo) / pdf`; `None` where the density is 0.
/// `wo` enters as a constant: a sampled direction is a variable of
/// integration, not a function of the parameters.
pub(crate) fn smooth_sample<R: ScalarReal>(
    b: &impl BsdfContextT<R>,
    wo: Vec3,
    eta: f32,
    lobe: BsdfFlags,
) -> Option<BsdfSample<R>> {
    let pdf = b.pdf(wo);
    if !(pdf > 0.0) {
        return None;
    }
    let wo = V3::cst(wo);
    Some(BsdfSample {
        wo,
        pdf,
        weight: b.eval(wo).scale(1.0 / pdf),
        eta,
        lobe,
    })
}

/// The transmitted half of [`sample_reflect_or_transmit`]: direction (in
/// `R`, a function of `si.wi`),
/// R-valued transmitted value (`1 − F`, times any radiance scaling), the
/// relative index along the path and the lobe.
pub(crate) type Transmitted<R> = (V3<R>, R, f32, BsdfFlags);

/// Chooses between the delta reflection and the delta transmission of a
/// smooth interface (`dielectric`, `thindielectric`) with the primal
/// probabilities `F` and `1 − F` of its R-valued reflectance `f`. The
/// reflected weight is `F / F` times `specular_reflectance`, the
/// transmitted one `value / (1 − F)` times `specular_transmittance`.
/// `None` when the transmission was chosen but has probability 0.
pub(crate) fn sample_reflect_or_transmit<R: ScalarReal>(
    wi: V3<R>,
    f: R,
    specular_reflectance: Option<Spectrum<R>>,
    specular_transmittance: Option<Spectrum<R>>,
    u1: f32,
    transmitted: Transmitted<R>,
) -> Option<BsdfSample<R>> {
    let r = f.val();
    let t = 1.0 - r;
    if u1 < r {
        let w = modulate(V3::splat(f / r), specular_reflectance);
        return Some(BsdfSample::specular_reflection(wi, r, w));
    }
    if !(t > 0.0) {
        return None;
    }
    let (wo, value, eta, lobe) = transmitted;
    Some(BsdfSample {
        wo,
        pdf: t,
        weight: modulate(V3::splat(value / t), specular_transmittance),
        eta,
        lobe,
    })
}

/// Where `u` (uniform on [0, 1)) lands inside the sub-interval
/// `[start, start + width)` it fell in, rescaled to [0, 1) for reuse by
/// the chosen component (`blendbsdf`, `mask`).
pub(crate) fn reuse_uniform(u: f32, start: f32, width: f32) -> f32 {
    ((u - start) / width).min(1.0 - f32::EPSILON)
}

/// A component's sample scaled by the probability `prob` (primal) /
/// `prob_r` (differentiable) with which the component was chosen: the
/// density times `prob`, the weight times `prob_r / prob`.
pub(crate) fn chosen_with<R: ScalarReal>(
    mut bs: BsdfSample<R>,
    prob: f32,
    prob_r: R,
) -> BsdfSample<R> {
    bs.pdf *= prob;
    bs.weight *= prob_r / prob;
    bs
}

/// Mitsuba's default `eval_diffuse_reflectance`: `π f(wi, +z) cos`, used
/// as the albedo of BSDFs without a diffuse colour.
pub(crate) fn default_albedo<R: ScalarReal>(b: &impl BsdfContextT<R>) -> Spectrum<R> {
    b.eval(V3::cst(Vec3::Z)).scale(std::f32::consts::PI)
}

#[cfg(test)]
mod tests {
    use super::test_util::*;
    use super::*;
    use crate::ad::Dual;

    #[test]
    fn unknown_plugins_are_errors_listing_the_known_ones() {
        let n = node_with_key("principled2", "b", &[]);
        let e = Bsdf::from_node(&n, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown BSDF plugin 'principled2'") && e.contains("roughplastic"),
            "{e}"
        );
        let n = node_with_key("diffuse", "b", &[("reflectanse", float(0.3))]);
        let e = Bsdf::from_node(&n, &mut LoadContext::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown parameter 'reflectanse'"), "{e}");
    }

    /// A BSDF whose context would not fit in a [`BsdfContext`] is refused
    /// when loaded.
    #[test]
    fn bsdfs_nested_beyond_the_context_size_are_refused() {
        // k blends of a blend and a diffuse: 2k + 1 nodes
        fn blends(key: &str, k: usize) -> Node {
            if k == 0 {
                return node_with_key("diffuse", key, &[]);
            }
            let inner = blends(&format!("{key}.a"), k - 1);
            node_with_key(
                "blendbsdf",
                key,
                &[
                    ("weight", float(0.5)),
                    ("a", Value::Node(Rc::new(inner))),
                    ("c", nested(key, "c", "diffuse", &[])),
                ],
            )
        }
        let fits = blends("b", (MAX_CONTEXT_NODES - 1) / 2);
        let b = Bsdf::from_node(&fits, &mut LoadContext::default()).unwrap();
        assert_eq!(b.context_len(), MAX_CONTEXT_NODES - 1);
        let e = Bsdf::from_node(&blends("b", MAX_CONTEXT_NODES / 2), &mut Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nests 9 BSDFs") && e.contains("at most 8"),
            "{e}"
        );
    }

    /// One configuration of every plugin.
    fn all_plugins() -> Vec<(&'static str, Vec<(&'static str, Value)>)> {
        vec![
            ("diffuse", vec![]),
            ("conductor", vec![("material", string("Cu"))]),
            (
                "roughconductor",
                vec![("distribution", string("ggx")), ("material", string("Au"))],
            ),
            ("dielectric", vec![]),
            ("thindielectric", vec![]),
            ("roughdielectric", vec![("alpha", float(0.3))]),
            ("plastic", vec![]),
            ("roughplastic", vec![("distribution", string("ggx"))]),
            ("pplastic", vec![("alpha", float(0.2))]),
            (
                "principled",
                vec![
                    ("metallic", float(0.3)),
                    ("spec_trans", float(0.4)),
                    ("clearcoat", float(0.5)),
                    ("sheen", float(0.6)),
                ],
            ),
            (
                "principledthin",
                vec![("spec_trans", float(0.4)), ("diff_trans", float(0.8))],
            ),
            ("null", vec![]),
            (
                "twosided",
                vec![("bsdf", nested("b", "bsdf", "roughconductor", &[]))],
            ),
            ("mask", vec![("bsdf", nested("b", "bsdf", "plastic", &[]))]),
            (
                "normalmap",
                vec![
                    ("normalmap", rgb(0.6, 0.35, 0.9)),
                    ("bsdf", nested("b", "bsdf", "roughconductor", &[])),
                ],
            ),
            (
                "blendbsdf",
                vec![
                    ("weight", float(0.4)),
                    ("a", nested("b", "a", "diffuse", &[])),
                    ("c", nested("b", "c", "roughplastic", &[])),
                ],
            ),
        ]
    }

    /// Every plugin gives bit-identical primal values in f32 and Dual
    /// (eval, and sample weights / pdfs / directions).
    #[test]
    fn f32_and_dual_primals_are_identical() {
        let plugins = all_plugins();
        let wis = [dir(0.8, 0.3), dir(0.3, 2.0), dir(-0.6, 1.0)];
        for (plugin, props) in &plugins {
            let (b, store) = build(plugin, props);
            for wi in wis {
                let (sf, sd) = (si::<f32>(wi), si::<Dual>(wi));
                for k in 0..16 {
                    let u1 = (k as f32 + 0.5) / 16.0;
                    let u2 = Vec2::new(
                        (k * 7 % 16) as f32 / 16.0 + 0.01,
                        (k * 5 % 16) as f32 / 16.0 + 0.02,
                    );
                    let a = b.context(&store.primal(), &sf).sample(u1, u2);
                    let d = b.context(&store.primal(), &sd).sample(u1, u2);
                    match (a, d) {
                        (None, None) => {}
                        (Some(a), Some(d)) => {
                            assert_eq!(
                                (a.wo.val(), a.pdf, a.lobe, a.eta),
                                (d.wo.val(), d.pdf, d.lobe, d.eta),
                                "{plugin}"
                            );
                            assert_eq!(a.weight.val(), d.weight.val(), "{plugin}");
                            let fa = b.context(&store.primal(), &sf).eval(a.wo).val();
                            let fd = b
                                .context(&store.primal(), &sd)
                                .eval(V3::cst(a.wo.val()))
                                .val();
                            assert_eq!(fa, fd, "{plugin}");
                        }
                        (a, d) => panic!("{plugin}: {a:?} vs {d:?}"),
                    }
                }
            }
        }
    }

    /// Every plugin is differentiable in `si.wi` and `wo`: eval, and the
    /// directions and values of delta samples (the smooth plugins are also
    /// checked in each of their own test configurations, by
    /// `check_smooth`).
    #[test]
    fn direction_derivatives_match_finite_differences() {
        for (plugin, props) in &all_plugins() {
            let (b, store) = build(plugin, props);
            check_direction_derivatives(&b, &store, 11);
        }
    }

    /// The pass-through weights shadow rays carry through a surface, as
    /// Mitsuba 3.9 (`scalar_rgb`) gives them by `eval_null_transmission`
    /// at wi = (0.6, 0, 0.8): a thin dielectric's transmission (times
    /// `specular_transmittance`), a mask's transparency plus its nested
    /// BSDF's through its opacity, a blend's mixture; none for BSDFs
    /// without the lobe.
    #[test]
    fn null_transmission_matches_mitsuba() {
        let thin = || nested("b", "bsdf", "thindielectric", &[]);
        let cases = [
            ("null", vec![], Vec3::ONE),
            ("thindielectric", vec![], Vec3::splat(0.91488)),
            (
                "thindielectric",
                vec![
                    ("specular_transmittance", rgb(0.5, 0.2, 1.0)),
                    ("specular_reflectance", float(0.3)),
                ],
                Vec3::new(0.45744, 0.182976, 0.91488),
            ),
            (
                "mask",
                vec![
                    ("opacity", float(0.3)),
                    ("bsdf", nested("b", "bsdf", "diffuse", &[])),
                ],
                Vec3::splat(0.7),
            ),
            (
                "mask",
                vec![("opacity", float(0.3)), ("bsdf", thin())],
                Vec3::splat(0.974464),
            ),
            (
                "blendbsdf",
                vec![
                    ("weight", float(0.3)),
                    ("a", thin()),
                    ("b", nested("b", "b2", "diffuse", &[])),
                ],
                Vec3::splat(0.640416),
            ),
            ("dielectric", vec![], Vec3::ZERO),
            (
                "principledthin",
                vec![("spec_trans", float(0.5))],
                Vec3::ZERO,
            ),
        ];
        for (plugin, props, want) in cases {
            let (b, store) = build(plugin, &props);
            let got = b
                .context(&store.primal(), &si::<f32>(dir(0.8, 0.0)))
                .null_transmission()
                .val();
            assert!(
                (got - want).abs().max_element() < 1e-5,
                "{plugin} {props:?}: {got}, Mitsuba {want}"
            );
        }
    }
}
