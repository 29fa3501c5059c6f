//! Mitsuba's `envmap` emitter: radiance at infinity from a
//! latitude-longitude image, importance-sampled by luminance.

use super::{far_point, BoundingSphere, DirectionSample, EmitterSample, EmitterT};
use crate::ad::ScalarReal;
use crate::error::{Error, Result};
use crate::geometry::{Shape, SurfaceInteraction};
use crate::image::{read_image, srgb_to_linear, Image};
use crate::math::{floor_i64, warp, Distribution2D, Spectrum, Transform, V2, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::scene::description::{LoadContext, Node};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// An environment map in Mitsuba 3's latitude-longitude convention, in the
/// emitter's local frame (world = `to_world` · local):
/// - v = θ/π with θ measured from local +y (v = 0 is +y, "up");
/// - u = φ/2π with φ = atan2(x, −z): u = 0 is −z, u = ¼ is +x, u = ½ is
///   +z, u = ¾ is −x;
/// - image row j sits at v = j/(h−1) (first row at the +y pole, last row
///   at the −y pole) and column i at u = (i + ½)/w, bilinear in between
///   and periodic in u.
///
/// Texels are the differentiable parameter `<key>.data` (`[h, w, 3]`,
/// linear RGB; PNG/JPEG are sRGB-decoded at load), multiplied by the
/// differentiable `<key>.scale`. Directions are importance-sampled from a
/// piecewise-constant density over the w × (h−1) cells between texel
/// centres, proportional to the cell's mean corner luminance times the
/// mean of sin θ over the cell; solid-angle pdf = pdf_uv / (2π² sin θ).
#[derive(Clone, Debug)]
pub struct Envmap {
    pub data: ParamId,
    pub scale: ParamId,
    pub to_world: Transform,
    pub width: usize,
    pub height: usize,
    /// `None` when the map is black (nothing to sample).
    pub distribution: Option<Distribution2D>,
    pub bounds: BoundingSphere,
}

impl Envmap {
    /// `filename` (EXR, PNG, JPEG), `scale` (default 1), `to_world`.
    pub fn from_node(node: &Node, ctx: &mut LoadContext) -> Result<Envmap> {
        let filename = node
            .string_opt("filename")?
            .ok_or_else(|| node.error("missing required parameter 'filename'"))?;
        let path = ctx.resolve_path(node, "filename", &filename)?;
        let mut img = read_image(&path).map_err(|e| node.error(e))?;
        let is_exr = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !is_exr {
            for v in img.data.iter_mut() {
                *v = srgb_to_linear(*v);
            }
        }
        let scale = node.float("scale", 1.0)?;
        let to_world = node.transform("to_world")?;
        Envmap::new(&node.key, img, scale, to_world, ctx).map_err(|e| node.error(e))
    }

    /// An envmap over linear image `img` (1, 2, 3 or 4 channels; grey is
    /// replicated to RGB, alpha dropped), at least 2 × 3 texels.
    pub fn new(
        key: &str,
        img: Image,
        scale: f32,
        to_world: Transform,
        ctx: &mut LoadContext,
    ) -> Result<Envmap> {
        if img.width < 2 || img.height < 3 {
            return Err(Error::Invalid(format!(
                "the environment map resolution must be at least 2x3 pixels, got {}x{}",
                img.width, img.height
            )));
        }
        let rgb: Vec<f32> = if img.channels >= 3 {
            img.take_channels(3).data
        } else {
            img.data
                .chunks_exact(img.channels)
                .flat_map(|px| [px[0]; 3])
                .collect()
        };
        let (w, h) = (img.width, img.height);
        let data = ctx.store.add(
            format!("{key}.data"),
            rgb,
            vec![h, w, 3],
            ParamFlags::DIFFERENTIABLE,
            Domain::Finite,
        )?;
        let scale = ctx.store.add(
            format!("{key}.scale"),
            vec![scale],
            vec![1],
            ParamFlags::DIFFERENTIABLE,
            Domain::Finite,
        )?;
        let mut e = Envmap {
            data,
            scale,
            to_world,
            width: w,
            height: h,
            distribution: None,
            bounds: BoundingSphere::default(),
        };
        e.rebuild_distribution(&ctx.store);
        Ok(e)
    }

    /// Rebuilds the sampling density from the current texels (call after
    /// `<key>.data` was updated).
    pub fn rebuild_distribution(&mut self, store: &ParamStore) {
        let (w, h) = (self.width, self.height);
        let d = store.data(self.data);
        let lum = |x: usize, y: usize| {
            let i = 3 * (y * w + x % w);
            (0.212671 * d[i] + 0.715160 * d[i + 1] + 0.072169 * d[i + 2]).max(0.0)
        };
        let rows = h - 1;
        let dtheta = PI / rows as f32;
        let mut weights = Vec::with_capacity(w * rows);
        for j in 0..rows {
            let (t0, t1) = (j as f32 * dtheta, (j + 1) as f32 * dtheta);
            let mean_sin = (t0.cos() - t1.cos()) / dtheta;
            for i in 0..w {
                let corners = lum(i, j) + lum(i + 1, j) + lum(i, j + 1) + lum(i + 1, j + 1);
                weights.push(0.25 * corners * mean_sin);
            }
        }
        self.distribution = Distribution2D::new(&weights, w, rows);
    }

    /// Local direction → (u, v) in [0,1)×[0,1] (Mitsuba's convention).
    #[inline]
    pub fn direction_to_uv<R: ScalarReal>(d: V3<R>) -> V2<R> {
        let u = d.x.atan2(-d.z) * (0.5 / PI);
        let v = d.y.acos() / PI;
        V2::new(u - floor_i64(u.val()) as f32, v)
    }

    /// (u, v) → unit local direction.
    #[inline]
    pub fn uv_to_direction(uv: Vec2) -> Vec3 {
        let (sin_t, cos_t) = (uv.y * PI).sin_cos();
        let (sin_p, cos_p) = warp::sin_cos_turns(uv.x);
        Vec3::new(sin_p * sin_t, cos_t, -cos_p * sin_t)
    }

    /// Texel-grid coordinates of (u, v): x in [0, w) (periodic), y in
    /// [0, h−1].
    #[inline]
    fn uv_to_grid<R: ScalarReal>(&self, uv: V2<R>) -> V2<R> {
        let x = uv.x - 0.5 / self.width as f32;
        V2::new(
            (x - floor_i64(x.val()) as f32) * self.width as f32,
            uv.y.clamp(0.0, 1.0) * (self.height - 1) as f32,
        )
    }

    /// Bilinear radiance (times scale) at texel-grid coordinates `g`; the
    /// bilinear weights are differentiable in `g` (the direction looked
    /// along moves when the camera or a mirror does).
    fn lookup<R: ScalarReal>(&self, store: &ParamView, g: V2<R>) -> Spectrum<R> {
        let (w, h) = (self.width, self.height);
        let x0 = (floor_i64(g.x.val()).max(0) as usize).min(w - 1);
        let y0 = (floor_i64(g.y.val()).max(0) as usize).min(h - 2);
        let (fx, fy) = (g.x - x0 as f32, g.y - y0 as f32);
        let x1 = (x0 + 1) % w;
        let t = |x: usize, y: usize| store.read3::<R>(self.data, y * w + x);
        let one = R::cst(1.0);
        let top = t(x0, y0) * (one - fx) + t(x1, y0) * fx;
        let bottom = t(x0, y0 + 1) * (one - fx) + t(x1, y0 + 1) * fx;
        let s: R = store.read(self.scale, 0);
        (top * (one - fy) + bottom * fy) * s
    }

    fn to_local<R: ScalarReal>(&self, d: V3<R>) -> V3<R> {
        self.to_world.inverse().vector_r(d).normalize()
    }
}

impl EmitterT for Envmap {
    fn sample_direction<R: ScalarReal>(
        &self,
        store: &ParamView,
        _shapes: &[Shape],
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let dist = self.distribution.as_ref()?;
        let (s, pdf_s) = dist.sample(u);
        if !(pdf_s > 0.0) {
            return None;
        }
        let w = self.width as f32;
        let uv = Vec2::new(s.x + 0.5 / w, s.y);
        let uv = Vec2::new(uv.x - floor_i64(uv.x) as f32, uv.y);
        let sin_theta = (s.y * PI).sin();
        if !(sin_theta > 0.0) {
            return None;
        }
        let pdf = pdf_s / (2.0 * PI * PI * sin_theta);
        let d = self
            .to_world
            .vector(Envmap::uv_to_direction(uv))
            .normalize();
        let g = Vec2::new(s.x * w, s.y * (self.height - 1) as f32);
        let l = self.lookup::<R>(store, V2::cst(g));
        let ds = DirectionSample {
            p: far_point(&self.bounds, ref_p.val(), d),
            n: -d,
            d,
            dist: f32::INFINITY,
            pdf,
            delta: false,
        };
        Some(EmitterSample::fixed_direction(ds, l.scale(1.0 / pdf)))
    }

    fn pdf_direction(
        &self,
        _: &ParamStore,
        _: &[Shape],
        _: Vec3,
        d: Vec3,
        _: Vec3,
        _: Vec3,
    ) -> f32 {
        let Some(dist) = &self.distribution else {
            return 0.0;
        };
        let local = self.to_local(V3::<f32>::cst(d)).val();
        let g = self
            .uv_to_grid(Envmap::direction_to_uv(V3::<f32>::cst(local)))
            .val();
        let s = Vec2::new(g.x / self.width as f32, g.y / (self.height - 1) as f32);
        let sin_theta = (local.x * local.x + local.z * local.z).sqrt();
        dist.pdf(s) / (2.0 * PI * PI * sin_theta.max(1e-7))
    }

    fn eval_surface<R: ScalarReal>(&self, _: &ParamView, _: &SurfaceInteraction<R>) -> Spectrum<R> {
        V3::zero()
    }

    /// Radiance seen looking along world direction `d` (the direction of
    /// a ray that escaped the scene).
    fn eval_environment<R: ScalarReal>(&self, store: &ParamView, d: V3<R>) -> Spectrum<R> {
        let local = self.to_local(d);
        self.lookup(store, self.uv_to_grid(Envmap::direction_to_uv(local)))
    }
    fn is_delta(&self) -> bool {
        false
    }
    fn is_environment(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::emitter::test_util::{node, CHI2_ALPHA};
    use crate::emitter::Emitter;
    use crate::emitter::EmitterSample;
    use crate::math::V3;
    use crate::params::Seeds;
    use crate::scene::description::Value;
    use crate::testing::Chi2Test;
    use glam::{Mat4, Vec4};

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Image {
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                for (c, v) in f(x, y).into_iter().enumerate() {
                    img.set(x, y, c, v);
                }
            }
        }
        img
    }

    /// Values Mitsuba 3.9.1's envmap returns for a 4×3 map with texel
    /// (x, y) = (x + 1, y + 1, 0), looking along these directions.
    #[test]
    fn lat_long_convention_matches_mitsuba() {
        let mut ctx = LoadContext::default();
        let img = image(4, 3, |x, y| [x as f32 + 1.0, y as f32 + 1.0, 0.0]);
        let e = Envmap::new("env", img, 1.0, Transform::IDENTITY, &mut ctx).unwrap();
        for (d, want) in [
            (Vec3::new(0.0, 0.0, -1.0), Vec3::new(2.5, 2.0, 0.0)),
            (Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.5, 2.0, 0.0)),
            (Vec3::new(0.0, 0.0, 1.0), Vec3::new(2.5, 2.0, 0.0)),
            (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(3.5, 2.0, 0.0)),
            (Vec3::new(0.0, 1.0, 0.0), Vec3::new(2.5, 1.0, 0.0)),
            (Vec3::new(0.0, -1.0, 0.0), Vec3::new(2.5, 3.0, 0.0)),
        ] {
            let got = e
                .eval_environment::<f32>(&ctx.store.primal(), V3::cst(d))
                .val();
            assert!(
                (got - want).abs().max_element() < 1e-4,
                "{d}: {got} vs {want}"
            );
        }
        // uv <-> direction are inverse to each other
        for uv in [
            Vec2::new(0.1, 0.3),
            Vec2::new(0.8, 0.9),
            Vec2::new(0.45, 0.5),
        ] {
            let back = Envmap::direction_to_uv(V3::<f32>::cst(Envmap::uv_to_direction(uv))).val();
            assert!((back - uv).abs().max_element() < 1e-5, "{uv} -> {back}");
        }
    }

    #[test]
    fn texel_and_scale_derivatives() {
        let mut ctx = LoadContext::default();
        let img = image(4, 3, |x, y| [x as f32 + 1.0, y as f32 + 1.0, 0.5]);
        let e = Envmap::new("env", img, 2.0, Transform::IDENTITY, &mut ctx).unwrap();
        // u = 0.3 → x = 0.3·4 − 0.5 = 0.7 (columns 0, 1); v = 0.25 → y = 0.5
        let d = Envmap::uv_to_direction(Vec2::new(0.3, 0.25));
        let mut t = vec![0.0; 36];
        t[(4 + 1) * 3] = 1.0; // texel (1, 1), red
        let seeds = Seeds::tangents(&ctx.store, &[("env.data", &t)]).unwrap();
        let l = e.eval_environment::<Dual>(&ctx.store.view(&seeds), V3::cst(d));
        assert!((l.x.d - 2.0 * 0.7 * 0.5).abs() < 1e-4, "{l:?}");
        assert_eq!(l.y.d, 0.0);
        let seeds = Seeds::tangents(&ctx.store, &[("env.scale", &[1.0])]).unwrap();
        let l = e.eval_environment::<Dual>(&ctx.store.view(&seeds), V3::cst(d));
        assert!((l.x.d - l.x.v / 2.0).abs() < 1e-5, "{l:?}");
    }

    #[test]
    fn sampling_matches_pdf_direction() {
        // 20 columns: cell edges in u fall on the χ² test's 40 φ-bin edges
        let (w, h) = (20, 5);
        let img = image(w, h, |x, y| {
            let v = if (x + 2 * y) % 7 == 0 {
                0.0
            } else {
                1.0 + ((x * 7 + y * 3) % 5) as f32
            };
            [v, 0.5 * v + (y as f32), 0.2]
        });
        // local +y (the map's pole) to world +z: the test's cos θ bins and
        // the map's rows share their axis
        let m = Mat4::from_cols(Vec4::Y, Vec4::Z, Vec4::X, Vec4::W);
        let mut ctx = LoadContext::default();
        let e = Envmap::new("env", img, 1.5, Transform::new(m).unwrap(), &mut ctx).unwrap();
        let e = Emitter::Envmap(e);
        let s = &ctx.store;
        let ref_p = Vec3::new(0.1, 0.2, 0.3);
        let test = Chi2Test {
            integration_res: 24,
            ..Chi2Test::default()
        };
        // samples within round-off of a cell edge may map back into the
        // neighbouring cell: count disagreements instead of failing on one
        let mut mismatches = 0usize;
        let r = test.run(
            |rng| {
                let EmitterSample {
                    ds, weight: wgt, ..
                } = e.sample_direction::<f32>(&s.primal(), &[], V3::cst(ref_p), rng.next_2d())?;
                let pdf = e.pdf_direction(s, &[], ref_p, ds.d, ds.p, ds.n);
                let want = e.eval_environment::<f32>(&s.primal(), V3::cst(ds.d)).val() / pdf;
                // f32 round-off in the direction (~1e-6) moves u by
                // ~1e-6 / sin θ, and radiance changes by at most ~w · 6×
                // per unit u on this map
                let sin_theta = ds.d.truncate().length();
                let tol = (1e-3 + 2e-4 / sin_theta) * want.max_element();
                if (pdf - ds.pdf).abs() > 1e-3 * pdf || (wgt.val() - want).abs().max_element() > tol
                {
                    mismatches += 1;
                }
                Some(ds.d)
            },
            |d| e.pdf_direction(s, &[], ref_p, d, Vec3::ZERO, Vec3::ZERO),
        );
        assert!(
            mismatches * 1000 <= test.samples,
            "{mismatches} inconsistent samples"
        );
        assert!(r.p_value > CHI2_ALPHA, "{r:?}");
        assert!((r.pdf_integral - 1.0).abs() < 1e-2, "{r:?}");
    }

    #[test]
    fn museum_loads_and_samples_consistently() {
        let p = crate::testing::repo_file("scenes/textures/museum.exr");
        let n = node(
            "envmap",
            "env",
            vec![
                ("filename", Value::Str(p.to_str().unwrap().into())),
                ("scale", Value::Float(0.5)),
            ],
        );
        let mut ctx = LoadContext::default();
        let mut e = Emitter::from_node(&n, None, &mut ctx).unwrap();
        e.set_scene_bounds(Vec3::ONE, 2.0);
        let s = &ctx.store;
        let shape = &s.get(s.require("env.data").unwrap()).shape;
        assert_eq!(shape.len(), 3);
        assert_eq!(shape[2], 3);
        let mut rng = crate::testing::Pcg32::new(3);
        let mut n_ok = 0;
        for _ in 0..2000 {
            let Some(EmitterSample { ds, weight: w, .. }) =
                e.sample_direction::<f32>(&s.primal(), &[], V3::cst(Vec3::ZERO), rng.next_2d())
            else {
                continue;
            };
            n_ok += 1;
            let pdf = e.pdf_direction(s, &[], Vec3::ZERO, ds.d, ds.p, ds.n);
            assert!((pdf - ds.pdf).abs() <= 2e-3 * pdf, "{pdf} vs {}", ds.pdf);
            let l = e.eval_environment::<f32>(&s.primal(), V3::cst(ds.d)).val();
            assert!((w.val() * pdf - l).abs().max_element() <= 2e-3 * l.max_element() + 1e-6);
            assert!((ds.p - Vec3::ONE).length() > 2.0);
        }
        assert!(n_ok > 1990);
        // the density integrates to one over the sphere
        let r = Chi2Test {
            samples: 0,
            ..Chi2Test::default()
        }
        .run(
            |_| None,
            |d| e.pdf_direction(s, &[], Vec3::ZERO, d, Vec3::ZERO, Vec3::ZERO),
        );
        assert!((r.pdf_integral - 1.0).abs() < 1e-2, "{r:?}");
    }

    #[test]
    fn tiny_maps_are_rejected() {
        let mut ctx = LoadContext::default();
        let e = Envmap::new("e", Image::new(2, 2, 3), 1.0, Transform::IDENTITY, &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(e.contains("at least 2x3"), "{e}");
        let n = node("envmap", "e", vec![]);
        let e = Emitter::from_node(&n, None, &mut ctx)
            .unwrap_err()
            .to_string();
        assert!(e.contains("test.xml:1") && e.contains("'filename'"), "{e}");
    }
}
