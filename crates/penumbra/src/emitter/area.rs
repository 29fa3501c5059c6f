//! Mitsuba's `area` emitter: a shape that emits radiance from the side its
//! normal points to.

use super::{emission_prop, eval_at, surface_si, DirectionSample, EmitterSample, EmitterT};
use crate::ad::ScalarReal;
use crate::error::Result;
use crate::geometry::{Hit, PositionSample, Shape, ShapeT, SurfaceInteraction};
use crate::math::{Spectrum, V3};
use crate::params::{ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use crate::texture::{AttributeUses, Texture, TextureT};
use glam::{Vec2, Vec3};

/// Radiance `radiance` (a value or a texture over the shape's uv, key
/// `<shape key>.emitter.radiance.value` for a value) leaving shape `shape`
/// on the side of its normal; nothing leaves the back side. Sampled by
/// the shape's position sampling for the lit point
/// ([`ShapeT::sample_position_from`]: uniform by area, or by solid angle
/// for a sphere seen from outside), converted to solid angle.
#[derive(Clone, Debug)]
pub struct Area {
    pub radiance: Texture,
    /// Index of the shape in the scene's shape list.
    pub shape: u32,
    /// The radiance reads the mesh's attributes (`mesh_attribute`), which
    /// need the sampled point's triangle and barycentrics.
    reads_mesh_attributes: bool,
}

impl Area {
    pub fn from_node(node: &Node, shape: u32, ctx: &mut LoadContext) -> Result<Area> {
        let uses_before = ctx.state::<AttributeUses>().0.len();
        let radiance = emission_prop(node, "radiance", ctx)?;
        Ok(Area {
            radiance,
            shape,
            reads_mesh_attributes: ctx.state::<AttributeUses>().0.len() > uses_before,
        })
    }

    /// The direction sample towards position sample `ps` (area density)
    /// seen from `ref_p`: solid-angle density `pdf_A · dist² / |cos θ_e|`
    /// and weight `L / pdf`. `None` when `ref_p` is behind the emitting
    /// side or coincides with the sample.
    ///
    /// `y` is the sampled point re-evaluated in `R` (moving with the
    /// emitter's shape, [`ShapeT::point_at`]): the direction and weight
    /// follow it and `ref_p`. The sample's density is a constant, so the
    /// weight carries the derivative of the Jacobian from the emitter's
    /// area to solid angle at `ref_p`, `area_scale · |cos θ_e| / dist²`
    /// (Zhang et al. 2020, "Path-Space Differentiable Rendering", §4).
    #[inline(always)]
    pub fn sample_from_position<R: ScalarReal>(
        &self,
        store: &ParamView,
        ps: &PositionSample,
        y: SurfaceInteraction<R>,
        ref_p: V3<R>,
    ) -> Option<EmitterSample<R>> {
        let (ds, d, jacobian) = Self::direction_to(ps, y.p, y.n, y.area_scale, ref_p)?;
        let l = self.radiance.eval(store, &y);
        Some(EmitterSample {
            weight: l * (jacobian / ds.pdf),
            ds,
            d,
        })
    }

    /// The geometric part of [`Area::sample_from_position`], for the
    /// sampled point at `p` (normal `n`, area scale `area_scale`, in `R`):
    /// the direction sample, the direction in `R` and the Jacobian's
    /// derivative factor (1 in value).
    #[inline(always)]
    fn direction_to<R: ScalarReal>(
        ps: &PositionSample,
        p: V3<R>,
        n: V3<R>,
        area_scale: R,
        ref_p: V3<R>,
    ) -> Option<(DirectionSample, V3<R>, R)> {
        let to = p - ref_p;
        let dist2 = to.length_squared();
        if !(dist2.val() > 0.0) || !(ps.pdf > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let d = to / dist;
        // cosine at the emitter between its normal and the direction to ref_p
        let cos_e = -d.dot(n);
        if !(cos_e.val() > 0.0) {
            return None;
        }
        let pdf = ps.pdf * dist2.val() / cos_e.val();
        let jacobian = if R::DIFFERENTIABLE {
            let j = area_scale * cos_e / dist2;
            j / j.val()
        } else {
            R::cst(1.0)
        };
        let ds = DirectionSample {
            p: ps.p,
            n: ps.n,
            d: d.val(),
            dist: dist.val(),
            pdf,
            delta: false,
        };
        Some((ds, d, jacobian))
    }

    /// Solid-angle density of reaching emitter point `p` (normal `n`) along
    /// `d` from `ref_p`, when positions are sampled with area density
    /// `pdf_area`.
    pub fn pdf_from_area(pdf_area: f32, ref_p: Vec3, d: Vec3, p: Vec3, n: Vec3) -> f32 {
        let cos_e = -d.dot(n);
        if !(cos_e > 0.0) {
            return 0.0;
        }
        pdf_area * (p - ref_p).length_squared() / cos_e
    }
}

impl EmitterT for Area {
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        shapes: &[Shape],
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let shape = shapes.get(self.shape as usize)?;
        let ps = shape.sample_position_from(store, ref_p.val(), u);
        // the point as the shape's full surface interaction where the
        // radiance reads per-vertex data or the point moves; otherwise a
        // lighter one (no triangle, no barycentrics)
        if self.reads_mesh_attributes || shape.moves::<R>(store) {
            let hit = Hit {
                t: 0.0,
                shape: self.shape,
                prim: ps.prim,
                uv: ps.local,
                instance: None,
            };
            let y = shape.point_at::<R>(store, &hit, ps.p);
            return self.sample_from_position(store, &ps, y, ref_p);
        }
        if R::DIFFERENTIABLE && !ref_p.is_const() {
            let y = surface_si::<R>(ps.p, ps.n, ps.uv, Vec3::Z, self.shape, ps.prim);
            return self.sample_from_position(store, &ps, y, ref_p);
        }
        // Nothing the direction depends on carries a derivative (the
        // Jacobian's factor is then exactly 1): the geometry in f32, the
        // same values as in `R` for a fraction of the cost; only the
        // radiance, which may be differentiated, in `R`, and without an
        // interaction to evaluate it at if it is a plain value.
        let (p, n) = (V3::cst(ps.p), V3::cst(ps.n));
        let (ds, d, _) = Self::direction_to(&ps, p, n, 1.0, V3::cst(ref_p.val()))?;
        let l: Spectrum<R> = eval_at(&self.radiance, store, || {
            surface_si(ps.p, ps.n, ps.uv, Vec3::Z, self.shape, ps.prim)
        });
        Some(EmitterSample {
            weight: l.scale(1.0 / ds.pdf),
            ds,
            d: V3::cst(d.val()),
        })
    }

    /// The solid-angle form of the shape's [`ShapeT::pdf_position_from`].
    fn pdf_direction(
        &self,
        store: &ParamStore,
        shapes: &[Shape],
        ref_p: Vec3,
        d: Vec3,
        p: Vec3,
        n: Vec3,
    ) -> f32 {
        let Some(shape) = shapes.get(self.shape as usize) else {
            return 0.0;
        };
        if !(shape.surface_area() > 0.0) {
            return 0.0;
        }
        let pdf_area = shape.pdf_position_from(store, ref_p, p, n);
        Area::pdf_from_area(pdf_area, ref_p, d, p, n)
    }

    /// Radiance towards `si.wi` if it is on the front side (shading frame
    /// cos θ > 0, as Mitsuba), else zero.
    fn eval_surface<R: ScalarReal>(
        &self,
        store: &ParamView,
        si: &SurfaceInteraction<R>,
    ) -> Spectrum<R> {
        if !(si.wi.z.val() > 0.0) {
            return V3::zero();
        }
        self.radiance.eval(store, si)
    }

    fn eval_environment<R: ScalarReal>(&self, _store: &ParamView, _d: V3<R>) -> Spectrum<R> {
        V3::zero()
    }
    fn is_delta(&self) -> bool {
        false
    }
    fn is_environment(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::emitter::test_util::{node, CHI2_ALPHA};
    use crate::emitter::EmitterSample;
    use crate::emitter::{surface_si, Emitter};
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::Value;
    use crate::testing::Chi2Test;

    /// A 2 × 3 rectangle centred at (0, 0, 1) facing −z, sampled uniformly
    /// by area (stands in for a shape's `sample_position`).
    const C: Vec3 = Vec3::new(0.0, 0.0, 1.0);
    const EX: Vec3 = Vec3::new(1.0, 0.0, 0.0);
    const EY: Vec3 = Vec3::new(0.0, 1.5, 0.0);
    const N: Vec3 = Vec3::new(0.0, 0.0, -1.0);
    const AREA: f32 = 6.0;

    fn sample_rect(u: Vec2) -> PositionSample {
        PositionSample {
            p: C + EX * (2.0 * u.x - 1.0) + EY * (2.0 * u.y - 1.0),
            n: N,
            uv: u,
            local: u,
            pdf: 1.0 / AREA,
            prim: 0,
        }
    }

    /// The rectangle's sample as a (constant) surface interaction.
    fn ps_si<R: ScalarReal>(ps: &PositionSample) -> SurfaceInteraction<R> {
        surface_si(ps.p, ps.n, ps.uv, -ps.n, 3, ps.prim)
    }

    /// Where the ray from `o` along `d` meets the rectangle, if it does.
    fn hit_rect(o: Vec3, d: Vec3) -> Option<Vec3> {
        let t = (C - o).dot(N) / d.dot(N);
        if !(t > 0.0) {
            return None;
        }
        let p = o + d * t;
        let q = p - C;
        (q.dot(EX).abs() <= EX.length_squared() && q.dot(EY).abs() <= EY.length_squared())
            .then_some(p)
    }

    fn make() -> (Area, LoadContext) {
        let mut ctx = LoadContext::default();
        let n = node(
            "area",
            "light.emitter",
            vec![("radiance", Value::Rgb(Vec3::new(4.0, 2.0, 1.0)))],
        );
        let Emitter::Area(a) = Emitter::from_node(&n, Some(3), &mut ctx).unwrap() else {
            panic!("not an area emitter")
        };
        assert_eq!(a.shape, 3);
        (a, ctx)
    }

    #[test]
    fn solid_angle_sampling_matches_pdf() {
        let (a, ctx) = make();
        let s = &ctx.store;
        let ref_p = Vec3::new(0.2, -0.1, 0.0);
        let test = Chi2Test {
            integration_res: 24,
            ..Chi2Test::default()
        };
        let r = test.run(
            |rng| {
                let ps = sample_rect(rng.next_2d());
                let EmitterSample { ds, weight: w, .. } =
                    a.sample_from_position::<f32>(&s.primal(), &ps, ps_si(&ps), V3::cst(ref_p))?;
                let pdf = Area::pdf_from_area(1.0 / AREA, ref_p, ds.d, ds.p, ds.n);
                assert!((pdf - ds.pdf).abs() <= 1e-4 * pdf);
                assert!(!ds.delta && (ds.dist - (ds.p - ref_p).length()).abs() < 1e-5);
                // weight = L / pdf, with L evaluated as a ray hitting ds.p sees it
                let si = surface_si::<f32>(ds.p, ds.n, ps.uv, -ds.d, 3, 0);
                let l = a.eval_surface(&s.primal(), &si).val();
                assert!((w.val() * pdf - l).abs().max_element() < 1e-4 * l.max_element());
                Some(ds.d)
            },
            |d| match hit_rect(ref_p, d) {
                Some(p) => Area::pdf_from_area(1.0 / AREA, ref_p, d, p, N),
                None => 0.0,
            },
        );
        assert!(r.p_value > CHI2_ALPHA, "{r:?}");
        assert!((r.pdf_integral - 1.0).abs() < 1e-2, "{r:?}");
    }

    #[test]
    fn one_sided_emission() {
        let (a, ctx) = make();
        let s = &ctx.store;
        // behind the emitting side: nothing to sample
        let behind = Vec3::new(0.0, 0.0, 2.0);
        assert!(a
            .sample_from_position::<f32>(
                &s.primal(),
                &sample_rect(Vec2::splat(0.3)),
                ps_si(&sample_rect(Vec2::splat(0.3))),
                V3::cst(behind)
            )
            .is_none());
        assert_eq!(Area::pdf_from_area(1.0 / AREA, behind, -Vec3::Z, C, N), 0.0);
        let front = surface_si::<f32>(C, N, Vec2::ZERO, -Vec3::Z, 3, 0);
        let back = surface_si::<f32>(C, N, Vec2::ZERO, Vec3::Z, 3, 0);
        assert_eq!(
            a.eval_surface(&s.primal(), &front).val(),
            Vec3::new(4.0, 2.0, 1.0)
        );
        assert_eq!(a.eval_surface(&s.primal(), &back).val(), Vec3::ZERO);
    }

    #[test]
    fn radiance_key_and_derivative() {
        let (a, ctx) = make();
        let seeds = Seeds::tangents(
            &ctx.store,
            &[("light.emitter.radiance.value", &[0.0, 0.0, 1.0])],
        )
        .unwrap();
        let store = ctx.store.view(&seeds);
        let ps = sample_rect(Vec2::new(0.5, 0.5));
        let EmitterSample { ds, weight: w, .. } = a
            .sample_from_position::<Dual>(&store, &ps, ps_si(&ps), V3::cst(Vec3::ZERO))
            .unwrap();
        assert!((w.z.d - 1.0 / ds.pdf).abs() < 1e-5 && w.x.d == 0.0);
        // straight below the centre: pdf = dist² / (A cos θ) = 1/6
        assert!((ds.pdf - 1.0 / 6.0).abs() < 1e-6);
    }

    #[test]
    fn attachment_rules() {
        let mut ctx = LoadContext::default();
        let e = Emitter::from_node(&node("area", "x", vec![]), None, &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(e.contains("nested inside a shape"), "{e}");
        let e = Emitter::from_node(&node("point", "y", vec![]), Some(0), &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot be attached"), "{e}");
        let e = Emitter::from_node(
            &node("area", "z", vec![("radience", Value::Float(1.0))]),
            Some(0),
            &mut ctx,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("unknown parameter 'radience'"), "{e}");
        let e = Emitter::from_node(&node("sun", "w", vec![]), None, &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown emitter plugin 'sun'"), "{e}");
    }
}
