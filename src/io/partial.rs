//! Temporary outputs (`.btfmrf-partial-*`) that an interrupt must not leave behind: every one
//! is listed in a process-wide registry while it exists, and [`remove_registered`] (called by
//! the binary's SIGINT/SIGTERM handler) deletes whatever is listed.
//!
//! The order of steps keeps the registry a superset of what is on disk: a path is listed
//! before it is created and unlisted only after it is renamed to its final name or deleted.

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

static REGISTRY: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn registry() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    REGISTRY.lock().unwrap_or_else(|p| p.into_inner())
}

fn register(path: &Path) {
    registry().push(path.to_path_buf());
}

fn unregister(path: &Path) {
    let mut list = registry();
    if let Some(i) = list.iter().position(|p| p == path) {
        list.swap_remove(i);
    }
}

/// Deletes every registered temporary file and folder and returns how many were there. The
/// registry stays locked until the process exits, so nothing new is registered meanwhile; the
/// caller must exit right after (it is meant for signal handlers).
pub fn remove_registered() -> usize {
    let list = registry();
    let mut removed = 0;
    for path in list.iter() {
        // A writer thread may still be adding files to a folder: try a few times.
        for _ in 0..5 {
            let gone = match std::fs::symlink_metadata(path) {
                Err(_) => break,
                Ok(m) if m.is_dir() => std::fs::remove_dir_all(path).is_ok(),
                Ok(_) => std::fs::remove_file(path).is_ok(),
            };
            if gone {
                removed += 1;
                break;
            }
        }
    }
    std::mem::forget(list); // keep it locked: the process is about to exit
    removed
}

/// The builder of every temporary name: `.btfmrf-partial-` and random letters.
fn builder() -> tempfile::Builder<'static, 'static> {
    let mut b = tempfile::Builder::new();
    b.prefix(".btfmrf-partial-");
    b
}

/// A temporary file beside its final name, deleted when dropped unless persisted.
pub struct PartialFile {
    file: Option<tempfile::NamedTempFile>,
    path: PathBuf,
}

impl PartialFile {
    /// A new empty file in `dir` (mode 0644 before the umask, like any output).
    pub(crate) fn new_in(dir: &Path) -> std::io::Result<Self> {
        let file = builder().make_in(dir, |path| {
            register(path); // listed before it exists
            let mut options = std::fs::OpenOptions::new();
            options.read(true).write(true).create_new(true);
            #[cfg(unix)]
            std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o644);
            options.open(path).inspect_err(|_| unregister(path))
        })?;
        let path = file.path().to_path_buf();
        Ok(Self {
            file: Some(file),
            path,
        })
    }

    fn inner(&mut self) -> &mut tempfile::NamedTempFile {
        self.file.as_mut().expect("present until persisted")
    }

    /// The open file.
    pub fn as_file_mut(&mut self) -> &mut File {
        self.inner().as_file_mut()
    }

    /// Renames the file to `path` (atomically: same folder).
    ///
    /// # Errors
    /// The rename failed; the temporary is then deleted.
    pub fn persist(mut self, path: &Path) -> std::io::Result<File> {
        let file = self.file.take().expect("present until persisted");
        file.persist(path).map_err(|e| e.error)
        // `self` drops here: unlisted after the rename, or after the failed file's deletion.
    }
}

impl Drop for PartialFile {
    fn drop(&mut self) {
        drop(self.file.take()); // deletes the file unless persisted
        unregister(&self.path);
    }
}

impl Write for PartialFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.inner().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner().flush()
    }
}

impl Seek for PartialFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner().seek(pos)
    }
}

/// A temporary folder beside its final name, deleted (with its contents) when dropped unless
/// published ([`super::publish_dir`]).
pub struct PartialDir {
    path: PathBuf,
    published: bool,
}

impl PartialDir {
    /// A new empty folder in `parent` (mode 0755 before the umask).
    pub(crate) fn new_in(parent: &Path) -> std::io::Result<Self> {
        let made = builder().make_in(parent, |path| {
            register(path);
            let mut b = std::fs::DirBuilder::new();
            #[cfg(unix)]
            std::os::unix::fs::DirBuilderExt::mode(&mut b, 0o755);
            b.create(path).inspect_err(|_| unregister(path))
        })?;
        // The folder is ours to delete (tempfile would try to remove it as a file).
        let path = made
            .into_temp_path()
            .keep()
            .map_err(|e| std::io::Error::other(e.error))?;
        Ok(Self {
            path,
            published: false,
        })
    }

    /// Where the folder is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the folder to `path`; on failure it is deleted.
    pub(crate) fn publish(mut self, path: &Path) -> std::io::Result<()> {
        std::fs::rename(&self.path, path)?;
        self.published = true;
        Ok(())
    }
}

impl Drop for PartialDir {
    fn drop(&mut self) {
        if !self.published {
            let _ = std::fs::remove_dir_all(&self.path);
        }
        unregister(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporaries_are_listed_while_they_exist() {
        let dir = tempfile::tempdir().unwrap();
        let mut f = PartialFile::new_in(dir.path()).unwrap();
        let d = PartialDir::new_in(dir.path()).unwrap();
        assert!(registry().iter().any(|p| p == d.path()));
        f.write_all(b"x").unwrap();
        let tmp_name = f.path.clone();
        f.persist(&dir.path().join("out")).unwrap();
        assert!(!tmp_name.exists() && dir.path().join("out").exists());
        assert!(!registry().contains(&tmp_name), "unlisted once renamed");
        let kept = d.path().to_path_buf();
        std::fs::write(kept.join("inner"), b"y").unwrap();
        drop(d);
        assert!(
            !kept.exists(),
            "dropped unpublished: deleted with its contents"
        );
        assert!(!registry().contains(&kept), "unlisted once deleted");
    }
}
