//! Reading and writing BTFs on disk: the Bonn UBO2003/ATRIUM layout (zip or folder of
//! JPEG/PNG/EXR images), RTI folders with a `.lp` light file and single images. Every output is
//! written atomically through [`crate::io`] (temporary name, then rename), so that no
//! half-written output is ever left as if complete.

mod export;
mod photo;
pub mod picture;
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

pub use self::picture::ImageFormat;
use crate::io::{parent_dir, write_file_atomic};
pub use export::write_btf;
pub use ubo2003::write_ubo2003;

/// The largest file this library reads into memory at once (an image or a `.lp` file).
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Memory reserved up front for a read: sizes declared in headers are not trusted beyond it
/// (a larger file grows the buffer as real bytes arrive).
const MAX_RESERVE: u64 = 64 << 20;

/// Opens a BTF: a zip archive (UBO2003, or RTI with a `.lp` member), a UBO2003 folder, an RTI
/// folder, an RTI `.lp` file, or a photograph (a PNG/JPEG/EXR file, or a folder holding one):
/// see [`photo`].
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
    if let Some(lp) = rti::find_lp_member(&zip)? {
        return rti::open_zip(zip, &lp);
    }
    ubo2003::open(zip)
}

/// A place holding named files: a zip archive or a folder.
pub(crate) enum Container {
    /// A zip archive; members are read under a lock and decoded outside it.
    Zip {
        path: PathBuf,
        archive: Mutex<ZipArchive<BufReader<File>>>,
    },
    /// A folder on disk; when `confined`, members resolve inside it ([`member_path`]).
    Dir { root: PathBuf, confined: bool },
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

    /// A BTF's folder: members named by its files stay inside it (unless
    /// [`ALLOW_OUTSIDE_ENV`] says otherwise).
    pub(crate) fn dir(root: &Path) -> Self {
        Container::Dir {
            root: root.to_path_buf(),
            confined: !outside_allowed(),
        }
    }

    /// The folder of a file the user named directly: no confinement to check.
    pub(crate) fn user_dir(root: &Path) -> Self {
        Container::Dir {
            root: root.to_path_buf(),
            confined: false,
        }
    }

    /// Where the container is, for messages.
    pub(crate) fn location(&self) -> String {
        match self {
            Container::Zip { path, .. } => path.display().to_string(),
            Container::Dir { root, .. } => root.display().to_string(),
        }
    }

    /// A member's name as a user should read it in a message.
    pub(crate) fn describe(&self, name: &str) -> String {
        match self {
            Container::Zip { path, .. } => format!("{}: {name}", path.display()),
            Container::Dir { root, .. } => root.join(name).display().to_string(),
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
            Container::Dir { root, .. } => {
                // Files and links (a link is checked like any member when it is read: one
                // rule for UBO folders and RTI lists).
                let mut names = Vec::new();
                for entry in std::fs::read_dir(root).map_err(|e| BtfError::io(root, e))? {
                    let entry = entry.map_err(|e| BtfError::io(root, e))?;
                    let kind = entry.file_type().ok();
                    let is_file = kind.is_some_and(|t| t.is_file())
                        || kind.is_some_and(|t| t.is_symlink()) && entry.path().is_file();
                    if is_file {
                        names.push(entry.file_name().to_string_lossy().into_owned());
                    }
                }
                names.sort();
                Ok(names)
            }
        }
    }

    /// Fails when a folder's member resolves outside a confined folder ([`member_path`]).
    pub(crate) fn check_inside(&self, name: &str) -> Result<()> {
        match self {
            Container::Dir { root, confined } => member_path(root, name, *confined).map(drop),
            Container::Zip { .. } => Ok(()),
        }
    }

    /// Reads a member whole (at most [`MAX_FILE_BYTES`]), or only its first `prefix` bytes.
    pub(crate) fn read(&self, name: &str, prefix: Option<u64>) -> Result<Vec<u8>> {
        match prefix {
            Some(n) => self.read_at_most(name, n.min(MAX_FILE_BYTES), false),
            None => self.read_at_most(name, MAX_FILE_BYTES, true),
        }
    }

