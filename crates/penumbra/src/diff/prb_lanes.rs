//! Reverse mode in lanes, for the derivatives by diffuse reflectances, by
//! emitters' radiances and by the parameters of the rough BSDFs.
//!
//! Where the path tracer renders in lanes (`integrator/lanes.rs`: meshes
//! and spheres with `diffuse` BSDFs and the rough BSDFs written for lanes)
//! and every recorded parameter is read by the `diffuse` reflectances
//! (plain values or textures) or by the plain radiances of `area` lights,
//! `constant` environments, `point` and `directional` lights alone (not
//! by another BSDF or emitter, a shape or the camera), the radiance of a
//! path is a polynomial in its vertices' reflectances ρ_d that the lane
//! loop can differentiate without a tape. With β_d the throughput reaching vertex d, E_d what is emitted
//! towards the camera there per unit of β_d (a surface's or the
//! environment's emission, MIS-weighted), N_d the light sample's
//! contribution per unit of β_d ⊙ ρ_d, and s_d the roulette's factor on the
//! throughput after the bounce (1/q, or 0 where the path ended), one path's
//! estimate is
//!
//! ```text
//! L = R_0,   R_d = E_d + ρ_d ⊙ B_d,   B_d = N_d + s_d R_{d+1},
//! ```
//!
//! since a diffuse sample's weight f cos θ / pdf is ρ_d and the BSDF value
//! of the light sample is ρ_d times a factor free of it. A vertex of
//! another BSDF fits the same recursion with ρ_d its sample's weight, its
//! light sample's whole contribution (per unit of β_d) counted in E_d and
//! N_d zero: it reads no diffuse reflectance, so for those its factors
//! are constants (its own parameters: below). So
//! ∂L/∂ρ_d = β_d ⊙ B_d, the radiance that leaves vertex d through its
//! reflection per unit of reflectance. One pass traces the lanes' paths and
//! logs (E, N, ρ, β, s) per vertex; a sweep from the last vertex back gives
//! every B_d without dividing by a reflectance (a zero one has its
//! derivative too). The roulette's q is held fixed, as in the scalar
//! reverse mode: its derivative is not part of the estimator's (Vicini et
//! al. 2021, "Path Replay Backpropagation", §4; Mitsuba's `prb` detaches
//! it likewise).
//!
//! Each vertex's adjoint δL ⊙ β_d ⊙ B_d reaches the parameters through the
//! reflectance's own code evaluated on [`Var`]s: a texture per vertex, at
//! the point the primal pass looked it up; a plain value once per tile for
//! the sum of its adjoints. A bitmap whose `to_uv` is not recorded skips
//! the tape: its look-up's weights are constants, and
//! `Bitmap::scatter_adjoint` hands each texel its share directly.
//!
//! The light of one emitter is linear in its radiance L_e, and nothing
//! else of the path depends on it (the emitters are picked by their
//! `sampling_weight`, not their power): each emission the path reaches
//! and each light sample is β_d ⊙ L_e ⊙ c with c free of L_e (the MIS
//! weight; for a light sample also the BSDF value over the sample's
//! density), so ∂L/∂L_e = Σ β_d ⊙ c over the contributions of emitter e,
//! which the loop hands over as it traces ([`PathLog::light`]) and which
//! need no sweep. Their adjoints are summed per emitter over a tile and
//! handed to the radiance once, as a plain reflectance's.
//!
//! A rough BSDF's parameters (roughness, index of refraction, specular
//! factor: plain values, as the loop in lanes reads them) enter a path's
//! estimate through its values at vertex d along two directions: the
//! light sample's, f_l, counted in E_d as f_l ⊙ w_l per unit of β_d (w_l
//! the sample's weight and MIS weight), and the bounce's, f_b, in
//! ρ_d = f_b / p_b. The samples' directions, densities and MIS weights
//! are constants (detached sampling, as the scalar reverse mode and
//! Mitsuba's `prb` hold them), so ∂L/∂θ gets β_d ⊙ (∂f_l/∂θ ⊙ w_l +
//! ∂f_b/∂θ ⊙ B_d / p_b) from the vertex, the sweep's B_d included: the
//! loop logs the two directions ([`Scattering`]), and the plugin's own
//! code evaluates f_l and f_b on [`Var`]s there.
//!
//! Scenes or parameters outside this take the scalar reverse mode of
//! `prb.rs`, which records whole paths.

use super::prb::TileSums;
use crate::ad::lanes::{lane3, lanes3, LaneMask, Lanes};
use crate::ad::reverse::{backward, clear_tape};
use crate::ad::{Float, Mask, Var};
use crate::bsdf::lanes::LaneBsdf;
use crate::bsdf::{Bsdf, BsdfContext, BsdfContextT};
use crate::emitter::{surface_si, Emitter};
use crate::geometry::Hit;
use crate::image::film::{AdjointImage, PixelGather};
use crate::integrator::lanes::{
    run_lanes, CameraGroup, LaneKernel, LanePath, PathLog, SampleBlock, Scattering,
};
use crate::integrator::render::{SampleLayout, Tile};
use crate::math::V3;
use crate::params::{ParamId, ParamView};
use crate::texture::{Texture, TextureT};
use glam::{DVec3, Vec2, Vec3};

