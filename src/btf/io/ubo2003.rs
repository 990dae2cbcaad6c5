//! The Bonn UBO2003 / ATRIUM layout: one image per (view, light) pair, named
//! `<anything>tl<θl:03> pl<φl:03> tv<θv:03> pv<φv:03>.jpg` (whole degrees), in a zip archive
//! or a folder. We read JPEG, PNG and EXR members and write the same layout.

use std::collections::HashMap;
use std::io::{Seek, Write};
use std::path::Path;

use ndarray::Array3;
use rayon::prelude::*;

use super::Container;
use super::picture::{self, ImageFormat};
use crate::btf::dataset::{Btf, ImageSource};
use crate::btf::directions::{Direction, DirectionSet};
use crate::btf::error::{BtfError, Result};
use crate::progress::Progress;

/// The four whole-degree angles in a UBO2003 file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct UboAngles {
    /// Light elevation, degrees.
    pub theta_l: u32,
    /// Light azimuth, degrees.
    pub phi_l: u32,
    /// View elevation, degrees.
    pub theta_v: u32,
    /// View azimuth, degrees.
    pub phi_v: u32,
}

impl UboAngles {
    /// The view direction.
    pub fn view(&self) -> Direction {
        Direction::new(f64::from(self.theta_v), f64::from(self.phi_v))
    }

    /// The light direction.
    pub fn light(&self) -> Direction {
        Direction::new(f64::from(self.theta_l), f64::from(self.phi_l))
    }
}

/// Parses the angles of a UBO2003 image name (any folder prefix and leading text allowed;
/// the separators between the four fields may be spaces or underscores).
///
/// Returns `None` when the name does not end in the pattern or the extension is not an image.
pub fn parse_name(name: &str) -> Option<UboAngles> {
    let base = name.rsplit(['/', '\\']).next()?;
    ImageFormat::from_name(base)?;
    let stem = &base[..base.rfind('.')?];
    let lower = stem.to_ascii_lowercase();
    // Read the four fields backwards from the end of the stem.
    let mut rest = lower.as_str();
    let mut values = [0u32; 4];
    for (slot, key) in [(3, "pv"), (2, "tv"), (1, "pl"), (0, "tl")] {
        rest = rest.trim_end_matches([' ', '_', '-']);
        let digits = rest.len() - rest.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        if digits == 0 || digits > 3 {
            return None;
        }
        values[slot] = rest[rest.len() - digits..].parse().ok()?;
        rest = rest[..rest.len() - digits].strip_suffix(key)?;
    }
    let [theta_l, phi_l, theta_v, phi_v] = values;
    Some(UboAngles {
        theta_l,
        phi_l,
        theta_v,
        phi_v,
    })
}

/// The UBO2003 name of image number `index`, e.g. `00017 tl015 pl060 tv000 pv000.jpg`.
pub fn format_name(index: usize, angles: &UboAngles, format: ImageFormat) -> String {
    format!(
        "{index:05} tl{:03} pl{:03} tv{:03} pv{:03}.{}",
        angles.theta_l,
        angles.phi_l,
        angles.theta_v,
        angles.phi_v,
        format.extension()
    )
}

/// Images of a validated UBO2003 container, view-major.
struct UboSource {
    container: Container,
    lights: usize,
    names: Vec<String>,
}

impl ImageSource for UboSource {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>> {
        self.container
            .load_image(&self.names[view * self.lights + light])
    }

    fn describe(&self, view: usize, light: usize) -> String {
        self.container
            .describe(&self.names[view * self.lights + light])
    }
}

