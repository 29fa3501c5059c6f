//! Inverse rendering: losses, optimisers, and optimisation jobs.

pub mod job;
mod loss;
mod optimizer;

pub use job::{Job, JobResult};
pub use loss::Loss;
pub use optimizer::{project, Method, Optimizer};
