//! Reading and writing BTFs on disk: the Bonn UBO2003/ATRIUM layout (zip or folder of
//! JPEG/PNG/EXR images), RTI folders with a `.lp` light file, single images, and atomic writes
//! (temporary name, then rename) so that no half-written output is ever left as if complete.

pub(crate) mod envelope;
pub mod image;
mod photo;
pub mod rti;
pub mod ubo2003;

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use ndarray::Array3;
use zip::ZipArchive;

use super::dataset::Btf;
use super::error::{BtfError, Result};

pub use self::image::ImageFormat;
pub use ubo2003::write_ubo2003;

/// The largest file this library reads into memory at once (an image or a `.lp` file).
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Memory reserved up front for a read: sizes declared in headers are not trusted beyond it
/// (a larger file grows the buffer as real bytes arrive).
const MAX_RESERVE: u64 = 64 << 20;

/// Opens a BTF: a zip archive, a UBO2003 folder, an RTI folder, an RTI `.lp` file, or a
/// photograph (a PNG/JPEG/EXR file, or a folder holding one): see [`photo`].
pub(crate) fn open(path: &Path) -> Result<Btf> {
    let meta = std::fs::metadata(path).map_err(|e| BtfError::io(path, e))?;
    if meta.is_dir() {
        if let Some(lp) = rti::find_lp_file(path)? {
            return rti::open(&lp);
        }
        if let Some(btf) = photo::open_folder(path)? {
            return Ok(btf);
        }
        return ubo2003::open(Container::dir(path));
    }
    let lower = path.to_string_lossy().to_ascii_lowercase();
    if lower.ends_with(".lp") {
        return rti::open(path);
    }
    if photo::is_photo(path) {
        return photo::open_file(path);
    }
    let zip = Container::zip(path).map_err(|e| match e {
        BtfError::Zip { source, .. } => BtfError::layout(
            path.display(),
            format!(
                "expected a BTF zip archive, an RTI .lp file or a PNG/JPEG/EXR photograph, \
                 but this is not a readable zip archive ({source}) nor an image"
            ),
        ),
        other => other,
    })?;
    ubo2003::open(zip)
}

/// A place holding named files: a zip archive or a folder.
pub(crate) enum Container {
    /// A zip archive; members are read under a lock and decoded outside it.
    Zip {
        path: PathBuf,
        archive: Mutex<ZipArchive<BufReader<File>>>,
    },
    /// A folder on disk.
    Dir { root: PathBuf },
}

impl Container {
    pub(crate) fn zip(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| BtfError::io(path, e))?;
        let archive = ZipArchive::new(BufReader::new(file)).map_err(|source| BtfError::Zip {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Container::Zip {
            path: path.to_path_buf(),
            archive: Mutex::new(archive),
        })
    }

    pub(crate) fn dir(root: &Path) -> Self {
        Container::Dir {
            root: root.to_path_buf(),
        }
    }

    /// Where the container is, for messages.
    pub(crate) fn location(&self) -> String {
        match self {
            Container::Zip { path, .. } => path.display().to_string(),
            Container::Dir { root } => root.display().to_string(),
        }
    }

    /// A member's name as a user should read it in a message.
    pub(crate) fn describe(&self, name: &str) -> String {
        match self {
            Container::Zip { path, .. } => format!("{}: {name}", path.display()),
            Container::Dir { root } => root.join(name).display().to_string(),
        }
    }

    /// Names of the files directly held (zip: every file member; folder: the top level).
    pub(crate) fn names(&self) -> Result<Vec<String>> {
        match self {
            Container::Zip { path, archive } => {
                let archive = archive.lock().unwrap_or_else(|p| p.into_inner());
                let mut names = Vec::with_capacity(archive.len());
                for name in archive.file_names() {
                    let name = name.map_err(|source| BtfError::Zip {
                        path: path.clone(),
                        source,
                    })?;
                    if !name.ends_with('/') {
                        names.push(name.into_owned());
                    }
                }
                Ok(names)
            }
            Container::Dir { root } => {
                let mut names = Vec::new();
                for entry in std::fs::read_dir(root).map_err(|e| BtfError::io(root, e))? {
                    let entry = entry.map_err(|e| BtfError::io(root, e))?;
                    let is_file = entry.file_type().map(|t| t.is_file()).unwrap_or(false);
                    if is_file {
                        names.push(entry.file_name().to_string_lossy().into_owned());
                    }
                }
                names.sort();
                Ok(names)
            }
        }
    }