/// A shape's reflectance that reads a recorded parameter.
#[derive(Clone, Copy)]
enum Reflectance<'a> {
    /// The same everywhere: its adjoints are summed over a tile and
    /// handed to it once.
    Uniform(&'a Texture),
    /// Looked up at each vertex.
    Varying(&'a Texture),
}

/// The reverse mode in lanes for a scene and its recorded parameters.
pub(super) struct LaneAdjoint<'a> {
    lanes: LanePath<'a>,
    /// The parameter store with the recorded parameters.
    store: &'a ParamView<'a>,
    /// Per shape, its reflectance where it reads a recorded parameter.
    reflectance: Vec<Option<Reflectance<'a>>>,
    /// Per emitter, its radiance where it reads a recorded parameter (a
    /// plain value: see [`LaneAdjoint::new`]).
    radiance: Vec<Option<&'a Texture>>,
    /// Per shape, whether its BSDF (not `diffuse`) holds a recorded
    /// parameter: differentiated at each vertex by its own code on
    /// [`Var`]s.
    scattering: Vec<bool>,
}

impl<'a> LaneAdjoint<'a> {
    /// The reverse mode in lanes `width` wide for the parameters recorded
    /// in `store`, or `None` where the scene does not render in lanes or a
    /// recorded parameter is read by anything but the diffuse
    /// reflectances (see the module documentation).
    pub(super) fn new(
        scene: &'a crate::scene::Scene,
        store: &'a ParamView<'a>,
        width: usize,
    ) -> Option<LaneAdjoint<'a>> {
        if store.moves_geometry() {
            return None;
        }
        let lanes = LanePath::new(scene, width)?;
        let recorded = |ids: &[ParamId]| ids.iter().any(|&id| store.is_recorded(id));
        let mut read = Vec::new();
        let mut reflectance = Vec::with_capacity(scene.shapes.len());
        let mut scattering = vec![false; scene.shapes.len()];
        for shape in 0..scene.shapes.len() as u32 {
            let bsdf = scene.shape_bsdf(shape);
            let Bsdf::Diffuse(diffuse) = bsdf else {
                // another BSDF of the loop in lanes (which reads its
                // values, recorded or not): a vertex's factor in the log,
                // and where it holds a recorded parameter, its value along
                // the vertex's two directions on Vars (a plastic's diffuse
                // base, scaled by its interface, is not a diffuse
                // reflectance's ρ: recorded, it takes the tape)
                let (_, base) = LaneBsdf::of(bsdf, &scene.params.primal())?;
                if base.is_some_and(|t| t.param_ids().is_none_or(|ids| recorded(&ids))) {
                    return None;
                }
                let held = LaneBsdf::held_params(bsdf)?;
                scattering[shape as usize] = recorded(&held);
                read.extend(held);
                reflectance.push(None);
                continue;
            };
            let texture = &diffuse.reflectance;
            let ids = texture.param_ids()?;
            reflectance.push(recorded(&ids).then_some(match texture {
                Texture::Uniform(_) => Reflectance::Uniform(texture),
                _ => Reflectance::Varying(texture),
            }));
            read.extend(ids);
        }
        let mut radiance = Vec::with_capacity(scene.emitters.len());
        for (em, emitter) in scene.emitters.iter().enumerate() {
            let texture = match emitter {
                Emitter::Area(area) => &area.radiance,
                Emitter::Constant(constant) => &constant.radiance,
                Emitter::Point(point) => &point.intensity,
                Emitter::Directional(directional) => &directional.irradiance,
                // the loop samples other emitters by their own code: their
                // parameters, not read here, take the tape
                _ => {
                    radiance.push(None);
                    continue;
                }
            };
            let ids = texture.param_ids()?;
            // the light of an emitter the loop reads as a plain value is
            // linear in it; the others' (a textured constant) take the tape
            let differentiable = recorded(&ids);
            if differentiable && !lanes.plain_radiance(em as u32) {
                return None;
            }
            radiance.push(differentiable.then_some(texture));
            read.extend(ids);
        }
        let only_read = scene
            .params
            .iter()
            .all(|(id, _)| !store.is_recorded(id) || read.contains(&id));
        only_read.then_some(LaneAdjoint {
            lanes,
            store,
            reflectance,
            radiance,
            scattering,
        })
    }

    /// Adds to `sums` the gradients of the samples of `tile`, each
    /// weighted by its adjoint radiance from `adjoint`; returns how many
    /// samples it left out for a non-finite radiance.
    pub(super) fn tile(
        &self,
        layout: &SampleLayout,
        tile: Tile,
        adjoint: &AdjointImage,
        sums: &mut TileSums,
    ) -> usize {
        struct Kernel<'s, 'a, 'o> {
            this: &'s LaneAdjoint<'a>,
            layout: &'s SampleLayout<'s>,
            tile: Tile,
            adjoint: &'s AdjointImage,
            sums: &'s mut TileSums<'o>,
        }
        impl LaneKernel for Kernel<'_, '_, '_> {
            type Out = usize;
            #[inline(always)]
            fn run<const N: usize>(&mut self) -> usize {
                self.this
                    .tile_lanes::<N>(self.layout, self.tile, self.adjoint, self.sums)
            }
        }
        let mut kernel = Kernel {
            this: self,
            layout,
            tile,
            adjoint,
            sums,
        };
        run_lanes(self.lanes.width(), &mut kernel)
    }

    /// [`LaneAdjoint::tile`] `N` lanes wide: the samples of each pixel in
    /// blocks of `N`, as the primal image in lanes takes them (with its
    /// loops, written out: see `LanePath::tile_lanes`).
    #[inline(always)]
    fn tile_lanes<const N: usize>(
        &self,
        layout: &SampleLayout,
        tile: Tile,
        adjoint: &AdjointImage,
        sums: &mut TileSums,
    ) -> usize {
        let scene = self.lanes.scene();
        let filter = &layout.sensor.film.rfilter;
        let emitters: Vec<u32> = (0..scene.emitters.len() as u32)
            .filter(|&em| self.radiance[em as usize].is_some())
            .collect();
        let mut log = Replay::<N> {
            reflectances: self.reflectance.iter().any(Option::is_some)
                || self.scattering.contains(&true),
            scatterings: self.scattering.contains(&true),
            per_radiance: vec![V3::zero(); emitters.len()],
            emitters,
            ..Default::default()
        };
        // per shape, the adjoints of a uniform reflectance over the tile
        let mut uniform = vec![DVec3::ZERO; scene.shapes.len()];
        // per recorded radiance (`log.emitters`), its adjoints over the tile
        let mut radiance = vec![DVec3::ZERO; log.emitters.len()];
        let mut non_finite = 0;
        let mut group = CameraGroup::new();
        // (filters wider than its window take `AdjointImage::gather`)
        let mut window = PixelGather::new(filter);
        for y in tile.y0..tile.y0 + tile.h {
            for x in tile.x0..tile.x0 + tile.w {
                if let Some(window) = &mut window {
                    window.start(adjoint, x, y);
                }
                let mut first = 0;
                while first < layout.spp {
                    self.lanes.camera_group(layout, x, y, first, &mut group);
                    first += group.len() as u32;
                    for at in (0..group.len()).step_by(N) {
                        let SampleBlock {
                            pos,
                            rays,
                            hits,
                            rngs,
                            active,
                        } = group.block::<N>(at);
                        let delta = match &window {
                            Some(window) => {
                                let px = Lanes::<N>::from_fn(|k| pos[k].x);
                                let py = Lanes::<N>::from_fn(|k| pos[k].y);
                                let [r, g, b] = window.gather(filter, px, py);
                                V3::new(r, g, b)
                            }
                            None => lanes3(|k| adjoint.gather(filter, pos[k].x, pos[k].y).into()),
                        };
                        // a sample without adjoint radiance is not shaded
                        let active = active & !delta.is_zero();
                        if active.none() {
                            continue;
                        }
                        // (the group's hits, read by no one after this block)
                        for (k, hit) in hits.iter_mut().enumerate() {
                            if !active.lane(k) {
                                *hit = None;
                            }
                        }
                        log.vertices.clear();
                        log.per_radiance.fill(V3::zero());
                        let (l, _) = self.lanes.trace(rays, hits, active, rngs, &mut log);
                        // samples with a non-finite radiance are left out
                        let keep = active & l.x.finite() & l.y.finite() & l.z.finite();
                        non_finite += (0..N).filter(|&k| active.lane(k) && !keep.lane(k)).count();
                        let delta = V3::select(keep, delta, V3::zero());
                        for (sum, per_radiance) in radiance.iter_mut().zip(&log.per_radiance) {
                            // (a left-out lane's light may not be finite)
                            let g = V3::select(keep, delta.mul_elem(*per_radiance), V3::zero());
                            *sum += (0..N).map(|k| lane3(g, k).as_dvec3()).sum::<DVec3>();
                        }
                        log.sweep(delta, |vertex, k, hit, g| {
                            if self.scattering[hit.shape as usize] {
                                let through = lane3(delta.mul_elem(vertex.throughput), k);
                                self.scatter_bsdf(vertex, k, hit, through, g, sums);
                            }
                            if g == Vec3::ZERO {
                                return;
                            }
                            match self.reflectance[hit.shape as usize] {
                                None => {}
                                Some(Reflectance::Uniform(_)) => {
                                    uniform[hit.shape as usize] += g.as_dvec3();
                                }
                                Some(Reflectance::Varying(texture)) => {
                                    // the look-up of the primal pass, on Vars
                                    // (a bitmap's texels without them)
                                    let mesh = self.lanes.mesh(hit.shape);
                                    let uv = mesh.uv_primal(&scene.params, hit.prim, hit.uv);
                                    if let Texture::Bitmap(bitmap) = texture {
                                        if !self.store.is_recorded(bitmap.to_uv) {
                                            // texels alone: their weights, no tape
                                            bitmap.scatter_adjoint(self.store, uv, g, |i, d| {
                                                sums.add_run(bitmap.data, i, d)
                                            });
                                            return;
                                        }
                                    }
                                    let p = lane3(vertex.p, k);
                                    let si = surface_si::<Var>(
                                        p,
                                        vertex.n[k],
                                        uv,
                                        Vec3::Z,
                                        hit.shape,
                                        hit.prim,
                                    );
                                    self.scatter(texture, &si, g, sums);
                                }
                            }
                        });
                    }
                }
            }
        }
        for (shape, g) in uniform.iter().enumerate() {
            if let Some(Reflectance::Uniform(texture)) = self.reflectance[shape] {
                self.scatter_plain(texture, *g, sums);
            }
        }
        for (&em, g) in log.emitters.iter().zip(&radiance) {
            let texture = self.radiance[em as usize].expect("a recorded radiance");
            self.scatter_plain(texture, *g, sums);
        }
        non_finite
    }

    /// [`LaneAdjoint::scatter`] for a plain value (the same at any
    /// interaction), the sum `g` of its adjoints over a tile.
    fn scatter_plain(&self, texture: &Texture, g: DVec3, sums: &mut TileSums) {
        if g != DVec3::ZERO {
            let si = surface_si::<Var>(Vec3::ZERO, Vec3::Z, Vec2::ZERO, Vec3::Z, 0, 0);
            self.scatter(texture, &si, g.as_vec3(), sums);
        }
    }

    /// Adds to `sums` the gradient of the BSDF of lane `k`'s vertex (at
    /// `hit`) by its recorded parameters: its value along the light
    /// sample's direction weighs `through` ⊙ the sample's weight (`through`
    /// = δL ⊙ β_d, the adjoint radiance times the throughput there), and
    /// along the bounce's, over the bounce's density, `g` = δL ⊙ β_d ⊙ B_d
    /// (what the sweep carries back): the derivative of E_d and of ρ_d ⊙
    /// B_d with the samples' directions and densities held, as the tape
    /// differentiates them.
    fn scatter_bsdf<const N: usize>(
        &self,
        vertex: &Vertex<N>,
        k: usize,
        hit: &Hit,
        through: Vec3,
        g: Vec3,
        sums: &mut TileSums,
    ) {
        let at = &vertex.scattering;
        let light = through * lane3(at.light_weight, k);
        let pdf = at.bounce_pdf.0[k];
        let bounce = if pdf > 0.0 { g / pdf } else { Vec3::ZERO };
        if light == Vec3::ZERO && bounce == Vec3::ZERO {
            return;
        }
        // (a BSDF of the loop in lanes holds plain values: no uv)
        let si = surface_si::<Var>(
            lane3(vertex.p, k),
            lane3(at.ns, k),
            Vec2::ZERO,
            lane3(at.wi, k),
            hit.shape,
            hit.prim,
        );
        clear_tape();
        let mut bsdf = BsdfContext::empty();
        bsdf.set(self.lanes.scene().shape_bsdf(hit.shape), self.store, &si);
        let along = |d: V3<Lanes<N>>| bsdf.eval(si.to_local(V3::cst(lane3(d, k))));
        let (f_light, f_bounce) = (along(at.light_d), along(at.bounce_d));
        backward(
            &[
                (f_light.x, light.x),
                (f_light.y, light.y),
                (f_light.z, light.z),
                (f_bounce.x, bounce.x),
                (f_bounce.y, bounce.y),
                (f_bounce.z, bounce.z),
            ],
            |id, i, d| sums.add(id, i, d),
        );
    }

    /// Adds to `sums` the gradient of `texture` at `si` for the adjoint
    /// `g` of its value.
    fn scatter(
        &self,
        texture: &Texture,
        si: &crate::geometry::SurfaceInteraction<Var>,
        g: Vec3,
        sums: &mut TileSums,
    ) {
        clear_tape();
        let value = texture.eval(self.store, si);
        backward(
            &[(value.x, g.x), (value.y, g.y), (value.z, g.z)],
            |id, i, d| sums.add(id, i, d),
        );
    }
}

