//! The compact material model (`MaterialModel`), its `.btfm` file format and its errors.

mod error;
pub mod format;
mod material;

pub use error::{ModelError, Result};
pub use material::{
    BandMarginals, BandModel, LevelModel, MaterialModel, ModelKind, RangeMap, SubspaceModel,
};
