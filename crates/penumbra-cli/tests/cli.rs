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
