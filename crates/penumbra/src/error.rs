//! Errors reported to users: each says what went wrong, where (file:line,
//! parameter key) and, where it helps, what to do.

use std::fmt;
use std::path::PathBuf;

/// A place in a scene file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SrcLoc {
    pub file: PathBuf,
    pub line: u32,
}

impl fmt::Display for SrcLoc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.file.display(), self.line)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A problem in a scene description, at a known place.
    #[error("{loc}: {msg}")]
    Scene { loc: SrcLoc, msg: String },
    /// A file that could not be read or written.
    #[error("{path}: {msg}")]
    File { path: PathBuf, msg: String },
    /// A parameter access or update that is not valid.
    #[error("parameter '{key}': {msg}")]
    Param { key: String, msg: String },
    /// Invalid arguments to an API call (shapes, sizes, options).
    #[error("{0}")]
    Invalid(String),
    /// The operation was cancelled (Ctrl-C, or a cancel flag).
    #[error("interrupted")]
    Interrupted,
}

impl Error {
    pub fn scene(loc: &SrcLoc, msg: impl Into<String>) -> Error {
        Error::Scene {
            loc: loc.clone(),
            msg: msg.into(),
        }
    }
    pub fn file(path: impl Into<PathBuf>, msg: impl fmt::Display) -> Error {
        Error::File {
            path: path.into(),
            msg: msg.to_string(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
