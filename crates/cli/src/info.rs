//! `btfmrf info`: what a BTF holds.

use std::path::PathBuf;

use btfmrf::btf::{Btf, DirectionSet};
use btfmrf::model::{CoarseSource, MaterialModel, format};
use btfmrf::source::{AnyModel, ModelFile};

use super::{Global, emit, emit_json, human_bytes};

/// Describe a BTF: its view and light directions, image size and raw size. Reads and checks
/// the whole layout (names, directions, image headers) without decoding pixels.
///
/// Accepts a UBO2003 zip or folder, an RTI folder or zip (with a .lp file) or a .lp file; a
/// model file (.btfm or .lpca, told by its first bytes) is described too: its kind, size and
/// measured directions, and for a .btfm the optional parts it holds (exemplar, range map,
/// lattice, tables) with what each stores.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The BTF: FILE.zip, a folder, or an RTI .lp file; or a model file.
    btf: PathBuf,
    /// Print one JSON object (views, lights, width, height, images, raw_bytes, directions).
    #[arg(long)]
    json: bool,
}

/// What `info --json` prints.
#[derive(serde::Serialize)]
struct InfoReport<'a> {
    path: &'a std::path::Path,
    views: usize,
    lights: usize,
    width: u32,
    height: u32,
    images: usize,
    raw_bytes: u64,
    view_directions: Vec<Angles>,
    light_directions: Vec<Angles>,
    warnings: &'a [String],
}

/// A direction in degrees.
#[derive(serde::Serialize)]
struct Angles {
    theta_deg: f64,
    phi_deg: f64,
}

fn angles(set: &DirectionSet) -> Vec<Angles> {
    set.iter()
        .map(|d| Angles {
            theta_deg: d.theta_deg,
            phi_deg: d.phi_deg,
        })
        .collect()
}

/// "6 elevations (0-75 deg)" style summary of a set.
fn summary(set: &DirectionSet) -> String {
    let mut thetas: Vec<f64> = set.iter().map(|d| d.theta_deg).collect();
    thetas.sort_by(f64::total_cmp);
    thetas.dedup_by(|a, b| (*a - *b).abs() < 0.5);
    let (lo, hi) = (thetas[0], thetas[thetas.len() - 1]);
    format!(
        "{} ({} elevation{}, theta {lo:.0}-{hi:.0} deg)",
        set.len(),
        thetas.len(),
        if thetas.len() == 1 { "" } else { "s" }
    )
}

/// What `info --json` prints for a model file.
#[derive(serde::Serialize)]
struct ModelInfo<'a> {
    path: &'a std::path::Path,
    /// "btfm" or "lpca".
    format: &'static str,
    /// `gmrf`, `2dcar`, `3dcar`, `lpca`, `pca-btf` or `pca-rf`.
    model: &'static str,
    /// Subspace images (MRF) or clusters (PCA).
    clusters: usize,
    /// Pyramid levels (MRF only).
    #[serde(skip_serializing_if = "Option::is_none")]
    levels: Option<usize>,
    /// Principal components per cluster (PCA only).
    #[serde(skip_serializing_if = "Option::is_none")]
    components: Option<usize>,
    /// The measured tile, pixels.
    width: usize,
    height: usize,
    views: usize,
    lights: usize,
    view_directions: Vec<Angles>,
    light_directions: Vec<Angles>,
    /// The optional parts of an MRF model (empty for PCA).
    parts: Vec<ModelPart>,
}

/// One optional part of an MRF model file.
#[derive(serde::Serialize)]
struct ModelPart {
    /// "exemplar", "range map", "lattice", "colour tables", "lit tables", "light tables" or
    /// "band tables".
    part: &'static str,
    /// Its bytes in the payload before deflate.
    bytes: usize,
    /// What it holds, in words.
    holds: String,
}

