//! Optimisation jobs described in TOML (`penumbra optimize JOB.toml`):
//! the scene, the targets (images, or renders of the scene as loaded), the
//! parameters with their initial values and learning rates, the loss, the
//! optimiser, the iterations and samples per pixel. A job writes, in its
//! output folder: the target image(s) (`target.exr`, `target.png`; with
//! several views `target_<v>.*`), the final render beside them
//! (`final.exr`, `final.png`, with the target's samples per pixel),
//! progress images (`iter_<i>.png`), the final parameters and poses
//! (`params.txt`, EXR for textures), the loss per iteration (`loss.csv`,
//! with the parameter and pose errors when the truth is known) and a plot
//! of it (`loss.png`: raw values faint, their trend bold, log scale; more
//! panels with the parameter error and the pose's translation and rotation
//! errors when the truth is known).
//!
//! ```toml
//! scene = "../scenes/cbox.xml"       # relative to the job file
//! defines = { res = "128" }
//! output = "out/cbox-walls"          # optional, relative to the job file;
//!                                    # default out/optimize/<job name>/
//! iterations = 60
//! spp = 16
//! sppp = 16                          # optional: edge samples per pixel of
//!                                    # the primary-visibility boundary
//!                                    # term (default: the integrator's)
//! sppi = 16                          # optional: samples per pixel of the
//!                                    # shadow boundary term (default:
//!                                    # the integrator's)
//! loss = "l2"                        # l1 | l2 | rel_l2
//! optimizer = { method = "adam" }    # or { method = "sgd", momentum = 0.9 }
//! target = { render_spp = 256 }      # or { images = ["target.exr"] }
//!
//! [[param]]
//! key = "red.reflectance.value"
//! init = [0.4, 0.4, 0.4]             # a list, or one number for all elements
//! lr = 0.02
//!
//! [[pose]]                           # optional: a rigid motion of a mesh
//! key = "bunny.vertex_positions"     # or a [4, 4] "<id>.to_world"
//! pivot = [0, 0, 0]                  # optional; default: the vertices'
//!                                    # centroid, or the transform's origin
//! init_translation = [0.1, 0, 0]     # optional start, world units
//! init_rotation_deg = [0, 5, 0]      # optional start: rotation vector,
//!                                    # degrees (axis × angle)
//! lr_translation = 0.01              # Adam step ≈ lr per iteration
//! lr_rotation_deg = 0.5              # in degrees
//!
//! [[view]]                           # optional: extra camera poses
//! origin = [0, 1, 3]
//! target = [0, 0, 0]
//! up = [0, 1, 0]
//! ```
//!
//! A job optimises `[[param]]` values directly and `[[pose]]`s through
//! their latent translation and rotation ([`super::pose`]): `init` and
//! `init_translation` / `init_rotation_deg` are where the optimisation
//! starts, and the scene as loaded is the truth (the zero pose), against
//! which errors are reported when the targets are rendered from it.
//! A mesh's vertex normals turn with its positions. A `[[pose]]` of a
//! sensor's `to_world` moves the camera (`scenes/jobs/pose_camera.toml`).
//! The gradients are reverse mode's: the interior term and, when the
//! parameters move geometry or the camera, the boundary term of primary
//! visibility (`sppp`); the boundary terms of shadows and of edges seen
//! after a bounce are missing (see
//! [`crate::diff::missing_indirect_boundary_terms_message`]).