    /// The first `limit` bytes of a member; with `whole`, a member longer than `limit` (by its
    /// declared size or by the bytes that arrive) is an error instead. Memory is bounded by
    /// `limit`, whatever a zip header declares.
    fn read_at_most(&self, name: &str, limit: u64, whole: bool) -> Result<Vec<u8>> {
        let too_big = |len: String| {
            BtfError::image(
                self.describe(name),
                format!("file of {len} bytes exceeds the {limit}-byte limit for it"),
            )
        };
        // One byte past the limit tells a member that is too long from one that fits exactly.
        let take = if whole { limit + 1 } else { limit };
        let mut buf = Vec::new();
        match self {
            Container::Zip { path, archive } => {
                let mut archive = archive.lock().unwrap_or_else(|p| p.into_inner());
                let mut member = archive.by_name(name).map_err(|source| BtfError::Zip {
                    path: path.clone(),
                    source,
                })?;
                if whole && member.size() > limit {
                    return Err(too_big(member.size().to_string()));
                }
                buf.reserve(member.size().min(take).min(MAX_RESERVE) as usize);
                (&mut member)
                    .take(take)
                    .read_to_end(&mut buf)
                    .map_err(|e| {
                        BtfError::image(
                            self.describe(name),
                            format!("corrupt archive member ({e})"),
                        )
                    })?;
            }
            Container::Dir { root, confined } => {
                let path = member_path(root, name, *confined)?;
                let file = File::open(&path).map_err(|e| BtfError::io(&path, e))?;
                let len = file.metadata().map_err(|e| BtfError::io(&path, e))?.len();
                if whole && len > limit {
                    return Err(too_big(len.to_string()));
                }
                buf.reserve(len.min(take).min(MAX_RESERVE) as usize);
                file.take(take)
                    .read_to_end(&mut buf)
                    .map_err(|e| BtfError::io(&path, e))?;
            }
        }
        if whole && buf.len() as u64 > limit {
            return Err(too_big(format!("more than {limit}")));
        }
        Ok(buf)
    }

    /// Width and height of an image member from its header (reads a prefix, the whole file
    /// only when the header does not fit in it).
    pub(crate) fn probe_image(&self, name: &str) -> Result<(u32, u32)> {
        self.probe_with_head(name).map(|(size, _)| size)
    }

    /// The header's size and the prefix read for it (the whole file when it is shorter than
    /// [`PROBE_PREFIX`]).
    fn probe_with_head(&self, name: &str) -> Result<((u32, u32), Vec<u8>)> {
        let file = self.describe(name);
        let head = self.read(name, Some(PROBE_PREFIX))?;
        match picture::probe_size(&head, &file) {
            Err(BtfError::Image { .. }) if head.len() as u64 == PROBE_PREFIX => {
                Ok((picture::probe_size(&self.read(name, None)?, &file)?, head))
            }
            other => Ok((other?, head)),
        }
    }

    /// Decodes an image member into planar `(3, h, w)` linear RGB. The member is read only up
    /// to what an image of its declared size can need ([`picture::max_file_bytes`]): a small
    /// image followed by a gigabyte of padding is refused, not loaded.
    pub(crate) fn load_image(&self, name: &str) -> Result<Array3<f32>> {
        let ((w, h), head) = self.probe_with_head(name)?;
        let bytes = if (head.len() as u64) < PROBE_PREFIX {
            head // the whole file already
        } else {
            self.read_at_most(name, picture::max_file_bytes(w, h), true)?
        };
        picture::decode(&bytes, &self.describe(name))
    }
}

/// How much of an image is read to find its size in the header.
const PROBE_PREFIX: u64 = 256 * 1024;

/// Whether the images a set names may lie outside its folder (`../x`, absolute paths, links
/// out): never, unless this environment variable is `1`.
pub const ALLOW_OUTSIDE_ENV: &str = "BTFMRF_ALLOW_OUTSIDE";

fn outside_allowed() -> bool {
    std::env::var_os(ALLOW_OUTSIDE_ENV).is_some_and(|v| v == "1")
}

/// The file `name` inside `root`; when `confined`, its canonical path (links resolved) must lie
/// inside the canonical `root`, so that a hostile list cannot make us read `/etc/shadow`.
pub(crate) fn member_path(root: &Path, name: &str, confined: bool) -> Result<PathBuf> {
    let path = root.join(name);
    if !confined {
        return Ok(path);
    }
    let outside = |why: &str| {
        BtfError::layout(
            root.display(),
            format!(
                "'{name}' {why}; images must stay inside the set's folder \
                 (set {ALLOW_OUTSIDE_ENV}=1 to allow it)"
            ),
        )
    };
    if Path::new(name).is_absolute() {
        return Err(outside("is an absolute path"));
    }
    let base = root.canonicalize().map_err(|e| BtfError::io(root, e))?;
    let real = path.canonicalize().map_err(|e| BtfError::io(&path, e))?;
    if !real.starts_with(&base) {
        return Err(outside("lies outside the folder"));
    }
    Ok(real)
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
    let bytes = picture::encode(image, format, &name)?;
    Ok(write_file_atomic(path, &bytes)?)
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
    Container::user_dir(parent).load_image(&name)
}
