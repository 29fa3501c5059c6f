//! Where relative file names lead: Mitsuba 3's file resolver, an ordered
//! list of folders searched in turn.
//!
//! The rules (those of Mitsuba 3.9's XML parser):
//! - reading a scene file puts its folder first in the list; each
//!   `<path value="…"/>` it declares is then put first in turn (so the
//!   latest declared path is searched first);
//! - an `<include>`d file starts from the list of the including file as it
//!   is at the `<include>`, with its own folder put first; its `<path>`s
//!   only affect the files it includes itself;
//! - the plugins of the whole scene (meshes, textures, …, also those
//!   declared in included files) resolve their files with the main file's
//!   list as it is at the end of that file;
//! - the last folder of every list is the working directory.

use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileResolver {
    /// Searched first to last.
    dirs: Vec<PathBuf>,
}

impl Default for FileResolver {
    /// The working directory only.
    fn default() -> FileResolver {
        FileResolver {
            dirs: std::env::current_dir().into_iter().collect(),
        }
    }
}

impl FileResolver {
    /// Searches `dir` before all other folders (an empty `dir`, the folder
    /// of a file named without one, is the working directory: kept last).
    pub fn prepend(&mut self, dir: &Path) {
        if !dir.as_os_str().is_empty() {
            self.dirs.insert(0, dir.to_path_buf());
        }
    }

    /// The first existing file or folder `dir/name` in search order; an
    /// absolute `name` if it exists.
    pub fn resolve(&self, name: &str) -> Option<PathBuf> {
        let name = Path::new(name);
        if name.is_absolute() {
            return name.exists().then(|| name.to_path_buf());
        }
        self.dirs.iter().map(|d| d.join(name)).find(|p| p.exists())
    }

    /// The folders searched, in order, for messages: "a, b, c".
    pub fn describe(&self) -> String {
        let dirs: Vec<String> = self.dirs.iter().map(|d| d.display().to_string()).collect();
        dirs.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latest_prepended_folder_wins_and_absolute_names_are_kept() {
        let d = std::env::temp_dir().join(format!("penumbra-resolver-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        for sub in ["a", "b"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
            std::fs::write(d.join(sub).join("x.obj"), "").unwrap();
        }
        std::fs::write(d.join("a/only_a.obj"), "").unwrap();
        let mut r = FileResolver::default();
        r.prepend(&d.join("a"));
        r.prepend(&d.join("b"));
        r.prepend(Path::new(""));
        assert_eq!(r.resolve("x.obj"), Some(d.join("b/x.obj")));
        assert_eq!(r.resolve("only_a.obj"), Some(d.join("a/only_a.obj")));
        assert_eq!(r.resolve("missing.obj"), None);
        let abs = d.join("a/x.obj");
        assert_eq!(r.resolve(abs.to_str().unwrap()), Some(abs));
        assert!(r.describe().starts_with(&d.join("b").display().to_string()));
        let _ = std::fs::remove_dir_all(&d);
    }
}