    /// Reads a member whole (at most [`MAX_FILE_BYTES`]), or only its first `prefix` bytes.
    pub(crate) fn read(&self, name: &str, prefix: Option<u64>) -> Result<Vec<u8>> {
        let limit = prefix.unwrap_or(MAX_FILE_BYTES).min(MAX_FILE_BYTES);
        let mut buf = Vec::new();
        let too_big = |len: u64| {
            BtfError::image(
                self.describe(name),
                format!("file of {len} bytes exceeds the {MAX_FILE_BYTES}-byte limit"),
            )
        };
        match self {
            Container::Zip { path, archive } => {
                let mut archive = archive.lock().unwrap_or_else(|p| p.into_inner());
                let mut member = archive.by_name(name).map_err(|source| BtfError::Zip {
                    path: path.clone(),
                    source,
                })?;
                if prefix.is_none() && member.size() > MAX_FILE_BYTES {
                    return Err(too_big(member.size()));
                }
                buf.reserve(member.size().min(limit).min(MAX_RESERVE) as usize);
                (&mut member)
                    .take(limit)
                    .read_to_end(&mut buf)
                    .map_err(|e| {
                        BtfError::image(
                            self.describe(name),
                            format!("corrupt archive member ({e})"),
                        )
                    })?;
            }
            Container::Dir { root } => {
                let path = root.join(name);
                let file = File::open(&path).map_err(|e| BtfError::io(&path, e))?;
                let len = file.metadata().map_err(|e| BtfError::io(&path, e))?.len();
                if prefix.is_none() && len > MAX_FILE_BYTES {
                    return Err(too_big(len));
                }
                buf.reserve(len.min(limit).min(MAX_RESERVE) as usize);
                file.take(limit)
                    .read_to_end(&mut buf)
                    .map_err(|e| BtfError::io(&path, e))?;
            }
        }
        Ok(buf)
    }

    /// Width and height of an image member from its header (reads a prefix, the whole file
    /// only when the header does not fit in it).
    pub(crate) fn probe_image(&self, name: &str) -> Result<(u32, u32)> {
        const PREFIX: u64 = 256 * 1024;
        let file = self.describe(name);
        let head = self.read(name, Some(PREFIX))?;
        match image::probe_size(&head, &file) {
            Err(BtfError::Image { .. }) if head.len() as u64 == PREFIX => {
                image::probe_size(&self.read(name, None)?, &file)
            }
            other => other,
        }
    }

    /// Decodes an image member into planar `(3, h, w)` linear RGB.
    pub(crate) fn load_image(&self, name: &str) -> Result<Array3<f32>> {
        let bytes = self.read(name, None)?;
        image::decode(&bytes, &self.describe(name))
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, then a rename.
///
/// # Errors
/// The folder is not writable, or the disk is full.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let mut tmp = temp_file_beside(path)?;
    tmp.write_all(bytes)
        .and_then(|_| tmp.flush())
        .map_err(|e| BtfError::io(path, e))?;
    tmp.persist(path).map_err(|e| BtfError::io(path, e.error))?;
    Ok(())
}

/// A temporary file next to `path` (same folder, so that the final rename is atomic); it is
/// deleted if dropped before being persisted.
pub(crate) fn temp_file_beside(path: &Path) -> Result<tempfile::NamedTempFile> {
    let parent = parent_dir(path);
    partial_builder(0o644)
        .tempfile_in(parent)
        .map_err(|e| BtfError::io(parent, e))
}

/// A temporary folder next to `path`, deleted if dropped; [`publish_dir`] gives it its name.
pub fn temp_dir_beside(path: &Path) -> Result<tempfile::TempDir> {
    if path.exists() {
        return Err(BtfError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "already exists; remove it or choose another name",
            ),
        ));
    }
    let parent = parent_dir(path);
    partial_builder(0o755)
        .tempdir_in(parent)
        .map_err(|e| BtfError::io(parent, e))
}

/// Renames a completed temporary folder to `path` (removing it if that fails).
pub fn publish_dir(tmp: tempfile::TempDir, path: &Path) -> Result<()> {
    let kept = tmp.keep();
    std::fs::rename(&kept, path).map_err(|e| {
        let _ = std::fs::remove_dir_all(&kept);
        BtfError::io(path, e)
    })
}

/// Temporary names start with `.btfmrf-partial-`; finished outputs get ordinary permissions
/// (the temporary-file default, owner-only, would surprise users).
fn partial_builder(#[allow(unused_variables)] mode: u32) -> tempfile::Builder<'static, 'static> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(".btfmrf-partial-");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(mode));
    }
    builder
}

/// The folder holding `path` ("." for a bare file name).
pub(crate) fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Writes one image file (format from the extension: `.png`, `.jpg`, `.exr`), atomically.
///
/// # Errors
/// An unknown extension, an encoder failure, or an unwritable path.
pub fn write_image(path: &Path, image: &Array3<f32>) -> Result<()> {
    let name = path.display().to_string();
    let format = ImageFormat::from_name(&name).ok_or_else(|| {
        BtfError::parameter(
            "--out",
            format!("{name}: use a .png, .jpg or .exr file name"),
        )
    })?;
    let bytes = image::encode(image, format, &name)?;
    write_file_atomic(path, &bytes)
}

/// Reads one image file (PNG, JPEG or EXR) into planar `(3, h, w)` linear RGB.
///
/// # Errors
/// Unreadable, corrupt, oversized or non-finite images.
pub fn read_image(path: &Path) -> Result<Array3<f32>> {
    let parent = parent_dir(path);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| BtfError::parameter("path", format!("{} is not a file", path.display())))?;
    Container::dir(parent).load_image(&name)
}
