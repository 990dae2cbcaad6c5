//! RTI captures: a folder of photographs under one fixed view (straight down) and N lights,
//! described by a `.lp` light-position file. Such a capture is a BTF with one view: a
//! fixed-view reflectance field.
//!
//! The `.lp` format: the first line holds the number of images N; then one line per image,
//! `name lx ly lz`: a path relative to the folder and the direction towards the light (x right,
//! y up in the image, z out of the surface). Real files are untidy; we trust the lines over the
//! count, normalise the vectors, keep grazing lights (z <= 0), skip blank lines and trailing
//! spaces, and report every deviation as a warning.

use std::path::{Path, PathBuf};

use ndarray::Array3;

use super::Container;
use crate::btf::dataset::{Btf, ImageSource};
use crate::btf::directions::{Direction, DirectionSet};
use crate::btf::error::{BtfError, Result};

/// One parsed `.lp` file.
#[derive(Debug, Clone, PartialEq)]
pub struct LightPositions {
    /// Image paths relative to the `.lp` file's folder, in file order.
    pub images: Vec<String>,
    /// Unit vectors towards the light, one per image.
    pub directions: Vec<[f64; 3]>,
    /// Things that were odd but tolerated (count mismatch, non-unit vectors, grazing lights).
    pub warnings: Vec<String>,
}

/// Parses the text of a `.lp` file; `path` is only used in messages.
///
/// # Errors
/// No images listed, a line without three numbers after the name, a zero or non-finite vector.
pub fn parse_lp(text: &str, path: &Path) -> Result<LightPositions> {
    let err = |line: usize, reason: String| BtfError::LightPositions {
        path: path.to_path_buf(),
        line,
        reason,
    };
    // Editors on Windows start files with a UTF-8 byte-order mark: not part of the count.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty());
    let (count_line, count_text) = lines
        .next()
        .ok_or_else(|| err(1, "empty file: expected the number of images".into()))?;
    let declared: usize = count_text.parse().map_err(|_| {
        err(
            count_line,
            format!("expected the number of images, found '{count_text}'"),
        )
    })?;
    let mut out = LightPositions {
        images: Vec::new(),
        directions: Vec::new(),
        warnings: Vec::new(),
    };
    let mut grazing = 0usize;
    let mut non_unit = 0usize;
    for (n, line) in lines {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() < 4 {
            return Err(err(n, format!("expected 'image lx ly lz', found '{line}'")));
        }
        let (name_fields, nums) = fields.split_at(fields.len() - 3);
        let mut v = [0.0f64; 3];
        for (slot, text) in v.iter_mut().zip(nums) {
            *slot = text
                .parse()
                .map_err(|_| err(n, format!("'{text}' is not a number")))?;
        }
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if !len.is_finite() || len < 1e-9 {
            return Err(err(
                n,
                format!(
                    "light vector ({}, {}, {}) has no direction",
                    v[0], v[1], v[2]
                ),
            ));
        }
        if (len - 1.0).abs() > 1e-3 {
            non_unit += 1;
        }
        let v = v.map(|c| c / len);
        if v[2] <= 0.0 {
            grazing += 1;
        }
        out.images.push(name_fields.join(" "));
        out.directions.push(v);
    }
    if out.images.is_empty() {
        return Err(err(count_line, "no images listed".into()));
    }
    if declared != out.images.len() {
        out.warnings.push(format!(
            "{}: header says {declared} images but {} are listed; using the listed ones",
            path.display(),
            out.images.len()
        ));
    }
    if non_unit > 0 {
        out.warnings.push(format!(
            "{}: {non_unit} light vector(s) were not unit length and were normalised",
            path.display()
        ));
    }
    if grazing > 0 {
        out.warnings.push(format!(
            "{}: {grazing} light(s) at or below the horizon (z <= 0) kept as they are",
            path.display()
        ));
    }
    Ok(out)
}

/// The `.lp` file in a folder: `dirs.lp` if present, else the only `*.lp` file.
pub(crate) fn find_lp_file(dir: &Path) -> Result<Option<PathBuf>> {
    let preferred = dir.join("dirs.lp");
    if preferred.is_file() {
        return Ok(Some(preferred));
    }
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| BtfError::io(dir, e))? {
        let entry = entry.map_err(|e| BtfError::io(dir, e))?;
        let p = entry.path();
        if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("lp")) && p.is_file() {
            found.push(p);
        }
    }
    match found.len() {
        0 => Ok(None),
        1 => Ok(found.pop()),
        _ => Err(BtfError::layout(
            dir.display(),
            "several .lp files; name the one to use",
        )),
    }
}

struct RtiSource {
    container: Container,
    images: Vec<String>,
}

impl ImageSource for RtiSource {
    fn load(&self, _view: usize, light: usize) -> Result<Array3<f32>> {
        self.container.load_image(&self.images[light])
    }

    fn describe(&self, _view: usize, light: usize) -> String {
        self.container.describe(&self.images[light])
    }
}

/// Opens an RTI capture from its `.lp` file: one view (the zenith), one light per listed image.
pub(crate) fn open(lp_path: &Path) -> Result<Btf> {
    let bytes = Container::user_dir(crate::io::parent_dir(lp_path)).read(
        &lp_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        None,
    )?;
    let text = String::from_utf8_lossy(&bytes);
    let lp = parse_lp(&text, lp_path)?;
    let root = crate::io::parent_dir(lp_path);
    let container = Container::dir(root);
    for name in &lp.images {
        let p = root.join(name);
        if !p.is_file() {
            return Err(BtfError::layout(
                lp_path.display(),
                format!("lists image '{name}', but {} does not exist", p.display()),
            ));
        }
        container.check_inside(name)?;
    }
    let (width, height) = super::ubo2003::common_size(&container, &lp.images)?;
    let lights = DirectionSet::new(
        lp.directions
            .iter()
            .map(|v| Direction::from_vector(*v).expect("normalised, finite"))
            .collect(),
    )?;
    let source = RtiSource {
        container,
        images: lp.images,
    };
    let btf = Btf::from_source(
        lp_path.display().to_string(),
        DirectionSet::zenith(),
        lights,
        width,
        height,
        Box::new(source),
    )?;
    Ok(btf.with_warnings(lp.warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerates_real_world_quirks() {
        let text = "3\nimg a.jpg 0 0 2 \n b.jpg 1 0 0\n\nc.jpg 0.6 0 0.8\nd.jpg 0 0.1 -0.01\n\n\n";
        let lp = parse_lp(text, Path::new("x.lp")).unwrap();
        assert_eq!(lp.images, ["img a.jpg", "b.jpg", "c.jpg", "d.jpg"]);
        assert_eq!(lp.directions[0], [0.0, 0.0, 1.0]);
        assert!((lp.directions[3][2] + 0.0995).abs() < 1e-3);
        // Count mismatch, non-unit vectors and grazing lights are each reported once.
        assert_eq!(lp.warnings.len(), 3, "{:?}", lp.warnings);
    }

    #[test]
    fn rejects_what_cannot_be_guessed() {
        let p = Path::new("x.lp");
        assert!(parse_lp("", p).is_err());
        assert!(parse_lp("2\n", p).is_err());
        assert!(parse_lp("two\na.jpg 0 0 1\n", p).is_err());
        let e = parse_lp("1\na.jpg 0 0\n", p).unwrap_err().to_string();
        assert!(e.contains("x.lp:2"), "{e}");
        assert!(parse_lp("1\na.jpg 0 0 0\n", p).is_err());
        assert!(parse_lp("1\na.jpg nan 0 1\n", p).is_err());
    }
}
