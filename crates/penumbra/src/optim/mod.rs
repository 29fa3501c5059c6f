//! Inverse rendering: losses, optimisers, latent poses, and optimisation
//! jobs.

pub mod job;
mod loss;
mod optimizer;
pub mod pose;

pub use job::{Job, JobResult};
pub use loss::Loss;
pub use optimizer::{project, Method, Optimizer};
pub use pose::{Pose, PoseGrad, PoseLayout};
