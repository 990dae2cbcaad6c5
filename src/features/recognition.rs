//! The material recognition experiment: 1-nearest-neighbour classification of held-out images
//! with the invariant MRF features ([`super::extract`]) against two baselines
//! ([`super::baselines`]), on three kinds of data:
//!
//! - (a) [`synthetic_dataset`]: the generated materials under the Bonn view x light sampling;
//!   the views and the lights are each split at random into two halves, training images use
//!   only the first halves and test images only the second, so every test direction is unseen;
//! - (b) [`rti_dataset`]: real RTI sets (one view, many lights), each a class; every fourth
//!   light trains, the others test;
//! - (c) [`texture_dataset`]: photographs cut into a grid of crops, crops on the "black squares"
//!   of the grid train (original illumination), crops on the "white squares" test, each relit
//!   by random illuminants ([`random_illuminant`], [`relight`]) and stored at 8 bits.
//!
//! Distances: MRF features, L1 after dividing each feature by its standard deviation over the
//! training set (Vácha & Haindl; features constant over the training set are ignored); colour
//! histograms, histogram intersection; LBP histograms, L1.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Matrix3;
use ndarray::{Array3, s};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use super::baselines::{colour_histogram, intersection_distance, l1_distance, lbp_histogram};
use super::{FeatureError, FeatureOptions, Invariance, extract};
use crate::btf::synthetic::SyntheticMaterial;
use crate::btf::{Btf, BtfError, io};
use crate::color::{Srgb8Encoder, linear_to_xyz, srgb8_to_linear_table, xyz_to_linear};
use crate::progress::Progress;

/// A descriptor and its distance (serialized as its table name).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Descriptor {
    /// All invariant MRF features, std-normalised L1.
    Mrf,
    /// Only the MRF features invariant to any 3x3 colour transform, std-normalised L1.
    MrfColourTransform,
    /// Joint RGB histogram, intersection.
    ColourHistogram,
    /// Multi-scale uniform LBP of luminance, L1.
    Lbp,
}

impl Descriptor {
    /// Every method, in report order.
    pub const ALL: [Descriptor; 4] = [
        Descriptor::Mrf,
        Descriptor::MrfColourTransform,
        Descriptor::ColourHistogram,
        Descriptor::Lbp,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Descriptor::Mrf => "MRF (all)",
            Descriptor::MrfColourTransform => "MRF (3x3-invariant)",
            Descriptor::ColourHistogram => "colour histogram",
            Descriptor::Lbp => "LBP",
        }
    }
}

impl serde::Serialize for Descriptor {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// A labelled image set split into training and test images.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Short name.
    pub name: String,
    /// What the split is, in words.
    pub description: String,
    /// Class names (`train`/`test` hold indices into this).
    pub classes: Vec<String>,
    /// (class, `(3, h, w)` linear image) used as the database.
    pub train: Vec<(usize, Array3<f32>)>,
    /// (class, image) to be recognised.
    pub test: Vec<(usize, Array3<f32>)>,
}

/// Accuracy of one method on one dataset.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Outcome {
    /// The method (its table name in JSON).
    pub method: Descriptor,
    /// Test images assigned to their own class.
    pub correct: usize,
    /// Test images.
    pub total: usize,
}

impl Outcome {
    /// `correct / total` (0 for an empty test set).
    pub fn accuracy(&self) -> f64 {
        self.correct as f64 / self.total.max(1) as f64
    }
}

