//! Evaluation: measures of how well a model reproduces a material.

pub mod metrics;

pub use metrics::{Fidelity, TextureStats, correlation, texture_fidelity};
