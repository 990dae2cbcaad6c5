//! `btfmrf recognize`: the material recognition experiment of issue 6.

use std::path::PathBuf;

use btfmrf::features::recognition::{
    DATA_ENV, ExperimentOptions, RTI_FOLDER, TEXTURES_FOLDER, run_experiment,
};
use btfmrf::io::write_file_atomic;

use super::{Bar, Global, emit};

/// Run the material recognition experiment: 1-nearest-neighbour classification of held-out
/// images by the invariant MRF features, against colour histograms and LBP histograms.
///
/// Datasets: (a) the four generated materials, training and test images from disjoint halves
/// of the Bonn views and lights, and the same with every test image relit by a random
/// illuminant and stored at 8 bits; (b) the RTI sets in DATA/rti (one class each; every 4th light
/// trains); (c0) the photographs in DATA/textures cut into a --grid of crops (4x4), half the crops
/// train, the other half test as they are; (c) the same test crops relit by random
/// illuminants (colour, brightness, tungsten white balance) and stored at 8 bits. A missing
/// rti/ or textures/ inside DATA skips its datasets with a note; a missing DATA is an error.
/// Everything is deterministic in --seed.
///
/// The data folder comes from --data or else the BTFMRF_DATA environment variable; without
/// either, the command stops with an error.
///
/// Example:
///   btfmrf recognize --data /path/to/data --out recognition.md
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Folder holding rti/ (RTI sets: one folder per material, each with its images and a .lp
    /// light file) and textures/ (photographs, PNG/JPEG/EXR, one material each); default: the
    /// BTFMRF_DATA environment variable.
    #[arg(long, value_name = "DIR")]
    data: Option<PathBuf>,
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

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let Some(data) = args
        .data
        .or_else(|| std::env::var_os(DATA_ENV).map(PathBuf::from))
    else {
        anyhow::bail!(
            "recognize needs a data folder: --data DIR (or {DATA_ENV}=DIR), holding \
             {RTI_FOLDER}/ (RTI sets) and {TEXTURES_FOLDER}/ (photographs)"
        );
    };
    let options = ExperimentOptions {
        size: args.size,
        train: args.train,
        test: args.test,
        grid: args.grid as usize,
        relit: args.relit,
        seed: args.seed,
    };
    let report = run_experiment(&data, &options, &Bar::new(global))?;
    let markdown = report.markdown();
    if let Some(out) = &args.out {
        write_file_atomic(out, markdown.as_bytes())?;
    }
    if args.json {
        emit(serde_json::to_string(&report)?)
    } else {
        emit(markdown.trim_end())
    }
}
