//! The texture family: spatially varying reflectance, roughness, radiance.
//! Texel data lives in the parameter store (`<key>.data`, shape
//! `[h, w, c]`), uniform values in `<key>.value`.

pub mod bitmap;
mod checkerboard;
mod mesh_attribute;
mod uniform;

pub use bitmap::{Bitmap, FilterType, WrapMode};
#[cfg(test)]
pub(crate) use checkerboard::EVALS as CHECKERBOARD_EVALS;
pub use checkerboard::{Checkerboard, MITSUBA_EVAL1_SWAPS_COLORS};
pub use mesh_attribute::MeshAttribute;
pub use uniform::Uniform;

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::Spectrum;
use crate::params::{Domain, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node, Value};
use std::collections::HashMap;

/// What every texture plugin provides.
pub trait TextureT {
    /// RGB value at the interaction's uv.
    fn eval<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R>;
    /// Scalar value at the interaction's uv (first channel, or the
    /// luminance-free mean for RGB data, as Mitsuba's `eval_1`).
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R;
    /// Mean over the texture (for sampling heuristics), primal only.
    fn mean(&self, store: &ParamStore) -> f32;
    /// Largest value over the texture, primal only.
    fn max(&self, store: &ParamStore) -> f32;
}

/// All texture plugins.
#[derive(Clone, Debug)]
pub enum Texture {
    Uniform(Uniform),
    Bitmap(Bitmap),
    Checkerboard(Checkerboard),
    MeshAttribute(MeshAttribute),
}

impl TextureT for Texture {
    #[inline]
    fn eval<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        match self {
            Texture::Uniform(t) => t.eval(store, si),
            Texture::Bitmap(t) => t.eval(store, si),
            Texture::Checkerboard(t) => t.eval(store, si),
            Texture::MeshAttribute(t) => t.eval(store, si),
        }
    }
    #[inline]
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        match self {
            Texture::Uniform(t) => t.eval_1(store, si),
            Texture::Bitmap(t) => t.eval_1(store, si),
            Texture::Checkerboard(t) => t.eval_1(store, si),
            Texture::MeshAttribute(t) => t.eval_1(store, si),
        }
    }
    fn mean(&self, store: &ParamStore) -> f32 {
        match self {
            Texture::Uniform(t) => t.mean(store),
            Texture::Bitmap(t) => t.mean(store),
            Texture::Checkerboard(t) => t.mean(store),
            Texture::MeshAttribute(t) => t.mean(store),
        }
    }
    fn max(&self, store: &ParamStore) -> f32 {
        match self {
            Texture::Uniform(t) => t.max(store),
            Texture::Bitmap(t) => t.max(store),
            Texture::Checkerboard(t) => t.max(store),
            Texture::MeshAttribute(t) => t.max(store),
        }
    }
}

impl Texture {
    /// The parameters this texture reads (values, texels, uv transforms),
    /// or `None` where they are not known from the texture alone (a mesh
    /// attribute is the shape's).
    pub(crate) fn param_ids(&self) -> Option<Vec<ParamId>> {
        match self {
            Texture::Uniform(t) => Some(vec![t.id]),
            Texture::Bitmap(t) => Some(vec![t.data, t.to_uv]),
            Texture::Checkerboard(t) => {
                let mut ids = t.color0.param_ids()?;
                ids.extend(t.color1.param_ids()?);
                ids.push(t.to_uv);
                Some(ids)
            }
            Texture::MeshAttribute(_) => None,
        }
    }
}

/// How a texture-valued property is stored when given as a plain value.
#[derive(Clone, Copy, Debug)]
pub enum Channels {
    /// One value (roughness, weight): `<float>`.
    Mono,
    /// RGB (reflectance, radiance): `<rgb>`, `<spectrum>` or `<float>`.
    Rgb,
}

/// The textures built from nodes with an id while a scene loads, shared
/// by every use (their parameters exist once in the store).
#[derive(Default)]
struct SharedTextures(HashMap<*const Node, Texture>);

/// The `mesh_attribute` textures built (or reused) since the scene's
/// builder last took them: it checks them against the shape they are used
/// on.
#[derive(Default)]
pub(crate) struct AttributeUses(pub(crate) Vec<MeshAttribute>);

