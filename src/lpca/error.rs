//! The error type of the local-PCA area: fitting, the `.lpca` format and reconstruction.

use std::path::PathBuf;

use crate::btf::BtfError;
use crate::io::IoError;

/// Result alias for the local-PCA area.
pub type Result<T, E = LpcaError> = std::result::Result<T, E>;

/// What can go wrong while fitting a (local) PCA model, reading or writing one, or
/// reconstructing images from it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LpcaError {
    /// Reading the BTF failed.
    #[error(transparent)]
    Btf(#[from] BtfError),
    /// Reading or writing a model file failed.
    #[error(transparent)]
    Io(#[from] IoError),
    /// A `.lpca` file is corrupt, truncated, of another version, or hostile.
    #[error("{}: {reason}", path.display())]
    Format {
        /// The model file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A caller's argument is out of range (named as on the command line).
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Why it is rejected.
        reason: String,
    },
    /// A dense linear-algebra step failed (an eigen decomposition did not converge).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

impl LpcaError {
    pub(crate) fn parameter(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }
}