/// Views x lights split for dataset (a): `train_per_class` training and `test_per_class` test
/// images per material, `size` x `size` texels, everything deterministic in `seed`.
///
/// # Errors
/// An invalid size, or a rendering failure.
pub fn synthetic_dataset(
    size: u32,
    seed: u64,
    train_per_class: usize,
    test_per_class: usize,
) -> Result<Dataset, BtfError> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut train = Vec::new();
    let mut test = Vec::new();
    let mut classes = Vec::new();
    for (class, material) in SyntheticMaterial::ALL.into_iter().enumerate() {
        let btf = Btf::synthetic(material, size, seed)?;
        classes.push(material.name().to_string());
        let views = shuffled(btf.views().len(), &mut rng);
        let lights = shuffled(btf.lights().len(), &mut rng);
        let (vh, lh) = (views.len() / 2, lights.len() / 2);
        let mut pick = |vs: &[usize], ls: &[usize], n: usize| -> Vec<(usize, usize)> {
            let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(n);
            while pairs.len() < n.min(vs.len() * ls.len()) {
                let p = (
                    vs[rng.random_range(0..vs.len())],
                    ls[rng.random_range(0..ls.len())],
                );
                if !pairs.contains(&p) {
                    pairs.push(p);
                }
            }
            pairs
        };
        let train_pairs = pick(&views[..vh], &lights[..lh], train_per_class);
        let test_pairs = pick(&views[vh..], &lights[lh..], test_per_class);
        // Stored at 8 bits, like the Bonn measurements.
        let stored = |v, l| -> Result<Array3<f32>, BtfError> {
            Ok(relight(&btf.image(v, l)?, &Matrix3::identity(), true))
        };
        for (v, l) in train_pairs {
            train.push((class, stored(v, l)?));
        }
        for (v, l) in test_pairs {
            test.push((class, stored(v, l)?));
        }
    }
    Ok(Dataset {
        name: format!("(a) generated BTFs {size}x{size}"),
        description: format!(
            "{} materials; views and lights each split in halves at random (seed {seed}); \
             {train_per_class} training images per material from the first halves, \
             {test_per_class} test images from the second halves; images stored at 8 bits",
            classes.len()
        ),
        classes,
        train,
        test,
    })
}

/// The same training images, and every test image replaced by a copy relit by a random
/// illuminant ([`random_illuminant`]) and stored at 8 bits: recognition under an unknown
/// illuminant colour and brightness on top of the dataset's own changes.
pub fn with_relit_tests(dataset: &Dataset, seed: u64) -> Dataset {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    Dataset {
        name: format!("{}, relit tests", dataset.name),
        description: format!(
            "{}; every test image relit by a random illuminant and stored at 8 bits (seed {seed})",
            dataset.description
        ),
        classes: dataset.classes.clone(),
        train: dataset.train.clone(),
        test: dataset
            .test
            .iter()
            .map(|(class, image)| (*class, relight(image, &random_illuminant(&mut rng), true)))
            .collect(),
    }
}

/// 0..n in a seeded random order (Fisher-Yates).
fn shuffled(n: usize, rng: &mut Pcg64Mcg) -> Vec<usize> {
    let mut v: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        v.swap(i, rng.random_range(0..=i));
    }
    v
}

/// Dataset (b): each RTI folder is a class; light `i` trains when `i % train_every == 0`, the
/// others test (only the first view is used).
///
/// # Errors
/// A folder that does not open as a BTF, or an unreadable image (the error names it).
pub fn rti_dataset(folders: &[PathBuf], train_every: usize) -> Result<Dataset, BtfError> {
    let every = train_every.max(2);
    let mut train = Vec::new();
    let mut test = Vec::new();
    let mut classes = Vec::new();
    let mut sizes = Vec::new();
    for (class, folder) in folders.iter().enumerate() {
        let btf = Btf::open(folder)?;
        classes.push(file_name(folder));
        sizes.push(format!(
            "{} {}x{}, {} lights",
            file_name(folder),
            btf.width(),
            btf.height(),
            btf.lights().len()
        ));
        for l in 0..btf.lights().len() {
            let image = btf.image(0, l)?;
            if l % every == 0 {
                train.push((class, image));
            } else {
                test.push((class, image));
            }
        }
    }
    Ok(Dataset {
        name: "(b) real RTI sets".into(),
        description: format!(
            "{} classes ({}); every {every}th light trains, the other lights test",
            classes.len(),
            sizes.join("; ")
        ),
        classes,
        train,
        test,
    })
}

