//! `btfmrf bench`: every method on one BTF, speed against error, as a table, JSON and plots.

use std::path::PathBuf;

use btfmrf::btf::Btf;
use btfmrf::eval::bench::{self, BenchOptions};

use super::{Bar, Global, emit};

/// Run every method on the same BTF and report speed against error: analysis time, synthesis
/// time of one 1024x1024 image, model size, compression ratio, mean CIE76 ΔE (methods that
/// reproduce pixels) and texture fidelity (all methods; 0 = identical statistics).
///
/// Writes DIR/report.json (a list `methods`), DIR/report.md (the table and a sentence per
/// method on where it wins) and PNG plots of fidelity and ΔE against model size and analysis
/// time. DIR must not exist; it appears complete or not at all.
///
/// Example: btfmrf generate stones --size 64 --out stones.zip && btfmrf bench stones.zip --out bench
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The measured BTF: FILE.zip, a folder, or an RTI .lp file.
    btf: PathBuf,
    /// Output folder (must not exist).
    #[arg(long)]
    out: PathBuf,
    /// Subspace images of the MRF models.
    #[arg(long, default_value_t = 20)]
    clusters: usize,
    /// Side of the image whose synthesis is timed, pixels.
    #[arg(long, default_value_t = 1024)]
    synthesis_size: usize,
    /// Measured (view, light) pairs over which fidelity is averaged.
    #[arg(long, default_value_t = 8)]
    fidelity_pairs: usize,
    /// Seed of every random step.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print report.json's content on stdout too.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    if args.out.exists() {
        anyhow::bail!(
            "{}: already exists; choose a new folder",
            args.out.display()
        );
    }
    let btf = Btf::open(&args.btf)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    let options = BenchOptions {
        clusters: args.clusters,
        synthesis_side: args.synthesis_size,
        fidelity_pairs: args.fidelity_pairs,
        seed: args.seed,
    };
    let report = bench::run(
        &btf,
        &args.btf.display().to_string(),
        &options,
        &Bar::new(global),
    )?
    .report;
    let plots = report.write(&args.out)?;
    if args.json {
        emit(serde_json::to_string(&report)?)?;
    } else {
        emit(format!(
            "wrote {} ({} methods, {} plots)",
            args.out.display(),
            report.methods.len(),
            plots.len()
        ))?;
    }
    Ok(())
}
