//! `penumbra`: render Mitsuba 3 scenes from the command line.

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use penumbra::diff::{
    check_gradient, gradient_seed, perturbation_tangent, render_backward, render_forward,
    translation_tangent, CheckOptions, Estimate,
};
use penumbra::image::plot::{median, trend};
use penumbra::image::{write_exr, write_png, Image};
use penumbra::integrator::{render, ProgressFn, RenderOptions};
use penumbra::optim::{Job, Loss};
use penumbra::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(
    name = "penumbra",
    version,
    about = "A physics-based differentiable renderer"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// No progress bars or timing reports on stderr (for scripts).
    #[arg(short, long, global = true)]
    quiet: bool,
}

/// The scene and its `-D` overrides.
#[derive(Args)]
struct SceneArgs {
    /// The scene file (Mitsuba 3 XML).
    scene: PathBuf,
    /// Override a <default> of the scene: -D name=value (repeatable). A
    /// name the scene does not know is an error.
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    define: Vec<String>,
}

impl SceneArgs {
    fn load(&self) -> Result<Scene, String> {
        let defines = parse_defines(&self.define)?;
        Scene::load_file(&self.scene, &defines).map_err(|e| e.to_string())
    }
}

/// How renders run.
#[derive(Args)]
struct RunArgs {
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Render even if the film's buffers would need more memory than is
    /// available.
    #[arg(long)]
    force: bool,
}

/// `--spp`: at least 1 (the scene's sampler decides when it is not given).
fn spp_parser() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..)
}

/// `--sppp`, `--sppi`: samples per pixel of the boundary terms of primary
/// visibility and of the visibility seen from the first vertex (shadows),
/// 0 turning a term off (the integrator's `sppp` / `sppi`, else the pass's
/// samples per pixel, when not given).
#[derive(Args)]
struct BudgetArgs {
    /// Edge samples per pixel of the boundary term of primary visibility in
    /// the derivative passes; 0 turns the term off [default: the
    /// integrator's sppp, else the samples per pixel].
    // negative numbers are parsed as values, so that `--sppp -1` is refused
    // naming the option rather than taken for a flag
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    sppp: Option<u32>,
    /// Samples per pixel of the boundary term of the visibility seen from
    /// the first vertex (shadows) in the derivative passes; 0 turns the term
    /// off [default: the integrator's sppi, else the samples per pixel].
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    sppi: Option<u32>,
}

/// `--translate`: three comma-separated numbers.
fn vec3_parser(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("'{s}': {e}; expected three numbers like 0,0,1"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!("'{s}': expected three finite numbers like 0,0,1")),
    }
}

