//! Integrators: estimators of the radiance arriving along camera rays, and
//! the tiled render loop that drives them.

mod aov;
mod budgets;
mod direct;
pub(crate) mod lanes;
mod moment;
pub(crate) mod path;
pub(crate) mod render;
mod volpath;

pub use aov::{AovIntegrator, AovKind};
pub use budgets::Budgets;
pub use direct::DirectIntegrator;
pub use moment::MomentIntegrator;
pub use path::{PathIntegrator, RouletteCount};
pub use render::{render, ProgressFn, RenderOptions, Rendered};
pub use volpath::VolPathIntegrator;

use crate::ad::{Float, ScalarReal};
use crate::bsdf::{BsdfContext, BsdfContextT, BsdfFlags, BsdfSample};
use crate::emitter::EmitterT;
use crate::error::Result;
use crate::geometry::{DiffRay, Hit, Ray, SurfaceInteraction};
use crate::math::Spectrum;
use crate::math::V3;
use crate::params::ParamView;
use crate::sampler::SampleStream;
use crate::scene::{Node, Scene};
use crate::sensor::CameraSample;

/// All integrator plugins. Mitsuba's differentiable integrators are
/// names of these: every radiance integrator here is differentiable, in
/// both modes.
#[derive(Clone, Debug)]
pub enum Integrator {
    /// `path`, `prb`, `prb_basic`, `prb_projective`.
    Path(PathIntegrator),
    /// `direct`, `direct_projective`.
    Direct(DirectIntegrator),
    Aov(AovIntegrator),
    Moment(MomentIntegrator),
    /// `volpath`, `volpathmis`, `prbvolpath`: participating media.
    VolPath(VolPathIntegrator),
}

impl Integrator {
    pub fn from_node(node: &Node) -> Result<Integrator> {
        let i = match node.plugin.as_str() {
            "path" => Integrator::Path(PathIntegrator::from_node(
                node,
                -1,
                RouletteCount::FromOne,
                Budgets::default(),
            )?),
            "prb" => Integrator::Path(PathIntegrator::from_node(
                node,
                6,
                RouletteCount::FromZero,
                Budgets::default(),
            )?),
            "prb_basic" => Integrator::Path(PathIntegrator::from_node(
                node,
                6,
                RouletteCount::Never,
                Budgets::default(),
            )?),
            "prb_projective" => Integrator::Path(PathIntegrator::from_node(
                node,
                6,
                RouletteCount::FromZero,
                Budgets::from_projective_node(node)?,
            )?),
            "direct" => Integrator::Direct(DirectIntegrator::from_node(node)?),
            "direct_projective" => {
                Integrator::Direct(DirectIntegrator::projective_from_node(node)?)
            }
            "aov" => Integrator::Aov(AovIntegrator::from_node(node)?),
            "moment" => Integrator::Moment(MomentIntegrator::from_node(node)?),
            "volpath" | "volpathmis" => {
                Integrator::VolPath(VolPathIntegrator::from_node(node, -1)?)
            }
            "prbvolpath" => Integrator::VolPath(VolPathIntegrator::from_node(node, 6)?),
            other => {
                return Err(node.error(format!(
                    "unknown integrator plugin '{other}' (Penumbra has: path, prb, prb_basic, \
                     prb_projective, direct, direct_projective, aov, moment, volpath, \
                     volpathmis, prbvolpath)"
                )))
            }
        };
        node.check_all_used()?;
        Ok(i)
    }

    /// The sample budgets this integrator gives derivative passes.
    pub fn budgets(&self) -> Budgets {
        match self {
            Integrator::Path(p) => p.budgets,
            Integrator::Direct(d) => d.budgets,
            Integrator::VolPath(v) => v.budgets(),
            Integrator::Aov(_) | Integrator::Moment(_) => Budgets::default(),
        }
    }