impl Texture {
    /// The texture for property `name` of `node`: a nested `<texture>`, a
    /// reference to one, or a plain value (`<float>`, `<rgb>`,
    /// `<spectrum>`), which becomes a uniform texture with parameter key
    /// `<node key>.<name>.value`. `default` is used when the property is
    /// absent; `None` makes it required.
    pub fn from_prop(
        node: &Node,
        name: &str,
        default: Option<f32>,
        channels: Channels,
        domain: Domain,
        ctx: &mut LoadContext,
    ) -> Result<Texture> {
        let key = format!("{}.{}", node.key, name);
        let Some(p) = node.prop(name) else {
            return match default {
                Some(v) => Uniform::new(&key, channels, glam::Vec3::splat(v), domain, ctx)
                    .map(Texture::Uniform),
                None => Err(node.error(format!("missing required parameter '{name}'"))),
            };
        };
        let value = match &p.value {
            Value::Float(v) => glam::Vec3::splat(*v as f32),
            Value::Spectrum(v) => glam::Vec3::splat(*v),
            Value::Rgb(v) => match channels {
                Channels::Rgb => *v,
                Channels::Mono => {
                    return Err(node.prop_error(p, "must be a float or a texture, found an rgb"))
                }
            },
            Value::Node(n) => return Texture::from_node(n, domain, ctx),
            _ => return Err(node.prop_error(p, "must be a float, rgb, spectrum or texture")),
        };
        Uniform::new(&key, channels, value, domain, ctx)
            .map(Texture::Uniform)
            .map_err(|e| node.prop_error(p, e))
    }

    /// Builds a `<texture>` node (and checks that all its parameters were
    /// used). `domain` is the valid range of the slot it fills (a
    /// reflectance: [0, 1]); its parameters get it, so that optimisers
    /// project them into it. A texture shared by id keeps the domain of
    /// its first use.
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Texture> {
        let shared = node.id.is_some().then_some(node as *const Node);
        let t = match shared.and_then(|p| ctx.state::<SharedTextures>().0.get(&p)) {
            Some(t) => t.clone(),
            None => {
                let t = Texture::new(node, domain, ctx)?;
                if let Some(p) = shared {
                    ctx.state::<SharedTextures>().0.insert(p, t.clone());
                }
                t
            }
        };
        // every use, shared or not: the builder checks each shape using it
        if let Texture::MeshAttribute(m) = &t {
            ctx.state::<AttributeUses>().0.push(m.clone());
        }
        Ok(t)
    }

    fn new(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Texture> {
        let t = match node.plugin.as_str() {
            "bitmap" => Texture::Bitmap(Bitmap::from_node(node, domain, ctx)?),
            "checkerboard" => Texture::Checkerboard(Checkerboard::from_node(node, domain, ctx)?),
            "mesh_attribute" => Texture::MeshAttribute(MeshAttribute::from_node(node)?),
            _ => {
                return Err(node.error(format!(
                    "unknown texture plugin '{}' (Penumbra has: bitmap, checkerboard, \
                     mesh_attribute)",
                    node.plugin
                )))
            }
        };
        node.check_all_used()?;
        Ok(t)
    }
}

/// A surface interaction at `uv` (on the z = 0 plane, normal +z, viewed
/// from above), for texture tests.
#[cfg(test)]
pub(crate) fn si_at_uv<R: ScalarReal>(u: f32, v: f32) -> SurfaceInteraction<R> {
    use crate::math::{Frame, V2, V3};
    let n = V3::cst(glam::Vec3::Z);
    SurfaceInteraction {
        t: R::cst(1.0),
        p: V3::cst(glam::Vec3::new(u, v, 0.0)),
        n,
        sh_frame: Frame::from_normal(n),
        uv: V2::cst(glam::Vec2::new(u, v)),
        dp_du: V3::cst(glam::Vec3::X),
        dp_dv: V3::cst(glam::Vec3::Y),
        wi: V3::cst(glam::Vec3::Z),
        area_scale: R::cst(1.0),
        shape: 0,
        prim: 0,
        vertices: [0; 3],
        bary: V2::zero(),
    }
}

/// A node with the given properties, declared at `test.xml:1`.
#[cfg(test)]
pub(crate) fn test_node(
    class: crate::scene::description::Class,
    plugin: &str,
    key: &str,
    props: Vec<(&str, Value)>,
) -> Node {
    use crate::error::SrcLoc;
    let loc = SrcLoc {
        file: "/tmp/test.xml".into(),
        line: 1,
    };
    let mut n = Node::new(class, plugin, Some(key.into()), key.into(), loc.clone());
    for (name, v) in props {
        n.props
            .push(crate::scene::description::Prop::new(name, v, loc.clone()));
    }
    n
}
