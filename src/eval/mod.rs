//! Evaluation: measures of how well a model reproduces a material, the speed-against-error
//! benchmark of every method, and its plots.

pub mod bench;
mod error;
pub mod metrics;
pub mod montage;
pub mod plot;

pub use error::{EvalError, Result};
pub use metrics::{Fidelity, TextureStats, correlation, texture_fidelity};
