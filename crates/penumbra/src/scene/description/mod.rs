//! The scene description: a Mitsuba XML file (with its includes, search
//! paths and `<default>`s, upgraded from older scene versions) as a tree of
//! plugin [`Node`]s with typed [`Prop`]s, and the [`FileResolver`] that
//! finds the files it names.
//!
//! This layer sits BELOW the plugins: it imports no plugin. Plugins read
//! their parameters from a [`Node`]; the assembly of a `Scene`
//! (`scene/build.rs`), above the plugins, builds them from the tree.

mod load_context;
mod props;
mod resolver;
pub mod spectrum;
mod spectrum_plugin;
mod upgrade;
pub mod xml;

pub use load_context::LoadContext;
pub use props::{Class, Node, Prop, Value};
pub use resolver::FileResolver;
pub use xml::{child_key, parse_file, parse_str, SceneDescription};
