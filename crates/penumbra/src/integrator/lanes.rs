//! The path tracer's primal image, many samples at once: each of `N`
//! samples of a pixel is a lane of [`Lanes<N>`], and the shading of a
//! bounce (the vertex's frame, the BSDF's value, density and sample, the
//! MIS weights, Russian roulette, the throughput) is one instruction for
//! all of them: four lanes by default ([`lane_width`]), 8 or 16 where the
//! processor has AVX2 or AVX-512 and they are asked for
//! (docs/perf/lanes.md). Emission and light sampling of `area`
//! emitters on meshes (a plain radiance) are in lanes too, and light
//! samples of a `constant` environment of plain radiance, of a `point`
//! light of plain intensity and of a `directional` light of plain
//! irradiance are drawn here.
//! A pixel's camera rays, up to [`PACKET`] of them, are traced together
//! as one packet before their samples are shaded `N` at a time, and the
//! primal image traces their light samples' shadow rays likewise, depth
//! by depth, once their paths are done ([`ShadowQueue`]); the bounce
//! rays' traversal, the other emitters' sampling and
//! texture look-ups (at an interaction that holds only the hit's uv) are
//! the plugins' own code, called lane by lane.
//!
//! The estimator is [`PathIntegrator::trace`]'s, step for step (the same
//! random numbers drawn in the same order), for the scenes whose plugins
//! have their shading written for lanes so far: triangle meshes (not
//! instanced) and spheres, whose BSDFs are `diffuse` or rough GGX
//! conductors, dielectrics and plastics of plain parameters
//! ([`crate::bsdf::lanes`]); textured reflectances on meshes; any
//! emitters, area lights on meshes. Other scenes, derivatives and the
//! other integrators take the scalar loop. The images of both loops agree
//! within noise, not bit for bit: the shading frame here is built from
//! the shading normal alone, where the scalar loop's follows the
//! surface's tangent, so the same random numbers give other (equally
//! distributed) directions.

use super::path::PathIntegrator;
use super::render::{SampleLayout, Tile};
use super::{mis_weight, survival_probability, Integrator};
use crate::ad::lanes::{each_lane, lane3, lanes3, widest_lanes, LaneMask, Lanes};
use crate::ad::{Float, Mask, Real};
use crate::bsdf::lambert_eval;
use crate::bsdf::lanes::{BsdfLanes, LaneBsdf, MixedLanes};
use crate::emitter::{point_light_sample, surface_si, Constant, Emitter, EmitterT};
use crate::error::{Error, Result};
use crate::geometry::mesh::Mesh;
use crate::geometry::{Hit, Ray, Shape, ShapeT, SurfacePoint};
use crate::image::film::PixelSplat;
use crate::image::ImageBlock;
use crate::math::{Frame, Spectrum, V2, V3};
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::Scene;
use crate::sensor::Camera;
use crate::texture::{Texture, TextureT};
use glam::{Vec2, Vec3};

/// How many of a pixel's samples have their camera rays traced together,
/// as one packet ([`crate::geometry::Accel::intersect_packet`]): one
/// pixel's camera rays leave one point in nearly one direction, the most
/// coherent rays there are, and sixteen of them fill an AVX-512 register
/// (or two AVX2 ones).
/// The samples are then shaded `N` at a time (docs/perf/traversal.md,
/// "Camera rays in packets").
const PACKET: usize = 16;

/// Up to [`PACKET`] samples of a pixel ([`LanePath::camera_group`]): film
/// positions in pixels, camera rays, their first hits, and the samples'
/// streams of random numbers.
pub(crate) struct CameraGroup {
    pos: [Vec2; PACKET],
    rays: [Ray; PACKET],
    hits: [Option<Hit>; PACKET],
    rngs: [SampleStream; PACKET],
    count: usize,
}

/// `N` samples of a [`CameraGroup`] ([`CameraGroup::block`]), in place:
/// the loop traces them where the group holds them (copies of the rays,
/// hits and streams drew 4 % of the lanes loop's perf samples on
/// textured; 0.85 % fewer instructions without them).
pub(crate) struct SampleBlock<'g, const N: usize> {
    pub pos: &'g [Vec2; N],
    pub rays: &'g mut [Ray; N],
    pub hits: &'g mut [Option<Hit>; N],
    pub rngs: &'g mut [SampleStream; N],
    /// The lanes that hold a sample of the group.
    pub active: LaneMask<N>,
}

impl CameraGroup {
    /// An empty group, for [`LanePath::camera_group`] to fill.
    pub(crate) fn new() -> CameraGroup {
        CameraGroup {
            pos: [Vec2::ZERO; PACKET],
            rays: [Ray::new(Vec3::ZERO, Vec3::Z); PACKET],
            hits: [None; PACKET],
            rngs: [SampleStream::PLACEHOLDER; PACKET],
            count: 0,
        }
    }

    /// The number of samples in the group.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.count
    }

    /// Samples `at..at + N` of the group in `N` lanes. Lanes past the
    /// group's end are inactive and have no hit (the packet traced only
    /// the group's rays); their positions, rays and streams are whatever
    /// an earlier group left there, and are not read.
    #[inline(always)]
    pub(crate) fn block<const N: usize>(&mut self, at: usize) -> SampleBlock<'_, N> {
        const { assert!(PACKET.is_multiple_of(N)) };
        let lanes = at..at + N;
        let window = "a block lies within the group: `at` is a multiple of N, which divides PACKET";
        SampleBlock {
            pos: self.pos[lanes.clone()].try_into().expect(window),
            rays: (&mut self.rays[lanes.clone()]).try_into().expect(window),
            hits: (&mut self.hits[lanes.clone()]).try_into().expect(window),
            rngs: (&mut self.rngs[lanes]).try_into().expect(window),
            active: LaneMask::from_fn(|k| at + k < self.count),
        }
    }
}

/// What the loop reads of a shape at each hit.
struct LaneShape<'a> {
    geometry: LaneGeometry<'a>,
    bsdf: LaneBsdf<'a>,
    /// The diffuse reflectance of `diffuse` and `roughplastic` (zero for
    /// the others).
    albedo: Albedo<'a>,
    /// The shape's `area` emitter, if it has one.
    emission: Option<MeshLight<'a>>,
}

/// The surface a shape's hits are on.
#[derive(Clone, Copy)]
enum LaneGeometry<'a> {
    /// A triangle mesh: its triangle's corners, normals and face normal.
    Mesh(&'a Mesh),
    /// An analytic sphere: the hit's point put back on it along the
    /// direction from its centre (as the plugin's), which is its normal.
    Sphere {
        center: Vec3,
        radius: f32,
        flip_normals: bool,
    },
}

/// A diffuse reflectance as the loop looks it up.
#[derive(Clone, Copy)]
enum Albedo<'a> {
    /// A plain value.
    Plain(Vec3),
    /// A texture over a mesh's uv (not a mesh attribute, see
    /// [`LanePath::new`]): looked up at an interaction that holds only the
    /// hit's uv (bitmaps in lanes).
    Textured {
        mesh: &'a Mesh,
        texture: &'a Texture,
    },
}

/// An `area` emitter on a mesh with a plain radiance value: what its
/// emission and its samples need, in lanes without a surface interaction.
#[derive(Clone, Copy)]
struct MeshLight<'a> {
    mesh: &'a Mesh,
    radiance: Vec3,
    /// Density of the points [`Scene::sample_emitter`] draws on it, per
    /// unit area: the emitter's selection probability over the mesh's area.
    pdf_area: f32,
}

