//! Scenes: loading (Mitsuba 3 XML, Python dicts), the plugin registry, and
//! the assembled [`Scene`] that integrators render.

mod props;
pub mod xml;

pub use props::{Class, Node, Prop, Value};
pub use xml::{child_key, parse_file, parse_str};

use crate::error::{Error, Result};
use crate::params::ParamStore;
use std::path::PathBuf;

/// State shared by plugin constructors while a scene is built.
#[derive(Debug, Default)]
pub struct LoadContext {
    /// Where constructors register their parameters.
    pub store: ParamStore,
}

impl LoadContext {
    /// Resolves `filename` (parameter `prop` of `node`) relative to the
    /// directory of the file that declared the node; errors if it does not
    /// exist.
    pub fn resolve_path(&self, node: &Node, prop: &str, filename: &str) -> Result<PathBuf> {
        let p = PathBuf::from(filename);
        let full = if p.is_absolute() {
            p
        } else {
            node.loc.file.parent().map(|d| d.join(&p)).unwrap_or(p)
        };
        if !full.is_file() {
            return Err(Error::scene(
                &node.loc,
                format!(
                    "{node}: file '{}' (parameter '{prop}') not found; looked for {}",
                    filename,
                    full.display()
                ),
            ));
        }
        Ok(full)
    }
}
