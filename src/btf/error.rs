//! The one error type of the BTF area: reading, validating, generating and writing BTFs.

use std::path::PathBuf;

/// Result alias for the BTF area.
pub type Result<T, E = BtfError> = std::result::Result<T, E>;

/// Everything that can go wrong while reading, generating or writing a BTF.
///
/// Every variant names the file (or archive member, written `archive.zip: member`) at fault,
/// so that a CLI can print one line a user can act on.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BtfError {
    /// The operating system refused a read or write.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is not a readable zip archive (random bytes, truncated, unsupported method).
    #[error("{}: not a readable zip archive ({source})", path.display())]
    Zip {
        /// The archive.
        path: PathBuf,
        /// The zip library's diagnosis.
        source: zip::result::ZipError,
    },
    /// An image file could not be decoded or encoded.
    #[error("{file}: {reason}")]
    Image {
        /// The image file or archive member.
        file: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An image is larger than this library accepts (checked before pixels are allocated).
    #[error("{file}: image of {width}x{height} pixels exceeds the limit of {limit}x{limit}")]
    TooLarge {
        /// The image file or archive member.
        file: String,
        /// Width claimed by the file header.
        width: u64,
        /// Height claimed by the file header.
        height: u64,
        /// The largest accepted side, in pixels.
        limit: u32,
    },
    /// An HDR image holds NaN or infinite values.
    #[error("{file}: contains {count} NaN or infinite sample(s); the first at x={x}, y={y}")]
    NonFinite {
        /// The image file or archive member.
        file: String,
        /// How many samples are not finite.
        count: usize,
        /// Column of the first bad sample.
        x: usize,
        /// Row of the first bad sample.
        y: usize,
    },
    /// The images of one BTF do not share one size.
    #[error("{file}: image is {found_w}x{found_h}, but the BTF's images are {width}x{height}")]
    SizeMismatch {
        /// The odd image.
        file: String,
        /// Expected width.
        width: u32,
        /// Expected height.
        height: u32,
        /// Its width.
        found_w: u32,
        /// Its height.
        found_h: u32,
    },
    /// A BTF layout is incomplete or contradictory (missing or duplicate directions, a bad
    /// file name, an empty folder).
    #[error("{location}: {reason}")]
    Layout {
        /// The archive, folder or file.
        location: String,
        /// What is wrong.
        reason: String,
    },
    /// A light-position (`.lp`) file cannot be parsed.
    #[error("{}:{line}: {reason}", path.display())]
    LightPositions {
        /// The `.lp` file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A caller's argument is out of range (the name is the CLI flag or parameter).
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// Parameter name, spelled as on the command line where there is a flag.
        name: &'static str,
        /// Why the value is rejected.
        reason: String,
    },
}

impl From<crate::io::IoError> for BtfError {
    fn from(e: crate::io::IoError) -> Self {
        Self::Io {
            path: e.path,
            source: e.source,
        }
    }
}

impl BtfError {
    /// An I/O error on `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// A layout error at `location`.
    pub(crate) fn layout(location: impl std::fmt::Display, reason: impl Into<String>) -> Self {
        Self::Layout {
            location: location.to_string(),
            reason: reason.into(),
        }
    }

    /// A decoding or encoding error of one image.
    pub(crate) fn image(file: impl Into<String>, reason: impl std::fmt::Display) -> Self {
        Self::Image {
            file: file.into(),
            reason: reason.to_string(),
        }
    }

    /// A parameter out of range.
    pub(crate) fn parameter(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }
}
