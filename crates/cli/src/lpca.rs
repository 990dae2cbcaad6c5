//! `btfmrf lpca`: a measured BTF compressed by local PCA (or a global / per-view PCA
//! baseline) into a `.lpca` file, with its error against the input.

use std::path::PathBuf;
use std::time::Instant;

use btfmrf::btf::Btf;
use btfmrf::lpca::{LpcaModel, LpcaOptions, Method, format};
use btfmrf::memory;

use super::{Bar, Global, emit, emit_json, human_bytes};

/// What `lpca --json` prints.
#[derive(serde::Serialize)]
struct LpcaSummary<'a> {
    method: &'static str,
    btf: &'a std::path::Path,
    out: &'a std::path::Path,
    width: usize,
    height: usize,
    views: usize,
    lights: usize,
    clusters: usize,
    components: usize,
    iterations: usize,
    converged: bool,
    /// The last iteration's mean squared error.
    mean_squared_error: Option<f64>,
    analysis_seconds: f64,
    load_seconds: f64,
    fit_seconds: f64,
    evaluation_seconds: f64,
    total_seconds: f64,
    model_bytes: u64,
    raw_bytes: u64,
    compression_ratio: f64,
    mean_delta_e: f64,
    psnr_db: f64,
    per_view_delta_e: Vec<ViewError>,
    worst_image: WorstImage,
}

/// Mean ΔE of one view's images.
#[derive(serde::Serialize)]
struct ViewError {
    view: usize,
    theta: f64,
    phi: f64,
    delta_e: f64,
}

/// The image with the largest mean ΔE.
#[derive(serde::Serialize)]
struct WorstImage {
    view: usize,
    light: usize,
    view_theta: f64,
    view_phi: f64,
    light_theta: f64,
    light_phi: f64,
    delta_e: f64,
}

/// Compress a BTF by local PCA (Müller, Meseth and Klein 2003): every texel's apparent BRDF
/// (all its view x light x RGB values) is assigned to one of K clusters, each a mean plus C
/// principal components, by iterated clustering on the reconstruction error. Stored as
/// 16-bit floats in a .lpca file; rebuild images with `btfmrf synthesize FILE.lpca`.
///
/// Methods: lpca (the above), pca-btf (one global PCA over whole images, eigen-textures;
/// survey section 4.2.2), pca-rf (one PCA per view over the texels' light x RGB vectors;
/// survey section 4.2.1). --clusters and --iterations apply to lpca only.
///
/// The error is measured against every input image, both quantised to 8-bit sRGB: mean
/// CIE76 ΔE, PSNR and the per-view ΔE curve.
///
/// Example: btfmrf lpca stones.zip --clusters 32 --components 8 --out stones.lpca --json
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The measured BTF: FILE.zip, a folder, or an RTI .lp file.
    btf: PathBuf,
    /// The factorization.
    #[arg(long, value_enum, default_value_t = MethodArg::Lpca)]
    method: MethodArg,
    /// Clusters K (lpca).
    #[arg(long, default_value_t = 32)]
    clusters: usize,
    /// Principal components C per cluster (per view for pca-rf).
    #[arg(long, default_value_t = 8)]
    components: usize,
    /// Output model file (.lpca).
    #[arg(long)]
    out: PathBuf,
    /// The most clustering iterations (lpca).
    #[arg(long, default_value_t = 20)]
    iterations: usize,
    /// Stop iterating when the mean squared error changes by less than this fraction.
    #[arg(long, default_value_t = 1e-3)]
    tolerance: f64,
    /// Seed of the initial cluster centres and of randomized PCA.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object: analysis_seconds, model_bytes, raw_bytes, compression_ratio,
    /// mean_delta_e, psnr_db, per_view_delta_e, worst_image, and more.
    #[arg(long)]
    json: bool,
}

