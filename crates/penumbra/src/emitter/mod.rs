//! The emitter family. Radiance is RGB; sampling is detached (f32), the
//! returned weights (`radiance / pdf`) are differentiable in `R`.

mod area;
mod constant;
mod directional;
mod envmap;
mod point;
mod projector;
mod spot;

pub use area::Area;
pub use constant::Constant;
pub use directional::Directional;
pub use envmap::Envmap;
pub use point::Point;
pub use projector::Projector;
pub use spot::Spot;

use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::{Shape, SurfaceInteraction};
use crate::math::{Frame, Spectrum, Transform, V2, V3};
use crate::params::{Domain, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// A sphere enclosing the scene: environment and directional emitters
/// place their sample points outside it.
#[derive(Clone, Copy, Debug)]
pub struct BoundingSphere {
    pub center: Vec3,
    pub radius: f32,
}

impl Default for BoundingSphere {
    /// The unit sphere (Mitsuba's default until the scene is known).
    fn default() -> Self {
        BoundingSphere {
            center: Vec3::ZERO,
            radius: 1.0,
        }
    }
}

/// A point beyond the scene from `ref_p` along unit `d`: at twice the
/// larger of the bounding radius and the distance of `ref_p` from its
/// centre (as Mitsuba places environment samples).
#[inline]
pub(crate) fn far_point(bs: &BoundingSphere, ref_p: Vec3, d: Vec3) -> Vec3 {
    let r = bs.radius.max((ref_p - bs.center).length());
    ref_p + d * (2.0 * r)
}

/// A surface interaction at an emitter point (for texture lookups by uv):
/// position `p`, unit normal `n`, `wi_world` the unit direction leaving
/// the surface.
#[inline(always)]
pub(crate) fn surface_si<R: ScalarReal>(
    p: Vec3,
    n: Vec3,
    uv: Vec2,
    wi_world: Vec3,
    shape: u32,
    prim: u32,
) -> SurfaceInteraction<R> {
    let frame = Frame::from_normal(V3::cst(n));
    let wi = frame.to_local(V3::cst(wi_world));
    SurfaceInteraction {
        t: R::cst(0.0),
        p: V3::cst(p),
        n: V3::cst(n),
        sh_frame: frame,
        uv: V2::cst(uv),
        dp_du: V3::zero(),
        dp_dv: V3::zero(),
        wi,
        area_scale: R::cst(1.0),
        shape,
        prim,
        vertices: [0; 3],
        bary: V2::zero(),
    }
}

/// Emission texture `t` at a point that does not move, whose interaction
/// `si` builds: only for textures that read it. A plain value (the usual
/// case: a constant environment, evaluated for every ray that leaves the
/// scene, or an area light's uniform radiance at each of its samples)
/// needs none.
#[inline]
pub(crate) fn eval_at<R: ScalarReal>(
    t: &Texture,
    store: &ParamView,
    si: impl FnOnce() -> SurfaceInteraction<f32>,
) -> Spectrum<R> {
    match t {
        Texture::Uniform(u) => u.value(store),
        t => t.eval(store, &SurfaceInteraction::cst(&si())),
    }
}

/// A texture evaluated where position does not matter (uniform values of
/// point, spot, directional and constant emitters): at uv = (0, 0).
#[inline]
pub(crate) fn eval_uniform<R: ScalarReal>(t: &Texture, store: &ParamView) -> Spectrum<R> {
    eval_at(t, store, || {
        surface_si(Vec3::ZERO, Vec3::Z, Vec2::ZERO, Vec3::Z, 0, 0)
    })
}

/// The emitted quantity `name` of a light (`radiance`, `intensity`,
/// `irradiance`): an RGB value or texture, non-negative, default 1, keyed
/// `<key>.<name>.value` for a value.
pub(crate) fn emission_prop(node: &Node, name: &str, ctx: &mut LoadContext) -> Result<Texture> {
    Texture::from_prop(
        node,
        name,
        Some(1.0),
        Channels::Rgb,
        Domain::NonNegative,
        ctx,
    )
}

/// A light's placement given either directly as the vector parameter
/// `name` (`position` of `point`, `direction` of `directional`) or through
/// `to_world` (mapped by `from_to_world`); giving both is an error, as in
/// Mitsuba.
pub(crate) fn vec3_or_to_world(
    node: &Node,
    name: &str,
    from_to_world: impl FnOnce(&Transform) -> Vec3,
) -> Result<Vec3> {
    match (node.vec3_opt(name)?, node.has("to_world")) {
        (Some(_), true) => Err(node.error(format!(
            "only one of the parameters '{name}' and 'to_world' can be given"
        ))),
        (Some(v), false) => Ok(v),
        (None, _) => Ok(from_to_world(&node.transform("to_world")?)),
    }
}

/// The direction sample of a light at the point `p` (point, spot, projector) seen
/// from `ref_p`: unit direction and distance to `p`, pdf 1, delta, no
/// normal; with the direction and squared distance (for the inverse-square
/// falloff) in `R`, following the reference point and the light. `None`
/// when `ref_p` is at the light.
pub(crate) fn point_light_sample<R: ScalarReal>(
    p: V3<R>,
    ref_p: V3<R>,
) -> Option<(DirectionSample, V3<R>, R)> {
    let to = p - ref_p;
    let dist2 = to.length_squared();
    if !(dist2.val() > 0.0) {
        return None;
    }
    let d = to / dist2.sqrt();
    let ds = DirectionSample {
        p: p.val(),
        n: Vec3::ZERO,
        d: d.val(),
        dist: dist2.val().sqrt(),
        pdf: 1.0,
        delta: true,
    };
    Some((ds, d, dist2))
}

/// The [`EmitterT`] queries of a delta light (`point`, `spot`,
/// `directional`), written inside its `impl EmitterT`: no ray can hit it,
/// so its direction density and its surface and environment radiance are
/// zero; `is_delta` is true, `is_environment` false.
macro_rules! delta_light_queries {
    () => {
        fn pdf_direction(
            &self,
            _: &$crate::params::ParamStore,
            _: &[$crate::geometry::Shape],
            _: glam::Vec3,
            _: glam::Vec3,
            _: glam::Vec3,
            _: glam::Vec3,
        ) -> f32 {
            0.0
        }
        fn eval_surface<R: $crate::ad::ScalarReal>(
            &self,
            _: &$crate::params::ParamView,
            _: &$crate::geometry::SurfaceInteraction<R>,
        ) -> $crate::math::Spectrum<R> {
            $crate::math::V3::zero()
        }
        fn eval_environment<R: $crate::ad::ScalarReal>(
            &self,
            _: &$crate::params::ParamView,
            _: $crate::math::V3<R>,
        ) -> $crate::math::Spectrum<R> {
            $crate::math::V3::zero()
        }
        fn is_delta(&self) -> bool {
            true
        }
        fn is_environment(&self) -> bool {
            false
        }
    };
}
pub(crate) use delta_light_queries;

/// An emitter sample in `R`: the primal sample, the unit direction from the
/// reference point to the sampled point, and the weight `radiance / pdf`,
/// both attached to the reference point and the emitter's parameters (the
/// sampled point moves with the emitter; the density is a constant).
#[derive(Clone, Copy, Debug)]
pub struct EmitterSample<R> {
    pub ds: DirectionSample,
    pub d: V3<R>,
    pub weight: Spectrum<R>,
}

impl<R: ScalarReal> EmitterSample<R> {
    /// A sample whose direction does not move (environment and
    /// directional emitters: their points are at infinity).
    pub(crate) fn fixed_direction(ds: DirectionSample, weight: Spectrum<R>) -> Self {
        EmitterSample {
            d: V3::cst(ds.d),
            ds,
            weight,
        }
    }
}

/// A direction sampled towards an emitter from a reference point.
#[derive(Clone, Copy, Debug)]
pub struct DirectionSample {
    /// Point on the emitter (for environment emitters: far away along `d`).
    pub p: Vec3,
    /// Emitter surface normal at `p` (zero for point-like and environment
    /// emitters).
    pub n: Vec3,
    /// Unit direction from the reference point to `p`.
    pub d: Vec3,
    /// Distance to `p` (infinite for environment/directional emitters).
    pub dist: f32,
    /// Solid-angle density (for delta emitters: 1).
    pub pdf: f32,
    /// True for emitters that cannot be hit by rays (point, spot, projector,
    /// directional): no MIS with BSDF sampling.
    pub delta: bool,
}

/// What every emitter plugin provides.
pub trait EmitterT {
    /// Samples a direction from `ref_p` towards the emitter. Returns the
    /// sample and `radiance / pdf` (visibility not included).
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        shapes: &[Shape],
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>>;
    /// Solid-angle density of sampling the emitter point hit along `d` from
    /// `ref_p` (`p`, `n`: the hit point and its normal; unused by
    /// environment emitters).
    fn pdf_direction(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        d: Vec3,
        p: Vec3,
        n: Vec3,
    ) -> f32;
    /// Radiance leaving a surface emitter at `si` towards `si.wi`.
    fn eval_surface<R: ScalarReal>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> Spectrum<R>;
    /// Radiance arriving from infinity along ray direction `d` (environment
    /// emitters; zero for others), in `R`: the direction follows the camera
    /// or a specular chain when they move.
    fn eval_environment<R: ScalarReal>(&self, store: &ParamView, d: V3<R>) -> Spectrum<R>;
    /// True for point, spot, projector and directional emitters.
    fn is_delta(&self) -> bool;
    /// True for constant and envmap emitters.
    fn is_environment(&self) -> bool;
}

/// All emitter plugins.
#[derive(Clone, Debug)]
pub enum Emitter {
    Area(Area),
    Point(Point),
    Spot(Spot),
    Projector(Projector),
    Directional(Directional),
    Constant(Constant),
    Envmap(Envmap),
}

macro_rules! dispatch {
    ($self:expr, $e:ident => $body:expr) => {
        match $self {
            Emitter::Area($e) => $body,
            Emitter::Point($e) => $body,
            Emitter::Spot($e) => $body,
            Emitter::Projector($e) => $body,
            Emitter::Directional($e) => $body,
            Emitter::Constant($e) => $body,
            Emitter::Envmap($e) => $body,
        }
    };
}

impl EmitterT for Emitter {
    #[inline]
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        shapes: &[Shape],
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>> {
        dispatch!(self, e => e.sample_direction(store, shapes, ref_p, u))
    }
    #[inline]
    fn pdf_direction(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        d: Vec3,
        p: Vec3,
        n: Vec3,
    ) -> f32 {
        dispatch!(self, e => e.pdf_direction(store, shapes, ref_p, d, p, n))
    }
    #[inline]
    fn eval_surface<R: ScalarReal>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> Spectrum<R> {
        dispatch!(self, e => e.eval_surface(store, si))
    }
    #[inline]
    fn eval_environment<R: ScalarReal>(&self, store: &ParamView, d: V3<R>) -> Spectrum<R> {
        dispatch!(self, e => e.eval_environment(store, d))
    }
    fn is_delta(&self) -> bool {
        dispatch!(self, e => e.is_delta())
    }
    fn is_environment(&self) -> bool {
        dispatch!(self, e => e.is_environment())
    }
}

/// Where the light of a delta emitter comes from: all its rays leave one
/// point, or all travel along one direction.
#[derive(Clone, Copy, Debug)]
pub enum DeltaOrigin<R> {
    Point(V3<R>),
    Direction(Vec3),
}

impl Emitter {
    /// The origin of a point, spot, projector or directional emitter's light, in `R`
    /// (a point light's `position` is a parameter); `None` for the others.
    pub(crate) fn delta_origin<R: ScalarReal>(&self, store: &ParamView) -> Option<DeltaOrigin<R>> {
        match self {
            Emitter::Point(p) => Some(DeltaOrigin::Point(store.read3(p.position, 0))),
            Emitter::Spot(s) => Some(DeltaOrigin::Point(V3::cst(s.to_world.point(Vec3::ZERO)))),
            Emitter::Projector(p) => {
                Some(DeltaOrigin::Point(V3::cst(p.to_world.point(Vec3::ZERO))))
            }
            Emitter::Directional(d) => Some(DeltaOrigin::Direction(d.direction)),
            _ => None,
        }
    }

    /// Builds an `<emitter>` node (and checks that all its parameters were
    /// used). `shape` is the index of the shape an area emitter is
    /// attached to (`None` at scene level). Every plugin also accepts
    /// Mitsuba's `sampling_weight`; [`Emitter::from_node_weighted`]
    /// returns it.
    pub fn from_node(node: &Node, shape: Option<u32>, ctx: &mut LoadContext) -> Result<Emitter> {
        Ok(Emitter::from_node_weighted(node, shape, ctx)?.0)
    }

    /// As [`Emitter::from_node`], also returning Mitsuba's
    /// `sampling_weight` (default 1), the relative probability of choosing
    /// this emitter for light sampling.
    pub fn from_node_weighted(
        node: &Node,
        shape: Option<u32>,
        ctx: &mut LoadContext,
    ) -> Result<(Emitter, f32)> {
        let weight = node.float_checked("sampling_weight", 1.0, false)?;
        let e = match node.plugin.as_str() {
            "area" => {
                let Some(shape) = shape else {
                    return Err(node.error(
                        "an area emitter must be nested inside a shape (<shape> ... <emitter type=\"area\"> ...)",
                    ));
                };
                Emitter::Area(Area::from_node(node, shape, ctx)?)
            }
            "point" => Emitter::Point(Point::from_node(node, ctx)?),
            "spot" => Emitter::Spot(Spot::from_node(node, ctx)?),
            "projector" => Emitter::Projector(Projector::from_node(node, ctx)?),
            "directional" => Emitter::Directional(Directional::from_node(node, ctx)?),
            "constant" => Emitter::Constant(Constant::from_node(node, ctx)?),
            "envmap" => Emitter::Envmap(Envmap::from_node(node, ctx)?),
            _ => {
                return Err(node.error(format!(
                    "unknown emitter plugin '{}' (Penumbra has: area, point, spot, projector, directional, constant, envmap)",
                    node.plugin
                )))
            }
        };
        if shape.is_some() && !matches!(e, Emitter::Area(_)) {
            return Err(node.error(format!(
                "a '{}' emitter cannot be attached to a shape; only 'area' can",
                node.plugin
            )));
        }
        node.check_all_used()?;
        Ok((e, weight))
    }

    /// Tells environment and directional emitters the scene's bounding
    /// sphere (they place sample points outside it). Call once the scene's
    /// geometry is known; without it the unit sphere is assumed.
    pub fn set_scene_bounds(&mut self, center: Vec3, radius: f32) {
        let bs = BoundingSphere {
            center,
            radius: radius.max(crate::math::RAY_EPSILON) * (1.0 + crate::math::RAY_EPSILON),
        };
        match self {
            Emitter::Directional(e) => e.bounds = bs,
            Emitter::Constant(e) => e.bounds = bs,
            Emitter::Envmap(e) => e.bounds = bs,
            _ => {}
        }
    }

    /// Refreshes what depends on parameter values (the envmap's sampling
    /// density) after the parameters `changed` were updated in `store`.
    pub fn parameters_changed(&mut self, store: &ParamStore, changed: &[ParamId]) {
        if let Emitter::Envmap(e) = self {
            if changed.contains(&e.data) {
                e.rebuild_distribution(store);
            }
        }
    }

    /// The shape an area emitter is attached to.
    pub fn shape(&self) -> Option<u32> {
        match self {
            Emitter::Area(a) => Some(a.shape),
            _ => None,
        }
    }
}

/// Helpers shared by the emitter tests.
#[cfg(test)]
pub(crate) mod test_util {
    use super::*;
    use crate::error::SrcLoc;
    use crate::scene::description::{Class, Prop, Value};

    /// An `<emitter>` node with the given properties at `test.xml:1`.
    pub fn node(plugin: &str, key: &str, props: Vec<(&str, Value)>) -> Node {
        let loc = SrcLoc {
            file: "/tmp/test.xml".into(),
            line: 1,
        };
        let mut n = Node::new(Class::Emitter, plugin, None, key.into(), loc.clone());
        for (name, v) in props {
            n.props.push(Prop::new(name, v, loc.clone()));
        }
        n
    }

    /// p-value threshold of the χ² tests in this module: 10⁻³ spread over
    /// the (at most 5) sampling tests that run.
    pub const CHI2_ALPHA: f64 = 1e-3 / 5.0;
}
