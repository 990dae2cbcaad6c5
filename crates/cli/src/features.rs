//! `btfmrf features`: the illumination-invariant MRF feature vector of an image or a BTF.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use btfmrf::btf::{Btf, Direction, io};
use btfmrf::features::{FeatureOptions, Invariance, extract};
use btfmrf::progress::Progress;
use rayon::prelude::*;

use super::synthesize::parse_direction;
use super::{Bar, Global, emit, emit_json};

/// What `features --json` prints.
#[derive(serde::Serialize)]
struct FeaturesReport<'a> {
    path: &'a Path,
    /// "image", "btf image NAME" or "btf mean of N images".
    source: &'a str,
    width: usize,
    height: usize,
    images: usize,
    levels: usize,
    order: usize,
    length: usize,
    features: &'a [f64],
    names: &'a [String],
    invariance: Vec<Invariance>,
    seconds: f64,
    /// With --all: every image's vector.
    #[serde(skip_serializing_if = "Option::is_none")]
    per_image: Option<Vec<ImageFeatures>>,
}

/// One image's feature vector; directions as [theta, phi] in degrees.
#[derive(serde::Serialize)]
struct ImageFeatures {
    view: [f64; 2],
    light: [f64; 2],
    features: Vec<f64>,
}

/// Compute the illumination-invariant texture features (3D/2D CAR models on a Gaussian
/// pyramid; invariant to the illuminant's colour and brightness) of an image or a BTF.
///
/// An image (.png, .jpg, .jpeg, .exr) gives one vector. A BTF (UBO2003 zip or folder, RTI
/// folder or .lp file) gives, by default, the mean of the vectors of all its images; with
/// --view and --light, the vector of that one measured image; with --all, every image's vector
/// too (and their mean).
///
/// Examples:
///   btfmrf features ../shared/data/textures/brick.png --json
///   btfmrf features stones.zip --view 0,0 --light 45,90 --json
///   btfmrf features ../shared/data/rti/clay-leaf --all --json
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// An image file or a BTF.
    input: PathBuf,
    /// BTF only: the measured view "theta,phi" (degrees, within 1 deg) of the one image to use.
    #[arg(long, value_parser = parse_direction, requires = "light")]
    view: Option<Direction>,
    /// BTF only: the measured light "theta,phi" (degrees, within 1 deg), with --view.
    #[arg(long, value_parser = parse_direction, requires = "view")]
    light: Option<Direction>,
    /// BTF only: also print the vector of every image.
    #[arg(long, conflicts_with = "view")]
    all: bool,
    /// Levels of the Gaussian pyramid.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u8).range(1..=8))]
    levels: u8,
    /// Causal neighbourhood order of the CAR models (1 = left and up, 2 adds the diagonals).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=6))]
    order: u8,
    /// Print one JSON object: features, names, invariance, length, seconds, source, images.
    #[arg(long)]
    json: bool,
}

/// True when the path names a single image file rather than a BTF.
fn is_image(path: &Path) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg" | "exr")) && !path.is_dir()
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let options = FeatureOptions {
        levels: args.levels as usize,
        order: args.order as usize,
    };
    let start = Instant::now();
    let path = &args.input;
    let features_of = |image: &ndarray::Array3<f32>, what: &str| {
        extract(image, &options).with_context(|| format!("{}: {what}", path.display()))
    };
    let mut per_image: Vec<ImageFeatures> = Vec::new();
    let (vector, source, width, height, images) = if is_image(path) {
        if args.view.is_some() || args.all {
            bail!(
                "{}: --view, --light and --all apply to BTFs only",
                path.display()
            );
        }
        let image = io::read_image(path)?;
        let (_, h, w) = image.dim();
        let f = features_of(&image, "image")?;
        (f.values, "image".to_string(), w, h, 1)
    } else {
        let btf = Btf::open(path)?;
        for w in btf.warnings() {
            eprintln!("warning: {w}");
        }
        let (w, h) = (btf.width() as usize, btf.height() as usize);
        if let (Some(view), Some(light)) = (&args.view, &args.light) {
            let v = btf.views().find(view, 1.0).with_context(|| {
                format!(
                    "{}: no measured view within 1 deg of {},{}",
                    path.display(),
                    view.theta_deg,
                    view.phi_deg
                )
            })?;
            let l = btf.lights().find(light, 1.0).with_context(|| {
                format!(
                    "{}: no measured light within 1 deg of {},{}",
                    path.display(),
                    light.theta_deg,
                    light.phi_deg
                )
            })?;
            let f = features_of(&btf.image(v, l)?, &btf.describe(v, l))?;
            (
                f.values,
                format!("btf image {}", btf.describe(v, l)),
                w,
                h,
                1,
            )
        } else {
            let pairs: Vec<(usize, usize)> = (0..btf.views().len())
                .flat_map(|v| (0..btf.lights().len()).map(move |l| (v, l)))
                .collect();
            let bar = Bar::new(global);
            bar.start("features", pairs.len() as u64);
            let vectors = pairs
                .par_iter()
                .map(|&(v, l)| {
                    let f = features_of(&btf.image(v, l)?, &btf.describe(v, l))?;
                    bar.advance(1);
                    Ok(f.values)
                })
                .collect::<anyhow::Result<Vec<Vec<f64>>>>()?;
            bar.finish();
            let n = vectors.len().max(1) as f64;
            let mean: Vec<f64> = (0..options.len())
                .map(|i| vectors.iter().map(|v| v[i]).sum::<f64>() / n)
                .collect();
            if args.all {
                let dir = |d: &Direction| [d.theta_deg, d.phi_deg];
                per_image = pairs
                    .iter()
                    .zip(vectors)
                    .map(|(&(v, l), features)| ImageFeatures {
                        view: dir(&btf.views().as_slice()[v]),
                        light: dir(&btf.lights().as_slice()[l]),
                        features,
                    })
                    .collect();
            }
            (
                mean,
                format!("btf mean of {} images", pairs.len()),
                w,
                h,
                pairs.len(),
            )
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    let names = options.names();
    if args.json {
        emit_json(&FeaturesReport {
            path,
            source: &source,
            width,
            height,
            images,
            levels: options.levels,
            order: options.order,
            length: vector.len(),
            features: &vector,
            names: &names,
            invariance: options.invariances(),
            seconds,
            per_image: args.all.then_some(per_image),
        })?;
    } else {
        emit(format!(
            "{}: {} features ({source}, {width}x{height}) in {seconds:.3} s",
            path.display(),
            vector.len()
        ))?;
        for (name, value) in names.iter().zip(&vector) {
            emit(format!("  {name:<22} {value:>12.6}"))?;
        }
    }
    Ok(())
}
