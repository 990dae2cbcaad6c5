//! The error type of the evaluation area: benchmarks, reports and plots.

use std::path::PathBuf;

use crate::btf::BtfError;
use crate::io::IoError;
use crate::lpca::LpcaError;
use crate::model::ModelError;

/// Result alias for the evaluation area.
pub type Result<T, E = EvalError> = std::result::Result<T, E>;

/// What can go wrong while benchmarking methods or writing their report.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// Reading the BTF or writing an image failed.
    #[error(transparent)]
    Btf(#[from] BtfError),
    /// Writing a report file failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// Analysing or synthesizing a model failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Fitting or reconstructing a PCA baseline failed.
    #[error(transparent)]
    Lpca(#[from] LpcaError),
    /// An image the texture judge cannot measure (too small, not colour).
    #[error("{0}")]
    Judge(String),
    /// Drawing a plot failed.
    #[error("{}: cannot draw the plot: {reason}", path.display())]
    Plot {
        /// The plot file.
        path: PathBuf,
        /// What the plotting library said.
        reason: String,
    },
}
