//! Sensors: cameras that turn film positions into rays, with their film
//! and sampler (Mitsuba's `<sensor>` with nested `<film>` and
//! `<sampler>`).

mod orthographic;
mod perspective;
pub(crate) mod projection;
mod thinlens;

pub use orthographic::Orthographic;
pub use perspective::Perspective;
pub use thinlens::ThinLens;

use crate::ad::lanes::{lane3, Lanes};
use crate::ad::{Real, ScalarReal};
use crate::error::{Error, Result};
use crate::geometry::{DiffRay, Ray};
use crate::image::{Film, ReconstructionFilter};
use crate::math::{Transform, V3};
use crate::params::{Domain, ParamFlags, ParamId, ParamStore, ParamView};
use crate::sampler::{Independent, Sampler};
use crate::scene::description::{Class, Node};
use glam::{Mat4, Vec2};

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
    /// The camera ray in `R` if geometry or the camera moves, else its
    /// primal value as a constant (cheaper: nothing to differentiate).
    #[inline]
    pub fn ray_if_moving<R: ScalarReal>(&self, store: &ParamView) -> DiffRay<R> {
        if store.moves_geometry() {
            self.ray(store)
        } else {
            DiffRay::cst(&self.ray::<f32>(store).val())
        }
    }

    /// The camera ray of this sample, in `R`.
    #[inline]
    pub fn ray<R: ScalarReal>(&self, store: &ParamView) -> DiffRay<R> {
        self.sensor.ray(store, self.film, self.lens)
    }
}

/// A camera with its film and sampler.
///
/// Its pose and lens live in the scene's [`ParamStore`] under Mitsuba's
/// `traverse()` names, prefixed by `key`: `<key>.to_world` for every camera
/// (see the camera types for the others). All are geometry parameters:
/// moving the camera moves silhouettes across the image.
#[derive(Clone, Debug)]
pub struct Sensor {
    /// Parameter-key prefix (the sensor's id, or `_unnamed_<n>`).
    pub key: String,
    pub camera: Camera,
    pub film: Film,
    pub sampler: Sampler,
    /// The medium the sensor sits in (an index into the scene's media),
    /// set by the scene builder.
    pub medium: Option<u32>,
    pose: Pose,
    /// The parameters' current values as primal rays use them, refreshed
    /// by [`Sensor::parameters_changed`]: an f32 camera ray reads no
    /// parameter and evaluates no tangent.
    primal: PrimalLens,
}

/// The primal pose and pinhole lens of a sensor: `to_world` (row-major)
/// and `(tan(x_fov / 2), principal point offset)` (zero for cameras
/// without a field of view).
#[derive(Clone, Copy, Debug)]
struct PrimalLens {
    to_world: [f32; 16],
    lens: (f32, [f32; 2]),
}

/// Where a sensor's `to_world` comes from.
#[derive(Clone, Copy, Debug)]
enum Pose {
    /// The `<key>.to_world` parameter (differentiable).
    Param(ParamId),
    /// A constant pose, for a copy placed elsewhere by
    /// [`Sensor::with_to_world`]: not a parameter, so not differentiated.
    Fixed(Transform),
}

/// A sensor's `to_world` in `R`, row-major.
pub(crate) struct ToWorld<R>([R; 16]);

impl<R: ScalarReal> ToWorld<R> {
    fn read(pose: &Pose, store: &ParamView) -> Self {
        ToWorld(match pose {
            Pose::Param(id) => std::array::from_fn(|i| store.read(*id, i)),
            Pose::Fixed(t) => {
                let rows = t.m.transpose().to_cols_array();
                std::array::from_fn(|i| R::cst(rows[i]))
            }
        })
    }

    #[inline(always)]
    pub(crate) fn point(&self, p: V3<R>) -> V3<R> {
        let row = |k: usize| self.row(k, p) + self.0[4 * k + 3];
        let (x, y, z, w) = (row(0), row(1), row(2), row(3));
        if w.val() == 1.0 {
            V3::new(x, y, z)
        } else {
            V3::new(x / w, y / w, z / w)
        }
    }
}

impl<R: Real> ToWorld<R> {
    /// Row `k` of the linear part applied to `v`, summed in the order of
    /// glam's matrix product, so that `R = f32` reproduces [`Transform`]
    /// bit for bit (the reference images do not change).
    #[inline(always)]
    fn row(&self, k: usize, v: V3<R>) -> R {
        let m = &self.0[4 * k..4 * k + 3];
        v.x * m[0] + v.y * m[1] + v.z * m[2]
    }

    #[inline(always)]
    pub(crate) fn vector(&self, v: V3<R>) -> V3<R> {
        V3::new(self.row(0, v), self.row(1, v), self.row(2, v))
    }
}