/// What one depth of the lanes' paths contributes (see the module
/// documentation); zero in lanes without a vertex there.
#[derive(Clone, Copy)]
struct Vertex<const N: usize> {
    /// E_d.
    emitted: V3<Lanes<N>>,
    /// N_d.
    next_event: V3<Lanes<N>>,
    /// β_d.
    throughput: V3<Lanes<N>>,
    /// ρ_d.
    reflectance: V3<Lanes<N>>,
    /// s_d.
    survival: Lanes<N>,
    /// Where each lane's ray reached a surface, its point and face normal.
    hits: [Option<Hit>; N],
    p: V3<Lanes<N>>,
    n: [Vec3; N],
    /// The directions it scattered along, where a BSDF's parameters are
    /// recorded.
    scattering: Scattering<N>,
}

impl<const N: usize> Default for Vertex<N> {
    fn default() -> Self {
        let zero = V3::zero();
        Vertex {
            emitted: zero,
            next_event: zero,
            throughput: zero,
            reflectance: zero,
            survival: Lanes::splat(0.0),
            hits: [None; N],
            p: zero,
            // zeros, not +z, in the lanes without a hit (whose normal no
            // one reads): a log starts each block and depth from this
            // value, and LLVM built `[Vec3::Z; N]` with narrower stores
            // than the loads that copied it, which waited on them (2.7 %
            // and 2.0 % of the replay kernel's samples on cbox)
            n: [Vec3::ZERO; N],
            scattering: Scattering {
                ns: zero,
                wi: zero,
                light_d: zero,
                light_weight: zero,
                bounce_d: zero,
                bounce_pdf: Lanes::splat(0.0),
            },
        }
    }
}

