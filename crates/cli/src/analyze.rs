//! `btfmrf analyze`: a measured BTF to a compact `.btfm` model.

use std::path::PathBuf;
use std::time::Instant;

use btfmrf::analysis::{AnalysisOptions, AnalysisRepair, ReliefLayout, analyze};
use btfmrf::btf::Btf;
use btfmrf::geometry::relight::Shadows;
use btfmrf::memory;
use btfmrf::model::{CoarseSource, ModelKind, format};

use super::{Bar, Global, emit, emit_json, human_bytes};

/// What `analyze --json` prints.
#[derive(serde::Serialize)]
struct AnalyzeReport<'a> {
    /// `gmrf`, `2dcar` or `3dcar`.
    model: &'static str,
    analysis_seconds: f64,
    model_bytes: u64,
    raw_bytes: u64,
    compression_ratio: f64,
    clusters: usize,
    levels: usize,
    /// The stored range map's size; `None` without one.
    range_map: Option<RangeMapSize>,
    band_marginal_bytes: usize,
    colour_marginal_bytes: usize,
    lit_marginal_bytes: usize,
    light_table_bytes: usize,
    exemplar_bytes: usize,
    /// Where the exemplar's synthesis takes the L* coarser than its patches ("mrf" or
    /// "laid"); `None` without an exemplar.
    exemplar_coarse: Option<CoarseSource>,
    /// Periods (rows, columns; measured pixels) of the lattice found, if any.
    lattice: Option<[f64; 2]>,
    periodic_bytes: usize,
    repairs: &'a [AnalysisRepair],
    warnings: &'a [String],
    /// What analysis chose that is not a problem (e.g. what the byte limit cut).
    notes: &'a [String],
}

/// Rows, columns and step (measured texels per sample) of a stored range map.
#[derive(serde::Serialize)]
struct RangeMapSize {
    rows: usize,
    cols: usize,
    step: usize,
    shadows: Shadows,
}

/// `--shadows`: which shadows the range map casts, or let analysis choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ShadowChoice {
    Auto,
    Attached,
    Cast,
}

/// `--relief-layout`: where a large capture keeps its range map, or let analysis choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum LayoutChoice {
    Auto,
    Window,
    Whole,
}

/// `--coarse`: where the exemplar's coarse variation comes from, or let analysis choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum CoarseChoice {
    Auto,
    Laid,
    Mrf,
}

