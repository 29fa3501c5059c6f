//! Optimisation jobs described in TOML (`penumbra optimize JOB.toml`):
//! the scene, the targets (images, or renders of the scene as loaded), the
//! parameters with their initial values and learning rates, the loss, the
//! optimiser, the iterations and samples per pixel. A job writes, in its
//! output folder: the target image(s) (`target.exr`, `target.png`; with
//! several views `target_<v>.*`), the final render beside them
//! (`final.exr`, `final.png`, with the target's samples per pixel),
//! progress images (`iter_<i>.png`), the final parameters (`params.txt`,
//! EXR for textures), the loss per iteration (`loss.csv`) and a plot of it
//! (`loss.png`: raw values faint, their trend bold, log scale; a
//! second panel with the parameter error when the truth is known).
//!
//! ```toml
//! scene = "../scenes/cbox.xml"       # relative to the job file
//! defines = { res = "128" }
//! output = "out/cbox-walls"          # optional, relative to the job file;
//!                                    # default out/optimize/<job name>/
//! iterations = 60
//! spp = 16
//! loss = "l2"                        # l1 | l2 | rel_l2
//! optimizer = { method = "adam" }    # or { method = "sgd", momentum = 0.9 }
//! target = { render_spp = 256 }      # or { images = ["target.exr"] }
//!
//! [[param]]
//! key = "red.reflectance.value"
//! init = [0.4, 0.4, 0.4]             # a list, or one number for all elements
//! lr = 0.02
//!
//! [[view]]                           # optional: extra camera poses
//! origin = [0, 1, 3]
//! target = [0, 0, 0]
//! up = [0, 1, 0]
//! ```

use super::{Loss, Method, Optimizer};
use crate::diff::render_backward;
use crate::error::{Error, Result};
use crate::image::plot::{plot_curve, stack};
use crate::image::{read_image, write_exr, write_png, Image};
use crate::integrator::{render, RenderOptions};
use crate::math::Transform;
use crate::scene::Scene;
use glam::Vec3;
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
    #[serde(default = "default_loss")]
    pub loss: String,
    #[serde(default)]
    pub optimizer: OptimizerSpec,
    pub target: TargetSpec,
    #[serde(rename = "param")]
    pub params: Vec<ParamSpec>,
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
        if spec.params.is_empty() {
            return Err(Error::file(path, "the job names no [[param]] to optimise"));
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

        // initial values
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
        scene.update()?;

        let keys: Vec<&str> = spec.params.iter().map(|p| p.key.as_str()).collect();
        let mut opt = Optimizer::new(
            method,
            spec.params.iter().map(|p| (p.key.clone(), p.lr)).collect(),
        )?;
        let mut losses = Vec::with_capacity(spec.iterations as usize);
        let mut error_curve = Vec::new();
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
            scene.update()?;
            losses.push(total);
            if known_truth {
                error_curve.push(mean_error(&scene.params)?);
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
        let csv: String = losses
            .iter()
            .enumerate()
            .map(|(i, l)| match error_curve.get(i) {
                Some(e) => format!("{i},{l:e},{e:e}\n"),
                None => format!("{i},{l:e},\n"),
            })
            .collect();
        std::fs::write(
            out.join("loss.csv"),
            format!("iteration,loss,mean_abs_param_error\n{csv}"),
        )
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
        std::fs::write(out.join("params.txt"), &summary)
            .map_err(|e| Error::file(out.join("params.txt"), e))?;
        Ok(JobResult {
            losses,
            param_error_curve: error_curve,
            param_errors,
            output: out,
        })
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
