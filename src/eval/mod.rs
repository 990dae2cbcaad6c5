//! Evaluation: measures of how well a model reproduces a material, the speed-against-error
//! benchmark of every method, and its plots.

pub mod artefacts;
pub mod bench;
mod error;
pub mod judge;
pub mod metrics;
pub mod montage;
pub mod plot;
pub mod pyramid;

pub use error::{EvalError, Result};
pub use judge::{Judgement, Levels, Signature, Verdict, Yardstick};
pub use metrics::{Fidelity, TextureStats, correlation, texture_fidelity};
