//! The integration tests, as one test binary: each module below is one
//! file of this folder. One binary instead of one per file because each
//! release test binary is linked with thin LTO over the whole renderer
//! (about 75 s on two cores), which made up most of CI's time.
//!
//! Run one file's tests with `cargo test --release -p penumbra --test
//! integration <module>::`, e.g. `visibility_gradients::`.

// helpers shared by several files
mod common;
mod reference_check;
mod volume_scenes;

mod bad_mesh_files;
mod check_grad;
mod conformance;
mod corpus_gaps;
mod degenerate_meshes;
mod emitter_strategies;
mod furnace;
mod geometry_gradients;
mod gradients_mitsuba;
mod instance_gradients;
mod media_gradients;
mod non_finite;
mod optimize;
mod projective_integrators;
mod reference;
mod samplers;
mod self_contained;
mod visibility_gradients;