fn file_name(path: &Path) -> String {
    path.file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// Dataset (c): each photograph is a class, cut into `grid` x `grid` square crops; crops with
/// even `row + col` train at their original illumination, the others test: `relit_per_crop`
/// copies under random illuminants (stored at 8 bits), or the original crop if
/// `relit_per_crop` is 0 (the control).
///
/// # Errors
/// An unreadable image (the error names it) or one smaller than `grid` pixels a side.
pub fn texture_dataset(
    photos: &[PathBuf],
    grid: usize,
    relit_per_crop: usize,
    seed: u64,
) -> Result<Dataset, BtfError> {
    let grid = grid.max(1);
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut train = Vec::new();
    let mut test = Vec::new();
    let mut classes = Vec::new();
    let mut crop_size = usize::MAX;
    for (class, path) in photos.iter().enumerate() {
        let image = io::read_image(path)?;
        let (_, h, w) = image.dim();
        let side = h.min(w) / grid;
        if side == 0 {
            return Err(BtfError::parameter(
                "image",
                format!(
                    "{}: {w}x{h} is too small for {grid}x{grid} crops",
                    path.display()
                ),
            ));
        }
        crop_size = crop_size.min(side);
        classes.push(file_name(path));
        for i in 0..grid {
            for j in 0..grid {
                let crop = image
                    .slice(s![.., i * side..(i + 1) * side, j * side..(j + 1) * side])
                    .to_owned();
                if (i + j) % 2 == 0 {
                    train.push((class, crop));
                } else if relit_per_crop == 0 {
                    test.push((class, crop));
                } else {
                    for _ in 0..relit_per_crop {
                        let b = random_illuminant(&mut rng);
                        test.push((class, relight(&crop, &b, true)));
                    }
                }
            }
        }
    }
    let what = if relit_per_crop == 0 {
        "the held-out crops at their original illumination (control)".to_string()
    } else {
        format!(
            "{relit_per_crop} relit 8-bit copies of every held-out crop (random illuminant \
             colour, brightness and, for half, a tungsten white balance; seed {seed})"
        )
    };
    Ok(Dataset {
        name: if relit_per_crop == 0 {
            "(c0) photographs, held-out crops".into()
        } else {
            "(c) photographs, relit held-out crops".into()
        },
        description: format!(
            "{} classes ({}); {grid}x{grid} crops of {crop_size}^2 px, the checkerboard's even \
             crops train (original), test: {what}",
            classes.len(),
            classes.join(", ")
        ),
        classes,
        train,
        test,
    })
}

/// A random illuminant change as a 3x3 matrix on linear RGB: per-channel gains in [0.4, 1],
/// for half of the draws composed with a von Kries change from D65 to CIE illuminant A
/// (tungsten, scaling done in XYZ, so the matrix is full), then scaled so that white maps to a
/// brightness in [0.3, 1] in its brightest channel.
pub fn random_illuminant(rng: &mut Pcg64Mcg) -> Matrix3<f64> {
    let gains = Matrix3::from_diagonal(&nalgebra::Vector3::from_fn(|_, _| {
        rng.random_range(0.4..=1.0)
    }));
    let mut b = gains;
    if rng.random_range(0..2) == 1 {
        b *= tungsten_adaptation();
    }
    let brightness = rng.random_range(0.3..=1.0);
    let white = b * nalgebra::Vector3::repeat(1.0);
    b * (brightness / white.max())
}

/// The von Kries adaptation from D65 to illuminant A (white point (1.09850, 1, 0.35585)) by
/// scaling XYZ, as a matrix on linear sRGB.
pub fn tungsten_adaptation() -> Matrix3<f64> {
    let column = |f: fn([f32; 3]) -> [f32; 3], i: usize| {
        let mut e = [0.0f32; 3];
        e[i] = 1.0;
        let v = f(e);
        nalgebra::Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)
    };
    let to_xyz = Matrix3::from_columns(&[
        column(linear_to_xyz, 0),
        column(linear_to_xyz, 1),
        column(linear_to_xyz, 2),
    ]);
    let from_xyz = Matrix3::from_columns(&[
        column(xyz_to_linear, 0),
        column(xyz_to_linear, 1),
        column(xyz_to_linear, 2),
    ]);
    let d65 = crate::color::D65_WHITE;
    let a = [1.098_50, 1.0, 0.355_85];
    let scale = Matrix3::from_diagonal(&nalgebra::Vector3::from_fn(|i, _| a[i] / d65[i] as f64));
    from_xyz * scale * to_xyz
}

