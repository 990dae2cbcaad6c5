//! Helpers shared by the integration tests of the library and of the CLI (which includes this
//! file): temporary folders, small BTF archives that tests can then damage on purpose, and the
//! repository's own files.
#![allow(dead_code)] // each test binary uses a different subset

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, ImageFormat, io};
use btfmrf::progress::NoProgress;

/// A fresh temporary folder, removed when dropped.
pub fn temp() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary folder")
}

/// The path as &str (test paths are UTF-8).
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Writes a tiny synthetic Bonn BTF (81 x 81 images of `size`^2) to `path` (zip or folder).
pub fn tiny_btf(path: &Path, size: u32, format: ImageFormat) -> PathBuf {
    let btf = Btf::synthetic(SyntheticMaterial::Knit, size, 3).expect("synthetic BTF");
    io::write_ubo2003(&btf, path, format, &NoProgress).expect("written");
    path.to_path_buf()
}

/// All members of a zip archive, in order.
pub fn read_zip(path: &Path) -> Vec<(String, Vec<u8>)> {
    let mut archive = zip::ZipArchive::new(std::fs::File::open(path).unwrap()).unwrap();
    (0..archive.len())
        .map(|i| {
            let mut f = archive.by_index(i).unwrap();
            let mut bytes = Vec::new();
            f.read_to_end(&mut bytes).unwrap();
            (f.name().unwrap().into_owned(), bytes)
        })
        .collect()
}

/// Writes members into a new zip archive.
pub fn write_zip(path: &Path, members: &[(String, Vec<u8>)]) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in members {
        zip.start_file(name.as_str(), options).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

/// Files (not folders) directly inside `dir`, hidden ones included.
pub fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The repository root (the library crate's folder): golden files, models, `../shared`.
pub fn repo() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    // This file is compiled into the library's tests and the CLI crate's (crates/cli) tests.
    if here.join("crates").is_dir() {
        here.to_path_buf()
    } else {
        here.join("../..")
    }
}

/// A real RTI capture in `../shared/data/rti` (beside the repository), as a path string.
pub fn rti(set: &str) -> String {
    repo()
        .join("../shared/data/rti")
        .join(set)
        .to_str()
        .expect("utf-8 path")
        .to_string()
}

/// Over the judge's nine frontal lights, the geometric mean of model `a`'s structure over
/// model `b`'s, each x the another-crop level of `measured` (the other crop from `another`, the
/// same material generated with another seed); both synthesized at `enlarge` times the
/// measured side, seed 1. Prints each light's two figures under `names`.
pub fn judged_ratio(
    measured: &Btf,
    another: &Btf,
    [a, b]: [&btfmrf::model::MaterialModel; 2],
    names: [&str; 2],
    enlarge: usize,
) -> f64 {
    use btfmrf::btf::Direction;
    use btfmrf::eval::{JUDGED_LIGHTS, Yardstick};
    let o = btfmrf::synthesis::SynthesisOptions {
        rows: enlarge * measured.height() as usize,
        cols: enlarge * measured.width() as usize,
        seed: 1,
        tileable: false,
    };
    let view = *measured.views().get(0).unwrap();
    let mut log_ratio = 0.0;
    for (theta, phi) in JUDGED_LIGHTS {
        let light = Direction::new(theta, phi);
        let l = measured.lights().find(&light, 0.5).unwrap();
        let y = Yardstick::from_samples(
            &measured.image(0, l).unwrap(),
            &another.image(0, l).unwrap(),
            None,
            1,
        )
        .unwrap();
        let [x, z] = [a, b].map(|m| {
            y.judge(&m.synthesize_image(&view, &light, &o).unwrap())
                .unwrap()
                .structure_vs_crop
        });
        println!(
            "light {theta}/{phi}: {} x{x:.2}, {} x{z:.2} the crop level",
            names[0], names[1]
        );
        log_ratio += (x / z).ln();
    }
    (log_ratio / JUDGED_LIGHTS.len() as f64).exp()
}