    /// The options of a derivative pass: `opts` with the integrator's
    /// budgets filled in ([`Budgets::resolve`]).
    pub(crate) fn derivative_options(
        &self,
        scene: &Scene,
        opts: &RenderOptions,
    ) -> Result<RenderOptions> {
        let sampler_spp = scene.sensor(opts.sensor)?.sampler.sample_count();
        Ok(self.budgets().resolve(opts, sampler_spp))
    }

    /// Names of the output channels (EXR channel names).
    pub fn channel_names(&self) -> Vec<String> {
        match self {
            Integrator::Aov(a) => a.channel_names(),
            Integrator::Moment(m) => m.channel_names(),
            _ => vec!["R".into(), "G".into(), "B".into()],
        }
    }

    pub fn channel_count(&self) -> usize {
        match self {
            Integrator::Aov(a) => a.channel_names().len(),
            Integrator::Moment(m) => m.channel_count(),
            _ => 3,
        }
    }

    /// Whether the first three channels are an RGB radiance image (all
    /// but an `aov` integrator without a nested one).
    pub fn has_radiance_channels(&self) -> bool {
        match self {
            Integrator::Aov(a) => a.nested.is_some(),
            _ => true,
        }
    }

    /// Fails for the integrators that only write images (`aov`,
    /// `moment`): derivatives need a radiance integrator.
    pub(crate) fn check_differentiable(&self) -> Result<()> {
        let name = match self {
            Integrator::Aov(_) => "aov",
            Integrator::Moment(_) => "moment",
            Integrator::Path(_) | Integrator::Direct(_) | Integrator::VolPath(_) => return Ok(()),
        };
        Err(crate::Error::Invalid(format!(
            "the {name} integrator has no derivatives; use path or direct"
        )))
    }

    /// Primal estimate through the camera sample `cs`, written to `out`
    /// (`channel_count()` values). Returns whether the camera ray reached
    /// a surface (the alpha of an rgba film) where the integrator traced
    /// it (`None` for `aov` and `moment`).
    pub fn sample(
        &self,
        scene: &Scene,
        cs: &CameraSample,
        rng: &mut SampleStream,
        out: &mut [f32],
    ) -> Option<bool> {
        match self {
            Integrator::Aov(a) => {
                a.sample(scene, cs, rng, out);
                return None;
            }
            Integrator::Moment(m) => {
                m.sample(scene, cs, rng, out);
                return None;
            }
            Integrator::Path(_) | Integrator::Direct(_) | Integrator::VolPath(_) => {}
        }
        let (rgb, hit) = self
            .estimate::<f32>(scene, &scene.params.primal(), cs, rng)
            .expect("path, direct and volpath estimate radiance");
        out[..3].copy_from_slice(&rgb.val().to_array());
        Some(hit)
    }

    /// The radiance estimate through camera sample `cs` in `R` (primal for
    /// f32, derivatives for dual numbers and recorded variables); `None` for
    /// the AOV and moment integrators, which only write images.
    /// Parameters are read through `store`, the scene's values with the
    /// derivative state of the call; when a differentiated parameter moves
    /// surfaces or the camera ([`ParamView::moves_geometry`]) the path is
    /// re-evaluated in the parameterisation of [`scatter`], otherwise
    /// nothing moves and the sampled weights are used as they are.
    pub fn radiance<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> Option<Spectrum<R>> {
        self.estimate(scene, store, cs, rng).map(|(l, _)| l)
    }

    /// [`Integrator::radiance`] and whether the camera ray reached a
    /// surface.
    fn estimate<R: ScalarReal>(
        &self,
        scene: &Scene,
        store: &ParamView,
        cs: &CameraSample,
        rng: &mut SampleStream,
    ) -> Option<(Spectrum<R>, bool)> {
        match self {
            Integrator::Path(p) => Some(p.sample::<R>(scene, store, cs, rng)),
            Integrator::Direct(d) => Some(d.sample::<R>(scene, store, cs, rng)),
            Integrator::VolPath(v) => Some(v.sample::<R>(scene, store, cs, rng)),
            Integrator::Aov(_) | Integrator::Moment(_) => None,
        }
    }
}

