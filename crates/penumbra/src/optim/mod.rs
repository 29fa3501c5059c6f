//! Inverse rendering: losses, optimisers, and optimisation jobs.

mod loss;
mod optimizer;

pub use loss::Loss;
pub use optimizer::{project, Method, Optimizer};
