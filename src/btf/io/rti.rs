//! RTI captures: a folder of photographs under one fixed view (straight down) and N lights,
//! described by a `.lp` light-position file. Such a capture is a BTF with one view: a
//! fixed-view reflectance field.
//!
//! The `.lp` format: the first line holds the number of images N; then one line per image,
//! `name lx ly lz`: a path relative to the folder and the direction towards the light (x right,
//! y up in the image, z out of the surface). Real files are untidy; we trust the lines over the
//! count, normalise the vectors, keep grazing lights (z <= 0), skip blank lines and trailing
//! spaces, and report every deviation as a warning.
//!
//! A capture is read from a folder or from a zip archive holding the `.lp` file, and written
//! back ([`write_rti`]) when its light directions are not in whole degrees, which the UBO2003
//! names need.

use std::path::{Path, PathBuf};

use ndarray::Array3;

use super::{Container, ImageFormat};
use crate::btf::dataset::{Btf, ImageSource};
use crate::btf::directions::{Direction, DirectionSet};
use crate::btf::error::{BtfError, Result};
use crate::progress::Progress;

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
    let lp = parse_lp(&String::from_utf8_lossy(&bytes), lp_path)?;
    let root = crate::io::parent_dir(lp_path);
    for name in &lp.images {
        let p = root.join(name);
        if !p.is_file() {
            return Err(BtfError::layout(
                lp_path.display(),
                format!("lists image '{name}', but {} does not exist", p.display()),
            ));
        }
    }
    from_parts(Container::dir(root), lp, lp_path.display().to_string())
}

/// The `.lp` member of a zip archive: `dirs.lp` if present, else the only `*.lp` member;
/// `None` when there is none (a UBO2003 archive).
pub(crate) fn find_lp_member(zip: &Container) -> Result<Option<String>> {
    let mut found: Vec<String> = zip
        .names()?
        .into_iter()
        .filter(|n| n.to_ascii_lowercase().ends_with(".lp"))
        .collect();
    if let Some(k) = found.iter().position(|n| n == LP_NAME) {
        return Ok(Some(found.swap_remove(k)));
    }
    match found.len() {
        0 | 1 => Ok(found.pop()),
        _ => Err(BtfError::layout(
            zip.location(),
            "several .lp members; keep one",
        )),
    }
}

/// Opens an RTI capture held in a zip archive whose `.lp` member is `lp_name`; image names
/// are relative to that member's folder in the archive.
pub(crate) fn open_zip(zip: Container, lp_name: &str) -> Result<Btf> {
    let label = zip.describe(lp_name);
    let mut lp = parse_lp(
        &String::from_utf8_lossy(&zip.read(lp_name, None)?),
        Path::new(&label),
    )?;
    let folder = lp_name.rsplit_once('/').map_or("", |(dir, _)| dir);
    let members: std::collections::HashSet<String> = zip.names()?.into_iter().collect();
    for name in &mut lp.images {
        if !folder.is_empty() {
            *name = format!("{folder}/{name}");
        }
        if !members.contains(name.as_str()) {
            return Err(BtfError::layout(
                &label,
                format!("lists image '{name}', which the archive does not hold"),
            ));
        }
    }
    from_parts(zip, lp, label)
}

/// The BTF of a parsed `.lp` file whose images `container` holds.
fn from_parts(container: Container, lp: LightPositions, label: String) -> Result<Btf> {
    for name in &lp.images {
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
        label,
        DirectionSet::zenith(),
        lights,
        width,
        height,
        Box::new(source),
    )?;
    Ok(btf.with_warnings(lp.warnings))
}

/// The light file's name in the RTI captures this library writes.
pub const LP_NAME: &str = "dirs.lp";

/// Whether `btf` fits the RTI layout: one view, at the zenith (the reader assumes it).
pub fn is_fixed_view(btf: &Btf) -> bool {
    btf.views().len() == 1 && btf.views().as_slice()[0].theta_deg.abs() < 1e-9
}

/// The text of a `.lp` file for `images` lit from `lights`: the count, then one line
/// `name lx ly lz` per image with the unit vector towards the light, each coordinate in the
/// shortest decimal that reads back as the same `f64`.
pub fn format_lp(images: &[String], lights: &DirectionSet) -> String {
    let mut text = format!("{}\n", images.len());
    for (name, d) in images.iter().zip(lights.iter()) {
        let [x, y, z] = d.vector();
        text.push_str(&format!("{name} {x:?} {y:?} {z:?}\n"));
    }
    text
}

/// Writes a fixed-view BTF as an RTI capture readable by [`open`]: images `000.png`,
/// `001.png`, ... (in light order, in `format`) and [`LP_NAME`] with the exact light
/// vectors, as a zip archive when `out` ends in `.zip`, otherwise as a new folder. For light
/// directions that are not in whole degrees, which the UBO2003 names cannot hold.
///
/// # Errors
/// More than one view or a view off the zenith, unreadable source images, an existing output
/// folder, or an unwritable destination.
pub fn write_rti(
    btf: &Btf,
    out: &Path,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    if !is_fixed_view(btf) {
        return Err(BtfError::parameter(
            "directions",
            format!(
                "an RTI capture holds one view at the zenith; this BTF has {} view(s)",
                btf.views().len()
            ),
        ));
    }
    let digits = (btf.lights().len().max(1) - 1).to_string().len().max(3);
    let names: Vec<String> = (0..btf.lights().len())
        .map(|i| format!("{i:0digits$}.{}", format.extension()))
        .collect();
    let lp = format_lp(&names, btf.lights());
    super::ubo2003::write_images(
        btf,
        out,
        &names,
        Some((LP_NAME, lp.as_bytes())),
        format,
        progress,
    )
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
