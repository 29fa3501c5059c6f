//! Mitsuba's `envmap` emitter: radiance at infinity from a
//! latitude-longitude image, importance-sampled by luminance.

use super::{far_point, BoundingSphere, DirectionSample, EmitterT};
use crate::ad::Real;
use crate::error::{Error, Result};
use crate::geometry::{Shape, SurfaceInteraction};
use crate::image::{read_image, srgb_to_linear, Image};
use crate::math::{Distribution2D, Spectrum, Transform, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore};
use crate::scene::{LoadContext, Node};
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
    pub fn direction_to_uv(d: Vec3) -> Vec2 {
        let u = d.x.atan2(-d.z) * (0.5 / PI);
        let v = d.y.clamp(-1.0, 1.0).acos() / PI;
        Vec2::new(u - u.floor(), v)
    }

    /// (u, v) → unit local direction.
    #[inline]
    pub fn uv_to_direction(uv: Vec2) -> Vec3 {
        let (sin_t, cos_t) = (uv.y * PI).sin_cos();
        let (sin_p, cos_p) = (uv.x * 2.0 * PI).sin_cos();
        Vec3::new(sin_p * sin_t, cos_t, -cos_p * sin_t)
    }

    /// Texel-grid coordinates of (u, v): x in [0, w) (periodic), y in
    /// [0, h−1].
    #[inline]
    fn uv_to_grid(&self, uv: Vec2) -> Vec2 {
        let x = uv.x - 0.5 / self.width as f32;
        Vec2::new(
            (x - x.floor()) * self.width as f32,
            uv.y.clamp(0.0, 1.0) * (self.height - 1) as f32,
        )
    }

    /// Bilinear radiance (times scale) at texel-grid coordinates `g`.
    fn lookup<R: Real>(&self, store: &ParamStore, g: Vec2) -> Spectrum<R> {
        let (w, h) = (self.width, self.height);
        let x0 = (g.x.floor() as usize).min(w - 1);
        let y0 = (g.y.floor() as usize).min(h - 2);
        let (fx, fy) = (g.x - x0 as f32, g.y - y0 as f32);
        let x1 = (x0 + 1) % w;
        let t = |x: usize, y: usize| store.read3::<R>(self.data, y * w + x);
        let top = t(x0, y0).scale(1.0 - fx) + t(x1, y0).scale(fx);
        let bottom = t(x0, y0 + 1).scale(1.0 - fx) + t(x1, y0 + 1).scale(fx);
        let s: R = store.read(self.scale, 0);
        (top.scale(1.0 - fy) + bottom.scale(fy)) * s
    }

    fn to_local(&self, d: Vec3) -> Vec3 {
        self.to_world.inverse().vector(d).normalize()
    }
}

impl EmitterT for Envmap {
    fn sample_direction<R: Real>(
        &self,
        store: &ParamStore,
        _shapes: &[Shape],
        ref_p: Vec3,
        u: Vec2,
    ) -> Option<(DirectionSample, Spectrum<R>)> {
        let dist = self.distribution.as_ref()?;
        let (s, pdf_s) = dist.sample(u);
        if !(pdf_s > 0.0) {
            return None;
        }
        let w = self.width as f32;
        let uv = Vec2::new(s.x + 0.5 / w, s.y);
        let uv = Vec2::new(uv.x - uv.x.floor(), uv.y);
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
        let l = self.lookup::<R>(store, g);
        let ds = DirectionSample {
            p: far_point(&self.bounds, ref_p, d),
            n: -d,
            d,
            dist: f32::INFINITY,
            pdf,
            delta: false,
        };
        Some((ds, l.scale(1.0 / pdf)))
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
        let local = self.to_local(d);
        let g = self.uv_to_grid(Envmap::direction_to_uv(local));
        let s = Vec2::new(g.x / self.width as f32, g.y / (self.height - 1) as f32);
        let sin_theta = (local.x * local.x + local.z * local.z).sqrt();
        dist.pdf(s) / (2.0 * PI * PI * sin_theta.max(1e-7))
    }

    fn eval_surface<R: Real>(&self, _: &ParamStore, _: &SurfaceInteraction<R>) -> Spectrum<R> {
        V3::zero()
    }

    /// Radiance seen looking along world direction `d` (the direction of
    /// a ray that escaped the scene).
    fn eval_environment<R: Real>(&self, store: &ParamStore, d: Vec3) -> Spectrum<R> {
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
