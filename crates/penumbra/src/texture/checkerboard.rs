//! Mitsuba's `checkerboard` texture: two textures alternating on a 2×2
//! grid per unit square of (transformed) uv.

use super::bitmap::{add_to_uv, apply_to_uv};
use super::{Channels, Texture, TextureT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::SurfaceInteraction;
use crate::math::{floor_i64, Spectrum};
use crate::params::{Domain, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};

/// Mitsuba 3.9.1's checkerboard `eval_1` returns `color1` where `eval`
/// returns `color0` and vice versa (observed: default colours at uv =
/// (0.25, 0.25) give eval 0.4, eval_1 0.2). We reproduce it so that scenes
/// using a checkerboard as a scalar (roughness, weight) render as in
/// Mitsuba; set to `false` for the consistent definition.
pub const MITSUBA_EVAL1_SWAPS_COLORS: bool = true;

#[cfg(test)]
thread_local! {
    /// Checkerboard evaluations on this thread: tests count the texture
    /// reads of code that uses checkerboards.
    pub(crate) static EVALS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// `color0` where the fractional parts of u and v are both ≤ ½ or both
/// > ½, `color1` elsewhere (uv after `to_uv`), as Mitsuba 3 defines it.
#[derive(Clone, Debug)]
pub struct Checkerboard {
    pub color0: Box<Texture>,
    pub color1: Box<Texture>,
    pub to_uv: ParamId,
}

impl Checkerboard {
    /// `color0` (default 0.4), `color1` (default 0.2): values or
    /// textures, in the `domain` of the slot the checkerboard fills;
    /// `to_uv`.
    pub fn from_node(node: &Node, domain: Domain, ctx: &mut LoadContext) -> Result<Checkerboard> {
        let color0 = Texture::from_prop(node, "color0", Some(0.4), Channels::Rgb, domain, ctx)?;
        let color1 = Texture::from_prop(node, "color1", Some(0.2), Channels::Rgb, domain, ctx)?;
        let t = node.transform("to_uv")?;
        let to_uv = add_to_uv(&node.key, &t, ctx)?;
        Ok(Checkerboard {
            color0: Box::new(color0),
            color1: Box::new(color1),
            to_uv,
        })
    }

    /// True where `color0` applies.
    #[inline]
    fn is_color0<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> bool {
        let uv = apply_to_uv(store, self.to_uv, si.uv).val();
        let (fu, fv) = (uv.x - floor_i64(uv.x) as f32, uv.y - floor_i64(uv.y) as f32);
        (fu > 0.5) == (fv > 0.5)
    }
}

impl TextureT for Checkerboard {
    fn eval<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> Spectrum<R> {
        #[cfg(test)]
        EVALS.with(|n| n.set(n.get() + 1));
        if self.is_color0(store, si) {
            self.color0.eval(store, si)
        } else {
            self.color1.eval(store, si)
        }
    }
    fn eval_1<R: ScalarReal>(&self, store: &ParamView, si: &SurfaceInteraction<R>) -> R {
        #[cfg(test)]
        EVALS.with(|n| n.set(n.get() + 1));
        if self.is_color0(store, si) != MITSUBA_EVAL1_SWAPS_COLORS {
            self.color0.eval_1(store, si)
        } else {
            self.color1.eval_1(store, si)
        }
    }
    fn mean(&self, store: &ParamStore) -> f32 {
        0.5 * (self.color0.mean(store) + self.color1.mean(store))
    }
    fn max(&self, store: &ParamStore) -> f32 {
        self.color0.max(store).max(self.color1.max(store))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::description::{Class, Value};
    use crate::texture::{si_at_uv, test_node};

    /// A checkerboard with distinct RGB colours and
    /// `to_uv` = translate(0.1, −0.3) · scale(3, 2), so that uv ↦ (3u + 0.1,
    /// 2v − 0.3).
    fn shifted_board(ctx: &mut LoadContext) -> Texture {
        let m = glam::Mat4::from_translation(glam::Vec3::new(0.1, -0.3, 0.0))
            * glam::Mat4::from_scale(glam::Vec3::new(3.0, 2.0, 1.0));
        let node = test_node(
            Class::Texture,
            "checkerboard",
            "c",
            vec![
                ("color0", Value::Rgb(glam::Vec3::new(0.9, 0.5, 0.1))),
                ("color1", Value::Rgb(glam::Vec3::new(0.2, 0.3, 0.7))),
                (
                    "to_uv",
                    Value::Transform(crate::math::Transform::new(m).unwrap()),
                ),
            ],
        );
        Texture::from_node(&node, Domain::Finite, ctx).unwrap()
    }

    #[test]
    fn matches_the_parity_formula() {
        // Independent statement of Mitsuba's rule: with (s, t) the uv after
        // to_uv, color0 covers the half-unit squares whose indices
        // ⌊2s⌋ + ⌊2t⌋ are even.
        let mut ctx = LoadContext::default();
        let t = shifted_board(&mut ctx);
        let (c0, c1) = (
            glam::Vec3::new(0.9, 0.5, 0.1),
            glam::Vec3::new(0.2, 0.3, 0.7),
        );
        let mut rng = crate::testing::Pcg32::new(7);
        let mut n0 = 0;
        for _ in 0..2000 {
            let (u, v) = (rng.next_f32() * 4.0 - 2.0, rng.next_f32() * 4.0 - 2.0);
            let (s, tt) = (3.0 * u as f64 + 0.1, 2.0 * v as f64 - 0.3);
            let (i, j) = ((2.0 * s).floor() as i64, (2.0 * tt).floor() as i64);
            // skip points within rounding distance of an edge
            if ((2.0 * s) - (2.0 * s).round()).abs() < 1e-4
                || ((2.0 * tt) - (2.0 * tt).round()).abs() < 1e-4
            {
                continue;
            }
            let want = if (i + j).rem_euclid(2) == 0 { c0 } else { c1 };
            n0 += usize::from(want == c0);
            let got = t.eval::<f32>(&ctx.store.primal(), &si_at_uv(u, v)).val();
            assert!(
                (got - want).abs().max_element() < 1e-6,
                "uv ({u}, {v}): {got} vs {want}"
            );
        }
        assert!((900..1100).contains(&n0), "{n0} of 2000 points on color0");
    }

    #[test]
    fn region_mean_is_the_area_fraction() {
        // Over uv ∈ [0, ¾]² (default to_uv) the squares are [0,½]² (color0,
        // area ¼), [½,¾]×[0,½] and [0,½]×[½,¾] (color1, ⅛ each) and [½,¾]²
        // (color0, 1/16): color0 covers (¼ + 1/16) / (9/16) = 5/9.
        let node = test_node(Class::Texture, "checkerboard", "c", vec![]);
        let mut ctx = LoadContext::default();
        let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
        let n = 300; // cell 1/400: the edge at ½ falls between cells
        let mut sum = 0.0f64;
        for j in 0..n {
            for i in 0..n {
                let (u, v) = (
                    0.75 * (i as f32 + 0.5) / n as f32,
                    0.75 * (j as f32 + 0.5) / n as f32,
                );
                sum += t.eval::<f32>(&ctx.store.primal(), &si_at_uv(u, v)).val().x as f64;
            }
        }
        let want = 5.0 / 9.0 * 0.4 + 4.0 / 9.0 * 0.2;
        assert!(
            (sum / (n * n) as f64 - want).abs() < 1e-6,
            "{} vs {want}",
            sum / (n * n) as f64
        );
    }

    #[test]
    fn pattern_defaults_and_eval_1() {
        let node = test_node(Class::Texture, "checkerboard", "c", vec![]);
        let mut ctx = LoadContext::default();
        let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
        let s = &ctx.store;
        for ((u, v), want) in [
            ((0.25, 0.25), 0.4),
            ((0.75, 0.25), 0.2),
            ((0.25, 0.75), 0.2),
            ((0.75, 0.75), 0.4),
            ((1.25, -0.25), 0.2),
            ((-0.25, -0.25), 0.4),
        ] {
            let e = t.eval::<f32>(&s.primal(), &si_at_uv(u, v)).val();
            assert!(
                (e - glam::Vec3::splat(want)).abs().max_element() < 1e-6,
                "({u},{v}) {e}"
            );
            let e1 = t.eval_1::<f32>(&s.primal(), &si_at_uv(u, v));
            let want1 = if MITSUBA_EVAL1_SWAPS_COLORS {
                0.6 - want
            } else {
                want
            };
            assert!((e1 - want1).abs() < 1e-6, "({u},{v}) eval_1 {e1}");
        }
        assert!((t.mean(s) - 0.3).abs() < 1e-6);
        assert!((t.max(s) - 0.4).abs() < 1e-6);
        assert!(s.id("c.color0.value").is_some() && s.id("c.to_uv").is_some());
    }

    #[test]
    fn rgb_colors_and_to_uv() {
        let scale =
            crate::math::Transform::new(glam::Mat4::from_scale(glam::Vec3::new(2.0, 2.0, 1.0)))
                .unwrap();
        let node = test_node(
            Class::Texture,
            "checkerboard",
            "c",
            vec![
                ("color0", Value::Rgb(glam::Vec3::new(1.0, 0.0, 0.0))),
                ("color1", Value::Rgb(glam::Vec3::new(0.0, 0.0, 1.0))),
                ("to_uv", Value::Transform(scale)),
            ],
        );
        let mut ctx = LoadContext::default();
        let t = Texture::from_node(&node, Domain::Finite, &mut ctx).unwrap();
        // uv (0.3, 0.1) -> (0.6, 0.2): color1
        let e = t
            .eval::<f32>(&ctx.store.primal(), &si_at_uv(0.3, 0.1))
            .val();
        assert_eq!(e, glam::Vec3::new(0.0, 0.0, 1.0));
        let e = t
            .eval::<f32>(&ctx.store.primal(), &si_at_uv(0.3, 0.3))
            .val();
        assert_eq!(e, glam::Vec3::new(1.0, 0.0, 0.0));
    }
}