#[derive(Subcommand)]
enum Command {
    /// Render a Mitsuba 3 XML scene to an EXR (linear float32, all channels)
    /// or PNG (sRGB, 8-bit) image.
    Render {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output image: .exr or .png [default: out/render/<scene name>.exr].
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Samples per pixel (default: the scene's sampler).
        #[arg(long, value_parser = spp_parser())]
        spp: Option<u32>,
        /// Seed of the random numbers.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Derivatives of a render: a forward-mode derivative image along the
    /// parameters' own values (d image / d s for θ·s at s = 1) or along
    /// --translate, or reverse-mode gradients of an L2 loss against a target
    /// image (of the image sum without --target).
    Grad {
        #[command(flatten)]
        scene: SceneArgs,
        /// Parameter key (repeatable; `penumbra params SCENE` lists them).
        #[arg(long = "param", required = true)]
        params: Vec<String>,
        /// forward or reverse.
        #[arg(long, default_value = "reverse")]
        mode: String,
        /// Target image for the L2 loss (reverse mode).
        #[arg(long)]
        target: Option<PathBuf>,
        /// Set every element of the parameters to this value first.
        #[arg(long)]
        init: Option<f32>,
        /// Samples per pixel (default: the scene's sampler).
        #[arg(long, value_parser = spp_parser())]
        spp: Option<u32>,
        /// Seed of the image's random numbers.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Seed of the gradient pass (reverse mode) [default: derived from
        /// --seed by penumbra::diff::gradient_seed, decorrelated from it].
        #[arg(long)]
        seed_grad: Option<u64>,
        /// Forward mode: differentiate along a translation "x,y,z" instead of
        /// θ·s: moves every point of vertex positions or a sphere's centre,
        /// or the translation of a to_world (as check-grad --translate).
        #[arg(long, value_parser = vec3_parser)]
        translate: Option<[f32; 3]>,
        #[command(flatten)]
        budgets: BudgetArgs,
        /// Output folder (derivative image, gradient images of textures).
        #[arg(short, long, default_value = "out/grad")]
        output: PathBuf,
        /// Time this many more runs after the first and print a JSON line
        /// with timings and peak memory.
        #[arg(long)]
        reps: Option<usize>,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Check derivatives: finite differences (same random numbers) vs
    /// forward mode vs reverse mode, per parameter, over several batches.
    /// Prints a table and writes the derivative images.
    CheckGrad {
        #[command(flatten)]
        scene: SceneArgs,
        /// Parameter key (repeatable), e.g. red.reflectance.value.
        #[arg(long = "param", required = true)]
        params: Vec<String>,
        /// Samples per pixel of each batch.
        #[arg(long, default_value_t = 16, value_parser = spp_parser())]
        spp: u32,
        #[command(flatten)]
        budgets: BudgetArgs,
        /// Independent batches for the error bars.
        #[arg(long, default_value_t = 4)]
        batches: u32,
        /// Relative finite-difference step.
        #[arg(long, default_value_t = 1e-2)]
        eps: f32,
        /// Differentiate along a translation "x,y,z" instead of θ·(1+s):
        /// moves every point of vertex positions or a sphere's centre, or
        /// the translation of a to_world (shapes, the sensor: camera
        /// motion).
        #[arg(long, value_parser = vec3_parser, conflicts_with = "perturb")]
        translate: Option<[f32; 3]>,
        /// Differentiate along a random perturbation of every element
        /// (e.g. of every vertex), drawn from this seed.
        #[arg(long)]
        perturb: Option<u64>,
        /// Folder for the derivative images (EXR).
        #[arg(short, long, default_value = "out/check-grad")]
        output: PathBuf,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Run an inverse-rendering job described in a TOML file: writes the
    /// target and final images, progress images, the final parameters,
    /// loss.csv and a loss plot (loss.png).
    Optimize {
        job: PathBuf,
        /// Output folder (default: the job's `output`, else
        /// out/optimize/<job name>/).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Time renders of a scene in one process: the first render and the
    /// following (warm) ones, with peak memory; prints one JSON line.
    Bench {
        #[command(flatten)]
        scene: SceneArgs,
        /// Samples per pixel (default: the scene's sampler).
        #[arg(long, value_parser = spp_parser())]
        spp: Option<u32>,
        /// Warm renders after the first.
        #[arg(long, default_value_t = 3)]
        reps: usize,
        #[command(flatten)]
        run: RunArgs,
    },
    /// List the scene's parameters: key, shape, flags (differentiable,
    /// discontinuous, read-only), domain and a summary of the value.
    Params {
        #[command(flatten)]
        scene: SceneArgs,
    },
}

/// Splits `-D name=value` arguments.
fn parse_defines(defines: &[String]) -> Result<Vec<(String, String)>, String> {
    defines
        .iter()
        .map(|d| match d.split_once('=') {
            Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.to_string())),
            _ => Err(format!("-D expects name=value, got '{d}'")),
        })
        .collect()
}

/// A progress bar on stderr (none with --quiet); `{msg}` says what runs.
fn progress_bar(quiet: bool, len: u64) -> Option<ProgressBar> {
    if quiet {
        return None;
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg} [{elapsed_precise}] [{wide_bar}] {percent}% (ETA {eta})",
        )
        .expect("the progress template is valid")
        .progress_chars("=> "),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    Some(bar)
}

/// Reports a render's tiles on `bar` (the bar's length follows the tiles).
fn tile_progress(bar: &Option<ProgressBar>) -> Option<Arc<ProgressFn>> {
    bar.clone().map(|b| {
        Arc::new(move |done: usize, total: usize| {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }) as Arc<ProgressFn>
    })
}

/// Creates `dir` (and its parents).
fn create_dir(dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("{}: cannot create folder: {e}", dir.display()))
}

fn write_output(path: &Path, img: &Image, names: &[String]) -> penumbra::Result<()> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
    {
        Some(e) if e == "exr" => {
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            write_exr(path, img, &names)
        }
        Some(e) if e == "png" => {
            // PNG holds the colour channels only
            let c = img.channels;
            let rgb = Image {
                width: img.width,
                height: img.height,
                channels: 3,
                data: img
                    .data
                    .chunks_exact(c)
                    .flat_map(|px| [px[0], px[1.min(c - 1)], px[2.min(c - 1)]])
                    .collect(),
            };
            write_png(path, &rgb)
        }
        _ => Err(penumbra::Error::file(
            path,
            "unknown image format; use a .exr or .png file name",
        )),
    }
}

