//! `btfmrf bench`: every method on one BTF, speed against error, as a table, JSON and plots.

use std::path::PathBuf;

use btfmrf::btf::Btf;
use btfmrf::eval::bench::{self, Baseline, BenchOptions};
use btfmrf::lpca::Method;
use btfmrf::memory;

use super::{Bar, Global, emit};

/// Run every method on the same BTF and report speed against error: analysis time, synthesis
/// time of one 1024x1024 image, model size, compression ratio, mean CIE76 ΔE (methods that
/// reproduce pixels) and the texture judge (all methods): structure distance, the same over
/// the another-crop and random-phase reference levels, and colour (mean |Lab quantile
/// difference|), with the reference levels (another crop, random phase, shuffled, blurred,
/// and --other-material) as rows.
///
/// Writes DIR/report.json (lists `methods` and `levels`), DIR/report.md (the table and a
/// sentence per method on where it wins), DIR/sheet.png (measured, each method, the MRF
/// enlargements side by side) and PNG plots of structure and ΔE against model size and
/// analysis time. DIR must not exist; it appears complete or not at all.
///
/// Example: btfmrf generate stones --size 64 --out stones.zip && btfmrf bench stones.zip --out bench
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The measured BTF: FILE.zip, a folder, an RTI .lp file, or a photograph (PNG/JPEG/EXR).
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
    /// Measured (view, light) pairs over which the judge's figures are averaged: views spread
    /// evenly from frontal to grazing, lights varied independently of them (golden-ratio
    /// steps through the light list).
    #[arg(long, default_value_t = 8)]
    fidelity_pairs: usize,
    /// Local-PCA settings to run, each CLUSTERSxCOMPONENTS (repeat the option for several).
    #[arg(long = "lpca", value_name = "KxC", value_parser = parse_kxc, default_values = ["8x4", "32x8"])]
    lpca: Vec<(usize, usize)>,
    /// Components of the global PCA of images (PCA BTF); 0 skips it.
    #[arg(long, default_value_t = 8)]
    pca_btf: usize,
    /// Components per view of the per-view PCA (PCA RF); 0 skips it.
    #[arg(long, default_value_t = 4)]
    pca_rf: usize,
    /// Only the MRF models (no pixelwise baselines).
    #[arg(long)]
    mrf_only: bool,
    /// An image of a different material, for the judge's other-material reference level.
    #[arg(long, value_name = "IMAGE")]
    other_material: Option<PathBuf>,
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
    let shape = (
        btf.width() as usize,
        btf.height() as usize,
        btf.image_count(),
    );
    let threads = memory::worker_threads();
    let need = |side| memory::bench_bytes(shape, args.clusters, side, !args.mrf_only, threads);
    global.check_memory(
        format!("bench with --synthesis-size {}", args.synthesis_size),
        need(args.synthesis_size),
        |budget| match memory::largest_fitting(args.synthesis_size, budget, need) {
            Some(s) if need(s) > need(1) => format!("--synthesis-size {s} fits"),
            _ if !args.mrf_only => "try --mrf-only, or a smaller BTF".into(),
            _ => "the images are too large for this budget".into(),
        },
    )?;
    let options = BenchOptions {
        clusters: args.clusters,
        synthesis_side: args.synthesis_size,
        fidelity_pairs: args.fidelity_pairs,
        seed: args.seed,
        baselines: if args.mrf_only {
            Vec::new()
        } else {
            baselines(&args.lpca, args.pca_btf, args.pca_rf)
        },
        other_material: args
            .other_material
            .as_deref()
            .map(btfmrf::btf::io::read_image)
            .transpose()?,
    };
    let run = bench::run(
        &btf,
        &args.btf.display().to_string(),
        &options,
        &Bar::new(global),
    )?;
    let report = run.report;
    let plots = report.write(&args.out, &run.sheet)?;
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

/// The baselines asked for on the command line.
fn baselines(lpca: &[(usize, usize)], pca_btf: usize, pca_rf: usize) -> Vec<Baseline> {
    let mut out: Vec<Baseline> = lpca
        .iter()
        .map(|&(clusters, components)| Baseline {
            method: Method::Lpca,
            clusters,
            components,
        })
        .collect();
    for (method, components) in [(Method::PcaBtf, pca_btf), (Method::PcaRf, pca_rf)] {
        if components > 0 {
            out.push(Baseline {
                method,
                clusters: 1,
                components,
            });
        }
    }
    out
}

/// `8x4` as (8, 4).
fn parse_kxc(s: &str) -> Result<(usize, usize), String> {
    let (k, c) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected CLUSTERSxCOMPONENTS, e.g. 8x4, not {s:?}"))?;
    let num = |t: &str| {
        t.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| format!("{t:?} in {s:?} is not a positive whole number"))
    };
    Ok((num(k)?, num(c)?))
}
