//! Films, reconstruction filters, image IO.

pub mod film;
pub mod plot;
pub mod rfilter;

pub use film::{Film, ImageBlock};
pub use rfilter::ReconstructionFilter;