/// `B Y` at every pixel of a `(3, h, w)` linear image, clamped to [0, 1] (a camera saturates);
/// with `quantise`, also rounded to 8-bit sRGB and decoded back, like a stored photograph.
pub fn relight(image: &Array3<f32>, b: &Matrix3<f64>, quantise: bool) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let encoder = Srgb8Encoder::new();
    let table = srgb8_to_linear_table();
    let mut out = Array3::<f32>::zeros((3, h, w));
    for r in 0..h {
        for c in 0..w {
            let y = [image[[0, r, c]], image[[1, r, c]], image[[2, r, c]]];
            for k in 0..3 {
                let v = (0..3).map(|j| b[(k, j)] * y[j] as f64).sum::<f64>();
                let v = v.clamp(0.0, 1.0) as f32;
                out[[k, r, c]] = if quantise {
                    table[encoder.encode(v) as usize]
                } else {
                    v
                };
            }
        }
    }
    out
}

/// The descriptor of `method` for one image.
///
/// # Errors
/// See [`extract`].
pub fn descriptor(
    method: Descriptor,
    image: &Array3<f32>,
    options: &FeatureOptions,
) -> Result<Vec<f64>, FeatureError> {
    Ok(match method {
        Descriptor::Mrf => extract(image, options)?.values,
        Descriptor::MrfColourTransform => {
            let all = extract(image, options)?.values;
            all.into_iter()
                .zip(options.invariances())
                .filter(|(_, i)| *i == Invariance::ColourTransform)
                .map(|(v, _)| v)
                .collect()
        }
        Descriptor::ColourHistogram => colour_histogram(image),
        Descriptor::Lbp => lbp_histogram(image),
    })
}

/// `1 / std` of every feature over a set of vectors (0 where the std is below 1e-12 of the
/// feature's magnitude, i.e. the feature is constant over the set and carries no information).
pub fn std_weights(vectors: &[Vec<f64>]) -> Vec<f64> {
    let n = vectors.len().max(1) as f64;
    let len = vectors.first().map_or(0, Vec::len);
    (0..len)
        .map(|i| {
            let mean = vectors.iter().map(|v| v[i]).sum::<f64>() / n;
            let var = vectors.iter().map(|v| (v[i] - mean).powi(2)).sum::<f64>() / n;
            let sd = var.sqrt();
            if sd > 1e-12 * mean.abs().max(1e-300) && sd > 0.0 {
                1.0 / sd
            } else {
                0.0
            }
        })
        .collect()
}

/// Weighted L1 distance `sum_i w_i |a_i - b_i|`.
pub fn weighted_l1(weights: &[f64], a: &[f64], b: &[f64]) -> f64 {
    weights
        .iter()
        .zip(a.iter().zip(b))
        .map(|(w, (x, y))| w * (x - y).abs())
        .sum()
}