fn run(cli: Cli) -> Result<(), String> {
    let quiet = cli.quiet;
    let err = |e: penumbra::Error| e.to_string();
    match cli.command {
        Command::Render {
            scene: scene_args,
            output,
            spp,
            seed,
            run,
        } => {
            let output = match output {
                Some(o) => o,
                None => {
                    // the whole stem: "cbox.v2.xml" gives "cbox.v2.exr"
                    let stem = scene_args.scene.file_stem().unwrap_or("render".as_ref());
                    Path::new("out/render").join(format!("{}.exr", stem.to_string_lossy()))
                }
            };
            let t0 = Instant::now();
            let scene = scene_args.load()?;
            let t_load = t0.elapsed();
            if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
                create_dir(dir)?;
            }
            let bar = progress_bar(quiet, 1);
            if let Some(b) = &bar {
                b.set_message("rendering");
            }
            let opts = RenderOptions {
                spp,
                seed,
                threads: run.threads,
                force: run.force,
                progress: tile_progress(&bar),
                ..Default::default()
            };
            let t1 = Instant::now();
            let img = render(&scene, &opts).map_err(err)?;
            let t_render = t1.elapsed();
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            let image = Image {
                width: img.width,
                height: img.height,
                channels: img.channels(),
                data: img.data,
            };
            write_output(&output, &image, &img.channel_names).map_err(err)?;
            if !quiet {
                eprintln!(
                    "{}: {}x{}, {} spp, loaded in {:.2} s, rendered in {:.2} s",
                    output.display(),
                    image.width,
                    image.height,
                    scene.sensors[0].sampler.pass_count(spp),
                    t_load.as_secs_f64(),
                    t_render.as_secs_f64()
                );
            }
            Ok(())
        }
        Command::Grad {
            scene: scene_args,
            params,
            mode,
            target,
            init,
            spp,
            seed,
            seed_grad,
            translate,
            budgets,
            output,
            reps,
            run,
        } => {
            if mode != "forward" && mode != "reverse" {
                return Err(format!("--mode must be forward or reverse, not '{mode}'"));
            }
            if translate.is_some() && mode != "forward" {
                return Err(
                    "--translate gives the tangent of forward mode; add --mode forward".into(),
                );
            }
            let mut scene = scene_args.load()?;
            if let Some(v) = init {
                for key in &params {
                    let id = scene.params.require(key).map_err(err)?;
                    let n = scene.params.data(id).len();
                    scene.params.set(key, &vec![v; n]).map_err(err)?;
                }
                scene.update().map_err(err)?;
            }
            create_dir(&output)?;
            let keys: Vec<&str> = params.iter().map(String::as_str).collect();
            let target = target
                .map(|t| penumbra::image::read_image(&t))
                .transpose()
                .map_err(err)?;
            let runs = reps.unwrap_or(0) + 1;
            let bar = progress_bar(quiet, 1);
            let mut times = Vec::new();
            let mut report = Vec::new();
            for i in 0..runs {
                let opts = RenderOptions {
                    spp,
                    sppp: budgets.sppp,
                    sppi: budgets.sppi,
                    seed: seed + i as u64,
                    threads: run.threads,
                    force: run.force,
                    progress: tile_progress(&bar),
                    ..Default::default()
                };
                let step = |what: &str| {
                    if let Some(b) = &bar {
                        b.set_message(if runs > 1 {
                            format!("{what} (run {}/{runs})", i + 1)
                        } else {
                            what.to_string()
                        });
                    }
                };
                let t = Instant::now();
                if mode == "forward" {
                    let tangents: Vec<Vec<f32>> = keys
                        .iter()
                        .map(|k| match translate {
                            Some(t) => translation_tangent(&scene, k, t),
                            None => scene
                                .params
                                .require(k)
                                .map(|id| scene.params.data(id).to_vec()),
                        })
                        .collect::<Result<_, _>>()
                        .map_err(err)?;
                    let pairs: Vec<(&str, &[f32])> = keys
                        .iter()
                        .copied()
                        .zip(tangents.iter().map(Vec::as_slice))
                        .collect();
                    step("forward mode");
                    let d = render_forward(&scene, &pairs, &opts).map_err(err)?;
                    times.push(t.elapsed().as_secs_f64());
                    if i == 0 {
                        let img = Image {
                            width: d.width,
                            height: d.height,
                            channels: 3,
                            data: d.data,
                        };
                        write_exr(&output.join("dimage.exr"), &img, &["R", "G", "B"])
                            .map_err(err)?;
                    }
                    continue;
                }
                step("rendering");
                let img = render(&scene, &opts).map_err(err)?;
                let (loss, d_img) = match &target {
                    Some(t) => Loss::L2.eval(&img.data, &t.data).map_err(err)?,
                    None => (f64::NAN, vec![1.0; img.data.len()]),
                };
                let gopts = RenderOptions {
                    seed: seed_grad.unwrap_or_else(|| gradient_seed(opts.seed)),
                    ..opts.clone()
                };
                step("gradients");
                let g = render_backward(&scene, &d_img, Some(&keys), &gopts).map_err(err)?;
                times.push(t.elapsed().as_secs_f64());
                if i > 0 {
                    continue;
                }
                // printed once the bar is gone
                if target.is_some() {
                    report.push(format!("loss {loss:.6e}"));
                }
                for e in &g.entries {
                    let sum: f64 = e.data.iter().map(|&v| v as f64).sum();
                    let head: Vec<String> =
                        e.data.iter().take(6).map(|v| format!("{v:.5e}")).collect();
                    report.push(format!(
                        "d loss / d {} (shape {:?}): [{}{}], sum {sum:.6e}",
                        e.key,
                        e.shape,
                        head.join(", "),
                        if e.data.len() > 6 { ", …" } else { "" }
                    ));
                    if e.shape.len() == 3 && e.shape[2] <= 3 {
                        let img = Image {
                            width: e.shape[1],
                            height: e.shape[0],
                            channels: e.shape[2],
                            data: e.data.clone(),
                        };
                        let names: &[&str] = if e.shape[2] == 1 {
                            &["Y"]
                        } else {
                            &["R", "G", "B"]
                        };
                        write_exr(&output.join(format!("{}.exr", e.key)), &img, names)
                            .map_err(err)?;
                    }
                }
            }
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            for line in report {
                println!("{line}");
            }
            if reps.is_some() {
                let median = median(&times[1..]);
                println!(
                    "{{\"mode\": \"{mode}\", \"first_s\": {:.4}, \"warm_median_s\": {median:.4}, \"peak_rss_mb\": {:.1}}}",
                    times[0],
                    peak_rss_mb()
                );
            }
            if !quiet {
                eprintln!("images in {}", output.display());
            }
            Ok(())
        }
        Command::CheckGrad {
            scene: scene_args,
            params,
            spp,
            budgets,
            batches,
            eps,
            translate,
            perturb,
            output,
            run,
        } => {
            let mut scene = scene_args.load()?;
            create_dir(&output)?;
            let total = (params.len() * batches as usize) as u64;
            let bar = progress_bar(quiet, total);
            let direction = match (translate, perturb) {
                (Some(t), _) => format!("the translation ({}, {}, {})", t[0], t[1], t[2]),
                (None, Some(seed)) => format!("a random perturbation (seed {seed})"),
                (None, None) => "θ·(1+s)".to_string(),
            };
            println!(
                "d/ds Σ image along {direction}, {batches} batches × {spp} spp (mean ± standard error)"
            );
            println!(
                "{:<40} {:>24} {:>24} {:>24} {:>8} {:>8}",
                "parameter", "finite differences", "forward", "reverse", "z(f,fd)", "z(r,fd)"
            );
            let mut worst = 0.0f64;
            for (i, key) in params.iter().enumerate() {
                if let Some(b) = &bar {
                    b.set_message(format!("checking {key}"));
                }
                let tangent = match (translate, perturb) {
                    (Some(t), _) => Some(translation_tangent(&scene, key, t).map_err(err)?),
                    (None, Some(seed)) => {
                        Some(perturbation_tangent(&scene, key, seed).map_err(err)?)
                    }
                    (None, None) => None,
                };
                let opts = CheckOptions {
                    spp,
                    sppp: budgets.sppp,
                    sppi: budgets.sppi,
                    batches,
                    eps,
                    tangent,
                    threads: run.threads,
                    force: run.force,
                    progress: bar.clone().map(|b| {
                        let before = (i * batches as usize) as u64;
                        Arc::new(move |done: usize, _: usize| b.set_position(before + done as u64))
                            as Arc<ProgressFn>
                    }),
                };
                let r = check_gradient(&mut scene, key, &opts).map_err(err)?;
                let fmt = |e: &Estimate| format!("{:.5e} ± {:.1e}", e.mean, e.std_err);
                let (zf, zr) = (
                    r.forward.z_score(&r.finite_differences),
                    r.reverse.z_score(&r.finite_differences),
                );
                worst = worst.max(zf).max(zr);
                let line = format!(
                    "{:<40} {:>24} {:>24} {:>24} {:>8.2} {:>8.2}",
                    key,
                    fmt(&r.finite_differences),
                    fmt(&r.forward),
                    fmt(&r.reverse),
                    zf,
                    zr
                );
                match &bar {
                    Some(b) => b.suspend(|| println!("{line}")),
                    None => println!("{line}"),
                }
                for (name, img) in [("fd", &r.fd_image), ("forward", &r.forward_image)] {
                    let file = output.join(format!("{key}.{name}.exr"));
                    let image = Image {
                        width: img.width,
                        height: img.height,
                        channels: 3,
                        data: img.data.clone(),
                    };
                    write_exr(&file, &image, &["R", "G", "B"]).map_err(err)?;
                }
            }
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            println!(
                "derivative images in {}; largest z-score {worst:.2} ({})",
                output.display(),
                if worst < 4.0 {
                    "agree within noise"
                } else {
                    "DISAGREE beyond noise"
                }
            );
            if worst >= 4.0 {
                return Err("gradients disagree beyond their noise".into());
            }
            Ok(())
        }
        Command::Optimize { job, output } => {
            let mut job = Job::load(&job).map_err(err)?;
            if let Some(dir) = output {
                job.output = dir;
            }
            let n = job.spec.iterations as u64;
            let bar = (!quiet).then(|| {
                let b = ProgressBar::new(n);
                b.set_style(
                    ProgressStyle::with_template(
                        "{spinner} optimizing [{elapsed_precise}] [{wide_bar}] {pos}/{len} (ETA {eta}) {msg}",
                    )
                    .expect("the progress template is valid")
                    .progress_chars("=> "),
                );
                b
            });
            let result = job
                .run(|it, loss| {
                    if let Some(b) = &bar {
                        b.set_position(it as u64 + 1);
                        b.set_message(format!("loss {loss:.3e}"));
                    }
                })
                .map_err(err)?;
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            // the loss of one step is noisy: report its trend, as loss.png
            // draws it
            let t = trend(&result.losses);
            let first = t.first().copied().unwrap_or(f64::NAN);
            let last = t.last().copied().unwrap_or(f64::NAN);
            println!(
                "loss (trend) {first:.4e} -> {last:.4e} over {} iterations; results in {}",
                result.losses.len(),
                result.output.display()
            );
            for (key, mean, max) in &result.param_errors {
                println!("{key}: |error| vs the scene's value: mean {mean:.4}, max {max:.4}");
            }
            Ok(())
        }
        Command::Bench {
            scene: scene_args,
            spp,
            reps,
            run,
        } => {
            let t0 = Instant::now();
            let loaded = scene_args.load()?;
            let load_s = t0.elapsed().as_secs_f64();
            let bar = progress_bar(quiet, 1);
            let mut times = Vec::with_capacity(reps + 1);
            for i in 0..=reps {
                if let Some(b) = &bar {
                    b.set_message(format!("render {}/{}", i + 1, reps + 1));
                }
                let opts = RenderOptions {
                    spp,
                    seed: i as u64,
                    threads: run.threads,
                    force: run.force,
                    progress: tile_progress(&bar),
                    ..Default::default()
                };
                let t = Instant::now();
                let img = render(&loaded, &opts).map_err(err)?;
                times.push(t.elapsed().as_secs_f64());
                std::hint::black_box(img);
            }
            if let Some(b) = bar {
                b.finish_and_clear();
            }
            let median = median(&times[1..]);
            println!(
                "{{\"scene\": \"{}\", \"spp\": {}, \"load_s\": {load_s:.4}, \"first_s\": {:.4}, \"warm_median_s\": {median:.4}, \"peak_rss_mb\": {:.1}}}",
                scene_args.scene.display(),
                loaded.sensors[0].sampler.pass_count(spp),
                times[0],
                peak_rss_mb()
            );
            Ok(())
        }
        Command::Params { scene: scene_args } => {
            let scene = scene_args.load()?;
            print!("{}", scene.params);
            Ok(())
        }
    }
}

/// Peak resident memory of this process (VmHWM), in MiB; NaN where the
/// platform does not report it.
fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
