//! `btfmrf info`: what a BTF holds.

use std::path::PathBuf;

use btfmrf::btf::{Btf, DirectionSet};

use super::{Global, emit, human_bytes};

/// Describe a BTF: its view and light directions, image size and raw size. Reads and checks
/// the whole layout (names, directions, image headers) without decoding pixels.
///
/// Accepts a UBO2003 zip or folder, an RTI folder (with a .lp file) or a .lp file.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The BTF: FILE.zip, a folder, or an RTI .lp file.
    btf: PathBuf,
    /// Print one JSON object (views, lights, width, height, images, raw_bytes, directions).
    #[arg(long)]
    json: bool,
}

fn directions_json(set: &DirectionSet) -> serde_json::Value {
    set.iter()
        .map(|d| serde_json::json!({"theta_deg": d.theta_deg, "phi_deg": d.phi_deg}))
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

pub fn run(args: Args, _global: &Global) -> anyhow::Result<()> {
    let btf = Btf::open(&args.btf)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    if args.json {
        let report = serde_json::json!({
            "path": args.btf,
            "views": btf.views().len(),
            "lights": btf.lights().len(),
            "width": btf.width(),
            "height": btf.height(),
            "images": btf.image_count(),
            "raw_bytes": btf.raw_bytes(),
            "view_directions": directions_json(btf.views()),
            "light_directions": directions_json(btf.lights()),
            "warnings": btf.warnings(),
        });
        emit(report)?;
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