impl Integrator {
    /// The radiance that reaches a first vertex (one the camera sees)
    /// along `ray`, as this integrator's estimate at that vertex counts it,
    /// primal: the emission of what the ray reaches, with its whole weight
    /// (the MIS weights of the strategies that find it add up to one), and
    /// with path tracing beyond depth 2 the rest of the path from there.
    /// The boundary term of the first vertex's visibility measures its
    /// jump across the edges seen from that vertex.
    pub(crate) fn incident_radiance(
        &self,
        scene: &Scene,
        ray: &Ray,
        rng: &mut SampleStream,
    ) -> glam::Vec3 {
        let store = scene.params.primal();
        match self {
            Integrator::Path(p) => p
                .trace::<f32>(
                    scene,
                    &store,
                    DiffRay::cst(ray),
                    scene.intersect(ray).as_ref(),
                    1,
                    rng,
                )
                .val(),
            Integrator::Direct(_) => match scene.intersect(ray) {
                Some(hit) => match scene.shape_emitter(hit.shape) {
                    Some(em) => {
                        let si = scene.surface_interaction::<f32>(&store, &DiffRay::cst(ray), &hit);
                        scene.emitters[em as usize].eval_surface(&store, &si).val()
                    }
                    None => glam::Vec3::ZERO,
                },
                None => scene.environment.map_or(glam::Vec3::ZERO, |env| {
                    scene.emitters[env as usize]
                        .eval_environment::<f32>(&store, V3::cst(ray.d))
                        .val()
                }),
            },
            // media refuse geometry derivatives, which this serves
            Integrator::VolPath(_) | Integrator::Aov(_) | Integrator::Moment(_) => glam::Vec3::ZERO,
        }
    }

    /// Whether the radiance a first vertex receives includes light that
    /// bounced off other surfaces (path tracing beyond depth 2).
    pub(crate) fn traces_indirect_light(&self) -> bool {
        matches!(self, Integrator::Path(p) if p.max_depth > 2)
    }
}

/// Where a path goes after scattering at `si` by the BSDF sample `bs`: the
/// traced ray, the next vertex in `R`, and the weight of the bounce in `R`.
pub(crate) struct Bounce<R> {
    /// The ray traced from `si` (primal).
    pub ray: Ray,
    /// Its direction in `R`: what an environment emitter is looked up
    /// along if the ray escapes.
    pub d: V3<R>,
    pub hit: Option<Hit>,
    /// `f · cos / pdf` of the bounce, with the derivatives of the
    /// parameterisation below.
    pub weight: Spectrum<R>,
    /// The sample came from a delta lobe.
    pub delta: bool,
}

