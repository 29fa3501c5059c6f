//! `normalmap`: a nested BSDF seen through a shading frame whose normal an
//! RGB texture gives (Mitsuba 3's `src/bsdfs/normalmap.cpp`). The frame
//! perturbation and the evaluation in the perturbed frame are shared with
//! `bumpmap`, which only derives the normal differently.

use super::{
    nested_bsdfs, smooth_sample, Bsdf, BsdfContextT, BsdfFlags, BsdfSample, BsdfT, NestedContext,
    NodeContext,
};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{Frame, Spectrum, V3};
use crate::params::{Domain, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{Channels, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Normal mapping: the texture `normalmap` (RGB in [0, 1], usually a
/// bitmap with `raw` set) encodes the shading normal relative to the
/// shading frame, each component mapped by x ↦ (x + 1) / 2; (0.5, 0.5, 1)
/// leaves the surface unchanged. Parameter keys as Mitsuba's:
/// `<key>.normalmap.data` (texels, differentiable) and
/// `<key>.nested_bsdf.*`. Mitsuba 3.7.1's options (see [`Perturbation`]):
/// `flip_invalid_normals`, `use_shadowing_function` (both default true).
#[derive(Clone, Debug)]
pub struct NormalMap {
    pub nested: Box<Bsdf>,
    pub normalmap: Texture,
    pub options: Perturbation,
}

/// How `normalmap` and `bumpmap` treat their perturbed normal (Mitsuba
/// 3.7.1 and later, `src/bsdfs/normalmap.cpp`, `normalmap_helpers.h`).
#[derive(Clone, Copy, Debug)]
pub struct Perturbation {
    /// `flip_invalid_normals`: a normal on the other side of `wi` than the
    /// shading normal is mirrored through it (x, y negated), after
    /// Schüssler et al. 2017.
    pub flip_invalid_normals: bool,
    /// `use_shadowing_function`: values and sample weights are attenuated
    /// by the microfacet shadowing term of Conty Estevez, Lecocq and Stein
    /// 2019 (the bump terminator), whose roughness grows with the tilt.
    pub use_shadowing_function: bool,
}

impl Perturbation {
    pub fn from_node(node: &Node) -> Result<Perturbation> {
        Ok(Perturbation {
            flip_invalid_normals: node.bool("flip_invalid_normals", true)?,
            use_shadowing_function: node.bool("use_shadowing_function", true)?,
        })
    }
}

impl NormalMap {
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<NormalMap> {
        let nested = nested_bsdfs(node, &["nested_bsdf"])?;
        let nested = Box::new(Bsdf::from_node(&nested[0], ctx)?);
        let normalmap = Texture::from_prop(
            node,
            "normalmap",
            None,
            Channels::Rgb,
            // any finite encoding decodes to a direction (it is normalised)
            Domain::Finite,
            ctx,
        )?;
        let options = Perturbation::from_node(node)?;
        Ok(NormalMap {
            nested,
            normalmap,
            options,
        })
    }

    pub fn parameters_changed(&mut self, store: &ParamStore) {
        self.nested.parameters_changed(store);
    }
}

impl BsdfT for NormalMap {
    fn flags(&self) -> BsdfFlags {
        self.nested.flags()
    }

    fn context_len(&self) -> usize {
        1 + self.nested.context_len()
    }

    fn write_context<'a, R: ScalarReal>(
        &'a self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
        nodes: &mut [Option<NodeContext<'a, R>>],
    ) -> usize {
        let n = self.normalmap.eval(store, si).scale(2.0) - V3::splat(R::cst(1.0));
        write_perturbed(&self.nested, store, si, n, self.options, nodes)
    }
}

/// The perturbed shading frame with normal `n` (relative to the shading
/// frame, not necessarily unit), as Mitsuba 3.7.1+ builds it: flipped
/// first if `options` ask and `n` is on the other side of `wi`; a zero or
/// non-finite normal is the shading normal; the first tangent is the
/// shading frame's x made orthogonal to `n` (y where they are parallel).
pub(crate) fn perturbed_frame<R: ScalarReal>(
    n: V3<R>,
    wi: V3<R>,
    options: Perturbation,
) -> Frame<R> {
    let mut n = n;
    if options.flip_invalid_normals && (wi.z * wi.dot(n)).val() <= 0.0 {
        n = V3::new(-n.x, -n.y, n.z);
    }
    let l2 = n.length_squared().val();
    let n = if l2 > 0.0 && l2.is_finite() {
        n.normalize()
    } else {
        V3::cst(Vec3::Z)
    };
    let s = V3::cst(Vec3::X) - n * n.x;
    let s = if s.length_squared().val() > 0.0 {
        s.normalize()
    } else {
        V3::cst(Vec3::Y)
    };
    Frame {
        s,
        t: n.cross(s),
        n,
    }
}

/// Writes the context of a wrapper that evaluates `nested` in the frame
/// of the perturbed normal `n` (relative to the shading frame of `si`,
/// see [`perturbed_frame`]) and, after it, the nested context at `si`
/// seen in that frame.
pub(crate) fn write_perturbed<'a, R: ScalarReal>(
    nested: &'a Bsdf,
    store: &ParamView,
    si: &SurfaceInteraction<R>,
    n: V3<R>,
    options: Perturbation,
    nodes: &mut [Option<NodeContext<'a, R>>],
) -> usize {
    let frame = perturbed_frame(n, si.wi, options);
    let mut perturbed = *si;
    perturbed.sh_frame = Frame {
        s: si.to_world(frame.s),
        t: si.to_world(frame.t),
        n: si.to_world(frame.n),
    };
    perturbed.wi = frame.to_local(si.wi);
    nodes[0] = Some(NodeContext::PerturbedFrame(PerturbedFrameContext {
        frame,
        shadowing: options.use_shadowing_function,
    }));
    1 + nested.write_context(store, &perturbed, &mut nodes[1..])
}

/// Conty Estevez, Lecocq and Stein's shadowing term ("A Microfacet-Based
/// Shadowing Function to Solve the Bump Terminator Problem", Ray Tracing
/// Gems, 2019) for the unit perturbed normal `n` and direction `wo`, both
/// in the shading frame: Smith's G1 of a GGX surface whose α² is ⅛ of the
/// normal's tan² θ (at most 1), as Mitsuba's `eval_shadow_terminator`.
fn shadow_terminator<R: ScalarReal>(n: V3<R>, wo: V3<R>) -> R {
    let tan2 = |v: V3<R>| {
        let z2 = v.z * v.z;
        (R::cst(1.0) - z2).max(R::cst(0.0)) / z2
    };
    let alpha2 = (tan2(n) * 0.125).min(R::cst(1.0));
    R::cst(2.0) / ((alpha2 * tan2(wo) + 1.0).sqrt() + 1.0)
}

/// [`NormalMap`] or [`BumpMap`](super::BumpMap) at a vertex: the perturbed
/// frame in shading coordinates, followed in the
/// [`BsdfContext`](super::BsdfContext) by the nested BSDF's context (built
/// in that frame). As in Mitsuba, a direction scatters only if it is on
/// the same side of both frames: light must not leak through the surface
/// where the perturbed normal tilts a direction across it.
#[derive(Clone, Copy, Debug)]
pub struct PerturbedFrameContext<R: ScalarReal> {
    frame: Frame<R>,
    /// Whether values are attenuated by [`shadow_terminator`].
    shadowing: bool,
}

impl<R: ScalarReal> PerturbedFrameContext<R> {
    pub(crate) fn eval(&self, this: NestedContext<'_, '_, R>, wo: V3<R>) -> Spectrum<R> {
        let wo_p = self.frame.to_local(wo);
        if !(wo.z.val() * wo_p.z.val() > 0.0) {
            return V3::zero();
        }
        let value = this.at(1).eval(wo_p);
        if self.shadowing {
            value * shadow_terminator(self.frame.n, wo)
        } else {
            value
        }
    }

    pub(crate) fn pdf(&self, this: NestedContext<'_, '_, R>, wo: Vec3) -> f32 {
        let wo_p = self.frame.to_local(V3::<R>::cst(wo)).val();
        if !(wo.z * wo_p.z > 0.0) {
            return 0.0;
        }
        this.at(1).pdf(wo_p)
    }

    /// The nested BSDF's sample turned back into the shading frame (its
    /// weight, not its density, shadowed as `eval` is). A
    /// smooth sample's direction is a constant in the shading frame (the
    /// variable of integration), so its weight is re-evaluated there,
    /// where derivatives see the frame move with the texture; a delta
    /// sample's direction follows the frame.
    pub(crate) fn sample(
        &self,
        this: NestedContext<'_, '_, R>,
        u1: f32,
        u2: Vec2,
    ) -> Option<BsdfSample<R>> {
        let mut bs = this.at(1).sample(u1, u2)?;
        let wo = self.frame.to_world(bs.wo);
        if bs.weight.is_zero() || !(bs.wo.z.val() * wo.z.val() > 0.0) {
            return None;
        }
        if BsdfFlags::SMOOTH.has(bs.lobe) {
            return smooth_sample(&this, wo.val(), bs.eta, bs.lobe);
        }
        if self.shadowing {
            bs.weight *= shadow_terminator(self.frame.n, wo);
        }
        bs.wo = wo;
        Some(bs)
    }

    pub(crate) fn albedo(&self, this: NestedContext<'_, '_, R>) -> Spectrum<R> {
        this.at(1).albedo()
    }

    /// None, as in Mitsuba 3, whose `normalmap` and `bumpmap` do not pass
    /// the nested BSDF's on: shadow rays stop at them.
    pub(crate) fn null_transmission(&self, _: NestedContext<'_, '_, R>) -> Spectrum<R> {
        V3::zero()
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_util::*;
    use super::super::{Bsdf, BsdfContextT};
    use crate::ad::Dual;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::LoadContext;
    use crate::texture::TextureT;
    use glam::Vec3;

    fn normalmap(
        rgb_value: (f32, f32, f32),
        nested_plugin: &str,
    ) -> (Bsdf, crate::params::ParamStore) {
        let n = node_with_key(
            "normalmap",
            "nm",
            &[
                ("normalmap", rgb(rgb_value.0, rgb_value.1, rgb_value.2)),
                ("bsdf", nested("nm", "bsdf", nested_plugin, &[])),
            ],
        );
        let mut ctx = LoadContext::default();
        let b = Bsdf::from_node(&n, &mut ctx).unwrap_or_else(|e| panic!("{e}"));
        (b, ctx.store)
    }

    /// The perturbed frame is orthonormal and right-handed, with the
    /// decoded normal (flipped when behind `wi`); (0.5, 0.5, 1) is the
    /// shading normal.
    #[test]
    fn frame_is_orthonormal_with_the_decoded_normal() {
        let si = si::<f32>(dir(0.7, 0.4));
        for (c, want) in [
            ((0.5, 0.5, 1.0), Vec3::Z),
            ((0.8, 0.3, 0.9), Vec3::new(0.6, -0.4, 0.8).normalize()),
            ((0.4, 0.5, 0.6), Vec3::new(-0.2, 0.0, 0.2).normalize()),
            // behind wi: mirrored through the shading normal
            ((0.1, 0.5, 0.6), Vec3::new(0.8, 0.0, 0.2).normalize()),
        ] {
            let (b, store) = normalmap(c, "diffuse");
            let super::super::Bsdf::NormalMap(nm) = &b else {
                unreachable!()
            };
            let n = nm.normalmap.eval(&store.primal(), &si).scale(2.0) - V3::splat(1.0);
            let options = super::Perturbation {
                flip_invalid_normals: true,
                use_shadowing_function: true,
            };
            let f = super::perturbed_frame(n, si.wi, options);
            let (s, t, n) = (f.s.val(), f.t.val(), f.n.val());
            assert!((n - want).length() < 1e-6, "{n} vs {want}");
            for (a, b) in [(s, t), (t, n), (n, s)] {
                assert!(a.dot(b).abs() < 1e-6);
            }
            for v in [s, t, n] {
                assert!((v.length() - 1.0).abs() < 1e-6);
            }
            assert!((s.cross(t) - n).length() < 1e-6);
        }
    }

    /// eval and pdf of a roughplastic seen through a constant normal map,
    /// as Mitsuba 3.9.1 computes them at the test interaction (standard
    /// frame, ∂p/∂u = x): `tilted` (0.7, 0.4, 0.9), `steep` (0.2, 0.75,
    /// 0.6) (none within 0.1 of grazing either frame, where roughplastic's
    /// tables differ); the zero rows are directions the guards reject.
    #[rustfmt::skip]
    #[allow(clippy::excessive_precision)]
    const MITSUBA_ROWS: &[MitsubaRow] = &[
    ("tilted", [5.73201893e-01, 1.77312124e-01, 8.00000000e-01], [4.67915523e-01, 7.28735249e-01, 5.00000000e-01], [6.86106235e-02, 6.86106235e-02, 6.86106235e-02], 1.41669899e-01),
    ("tilted", [-3.32917469e-01, 7.27437941e-01, 6.00000000e-01], [-1.81394201e-01, -3.96353559e-01, 9.00000000e-01], [9.03285667e-02, 9.03285667e-02, 9.03285667e-02], 1.38224736e-01),
    ("tilted", [8.00000000e-01, 0.00000000e+00, 6.00000000e-01], [-9.44392652e-01, 1.34619908e-01, 3.00000000e-01], [0.00000000e+00, 0.00000000e+00, 0.00000000e+00], 0.00000000e+00),
    ("tilted", [2.35512315e-01, 3.66788699e-01, 9.00000000e-01], [9.60265212e-01, 1.94655395e-01, 2.00000000e-01], [6.88545033e-02, 6.88545033e-02, 6.88545033e-02], 1.61130458e-01),
    ("steep", [5.73201893e-01, 1.77312124e-01, 8.00000000e-01], [4.67915523e-01, 7.28735249e-01, 5.00000000e-01], [8.34233069e-04, 8.34233069e-04, 8.34233069e-04], 5.45957638e-03),
    ("steep", [-3.32917469e-01, 7.27437941e-01, 6.00000000e-01], [-1.81394201e-01, -3.96353559e-01, 9.00000000e-01], [9.39832162e-03, 9.39832162e-03, 9.39832162e-03], 3.29753123e-02),
    ("steep", [8.00000000e-01, 0.00000000e+00, 6.00000000e-01], [-9.44392652e-01, 1.34619908e-01, 3.00000000e-01], [0.00000000e+00, 0.00000000e+00, 0.00000000e+00], 0.00000000e+00),
    ("steep", [2.35512315e-01, 3.66788699e-01, 9.00000000e-01], [9.60265212e-01, 1.94655395e-01, 2.00000000e-01], [0.00000000e+00, 0.00000000e+00, 0.00000000e+00], 0.00000000e+00),
    ];

    #[test]
    fn matches_mitsuba() {
        assert_matches_mitsuba("normalmap", MITSUBA_ROWS, |name| {
            let map = match name {
                "tilted" => rgb(0.7, 0.4, 0.9),
                _ => rgb(0.2, 0.75, 0.6),
            };
            vec![
                ("normalmap", map),
                ("bsdf", nested("b", "bsdf", "roughplastic", &[])),
            ]
        });
    }

    /// A flat normal map is the nested BSDF itself.
    #[test]
    fn a_flat_map_is_the_nested_bsdf() {
        let (b, store) = normalmap((0.5, 0.5, 1.0), "roughplastic");
        let (plain, plain_store) = build("roughplastic", &[]);
        for wi in [dir(0.8, 0.3), dir(0.2, 2.0)] {
            for wo in [dir(0.5, 1.0), dir(0.9, -2.0), dir(-0.3, 0.5)] {
                let f = eval_f32(&b, &store, wi, wo);
                let g = eval_f32(&plain, &plain_store, wi, wo);
                assert!((f - g).abs().max_element() < 1e-6, "{f} vs {g}");
            }
        }
    }

    /// A tilted normal map: eval, pdf and sampling agree (the shared
    /// smooth-BSDF checks), nothing scatters across the shading surface,
    /// and the derivative with respect to the normal map's value matches a
    /// finite difference.
    #[test]
    fn tilted_map_sampling_guards_and_derivatives() {
        let (b, store) = normalmap((0.7, 0.4, 0.9), "roughplastic");
        let wis = [dir(0.8, 0.3), dir(0.4, 2.0), dir(0.15, -2.5)];
        check_smooth(&b, &store, &wis, 1);
        // the perturbed normal tilts wo = (−0.99, 0, 0.14) below its surface
        let wo = Vec3::new(-0.99, 0.0, 0.14).normalize();
        assert_eq!(eval_f32(&b, &store, dir(0.8, 0.0), wo), Vec3::ZERO);

        let key = "nm.normalmap.value";
        assert!(store.id(key).is_some() && store.id("nm.nested_bsdf.alpha").is_some());
        let (wi, wo) = (dir(0.7, 0.3), dir(0.6, 2.5));
        let seeds = Seeds::tangents(&store, &[(key, &[1.0, 0.0, 0.0])]).unwrap();
        let d = b
            .context(&store.view(&seeds), &si::<Dual>(wi))
            .eval(V3::cst(wo));
        let d = Vec3::new(d.x.d, d.y.d, d.z.d);
        let h = 1e-3;
        let at = |x: f32| {
            let (b, s) = normalmap((x, 0.4, 0.9), "roughplastic");
            eval_f32(&b, &s, wi, wo)
        };
        let fd = (at(0.7 + h) - at(0.7 - h)) / (2.0 * h);
        assert_derivative(d, fd, at(0.7), &|| "d eval / d normalmap.r".into());
    }
}
