//! The `penumbra` command line: renders, and fails cleanly (non-zero exit,
//! a message naming the file and line) on bad input.

use std::path::PathBuf;
use std::process::Command;

fn penumbra() -> Command {
    Command::new(env!("CARGO_BIN_EXE_penumbra"))
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn out_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("penumbra-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn renders_a_scene_to_exr_and_png() {
    let out = out_dir();
    for ext in ["exr", "png"] {
        let file = out.join(format!("cbox.{ext}"));
        let o = penumbra()
            .args(["render", "--quiet", "--spp", "2", "-D", "res=32", "-o"])
            .arg(&file)
            .arg(repo().join("scenes/cbox.xml"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let img = penumbra::image::read_image(&file).unwrap();
        assert_eq!((img.width, img.height), (32, 32));
    }
}

#[test]
fn bad_scenes_fail_with_file_and_line() {
    let dir = repo().join("crates/penumbra/tests/bad_scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("xml") {
            continue;
        }
        let o = penumbra()
            .args(["render", "--quiet", "-o"])
            .arg(out_dir().join("bad.exr"))
            .arg(&path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{}: {err}", path.display());
        let name = path.file_name().unwrap().to_str().unwrap();
        assert!(err.starts_with("error: "), "{err}");
        assert!(
            err.contains(name),
            "{}: message does not name the file: {err}",
            path.display()
        );
        assert!(!err.contains("panicked"), "{err}");
        n += 1;
    }
    assert!(
        n >= 4,
        "expected a corpus of bad scenes in {}",
        dir.display()
    );
}

#[test]
fn bad_arguments_are_reported() {
    let o = penumbra()
        .args(["render", "-D", "novalue", "-o", "x.exr"])
        .arg(repo().join("scenes/cbox.xml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("-D expects name=value"));
    let o = penumbra()
        .args([
            "render", "--quiet", "--spp", "1", "-D", "res=8", "-o", "x.tiff",
        ])
        .arg(repo().join("scenes/cbox.xml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("x.tiff"));
}

/// A fresh, empty working directory for one test.
fn fresh_dir(name: &str) -> PathBuf {
    let d = out_dir().join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cbox() -> PathBuf {
    repo().join("scenes/cbox.xml")
}

fn run_ok(args: &[&str]) -> String {
    let o = penumbra().args(args).arg(cbox()).output().unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

fn run_err(args: &[&str]) -> (Option<i32>, String) {
    let o = penumbra().args(args).arg(cbox()).output().unwrap();
    assert!(!o.status.success(), "{args:?} succeeded");
    (o.status.code(), String::from_utf8_lossy(&o.stderr).into())
}

#[test]
fn unknown_defines_are_errors_listing_the_scenes_defaults() {
    for cmd in ["render", "params", "bench"] {
        let (code, err) = run_err(&[cmd, "-q", "-D", "resolution=32"]);
        assert_eq!(code, Some(1), "{err}");
        assert!(
            err.contains("cbox.xml:5: -D resolution=32: the scene has no default 'resolution'; its defaults are: spp, res, max_depth"),
            "{cmd}: {err}"
        );
    }
}

#[test]
fn params_lists_every_key_with_shape_flags_and_value() {
    let out = run_ok(&["params", "-D", "res=8"]);
    let lines: Vec<&str> = out.lines().collect();
    let words = |l: &str| l.split_whitespace().collect::<Vec<_>>().join(" ");
    assert_eq!(words(lines[0]), "key shape flags domain value");
    let red = lines
        .iter()
        .find(|l| l.starts_with("red.reflectance.value "))
        .expect("red.reflectance.value is listed");
    assert!(words(red).starts_with("red.reflectance.value [3] differentiable in [0, 1] [0.5"));
    let box_positions = lines
        .iter()
        .find(|l| l.starts_with("small-box.vertex_positions "))
        .expect("mesh positions are listed");
    assert!(
        words(box_positions).contains("[24, 3] differentiable, discontinuous finite min "),
        "{box_positions}"
    );
    // the camera's pose and field of view (cbox's sensor has id "sensor")
    let row = |key: &str| {
        let l = lines
            .iter()
            .find(|l| l.split_whitespace().next() == Some(key))
            .unwrap_or_else(|| panic!("{key} is listed"));
        words(l)
    };
    assert!(
        row("sensor.to_world")
            .starts_with("sensor.to_world [4, 4] differentiable, discontinuous finite min "),
        "{out}"
    );
    assert!(
        row("sensor.x_fov")
            .starts_with("sensor.x_fov [1] differentiable, discontinuous finite and > 0 [39.3"),
        "{out}"
    );
    for key in [
        "sensor.principal_point_offset_x",
        "sensor.principal_point_offset_y",
    ] {
        assert_eq!(
            row(key),
            format!("{key} [1] differentiable, discontinuous finite [0.0000]")
        );
    }
    // one line per parameter: the same keys as the library's store
    let scene = penumbra::scene::Scene::load_file(&cbox(), &[]).unwrap();
    assert_eq!(lines.len(), scene.params.len() + 1);
}

#[test]
fn unknown_parameter_keys_point_to_the_params_command() {
    let (code, err) = run_err(&[
        "grad",
        "-q",
        "-D",
        "res=8",
        "--spp",
        "1",
        "--param",
        "red.reflectance.valeu",
    ]);
    assert_eq!(code, Some(1));
    assert!(
        err.contains("did you mean one of: red.reflectance.value"),
        "{err}"
    );
    assert!(err.contains("`penumbra params SCENE`"), "{err}");
}

#[test]
fn spp_zero_is_refused_by_every_command_that_takes_spp() {
    for cmd in ["render", "grad", "check-grad", "bench"] {
        let param: &[&str] = if cmd.contains("grad") {
            &["--param", "red.reflectance.value"]
        } else {
            &[]
        };
        let (code, err) = run_err(&[&[cmd, "--spp", "0"], param].concat());
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(err.contains("invalid value '0' for '--spp"), "{cmd}: {err}");
    }
}

#[test]
fn commands_write_under_out_by_default_and_keep_stdout_parseable() {
    let cwd = fresh_dir("default-outputs");
    let run = |args: &[&str]| {
        let o = penumbra()
            .current_dir(&cwd)
            .args(args)
            .arg(cbox())
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        if args.contains(&"-q") {
            assert!(o.stderr.is_empty(), "{args:?} -q wrote to stderr");
        }
        String::from_utf8(o.stdout).unwrap()
    };
    let key = "red.reflectance.value";
    let small = ["-D", "res=8", "--spp", "1"];
    for quiet in [true, false] {
        let q: &[&str] = if quiet { &["-q"] } else { &[] };
        fn with<'a>(args: &[&'a str], small: &[&'a str], q: &[&'a str]) -> Vec<&'a str> {
            [args, small, q].concat()
        }
        run(&with(&["render"], &small, q));
        let grad = run(&with(&["grad", "--param", key], &small, q));
        assert_eq!(grad.lines().count(), 1, "{grad}");
        assert!(grad.starts_with("d loss / d red.reflectance.value (shape [3]): ["));
        run(&with(
            &["grad", "--mode", "forward", "--param", key],
            &small,
            q,
        ));
        let check = run(&with(
            &["check-grad", "--batches", "2", "--param", key],
            &small,
            q,
        ));
        assert!(
            check.contains("derivative images in out/check-grad"),
            "{check}"
        );
        let bench = run(&with(&["bench", "--reps", "1"], &small, q));
        assert_eq!(bench.lines().count(), 1, "{bench}");
        assert!(bench.starts_with("{\"scene\": ") && bench.trim_end().ends_with('}'));
    }
    for file in [
        "out/render/cbox.exr",
        "out/grad/dimage.exr",
        "out/check-grad/red.reflectance.value.fd.exr",
        "out/check-grad/red.reflectance.value.forward.exr",
    ] {
        assert!(cwd.join(file).is_file(), "{file} was not written");
    }
    let mut top: Vec<String> = std::fs::read_dir(&cwd)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    top.sort();
    assert_eq!(
        top,
        ["out"],
        "only out/ is written into the working directory"
    );
}

#[test]
#[cfg(target_os = "linux")]
fn a_film_larger_than_memory_is_refused_with_the_estimate() {
    // 100000² pixels: had the render started, its allocations would abort
    let (code, err) = run_err(&[
        "render",
        "-q",
        "--spp",
        "1",
        "-D",
        "res=100000",
        "-o",
        "x.exr",
    ]);
    assert_eq!(code, Some(1));
    assert!(err.contains("the film 100000×100000 needs about"), "{err}");
    assert!(err.contains("GiB are available; pass --force"), "{err}");
}

#[test]
fn grad_decorrelates_the_gradient_seed_by_default_and_honours_seed_grad() {
    let grad = |extra: &[&str]| {
        let args = [
            &["grad", "-q", "-D", "res=8", "--spp", "1", "--seed", "5"][..],
            &["--param", "red.reflectance.value"],
            extra,
        ]
        .concat();
        run_ok(&args)
    };
    let derived = penumbra::diff::gradient_seed(5).to_string();
    let default = grad(&[]);
    assert_eq!(default, grad(&["--seed-grad", &derived]));
    assert_ne!(default, grad(&["--seed-grad", "5"]), "the image's own seed");
}

/// `--sppp` sets the budget of the boundary term of primary visibility
/// (0: off) on the commands that compute derivatives; a negative value is
/// refused naming the option.
#[test]
fn sppp_sets_the_primary_boundary_budget_of_derivative_commands() {
    let dir = fresh_dir("sppp");
    let dimage = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let args = [
            &[
                "grad", "-q", "-D", "res=8", "--spp", "1", "--mode", "forward",
            ][..],
            &["--param", "small-box.vertex_positions", "-o"],
            &[out.to_str().unwrap()],
            extra,
        ]
        .concat();
        run_ok(&args);
        penumbra::image::read_image(&out.join("dimage.exr"))
            .unwrap()
            .data
    };
    let off = dimage("off", &["--sppp", "0"]);
    let default = dimage("default", &[]);
    let explicit = dimage("explicit", &["--sppp", "1"]);
    assert_eq!(default, explicit, "the default budget is --spp");
    assert_ne!(off, default, "--sppp 0 removes the silhouettes' term");
    assert!(off.iter().all(|v| v.is_finite()));
    for cmd in ["grad", "check-grad"] {
        let (code, err) = run_err(&[cmd, "--sppp", "-1", "--param", "red.reflectance.value"]);
        assert_eq!(code, Some(2), "{cmd}: {err}");
        assert!(err.contains("'--sppp <N>'"), "{cmd}: {err}");
    }
}

/// `grad --mode forward --translate x,y,z` differentiates along a
/// translation (as `check-grad --translate`): the derivative image is
/// linear in it, and differs from the default tangent θ·s; reverse mode
/// refuses it.
#[test]
fn grad_translate_gives_the_forward_tangent() {
    let dir = fresh_dir("translate");
    let dimage = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let args = [
            &[
                "grad", "-q", "-D", "res=8", "--spp", "1", "--mode", "forward",
            ][..],
            &["--param", "small-box.vertex_positions", "-o"],
            &[out.to_str().unwrap()],
            extra,
        ]
        .concat();
        run_ok(&args);
        penumbra::image::read_image(&out.join("dimage.exr"))
            .unwrap()
            .data
    };
    let scale = dimage("scale", &[]);
    let x1 = dimage("x1", &["--translate", "1,0,0"]);
    let x2 = dimage("x2", &["--translate", "2,0,0"]);
    assert_ne!(scale, x1);
    assert!(x1.iter().any(|&v| v != 0.0));
    for (a, b) in x1.iter().zip(&x2) {
        assert!((2.0 * a - b).abs() <= 1e-5 * b.abs().max(1e-3), "{a} {b}");
    }
    let (code, err) = run_err(&[
        "grad",
        "-q",
        "--translate",
        "1,0,0",
        "--param",
        "small-box.vertex_positions",
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--mode forward"), "{err}");
}

#[test]
fn the_profile_guided_builds_training_jobs_run() {
    // scripts/build_pgo.sh trains the command with these runs: a scene,
    // key or option they name that no longer exists would fail the build
    let o = Command::new("python3")
        .arg(repo().join("scripts/pgo_train.py"))
        .arg("--cli")
        .arg(env!("CARGO_BIN_EXE_penumbra"))
        .output()
        .expect("python3 runs scripts/pgo_train.py");
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}