/// `--method` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum MethodArg {
    /// Local PCA over texel vectors (K clusters).
    Lpca,
    /// Global PCA over images (eigen-textures).
    PcaBtf,
    /// One PCA per view over texel reflectance fields.
    PcaRf,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let btf = Btf::open(&args.btf)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    let method = match args.method {
        MethodArg::Lpca => Method::Lpca,
        MethodArg::PcaBtf => Method::PcaBtf,
        MethodArg::PcaRf => Method::PcaRf,
    };
    let options = LpcaOptions {
        method,
        clusters: args.clusters,
        components: args.components,
        max_iterations: args.iterations,
        tolerance: args.tolerance,
        seed: args.seed,
        evaluate: true,
    };
    let (w, h) = (btf.width() as usize, btf.height() as usize);
    let (nv, nl) = (btf.views().len(), btf.lights().len());
    let held = |method| if method == Method::PcaRf { nl } else { nv * nl };
    let threads = memory::worker_threads();
    global.check_memory(
        format!(
            "lpca --method {} of {} images of {w}x{h}",
            method.name(),
            nv * nl
        ),
        memory::lpca_bytes(w, h, held(method), threads),
        |budget| {
            if method != Method::PcaRf && memory::lpca_bytes(w, h, nl, threads) <= budget {
                "--method pca-rf (one view at a time) fits".into()
            } else {
                "the images are too large for this budget".into()
            }
        },
    )?;
    let start = Instant::now();
    let (model, report) = LpcaModel::fit(&btf, &options, &Bar::new(global))?;
    let total = start.elapsed().as_secs_f64();
    let analysis_seconds = report.load_seconds + report.fit_seconds;
    format::write(&model, &args.out)?;
    let model_bytes = std::fs::metadata(&args.out)?.len();
    let ratio = btf.raw_bytes() as f64 / model_bytes as f64;
    let views = model.views();
    let lights = model.lights();
    let nl = lights.len();
    let (worst, worst_de) = report
        .per_image_delta_e
        .iter()
        .copied()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NAN));
    let (wv, wl) = (
        &views.as_slice()[worst / nl],
        &lights.as_slice()[worst % nl],
    );
    if args.json {
        let per_view: Vec<ViewError> = report
            .per_view_delta_e
            .iter()
            .zip(views.iter())
            .enumerate()
            .map(|(view, (&delta_e, d))| ViewError {
                view,
                theta: d.theta_deg,
                phi: d.phi_deg,
                delta_e,
            })
            .collect();
        emit_json(&LpcaSummary {
            method: method.name(),
            btf: &args.btf,
            out: &args.out,
            width: model.width(),
            height: model.height(),
            views: views.len(),
            lights: nl,
            clusters: model.clusters(),
            components: model.components(),
            iterations: report.iterations,
            converged: report.converged,
            mean_squared_error: report.error_history.last().copied(),
            analysis_seconds,
            load_seconds: report.load_seconds,
            fit_seconds: report.fit_seconds,
            evaluation_seconds: report.evaluation_seconds,
            total_seconds: total,
            model_bytes,
            raw_bytes: btf.raw_bytes(),
            compression_ratio: ratio,
            mean_delta_e: report.mean_delta_e,
            psnr_db: report.psnr_db,
            per_view_delta_e: per_view,
            worst_image: WorstImage {
                view: worst / nl,
                light: worst % nl,
                view_theta: wv.theta_deg,
                view_phi: wv.phi_deg,
                light_theta: wl.theta_deg,
                light_phi: wl.phi_deg,
                delta_e: worst_de,
            },
        })
    } else {
        emit(format!(
            "wrote {} ({}, {} cluster(s) x {} components, {} iterations): {} for {} raw, 1:{:.1}; \
             mean ΔE {:.3}, PSNR {:.2} dB; analysis {:.2} s",
            args.out.display(),
            method.name(),
            model.clusters(),
            model.components(),
            report.iterations,
            human_bytes(model_bytes),
            human_bytes(btf.raw_bytes()),
            ratio,
            report.mean_delta_e,
            report.psnr_db,
            analysis_seconds,
        ))
    }
}