/// The optional parts `m` holds.
fn model_parts(m: &MaterialModel) -> Vec<ModelPart> {
    let mut parts = Vec::new();
    let mut add = |part, bytes: usize, holds: String| {
        if bytes > 0 {
            parts.push(ModelPart { part, bytes, holds });
        }
    };
    let clusters = m.subspaces().len();
    add(
        "band tables",
        format::band_marginal_bytes(m),
        format!("quantiles of every band of {clusters} subspace images"),
    );
    add(
        "colour tables",
        format::colour_marginal_bytes(m),
        format!("joint colour marginals of {clusters} subspace images"),
    );
    add(
        "lit tables",
        format::lit_marginal_bytes(m),
        format!("relit L* quantiles of {clusters} subspace images"),
    );
    if let Some(t) = m.light_lightness() {
        add(
            "light tables",
            format::light_lightness_bytes(m),
            format!(
                "L* quantiles{}{} under each of {} lights in view {}",
                if t.spreads.is_some() {
                    ", detail band spreads"
                } else {
                    ""
                },
                if t.chroma.is_some() {
                    ", a* and b* quantiles"
                } else {
                    ""
                },
                t.tables.len(),
                t.view
            ),
        );
    }
    if let Some(e) = m.exemplar() {
        let coarse = match e.coarse {
            CoarseSource::Mrf => "the MRF",
            CoarseSource::Laid => "the laid crops",
        };
        let chroma = e.chroma.as_ref().map_or(String::new(), |c| {
            let side = c.step * e.step;
            format!(", chroma in {side} x {side} pixel blocks")
        });
        let sampling = match e.step {
            1 => String::new(),
            step => format!(", one sample every {step} pixels"),
        };
        let lights = e.light_weights.as_ref().map_or(String::new(), |l| {
            format!(
                "; each of {} lights in view {} weighs them",
                l.weights.len(),
                l.view
            )
        });
        add(
            "exemplar",
            format::exemplar_bytes(m),
            format!(
                "{} x {} L* crops (mean and {} deviations){sampling}{chroma}; coarse L* from {coarse}{lights}",
                e.cols,
                e.rows,
                e.lightness.basis.len().saturating_sub(1)
            ),
        );
    }
    if let Some(p) = m.periodic() {
        add(
            "lattice",
            format::periodic_bytes(m),
            format!(
                "period of {:.1} x {:.1} pixels in {} x {} samples (mean and {} {}deviations){}",
                p.lattice.cols,
                p.lattice.rows,
                p.cols,
                p.rows,
                p.periods.basis.len().saturating_sub(1),
                if p.grey_deviations() { "grey " } else { "" },
                p.light_weights.as_ref().map_or(String::new(), |l| format!(
                    "; each of {} lights in view {} weighs its deviations",
                    l.weights.len(),
                    l.view
                ))
            ),
        );
    }
    if let Some(r) = m.range_map() {
        let samples = match r.step {
            1 => "one a pixel".to_string(),
            step => format!("one every {step} pixels"),
        };
        let shadows = format!("{:?}", r.shadows).to_lowercase();
        add(
            "range map",
            format::range_map_bytes(m),
            format!(
                "{} x {} heights, {samples}; {shadows} shadows",
                r.cols, r.rows
            ),
        );
    }
    parts
}

fn describe_model(path: &std::path::Path, json: bool) -> anyhow::Result<()> {
    let model = AnyModel::open(path)?;
    let info = match &model {
        AnyModel::Mrf(m) => ModelInfo {
            path,
            format: "btfm",
            model: m.kind().name(),
            clusters: m.subspaces().len(),
            levels: Some(m.levels()),
            components: None,
            width: m.width() as usize,
            height: m.height() as usize,
            views: m.views().len(),
            lights: m.lights().len(),
            view_directions: angles(m.views()),
            light_directions: angles(m.lights()),
            parts: model_parts(m),
        },
        AnyModel::Lpca(m) => ModelInfo {
            path,
            format: "lpca",
            model: m.method().name(),
            clusters: m.clusters(),
            levels: None,
            components: Some(m.components()),
            width: m.width(),
            height: m.height(),
            views: m.views().len(),
            lights: m.lights().len(),
            view_directions: angles(m.views()),
            light_directions: angles(m.lights()),
            parts: Vec::new(),
        },
    };
    if json {
        return emit_json(&info);
    }
    let parts = match (info.levels, info.components) {
        (Some(levels), _) => format!("{} subspace images, {levels} levels", info.clusters),
        (_, Some(c)) => format!("{} cluster(s) x {c} components", info.clusters),
        _ => String::new(),
    };
    emit(format!(
        "{}: {} model (.{}), {parts}",
        path.display(),
        info.model,
        info.format
    ))?;
    emit(format!("  views:  {}", summary(model.views())))?;
    emit(format!("  lights: {}", summary(model.lights())))?;
    emit(format!(
        "  measured tile: {} x {} pixels",
        info.width, info.height
    ))?;
    if !info.parts.is_empty() {
        emit("  parts (sizes before the file's deflate):")?;
    }
    for p in &info.parts {
        let bytes = human_bytes(p.bytes as u64);
        emit(format!("    {} ({bytes}): {}", p.part, p.holds))?;
    }
    Ok(())
}

pub fn run(args: Args, _global: &Global) -> anyhow::Result<()> {
    if ModelFile::of(&args.btf)?.is_some() {
        return describe_model(&args.btf, args.json);
    }
    let btf = Btf::open(&args.btf)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    if args.json {
        emit_json(&InfoReport {
            path: &args.btf,
            views: btf.views().len(),
            lights: btf.lights().len(),
            width: btf.width(),
            height: btf.height(),
            images: btf.image_count(),
            raw_bytes: btf.raw_bytes(),
            view_directions: angles(btf.views()),
            light_directions: angles(btf.lights()),
            warnings: btf.warnings(),
        })?;
    } else {
        emit(btf.label())?;
        emit(format!("  views:  {}", summary(btf.views())))?;
        emit(format!("  lights: {}", summary(btf.lights())))?;
        emit(format!(
            "  size:   {} x {} pixels",
            btf.width(),
            btf.height()
        ))?;
        emit(format!(
            "  images: {} ({} as raw 8-bit RGB)",
            btf.image_count(),
            human_bytes(btf.raw_bytes())
        ))?;
    }
    Ok(())
}
