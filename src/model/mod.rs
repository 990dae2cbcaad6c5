//! The compact material model (`MaterialModel`), its `.btfm` file format and its errors.

mod error;
pub mod format;
mod material;

pub use crate::mrf::{AnyLevels, ModelKind};
pub use error::{ModelError, Result};
pub use material::{
    BandMarginals, CoarseSource, DeviationCodes, Exemplar, ExemplarChroma, LIGHTNESS_BANDS,
    LightChroma, LightLightness, LightWeights, LitMarginals, MAX_CHROMA_STEP,
    MAX_EXEMPLAR_COMPONENTS, MAX_EXEMPLAR_STEP, MAX_PERIOD_COMPONENTS, MAX_TILE_SAMPLES,
    MaterialModel, MaterialParts, PeriodicPart, Principal, RangeMap, SubspaceModel,
};