/// Traces the ray of BSDF sample `bs` from `si` (`bsdf`: the BSDF there)
/// and re-evaluates what it reaches in `R`, in a parameterisation of the
/// path that does not move with the parameters (the interior term of the derivative; Zhang et al.
/// 2020, "Path-Space Differentiable Rendering"; on which choices are valid:
/// Worchel et al. 2025, arXiv 2504.05750):
/// - after a smooth lobe, the sampled direction is a constant of the
///   integral only at the primal parameters; the next vertex is the point
///   of its surface with fixed surface coordinates, moving with that
///   surface (material form). The direction between the two vertices
///   follows both, the BSDF is re-evaluated along it, and the weight
///   carries the Jacobian `area_scale · |cos θ'| / dist²` from the next
///   surface's area to solid angle at `si` relative to its primal value
///   (the sample density itself is a constant: detached sampling).
/// - after a delta lobe, the direction is a function of `wi` and the
///   normal: the ray leaves the attached point along the attached
///   direction, and the next vertex slides along it.
///
/// When no geometry moves (material and emitter parameters only) both forms reduce to the sample's own weight and the
/// point where the ray hits, which is what this returns then.
///
/// The next vertex (`wi` set; `None` if the ray escaped) is written to
/// `next`: a surface interaction is a few hundred bytes, and a path's loop
/// keeps two (the vertex and the next) in slots it reuses, rather than
/// moving one out of the returned value at every bounce (the compiler
/// still copies the new interaction once into the slot).
pub(crate) fn scatter<R: ScalarReal>(
    scene: &Scene,
    store: &ParamView,
    bsdf: &BsdfContext<R>,
    si: &SurfaceInteraction<R>,
    bs: &BsdfSample<R>,
    next: &mut Option<SurfaceInteraction<R>>,
) -> Bounce<R> {
    let delta = bs.lobe.has(BsdfFlags::DELTA);
    let d = si.to_world(bs.wo).normalize();
    let ray = si.spawn_ray(d.val());
    let hit = scene.intersect(&ray);
    if delta || !store.moves_geometry() || !R::DIFFERENTIABLE {
        let dray = DiffRay {
            o: si.p,
            d,
            tmin: ray.tmin,
            tmax: ray.tmax,
        };
        *next = hit.map(|h| scene.surface_interaction(store, &dray, &h));
        return Bounce {
            ray,
            d,
            hit,
            weight: bs.weight,
            delta,
        };
    }
    *next = hit.map(|h| scene.point_at::<R>(store, &h, ray.at(h.t)));
    let (wo, jacobian) = match next {
        Some(next) => {
            let to = next.p - si.p;
            let dist2 = to.length_squared();
            let wo = to / dist2.sqrt();
            next.set_wi(-wo);
            let g = next.area_scale * wo.dot(next.n).abs() / dist2;
            (wo, g / g.val())
        }
        // towards the environment (at infinity): the world direction is the
        // constant, as for an emitter sample of the environment (both MIS
        // strategies must see it through the same map)
        None => (V3::cst(d.val()), R::cst(1.0)),
    };
    let f = bsdf.eval(si.to_local(wo));
    // the sample's own weight as value, the derivative of f · J / pdf
    let attach = |w: R, f: R| {
        if f.val() != 0.0 {
            f * (w.val() / f.val())
        } else {
            w
        }
    };
    let weight = V3::new(
        attach(bs.weight.x, f.x),
        attach(bs.weight.y, f.y),
        attach(bs.weight.z, f.z),
    ) * jacobian;
    Bounce {
        ray,
        d: wo,
        hit,
        weight,
        delta,
    }
}

/// Russian roulette on the throughput (times η² so that refraction does
/// not end paths early), from depth `rr_depth` on: false if the path ends
/// (also when nothing is left to carry); otherwise the throughput of a
/// surviving path is divided by its survival probability.
pub(crate) fn survives_roulette<R: ScalarReal>(
    throughput: &mut Spectrum<R>,
    eta: f32,
    depth: u32,
    rr_depth: u32,
    rng: &mut SampleStream,
) -> bool {
    let Some(survival) = roulette(throughput.val(), eta, depth, rr_depth, rng) else {
        return false;
    };
    survival.apply(throughput);
    true
}

/// A path that goes on after Russian roulette: with the probability `q`
/// it survived with, or `None` before the roulette's depth.
pub(crate) struct Survival(Option<f32>);

impl Survival {
    /// Divides the surviving path's throughput by its survival probability.
    pub(crate) fn apply<R: ScalarReal>(self, throughput: &mut Spectrum<R>) {
        if let Some(q) = self.0 {
            *throughput *= R::cst(1.0 / q);
        }
    }
}