/// How the loop draws an emitter's light samples.
#[derive(Clone, Copy)]
enum LaneLight<'a> {
    /// An `area` light of a mesh: a point on it, the direction and
    /// density in lanes.
    Mesh(MeshLight<'a>),
    /// A `constant` environment of plain radiance, picked with
    /// probability `pick`: a direction, its density and weight without
    /// an emitter sample (the values of [`Scene::sample_emitter`]).
    Constant { radiance: Vec3, pick: f32 },
    /// A `point` light of plain intensity at `position`: its sample (a
    /// delta) drawn in the loop, with the `point` emitter's arithmetic.
    Point { position: Vec3, intensity: Vec3 },
    /// A `directional` light of plain irradiance, arriving from
    /// `towards`: its sample (a delta at infinity) drawn in the loop.
    Directional { towards: Vec3, irradiance: Vec3 },
    /// Any other emitter: its own code, lane by lane.
    Other,
}

/// How the lanes' paths scatter at a vertex (world directions): the
/// BSDF's value along the light sample's direction and along the bounce's
/// is all a path's estimate reads of the BSDF's parameters (its samples
/// are constants: detached sampling), so these and the factors they are
/// weighted by give its derivatives by them (`diff/prb_lanes.rs`).
#[derive(Clone, Copy)]
pub(crate) struct Scattering<const N: usize> {
    /// The shading normal, and the direction towards where the path came
    /// from.
    pub ns: V3<Lanes<N>>,
    pub wi: V3<Lanes<N>>,
    /// The light sample's direction, and its contribution per unit of the
    /// throughput and of the BSDF's value (its weight and MIS weight; zero
    /// where it is blocked or there is none).
    pub light_d: V3<Lanes<N>>,
    pub light_weight: V3<Lanes<N>>,
    /// The bounce's direction and density.
    pub bounce_d: V3<Lanes<N>>,
    pub bounce_pdf: Lanes<N>,
}

/// What a caller of [`LanePath::trace`] learns of each path beyond its
/// radiance, per depth (0: the vertex the camera ray reaches). Reverse
/// mode in lanes (`diff/prb_lanes.rs`) keeps the factors of every
/// contribution so as to differentiate the radiance by the reflectances
/// and by the emitters' radiances; the primal image keeps only the light
/// samples' shadow rays, to trace later ([`ShadowQueue`]; its other calls
/// are the empty defaults, which compile away, closures and all).
pub(crate) trait PathLog<const N: usize> {
    /// The vertices the lanes' rays reached at `depth` (`None`: escaped
    /// or ended), their points and face normals.
    #[inline(always)]
    fn vertex(&mut self, depth: u32, hits: &[Option<Hit>; N], p: V3<Lanes<N>>, n: &[Vec3; N]) {
        let _ = (depth, hits, p, n);
    }
    /// Radiance that reaches the camera from `depth` per unit of the
    /// throughput there: emission of a surface hit or of the environment.
    #[inline(always)]
    fn emitted(&mut self, depth: u32, per_throughput: impl FnOnce() -> V3<Lanes<N>>) {
        let _ = (depth, per_throughput);
    }
    /// Light of single emitters reaching the camera, for the derivatives
    /// by their radiance: `throughput` the throughput of the lanes' paths
    /// where it arrives, and per lane the emitter (`None` where there is
    /// none, or one whose radiance the loop does not read as a plain
    /// value) and the contribution per unit of the throughput and of that
    /// emitter's radiance (its surface or environment emission, or a light
    /// sample; each call one of them).
    #[inline(always)]
    fn light(
        &mut self,
        throughput: V3<Lanes<N>>,
        per_radiance: impl FnOnce() -> ([Option<u32>; N], V3<Lanes<N>>),
    ) {
        let _ = (throughput, per_radiance);
    }
    /// The light sample's contribution at `depth`, in two parts: at
    /// `diffuse` vertices per unit of the throughput times the reflectance
    /// there, and at vertices of other BSDFs per unit of the throughput
    /// (each part zero in the other part's lanes).
    #[inline(always)]
    fn next_event(
        &mut self,
        depth: u32,
        contribution: impl FnOnce() -> (V3<Lanes<N>>, V3<Lanes<N>>),
    ) {
        let _ = (depth, contribution);
    }
    /// The directions of the scattering at `depth`, for derivatives by
    /// the parameters of the vertices' BSDFs ([`Scattering`]).
    #[inline(always)]
    fn scattering(&mut self, depth: u32, scattering: impl FnOnce() -> Scattering<N>) {
        let _ = (depth, scattering);
    }
    /// The shadow rays `ray(k)` of the light samples in the lanes of
    /// `tried` at `depth`, whose contributions are `contribution()` where
    /// they are not blocked: the lanes whose contribution counts now (the
    /// loop adds it to the radiance and tells the log of it, by
    /// [`PathLog::light`] and [`PathLog::next_event`]). Traced here, one
    /// ray at a time; the primal image's log ([`ShadowQueue`]) takes them
    /// to trace later, a pixel's rays of one depth as one packet, and
    /// counts none now.
    #[inline(always)]
    fn shadows(
        &mut self,
        scene: &Scene,
        depth: u32,
        tried: LaneMask<N>,
        ray: impl Fn(usize) -> Ray,
        contribution: impl FnOnce() -> V3<Lanes<N>>,
    ) -> LaneMask<N> {
        let _ = (depth, contribution);
        LaneMask::from_fn(|k| tried.lane(k) && !occluded(scene, &ray(k)))
    }
    /// The bounce from `depth`: the throughput that reached the vertex,
    /// the BSDF sample's weight (a diffuse vertex's reflectance) and the
    /// roulette's factor on the throughput after it (0 where the path
    /// ended).
    #[inline(always)]
    fn bounce(
        &mut self,
        depth: u32,
        throughput: V3<Lanes<N>>,
        reflectance: V3<Lanes<N>>,
        survival: Lanes<N>,
    ) {
        let _ = (depth, throughput, reflectance, survival);
    }
}

/// The primal image's log: it keeps nothing of the paths but their light
/// samples' shadow rays, which [`LanePath::trace`] would trace one at a
/// time as it reaches them. Whether a light sample is blocked changes
/// nothing else of its path, so they wait until all the samples of a
/// [`CameraGroup`] are traced, and then go, depth by depth, as one packet
/// of up to [`PACKET`] rays ([`Accel::occluded_packet`](crate::geometry::Accel::occluded_packet)):
/// a pixel's shadow rays of one depth start near each other and, for an
/// area light, end near each other, and the packet's walk tests a node
/// once for all of them while enough of them enter it (docs/perf/traversal.md,
/// "Hybrid packets, an occlusion packet, and a pixel's shadow rays as
/// packets").
pub(crate) struct ShadowQueue {
    /// Per depth, the shadow rays of the group's samples.
    depths: Vec<ShadowBatch>,
    /// The group's sample in lane 0 of the block being traced.
    at: usize,
}

/// One depth's shadow rays of a group: per ray its sample in the group and
/// its contribution to that sample's radiance where it is not blocked.
#[derive(Clone, Copy)]
struct ShadowBatch {
    rays: [Ray; PACKET],
    sample: [usize; PACKET],
    contribution: [Vec3; PACKET],
    count: usize,
}

impl ShadowQueue {
    pub(crate) fn new() -> ShadowQueue {
        ShadowQueue {
            depths: Vec::new(),
            at: 0,
        }
    }