/// The class of the training vector nearest to `query` (first one on ties); `None` for an empty
/// database.
pub fn nearest(
    database: &[(usize, Vec<f64>)],
    query: &[f64],
    distance: impl Fn(&[f64], &[f64]) -> f64,
) -> Option<usize> {
    database
        .iter()
        .map(|(class, v)| (*class, distance(v, query)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(class, _)| class)
}

/// 1-NN accuracy of every method on a dataset.
///
/// # Errors
/// An image the features refuse (see [`extract`]).
pub fn evaluate(
    dataset: &Dataset,
    methods: &[Descriptor],
    options: &FeatureOptions,
) -> Result<Vec<Outcome>, FeatureError> {
    methods
        .iter()
        .map(|&method| {
            let describe = |set: &[(usize, Array3<f32>)]| -> Result<Vec<(usize, Vec<f64>)>, _> {
                set.par_iter()
                    .map(|(class, image)| Ok((*class, descriptor(method, image, options)?)))
                    .collect()
            };
            let train = describe(&dataset.train)?;
            let test = describe(&dataset.test)?;
            let weights = std_weights(&train.iter().map(|t| t.1.clone()).collect::<Vec<_>>());
            let distance = |a: &[f64], b: &[f64]| match method {
                Descriptor::Mrf | Descriptor::MrfColourTransform => weighted_l1(&weights, a, b),
                Descriptor::ColourHistogram => intersection_distance(a, b),
                Descriptor::Lbp => l1_distance(a, b),
            };
            let correct = test
                .iter()
                .filter(|(class, v)| nearest(&train, v, distance) == Some(*class))
                .count();
            Ok(Outcome {
                method,
                correct,
                total: test.len(),
            })
        })
        .collect()
}

/// What can stop the whole experiment.
#[derive(Debug, thiserror::Error)]
pub enum RecognitionError {
    /// The data folder is missing or not a folder.
    #[error("{}: {reason}", path.display())]
    Data {
        /// The folder given.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A dataset could not be read or made.
    #[error(transparent)]
    Btf(#[from] BtfError),
    /// An image the features refuse.
    #[error(transparent)]
    Feature(#[from] FeatureError),
}

/// The settings of the whole experiment ([`run_experiment`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentOptions {
    /// Texels per side of the generated materials (dataset a).
    pub size: u32,
    /// Training images per generated material.
    pub train: usize,
    /// Test images per generated material.
    pub test: usize,
    /// The photographs are cut into `grid` x `grid` square crops (dataset c).
    pub grid: usize,
    /// Relit copies of every held-out photograph crop (at least 1 is made).
    pub relit: usize,
    /// Seed of every random choice (direction splits, illuminants).
    pub seed: u64,
}

/// The environment variable naming the data folder when `btfmrf recognize` is given no
/// `--data`.
pub const DATA_ENV: &str = "BTFMRF_DATA";

/// The RTI sets of dataset (b) lie in `DATA/rti`, one folder each.
pub const RTI_FOLDER: &str = "rti";
/// The photographs of dataset (c) lie in `DATA/textures` (PNG, JPEG or EXR).
pub const TEXTURES_FOLDER: &str = "textures";

/// Sorted entries of a folder that pass `keep`; empty if the folder is missing.
fn entries(dir: &Path, keep: impl Fn(&Path) -> bool) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| keep(p));
    v.sort();
    v
}

/// The experiment's datasets: (a) the generated materials and (a) relit, always; (b) when
/// `data/rti` holds at least two RTI folders; (c0) and (c) when `data/textures` holds at least
/// two photographs. Returns the datasets and a note for each kind skipped.
///
/// # Errors
/// `data` is not a folder, or a dataset fails to load.
pub fn find_datasets(
    data: &Path,
    options: &ExperimentOptions,
) -> Result<(Vec<Dataset>, Vec<String>), RecognitionError> {
    if !data.is_dir() {
        return Err(RecognitionError::Data {
            path: data.to_path_buf(),
            reason: format!(
                "not a folder; the data folder holds {RTI_FOLDER}/ (RTI sets) and \
                 {TEXTURES_FOLDER}/ (photographs)"
            ),
        });
    }
    let mut skipped = Vec::new();
    let generated = synthetic_dataset(options.size, options.seed, options.train, options.test)?;
    let relit = with_relit_tests(&generated, options.seed);
    let mut datasets = vec![generated, relit];
    let rti = entries(&data.join(RTI_FOLDER), |p| p.is_dir());
    if rti.len() >= 2 {
        datasets.push(rti_dataset(&rti, 4)?);
    } else {
        skipped.push(format!(
            "(b) needs at least two RTI folders in {}",
            data.join(RTI_FOLDER).display()
        ));
    }
    let photos = entries(&data.join(TEXTURES_FOLDER), |p| {
        p.extension().is_some_and(|e| {
            matches!(
                e.to_string_lossy().to_ascii_lowercase().as_str(),
                "png" | "jpg" | "jpeg" | "exr"
            )
        })
    });
    if photos.len() >= 2 {
        datasets.push(texture_dataset(&photos, options.grid, 0, options.seed)?);
        datasets.push(texture_dataset(
            &photos,
            options.grid,
            options.relit.max(1),
            options.seed,
        )?);
    } else {
        skipped.push(format!(
            "(c) needs at least two photographs in {}",
            data.join(TEXTURES_FOLDER).display()
        ));
    }
    Ok((datasets, skipped))
}

/// One dataset's row of the report.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DatasetResult {
    /// Short name, e.g. "(b) real RTI sets".
    pub name: String,
    /// What the split is, in words.
    pub description: String,
    /// Class names.
    pub classes: Vec<String>,
    /// Training images.
    pub train: usize,
    /// Test images.
    pub test: usize,
    /// Each method's accuracy, in [`Method::ALL`] order.
    pub results: Vec<MethodAccuracy>,
}

