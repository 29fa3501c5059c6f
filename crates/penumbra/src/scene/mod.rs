//! Scenes: the scene description ([`description`], below the plugins: it
//! imports none; the [`LoadContext`] plugins are built with is part of
//! it), and the assembly (`build.rs`, above the plugins) of the [`Scene`]
//! that integrators render.

pub mod description;

pub use description::{
    child_key, parse_file, parse_str, Class, FileResolver, LoadContext, Node, Prop,
    SceneDescription, Value,
};

use crate::error::{Error, Result};
use crate::params::{ParamStore, ParamView};

mod build;

use crate::ad::ScalarReal;
use crate::bsdf::{Bsdf, BsdfFlags};
use crate::emitter::{Emitter, EmitterSample, EmitterT};
use crate::geometry::accel::Accel;
use crate::geometry::{
    DiffRay, Hit, Instance, Ray, Shape, ShapeGroup, ShapeT, SurfaceInteraction, SurfacePoint,
};
use crate::integrator::Integrator;
use crate::math::{DiscreteDistribution, V3};
use crate::medium::Medium;
use crate::sensor::Sensor;
use glam::{Vec2, Vec3};
use std::path::Path;

/// Rays traced by one parallel task of [`Scene::intersect_rays`] and
/// [`Scene::occluded_rays`] (and of the Python `Scene.ray_intersect` /
/// `ray_test`): consecutive rays, the last task shorter. Every task is a
/// unit of rayon's work stealing, as Embree's users hand out chunks of rays
/// from a counter: left to its adaptive splitting, rayon cuts a batch into
/// a few pieces per thread (a quarter to a sixteenth of the rays each), and
/// since the cost of neighbouring rays is alike (sky, mesh), the thread
/// left with the last expensive piece worked 1.1–1.25× the mean. A task of
/// 1024 rays (0.1–0.5 ms) outweighs its scheduling (~1 µs).
pub const RAYS_PER_TASK: usize = 1024;

/// What the scene knows about a shape besides its geometry.
#[derive(Clone, Debug)]
pub struct ShapeInfo {
    /// Parameter-key prefix (the shape's id).
    pub key: String,
    pub bsdf: u32,
    /// The flags of [`ShapeInfo::bsdf`] (they follow from the BSDF's
    /// plugins, not from its parameters): read at every vertex, where
    /// asking the BSDF walks its wrappers.
    pub bsdf_flags: BsdfFlags,
    pub emitter: Option<u32>,
    /// The media inside and outside the shape (indices into
    /// [`Scene::media`]); outside is the side the normal points to.
    pub interior: Option<u32>,
    pub exterior: Option<u32>,
    /// The shape group the shape belongs to (index into
    /// [`Scene::groups`]): it is then rendered only through instances, and
    /// its geometry is in the group's space.
    pub group: Option<u32>,
}

/// A loaded scene: parameters, plugins, and the acceleration structure.
#[derive(Clone, Debug)]
pub struct Scene {
    pub params: ParamStore,
    /// Every shape, those of shape groups included.
    pub shapes: Vec<Shape>,
    pub shape_info: Vec<ShapeInfo>,
    /// The shape groups (`shapegroup`), rendered through [`Scene::instances`].
    pub groups: Vec<ShapeGroup>,
    /// The instances of shape groups (`instance`).
    pub instances: Vec<Instance>,
    pub bsdfs: Vec<Bsdf>,
    pub emitters: Vec<Emitter>,
    /// How next-event estimation picks an emitter (by `sampling_weight`).
    pub emitter_distribution: Option<DiscreteDistribution>,
    /// The environment emitter (constant, envmap), if any.
    pub environment: Option<u32>,
    /// The sensors, in file order (`RenderOptions::sensor` picks one).
    pub sensors: Vec<Sensor>,
    /// The participating media (shapes' `interior`/`exterior`, sensors').
    pub media: Vec<Medium>,
    pub integrator: Integrator,
    pub accel: Accel,
}

impl Scene {
    /// Loads a Mitsuba 3 XML scene; `defines` override its `<default>`s.
    pub fn load_file(path: &Path, defines: &[(String, String)]) -> Result<Scene> {
        Scene::from_description(&parse_file(path, defines)?)
    }