    /// Adds to `radiance` (per sample of the group) the contributions of
    /// the shadow rays that are not blocked, and empties the queue.
    fn resolve(&mut self, scene: &Scene, radiance: &mut [Vec3; PACKET]) {
        for batch in &mut self.depths {
            if batch.count == 0 {
                continue;
            }
            let rays = u32::MAX >> (32 - batch.count);
            let blocked = scene.accel.occluded_packet(&batch.rays, rays);
            for i in 0..batch.count {
                if blocked >> i & 1 == 0 {
                    radiance[batch.sample[i]] += batch.contribution[i];
                }
            }
            batch.count = 0;
        }
    }
}

impl<const N: usize> PathLog<N> for ShadowQueue {
    #[inline(always)]
    fn shadows(
        &mut self,
        _: &Scene,
        depth: u32,
        tried: LaneMask<N>,
        ray: impl Fn(usize) -> Ray,
        contribution: impl FnOnce() -> V3<Lanes<N>>,
    ) -> LaneMask<N> {
        let d = depth as usize;
        if self.depths.len() <= d {
            let empty = ShadowBatch {
                rays: [Ray::new(Vec3::ZERO, Vec3::Z); PACKET],
                sample: [0; PACKET],
                contribution: [Vec3::ZERO; PACKET],
                count: 0,
            };
            self.depths.resize(d + 1, empty);
        }
        let c = contribution();
        let batch = &mut self.depths[d];
        for k in 0..N {
            if tried.lane(k) {
                let i = batch.count;
                batch.rays[i] = ray(k);
                batch.sample[i] = self.at + k;
                batch.contribution[i] = lane3(c, k);
                batch.count += 1;
            }
        }
        LaneMask::from_fn(|_| false)
    }
}

/// Work done `N` lanes wide for a width chosen at run time ([`run_lanes`]):
/// `run` is compiled once per width, inside an entry point that carries
/// that width's target features. Everything it calls down to the lane
/// operations must be inlined into it (`#[inline(always)]`), or it is
/// compiled without them (docs/perf/lanes.md, the rule).
pub(crate) trait LaneKernel {
    type Out;
    fn run<const N: usize>(&mut self) -> Self::Out;
}

/// `kernel` run `width` lanes wide: 16 (AVX-512), 8 (AVX2 and FMA) or
/// else 4; `width` comes from [`lane_width`], which gives 16 and 8 only
/// where the processor has their features. Four lanes fill 128-bit
/// registers, which every x86-64 has; where the processor has AVX-512 they
/// are compiled with its features all the same: the kernel keeps dozens
/// of lane values live, and AVX-512 gives it 32 vector registers instead
/// of 16 (and mask registers for its selects), so fewer spill to the
/// stack. cbox renders in 0.91 of the time on an AMD EPYC (Zen 4) and
/// grad_rev_bsdf in 0.91; on an Intel Xeon, without them cbox takes 1.094
/// of the time; AVX2 and FMA alone (16 registers) buy nothing
/// (docs/perf/lanes.md, "Evening" and "Night").
pub(crate) fn run_lanes<K: LaneKernel>(width: usize, kernel: &mut K) -> K::Out {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
        fn x16<K: LaneKernel>(kernel: &mut K) -> K::Out {
            kernel.run::<16>()
        }
        #[target_feature(enable = "avx2,fma")]
        fn x8<K: LaneKernel>(kernel: &mut K) -> K::Out {
            kernel.run::<8>()
        }
        #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
        fn x4_avx512<K: LaneKernel>(kernel: &mut K) -> K::Out {
            kernel.run::<4>()
        }
        // SAFETY: `lane_width` gives 16 and 8 only where the processor
        // has their features, and `widest_lanes` is 16 only with AVX-512.
        match width {
            16 => return unsafe { x16(kernel) },
            8 => return unsafe { x8(kernel) },
            _ if widest_lanes() == 16 => return unsafe { x4_avx512(kernel) },
            _ => {}
        }
    }
    kernel.run::<4>()
}

/// A scene the path tracer in lanes renders, with what it reads per shape.
pub(crate) struct LanePath<'a> {
    scene: &'a Scene,
    store: ParamView<'a>,
    path: &'a PathIntegrator,
    shapes: Vec<LaneShape<'a>>,
    /// Per emitter, how its light samples are drawn.
    lights: Vec<LaneLight<'a>>,
    /// Lanes per call: 16, 8, 4 or 1 (the last: the scalar loop instead).
    width: usize,
    /// Whether a shape has another BSDF than `diffuse`.
    mixed_bsdfs: bool,
}