/// One method's accuracy on one dataset, as the report shows it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MethodAccuracy {
    /// The counts.
    #[serde(flatten)]
    pub outcome: Outcome,
    /// `correct / total`.
    pub accuracy: f64,
}

/// The whole experiment's result (the JSON of `btfmrf recognize --json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RecognitionReport {
    /// One row per dataset.
    pub datasets: Vec<DatasetResult>,
    /// A note per kind of dataset that was skipped for want of data.
    pub skipped: Vec<String>,
    /// Length of the MRF feature vector.
    pub feature_length: usize,
    /// Wall time of the whole experiment, seconds.
    pub seconds: f64,
}

/// Runs the experiment on the datasets [`find_datasets`] finds under `data`, every method
/// of [`Method::ALL`] with the default features.
///
/// # Errors
/// See [`find_datasets`] and [`evaluate`].
pub fn run_experiment(
    data: &Path,
    options: &ExperimentOptions,
    progress: &dyn Progress,
) -> Result<RecognitionReport, RecognitionError> {
    let start = Instant::now();
    let features = FeatureOptions::default();
    let (datasets, skipped) = find_datasets(data, options)?;
    progress.start("recognize", datasets.len() as u64);
    let mut rows = Vec::new();
    for d in &datasets {
        let outcomes = evaluate(d, &Descriptor::ALL, &features)?;
        rows.push(DatasetResult {
            name: d.name.clone(),
            description: d.description.clone(),
            classes: d.classes.clone(),
            train: d.train.len(),
            test: d.test.len(),
            results: outcomes
                .into_iter()
                .map(|o| MethodAccuracy {
                    accuracy: o.accuracy(),
                    outcome: o,
                })
                .collect(),
        });
        progress.advance(1);
    }
    progress.finish();
    Ok(RecognitionReport {
        datasets: rows,
        skipped,
        feature_length: features.len(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

impl RecognitionReport {
    /// The report as Markdown: the accuracy table, a line per dataset and per skipped kind,
    /// and how the methods compare images.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = write!(s, "| dataset | classes | train | test |");
        for m in Descriptor::ALL {
            let _ = write!(s, " {} |", m.name());
        }
        s.push_str("\n|---|---|---|---|");
        for _ in Descriptor::ALL {
            s.push_str("---|");
        }
        s.push('\n');
        for d in &self.datasets {
            let _ = write!(
                s,
                "| {} | {} | {} | {} |",
                d.name,
                d.classes.len(),
                d.train,
                d.test
            );
            for r in &d.results {
                let _ = write!(
                    s,
                    " {:.1} % ({}/{}) |",
                    100.0 * r.accuracy,
                    r.outcome.correct,
                    r.outcome.total
                );
            }
            s.push('\n');
        }
        s.push('\n');
        for d in &self.datasets {
            let _ = writeln!(s, "- {}: {}.", d.name, d.description);
        }
        for k in &self.skipped {
            let _ = writeln!(s, "- skipped: {k}.");
        }
        let _ = writeln!(
            s,
            "\n1-NN. MRF: {} features (4-level Gaussian pyramid, order-2 causal \
             neighbourhood), L1 after dividing each feature by its std over the training set; \
             \"3x3-invariant\" keeps only the 3D CAR invariants. Colour histogram: joint 8x8x8 \
             sRGB bins, intersection. LBP: uniform LBP(8,1) of luminance on 3 pyramid levels, L1. \
             Total {:.1} s.",
            self.feature_length, self.seconds
        );
        s
    }
}