/// The log of one block's paths, vertex by vertex.
#[derive(Default)]
struct Replay<const N: usize> {
    /// Whether to log the vertices (a reflectance or a parameter of
    /// another BSDF is recorded): the sweep needs them, the radiances do
    /// not.
    reflectances: bool,
    /// Whether to log the directions of the scattering (a parameter of a
    /// BSDF other than `diffuse` is recorded).
    scatterings: bool,
    vertices: Vec<Vertex<N>>,
    /// The emitters whose radiance is recorded.
    emitters: Vec<u32>,
    /// Per emitter of `emitters`, the lanes' ∂L/∂L_e: the sum of the light
    /// it sent to the camera per unit of its radiance.
    per_radiance: Vec<V3<Lanes<N>>>,
}

impl<const N: usize> Replay<N> {
    #[inline(always)]
    fn at(&mut self, depth: u32) -> &mut Vertex<N> {
        let d = depth as usize;
        if self.vertices.len() <= d {
            // each new vertex made in place (`resize` copied one made on
            // the stack: 3.8 % of the replay kernel's samples on cbox, the
            // copy's loads waiting on the stores that had just made it)
            self.vertices.resize_with(d + 1, Vertex::default);
        }
        &mut self.vertices[d]
    }

    /// From the last vertex back to the first: calls `scatter(vertex, k,
    /// hit, g)` with g = δL ⊙ ∂L/∂ρ_d of lane `k` where it is not zero, or
    /// where its light sample counts and the scattering is logged
    /// (`delta`: the lanes' adjoint radiance δL), and returns the radiance
    /// the log accounts for (the traced radiance, up to rounding).
    #[inline(always)]
    fn sweep(
        &self,
        delta: V3<Lanes<N>>,
        mut scatter: impl FnMut(&Vertex<N>, usize, &Hit, Vec3),
    ) -> V3<Lanes<N>> {
        // R_{d+1}, the radiance from the next vertex on per unit of its
        // throughput
        let mut after = V3::zero();
        for vertex in self.vertices.iter().rev() {
            let b = vertex.next_event + after * vertex.survival;
            after = vertex.emitted + vertex.reflectance.mul_elem(b);
            let g = delta.mul_elem(vertex.throughput).mul_elem(b);
            for k in 0..N {
                if let Some(hit) = &vertex.hits[k] {
                    let g = lane3(g, k);
                    // (a light sample's contribution counts where a BSDF's
                    // parameters are recorded, whatever comes after it)
                    let lit =
                        self.scatterings && lane3(vertex.scattering.light_weight, k) != Vec3::ZERO;
                    if g != Vec3::ZERO || lit {
                        scatter(vertex, k, hit, g);
                    }
                }
            }
        }
        after
    }
}