impl<'a> LanePath<'a> {
    /// The loop for `scene`, `None` where its plugins are not all written
    /// for lanes yet (see the module documentation) or `width` is 1.
    pub(crate) fn new(scene: &'a Scene, width: usize) -> Option<LanePath<'a>> {
        let Integrator::Path(path) = &scene.integrator else {
            return None;
        };
        if width == 1 || !scene.instances.is_empty() {
            return None;
        }
        let store = scene.params.primal();
        let value = |texture: &'a Texture| match texture {
            Texture::Uniform(u) => Ok(u.value::<f32>(&store).val()),
            texture => Err(texture),
        };
        let pick = |em: u32| {
            scene
                .emitter_distribution
                .as_ref()
                .map_or(0.0, |dist| dist.pmf(em as usize))
        };
        let shapes = scene
            .shapes
            .iter()
            .enumerate()
            .map(|(i, shape)| {
                let geometry = match shape {
                    Shape::Mesh(mesh) => LaneGeometry::Mesh(mesh),
                    Shape::Sphere(sphere) => {
                        let (center, radius) = sphere.center_radius(&scene.params);
                        LaneGeometry::Sphere {
                            center,
                            radius,
                            flip_normals: sphere.flip_normals,
                        }
                    }
                    _ => return None,
                };
                let (bsdf, albedo) = LaneBsdf::of(scene.shape_bsdf(i as u32), &store)?;
                let albedo = match albedo.map(value) {
                    None => Albedo::Plain(Vec3::ZERO),
                    Some(Ok(v)) => Albedo::Plain(v),
                    // textures that read more of the interaction than its
                    // uv, and textures on spheres, take the scalar loop
                    Some(Err(Texture::MeshAttribute(_))) => return None,
                    Some(Err(texture)) => match geometry {
                        LaneGeometry::Mesh(mesh) => Albedo::Textured { mesh, texture },
                        LaneGeometry::Sphere { .. } => return None,
                    },
                };
                // an emitting shape: a mesh with an `area` emitter of a
                // plain radiance
                let emission = match scene.shape_emitter(i as u32) {
                    None => None,
                    Some(em) => {
                        let (LaneGeometry::Mesh(mesh), Emitter::Area(area)) =
                            (geometry, &scene.emitters[em as usize])
                        else {
                            return None;
                        };
                        if !(mesh.surface_area() > 0.0) {
                            return None;
                        }
                        Some(MeshLight {
                            mesh,
                            radiance: value(&area.radiance).ok()?,
                            pdf_area: pick(em) / mesh.surface_area(),
                        })
                    }
                };
                Some(LaneShape {
                    geometry,
                    bsdf,
                    albedo,
                    emission,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        let mixed_bsdfs = shapes.iter().any(|s| !matches!(s.bsdf, LaneBsdf::Diffuse));
        let lights = scene
            .emitters
            .iter()
            .enumerate()
            .map(|(em, emitter)| match emitter {
                Emitter::Area(area) => shapes[area.shape as usize]
                    .emission
                    .map_or(LaneLight::Other, LaneLight::Mesh),
                Emitter::Constant(constant) => match value(&constant.radiance) {
                    Ok(radiance) => LaneLight::Constant {
                        radiance,
                        pick: pick(em as u32),
                    },
                    Err(_) => LaneLight::Other,
                },
                Emitter::Point(point) => match value(&point.intensity) {
                    Ok(intensity) => LaneLight::Point {
                        position: store.read3::<f32>(point.position, 0).val(),
                        intensity,
                    },
                    Err(_) => LaneLight::Other,
                },
                Emitter::Directional(directional) => match value(&directional.irradiance) {
                    Ok(irradiance) => LaneLight::Directional {
                        towards: -directional.direction,
                        irradiance,
                    },
                    Err(_) => LaneLight::Other,
                },
                _ => LaneLight::Other,
            })
            .collect();
        Some(LanePath {
            scene,
            store,
            path,
            shapes,
            lights,
            width,
            mixed_bsdfs,
        })
    }

    /// The scene it renders.
    pub(crate) fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The mesh of shape `shape`, whose reflectance is a texture (the
    /// loop looks textures up on meshes only: [`LanePath::new`]).
    pub(crate) fn mesh(&self, shape: u32) -> &'a Mesh {
        match self.shapes[shape as usize].geometry {
            LaneGeometry::Mesh(mesh) => mesh,
            LaneGeometry::Sphere { .. } => {
                unreachable!("the loop in lanes looks textures up on meshes only")
            }
        }
    }

    /// Whether the loop reads emitter `emitter`'s radiance as a plain
    /// value (an `area` light's on a mesh, a `constant` environment's, a
    /// `point` light's intensity, a `directional` light's irradiance): the
    /// light it sends is then linear in that value ([`PathLog::light`]).
    pub(crate) fn plain_radiance(&self, emitter: u32) -> bool {
        !matches!(self.lights[emitter as usize], LaneLight::Other)
    }

    /// Lanes per call.
    pub(crate) fn width(&self) -> usize {
        self.width
    }

    /// Splats the samples of `tile` into `block`, `width` at a time;
    /// returns how many it left out for a non-finite value. With `alpha`,
    /// a fourth channel is 1 where the camera ray reached a surface.
    pub(crate) fn render_tile(
        &self,
        layout: &SampleLayout,
        tile: Tile,
        alpha: bool,
        block: &mut ImageBlock,
    ) -> usize {
        struct Primal<'s, 'a> {
            lanes: &'s LanePath<'a>,
            layout: &'s SampleLayout<'s>,
            tile: Tile,
            alpha: bool,
            block: &'s mut ImageBlock,
        }
        impl LaneKernel for Primal<'_, '_> {
            type Out = usize;
            #[inline(always)]
            fn run<const N: usize>(&mut self) -> usize {
                self.lanes
                    .tile_lanes::<N>(self.layout, self.tile, self.alpha, self.block)
            }
        }
        let mut kernel = Primal {
            lanes: self,
            layout,
            tile,
            alpha,
            block,
        };
        run_lanes(self.width, &mut kernel)
    }

    /// The samples of each pixel of `tile` in blocks of `N` (the last one
    /// of a pixel partly filled), in the scalar loop's order. Reverse mode
    /// (`LaneAdjoint::tile_lanes`) walks a tile with the same nested loops,
    /// written out: the walk shared as a function taking the block's work
    /// as a closure, or as a `next()` over the blocks, added 1.0 % and
    /// 1.4 % instructions per sample on textured (the closure's captures
    /// kept in memory; the state machine's branches).
    #[inline(always)]
    fn tile_lanes<const N: usize>(
        &self,
        layout: &SampleLayout,
        tile: Tile,
        alpha: bool,
        block: &mut ImageBlock,
    ) -> usize {
        let filter = &layout.sensor.film.rfilter;
        let mut non_finite = 0;
        let mut group = CameraGroup::new();
        let mut shadows = ShadowQueue::new();
        // per sample of the group, its radiance and whether its camera ray
        // reached a surface
        let mut radiance = [Vec3::ZERO; PACKET];
        let mut reached = [false; PACKET];
        // (filters wider than a splat's window take `ImageBlock::put`)
        let mut splat = PixelSplat::<N>::new(filter);
        for y in tile.y0..tile.y0 + tile.h {
            for x in tile.x0..tile.x0 + tile.w {
                if let Some(splat) = &mut splat {
                    splat.start(x, y);
                }
                let mut first = 0;
                while first < layout.spp {
                    self.camera_group(layout, x, y, first, &mut group);
                    first += group.len() as u32;
                    for at in (0..group.len()).step_by(N) {
                        let SampleBlock {
                            rays,
                            hits,
                            rngs,
                            active,
                            ..
                        } = group.block::<N>(at);
                        shadows.at = at;
                        let (l, hit) = self.trace(rays, hits, active, rngs, &mut shadows);
                        for k in 0..N {
                            (radiance[at + k], reached[at + k]) = (lane3(l, k), hit[k]);
                        }
                    }
                    shadows.resolve(self.scene, &mut radiance);
                    for at in (0..group.len()).step_by(N) {
                        let (pos, active) =
                            (&group.pos, LaneMask::<N>::from_fn(|k| at + k < group.len()));
                        let l: V3<Lanes<N>> = lanes3(|k| radiance[at + k]);
                        let hit: [bool; N] = each_lane(|k| reached[at + k]);
                        // samples with a non-finite value are left out
                        let keep = active & l.x.finite() & l.y.finite() & l.z.finite();
                        non_finite += (0..N).filter(|&k| active.lane(k) && !keep.lane(k)).count();
                        let px = Lanes::<N>::from_fn(|k| pos[at + k].x);
                        let py = Lanes::<N>::from_fn(|k| pos[at + k].y);
                        let a = Lanes::<N>::from_fn(|k| if hit[k] { 1.0 } else { 0.0 });
                        match &mut splat {
                            Some(splat) if alpha => {
                                splat.add(filter, px, py, [l.x, l.y, l.z, a], keep);
                            }
                            Some(splat) => splat.add(filter, px, py, [l.x, l.y, l.z], keep),
                            None => {
                                for k in (0..N).filter(|&k| keep.lane(k)) {
                                    let v = [l.x.0[k], l.y.0[k], l.z.0[k], a.0[k]];
                                    let channels = if alpha { 4 } else { 3 };
                                    block.put(filter, px.0[k], py.0[k], &v[..channels]);
                                }
                            }
                        }
                    }
                }
                match &splat {
                    Some(splat) if alpha => splat.flush::<4>(block),
                    Some(splat) => splat.flush::<3>(block),
                    None => {}
                }
            }
        }
        non_finite
    }

    /// The next [`PACKET`] samples of pixel `(x, y)` from sample `first`
    /// on (fewer at the pixel's last), written to `group` (one group per
    /// tile, filled again and again: a group returned by value was copied
    /// each time, 1.4 % of textured's time): their film positions in
    /// pixels, camera rays and streams of random numbers, and the camera
    /// rays' hits, traced as one packet.
    #[inline(always)]
    pub(crate) fn camera_group(
        &self,
        layout: &SampleLayout,
        x: i64,
        y: i64,
        first: u32,
        group: &mut CameraGroup,
    ) {
        debug_assert!(first < layout.spp);
        let count = ((layout.spp - first) as usize).min(PACKET);
        // filled sample by sample, not through `std::array::from_fn`, whose
        // closures were left out of line, without the lanes' target
        // features; the pixel's key hashed once
        let key = layout.pixel_key(x, y);
        group.count = count;
        // a pinhole camera's rays are made in lanes, all at once
        let pinhole = matches!(layout.sensor.camera, Camera::Perspective(_));
        let mut film = [Vec2::ZERO; PACKET];
        for (k, at) in film.iter_mut().enumerate().take(count) {
            let (p, cs) = layout.camera_sample_of(x, y, key, first + k as u32, &mut group.rngs[k]);
            (group.pos[k], *at) = (p, cs.film);
            if !pinhole {
                group.rays[k] = cs.ray::<f32>(&self.store).val();
            }
        }
        if pinhole {
            let made = layout.sensor.pinhole_rays(&film, &mut group.rays);
            debug_assert!(made);
        }
        group.hits = intersect_camera_rays(self.scene, &group.rays, count);
    }

    /// [`PathIntegrator::trace`] from the camera rays `rays` in the lanes
    /// of `active`, whose first hits are `hits` (`None` in the other
    /// lanes), each lane drawing from its own stream: the radiance per
    /// lane, and whether each camera ray reached a surface. `log` hears of
    /// every vertex (see [`PathLog`]).
    #[inline(always)]
    pub(crate) fn trace<const N: usize>(
        &self,
        rays: &mut [Ray; N],
        hits: &mut [Option<Hit>; N],
        active: LaneMask<N>,
        rngs: &mut [SampleStream; N],
        log: &mut impl PathLog<N>,
    ) -> (Spectrum<Lanes<N>>, [bool; N]) {
        debug_assert!((0..N).all(|k| active.lane(k) || hits[k].is_none()));
        let (scene, store, path) = (self.scene, &self.store, self.path);
        let (zero, one) = (Lanes::<N>::cst(0.0), Lanes::<N>::cst(1.0));
        let mut result = V3::<Lanes<N>>::zero();
        let mut throughput = V3::splat(one);
        // the relative index of refraction along each path, for the roulette
        let mut eta = one;
        let camera_hits = each_lane(|k| hits[k].is_some());
        let mut alive = active;
        // the vertex each ray left and the density of its direction, for
        // the MIS weights of emitters it reaches
        let mut prev_p = V3::<Lanes<N>>::zero();
        let mut prev_pdf = one;
        let mut depth = 0u32;
        loop {
            // the first vertex's rays come from the camera: whatever they
            // reach counts whole, as after a delta bounce
            let shown = !(path.hide_emitters && depth == 0);
            let mis = |k: usize, pdf_em: f32| {
                if depth == 0 {
                    1.0
                } else {
                    mis_weight(prev_pdf.0[k], pdf_em)
                }
            };
            // escaped rays: the environment's emission
            if let (Some(env), true) = (scene.environment, shown) {
                let escaped = LaneMask::<N>::from_fn(|k| alive.lane(k) && hits[k].is_none());
                if escaped.any() {
                    let (le, w) = match self.lights[env as usize] {
                        // a constant environment in lanes: its radiance, and
                        // the density of its light samples, the same in
                        // every direction (`Scene::pdf_emitter_direction`)
                        LaneLight::Constant { radiance, pick } => {
                            let le = V3::select(escaped, V3::cst(radiance), V3::zero());
                            let w = if depth == 0 {
                                one
                            } else {
                                let pdf_em = Lanes::splat(Constant::DIRECTION_PDF * pick);
                                mis_weight(prev_pdf, pdf_em)
                            };
                            let w = Lanes::select(escaped, w, zero);
                            log.light(throughput, || ([Some(env); N], V3::splat(w)));
                            (le, w)
                        }
                        _ => {
                            let emitter = &scene.emitters[env as usize];
                            let mut w = Lanes::<N>::splat(0.0);
                            let le = lanes3(|k| {
                                if !escaped.lane(k) {
                                    return Vec3::ZERO;
                                }
                                let d = rays[k].d;
                                let at = lane3(prev_p, k);
                                let pdf_em = scene.pdf_emitter_direction(env, at, d, d, d);
                                w.0[k] = mis(k, pdf_em);
                                emitter.eval_environment::<f32>(store, V3::cst(d)).val()
                            });
                            (le, w)
                        }
                    };
                    result += throughput.mul_elem(le) * w;
                    log.emitted(depth, || le * w);
                }
            }
            alive = LaneMask::<N>::from_fn(|k| hits[k].is_some());
            if alive.none() {
                break;
            }
            // The vertex's random numbers, in the order of the scalar loop
            // (the light sample's, then the BSDF sample's and the
            // roulette's), drawn before the vertex is built: hashes of no
            // one's result, they run while its gathers wait (cbox 0.987 of
            // the time, textured 0.984). A vertex at the last depth
            // scatters nothing, and a lane whose path ended draws nothing
            // (its stream is its own and is not read again).
            let scatters = depth + 1 < path.max_depth;
            let zeros = || Lanes::<N>::splat(0.0);
            let mut u_light = [Vec2::ZERO; N];
            let (mut u1, mut u2, mut u_rr) = (zeros(), V2::new(zeros(), zeros()), zeros());
            let draws_light = scene.emitter_distribution.is_some();
            for (k, rng) in rngs.iter_mut().enumerate() {
                if alive.lane(k) && scatters {
                    if draws_light {
                        u_light[k] = rng.next_2d();
                    }
                    u1.0[k] = rng.next_1d();
                    let u = rng.next_2d();
                    (u2.x.0[k], u2.y.0[k]) = (u.x, u.y);
                    u_rr.0[k] = rng.next_1d();
                }
            }

            // the vertex: its point, normals and shading frame in lanes
            // (the dead lanes get a point at the origin facing +z: their
            // zero shading normal gives way to the face's). The arrays are
            // filled with zeros, not with +z: LLVM built one lane's
            // `[Vec3::Z; 3]` on the stack and copied it to the others with
            // wider loads than its stores, each load stalled on them (3 %
            // of cbox's kernel)
            let mut corners = [[Vec3::ZERO; 3]; N];
            let mut normals = [[Vec3::ZERO; 3]; N];
            let mut face_n = [Vec3::Z; N];
            let mut mesh_hit = [false; N];
            for k in 0..N {
                let Some(hit) = &hits[k] else { continue };
                match self.shapes[hit.shape as usize].geometry {
                    LaneGeometry::Mesh(mesh) => {
                        (corners[k], normals[k], face_n[k]) =
                            mesh.corners_primal(&scene.params, hit.prim);
                        mesh_hit[k] = true;
                    }
                    // the point as the first corner at barycentrics
                    // (0, 0), exactly
                    LaneGeometry::Sphere {
                        center,
                        radius,
                        flip_normals,
                    } => {
                        let ray = &rays[k];
                        let dir = (ray.o + ray.d * hit.t - center).normalize();
                        let n = if flip_normals { -dir } else { dir };
                        corners[k][0] = center + dir * radius;
                        (normals[k][0], face_n[k]) = (n, n);
                    }
                }
            }
            // the barycentrics read from the hits, written long before,
            // not from an array filled lane by lane in the loop above:
            // LLVM read such an array two lanes to a load, which waited on
            // the narrower stores that had just filled it (1.9 % of the
            // replay kernel's samples on cbox)
            let bary_of = |k: usize| match hits[k] {
                Some(hit) if mesh_hit[k] => hit.uv,
                _ => Vec2::ZERO,
            };
            let b1 = Lanes::<N>::from_fn(|k| bary_of(k).x);
            let b2 = Lanes::<N>::from_fn(|k| bary_of(k).y);
            let b0 = one - b1 - b2;
            let at = |c: &[[Vec3; 3]; N]| {
                lanes3(|k| c[k][0]) * b0 + lanes3(|k| c[k][1]) * b1 + lanes3(|k| c[k][2]) * b2
            };
            let p = at(&corners);
            let n = lanes3(|k| face_n[k]);
            let ns = at(&normals);
            let ns = V3::select(ns.length_squared().gt(0.0), ns.normalize(), n);
            let frame = Frame::from_normal(ns);
            let d = lanes3(|k| rays[k].d);
            let wi = frame.to_local(-d);
            let point = |k: usize| SurfacePoint {
                p: lane3(p, k),
                n: face_n[k],
            };
            log.vertex(depth, hits, p, &face_n);

            // emission of a surface hit by the previous BSDF sample: on
            // the front side (as `Area::eval_surface`), weighted against
            // the density with which the previous vertex's light sample
            // reaches the point (`Area::pdf_from_area`)
            if shown {
                let light = |k: usize| {
                    hits[k]
                        .as_ref()
                        .and_then(|hit| self.shapes[hit.shape as usize].emission)
                };
                let le = lanes3(|k| light(k).map_or(Vec3::ZERO, |l| l.radiance));
                let front = wi.z.gt(0.0);
                let w = if depth == 0 {
                    one
                } else {
                    let pdf_area = Lanes::<N>::from_fn(|k| light(k).map_or(0.0, |l| l.pdf_area));
                    let cos_e = -d.dot(n);
                    let dist2 = (p - prev_p).length_squared();
                    let pdf_em = Lanes::select(cos_e.gt(0.0), pdf_area * dist2 / cos_e, zero);
                    mis_weight(prev_pdf, pdf_em)
                };
                result += V3::select(front, throughput.mul_elem(le) * w, V3::zero());
                log.emitted(depth, || V3::select(front, le * w, V3::zero()));
                log.light(throughput, || {
                    let emitters =
                        each_lane(|k| light(k).and_then(|_| scene.shape_emitter(hits[k]?.shape)));
                    (emitters, V3::select(front, V3::splat(w), V3::zero()))
                });
            }

            if !scatters {
                break;
            }
            let albedo = self.albedo(hits, p, &face_n);
            let bsdf_of = |k: usize| hits[k].map(|hit| self.shapes[hit.shape as usize].bsdf);
            let mixed = self.mixed_bsdfs
                && (0..N).any(|k| !matches!(bsdf_of(k), None | Some(LaneBsdf::Diffuse)));
            let others = mixed.then(|| MixedLanes::new(&bsdf_of, albedo, wi));
            let bsdf = BsdfLanes::new(others.as_ref(), albedo, wi);

            // The BSDF sample and its world direction before the light
            // sample is looked at: the sample's chain (the warp's
            // division, polynomial and square roots, the frame, the
            // normalisation) runs beside the light sample's work instead
            // of after it, where the bounce ray waited on it.
            let (wo_bsdf, pdf_bsdf, weight_bsdf, eta_wo, sampled) = bsdf.sample(u1, u2);
            let d_bsdf = frame.to_world(wo_bsdf).normalize();

            // next-event estimation: a lane that picks a mesh's area
            // light samples its point there, and the direction, density
            // and weight follow in lanes (as `Area::sample_direction`);
            // any other emitter samples by its own code
            // (zeros where no sample is drawn, for the reason the
            // vertex's normals are)
            let mut y = [Vec3::ZERO; N];
            let mut yn = [Vec3::ZERO; N];
            let mut y_pdf = [0.0; N];
            let mut y_le = [Vec3::ZERO; N];
            // the emitter of each lane's sample, where its radiance is a
            // plain value
            let mut y_em = [None; N];
            // lanes whose emitter is not a mesh: the sample's direction,
            // density, weight, whether it is a delta, and its shadow ray's
            // end: a point, or a direction for an emitter at infinity
            let mut other = [false; N];
            let (mut o_d, mut o_pdf, mut o_w) = ([Vec3::ZERO; N], [0.0; N], [Vec3::ZERO; N]);
            let (mut o_delta, mut o_far, mut o_end) = ([false; N], [false; N], [Vec3::ZERO; N]);
            if let Some(dist) = &scene.emitter_distribution {
                for k in 0..N {
                    if !alive.lane(k) {
                        continue;
                    }
                    let u = u_light[k];
                    let (em, em_pick, ux) = dist.sample_reuse(u.x);
                    match self.lights[em] {
                        LaneLight::Mesh(light) => {
                            let (_, _, p, n) =
                                light.mesh.sample_point(&scene.params, Vec2::new(ux, u.y));
                            (y[k], yn[k], y_pdf[k], y_le[k]) =
                                (p, n, light.pdf_area, light.radiance);
                            y_em[k] = Some(em as u32);
                        }
                        LaneLight::Constant { radiance, pick } => {
                            y_em[k] = Some(em as u32);
                            let (d, pdf) = Constant::sample_direction_primal(Vec2::new(ux, u.y));
                            other[k] = true;
                            (o_d[k], o_pdf[k]) = (d, pdf * pick);
                            o_w[k] = radiance * (1.0 / pdf) * (1.0 / pick);
                            (o_far[k], o_end[k]) = (true, d);
                        }
                        // the `point` emitter's sample, weighted as
                        // `Scene::sample_emitter` weighs it
                        LaneLight::Point {
                            position,
                            intensity,
                        } => {
                            let at = V3::cst(lane3(p, k));
                            if let Some((ds, d, dist2)) =
                                point_light_sample::<f32>(V3::cst(position), at)
                            {
                                y_em[k] = Some(em as u32);
                                other[k] = true;
                                (o_d[k], o_pdf[k]) = (d.val(), ds.pdf * em_pick);
                                o_w[k] = intensity * dist2.recip() * (1.0 / em_pick);
                                o_delta[k] = true;
                                (o_far[k], o_end[k]) = (false, position);
                            }
                        }
                        // as `Directional::sample_direction` and
                        // `Scene::sample_emitter`
                        LaneLight::Directional {
                            towards,
                            irradiance,
                        } => {
                            y_em[k] = Some(em as u32);
                            other[k] = true;
                            (o_d[k], o_pdf[k]) = (towards, em_pick);
                            o_w[k] = irradiance * (1.0 / em_pick);
                            o_delta[k] = true;
                            (o_far[k], o_end[k]) = (true, towards);
                        }
                        LaneLight::Other => {
                            let at = V3::cst(lane3(p, k));
                            if let Some(es) = scene.sample_emitter::<f32>(store, at, u) {
                                other[k] = true;
                                (o_d[k], o_pdf[k], o_w[k]) =
                                    (es.d.val(), es.ds.pdf, es.weight.val());
                                o_delta[k] = es.ds.delta;
                                o_far[k] = !es.ds.dist.is_finite();
                                o_end[k] = if o_far[k] { es.ds.d } else { es.ds.p };
                            }
                        }
                    }
                }
            }
            let to = lanes3(|k| y[k]) - p;
            let dist2 = to.length_squared();
            let d_area = to / dist2.sqrt();
            let cos_e = -d_area.dot(lanes3(|k| yn[k]));
            let pdf_area = Lanes::<N>(y_pdf);
            let on_light = pdf_area.gt(0.0) & dist2.gt(0.0) & cos_e.gt(0.0);
            let pdf_light = pdf_area * dist2 / cos_e;
            let weight_light = lanes3(|k| y_le[k]) * (one / pdf_light);
            // most scenes' lights are all meshes: no lane to blend in
            let any_other = other.iter().any(|&o| o);
            let (d_em, pdf_em, weight, sampled_em) = if any_other {
                let other = LaneMask::<N>::from_fn(|k| other[k]);
                (
                    V3::select(on_light, d_area, lanes3(|k| o_d[k])),
                    Lanes::select(on_light, pdf_light, Lanes(o_pdf)),
                    V3::select(on_light, weight_light, lanes3(|k| o_w[k])),
                    on_light | other,
                )
            } else {
                (d_area, pdf_light, weight_light, on_light)
            };
            let wo = frame.to_local(d_em);
            let f = bsdf.eval(wo);
            let tried = sampled_em & !f.is_zero();
            let shadow_ray = |k: usize| match (other[k], o_far[k]) {
                (false, _) => point(k).spawn_ray_to(y[k]),
                (true, false) => point(k).spawn_ray_to(o_end[k]),
                (true, true) => point(k).spawn_ray(o_end[k]),
            };
            // the sample's MIS weight (one for a delta light) and its
            // contribution where its shadow ray is not blocked
            let weigh = || {
                let mis = mis_weight(pdf_em, bsdf.pdf(wo));
                let w = if any_other {
                    Lanes::select(LaneMask::<N>::from_fn(|k| o_delta[k]), one, mis)
                } else {
                    mis
                };
                (w, throughput.mul_elem(f).mul_elem(weight) * w)
            };
            let visible = log.shadows(scene, depth, tried, shadow_ray, || weigh().1);
            if visible.any() {
                let (w, c) = weigh();
                result += V3::select(visible, c, V3::zero());
                // a plain radiance's sample weighs it by one over the
                // sample's density (a directional light's irradiance: over
                // its pick's probability), a point light's intensity by
                // one over its pick's probability and the squared distance
                log.light(throughput, || {
                    let per_unit =
                        Lanes::<N>::from_fn(|k| match y_em[k].map(|em| self.lights[em as usize]) {
                            Some(LaneLight::Point { position, .. }) => {
                                w.0[k] / (o_pdf[k] * (position - lane3(p, k)).length_squared())
                            }
                            _ => w.0[k] / pdf_em.0[k],
                        });
                    (y_em, V3::select(visible, f * per_unit, V3::zero()))
                });
                log.next_event(depth, || {
                    // `lambert_eval` is a diffuse vertex's reflectance
                    // times this
                    let f1 = lambert_eval(wi, wo, V3::splat(one));
                    let per_reflectance = f1.mul_elem(weight) * w;
                    if !mixed {
                        return (V3::select(visible, per_reflectance, V3::zero()), V3::zero());
                    }
                    let diffuse =
                        LaneMask::<N>::from_fn(|k| matches!(bsdf_of(k), Some(LaneBsdf::Diffuse)));
                    (
                        V3::select(visible & diffuse, per_reflectance, V3::zero()),
                        V3::select(visible & !diffuse, f.mul_elem(weight) * w, V3::zero()),
                    )
                });
            }

            log.scattering(depth, || Scattering {
                ns,
                wi: -d,
                light_d: d_em,
                light_weight: V3::select(visible, weight * weigh().0, V3::zero()),
                bounce_d: d_bsdf,
                bounce_pdf: pdf_bsdf,
            });

            // continue the paths by the BSDF sample, then Russian roulette
            // on the throughput after the bounce (as the scalar loop)
            let reached = throughput;
            throughput = throughput.mul_elem(weight_bsdf);
            eta *= eta_wo;
            let (survives, q) =
                survival_probability(throughput.max_elem(), eta, depth, path.roulette_from, u_rr);
            let survival = if depth >= path.roulette_from {
                one / q
            } else {
                one
            };
            if depth >= path.roulette_from {
                throughput *= survival;
            }
            alive = alive & sampled & survives;
            log.bounce(
                depth,
                reached,
                weight_bsdf,
                Lanes::select(alive, survival, zero),
            );
            if alive.none() {
                break;
            }
            // a path that ended carries nothing (its throughput may be
            // infinite: divided by a survival probability of zero)
            throughput = V3::select(alive, throughput, V3::zero());
            // each hit is written where it is kept: through `then`, it
            // came back in a temporary, copied with wider loads than the
            // stores that had just written it, which waited on them (3 %
            // of cbox's kernel)
            for k in 0..N {
                if alive.lane(k) {
                    rays[k] = point(k).spawn_ray(lane3(d_bsdf, k));
                    hits[k] = intersect(scene, &rays[k]);
                } else {
                    hits[k] = None;
                }
            }
            prev_p = p;
            prev_pdf = pdf_bsdf;
            depth += 1;
        }
        (result, camera_hits)
    }

    /// The diffuse reflectance at each lane's hit (zero where none): plain
    /// values, and each texture looked up once for all the lanes that read
    /// it (a bitmap in lanes,
    /// [`Bitmap::eval_lanes`](crate::texture::Bitmap::eval_lanes)).
    #[inline(always)]
    fn albedo<const N: usize>(
        &self,
        hits: &[Option<Hit>; N],
        p: V3<Lanes<N>>,
        face_n: &[Vec3; N],
    ) -> V3<Lanes<N>> {
        let (scene, store) = (self.scene, &self.store);
        let albedo_of = |k: usize| hits[k].map(|hit| (hit, self.shapes[hit.shape as usize].albedo));
        let mut albedo = lanes3(|k| match albedo_of(k) {
            Some((_, Albedo::Plain(v))) => v,
            _ => Vec3::ZERO,
        });
        let mut uv = V2::new(Lanes::<N>::splat(0.0), Lanes::splat(0.0));
        let mut textured = [None; N];
        for (k, t) in textured.iter_mut().enumerate() {
            if let Some((hit, Albedo::Textured { mesh, texture })) = albedo_of(k) {
                let at = mesh.uv_primal(&scene.params, hit.prim, hit.uv);
                (uv.x.0[k], uv.y.0[k]) = (at.x, at.y);
                *t = Some(texture);
            }
        }
        while let Some(texture) = textured.iter().find_map(|t| *t) {
            let reads =
                LaneMask::<N>::from_fn(|k| textured[k].is_some_and(|t| std::ptr::eq(t, texture)));
            let value = match texture {
                Texture::Bitmap(bitmap) => bitmap.eval_lanes(store, uv, reads),
                _ => lanes3(|k| {
                    let Some(hit) = hits[k].filter(|_| reads.lane(k)) else {
                        return Vec3::ZERO;
                    };
                    let at = Vec2::new(uv.x.0[k], uv.y.0[k]);
                    let si =
                        surface_si::<f32>(lane3(p, k), face_n[k], at, Vec3::Z, hit.shape, hit.prim);
                    texture.eval(store, &si).val()
                }),
            };
            albedo = V3::select(reads, value, albedo);
            for (k, t) in textured.iter_mut().enumerate() {
                if reads.lane(k) {
                    *t = None;
                }
            }
        }
        albedo
    }
}

/// How many lanes the path tracer in lanes runs: `requested` (a render's
/// [`RenderOptions::lanes`](super::RenderOptions::lanes)), else
/// `PENUMBRA_LANES` where it is set (a switch for checks and
/// measurements), else 4; 1 is the scalar loop, 8 and 16 need a processor
/// that has them.
///
/// Four, not the widest the processor has: a block's lanes are one
/// pixel's samples, and the block runs until its longest path ends, so
/// the wider the block, the more of its lane-vertices belong to paths
/// that have ended (cbox, 256², 64 spp: 33 % at 4 lanes, 39 % at 8, 43 %
/// at 16); and most of the loop's work is per lane (traversal, light
/// samples, texture look-ups), which a wider register does not shorten.
/// Measured on an Intel Xeon with AVX-512 (docs/perf/lanes.md, "The
/// width"): 4 lanes render cbox in 0.79 of the time of 16 and 0.92 of 8,
/// textured in 0.86 of 16, mesh_heavy in 0.95.
pub(crate) fn lane_width(requested: Option<usize>) -> Result<usize> {
    const DEFAULT: usize = 4;
    let widest = widest_lanes().max(DEFAULT);
    let (width, source) = match (requested, std::env::var("PENUMBRA_LANES")) {
        (Some(w), _) => (Ok(w), format!("lanes = {w}")),
        (None, Ok(v)) => (v.trim().parse::<usize>(), format!("PENUMBRA_LANES={v}")),
        (None, Err(_)) => return Ok(DEFAULT),
    };
    match width {
        Ok(w @ (1 | 4)) => Ok(w),
        Ok(w @ (8 | 16)) if w <= widest => Ok(w),
        _ => Err(Error::Invalid(format!(
            "{source}: expected 1 (the scalar loop), 4 or a width this processor has (up to \
             {widest})"
        ))),
    }
}

/// The closest hits of the first `count` of a pixel's camera rays, traced
/// as one packet, out of line: the traversal picks its own kernel.
#[inline(never)]
fn intersect_camera_rays(
    scene: &Scene,
    rays: &[Ray; PACKET],
    count: usize,
) -> [Option<Hit>; PACKET] {
    scene.accel.intersect_packet(rays, u32::MAX >> (32 - count))
}

/// A ray's closest hit, out of line: the traversal picks its own kernel.
#[inline(never)]
fn intersect(scene: &Scene, ray: &Ray) -> Option<Hit> {
    scene.intersect(ray)
}

/// Whether a shadow ray is blocked, out of line as [`intersect`].
#[inline(never)]
fn occluded(scene: &Scene, ray: &Ray) -> bool {
    scene.occluded(ray)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::render::{render_samples, render_tiles};
    use crate::integrator::RenderOptions;
    use std::path::Path;

    fn scene(name: &str, res: u32) -> Scene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{name}.xml"));
        Scene::load_file(&path, &[("res".to_string(), res.to_string())]).unwrap()
    }

    /// The RGB image of `scene` at `spp` with the loop in lanes `width` wide
    /// (`None`: the scalar loop).
    fn image(scene: &Scene, spp: u32, seed: u64, width: Option<usize>) -> ImageBlock {
        let opts = RenderOptions {
            spp: Some(spp),
            seed,
            ..Default::default()
        };
        let (block, non_finite) = match width {
            Some(w) => {
                let lanes = LanePath::new(scene, w).expect("a scene the loop in lanes renders");
                render_tiles(scene, &opts, 3, "test", |layout, tile, block| {
                    lanes.render_tile(layout, tile, false, block)
                })
            }
            None => render_samples(scene, &opts, 3, "test", |cs, rng, out| {
                scene.integrator.sample(scene, cs, rng, out);
            }),
        }
        .unwrap();
        assert_eq!(non_finite, 0);
        block
    }

    /// Per channel, the mean of `a − b` over the image and its standard
    /// error, from the means over blocks of 8 × 8 pixels (a pixel's
    /// neighbours share its samples through the film's filter; blocks that
    /// large are nearly independent of each other), and the mean of `b`.
    fn mean_difference(a: &ImageBlock, b: &ImageBlock) -> [(f64, f64, f64); 3] {
        let (w, h) = (a.width, a.height);
        let px = |img: &ImageBlock, x: usize, y: usize, c: usize| {
            let o = (y * w + x) * 4;
            img.data[o + c] / img.data[o + 3]
        };
        std::array::from_fn(|c| {
            let blocks: Vec<(f64, f64)> = (0..h / 8)
                .flat_map(|by| (0..w / 8).map(move |bx| (bx, by)))
                .map(|(bx, by)| {
                    let (mut d, mut sb) = (0.0, 0.0);
                    for y in by * 8..by * 8 + 8 {
                        for x in bx * 8..bx * 8 + 8 {
                            d += px(a, x, y, c) - px(b, x, y, c);
                            sb += px(b, x, y, c);
                        }
                    }
                    (d / 64.0, sb / 64.0)
                })
                .collect();
            let n = blocks.len() as f64;
            let mean = blocks.iter().map(|v| v.0).sum::<f64>() / n;
            let var = blocks.iter().map(|v| (v.0 - mean).powi(2)).sum::<f64>() / (n - 1.0);
            let mean_b = blocks.iter().map(|v| v.1).sum::<f64>() / n;
            (mean, (var / n).sqrt(), mean_b)
        })
    }

    /// The widths this processor runs.
    fn widths() -> Vec<usize> {
        [4, 8, 16]
            .into_iter()
            .filter(|&w| w == 4 || w <= widest_lanes())
            .collect()
    }

    /// The loop in lanes and the scalar loop estimate the same image: on
    /// cbox (area light, plain reflectances), textured (bitmap
    /// reflectances, an environment beside the area light) and bsdfs
    /// (spheres of rough conductor, dielectric and plastic), 128², 128
    /// samples per pixel, over 256 blocks of 8 × 8 pixels, their mean
    /// differences are within 4.5 standard errors (Student's t with 255
    /// degrees of freedom: a chance of 10⁻⁵ per channel if both are
    /// unbiased), with independent random numbers (the
    /// two loops are given different seeds). The same statistic rejects the
    /// scalar image scaled by 1.05: the test sees a bias of that size.
    #[test]
    fn lanes_and_the_scalar_loop_render_the_same_image() {
        for name in ["cbox", "textured", "bsdfs"] {
            let scene = scene(name, 128);
            let scalar = image(&scene, 128, 1, None);
            for width in widths() {
                let lanes = image(&scene, 128, 2, Some(width));
                for (c, (d, se, mean)) in mean_difference(&lanes, &scalar).into_iter().enumerate() {
                    let at = format!("{name}, {width} lanes, channel {c}");
                    assert!((d / se).abs() < 4.5, "{at}: t = {}", d / se);
                    // the test's resolution: 4.5 standard errors are less
                    // than a 5 % bias (checked, not assumed)
                    assert!(
                        4.5 * se < 0.05 * mean,
                        "{at}: 4.5 se = {} of {mean}",
                        4.5 * se
                    );
                }
            }
        }
    }

    /// The same seed gives the same image at every width: each sample's
    /// random numbers are its own stream, whichever lane it runs in.
    #[test]
    fn the_image_does_not_depend_on_the_width() {
        let scene = scene("cbox", 16);
        let widths = widths();
        let first = image(&scene, 20, 7, Some(widths[0]));
        for &w in &widths[1..] {
            let other = image(&scene, 20, 7, Some(w));
            let close = first
                .data
                .iter()
                .zip(&other.data)
                .all(|(a, b)| (a - b).abs() <= 1e-4 * a.abs().max(1.0));
            assert!(close, "{w} lanes differ from {}", widths[0]);
        }
    }

    /// Scenes with plugins not written for lanes take the scalar loop.
    #[test]
    fn other_scenes_take_the_scalar_loop() {
        let cbox = scene("cbox", 16);
        assert!(LanePath::new(&cbox, 4).is_some());
        assert!(LanePath::new(&cbox, 1).is_none());
        // spheres and rough BSDFs
        let bsdfs = scene("bsdfs", 16);
        assert!(LanePath::new(&bsdfs, 4).is_some());
        // a Beckmann distribution (bsdfs' conductor otherwise)
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/bsdfs.xml");
        let text = std::fs::read_to_string(&path).unwrap();
        let text = text.replacen(r#"<string name="distribution" value="ggx"/>"#, "", 1);
        let beckmann = Scene::load_str(&text, &path, &[("res".into(), "16".into())]).unwrap();
        assert!(LanePath::new(&beckmann, 4).is_none());
    }
}