impl Sensor {
    /// Builds the sensor of a `<sensor>` node and registers its parameters
    /// in `store`.
    pub fn from_node(node: &Node, store: &mut ParamStore) -> Result<Sensor> {
        let film = match node.children(Class::Film).as_slice() {
            [] => Film::new(768, 576, ReconstructionFilter::gaussian(0.5)),
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
        let to_world = node.transform("to_world")?;
        let pose = Pose::Param(
            store
                .add(
                    format!("{}.to_world", node.key),
                    to_world.m.transpose().to_cols_array().to_vec(),
                    vec![4, 4],
                    ParamFlags::GEOMETRY,
                    Domain::Finite,
                )
                .map_err(|e| node.error(e))?,
        );
        let camera = match node.plugin.as_str() {
            "perspective" => Camera::Perspective(Perspective::from_node(node, aspect, store)?),
            "thinlens" => Camera::ThinLens(ThinLens::from_node(node, aspect, store)?),
            "orthographic" => Camera::Orthographic(Orthographic::from_node(node, aspect)?),
            other => {
                return Err(node.error(format!(
                    "unknown sensor plugin '{other}' (Penumbra has: perspective, thinlens, orthographic)"
                )))
            }
        };
        node.check_all_used()?;
        let mut sensor = Sensor {
            key: node.key.clone(),
            camera,
            film,
            sampler,
            medium: None,
            pose,
            primal: PrimalLens {
                to_world: [0.0; 16],
                lens: (0.0, [0.0; 2]),
            },
        };
        sensor
            .parameters_changed(store)
            .map_err(|e| node.error(e))?;
        Ok(sensor)
    }

    /// Checks the sensor's parameters after an update: `to_world` must be
    /// invertible (a camera is placed, not collapsed), the field of view in
    /// (0°, 180°); and refreshes the copy of their values that primal rays
    /// read.
    pub fn parameters_changed(&mut self, store: &ParamStore) -> Result<()> {
        if let Pose::Param(id) = self.pose {
            let rows: [f32; 16] = std::array::from_fn(|i| store.value(id, i));
            if Transform::new(Mat4::from_cols_array(&rows).transpose()).is_none() {
                return Err(Error::Param {
                    key: store.get(id).key.clone(),
                    msg: "the camera's to_world must be finite and invertible".into(),
                });
            }
        }
        match &self.camera {
            Camera::Perspective(c) => c.frustum.check(store)?,
            Camera::ThinLens(c) => c.frustum.check(store)?,
            Camera::Orthographic(_) => {}
        }
        let primal = store.primal();
        self.primal = PrimalLens {
            to_world: ToWorld::<f32>::read(&self.pose, &primal).0,
            lens: self.read_lens::<f32>(&primal),
        };
        Ok(())
    }

    /// `tan(x_fov / 2)` and the principal point offset in `R` (zero for an
    /// orthographic camera).
    #[inline(always)]
    fn read_lens<R: ScalarReal>(&self, store: &ParamView) -> (R, [R; 2]) {
        match &self.camera {
            Camera::Perspective(c) => c.frustum.read(store),
            Camera::ThinLens(c) => c.frustum.read(store),
            Camera::Orthographic(_) => (R::cst(0.0), [R::cst(0.0); 2]),
        }
    }

    /// The ray through film position `film` (in [0,1]² over the full film,
    /// (0,0) = top-left) and lens position `lens` ∈ [0,1]², in `R`: origin
    /// and direction follow the sensor's parameters (see [`CameraSample`]).
    /// In f32 the values refreshed by the last update are used (the same
    /// numbers, without reading them again per ray).
    #[inline]
    pub fn ray<R: ScalarReal>(&self, store: &ParamView, film: Vec2, lens: Vec2) -> DiffRay<R> {
        let (to_world, lens_params) = if R::DIFFERENTIABLE {
            (ToWorld::read(&self.pose, store), self.read_lens(store))
        } else {
            let (tan_x, [ox, oy]) = self.primal.lens;
            (
                ToWorld(self.primal.to_world.map(R::cst)),
                (R::cst(tan_x), [R::cst(ox), R::cst(oy)]),
            )
        };
        match &self.camera {
            Camera::Perspective(c) => c.ray(&to_world, lens_params, film),
            Camera::ThinLens(c) => c.ray(store, &to_world, lens_params, film, lens),
            Camera::Orthographic(c) => c.ray(&to_world, film),
        }
    }

    /// The f32 rays of a pinhole camera through the film positions `film`
    /// ([`CameraSample::film`]), all at once in lanes (a pixel's packet of
    /// camera rays): lane by lane the arithmetic of [`Sensor::ray`] in f32,
    /// so the same rays bit for bit, without a chain of divisions and
    /// square roots per ray, written to `rays`. False (and `rays` left as
    /// they are) for the other cameras.
    #[inline(always)]
    pub(crate) fn pinhole_rays<const N: usize>(
        &self,
        film: &[Vec2; N],
        rays: &mut [Ray; N],
    ) -> bool {
        let Camera::Perspective(c) = &self.camera else {
            return false;
        };
        let o = ToWorld(self.primal.to_world).point(V3::<f32>::zero()).val();
        let (tan_x, [ox, oy]) = self.primal.lens;
        let lens = (Lanes::splat(tan_x), [Lanes::splat(ox), Lanes::splat(oy)]);
        let pos = [Lanes::from_fn(|k| film[k].x), Lanes::from_fn(|k| film[k].y)];
        let v = c.frustum.direction::<Lanes<N>>(lens, pos);
        let len = v.length();
        let d = ToWorld(self.primal.to_world.map(Lanes::splat))
            .vector(v)
            .normalize();
        let (near, far) = (c.frustum.near, c.frustum.far);
        // written ray by ray, not through `std::array::from_fn`, whose
        // closure may be left out of line, without the lanes' target
        // features
        for (k, ray) in rays.iter_mut().enumerate() {
            *ray = Ray {
                o,
                d: lane3(d, k),
                tmin: near * len.0[k],
                tmax: far * len.0[k],
            };
        }
        true
    }

    /// True if rays need a lens sample (thin lens with an aperture).
    pub fn needs_aperture_sample(&self) -> bool {
        matches!(self.camera, Camera::ThinLens(_))
    }

    /// The same sensor (film, sampler, lens) placed at another pose, e.g.
    /// for the extra views of a multi-view optimisation. The pose is a
    /// constant of the copy: `<key>.to_world` no longer moves it.
    pub fn with_to_world(&self, to_world: Transform) -> Sensor {
        let rows = to_world.m.transpose().to_cols_array();
        Sensor {
            pose: Pose::Fixed(to_world),
            primal: PrimalLens {
                to_world: rows,
                ..self.primal
            },
            ..self.clone()
        }
    }
}

/// The horizontal field of view (degrees) of a film of aspect ratio
/// `aspect` = width / height, as Mitsuba reads it: either `fov` (degrees)
/// along `fov_axis` (x, the default; y, diagonal, smaller, larger), or
/// `focal_length` (default "50mm", 35 mm film equivalent), which gives the
/// diagonal field of view of a 36 × 24 mm frame. Not both.
pub(crate) fn fov_x(node: &Node, aspect: f32) -> Result<f32> {
    let (fov, axis) = match node.prop("fov") {
        Some(p) => {
            if node.has("focal_length") {
                return Err(node.prop_error(
                    p,
                    "give either a field of view ('fov') or a focal length ('focal_length'), not both",
                ));
            }
            let fov = node.float("fov", 0.0)?;
            let axis = node.string("fov_axis", "x")?.to_lowercase();
            let axis = match axis.as_str() {
                "smaller" if aspect > 1.0 => "y".to_string(),
                "smaller" => "x".to_string(),
                "larger" if aspect > 1.0 => "x".to_string(),
                "larger" => "y".to_string(),
                "x" | "y" | "diagonal" => axis,
                _ => {
                    let p = node
                        .prop("fov_axis")
                        .expect("a non-default value came from a property");
                    return Err(node.prop_error(
                        p,
                        format!("'{axis}' is not one of: x, y, diagonal, smaller, larger"),
                    ));
                }
            };
            (fov as f64, axis)
        }
        None => {
            if let Some(p) = node.prop("fov_axis") {
                return Err(node.prop_error(
                    p,
                    "applies to 'fov' only (a focal length gives the diagonal field of view); \
                     remove it or give 'fov'",
                ));
            }
            let s = node.string("focal_length", "50mm")?;
            let mm: f64 = s
                .strip_suffix("mm")
                .unwrap_or(&s)
                .trim()
                .parse()
                .ok()
                .filter(|mm: &f64| *mm > 0.0 && mm.is_finite())
                .ok_or_else(|| {
                    let p = node.prop("focal_length").expect("the default parses");
                    node.prop_error(p, format!("'{s}' is not a focal length like '50mm'"))
                })?;
            // the diagonal of a 36 × 24 mm frame
            let diagonal = (36.0f64 * 36.0 + 24.0 * 24.0).sqrt();
            (
                2.0 * (diagonal / (2.0 * mm)).atan().to_degrees(),
                "diagonal".to_string(),
            )
        }
    };
    let x_fov = x_fov_along(fov, &axis, aspect as f64);
    if !(x_fov > 0.0 && x_fov < 180.0) {
        let p = node
            .prop("fov")
            .or_else(|| node.prop("focal_length"))
            .expect("the default focal length is in range");
        return Err(node.prop_error(
            p,
            format!("gives a horizontal field of view of {x_fov} degrees; it must be in (0, 180)"),
        ));
    }
    Ok(x_fov as f32)
}

/// The horizontal field of view (degrees) of a film of aspect ratio
/// `aspect` whose field of view along `axis` (x, y or diagonal) is `fov`:
/// the half-angle tangents scale with the film's extent along each axis.
fn x_fov_along(fov: f64, axis: &str, aspect: f64) -> f64 {
    let t = (fov.to_radians() * 0.5).tan();
    let tx = match axis {
        "x" => t,
        "y" => t * aspect,
        _ => t * aspect / (1.0 + aspect * aspect).sqrt(),
    };
    2.0 * tx.atan().to_degrees()
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

/// The pinhole part shared by the perspective and thin-lens cameras:
/// `<key>.x_fov` (horizontal field of view, degrees), with the film's
/// aspect ratio and the clip range, and for the perspective camera only (as
/// in Mitsuba) `<key>.principal_point_offset_x` / `_y`, the position of
/// the principal point relative to the film's centre in units of the film
/// size.
#[derive(Clone, Debug)]
pub struct Frustum {
    pub x_fov: ParamId,
    pub principal_point_offset: Option<[ParamId; 2]>,
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
}

impl Frustum {
    fn from_node(
        node: &Node,
        aspect: f32,
        principal_point: bool,
        store: &mut ParamStore,
    ) -> Result<Frustum> {
        let fov = fov_x(node, aspect)?;
        let (near, far) = clip_range(node)?;
        let x_fov = add_scalar(node, "x_fov", fov, Domain::Positive, store)?;
        let principal_point_offset = if principal_point {
            let mut offset = |name: &str| {
                let v = node.float(name, 0.0)?;
                add_scalar(node, name, v, Domain::Finite, store)
            };
            Some([
                offset("principal_point_offset_x")?,
                offset("principal_point_offset_y")?,
            ])
        } else {
            None
        };
        Ok(Frustum {
            x_fov,
            principal_point_offset,
            aspect,
            near,
            far,
        })
    }

    /// `tan(x_fov / 2)` and the principal point offset, in `R`.
    #[inline(always)]
    pub(crate) fn read<R: ScalarReal>(&self, store: &ParamView) -> (R, [R; 2]) {
        // `to_radians` spelled out, as the same f32 operations
        let tan_x = (store.read::<R>(self.x_fov, 0) * (std::f32::consts::PI / 180.0) * 0.5).tan();
        let offset = match self.principal_point_offset {
            Some(ids) => ids.map(|id| store.read::<R>(id, 0)),
            None => [R::cst(0.0); 2],
        };
        (tan_x, offset)
    }

    /// The store's domain check gives fov > 0; a pinhole cannot see 180°.
    fn check(&self, store: &ParamStore) -> Result<()> {
        let fov = store.value(self.x_fov, 0);
        if !(fov < 180.0) {
            return Err(Error::Param {
                key: store.get(self.x_fov).key.clone(),
                msg: format!("must be in (0, 180) degrees, found {fov}"),
            });
        }
        Ok(())
    }

    /// Camera-space direction (z = 1, not normalised) through film position
    /// `pos` ∈ [0,1]², as Mitsuba maps it: film x grows towards camera −x
    /// ("left" is +x), film y downwards, and the principal point offset is
    /// added to the film position before the mapping.
    /// `lens` is `(tan(x_fov / 2), principal point offset)` as
    /// [`Frustum::read`] gives them.
    /// In any [`Real`]: film positions in lanes give the rays of a block
    /// of samples (`Sensor::pinhole_rays`).
    #[inline(always)]
    fn direction<R: Real>(&self, (tan_x, [ox, oy]): (R, [R; 2]), pos: [R::Prim; 2]) -> V3<R> {
        let from_film = |p: R::Prim| R::from_prim(R::Prim::cst(1.0) - p * 2.0);
        let x = (from_film(pos[0]) - ox * 2.0) * tan_x;
        let y = (from_film(pos[1]) - oy * 2.0) * tan_x / self.aspect;
        V3::new(x, y, R::cst(1.0))
    }
}

/// Registers the scalar `<key>.<name>` of a camera (a geometry parameter).
fn add_scalar(
    node: &Node,
    name: &str,
    value: f32,
    domain: Domain,
    store: &mut ParamStore,
) -> Result<ParamId> {
    store
        .add(
            format!("{}.{name}", node.key),
            vec![value],
            vec![1],
            ParamFlags::GEOMETRY,
            domain,
        )
        .map_err(|e| node.error(e))
}

#[cfg(test)]
mod tests;
