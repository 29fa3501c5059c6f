//! An optimisation job end to end (TOML → targets → Adam on path-replay
//! gradients → outputs): the Cornell box's red wall, started grey, moves
//! towards its true colour, and the job writes its images (target and
//! final render side by side), parameters, loss table and plots.

use penumbra::optim::Job;
use std::path::PathBuf;

#[test]
fn cbox_red_wall_job_recovers_the_colour() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = std::env::temp_dir().join(format!("penumbra-job-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let job = dir.join("job.toml");
    std::fs::write(
        &job,
        format!(
            r#"scene = "{}"
defines = {{ res = "32", max_depth = "4" }}
output = "out"
iterations = 40
spp = 8
target = {{ render_spp = 128 }}
save_every = 20

[[param]]
key = "red.reflectance.value"
init = 0.4
lr = 0.03
"#,
            repo.join("scenes/cbox.xml").display()
        ),
    )
    .unwrap();
    let mut job = Job::load(&job).unwrap();
    let mut seen = 0;
    let result = job.run(|_, _| seen += 1).unwrap();
    assert_eq!(seen, 40);
    let curve = &result.param_error_curve;
    eprintln!("mean |error|: {:.4} -> {:.4}", curve[0], curve[39]);
    // true colour (0.570, 0.043, 0.044): the grey start is 0.27 off on average
    assert!(
        curve[39] < 0.3 * curve[0],
        "error {} -> {}",
        curve[0],
        curve[39]
    );
    for f in [
        "loss.png",
        "loss.csv",
        "params.txt",
        "iter_0000.png",
        "iter_0039.png",
        "target.exr",
        "target.png",
        "final.exr",
        "final.png",
    ] {
        assert!(dir.join("out").join(f).is_file(), "{f} missing");
    }
    // the final render is the target's twin: same size, and close to it
    let read = |f: &str| penumbra::image::read_image(&dir.join("out").join(f)).unwrap();
    let (target, fin) = (read("target.exr"), read("final.exr"));
    assert_eq!((fin.width, fin.height), (32, 32));
    let mean = |i: &penumbra::image::Image| i.data.iter().map(|&v| v as f64).sum::<f64>();
    let rel = (mean(&fin) - mean(&target)).abs() / mean(&target);
    eprintln!("final vs target: relative difference of the means {rel:.4}");
    // a sanity bound (measured: 0.012): the same scene, same exposure
    assert!(rel < 0.05, "final vs target mean: {rel}");
    // two panels: the loss, and the parameter error (the truth is known)
    let plot = read("loss.png");
    assert_eq!((plot.width, plot.height), (640, 800));
    std::fs::remove_dir_all(&dir).ok();
}

/// Without `output`, a job writes under out/optimize/<job name>/ (like
/// the other commands); the CLI's `-o` replaces `Job::output`.
#[test]
fn job_output_defaults_to_out_optimize_job_name() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let job = Job::load(&repo.join("scenes/jobs/cbox_walls.toml")).unwrap();
    assert_eq!(job.output, PathBuf::from("out/optimize/cbox_walls"));
}

/// The textured job optimises a bitmap used as a diffuse reflectance: its
/// texels carry the [0, 1] domain, so every step projects them into it.
#[test]
fn textured_job_texels_are_reflectances() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let job = Job::load(&repo.join("scenes/jobs/textured_texture.toml")).unwrap();
    let store = &job.scene.params;
    let p = store.get(store.require("plane.bsdf.reflectance.data").unwrap());
    assert_eq!(p.domain, penumbra::params::Domain::UnitInterval);
    assert!(p.data.iter().all(|v| (0.0..=1.0).contains(v)));
}
