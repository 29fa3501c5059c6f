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

/// What a reference to something outside the repository looks like: a
/// relative path that climbs into a sibling `shared` folder, or an absolute
/// path into one machine's folders. Spelled in pieces so that this file
/// does not match itself (nor a grep for such lines).
const OUTSIDE: [&str; 3] = [
    concat!("..", "/shared/"),
    concat!("/", "work/"),
    concat!("/", "root/"),
];

fn outside_reference(line: &str) -> bool {
    OUTSIDE.iter().any(|p| line.contains(p))
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
    let mut offending = Vec::new();
    for f in &files {
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
    let sibling = format!("see {}DESIGN.md", OUTSIDE[0]);
    let absolute = format!("let p = \"{}shared/assets/museum.exr\";", OUTSIDE[1]);
    assert!(outside_reference(&sibling));
    assert!(outside_reference(&absolute));
    assert!(!outside_reference("scenes/refs/cbox_ref256.exr"));
}