/// The decision of [`survives_roulette`] for a path whose throughput will
/// be `throughput` (primal), for a caller that applies it later: `None`
/// if the path ends.
pub(crate) fn roulette(
    throughput: glam::Vec3,
    eta: f32,
    depth: u32,
    rr_depth: u32,
    rng: &mut SampleStream,
) -> Option<Survival> {
    let u = rng.next_1d();
    let (survives, q) = survival_probability(throughput.max_element(), eta, depth, rr_depth, u);
    survives.then_some(Survival((depth >= rr_depth).then_some(q)))
}

/// Russian roulette's decision for paths whose largest throughput channel
/// is `t_max` (primal, after the bounce), drawn with `u`: whether the path
/// goes on, and the probability it went on with (1 before `rr_depth`). A
/// path with nothing left to carry (`t_max` zero or NaN) ends at any depth.
#[inline(always)]
pub(crate) fn survival_probability<F: Float>(
    t_max: F,
    eta: F,
    depth: u32,
    rr_depth: u32,
    u: F,
) -> (F::Mask, F) {
    let t_max = t_max * eta * eta;
    let carries = t_max.gt(0.0);
    if depth < rr_depth {
        return (carries, F::cst(1.0));
    }
    let q = t_max.min(F::cst(0.95));
    (carries & u.lt(q), q)
}

/// Balance of two sampling strategies by the power heuristic (β = 2):
/// strategy a's weight, 1 where its density is infinite (a delta), 0 where
/// both vanish.
#[inline(always)]
pub(crate) fn mis_weight<F: Float>(pdf_a: F, pdf_b: F) -> F {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    let sum = a + b;
    F::select(
        sum.gt(0.0) & a.finite(),
        a / sum,
        F::select(a.equals(f32::INFINITY), F::cst(1.0), F::cst(0.0)),
    )
}

