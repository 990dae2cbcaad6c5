//! `btfmrf generate`: render a procedural reference material as a BTF.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use btfmrf::btf::io;
use btfmrf::btf::synthetic::{SyntheticBtf, SyntheticMaterial};

use super::{Bar, Global, OutputFormat, emit, emit_json, human_bytes};

/// What `generate --json` prints.
#[derive(serde::Serialize)]
struct GenerateReport<'a> {
    material: &'static str,
    seed: u64,
    width: u32,
    height: u32,
    views: usize,
    lights: usize,
    images: usize,
    out: &'a std::path::Path,
    /// Bytes written (the zip, or the folder's files).
    out_bytes: u64,
    seconds: f64,
}

/// Render a procedural material (a ray-marched height field with a spatially varying BRDF,
/// cast shadows and parallax) for all 81 x 81 Bonn view/light pairs, and write it in the Bonn
/// UBO2003 layout: a zip (when --out ends in .zip) or a folder of images.
///
/// Materials: sponge (porous foam), knit (plain weave), stones (cobbles in grout),
/// leather (fine creased grain). The same --seed gives the same bytes.
///
/// Example: btfmrf generate stones --size 128 --seed 7 --out stones.zip --truth stones-truth
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The material: sponge, knit, stones or leather.
    material: SyntheticMaterial,
    /// Tile size in texels (the images are size x size), 4 to 2048.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Random seed of the material's pattern.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output: FILE.zip, or a folder that does not exist yet.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    format: OutputFormat,
    /// Also write the ground truth (height.exr, normals.exr, albedo.exr, ...) into this new
    /// folder, for checking range-map estimation later.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Print one JSON object with what was written and how long it took.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let start = Instant::now();
    let source = SyntheticBtf::new(args.material, args.size, args.seed)?;
    if let Some(dir) = &args.truth {
        source
            .ground_truth()
            .write(dir)
            .context("writing the ground truth")?;
    }
    let btf = source.into_btf();
    let bar = Bar::new(global);
    io::write_ubo2003(&btf, &args.out, args.format.image_format(), &bar)?;
    let seconds = start.elapsed().as_secs_f64();
    let bytes = disk_bytes(&args.out);
    if args.json {
        emit_json(&GenerateReport {
            material: args.material.name(),
            seed: args.seed,
            width: btf.width(),
            height: btf.height(),
            views: btf.views().len(),
            lights: btf.lights().len(),
            images: btf.image_count(),
            out: &args.out,
            out_bytes: bytes,
            seconds,
        })?;
    } else {
        emit(format!(
            "wrote {} ({} images of {}x{}, {}) in {:.1} s",
            args.out.display(),
            btf.image_count(),
            btf.width(),
            btf.height(),
            human_bytes(bytes),
            seconds
        ))?;
    }
    Ok(())
}

/// Size on disk of a file, or the sum over a folder's files.
fn disk_bytes(path: &std::path::Path) -> u64 {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => m.len(),
        Ok(_) => std::fs::read_dir(path)
            .map(|entries| {
                entries
                    .filter_map(|e| e.ok()?.metadata().ok())
                    .map(|m| m.len())
                    .sum()
            })
            .unwrap_or(0),
        Err(_) => 0,
    }
}
