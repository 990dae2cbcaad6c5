//! `btfmrf recognize`: the material recognition experiment of issue 6.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use btfmrf::features::FeatureOptions;
use btfmrf::features::recognition::{
    Dataset, Descriptor, Outcome, evaluate, rti_dataset, synthetic_dataset, texture_dataset,
    with_relit_tests,
};
use btfmrf::io::write_file_atomic;
use btfmrf::progress::Progress;

use super::{Bar, Global, emit};

/// Run the material recognition experiment: 1-nearest-neighbour classification of held-out
/// images by the invariant MRF features, against colour histograms and LBP histograms.
///
/// Datasets: (a) the four generated materials, training and test images from disjoint halves
/// of the Bonn views and lights, and the same with every test image relit by a random
/// illuminant and stored at 8 bits; (b) the RTI sets in DATA/rti (one class each; every 4th light
/// trains); (c0) the photographs in DATA/textures cut into a --grid of crops (4x4), half the crops
/// train, the other half test as they are; (c) the same test crops relit by random
/// illuminants (colour, brightness, tungsten white balance) and stored at 8 bits. Missing
/// data folders are skipped with a note. Everything is deterministic in --seed.
///
/// Example:
///   btfmrf recognize --data ../shared/data --out recognition.md
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Folder holding rti/ (RTI sets) and textures/ (photographs).
    #[arg(long, default_value = "../shared/data")]
    data: PathBuf,
    /// Texels per side of the generated materials.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(8..=512))]
    size: u32,
    /// Training images per generated material.
    #[arg(long, default_value_t = 12)]
    train: usize,
    /// Test images per generated material.
    #[arg(long, default_value_t = 30)]
    test: usize,
    /// The photographs are cut into GRID x GRID square crops.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(2..=32))]
    grid: u32,
    /// Relit copies of every held-out photograph crop.
    #[arg(long, default_value_t = 3)]
    relit: usize,
    /// Seed of every random choice (direction splits, illuminants).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the report as Markdown to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Sorted entries of a folder that pass `keep`; empty if the folder is missing.
fn entries(dir: &Path, keep: impl Fn(&Path) -> bool) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| keep(p));
    v.sort();
    v
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let start = Instant::now();
    let options = FeatureOptions::default();
    let mut skipped: Vec<String> = Vec::new();
    let generated = synthetic_dataset(args.size, args.seed, args.train, args.test)?;
    let relit = with_relit_tests(&generated, args.seed);
    let mut datasets: Vec<Dataset> = vec![generated, relit];
    let rti = entries(&args.data.join("rti"), |p| p.is_dir());
    if rti.len() >= 2 {
        datasets.push(rti_dataset(&rti, 4)?);
    } else {
        skipped.push(format!(
            "(b) needs at least two RTI folders in {}",
            args.data.join("rti").display()
        ));
    }
    let photos = entries(&args.data.join("textures"), |p| {
        p.extension().is_some_and(|e| {
            matches!(
                e.to_string_lossy().to_ascii_lowercase().as_str(),
                "png" | "jpg" | "jpeg" | "exr"
            )
        })
    });
    if photos.len() >= 2 {
        datasets.push(texture_dataset(&photos, args.grid as usize, 0, args.seed)?);
        datasets.push(texture_dataset(
            &photos,
            args.grid as usize,
            args.relit.max(1),
            args.seed,
        )?);
    } else {
        skipped.push(format!(
            "(c) needs at least two photographs in {}",
            args.data.join("textures").display()
        ));
    }
    let bar = Bar::new(global);
    bar.start("recognize", datasets.len() as u64);
    let mut results: Vec<Vec<Outcome>> = Vec::new();
    for d in &datasets {
        results.push(evaluate(d, &Descriptor::ALL, &options)?);
        bar.advance(1);
    }
    bar.finish();
    let seconds = start.elapsed().as_secs_f64();
    let markdown = report(&datasets, &results, &skipped, options.len(), seconds);
    if let Some(out) = &args.out {
        write_file_atomic(out, markdown.as_bytes())?;
    }
    if args.json {
        let rows: Vec<serde_json::Value> = datasets
            .iter()
            .zip(&results)
            .map(|(d, r)| {
                serde_json::json!({
                    "name": d.name,
                    "description": d.description,
                    "classes": d.classes,
                    "train": d.train.len(),
                    "test": d.test.len(),
                    "results": r.iter().map(|o| serde_json::json!({
                        "method": o.method,
                        "correct": o.correct,
                        "total": o.total,
                        "accuracy": o.accuracy(),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        emit(serde_json::json!({
            "datasets": rows,
            "skipped": skipped,
            "feature_length": options.len(),
            "seconds": seconds,
        }))?;
    } else {
        emit(markdown.trim_end())?;
    }
    Ok(())
}

/// The Markdown table and notes.
fn report(
    datasets: &[Dataset],
    results: &[Vec<Outcome>],
    skipped: &[String],
    length: usize,
    seconds: f64,
) -> String {
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
    for (d, r) in datasets.iter().zip(results) {
        let _ = write!(
            s,
            "| {} | {} | {} | {} |",
            d.name,
            d.classes.len(),
            d.train.len(),
            d.test.len()
        );
        for o in r {
            let _ = write!(
                s,
                " {:.1} % ({}/{}) |",
                100.0 * o.accuracy(),
                o.correct,
                o.total
            );
        }
        s.push('\n');
    }
    s.push('\n');
    for d in datasets {
        let _ = writeln!(s, "- {}: {}.", d.name, d.description);
    }
    for k in skipped {
        let _ = writeln!(s, "- skipped: {k}.");
    }
    let _ = writeln!(
        s,
        "\n1-NN. MRF: {length} features (4-level Gaussian pyramid, order-2 causal \
         neighbourhood), L1 after dividing each feature by its std over the training set; \
         \"3x3-invariant\" keeps only the 3D CAR invariants. Colour histogram: joint 8x8x8 \
         sRGB bins, intersection. LBP: uniform LBP(8,1) of luminance on 3 pyramid levels, L1. \
         Total {seconds:.1} s."
    );
    s
}
