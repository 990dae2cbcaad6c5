//! The error type of the model area: analysis, the `.btfm` format and synthesis.

use std::path::PathBuf;

use crate::btf::BtfError;

/// Result alias for the model area.
pub type Result<T, E = ModelError> = std::result::Result<T, E>;

/// What can go wrong while analysing a BTF, reading or writing a model, or synthesizing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// Reading the BTF (or writing images) failed.
    #[error(transparent)]
    Btf(#[from] BtfError),
    /// A model file is corrupt, truncated, of another version, or hostile.
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
}

impl ModelError {
    pub(crate) fn parameter(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }
}