use super::pose::{rotation_matrix, PoseGrad, PosedParam};
use super::{Loss, Method, Optimizer};
use crate::diff::{render_backward, GradEntry, Gradients};
use crate::error::{Error, Result};
use crate::image::plot::{plot_curve, stack};
use crate::image::{read_image, write_exr, write_png, Image};
use crate::integrator::{render, RenderOptions};
use crate::math::Transform;
use crate::params::{Domain, ParamFlags, ParamStore};
use crate::scene::Scene;
use glam::{DVec3, Vec3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobFile {
    pub scene: PathBuf,
    #[serde(default)]
    pub defines: BTreeMap<String, String>,
    pub output: Option<PathBuf>,
    pub iterations: u32,
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Edge samples per pixel of the boundary term of primary visibility
    /// in the gradient passes ([`RenderOptions::sppp`]; default: the
    /// integrator's `sppp`, else `spp`).
    pub sppp: Option<u32>,
    /// Samples per pixel of the boundary term of the visibility seen from
    /// the first vertex, shadows ([`RenderOptions::sppi`]; default: the
    /// integrator's `sppi`, else `spp`).
    pub sppi: Option<u32>,
    #[serde(default = "default_loss")]
    pub loss: String,
    #[serde(default)]
    pub optimizer: OptimizerSpec,
    pub target: TargetSpec,
    #[serde(default, rename = "param")]
    pub params: Vec<ParamSpec>,
    #[serde(default, rename = "pose")]
    pub poses: Vec<PoseSpec>,
    #[serde(default, rename = "view")]
    pub views: Vec<ViewSpec>,
    #[serde(default)]
    pub seed: u64,
    /// Write a progress image every this many iterations.
    #[serde(default = "default_save_every")]
    pub save_every: u32,
}

fn default_spp() -> u32 {
    16
}
fn default_loss() -> String {
    "l2".into()
}
fn default_save_every() -> u32 {
    10
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizerSpec {
    #[serde(default = "default_method")]
    pub method: String,
    #[serde(default)]
    pub momentum: f32,
}

fn default_method() -> String {
    "adam".into()
}

impl Default for OptimizerSpec {
    fn default() -> Self {
        OptimizerSpec {
            method: default_method(),
            momentum: 0.0,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// One target image per view (EXR), relative to the job file.
    #[serde(default)]
    pub images: Vec<PathBuf>,
    /// Or: render the targets from the scene as loaded (before the initial
    /// values are applied), with this many samples per pixel.
    pub render_spp: Option<u32>,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum InitValue {
    Scalar(f32),
    List(Vec<f32>),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamSpec {
    pub key: String,
    pub init: Option<InitValue>,
    pub lr: f32,
}

/// A `[[pose]]`: a latent translation and rotation of `key`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    pub key: String,
    pub pivot: Option<[f32; 3]>,
    #[serde(default)]
    pub init_translation: [f32; 3],
    /// Rotation vector (axis × angle) in degrees, as Mitsuba's `<rotate>`.
    #[serde(default)]
    pub init_rotation_deg: [f32; 3],
    pub lr_translation: f32,
    pub lr_rotation_deg: f32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewSpec {
    pub origin: [f32; 3],
    pub target: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

/// What a finished job reports.
#[derive(Clone, Debug)]
pub struct JobResult {
    /// Loss per iteration (mean over views).
    pub losses: Vec<f64>,
    /// Mean absolute error of all optimised elements per iteration, against
    /// the values the scene was loaded with (when the targets were rendered
    /// from it).
    pub param_error_curve: Vec<f64>,
    /// Per parameter: (mean, max) absolute error against the values the
    /// scene was loaded with, when the targets were rendered from it.
    pub param_errors: Vec<(String, f64, f64)>,
    /// Per iteration: the translation error |t − t_true| and the rotation
    /// error (angle of R·R_trueᵀ, degrees), averaged over the poses, when
    /// the targets were rendered from the scene.
    pub pose_error_curve: Vec<(f64, f64)>,
    /// Per pose: (key, translation error, rotation error in degrees) at
    /// the end, when the targets were rendered from the scene.
    pub pose_errors: Vec<(String, f64, f64)>,
    pub output: PathBuf,
}

/// A loaded job, ready to run.
pub struct Job {
    pub spec: JobFile,
    pub scene: Scene,
    /// Where the results go: the job's `output` (relative to the job
    /// file), or `out/optimize/<job file name>/` (relative to the working
    /// directory, like the other commands' outputs). May be replaced
    /// before [`Job::run`] (the CLI's `-o`).
    pub output: PathBuf,
    dir: PathBuf,
}

/// Samples per pixel of the final render when the targets are images (a
/// rendered target sets its own).
const FINAL_SPP: u32 = 256;

impl Job {
    /// Reads a job file and loads its scene.
    pub fn load(path: &Path) -> Result<Job> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
        let spec: JobFile = toml::from_str(&text).map_err(|e| Error::file(path, e))?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let defines: Vec<(String, String)> = spec
            .defines
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        let mut scene = Scene::load_file(&dir.join(&spec.scene), &defines)?;
        if !spec.views.is_empty() {
            let base = scene.sensor(0)?.clone();
            scene.sensors = spec
                .views
                .iter()
                .map(|v| {
                    Transform::look_at(Vec3::from(v.origin), Vec3::from(v.target), Vec3::from(v.up))
                        .map(|t| base.with_to_world(t))
                        .ok_or_else(|| {
                            Error::file(path, format!("view at {:?}: degenerate look-at", v.origin))
                        })
                })
                .collect::<Result<_>>()?;
        }
        if spec.params.is_empty() && spec.poses.is_empty() {
            return Err(Error::file(
                path,
                "the job names no [[param]] or [[pose]] to optimise",
            ));
        }
        if spec.iterations == 0 || spec.spp == 0 {
            return Err(Error::file(path, "iterations and spp must be at least 1"));
        }
        let output = match &spec.output {
            Some(o) => dir.join(o),
            None => {
                let name = path.file_stem().unwrap_or_default();
                Path::new("out").join("optimize").join(name)
            }
        };
        Ok(Job {
            spec,
            scene,
            output,
            dir,
        })
    }

    /// Runs the job; `progress(iteration, loss)` is called after each step.
    pub fn run(&mut self, mut progress: impl FnMut(u32, f64)) -> Result<JobResult> {
        let spec = &self.spec;
        let out = self.output.clone();
        std::fs::create_dir_all(&out).map_err(|e| Error::file(&out, e))?;
        let loss = Loss::parse(&spec.loss)?;
        let method = match spec.optimizer.method.as_str() {
            "adam" => Method::Adam {
                beta1: 0.9,
                beta2: 0.999,
                epsilon: 1e-8,
            },
            "sgd" => Method::Sgd {
                momentum: spec.optimizer.momentum,
            },
            m => {
                return Err(Error::Invalid(format!(
                    "unknown optimizer '{m}' (adam or sgd)"
                )))
            }
        };
        let scene = &mut self.scene;
        let n_views = scene.sensors.len();
        // `<name>.exr` and `<name>.png` for one view, `<name>_<v>.*` for several
        let write_view = |name: &str, v: usize, img: &Image| -> Result<()> {
            let stem = if n_views == 1 {
                name.to_string()
            } else {
                format!("{name}_{v}")
            };
            write_exr(&out.join(format!("{stem}.exr")), img, &["R", "G", "B"])?;
            write_png(&out.join(format!("{stem}.png")), img)
        };

        // targets
        let truth: Vec<Vec<f32>> = spec
            .params
            .iter()
            .map(|p| {
                scene
                    .params
                    .require(&p.key)
                    .map(|id| scene.params.data(id).to_vec())
            })
            .collect::<Result<_>>()?;
        let targets: Vec<Vec<f32>> = if let Some(tspp) = spec.target.render_spp {
            (0..n_views)
                .map(|v| {
                    let img = render(
                        scene,
                        &RenderOptions {
                            spp: Some(tspp),
                            seed: 1 << 40,
                            sensor: v,
                            ..Default::default()
                        },
                    )?;
                    write_view("target", v, &to_image(&img.data, img.width, img.height))?;
                    Ok(img.data)
                })
                .collect::<Result<_>>()?
        } else {
            if spec.target.images.len() != n_views {
                return Err(Error::Invalid(format!(
                    "the job has {n_views} view(s) but {} target image(s)",
                    spec.target.images.len()
                )));
            }
            spec.target
                .images
                .iter()
                .enumerate()
                .map(|(v, p)| {
                    let path = self.dir.join(p);
                    let img = read_image(&path)?;
                    if img.channels < 3 {
                        return Err(Error::file(
                            &path,
                            format!(
                                "a target image needs R, G, B; it has {} channel(s)",
                                img.channels
                            ),
                        ));
                    }
                    let img = img.take_channels(3);
                    write_view("target", v, &img)?;
                    Ok(img.data)
                })
                .collect::<Result<_>>()?
        };

        // initial values; the poses bind to the scene as loaded (the truth)
        let mut poses = Poses::new(&spec.poses, &spec.params, &scene.params)?;
        for p in &spec.params {
            let id = scene.params.require(&p.key)?;
            let n = scene.params.data(id).len();
            let init = match &p.init {
                None => continue,
                Some(InitValue::Scalar(v)) => vec![*v; n],
                Some(InitValue::List(v)) if v.len() == n => v.clone(),
                Some(InitValue::List(v)) => {
                    return Err(Error::Param {
                        key: p.key.clone(),
                        msg: format!("init has {} values, the parameter {n}", v.len()),
                    })
                }
            };
            scene.params.set(&p.key, &init)?;
        }
        poses.apply(&mut scene.params)?;
        scene.update()?;

        let pose_keys: Vec<String> = poses.scene_keys().map(String::from).collect();
        let keys: Vec<&str> = spec
            .params
            .iter()
            .map(|p| p.key.as_str())
            .chain(pose_keys.iter().map(String::as_str))
            .collect();
        let mut opt = Optimizer::new(
            method,
            spec.params.iter().map(|p| (p.key.clone(), p.lr)).collect(),
        )?;
        let mut pose_opt = Optimizer::new(method, poses.learning_rates.clone())?;
        let mut losses = Vec::with_capacity(spec.iterations as usize);
        let mut error_curve = Vec::new();
        let mut pose_curve = Vec::new();
        let known_truth = spec.target.render_spp.is_some();
        let mean_error = |store: &crate::params::ParamStore| -> Result<f64> {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for (p, t) in spec.params.iter().zip(&truth) {
                let d = store.data(store.require(&p.key)?);
                sum += d
                    .iter()
                    .zip(t)
                    .map(|(a, b)| (a - b).abs() as f64)
                    .sum::<f64>();
                n += d.len();
            }
            Ok(sum / n as f64)
        };
        for it in 0..spec.iterations {
            let mut total = 0.0;
            let mut grads: Option<crate::diff::Gradients> = None;
            for (v, target) in targets.iter().enumerate() {
                let ro = RenderOptions {
                    spp: Some(spec.spp),
                    seed: spec.seed + (it as u64) * 1000 + v as u64,
                    sensor: v,
                    ..Default::default()
                };
                let img = render(scene, &ro)?;
                let (l, d_img) = loss.eval(&img.data, target)?;
                total += l / n_views as f64;
                // replay with a decorrelated seed (as Mitsuba's seed_grad):
                // reusing the primal's samples biases E[∂loss/∂θ] by the
                // covariance of the image noise and its derivative
                let ro_grad = RenderOptions {
                    seed: crate::diff::gradient_seed(ro.seed),
                    sppp: spec.sppp,
                    sppi: spec.sppi,
                    ..ro.clone()
                };
                let g = render_backward(scene, &d_img, Some(&keys), &ro_grad)?;
                grads = Some(match grads {
                    None => g,
                    Some(mut acc) => {
                        for (a, b) in acc.entries.iter_mut().zip(&g.entries) {
                            a.data.iter_mut().zip(&b.data).for_each(|(a, b)| *a += b);
                        }
                        acc
                    }
                });
                if v == 0 && (it % spec.save_every == 0 || it + 1 == spec.iterations) {
                    let im = to_image(&img.data, img.width, img.height);
                    write_png(&out.join(format!("iter_{it:04}.png")), &im)?;
                }
            }
            let mut g = grads.expect("a job has at least one view");
            for e in &mut g.entries {
                e.data.iter_mut().for_each(|x| *x /= n_views as f32);
            }
            opt.step(&mut scene.params, &g)?;
            if !poses.bound.is_empty() {
                let latent_grads = poses.gradients(&g)?;
                pose_opt.step(&mut poses.latents, &latent_grads)?;
                poses.apply(&mut scene.params)?;
            }
            scene.update()?;
            losses.push(total);
            if known_truth && !spec.params.is_empty() {
                error_curve.push(mean_error(&scene.params)?);
            }
            if known_truth && !poses.bound.is_empty() {
                let errs = poses.errors();
                let n = errs.len() as f64;
                pose_curve.push((
                    errs.iter().map(|e| e.0).sum::<f64>() / n,
                    errs.iter().map(|e| e.1).sum::<f64>() / n,
                ));
            }
            progress(it, total);
        }

        // results: the final render beside each target
        for v in 0..n_views {
            let img = render(
                scene,
                &RenderOptions {
                    spp: Some(spec.target.render_spp.unwrap_or(FINAL_SPP)),
                    seed: (1 << 40) + 1,
                    sensor: v,
                    ..Default::default()
                },
            )?;
            write_view("final", v, &to_image(&img.data, img.width, img.height))?;
        }
        let mut header = "iteration,loss,mean_abs_param_error".to_string();
        if !poses.bound.is_empty() {
            header += ",translation_error,rotation_error_deg";
        }
        let csv: String = losses
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let mut row = match error_curve.get(i) {
                    Some(e) => format!("{i},{l:e},{e:e}"),
                    None => format!("{i},{l:e},"),
                };
                if !poses.bound.is_empty() {
                    row += &match pose_curve.get(i) {
                        Some((t, r)) => format!(",{t:e},{r:e}"),
                        None => ",,".into(),
                    };
                }
                row + "\n"
            })
            .collect();
        std::fs::write(out.join("loss.csv"), format!("{header}\n{csv}"))
            .map_err(|e| Error::file(out.join("loss.csv"), e))?;
        let mut panels = vec![plot_curve(
            &losses,
            640,
            400,
            &format!("loss ({}, {} spp per step)", spec.loss, spec.spp),
            true,
        )];
        if !error_curve.is_empty() {
            panels.push(plot_curve(
                &error_curve,
                640,
                400,
                "mean |param - truth|",
                false,
            ));
        }
        if !pose_curve.is_empty() {
            let (t, r): (Vec<f64>, Vec<f64>) = pose_curve.iter().cloned().unzip();
            panels.push(plot_curve(
                &t,
                640,
                400,
                "pose |translation - truth|",
                false,
            ));
            panels.push(plot_curve(
                &r,
                640,
                400,
                "pose rotation error (degrees)",
                false,
            ));
        }
        write_png(&out.join("loss.png"), &stack(&panels))?;
        let mut summary = String::new();
        let mut param_errors = Vec::new();
        for (p, t) in spec.params.iter().zip(&truth) {
            let id = scene.params.require(&p.key)?;
            let param = scene.params.get(id);
            if param.shape.len() == 3 {
                let (h, w, c) = (param.shape[0], param.shape[1], param.shape[2]);
                let names: &[&str] = if c == 1 { &["Y"] } else { &["R", "G", "B"] };
                let img = Image {
                    width: w,
                    height: h,
                    channels: c,
                    data: param.data.clone(),
                };
                write_exr(
                    &out.join(format!("{}.exr", p.key)),
                    &img,
                    &names[..c.min(3)],
                )?;
            }
            let err = if spec.target.render_spp.is_some() {
                let errs: Vec<f64> = param
                    .data
                    .iter()
                    .zip(t)
                    .map(|(a, b)| (a - b).abs() as f64)
                    .collect();
                let mean = errs.iter().sum::<f64>() / errs.len() as f64;
                let max = errs.iter().cloned().fold(0.0, f64::max);
                param_errors.push((p.key.clone(), mean, max));
                format!(" (|error| vs the scene's value: mean {mean:.4}, max {max:.4})")
            } else {
                String::new()
            };
            let shown: Vec<String> = param
                .data
                .iter()
                .take(8)
                .map(|v| format!("{v:.4}"))
                .collect();
            summary += &format!(
                "{} = [{}{}]{err}\n",
                p.key,
                shown.join(", "),
                if param.data.len() > 8 { ", …" } else { "" }
            );
        }
        let mut pose_errors = Vec::new();
        for (i, b) in poses.bound.iter().enumerate() {
            let (t, r) = poses.latent(i);
            let err = if known_truth {
                let (et, er) = poses.errors()[i];
                pose_errors.push((b.key.clone(), et, er));
                format!(" (error vs the scene's pose: |translation| {et:.4}, rotation {er:.3}°)")
            } else {
                String::new()
            };
            let deg = r / DEG;
            summary += &format!(
                "{} pose: translation = [{:.4}, {:.4}, {:.4}], rotation_deg = [{:.3}, {:.3}, \
                 {:.3}], pivot = [{:.4}, {:.4}, {:.4}]{err}\n",
                b.key, t.x, t.y, t.z, deg.x, deg.y, deg.z, b.pivot.x, b.pivot.y, b.pivot.z
            );
        }
        std::fs::write(out.join("params.txt"), &summary)
            .map_err(|e| Error::file(out.join("params.txt"), e))?;
        Ok(JobResult {
            losses,
            param_error_curve: error_curve,
            param_errors,
            pose_error_curve: pose_curve,
            pose_errors,
            output: out,
        })
    }
}

const DEG: f64 = std::f64::consts::PI / 180.0;

/// The job's `[[pose]]`s bound to the scene, with their latents in a store
/// of their own (`<key>.pose.translation`, `<key>.pose.rotation_deg`) so
/// that an [`Optimizer`] steps them like parameters; the rotation latent
/// is in degrees so that `lr_rotation_deg` is the step in degrees.
struct Poses {
    bound: Vec<PosedParam>,
    latents: ParamStore,
    learning_rates: Vec<(String, f32)>,
}

fn latent_keys(key: &str) -> [String; 2] {
    [
        format!("{key}.pose.translation"),
        format!("{key}.pose.rotation_deg"),
    ]
}

impl Poses {
    fn new(specs: &[PoseSpec], params: &[ParamSpec], store: &ParamStore) -> Result<Poses> {
        let mut poses = Poses {
            bound: Vec::new(),
            latents: ParamStore::new(),
            learning_rates: Vec::new(),
        };
        let mut taken: Vec<String> = params.iter().map(|p| p.key.clone()).collect();
        for s in specs {
            let b = PosedParam::new(store, &s.key, s.pivot.map(|p| Vec3::from(p).as_dvec3()))?;
            for k in b.keys() {
                if taken.iter().any(|t| t == k) {
                    return Err(Error::Param {
                        key: s.key.clone(),
                        msg: format!(
                            "this [[pose]] writes '{k}', which another [[param]] or [[pose]] \
                             of the job optimises too"
                        ),
                    });
                }
            }
            taken.extend(b.keys().into_iter().map(String::from));
            let [kt, kr] = latent_keys(&s.key);
            let init = [
                (kt, s.init_translation, s.lr_translation),
                (kr, s.init_rotation_deg, s.lr_rotation_deg),
            ];
            for (k, v, lr) in init {
                let bad = v.iter().find(|x| !x.is_finite());
                if let Some(x) = bad {
                    return Err(Error::Param {
                        key: s.key.clone(),
                        msg: format!("the initial pose must be finite, found {x}"),
                    });
                }
                poses.latents.add(
                    k.clone(),
                    v.to_vec(),
                    vec![3],
                    ParamFlags::DIFFERENTIABLE,
                    Domain::Finite,
                )?;
                poses.learning_rates.push((k, lr));
            }
            poses.bound.push(b);
        }
        Ok(poses)
    }

    /// Translation and rotation vector (radians) of pose `i`.
    fn latent(&self, i: usize) -> (DVec3, DVec3) {
        let [kt, kr] = latent_keys(&self.bound[i].key);
        let get = |k: &str| {
            let d = self
                .latents
                .data(self.latents.id(k).expect("registered in new"));
            Vec3::from_slice(d).as_dvec3()
        };
        (get(&kt), get(&kr) * DEG)
    }

    /// The scene parameters the poses write, whose gradients they need.
    fn scene_keys(&self) -> impl Iterator<Item = &str> {
        self.bound.iter().flat_map(|b| b.keys())
    }

    /// Writes the posed values into the scene's store.
    fn apply(&self, store: &mut ParamStore) -> Result<()> {
        for (i, b) in self.bound.iter().enumerate() {
            let (t, r) = self.latent(i);
            b.apply(store, t, r)?;
        }
        Ok(())
    }

    /// The latents' gradients from the scene parameters' `grads`.
    fn gradients(&self, grads: &Gradients) -> Result<Gradients> {
        let mut entries = Vec::new();
        for (i, b) in self.bound.iter().enumerate() {
            let (t, r) = self.latent(i);
            let g: PoseGrad = b.backprop(grads, t, r)?;
            let [kt, kr] = latent_keys(&b.key);
            // the rotation latent is in degrees: ∂L/∂deg = ∂L/∂rad · π/180
            for (key, v) in [(kt, g.translation), (kr, g.rotation * DEG)] {
                entries.push(GradEntry {
                    key,
                    shape: vec![3],
                    data: v.as_vec3().to_array().to_vec(),
                });
            }
        }
        Ok(Gradients {
            entries,
            ..Default::default()
        })
    }

    /// Per pose: |translation| and the rotation angle in degrees, i.e. the
    /// errors against the scene as loaded (the zero pose).
    fn errors(&self) -> Vec<(f64, f64)> {
        (0..self.bound.len())
            .map(|i| {
                let (t, r) = self.latent(i);
                let m = rotation_matrix(r);
                let cos = (m.x_axis.x + m.y_axis.y + m.z_axis.z - 1.0) / 2.0;
                (t.length(), cos.clamp(-1.0, 1.0).acos() / DEG)
            })
            .collect()
    }
}

fn to_image(data: &[f32], width: usize, height: usize) -> Image {
    Image {
        width,
        height,
        channels: 3,
        data: data.to_vec(),
    }
}