impl<const N: usize> PathLog<N> for Replay<N> {
    #[inline(always)]
    fn vertex(&mut self, depth: u32, hits: &[Option<Hit>; N], p: V3<Lanes<N>>, n: &[Vec3; N]) {
        if !self.reflectances {
            return;
        }
        let v = self.at(depth);
        (v.hits, v.p, v.n) = (*hits, p, *n);
    }
    #[inline(always)]
    fn emitted(&mut self, depth: u32, per_throughput: impl FnOnce() -> V3<Lanes<N>>) {
        if !self.reflectances {
            return;
        }
        let v = self.at(depth);
        v.emitted += per_throughput();
    }
    #[inline(always)]
    fn light(
        &mut self,
        throughput: V3<Lanes<N>>,
        per_radiance: impl FnOnce() -> ([Option<u32>; N], V3<Lanes<N>>),
    ) {
        if self.emitters.is_empty() {
            return;
        }
        let (emitters, per_radiance) = per_radiance();
        let light = throughput.mul_elem(per_radiance);
        for (&em, sum) in self.emitters.iter().zip(&mut self.per_radiance) {
            let from = LaneMask::<N>::from_fn(|k| emitters[k] == Some(em));
            *sum += V3::select(from, light, V3::zero());
        }
    }
    #[inline(always)]
    fn next_event(
        &mut self,
        depth: u32,
        contribution: impl FnOnce() -> (V3<Lanes<N>>, V3<Lanes<N>>),
    ) {
        if !self.reflectances {
            return;
        }
        // the light sample of a vertex whose BSDF is not `diffuse` counts
        // as emitted there (see the module documentation)
        let (per_reflectance, per_throughput) = contribution();
        let v = self.at(depth);
        v.next_event = per_reflectance;
        v.emitted += per_throughput;
    }
    #[inline(always)]
    fn scattering(&mut self, depth: u32, scattering: impl FnOnce() -> Scattering<N>) {
        if !self.scatterings {
            return;
        }
        self.at(depth).scattering = scattering();
    }
    #[inline(always)]
    fn bounce(
        &mut self,
        depth: u32,
        throughput: V3<Lanes<N>>,
        reflectance: V3<Lanes<N>>,
        survival: Lanes<N>,
    ) {
        if !self.reflectances {
            return;
        }
        let v = self.at(depth);
        (v.throughput, v.reflectance, v.survival) = (throughput, reflectance, survival);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::lanes::widest_lanes;
    use crate::diff::prb::{backward_pass, render_backward};
    use crate::integrator::lanes::lane_width;
    use crate::integrator::{render, RenderOptions};
    use crate::params::Seeds;
    use crate::scene::Scene;
    use std::path::Path;

    /// A bundled scene; `textured_sun` is textured with a directional
    /// light `sun` beside its area light and environment.
    fn scene(name: &str, res: u32, max_depth: u32) -> Scene {
        let file = name.strip_suffix("_sun").unwrap_or(name);
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{file}.xml"));
        let defines = [
            ("res".to_string(), res.to_string()),
            ("max_depth".to_string(), max_depth.to_string()),
        ];
        if file == name {
            return Scene::load_file(&path, &defines).unwrap();
        }
        let sun = r#"<emitter type="directional" id="sun">
            <vector name="direction" x="0.3" y="-1" z="-0.4"/>
            <rgb name="irradiance" value="2, 1.8, 1.5"/>
        </emitter></scene>"#;
        let xml = std::fs::read_to_string(&path)
            .unwrap()
            .replace("</scene>", sun);
        Scene::load_str(&xml, &path, &defines).unwrap()
    }

    fn opts(spp: u32, seed: u64) -> RenderOptions {
        RenderOptions {
            spp: Some(spp),
            seed,
            ..Default::default()
        }
    }

    /// `n` numbers in [-1, 1) from a fixed seed (xorshift).
    fn noise(n: usize, mut state: u64) -> Vec<f32> {
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
            })
            .collect()
    }

    /// The lanes' radiance from the log's factors (the sweep) is the
    /// radiance the loop traced, lane by lane, on cbox (area light),
    /// textured (textures and an environment) and bsdfs (rough BSDFs on
    /// spheres beside a diffuse ground), roulette included: the log misses
    /// no contribution and counts none twice.
    #[test]
    fn the_sweep_gives_back_the_traced_radiance() {
        for name in ["cbox", "textured", "bsdfs"] {
            let scene = scene(name, 16, 12);
            let lanes = LanePath::new(&scene, 4).unwrap();
            let layout = SampleLayout::new(&scene, &opts(16, 3)).unwrap();
            let primal = scene.params.primal();
            let (mut compared, mut lit) = (0, 0);
            for y in 0..16 {
                for x in 0..16 {
                    for first in [0u32, 4, 8, 12] {
                        let samples: [_; 4] =
                            std::array::from_fn(|k| layout.camera_sample(x, y, first + k as u32));
                        let mut rays =
                            std::array::from_fn(|k| samples[k].1.ray::<f32>(&primal).val());
                        let mut rngs = samples.clone().map(|s| s.2);
                        let mut log = Replay::<4> {
                            reflectances: true,
                            ..Default::default()
                        };
                        let all = LaneMask::<4>::from_fn(|_| true);
                        let mut hits = rays.map(|r| scene.intersect(&r));
                        let (l, _) = lanes.trace(&mut rays, &mut hits, all, &mut rngs, &mut log);
                        let swept = log.sweep(V3::zero(), |_, _, _, _| {});
                        for k in 0..4 {
                            let (a, b) = (lane3(l, k), lane3(swept, k));
                            let scale = a.abs().max_element().max(1e-3);
                            assert!(
                                (a - b).abs().max_element() <= 1e-5 * scale,
                                "{name} ({x}, {y}), sample {}: traced {a}, swept {b}",
                                first + k as u32
                            );
                            compared += 1;
                            lit += (a != Vec3::ZERO) as usize;
                        }
                    }
                }
            }
            assert!(lit > compared / 2, "{name}: {lit} of {compared} lit");
        }
    }

    /// Where the reverse mode runs in lanes: the scenes and parameters of
    /// the module documentation (diffuse reflectances, plain radiances of
    /// area lights and constant environments), not a camera, a mesh or a
    /// BSDF other than `diffuse`.
    #[test]
    fn lanes_take_the_diffuse_reflectances_and_the_plain_radiances() {
        let takes = |name: &str, key: &str| {
            let scene = scene(name, 8, 6);
            let ids = [scene.params.require(key).unwrap()];
            let seeds = Seeds::recorded(&scene.params, &ids).unwrap();
            let store = scene.params.view(&seeds);
            LaneAdjoint::new(&scene, &store, 4).is_some()
        };
        assert!(takes("cbox", "red.reflectance.value"));
        assert!(takes("textured", "plane.bsdf.reflectance.data"));
        assert!(takes("cbox", "light.emitter.radiance.value"));
        assert!(takes("textured", "env.radiance.value"));
        assert!(takes("bsdfs", "ground.bsdf.reflectance.value"));
        assert!(takes("bsdfs", "light.emitter.radiance.value"));
        // beside point and directional lights, and by their plain values
        // (a point light's position moves shadows: the tape)
        assert!(takes("cbox_point", "red.reflectance.value"));
        assert!(takes("cbox_point", "light.emitter.radiance.value"));
        assert!(takes("cbox_point", "bulb.intensity.value"));
        assert!(takes("textured_sun", "sun.irradiance.value"));
        assert!(takes("textured_sun", "plane.bsdf.reflectance.data"));
        assert!(!takes("cbox_point", "bulb.position"));
        assert!(!takes("cbox", "light.vertex_positions"));
        assert!(!takes("cbox", "sensor.x_fov"));
        // the rough BSDFs' roughnesses, indices and factors, at each vertex
        // on Vars; not a plastic's diffuse base
        for key in [
            "conductor.bsdf.alpha.value",
            "conductor.bsdf.eta.value",
            "conductor.bsdf.k.value",
            "dielectric.bsdf.alpha.value",
            "dielectric.bsdf.eta",
            "plastic.bsdf.alpha",
            "plastic.bsdf.eta",
        ] {
            assert!(takes("bsdfs", key), "{key}");
        }
        assert!(!takes("bsdfs", "plastic.bsdf.diffuse_reflectance.value"));
    }

    /// The gradient in lanes is the derivative of the image in lanes with
    /// the same random numbers: for an adjoint image w, g · v against the
    /// central difference of Σ w · I(θ ± ε v), on cbox (a plain
    /// reflectance, and the area light's radiance, each channel; the
    /// reflectance and the point light's intensity in cbox_point), textured
    /// (a texture, along a random direction over its texels, the constant
    /// environment's radiance, and a directional light's irradiance added
    /// to it) and bsdfs (the diffuse ground's
    /// reflectance among rough BSDFs, the area light's radiance, and the
    /// rough conductor's index of refraction, which its samples do not
    /// depend on). max_depth 5 keeps the roulette out
    /// (its survival probability is held fixed by the gradient, not by a
    /// finite difference). The image is a polynomial in θ (smooth in a
    /// conductor's index), so the
    /// difference's error is its rounding, bounded by Σ |w| (|I₊| + |I₋|)
    /// 2·10⁻⁶ / 2ε (a pixel's value carries the rounding of ~32 f32
    /// operations of relative error 2⁻²⁴ each: the path's products, the
    /// filter and the sums), plus its truncation, bounded by the change
    /// from the difference at 2ε (Richardson: the error at ε is a third of
    /// that change).
    #[test]
    fn lane_gradients_are_the_derivatives_of_the_lane_image() {
        for (name, key, directions) in [
            ("cbox", "red.reflectance.value", 3),
            ("cbox", "light.emitter.radiance.value", 3),
            ("cbox_point", "red.reflectance.value", 3),
            ("cbox_point", "bulb.intensity.value", 3),
            ("textured_sun", "sun.irradiance.value", 3),
            ("textured", "plane.bsdf.reflectance.data", 1),
            ("textured", "env.radiance.value", 3),
            ("bsdfs", "ground.bsdf.reflectance.value", 3),
            ("bsdfs", "light.emitter.radiance.value", 3),
            ("bsdfs", "conductor.bsdf.eta.value", 3),
        ] {
            let mut scene = scene(name, 24, 5);
            let opts = opts(8, 11);
            let theta = scene
                .params
                .data(scene.params.require(key).unwrap())
                .to_vec();
            // an adjoint image of one sign: the derivative does not cancel
            // out over the pixels
            let w: Vec<f32> = noise(24 * 24 * 3, 5)
                .iter()
                .map(|v| 0.5 * (v + 1.0))
                .collect();
            let ids = [scene.params.require(key).unwrap()];
            let seeds = Seeds::recorded(&scene.params, &ids).unwrap();
            assert!(
                LaneAdjoint::new(
                    &scene,
                    &scene.params.view(&seeds),
                    lane_width(None).unwrap()
                )
                .is_some(),
                "{name}: not the reverse mode in lanes"
            );
            let g = render_backward(&scene, &w, Some(&[key]), &opts).unwrap();
            let g = g.get(key).unwrap().to_vec();
            for dir in 0..directions {
                let v: Vec<f32> = if directions == 1 {
                    noise(theta.len(), 17)
                } else {
                    (0..theta.len()).map(|i| (i == dir) as u32 as f32).collect()
                };
                // Σ w · I and Σ |w| |I| at θ + t v
                let mut at = |t: f32| {
                    let moved: Vec<f32> = theta.iter().zip(&v).map(|(a, b)| a + t * b).collect();
                    scene.params.set(key, &moved).unwrap();
                    scene.update().unwrap();
                    let img = render(&scene, &opts).unwrap().data;
                    let dot = img.iter().zip(&w).map(|(i, w)| (i * w) as f64).sum::<f64>();
                    let abs = img
                        .iter()
                        .zip(&w)
                        .map(|(i, w)| (i * w).abs() as f64)
                        .sum::<f64>();
                    (dot, abs)
                };
                // a step of 1 % of the parameter's scale: for a radiance
                // of 25, a step of 0.01 would leave the difference in the
                // rounding of the image
                // (a conductor's index by 3 %: its derivative is small
                // beside the image, whose rounding the difference divides
                // by the step)
                let scale = theta.iter().fold(1.0f32, |m, t| m.max(t.abs()));
                let eps = if key.starts_with("conductor.") {
                    3e-2
                } else {
                    1e-2
                } * scale;
                let (p1, a1) = at(eps);
                let (m1, a2) = at(-eps);
                let (p2, _) = at(2.0 * eps);
                let (m2, _) = at(-2.0 * eps);
                let fd = (p1 - m1) / (2.0 * eps as f64);
                let fd2 = (p2 - m2) / (4.0 * eps as f64);
                let tol = (a1 + a2) * 2e-6 / (2.0 * eps as f64) + (fd2 - fd).abs();
                let gv: f64 = g.iter().zip(&v).map(|(g, v)| (g * v) as f64).sum();
                assert!(
                    (gv - fd).abs() <= tol,
                    "{name}, direction {dir}: gradient {gv}, difference {fd} (±{tol})"
                );
                // the test resolves the derivative: its tolerance is under
                // 1 % of it (3 % for a conductor's index, whose small
                // derivatives sit in a whole image's rounding)
                let resolves = if key.starts_with("conductor.") {
                    0.03
                } else {
                    0.01
                };
                assert!(
                    tol < resolves * fd.abs(),
                    "{name} {key} {dir}: ±{tol} of {fd}"
                );
            }
            scene.params.set(key, &theta).unwrap();
        }
    }

    /// The reverse mode in lanes and the one on a tape estimate the same
    /// gradient at full depth, roulette included: the means of 16 runs each
    /// (other seeds, 32 spp) of cbox's red reflectance (also with a point
    /// light beside its area light) and light radiance, of the point
    /// light's intensity, of a directional light's irradiance added to
    /// textured, of
    /// bsdfs' ground reflectance and environment radiance, of its rough
    /// conductor's index of refraction and roughness (the derivatives of
    /// a rough BSDF's value on `Var`s at the vertices), and of the
    /// per-channel sum of textured's texture gradient differ by less than 4.5 standard
    /// errors (Welch; a chance of ~10⁻⁴ per number if both are unbiased),
    /// at every width this processor runs.
    /// Their images differ (the two loops' shading frames do), so the
    /// runs are compared in distribution, not sample by sample.
    #[test]
    fn lanes_and_the_tape_estimate_the_same_gradient() {
        for (name, key) in [
            ("cbox", "red.reflectance.value"),
            ("cbox", "light.emitter.radiance.value"),
            ("cbox_point", "red.reflectance.value"),
            ("cbox_point", "bulb.intensity.value"),
            ("textured_sun", "sun.irradiance.value"),
            ("textured", "plane.bsdf.reflectance.data"),
            ("bsdfs", "ground.bsdf.reflectance.value"),
            ("bsdfs", "env.radiance.value"),
            ("bsdfs", "conductor.bsdf.eta.value"),
            ("bsdfs", "conductor.bsdf.alpha.value"),
        ] {
            let resolves = match key {
                "conductor.bsdf.eta.value" => 0.10,
                "conductor.bsdf.alpha.value" => 1.0,
                _ => 0.05,
            };
            let scene = scene(name, 24, 12);
            let w: Vec<f32> = noise(24 * 24 * 3, 9)
                .iter()
                .map(|v| 0.5 * (v + 1.0))
                .collect();
            let ids = [scene.params.require(key).unwrap()];
            let seeds = Seeds::recorded(&scene.params, &ids).unwrap();
            let store = scene.params.view(&seeds);

            let per_channel = |lanes: Option<&LaneAdjoint>, seed: u64| -> [f64; 3] {
                let opts = scene
                    .integrator
                    .derivative_options(&scene, &opts(32, seed))
                    .unwrap();
                let (sums, non_finite) = backward_pass(&scene, &store, &w, &opts, lanes).unwrap();
                assert_eq!(non_finite, 0);
                let g = &sums[ids[0].0 as usize];
                std::array::from_fn(|c| g.iter().skip(c).step_by(3).sum())
            };
            // (a roughness is one value, a colour three)
            let channels = scene.params.data(ids[0]).len().min(3);
            let runs = |lanes: Option<&LaneAdjoint>, seed0: u64| -> Vec<[f64; 3]> {
                (0..16).map(|i| per_channel(lanes, seed0 + i)).collect()
            };
            let b = runs(None, 200);
            // every width this processor runs
            for width in [4, 8, 16]
                .into_iter()
                .filter(|&w| w == 4 || w <= widest_lanes())
            {
                let lanes = LaneAdjoint::new(&scene, &store, width).unwrap();
                let a = runs(Some(&lanes), 100);
                for c in 0..channels {
                    let stats = |r: &[[f64; 3]]| {
                        let n = r.len() as f64;
                        let mean = r.iter().map(|v| v[c]).sum::<f64>() / n;
                        let var = r.iter().map(|v| (v[c] - mean).powi(2)).sum::<f64>() / (n - 1.0);
                        (mean, var / n)
                    };
                    let ((ma, va), (mb, vb)) = (stats(&a), stats(&b));
                    let t = (ma - mb) / (va + vb).sqrt();
                    assert!(
                        t.abs() < 4.5,
                        "{name}, {width} lanes, channel {c}: lanes {ma}, tape {mb}, t = {t}"
                    );
                    // the comparison resolves a bias of 5 % (of 10 % for
                    // a conductor's index, of the gradient's own size for
                    // its roughness: noisier estimates at this budget)
                    assert!(
                        4.5 * (va + vb).sqrt() < resolves * mb.abs(),
                        "{name}, {width} lanes, channel {c}: 4.5 se = {} of {mb}",
                        4.5 * (va + vb).sqrt()
                    );
                }
            }
        }
    }
}
