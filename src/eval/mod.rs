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

/// The nine measured lights (theta, phi degrees) of the Bonn set's frontal view at which the
/// built-in materials are judged (docs/BENCHMARKS.md, `examples/judge_materials.rs`): every
/// elevation and several azimuths.
pub const JUDGED_LIGHTS: [(f64, f64); 9] = [
    (15.0, 120.0),
    (30.0, 90.0),
    (45.0, 20.0),
    (45.0, 160.0),
    (45.0, 280.0),
    (60.0, 90.0),
    (60.0, 234.0),
    (75.0, 45.0),
    (75.0, 195.0),
];
