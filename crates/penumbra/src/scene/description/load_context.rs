//! What plugin constructors share while one scene is built: the parameter
//! store they register into, the resolver that finds their files, and
//! state each plugin family keeps from one constructor to the next (the
//! objects shared by id, uses to check once the scene is assembled). This
//! module names no plugin type: a family keeps its state under a type of
//! its own ([`LoadContext::state`]), so the plugins depend on this layer
//! and never on the assembly above them.

use super::{FileResolver, Node};
use crate::error::Result;
use crate::params::ParamStore;
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::path::PathBuf;

/// State shared by plugin constructors while a scene is built.
#[derive(Default)]
pub struct LoadContext {
    /// Where constructors register their parameters.
    pub store: ParamStore,
    /// Where relative file names are searched (the main scene file's
    /// folder and `<path>`s; see [`FileResolver`]).
    pub resolver: FileResolver,
    /// One value per type, created on first use by [`LoadContext::state`].
    state: HashMap<TypeId, Box<dyn Any>>,
}

impl std::fmt::Debug for LoadContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoadContext")
            .field("store", &self.store)
            .field("resolver", &self.resolver)
            .finish_non_exhaustive()
    }
}

impl LoadContext {
    /// A context whose relative file names resolve with `resolver`.
    pub fn new(resolver: FileResolver) -> LoadContext {
        LoadContext {
            resolver,
            ..LoadContext::default()
        }
    }

    /// The state of type `T` kept for this scene's build (its default
    /// value at first): how a plugin family remembers what it built.
    pub fn state<T: Default + 'static>(&mut self) -> &mut T {
        self.state
            .entry(TypeId::of::<T>())
            .or_insert_with(|| Box::new(T::default()))
            .downcast_mut::<T>()
            .expect("each entry is keyed by its own type")
    }

    /// Finds `filename` (parameter `prop` of `node`) with the scene's file
    /// resolver; errors, naming the folders searched, if it does not exist.
    pub fn resolve_path(&self, node: &Node, prop: &str, filename: &str) -> Result<PathBuf> {
        self.resolver
            .resolve(filename)
            .filter(|p| p.is_file())
            .ok_or_else(|| {
                node.prop(prop).map_or_else(
                    || node.error(format!("file '{filename}' not found")),
                    |p| {
                        node.prop_error(
                            p,
                            format!(
                                "file '{filename}' not found (looked in: {}); declare its \
                                 folder with <path value=\"...\"/> or give its path relative to \
                                 the scene file",
                                self.resolver.describe()
                            ),
                        )
                    },
                )
            })
    }
}
