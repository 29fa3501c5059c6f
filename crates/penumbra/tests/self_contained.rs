//! The repository explains and tests itself: no file in it (code, tests,
//! scripts, docs, scenes) reads or links anything outside the checkout,
//! such as a sibling `shared` folder or an absolute path of one machine.

use std::path::{Path, PathBuf};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("the crate sits two folders below the repository root")
}

/// Text files of the checkout, without build output, caches and VCS data.
fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("a readable directory entry").path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if path.is_dir() {
            if !matches!(name, "target" | ".git" | "__pycache__" | "out" | ".venv") {
                text_files(&path, out);
            }
        } else if matches!(
            path.extension().and_then(|e| e.to_str()),
            Some("rs" | "py" | "sh" | "md" | "toml" | "xml" | "txt" | "json" | "cfg" | "yml")
        ) || name == "run"
        {
            out.push(path);
        }
    }
}

/// A reference to something outside the repository: a relative path that
/// climbs into a `shared` folder, or an absolute path into a machine's
/// work folders.
fn outside_reference(line: &str) -> bool {
    line.contains("../shared/") || line.contains("/work/") || line.contains("/root/")
}

#[test]
fn no_file_reads_or_links_outside_the_repository() {
    let root = repo_root();
    let mut files = Vec::new();
    text_files(&root, &mut files);
    assert!(
        files.len() > 50,
        "expected the repository's files under {}",
        root.display()
    );
    let this_file = Path::new(file!()).file_name();
    let mut offending = Vec::new();
    for f in &files {
        if f.file_name() == this_file {
            continue; // the patterns above
        }
        let Ok(text) = std::fs::read_to_string(f) else {
            continue; // not UTF-8: not a text file after all
        };
        for (i, line) in text.lines().enumerate() {
            if outside_reference(line) {
                offending.push(format!(
                    "{}:{}: {}",
                    f.strip_prefix(&root).unwrap_or(f).display(),
                    i + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(
        offending.is_empty(),
        "these lines reach outside the repository (a fresh clone has nothing beside it):\n{}",
        offending.join("\n")
    );
}

#[test]
fn the_check_sees_a_sibling_shared_folder_and_absolute_paths() {
    assert!(outside_reference("see ../shared/DESIGN.md"));
    assert!(outside_reference(
        r#"const P: &str = "/work/shared/assets/museum.exr";"#
    ));
    assert!(!outside_reference("scenes/refs/cbox_ref256.exr"));
}
