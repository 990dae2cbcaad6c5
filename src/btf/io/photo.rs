//! Photographs as input (issue 11, item 2): a single PNG, JPEG or EXR file, or a folder that
//! holds exactly one image and no light file, opens as a BTF of one view and one light, both
//! straight down (the photographer's camera and light are unknown; the zenith is the honest
//! default, and a one-light BTF makes no claim about other directions).
//!
//! A folder of several photographs without light directions is refused: the photographs may
//! be of different things, and even of one thing their lights are unknown, so calling them N
//! lights of one BTF would invent directions that photometric stereo and relighting would then
//! trust. The error says what to give instead (one photograph, or a `.lp` light file).

use std::path::Path;

use ndarray::Array3;

use super::{Container, ImageFormat};
use crate::btf::dataset::{Btf, ImageSource};
use crate::btf::directions::DirectionSet;
use crate::btf::error::{BtfError, Result};

/// Magic numbers of the image formats read here: PNG, JPEG, OpenEXR.
const MAGICS: [&[u8]; 3] = [b"\x89PNG", b"\xff\xd8\xff", &[0x76, 0x2f, 0x31, 0x01]];

/// Whether a file is a photograph: an image extension, or an image format's first bytes.
pub(crate) fn is_photo(path: &Path) -> bool {
    if ImageFormat::from_name(&path.to_string_lossy()).is_some() {
        return true;
    }
    let mut head = [0u8; 4];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
        .is_ok_and(|()| MAGICS.iter().any(|m| head.starts_with(m)))
}

/// Opens one photograph as a one-view, one-light BTF.
///
/// # Errors
/// The file cannot be read or decoded (the error names it).
pub(crate) fn open_file(path: &Path) -> Result<Btf> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    one_image(Container::user_dir(crate::io::parent_dir(path)), name, path)
}

/// Opens a folder without a light file as a photograph when none of its images carries a
/// UBO2003 name: `None` when some do (the folder is a UBO2003 BTF, read elsewhere).
///
/// # Errors
/// The folder holds several photographs (not a BTF: their lights are unknown), or its one
/// image cannot be read.
pub(crate) fn open_folder(dir: &Path) -> Result<Option<Btf>> {
    let container = Container::dir(dir);
    let images: Vec<String> = container
        .names()?
        .into_iter()
        .filter(|n| !n.starts_with('.') && ImageFormat::from_name(n).is_some())
        .collect();
    if images.is_empty()
        || images
            .iter()
            .any(|n| super::ubo2003::parse_name(n).is_some())
    {
        return Ok(None);
    }
    if images.len() > 1 {
        return Err(BtfError::layout(
            dir.display(),
            format!(
                "{} photographs ('{}', '{}', ...) but no light directions: several photographs \
                 are not one BTF. Give a single photograph, or add a dirs.lp file listing \
                 'image lx ly lz' per image (an RTI capture)",
                images.len(),
                images[0],
                images[1]
            ),
        ));
    }
    let name = images.into_iter().next().expect("one image");
    one_image(container, name, dir).map(Some)
}

fn one_image(container: Container, name: String, label: &Path) -> Result<Btf> {
    let (width, height) = super::ubo2003::common_size(&container, std::slice::from_ref(&name))?;
    Btf::from_source(
        label.display().to_string(),
        DirectionSet::zenith(),
        DirectionSet::zenith(),
        width,
        height,
        Box::new(Photo { container, name }),
    )
}

/// The single image of a photograph BTF.
struct Photo {
    container: Container,
    name: String,
}

impl ImageSource for Photo {
    fn load(&self, _view: usize, _light: usize) -> Result<Array3<f32>> {
        self.container.load_image(&self.name)
    }

    fn describe(&self, _view: usize, _light: usize) -> String {
        self.container.describe(&self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, w: u32, h: u32) {
        let image = Array3::from_shape_fn((3, h as usize, w as usize), |(c, y, x)| {
            ((x + 2 * y + c) % 7) as f32 / 7.0
        });
        super::super::write_image(path, &image).unwrap();
    }

    #[test]
    fn a_photograph_is_one_view_one_light_at_the_zenith() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("photo.png");
        write_png(&path, 40, 24);
        for btf in [
            super::super::open(&path).unwrap(),
            super::super::open(dir.path()).unwrap(),
        ] {
            assert_eq!((btf.views().len(), btf.lights().len()), (1, 1));
            assert_eq!((btf.width(), btf.height()), (40, 24));
            assert_eq!(btf.image(0, 0).unwrap().dim(), (3, 24, 40));
        }
        // An image under another name is still recognised by its first bytes.
        let renamed = dir.path().join("photo.data");
        std::fs::copy(&path, &renamed).unwrap();
        assert!(is_photo(&renamed));
        assert_eq!(super::super::open(&renamed).unwrap().width(), 40);
    }

    #[test]
    fn several_photographs_without_directions_are_refused_clearly() {
        let dir = tempfile::tempdir().unwrap();
        write_png(&dir.path().join("a.png"), 8, 8);
        write_png(&dir.path().join("b.jpg"), 8, 8);
        let e = super::super::open(dir.path()).err().unwrap().to_string();
        assert!(e.contains("2 photographs") && e.contains("dirs.lp"), "{e}");
    }

    #[test]
    fn an_undecodable_photograph_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.png");
        std::fs::write(&path, b"\x89PNG not really").unwrap();
        let e = super::super::open(&path).err().unwrap().to_string();
        assert!(e.contains("broken.png"), "{e}");
    }
}