/// `max_depth` as Mitsuba defines it: -1 for unbounded, else ≥ 0.
pub(crate) fn max_depth(node: &Node, default: i64) -> Result<u32> {
    let d = node.int("max_depth", default)?;
    if d < -1 {
        let p = node
            .prop("max_depth")
            .expect("a non-default value came from a property");
        return Err(node.prop_error(p, format!("must be -1 (unbounded) or >= 0, found {d}")));
    }
    Ok(if d == -1 { u32::MAX } else { d as u32 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ad::Dual;
    use crate::params::Seeds;
    use crate::texture::CHECKERBOARD_EVALS;
    use glam::Vec2;
    use std::path::Path;

    /// A camera looking at a large two-sided plane whose BSDF has two
    /// textures: a checkerboard blend weight of a roughconductor with a
    /// checkerboard roughness and a diffuse; lit by the environment.
    const SCENE: &str = r#"<scene version="3.0.0">
        INTEGRATOR
        <sensor type="perspective">
            <float name="fov" value="30"/>
            <transform name="to_world">
                <lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/>
            </transform>
            <film type="hdrfilm">
                <integer name="width" value="4"/>
                <integer name="height" value="4"/>
            </film>
        </sensor>
        <shape type="rectangle" id="plane">
            <transform name="to_world"><scale value="10"/></transform>
            <bsdf type="twosided">
                <bsdf type="blendbsdf">
                    <texture type="checkerboard" name="weight"/>
                    <bsdf type="roughconductor">
                        <texture type="checkerboard" name="alpha"/>
                    </bsdf>
                    <bsdf type="diffuse"/>
                </bsdf>
            </bsdf>
        </shape>
        <emitter type="constant"/>
    </scene>"#;

    /// The integrators read each texture of a vertex's BSDF once, however
    /// often they sample, evaluate and re-evaluate the BSDF there: with one
    /// scattering vertex per path (every camera ray hits the plane), the
    /// checkerboards are evaluated twice per path, in the primal and along
    /// moving geometry (where `scatter` re-evaluates the BSDF).
    #[test]
    fn bsdf_textures_are_read_once_per_vertex() {
        let integrators = [
            r#"<integrator type="path"><integer name="max_depth" value="2"/></integrator>"#,
            r#"<integrator type="direct">
                <integer name="emitter_samples" value="3"/>
                <integer name="bsdf_samples" value="3"/>
            </integrator>"#,
        ];
        for integrator in integrators {
            let xml = SCENE.replace("INTEGRATOR", integrator);
            let scene = Scene::load_str(&xml, Path::new("test.xml"), &[]).unwrap();
            let sensor = &scene.sensors[0];
            let paths = 64;
            // a geometry tangent: the paths move
            let key = "plane.to_world";
            let t = [1.0f32; 16];
            let seeds = Seeds::tangents(&scene.params, &[(key, &t)]).unwrap();
            for geometry_moves in [false, true] {
                let before = CHECKERBOARD_EVALS.with(|n| n.get());
                for k in 0..paths {
                    let cs = CameraSample {
                        sensor,
                        film: Vec2::new((k % 8) as f32 + 0.5, (k / 8) as f32 + 0.5) / 8.0,
                        lens: Vec2::ZERO,
                    };
                    let mut rng = sensor.sampler.stream(1, k, 0, 1);
                    if geometry_moves {
                        let store = scene.params.view(&seeds);
                        assert!(store.moves_geometry());
                        scene
                            .integrator
                            .radiance::<Dual>(&scene, &store, &cs, &mut rng);
                    } else {
                        scene.integrator.radiance::<f32>(
                            &scene,
                            &scene.params.primal(),
                            &cs,
                            &mut rng,
                        );
                    }
                }
                let evals = CHECKERBOARD_EVALS.with(|n| n.get()) - before;
                assert_eq!(
                    evals,
                    2 * paths as usize,
                    "{integrator}, geometry moves: {geometry_moves}"
                );
            }
        }
    }

    /// Russian roulette starts where the Mitsuba plugin the scene names
    /// starts it: `path` counts the first vertex (0 here) as depth 1,
    /// `prb` and `prb_projective` as 0, `prb_basic` plays none; a scene
    /// without an integrator gets `path`'s; `volpath` and `prbvolpath`
    /// once the scattering events exceed `rr_depth`.
    #[test]
    fn roulette_starts_where_mitsubas_plugin_starts_it() {
        let cases = [
            ("path", 5, 4),
            ("path", 1, 0),
            ("prb", 5, 5),
            ("prb_projective", 3, 3),
            ("prb_basic", 5, u32::MAX),
        ];
        for (plugin, rr_depth, from) in cases {
            let integrator = format!(
                r#"<integrator type="{plugin}"><integer name="rr_depth" value="{rr_depth}"/></integrator>"#
            );
            let xml = SCENE.replace("INTEGRATOR", &integrator);
            let scene = Scene::load_str(&xml, Path::new("test.xml"), &[]).unwrap();
            let Integrator::Path(p) = &scene.integrator else {
                panic!("{plugin}: a path tracer");
            };
            assert_eq!((p.rr_depth, p.roulette_from), (rr_depth, from), "{plugin}");
        }
        let scene = Scene::load_str(&SCENE.replace("INTEGRATOR", ""), Path::new("t.xml"), &[]);
        let Integrator::Path(p) = &scene.unwrap().integrator else {
            panic!("the default integrator is a path tracer");
        };
        assert_eq!((p.max_depth, p.rr_depth, p.roulette_from), (u32::MAX, 5, 4));
        for plugin in ["volpath", "prbvolpath"] {
            let integrator = format!(
                r#"<integrator type="{plugin}"><integer name="rr_depth" value="3"/></integrator>"#
            );
            let xml = SCENE.replace("INTEGRATOR", &integrator);
            let scene = Scene::load_str(&xml, Path::new("test.xml"), &[]).unwrap();
            let Integrator::VolPath(v) = &scene.integrator else {
                panic!("{plugin}: a volumetric path tracer");
            };
            assert_eq!(v.roulette_from(), 4, "{plugin}");
        }
    }
}