/// Opens and validates a UBO2003 zip or folder: every name parses, every (view, light) pair is
/// present exactly once, every image header is readable and of one size.
pub(crate) fn open(container: Container) -> Result<Btf> {
    let location = container.location();
    let mut entries = Vec::new();
    for name in container.names()? {
        let base = name.rsplit('/').next().unwrap_or(&name);
        if base.starts_with('.') || name.starts_with("__MACOSX/") {
            continue; // hidden files and macOS resource forks are not images
        }
        if ImageFormat::from_name(base).is_none() {
            continue; // text files, thumbnails databases, ... are not part of the BTF
        }
        let angles = parse_name(&name).ok_or_else(|| {
            BtfError::layout(
                container.describe(&name),
                "image name does not end in the UBO2003 pattern 'tl<θ> pl<φ> tv<θ> pv<φ>'",
            )
        })?;
        check_range(&angles).map_err(|e| BtfError::layout(container.describe(&name), e))?;
        entries.push((name, angles));
    }
    if entries.is_empty() {
        return Err(BtfError::layout(
            &location,
            "no UBO2003-named images (e.g. '00000 tl000 pl000 tv000 pv000.jpg') and no .lp light file",
        ));
    }
    let (views, lights) = direction_sets(&entries, &location)?;
    let (view_index, light_index) = (index_of(&views), index_of(&lights));
    // Time and memory linear in the number of members: a map of the pairs present, never a
    // table of every (view, light) pair (a hostile archive names thousands of each).
    let mut slots: HashMap<(usize, usize), usize> = HashMap::with_capacity(entries.len());
    for (k, (name, angles)) in entries.iter().enumerate() {
        // The sets were built from these very names, so both lookups succeed.
        let not_in_set = || BtfError::layout(container.describe(name), "direction not in the set");
        let v = *view_index
            .get(&key(angles.theta_v, angles.phi_v))
            .ok_or_else(not_in_set)?;
        let l = *light_index
            .get(&key(angles.theta_l, angles.phi_l))
            .ok_or_else(not_in_set)?;
        if let Some(prev) = slots.insert((v, l), k) {
            return Err(BtfError::layout(
                container.describe(name),
                format!(
                    "duplicate direction: the same view and light as '{}'",
                    entries[prev].0
                ),
            ));
        }
    }
    let total = views.len().saturating_mul(lights.len());
    if slots.len() < total {
        // The first few missing pairs, for the message: at most slots.len() + 5 pairs visited.
        let shown: Vec<String> = (0..total)
            .map(|i| (i / lights.len(), i % lights.len()))
            .filter(|vl| !slots.contains_key(vl))
            .take(5)
            .map(|(v, l)| {
                let (v, l) = (views.as_slice()[v], lights.as_slice()[l]);
                format!(
                    "tl{:03} pl{:03} tv{:03} pv{:03}",
                    l.theta_deg, l.phi_deg, v.theta_deg, v.phi_deg
                )
            })
            .collect();
        let missing = total - slots.len();
        return Err(BtfError::layout(
            &location,
            format!(
                "{missing} of {total} (view, light) images missing, e.g. {}{}",
                shown.join(", "),
                if missing > shown.len() { ", ..." } else { "" }
            ),
        ));
    }
    let mut names = vec![String::new(); total];
    for ((v, l), k) in slots {
        names[v * lights.len() + l] = entries[k].0.clone();
    }
    let (width, height) = common_size(&container, &names)?;
    let source = UboSource {
        container,
        lights: lights.len(),
        names,
    };
    Btf::from_source(location, views, lights, width, height, Box::new(source))
}

/// Elevations above 90 degrees and azimuths of 360 or more are not directions a name may hold
/// (`pv400` would otherwise be read as azimuth 40).
fn check_range(a: &UboAngles) -> std::result::Result<(), String> {
    for (field, value, max) in [
        ("tl", a.theta_l, 90),
        ("pl", a.phi_l, 359),
        ("tv", a.theta_v, 90),
        ("pv", a.phi_v, 359),
    ] {
        if value > max {
            return Err(format!(
                "angle {field}{value:03} is out of range (elevations 0..=90, azimuths 0..=359)"
            ));
        }
    }
    Ok(())
}

/// One key per whole-degree direction: at the zenith every azimuth is the same direction.
fn key(theta: u32, phi: u32) -> (u32, u32) {
    (theta, if theta == 0 { 0 } else { phi })
}

/// Index of each whole-degree direction of a set, by [`key`].
fn index_of(set: &DirectionSet) -> HashMap<(u32, u32), usize> {
    set.iter()
        .enumerate()
        .map(|(i, d)| (key(d.theta_deg.round() as u32, d.phi_deg.round() as u32), i))
        .collect()
}

