//! File plumbing every format shares (model, LPCA, BTF archives, synthetic sets, reports):
//! atomic writes (a temporary name beside the target, then a rename), the `.btfmrf-partial-*`
//! temporaries an interrupt removes ([`partial`]), the checksummed envelope of the model files
//! ([`envelope`]) and a bounds-checked little-endian byte reader ([`bytes`]).
//!
//! This module depends on nothing else in the crate, so that every area can use it without an
//! import cycle; its one error type converts into the BTF area's error (`BtfError::Io`).

pub(crate) mod bytes;
pub(crate) mod envelope;
pub mod partial;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use self::partial::{PartialDir, PartialFile};

/// The operating system refused a read or write of `path`.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct IoError {
    /// The file or folder.
    pub path: PathBuf,
    /// The underlying error.
    pub source: std::io::Error,
}

impl IoError {
    /// The error `source` about `path`.
    pub fn new(path: &Path, source: std::io::Error) -> Self {
        Self {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Result alias for file plumbing.
pub type Result<T, E = IoError> = std::result::Result<T, E>;

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, then a rename.
///
/// # Errors
/// The folder is not writable, or the disk is full.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = temp_file_beside(path)?;
    tmp.write_all(bytes)
        .and_then(|_| tmp.flush())
        .map_err(|e| IoError::new(path, e))?;
    tmp.persist(path).map_err(|e| IoError::new(path, e))?;
    Ok(())
}

/// The first `limit + 1` bytes of the file at `path` at most: one byte past the limit lets a
/// parser tell a file that is too long from one that fits exactly, without reading more.
///
/// # Errors
/// The file cannot be opened or read.
pub fn read_capped(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let file = std::fs::File::open(path).map_err(|e| IoError::new(path, e))?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| IoError::new(path, e))?;
    Ok(bytes)
}

/// A temporary file next to `path` (same folder, so that the final rename is atomic); it is
/// deleted if dropped before being persisted, or on an interrupt ([`partial`]).
///
/// # Errors
/// The folder is not writable.
pub(crate) fn temp_file_beside(path: &Path) -> Result<PartialFile> {
    let parent = parent_dir(path);
    PartialFile::new_in(parent).map_err(|e| IoError::new(parent, e))
}

/// A temporary folder next to `path`, deleted if dropped or on an interrupt ([`partial`]);
/// [`publish_dir`] gives it its name.
///
/// # Errors
/// `path` exists already, or its folder is not writable.
pub fn temp_dir_beside(path: &Path) -> Result<PartialDir> {
    if path.exists() {
        return Err(IoError::new(
            path,
            std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "already exists; remove it or choose another name",
            ),
        ));
    }
    let parent = parent_dir(path);
    PartialDir::new_in(parent).map_err(|e| IoError::new(parent, e))
}

/// Renames a completed temporary folder to `path` (removing it if that fails).
///
/// # Errors
/// The rename failed.
pub fn publish_dir(tmp: PartialDir, path: &Path) -> Result<()> {
    tmp.publish(path).map_err(|e| IoError::new(path, e))
}

/// The folder holding `path` ("." for a bare file name).
pub fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_writes_replace_whole_files_and_leave_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        write_file_atomic(&path, b"first").unwrap();
        write_file_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "only the output remains");
        let missing = dir.path().join("no-such-folder").join("x");
        let err = write_file_atomic(&missing, b"x").unwrap_err();
        assert!(err.to_string().contains("no-such-folder"), "{err}");
    }

    #[test]
    fn capped_reads_stop_one_byte_past_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, [7u8; 10]).unwrap();
        assert_eq!(read_capped(&path, 4).unwrap().len(), 5);
        assert_eq!(read_capped(&path, 100).unwrap().len(), 10);
        assert!(read_capped(&dir.path().join("missing"), 4).is_err());
    }

    #[test]
    fn a_temporary_folder_is_refused_over_an_existing_path() {
        let dir = tempfile::tempdir().unwrap();
        let err = temp_dir_beside(dir.path()).err().expect("refused");
        assert!(err.to_string().contains("already exists"), "{err}");
        let target = dir.path().join("set");
        let tmp = temp_dir_beside(&target).unwrap();
        std::fs::write(tmp.path().join("a"), b"x").unwrap();
        publish_dir(tmp, &target).unwrap();
        assert!(target.join("a").exists());
    }
}
