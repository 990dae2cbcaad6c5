//! `btfmrf demo`: the main job end to end on a built-in material (skeleton: the MRF part;
//! LPCA and the benchmark table are to be added).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use btfmrf::analysis::{AnalysisOptions, analyze};
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction, io};
use btfmrf::model::{ModelKind, format};
use btfmrf::render::{Camera, Light, Mapping, MeshKind, Renderer, Scene};
use btfmrf::synthesis::SynthesisOptions;

use super::{Bar, Global, emit};

/// Run the main job end to end on a built-in material and write a report.
///
/// Generates the sponge (128 x 128, 81 x 81 images), fits a 2D CAR model, synthesizes a
/// 2048 x 2048 enlargement, renders a sphere and a cloth under three lights with bump and
/// displacement mapping, and writes DIR/report.md with the images.
///
/// Example:
///   btfmrf demo --out demo-out
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Output folder (created; existing files of the same names are replaced).
    #[arg(long)]
    out: PathBuf,
    /// Side of the generated material, texels.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Side of the enlargement, pixels.
    #[arg(long, default_value_t = 2048)]
    enlargement: usize,
    /// Side of the rendered images, pixels.
    #[arg(long, default_value_t = 512)]
    render_size: u32,
    /// Seed of everything random.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    btfmrf::render::headless::check_size(args.render_size, args.render_size)?;
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut report = String::from("# btfmrf demo\n\n");
    let started = Instant::now();

    let btf = Btf::synthetic(SyntheticMaterial::Sponge, args.size, args.seed)?;
    let t = Instant::now();
    let (model, _) = analyze(
        &btf,
        &AnalysisOptions {
            kind: ModelKind::Car2d,
            seed: args.seed,
            ..AnalysisOptions::default()
        },
        &Bar::new(global),
    )?;
    let analysis_seconds = t.elapsed().as_secs_f64();
    let model_path = out.join("sponge-2dcar.btfm");
    format::write(&model, &model_path)?;
    let model_bytes = std::fs::metadata(&model_path)?.len();
    let raw_bytes = btf.image_count() as u64 * u64::from(args.size).pow(2) * 3;
    writeln!(
        report,
        "Material: procedural sponge, {0} x {0} texels, {1} views x {2} lights ({3} bytes raw).\n\n\
         Model: 2D CAR, {4} subspace images, {5} bytes (`sponge-2dcar.btfm`, {6:.0}:1), fitted in {7:.1} s.\n",
        args.size,
        btf.views().len(),
        btf.lights().len(),
        raw_bytes,
        model.subspaces.len(),
        model_bytes,
        raw_bytes as f64 / model_bytes as f64,
        analysis_seconds
    )?;

    let n = args.enlargement;
    let t = Instant::now();
    let big = model.synthesize_image(
        &Direction::new(0.0, 0.0),
        &Direction::new(45.0, 0.0),
        &SynthesisOptions {
            rows: n,
            cols: n,
            seed: args.seed,
            tileable: false,
        },
    )?;
    let big_path = out.join(format!("enlargement-{n}.png"));
    io::write_image(&big_path, &big)?;
    writeln!(
        report,
        "## Enlargement\n\n{n} x {n}, view 0,0, light 45,0, synthesized in {:.1} s:\n\n![enlargement]({})\n",
        t.elapsed().as_secs_f64(),
        big_path.file_name().unwrap_or_default().to_string_lossy()
    )?;

    let renderer = Renderer::new()?;
    // One tileable cache for every render: each subspace image is synthesized once, when a
    // scene first needs it, at the render size's power of two (at most 1024).
    let side = (args.render_size as usize)
        .next_power_of_two()
        .clamp(1 << model.levels().max(1).saturating_sub(1), 1024);
    let cache = model.synthesis_cache(&SynthesisOptions {
        rows: side,
        cols: side,
        seed: args.seed,
        tileable: true,
    })?;
    writeln!(
        report,
        "## Rendered ({}, textures {side}^2)\n\n| mesh | mapping | light | image | subspaces used | newly synthesized | synthesis s | render s |\n|---|---|---|---|---|---|---|---|",
        renderer.ctx.describe()
    )?;
    for kind in [MeshKind::Sphere, MeshKind::Cloth] {
        for mapping in [Mapping::Bump, Mapping::Displacement] {
            let detail = if mapping == Mapping::Displacement {
                384
            } else {
                64
            };
            let mesh = kind.build(detail, 1.0)?;
            for light in [
                Direction::new(30.0, 300.0),
                Direction::new(60.0, 200.0),
                Direction::new(75.0, 60.0),
            ] {
                let scene = Scene {
                    camera: Camera::orbit(Direction::new(35.0, 270.0), 4.2),
                    light: Light {
                        direction: light,
                        distance: Some(4.0),
                    },
                    width: args.render_size,
                    height: args.render_size,
                };
                let r = renderer.render_cached(&model, &cache, &mesh, &scene, mapping)?;
                let name = format!(
                    "{kind}-{mapping}-light{:.0}-{:.0}.png",
                    light.theta_deg, light.phi_deg
                );
                io::write_image(&out.join(&name), &r.image)?;
                writeln!(
                    report,
                    "| {kind} | {mapping} | {:.0},{:.0} | ![{name}]({name}) | {} of {} | {} | {:.2} | {:.3} |",
                    light.theta_deg,
                    light.phi_deg,
                    r.plan.clusters.len(),
                    r.subspaces_total,
                    r.subspaces_synthesized,
                    r.synthesis_seconds,
                    r.render_seconds
                )?;
            }
        }
    }
    writeln!(
        report,
        "\nTotal {:.1} s. LPCA and the benchmark table: to be added.",
        started.elapsed().as_secs_f64()
    )?;
    let report_path = out.join("report.md");
    std::fs::write(&report_path, report)
        .with_context(|| format!("writing {}", report_path.display()))?;
    emit(format!("demo: wrote {}", report_path.display()))
}
