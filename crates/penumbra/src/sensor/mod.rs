//! Sensors: cameras that turn film positions into rays, with their film
//! and sampler (Mitsuba's `<sensor>` with nested `<film>` and
//! `<sampler>`).

mod orthographic;
mod perspective;
mod thinlens;

pub use orthographic::Orthographic;
pub use perspective::Perspective;
pub use thinlens::ThinLens;

use crate::ad::Real;
use crate::error::Result;
use crate::geometry::{DiffRay, Ray};
use crate::image::{Film, ReconstructionFilter};
use crate::params::ParamStore;
use crate::sampler::{Independent, Sampler};
use crate::scene::{Class, Node};
use glam::Vec2;

/// The camera models.
#[derive(Clone, Debug)]
pub enum Camera {
    Perspective(Perspective),
    ThinLens(ThinLens),
    Orthographic(Orthographic),
}

/// The primary sample of one path: where on the film and on the lens the
/// path starts. These are constants of the integral (the pixel filter does
/// not move with the parameters); the sensor turns them into a ray in `R`,
/// so the ray follows the sensor's parameters.
#[derive(Clone, Copy, Debug)]
pub struct CameraSample<'a> {
    pub sensor: &'a Sensor,
    /// Film position in [0,1]² over the full film ((0,0) = top-left).
    pub film: Vec2,
    /// Lens position in [0,1]² (used by cameras with an aperture).
    pub lens: Vec2,
}

impl CameraSample<'_> {
    /// The camera ray of this sample, in `R`.
    #[inline]
    pub fn ray<R: Real>(&self, store: &ParamStore) -> DiffRay<R> {
        self.sensor.ray(store, self.film, self.lens)
    }
}

/// A camera with its film and sampler.
#[derive(Clone, Debug)]
pub struct Sensor {
    pub camera: Camera,
    pub film: Film,
    pub sampler: Sampler,
}

impl Sensor {
    pub fn from_node(node: &Node) -> Result<Sensor> {
        let film = match node.children(Class::Film).as_slice() {
            [] => Film::new(
                768,
                576,
                ReconstructionFilter::Gaussian {
                    stddev: 0.5,
                    radius: 2.0,
                },
            ),
            [f] => {
                let film = Film::from_node(f)?;
                f.check_all_used()?;
                film
            }
            _ => return Err(node.error("more than one <film>")),
        };
        let sampler = match node.children(Class::Sampler).as_slice() {
            [] => Sampler::Independent(Independent {
                sample_count: 4,
                seed: 0,
            }),
            [s] => Sampler::from_node(s)?,
            _ => return Err(node.error("more than one <sampler>")),
        };
        let aspect = film.width as f32 / film.height as f32;
        let camera = match node.plugin.as_str() {
            "perspective" => Camera::Perspective(Perspective::from_node(node, aspect)?),
            "thinlens" => Camera::ThinLens(ThinLens::from_node(node, aspect)?),
            "orthographic" => Camera::Orthographic(Orthographic::from_node(node, aspect)?),
            other => {
                return Err(node.error(format!(
                    "unknown sensor plugin '{other}' (Penumbra has: perspective, thinlens, orthographic)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(Sensor {
            camera,
            film,
            sampler,
        })
    }

    /// The ray through film position `pos` (in [0,1]² over the full film,
    /// (0,0) = top-left), with `lens` ∈ [0,1]² for cameras with an aperture.
    #[inline]
    pub fn sample_ray(&self, pos: Vec2, lens: Vec2) -> Ray {
        match &self.camera {
            Camera::Perspective(c) => c.sample_ray(pos),
            Camera::ThinLens(c) => c.sample_ray(pos, lens),
            Camera::Orthographic(c) => c.sample_ray(pos),
        }
    }

    /// The ray through film position `film` and lens position `lens`, in
    /// `R` (see [`CameraSample`]).
    #[inline]
    pub fn ray<R: Real>(&self, _store: &ParamStore, film: Vec2, lens: Vec2) -> DiffRay<R> {
        DiffRay::cst(&self.sample_ray(film, lens))
    }

    /// True if rays need a lens sample (thin lens with an aperture).
    pub fn needs_aperture_sample(&self) -> bool {
        matches!(self.camera, Camera::ThinLens(_))
    }

    /// The same sensor (film, sampler, lens) placed at another pose, e.g.
    /// for the extra views of a multi-view optimisation.
    pub fn with_to_world(&self, to_world: crate::math::Transform) -> Sensor {
        let mut s = self.clone();
        match &mut s.camera {
            Camera::Perspective(c) => c.to_world = to_world,
            Camera::ThinLens(c) => c.to_world = to_world,
            Camera::Orthographic(c) => c.to_world = to_world,
        }
        s
    }
}

/// The horizontal field of view (degrees) from Mitsuba's `fov` and
/// `fov_axis` (x, y, diagonal, smaller, larger) for a film of aspect
/// ratio `aspect` = width / height.
pub(crate) fn fov_x(node: &Node, aspect: f32) -> Result<f32> {
    let fov = if node.has("focal_length") {
        let s = node.string("focal_length", "50mm")?;
        let mm: f32 =
            s.trim_end_matches("mm").trim().parse().map_err(|_| {
                node.error(format!("focal_length '{s}' is not a length like '50mm'"))
            })?;
        // 35 mm film: 36 mm wide
        return Ok(2.0 * (36.0 / (2.0 * mm)).atan().to_degrees());
    } else {
        node.float("fov", 45.0)?
    };
    if !(fov > 0.0 && fov < 180.0) {
        let p = node.prop("fov").expect("fov came from a property");
        return Err(node.prop_error(p, format!("must be in (0, 180) degrees, found {fov}")));
    }
    let axis = node.choice("fov_axis", &["x", "y", "diagonal", "smaller", "larger"])?;
    let t = (fov.to_radians() * 0.5).tan();
    let axis = match axis.as_str() {
        "smaller" if aspect > 1.0 => "y",
        "smaller" => "x",
        "larger" if aspect > 1.0 => "x",
        "larger" => "y",
        a => a,
    };
    let tx = match axis {
        "x" => t,
        "y" => t * aspect,
        // diagonal: tan scales with the diagonal length
        _ => t * aspect / (1.0 + aspect * aspect).sqrt(),
    };
    Ok(2.0 * tx.atan().to_degrees())
}

/// Near/far clipping distances (along the view axis).
pub(crate) fn clip_range(node: &Node) -> Result<(f32, f32)> {
    let near = node.float_checked("near_clip", 0.01, true)?;
    let far = node.float_checked("far_clip", 10000.0, true)?;
    if near >= far {
        return Err(node.error(format!(
            "near_clip ({near}) must be smaller than far_clip ({far})"
        )));
    }
    Ok((near, far))
}

/// Camera-space direction through film position `pos` ∈ [0,1]² for a
/// pinhole with horizontal half-angle tangent `tan_x`, as Mitsuba maps it:
/// film x grows towards camera −x ("left" is +x), film y downwards.
#[inline(always)]
pub(crate) fn pinhole_direction(pos: Vec2, tan_x: f32, aspect: f32, offset: Vec2) -> glam::Vec3 {
    let x = (1.0 - 2.0 * pos.x + 2.0 * offset.x) * tan_x;
    let y = (1.0 - 2.0 * pos.y + 2.0 * offset.y) * tan_x / aspect;
    glam::Vec3::new(x, y, 1.0)
}