/// Fit the probabilistic BTF model of Haindl and Filip: cluster the view x light space into
/// subspace images (k-means on CIE Lab cumulative histograms), decorrelate colour (KL), split
/// each factor into a Gaussian-Laplacian pyramid and fit one MRF per band, then write the
/// parameters as a .btfm file of a few tens of kilobytes.
///
/// Models: 2dcar (2D causal autoregressive, Bayesian order selection), gmrf (Gaussian MRF,
/// exactly tileable), 3dcar (3D causal AR on the colour channels jointly, no KL).
///
/// Example: btfmrf analyze stones.zip --model gmrf --out stones.btfm --json
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The measured BTF: FILE.zip, a folder, an RTI .lp file, or a photograph (PNG/JPEG/EXR).
    btf: PathBuf,
    /// The band model.
    #[arg(long, default_value = "2dcar")]
    model: ModelKind,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
    /// Number of subspace images (clusters of the view x light space).
    #[arg(long, default_value_t = 20)]
    clusters: usize,
    /// Weight of the light and view directions beside the colour histograms when the images
    /// are clustered: the share of the histograms' variance the directions get (0: histograms
    /// alone, the survey's clustering). Histograms alone put every azimuth of a light's
    /// elevation in one subspace image, though the relief's shading and shadows fall another
    /// way under each; with the directions each subspace image stays with neighbouring
    /// lights (on the built-in materials the texture judge's structure distance fell by 14-24
    /// %). Default: 0.5 for a BTF of several views, 0 for a one-view capture (an RTI dome),
    /// where the histograms already follow the light's elevation and the directions measured
    /// slightly worse.
    #[arg(long)]
    direction_share: Option<f64>,
    /// Pyramid levels (default: as many as keep the coarsest band >= 16 px, at most 4).
    #[arg(long)]
    levels: Option<usize>,
    /// Largest causal neighbourhood order tried, 1-6 (2, 4, 6, 10, 12, 14 neighbours).
    #[arg(long, default_value_t = 6)]
    max_order: usize,
    /// Seed of the clustering.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Do not estimate a range map (photometric stereo on the frontal view); synthesized
    /// images are then not relit by bump mapping.
    #[arg(long)]
    no_range_map: bool,
    /// Store a 33-quantile table per pyramid band (74 bytes each) and match every
    /// synthesized band to it before the pyramid is collapsed.
    #[arg(long)]
    band_marginals: bool,
    /// Do not store the colour marginals along 12 directions, the chroma-lightness coupling
    /// and the chroma's spread per pyramid band (1,000 bytes a subspace image) that move
    /// every synthesized image's colours towards the measured joint colour distribution and
    /// chroma spectrum; without them the independently synthesized colour factors combine
    /// into colours the material never shows (saturated specks on dark pixels). Beside a
    /// range map, whose light tables give every light its measured chroma, analysis keeps
    /// them only where the judge finds the model closer with them (one more judged
    /// synthesis per judged light).
    #[arg(long)]
    no_colour_matching: bool,
    /// Do not store the measured lightness of each subspace image's representative with its
    /// relief shading in (33 L* quantiles, 74 bytes a subspace image; only beside a range
    /// map). With them, each subspace image is scaled pixel by pixel (chromaticity kept) so
    /// that, relit by the synthesized relief for its representative's light, its L*
    /// distribution is the measured one: the relief's shading otherwise meets the colours
    /// differently than in the measured image (on the built-in materials at 128^2, nine
    /// frontal lights, the mean Lab quantile distance fell from 0.90-1.88 to 0.53-1.57).
    #[arg(long)]
    no_lit_matching: bool,
    /// Do not store the measured lightness under every light of the view the range map is
    /// registered with (33 L* quantiles, 74 bytes a light; only beside a range map). With
    /// them, the finished image's L* is mapped (chromaticity kept) onto the requested light's
    /// tables, blended over the three nearest lights, in proportion to that view's share of
    /// the requested view: a cluster's lights share one subspace image, matched to its
    /// representative's light only. On the built-in materials (128^2, nine measured frontal lights,
    /// seeds 1-4) colour went from 0.56-1.50 to 0.25-0.66 Lab and structure from x1.26-4.72 to
    /// x1.12-4.28 the another-crop level; halfway between measured lights the leather, stones and
    /// knit still gain and the sponge loses 3-5 % of structure. 6 KB for 81 lights. The
    /// tables also hold the spread of each light's L* in five detail bands (about 2 to 64 px
    /// periods; 5 bytes a light), to which the image's bands are scaled before the mapping
    /// (bands finer than the range map's samples are left alone): structure x1.24 / 1.47 /
    /// 1.00 / 3.95 -> x1.17 / 1.43 / 0.96 / 3.78 on sponge / stones / leather / knit at the
    /// measured lights (seeds 1-4). `render` and `view` do not apply them yet.
    #[arg(long)]
    no_light_tables: bool,
    /// Do not store, with the light tables, every light's measured a* and b* quantiles (17
    /// each, a byte a value across the lights: 3.0 KB for 81 lights before deflate; none for
    /// a grey material). With them, the finished image's a* and b* are mapped onto the
    /// quantiles blended over the nearest lights, L* kept, and no pixel's chromaticity beyond
    /// the image's own range: a cluster's lights otherwise share their representative's
    /// chroma. Measured (built-in materials, 128^2, nine frontal lights): see
    /// docs/BENCHMARKS.md.
    #[arg(long)]
    no_light_chroma: bool,
    /// Do not store every light's own weights on the exemplar's L* deviations (only beside a
    /// range map and an exemplar; a byte a light and deviation, about 0.5 KB for 81 lights)
    /// and, on a lattice beside a range map, on the periods' deviations (about 0.7 KB). With
    /// them, the image under a light of the view the range map is registered with gets that
    /// light's own exemplar detail (its cast shadows, highlights and what the relief's shading
    /// leaves; on a lattice, of the brightness around the light's own period) and period
    /// instead of its cluster representative's, and the exemplar crops count in the deviations
    /// (together as much as the subspace images' crops; more deviations may be kept). Costs
    /// analysis one read and de-shading of every light's image in that view, and synthesis a
    /// second colour transfer for each image of that view (on a lattice, two more passes over
    /// the image instead).
    #[arg(long)]
    no_light_weights: bool,
    /// Largest side of the structure exemplar (pixels; 0: none): the L* of a centred crop of
    /// every subspace image, stored as their mean (a byte a pixel) and up to six principal
    /// deviations (4 bits a pixel), quilted at synthesis with one layout to carry each subspace image's
    /// structure finer than a third of the crop, which second-order MRF models lose (cells,
    /// grains, stones, the shadows of a relief under each light). The coarser L* comes from
    /// the MRF, or from the laid crops themselves where a check finds them clearly closer to
    /// the measured images (see --coarse). The crops' a* and b* are stored too (unless they
    /// vary by less than 0.01 Lab, as a grey photograph's do), averaged over 2 x 2 pixels
    /// (4 x 4 for a 256 crop, 8 x 8 for 320 or 360; at most 8 KiB), and laid with the same
    /// patches, so each stone or thread keeps its own colour. Default: 360 for a photograph
    /// (one subspace image, one crop of 127 KiB; a larger crop gives the quilt more to choose
    /// from: the three grey photographs' models take 77-120 KB, at most about 135 KB),
    /// 128 for several subspace images (the mean, 16 KiB, and up to sixteen deviations, 8 KiB
    /// each, of which `--max-bytes` keeps what fits).
    /// Stored when there is no range map (a photograph), and beside a range map when a check
    /// at analysis finds it brings the synthesis closer to the measured images. The exemplar
    /// then covers the range map's region, a centred window (at most 128 x 128) at every pixel
    /// or a larger capture's whole map averaged down to 128 samples a side (see
    /// --relief-layout), and the two are laid with the relief's own patches, so colour and
    /// relief line up (a side below that window stores no exemplar beside a range map). The
    /// check synthesizes and judges up to eight subspace images two or three times, on the
    /// measured images' centred crop of at most 256 x 256: a 256^2 built-in sponge (81 x 81
    /// images) took 21 s to analyse against 10 s with --exemplar 0, the 310^2 clay-leaf RTI
    /// capture 37 s (both layouts, see --relief-layout) against 2 s, on a 2-core machine. The quilt costs synthesis time: a 1024x1024 image of
    /// a photograph's model took 0.22-0.28 s with it and 0.08-0.10 s without on a 2-core
    /// machine for a grey photograph (gravel, medians of 11 calls in two runs), 0.33 s and
    /// 0.21 s for a colour one (a 334 x 322 painting, medians of 9 and 7), whose chroma is
    /// drawn, laid and matched as well.
    #[arg(long)]
    exemplar: Option<usize>,
    /// Do not look for a lattice. By default a material that repeats along both image axes (a
    /// weave, tiles, a brick bond photographed square-on: a clear autocorrelation peak at the
    /// period; a pattern at an angle or in perspective is not found) keeps each
    /// subspace image's mean period, at most 32 x 32 samples (a mean and up to 8 principal
    /// deviations of 6 KiB each: 56.7 KiB for a 128^2 knit at 20 subspace images), laid on
    /// the lattice at synthesis, and the MRF models only the variation around it; the range
    /// map is then laid on the same lattice instead of quilted. The exemplar (see --exemplar)
    /// then holds the detail around the period (a thread's fibres, L* only, at most 96 x 96
    /// cut at the lattice's origin, 32 KiB) and is quilted in step with the lattice, so each
    /// thread keeps its own grain (a 1024x1024 knit image: 0.65 s with it, 0.34 s without).
    /// Stochastic textures are not affected.
    #[arg(long)]
    no_lattice: bool,
    /// Which shadows the range map casts when synthesis relights it: `auto` (the default:
    /// cast where those shadows leave at most 0.9 of the frontal photographs' variation
    /// unexplained that attached shadows alone leave; built-in stones and sponge: 0.67 and
    /// 0.53, cast; knit, leather and the five RTI captures: attached), `attached` (facets
    /// turned from the light go dark) or `cast` (also where the relief blocks the way to the
    /// light: a hard shadow ray marched over the heights, one texel a step, at most 256 steps
    /// per pixel at synthesis and in the renderer's shader). Oblique views also see the
    /// relief's parallax and masking, which hide the shadows behind the bumps (always on with
    /// a range map). Cost of cast shadows: a 1024x1024 stones image takes about a quarter more
    /// CPU time, and `render` about 2 s more to tabulate the shadowed mean shading over light
    /// directions.
    #[arg(long, value_enum, default_value_t = ShadowChoice::Auto)]
    shadows: ShadowChoice,
    /// Where the structure exemplar's synthesis takes the L* variation coarser than its quilt
    /// patches (half a patch and up; the coarser chroma is always the MRF's): `laid` (the
    /// laid crops themselves, moved to the MRF's mean), `mrf` (the MRF's bands; every model
    /// before format version 11) or `auto` (the default: mrf, unless beside a range map on
    /// images of at least 64 pixels a side the judge finds the laid crops' at most 0.95 of
    /// the MRF's distance to the measured images at up to eight subspace images: one more
    /// synthesis of each, about a second more for a 128^2 built-in material, the leather
    /// 6.4 -> 7.4 s). Measured over seeds 1-4, nine frontal lights: the built-in leather's
    /// MRF drew blotches (x1.44 the another-crop level, laid x1.26; auto chooses laid); the
    /// stones, sponge and knit moved by at most 0.04 a seed either way (auto keeps mrf).
    #[arg(long, value_enum, default_value_t = CoarseChoice::Auto)]
    coarse: CoarseChoice,
    /// Where a capture over 128 pixels a side keeps its range map and the exemplar beside it:
    /// `window` (its centred 128 x 128 at every pixel: the finest relief, of a part of it),
    /// `whole` (all of it, averaged over 2 x 2 pixels or more to fit 128 samples a side:
    /// structures larger than a window's quilt patches stay whole, detail finer than a sample
    /// is lost) or `auto` (the default: whole where the relief varies more at the scales a
    /// window's patches cut through than finer than the averaged samples; where the whole
    /// capture's exemplar then fails analysis's check, the window is analysed too and kept if
    /// the judge finds it closer, which more than doubles the analysis time: the clay-leaf RTI
    /// capture 15 s -> 37 s, painted-door 23 s -> 55 s).
    /// Measured on the built-in materials at 256^2, enlarged to 512^2 (nine frontal lights,
    /// seed 1, x the another-crop level, window -> whole): stones 2.60 -> 1.71 (the window's
    /// patches cut the stones into blocks), sponge 2.04 -> 1.48, leather 2.00 -> 3.69 (its fine
    /// creases averaged away; auto keeps the window).
    #[arg(long, value_enum, default_value_t = LayoutChoice::Auto)]
    relief_layout: LayoutChoice,
    /// Largest model file in bytes (0: no limit). A model above it drops its light chroma
    /// tables where that alone makes it fit, else its exemplar's principal deviations, the
    /// last first (8 KiB each at a 128 x 128 crop), until it fits, and says so; analysis
    /// judges its candidates (colour tables or none, exemplar or none) as cut to it. The
    /// exemplar keeps up to sixteen deviations, so most multi-light captures fill the limit:
    /// the built-in sponge, stones and leather at 128^2 and 20 clusters drop 6, 7 and 10 of
    /// them (the knit, on a lattice, has its own smaller budget). Its default is the 150 KB
    /// the models are held to.
    #[arg(long, default_value_t = btfmrf::analysis::MODEL_BUDGET)]
    max_bytes: usize,
    /// Print one JSON object: analysis_seconds, model_bytes, raw_bytes, compression_ratio,
    /// clusters, levels, band_marginal_bytes, colour_marginal_bytes, lit_marginal_bytes,
    /// light_table_bytes, exemplar_bytes, exemplar_coarse, lattice, periodic_bytes, repairs,
    /// warnings, notes.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let btf = Btf::open(&args.btf)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    let (w, h, images) = (
        btf.width() as usize,
        btf.height() as usize,
        btf.image_count(),
    );
    let threads = memory::worker_threads();
    let need = |clusters| memory::analysis_bytes(w, h, images, clusters, threads);
    global.check_memory(
        format!(
            "analyze of {images} images of {w}x{h} into {} clusters",
            args.clusters
        ),
        need(args.clusters),
        |budget| match memory::largest_fitting(args.clusters, budget, need) {
            Some(k) => format!("--clusters {k} fits"),
            None => "the images are too large for this budget".into(),
        },
    )?;
    let start = Instant::now();
    let options = AnalysisOptions {
        kind: args.model,
        clusters: args.clusters,
        direction_share: args.direction_share,
        levels: args.levels,
        max_order: args.max_order,
        seed: args.seed,
        range_map: !args.no_range_map,
        band_marginals: args.band_marginals,
        colour_matching: !args.no_colour_matching,
        lit_matching: !args.no_lit_matching,
        light_tables: !args.no_light_tables,
        light_chroma: !args.no_light_chroma,
        light_weights: !args.no_light_weights,
        max_bytes: (args.max_bytes > 0).then_some(args.max_bytes),
        exemplar_side: args.exemplar,
        periodic: !args.no_lattice,
        shadows: match args.shadows {
            ShadowChoice::Auto => None,
            ShadowChoice::Attached => Some(Shadows::Attached),
            ShadowChoice::Cast => Some(Shadows::Cast),
        },
        coarse: match args.coarse {
            CoarseChoice::Auto => None,
            CoarseChoice::Laid => Some(CoarseSource::Laid),
            CoarseChoice::Mrf => Some(CoarseSource::Mrf),
        },
        relief_layout: match args.relief_layout {
            LayoutChoice::Auto => None,
            LayoutChoice::Window => Some(ReliefLayout::Window),
            LayoutChoice::Whole => Some(ReliefLayout::Whole),
        },
        ..AnalysisOptions::default()
    };
    let (model, report) = analyze(&btf, &options, &Bar::new(global))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    for n in &report.notes {
        eprintln!("note: {n}");
    }
    let seconds = start.elapsed().as_secs_f64();
    format::write(&model, &args.out)?;
    let model_bytes = std::fs::metadata(&args.out)?.len();
    let ratio = btf.raw_bytes() as f64 / model_bytes as f64;
    if args.json {
        emit_json(&AnalyzeReport {
            model: model.kind().name(),
            analysis_seconds: seconds,
            model_bytes,
            raw_bytes: btf.raw_bytes(),
            compression_ratio: ratio,
            clusters: model.subspaces().len(),
            levels: model.levels(),
            range_map: model.range_map().map(|r| RangeMapSize {
                rows: r.rows,
                cols: r.cols,
                step: r.step,
                shadows: r.shadows,
            }),
            band_marginal_bytes: format::band_marginal_bytes(&model),
            colour_marginal_bytes: format::colour_marginal_bytes(&model),
            lit_marginal_bytes: format::lit_marginal_bytes(&model),
            light_table_bytes: format::light_lightness_bytes(&model),
            exemplar_bytes: format::exemplar_bytes(&model),
            exemplar_coarse: model.exemplar().map(|e| e.coarse),
            lattice: model.periodic().map(|p| [p.lattice.rows, p.lattice.cols]),
            periodic_bytes: format::periodic_bytes(&model),
            repairs: &report.repairs,
            warnings: &report.warnings,
            notes: &report.notes,
        })?;
    } else {
        if !report.repairs.is_empty() {
            eprintln!(
                "note: {} estimate(s) were repaired (--json lists all), e.g. {}",
                report.repairs.len(),
                report.repairs[0]
            );
        }
        if let Some(p) = model.periodic() {
            eprintln!(
                "note: a lattice of {:.1} x {:.1} pixels was found; its mean period is stored ({}; --no-lattice turns it off)",
                p.lattice.rows,
                p.lattice.cols,
                human_bytes(format::periodic_bytes(&model) as u64)
            );
        }
        if args.shadows == ShadowChoice::Auto
            && model
                .range_map()
                .is_some_and(|m| m.shadows == Shadows::Cast)
        {
            eprintln!(
                "note: the range map casts shadows: they explain the frontal photographs clearly better (--shadows attached turns them off)"
            );
        }
        emit(format!(
            "wrote {} ({} model, {} subspaces, {} levels): {} for {} raw, 1:{:.0}, in {:.2} s",
            args.out.display(),
            model.kind(),
            model.subspaces().len(),
            model.levels(),
            human_bytes(model_bytes),
            human_bytes(btf.raw_bytes()),
            ratio,
            seconds
        ))?;
    }
    Ok(())
}