    /// Loads a scene from XML text; `path` names it in error messages and
    /// is the base of relative file names.
    pub fn load_str(text: &str, path: &Path, defines: &[(String, String)]) -> Result<Scene> {
        Scene::from_description(&parse_str(text, path, defines)?)
    }

    /// Sensor `i`, or an error naming how many there are.
    pub fn sensor(&self, i: usize) -> Result<&Sensor> {
        self.sensors.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "sensor {i} does not exist: the scene has {} sensor(s)",
                self.sensors.len()
            ))
        })
    }

    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.accel.intersect(ray)
    }

    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.accel.occluded(ray)
    }

    /// The first hits of many rays, traced in parallel on rayon's threads
    /// (in tasks of [`RAYS_PER_TASK`] rays).
    pub fn intersect_rays(&self, rays: &[Ray]) -> Vec<Option<Hit>> {
        use rayon::prelude::*;
        let mut hits = vec![None; rays.len()];
        hits.par_chunks_mut(RAYS_PER_TASK)
            .zip(rays.par_chunks(RAYS_PER_TASK))
            .with_max_len(1)
            .for_each(|(h, r)| {
                for (h, r) in h.iter_mut().zip(r) {
                    *h = self.intersect(r);
                }
            });
        hits
    }

    /// Whether each of many rays hits anything, in parallel (in tasks of
    /// [`RAYS_PER_TASK`] rays).
    pub fn occluded_rays(&self, rays: &[Ray]) -> Vec<bool> {
        use rayon::prelude::*;
        let mut hit = vec![false; rays.len()];
        hit.par_chunks_mut(RAYS_PER_TASK)
            .zip(rays.par_chunks(RAYS_PER_TASK))
            .with_max_len(1)
            .for_each(|(h, r)| {
                for (h, r) in h.iter_mut().zip(r) {
                    *h = self.occluded(r);
                }
            });
        hit
    }

    /// Re-evaluates a hit in `R`, the point sliding along `ray` (see
    /// [`ShapeT::surface_interaction`]).
    #[inline]
    pub fn surface_interaction<R: ScalarReal>(
        &self,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        let shape = &self.shapes[hit.shape as usize];
        if R::DIFFERENTIABLE && ray.is_const() && !shape.reads_tracked::<R>(store) {
            // nothing the hit depends on carries a derivative
            let ray = DiffRay::<f32>::cst(&ray.val());
            return SurfaceInteraction::cst(&self.hit_interaction(shape, store, &ray, hit));
        }
        self.hit_interaction(shape, store, ray, hit)
    }

    /// The point and geometric normal of `hit` (primal), equal to those of
    /// [`Scene::surface_interaction`] for a surface that does not move:
    /// what a ray passing through an index-matched boundary needs, at the
    /// cost of an interpolation for a triangle.
    pub fn hit_point(&self, store: &ParamView, ray: &Ray, hit: &Hit) -> SurfacePoint {
        match (&self.shapes[hit.shape as usize], hit.instance) {
            (Shape::Mesh(mesh), None) => mesh.triangle_point_primal(store, hit),
            _ => self
                .surface_interaction::<f32>(store, &DiffRay::cst(ray), hit)
                .point(),
        }
    }

    /// [`Scene::surface_interaction`] of a hit of `shape`, directly or
    /// through the instance that was hit.
    #[inline(always)]
    fn hit_interaction<R: ScalarReal>(
        &self,
        shape: &Shape,
        store: &ParamView,
        ray: &DiffRay<R>,
        hit: &Hit,
    ) -> SurfaceInteraction<R> {
        match hit.instance {
            None => shape.surface_interaction(store, ray, hit),
            Some(i) => self.instances[i as usize].surface_interaction(shape, store, ray, hit),
        }
    }

    /// Re-evaluates a hit in `R` as a point that moves with its shape (see
    /// [`ShapeT::point_at`]); `p` is the primal hit point.
    #[inline]
    pub fn point_at<R: ScalarReal>(
        &self,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        let shape = &self.shapes[hit.shape as usize];
        if R::DIFFERENTIABLE && !shape.reads_tracked::<R>(store) {
            return SurfaceInteraction::cst(&self.point_interaction(shape, store, hit, p));
        }
        self.point_interaction(shape, store, hit, p)
    }

    /// [`Scene::point_at`] of `shape`, directly or through its instance.
    #[inline(always)]
    fn point_interaction<R: ScalarReal>(
        &self,
        shape: &Shape,
        store: &ParamView,
        hit: &Hit,
        p: Vec3,
    ) -> SurfaceInteraction<R> {
        match hit.instance {
            None => shape.point_at(store, hit, p),
            Some(i) => self.instances[i as usize].point_at(shape, store, hit, p),
        }
    }

    /// Whether shape `shape` belongs to a shape group (it is then seen only
    /// through instances, and its geometry is in the group's space).
    #[inline]
    pub fn in_group(&self, shape: u32) -> bool {
        self.shape_info[shape as usize].group.is_some()
    }

    #[inline]
    pub fn shape_bsdf(&self, shape: u32) -> &Bsdf {
        &self.bsdfs[self.shape_info[shape as usize].bsdf as usize]
    }

    #[inline]
    pub fn shape_bsdf_flags(&self, shape: u32) -> BsdfFlags {
        self.shape_info[shape as usize].bsdf_flags
    }

    #[inline]
    pub fn shape_emitter(&self, shape: u32) -> Option<u32> {
        self.shape_info[shape as usize].emitter
    }

    /// Samples an emitter (by `sampling_weight`), then a direction towards
    /// it from `ref_p`, without testing visibility. Returns the sample with
    /// its weight `radiance / pdf` and density including the selection
    /// probability, in `R` following `ref_p` and the emitter.
    pub fn sample_emitter<R: ScalarReal>(
        &self,
        store: &ParamView,
        ref_p: V3<R>,
        u: Vec2,
    ) -> Option<EmitterSample<R>> {
        let (i, pick, ux) = self.emitter_distribution.as_ref()?.sample_reuse(u.x);
        let u = Vec2::new(ux, u.y);
        let mut es = self.emitters[i].sample_direction::<R>(store, &self.shapes, ref_p, u)?;
        if !(es.ds.pdf > 0.0) {
            return None;
        }
        es.ds.pdf *= pick;
        es.weight = es.weight.scale(1.0 / pick);
        Some(es)
    }

    /// Whether nothing lies between `si` and the point (or, for an emitter
    /// at infinity, the direction) of the emitter sample `es` taken from it:
    /// the shadow ray of next-event estimation. Integrators test it after
    /// the BSDF's value for the sample's direction, and only where that is
    /// nonzero: a light behind a reflecting surface (half the directions
    /// of an environment's uniform samples) needs no traversal.
    pub fn emitter_visible<R: ScalarReal>(
        &self,
        si: &SurfaceInteraction<R>,
        es: &EmitterSample<R>,
    ) -> bool {
        let ray = if es.ds.dist.is_finite() {
            si.spawn_ray_to(es.ds.p)
        } else {
            si.spawn_ray(es.ds.d)
        };
        !self.occluded(&ray)
    }

    /// Solid-angle density with which [`Scene::sample_emitter`]
    /// picks direction `d` from `ref_p` towards emitter `em`, reaching the
    /// point `p` with normal `n`.
    pub fn pdf_emitter_direction(&self, em: u32, ref_p: Vec3, d: Vec3, p: Vec3, n: Vec3) -> f32 {
        let pick = self
            .emitter_distribution
            .as_ref()
            .map_or(0.0, |dist| dist.pmf(em as usize));
        self.emitters[em as usize].pdf_direction(&self.params, &self.shapes, ref_p, d, p, n) * pick
    }

    /// Applies parameter updates: refreshes what depends on the changed
    /// parameters (vertex normals and the acceleration structure after
    /// vertex moves, envmap sampling after texel changes, BSDF sampling
    /// weights), and checks the sensors' poses and fields of view.
    pub fn update(&mut self) -> Result<()> {
        let changed = self.params.take_dirty();
        if changed.is_empty() {
            return Ok(());
        }
        for s in &mut self.shapes {
            s.parameters_changed(&mut self.params, &changed)?;
        }
        for inst in &mut self.instances {
            if changed.contains(&inst.to_world) {
                inst.parameters_changed(&self.params)?;
            }
        }
        // normals recomputed above are consequences, not new updates
        self.params.take_dirty();
        // only surfaces that moved need the acceleration structure refit
        // (a camera move does not)
        if self
            .shapes
            .iter()
            .any(|s| s.geometry_params().iter().any(|id| changed.contains(id)))
            || self.instances.iter().any(|i| changed.contains(&i.to_world))
        {
            self.accel
                .update_instanced(&self.shapes, &self.instances, &self.params);
        }
        for e in &mut self.emitters {
            e.parameters_changed(&self.params, &changed);
        }
        for b in &mut self.bsdfs {
            b.parameters_changed(&self.params);
        }
        for m in &mut self.media {
            m.parameters_changed(&self.params);
        }
        for s in &mut self.sensors {
            s.parameters_changed(&self.params)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The point and normal a ray passing through a surface is given are
    /// those of the full interaction, for meshes (flipped, rotated,
    /// instanced) and analytic shapes.
    #[test]
    fn hit_points_are_those_of_the_surface_interaction() {
        let scene = Scene::load_str(
            r#"<scene version="3.0.0">
                <sensor type="perspective"/>
                <shape type="sphere"><point name="center" x="-2" y="0" z="0"/></shape>
                <shape type="cube">
                    <boolean name="flip_normals" value="true"/>
                    <transform name="to_world">
                        <scale x="0.7" y="1.2" z="0.5"/><rotate x="1" y="1" angle="30"/>
                    </transform>
                </shape>
                <shape type="shapegroup" id="group">
                    <shape type="rectangle"/>
                </shape>
                <shape type="instance">
                    <ref id="group"/>
                    <transform name="to_world"><translate x="2.5"/></transform>
                </shape>
            </scene>"#,
            Path::new("t.xml"),
            &[],
        )
        .unwrap();
        let store = scene.params.primal();
        let mut kinds = [0; 3];
        for i in 0..400 {
            let (x, y) = ((i % 20) as f32 / 4.0 - 2.6, (i / 20) as f32 / 8.0 - 1.2);
            let ray = Ray::new(
                Vec3::new(x, y, -5.0),
                Vec3::new(0.02, 0.01, 1.0).normalize(),
            );
            let Some(hit) = scene.intersect(&ray) else {
                continue;
            };
            let si = scene.surface_interaction::<f32>(&store, &DiffRay::cst(&ray), &hit);
            assert_eq!(scene.hit_point(&store, &ray, &hit), si.point(), "{hit:?}");
            kinds[if hit.instance.is_some() {
                2
            } else {
                hit.shape.min(1) as usize
            }] += 1;
        }
        assert!(kinds.iter().all(|&k| k > 10), "{kinds:?}");
    }

    #[test]
    fn batch_queries_equal_one_ray_at_a_time() {
        // a sphere before a rectangle; rays over both and past them, more
        // than a few tasks' worth and not a multiple of RAYS_PER_TASK
        let scene = Scene::load_str(
            r#"<scene version="3.0.0">
                <sensor type="perspective"/>
                <shape type="sphere"/>
                <shape type="rectangle">
                    <transform name="to_world"><scale value="3"/><translate z="2"/></transform>
                </shape>
            </scene>"#,
            Path::new("t.xml"),
            &[],
        )
        .unwrap();
        let n = 5 * RAYS_PER_TASK + 17;
        let rays: Vec<Ray> = (0..n)
            .map(|i| {
                let (x, y) = ((i % 101) as f32 / 25.0 - 2.0, (i / 101) as f32 / 13.0 - 2.0);
                let mut r = Ray::new(Vec3::new(x, y, -5.0), Vec3::new(0.01 * x, 0.0, 1.0));
                r.tmax = if i % 3 == 0 { 5.5 } else { f32::INFINITY };
                r
            })
            .collect();
        let hits = scene.intersect_rays(&rays);
        let blocked = scene.occluded_rays(&rays);
        assert_eq!((hits.len(), blocked.len()), (n, n));
        let key = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.shape, h.prim, h.uv.to_array()));
        for (i, r) in rays.iter().enumerate() {
            assert_eq!(key(hits[i]), key(scene.intersect(r)), "ray {i}");
            assert_eq!(blocked[i], scene.occluded(r), "ray {i}");
        }
        let shapes: Vec<u32> = hits.iter().flatten().map(|h| h.shape).collect();
        assert!(shapes.contains(&0) && shapes.contains(&1) && shapes.len() < n);
    }
}