/// The view and light sets: the Bonn sets when the directions found are Bonn directions and
/// cover most of them (so a missing image is reported as missing rather than shrinking the
/// set), otherwise exactly the directions found, sorted by theta, then phi.
fn direction_sets(
    entries: &[(String, UboAngles)],
    location: &str,
) -> Result<(DirectionSet, DirectionSet)> {
    let bonn = DirectionSet::bonn();
    let pick = |angles: Vec<(u32, u32)>| -> Result<DirectionSet> {
        let mut seen = std::collections::HashSet::new();
        let mut unique: Vec<Direction> = Vec::new();
        for (theta, phi) in angles {
            if seen.insert(key(theta, phi)) {
                unique.push(Direction::new(f64::from(theta), f64::from(phi)));
            }
        }
        let all_bonn = unique.iter().all(|d| bonn.find(d, 1e-6).is_some());
        if all_bonn && 2 * unique.len() > bonn.len() {
            return Ok(bonn.clone());
        }
        unique.sort_by(|a, b| {
            (a.theta_deg, a.phi_deg)
                .partial_cmp(&(b.theta_deg, b.phi_deg))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        DirectionSet::new(unique).map_err(|e| BtfError::layout(location, e.to_string()))
    };
    let views = pick(entries.iter().map(|(_, a)| (a.theta_v, a.phi_v)).collect())?;
    let lights = pick(entries.iter().map(|(_, a)| (a.theta_l, a.phi_l)).collect())?;
    Ok((views, lights))
}

/// Reads every image header (in parallel) and checks they share one size.
pub(crate) fn common_size(container: &Container, names: &[String]) -> Result<(u32, u32)> {
    let sizes: Vec<(u32, u32)> = names
        .par_iter()
        .map(|n| container.probe_image(n))
        .collect::<Result<_>>()?;
    let (w, h) = sizes[0];
    if let Some(k) = sizes.iter().position(|&s| s != (w, h)) {
        return Err(BtfError::SizeMismatch {
            file: container.describe(&names[k]),
            width: w,
            height: h,
            found_w: sizes[k].0,
            found_h: sizes[k].1,
        });
    }
    Ok((w, h))
}

fn whole_degrees(d: &Direction, what: &str) -> Result<(u32, u32)> {
    let (t, p) = (d.theta_deg.round(), d.phi_deg.round());
    if (d.theta_deg - t).abs() > 0.01 || (d.phi_deg - p).abs() > 0.01 || !(0.0..=999.0).contains(&t)
    {
        return Err(BtfError::parameter(
            "directions",
            format!(
                "{what} theta={} phi={} is not in whole degrees, which the UBO2003 names need",
                d.theta_deg, d.phi_deg
            ),
        ));
    }
    // Azimuth 360 is azimuth 0; at the zenith the azimuth is written as 0.
    let p = if t == 0.0 { 0.0 } else { p % 360.0 };
    Ok((t as u32, p as u32))
}

/// Names for every image of `btf`, view-major, checked to be distinct.
fn output_names(btf: &Btf, format: ImageFormat) -> Result<Vec<String>> {
    let lights: Vec<(u32, u32)> = btf
        .lights()
        .iter()
        .map(|d| whole_degrees(d, "light"))
        .collect::<Result<_>>()?;
    let views: Vec<(u32, u32)> = btf
        .views()
        .iter()
        .map(|d| whole_degrees(d, "view"))
        .collect::<Result<_>>()?;
    let mut names = Vec::with_capacity(btf.image_count());
    let mut seen = HashMap::new();
    for (v, &(theta_v, phi_v)) in views.iter().enumerate() {
        for (l, &(theta_l, phi_l)) in lights.iter().enumerate() {
            let angles = UboAngles {
                theta_l,
                phi_l,
                theta_v,
                phi_v,
            };
            if let Some((v0, l0)) = seen.insert(angles, (v, l)) {
                return Err(BtfError::parameter(
                    "directions",
                    format!(
                        "images (view {v0}, light {l0}) and (view {v}, light {l}) get the same UBO2003 name"
                    ),
                ));
            }
            names.push(format_name(names.len(), &angles, format));
        }
    }
    Ok(names)
}

/// Writes `btf` in the UBO2003 layout: a zip archive when `out` ends in `.zip` (members stored
/// uncompressed, as JPEG/PNG/EXR do not deflate further), otherwise a new folder.
///
/// Images are decoded and encoded in parallel, written in (view, light) order. The output
/// appears under its final name only when complete; on error nothing is left behind.
///
/// # Errors
/// Non-whole-degree directions, unreadable source images, an existing output folder, or an
/// unwritable destination.
pub fn write_ubo2003(
    btf: &Btf,
    out: &Path,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    let names = output_names(btf, format)?;
    write_images(btf, out, &names, None, format, progress)
}

/// Whether every direction of `btf` is in whole degrees, so that [`write_ubo2003`] can name
/// its images.
pub(crate) fn has_whole_degrees(btf: &Btf) -> bool {
    let whole = |set: &crate::btf::DirectionSet| set.iter().all(|d| whole_degrees(d, "").is_ok());
    whole(btf.views()) && whole(btf.lights())
}

/// Writes every image of `btf` (view-major) under `names`, and `extra` (a name and its bytes,
/// e.g. an RTI `.lp` file) after them: a zip archive when `out` ends in `.zip` (members
/// stored uncompressed, as JPEG/PNG/EXR do not deflate further), otherwise a new folder. The
/// output appears under its final name only when complete.
pub(crate) fn write_images(
    btf: &Btf,
    out: &Path,
    names: &[String],
    extra: Option<(&str, &[u8])>,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    let lights = btf.lights().len();
    let is_zip = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("zip"));
    progress.start("writing images", names.len() as u64);
    let result = if is_zip {
        write_zip(btf, out, names, extra, lights, format, progress)
    } else {
        write_folder(btf, out, names, extra, lights, format, progress)
    };
    progress.finish();
    result
}

/// Encodes images in parallel batches and hands them, in order, to `sink`.
fn encode_in_order(
    btf: &Btf,
    names: &[String],
    lights: usize,
    format: ImageFormat,
    progress: &dyn Progress,
    mut sink: impl FnMut(&str, &[u8]) -> Result<()>,
) -> Result<()> {
    const BATCH: usize = 96;
    for start in (0..names.len()).step_by(BATCH) {
        let end = (start + BATCH).min(names.len());
        let encoded: Vec<Vec<u8>> = (start..end)
            .into_par_iter()
            .map(|i| {
                let im = btf.image(i / lights, i % lights)?;
                picture::encode(&im, format, &names[i])
            })
            .collect::<Result<_>>()?;
        for (i, bytes) in (start..end).zip(&encoded) {
            sink(&names[i], bytes)?;
        }
        progress.advance((end - start) as u64);
    }
    Ok(())
}

fn write_zip(
    btf: &Btf,
    out: &Path,
    names: &[String],
    extra: Option<(&str, &[u8])>,
    lights: usize,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    let tmp = crate::io::temp_file_beside(out)?;
    let io_err = |e: std::io::Error| BtfError::io(out, e);
    let zip_err = |e: zip::result::ZipError| BtfError::io(out, std::io::Error::other(e));
    let mut zip = zip::ZipWriter::new(std::io::BufWriter::new(tmp));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(btf.raw_bytes() > u64::from(u32::MAX) / 2);
    encode_in_order(btf, names, lights, format, progress, |name, bytes| {
        zip.start_file(name, options).map_err(zip_err)?;
        zip.write_all(bytes).map_err(io_err)
    })?;
    if let Some((name, bytes)) = extra {
        zip.start_file(name, options).map_err(zip_err)?;
        zip.write_all(bytes).map_err(io_err)?;
    }
    let mut buffered = zip.finish().map_err(zip_err)?;
    buffered.flush().map_err(io_err)?;
    let mut tmp = buffered.into_inner().map_err(|e| io_err(e.into_error()))?;
    tmp.as_file_mut().sync_all().map_err(io_err)?;
    tmp.rewind().map_err(io_err)?;
    tmp.persist(out).map_err(io_err)?;
    Ok(())
}

fn write_folder(
    btf: &Btf,
    out: &Path,
    names: &[String],
    extra: Option<(&str, &[u8])>,
    lights: usize,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    let tmp = crate::io::temp_dir_beside(out)?;
    encode_in_order(btf, names, lights, format, progress, |name, bytes| {
        let path = tmp.path().join(name);
        std::fs::write(&path, bytes).map_err(|e| BtfError::io(&path, e))
    })?;
    if let Some((name, bytes)) = extra {
        let path = tmp.path().join(name);
        std::fs::write(&path, bytes).map_err(|e| BtfError::io(&path, e))?;
    }
    Ok(crate::io::publish_dir(tmp, out)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_bonn_names_with_any_prefix_and_separator() {
        let a = parse_name("UBO_CORDUROY/00017 tl015 pl060 tv000 pv000.jpg").unwrap();
        assert_eq!(
            a,
            UboAngles {
                theta_l: 15,
                phi_l: 60,
                theta_v: 0,
                phi_v: 0
            }
        );
        assert_eq!(
            parse_name("tl075_pl345_tv060_pv018.PNG").unwrap().phi_l,
            345
        );
        assert_eq!(
            parse_name("x tl000 pl000 tv075 pv015.exr").unwrap().theta_v,
            75
        );
        assert!(parse_name("tl000 pl000 tv075.jpg").is_none());
        assert!(parse_name("tl000 pl000 tv000 pv000.txt").is_none());
        assert!(parse_name("tl0000 pl000 tv000 pv000.jpg").is_none());
        assert!(parse_name("photo.jpg").is_none());
    }

    #[test]
    fn names_round_trip() {
        let a = UboAngles {
            theta_l: 75,
            phi_l: 345,
            theta_v: 30,
            phi_v: 90,
        };
        let n = format_name(42, &a, ImageFormat::Png);
        assert_eq!(n, "00042 tl075 pl345 tv030 pv090.png");
        assert_eq!(parse_name(&n), Some(a));
    }
}
