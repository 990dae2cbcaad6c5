//! `btfmrf demo`: the main job, end to end, on a built-in material.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use btfmrf::btf::io;
use btfmrf::btf::synthetic::SyntheticMaterial;
use btfmrf::btf::{Btf, Direction, DirectionSet, ImageFormat};
use btfmrf::eval::bench::{self, Baseline, BenchOptions};
use btfmrf::eval::montage::montage;
use btfmrf::io::{publish_dir, temp_dir_beside, write_file_atomic};
use btfmrf::lpca::{LpcaModel, Method};
use btfmrf::memory;
use btfmrf::model::{MaterialModel, ModelKind, format};
use btfmrf::synthesis::SynthesisOptions;
use btfmrf_render::{Camera, Light, Mapping, MeshKind, Renderer, Scene};
use ndarray::Array3;

use super::{Bar, Global, emit};

/// The main job, end to end: generate a built-in material as a full Bonn BTF (81 views x 81
/// lights), fit the three MRF models (and the baselines), measure speed against error,
/// synthesize a seamless enlargement, compare measured and synthesized images under several
/// lights, and write DIR/report.md with the images, the table and the plots.
///
/// DIR must not exist; it appears complete or not at all. Takes about a minute at the default
/// size on 2 cores.
///
/// Example: btfmrf demo --out demo-out && xdg-open demo-out/report.md
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// Output folder (must not exist).
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// The built-in material: sponge, knit, stones or leather.
    #[arg(long, default_value = "sponge")]
    material: SyntheticMaterial,
    /// Measured tile size in texels (128 takes several minutes: local PCA of 16384 texel
    /// vectors of 19683 values).
    #[arg(long, default_value_t = 64)]
    size: u32,
    /// Side of the seamless enlargement, pixels.
    #[arg(long, default_value_t = 2048)]
    enlarge: usize,
    /// Side of the rendered images, pixels.
    #[arg(long, default_value_t = 384)]
    render_size: u32,
    /// Seed of every random step.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Lights of the rendered objects, (theta, phi) in degrees.
const RENDER_LIGHTS: [(f64, f64); 3] = [(30.0, 300.0), (60.0, 200.0), (75.0, 60.0)];

/// The lights of the comparisons, (theta, phi) in degrees: Bonn directions.
const LIGHTS: [(f64, f64); 3] = [(30.0, 0.0), (60.0, 90.0), (75.0, 210.0)];

/// The demo's one local-PCA size (keeps it short; `btfmrf bench` runs more): the model shown
/// in the comparison and rendered per fragment.
const DEMO_LPCA: Baseline = Baseline {
    method: Method::Lpca,
    clusters: 8,
    components: 4,
};

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let side = args.size as usize;
    let images = DirectionSet::bonn().len().pow(2);
    let bench = BenchOptions::default();
    let threads = memory::worker_threads();
    let need = |size: usize, enlarge: usize| {
        memory::bench_bytes(
            (size, size, images),
            bench.clusters,
            bench.synthesis_side,
            true,
            threads,
        )
        .max(memory::synthesis_bytes(
            enlarge,
            enlarge,
            memory::SUBSPACES_PER_IMAGE,
        ))
    };
    global.check_memory(
        format!("demo --size {} --enlarge {}", args.size, args.enlarge),
        need(side, args.enlarge),
        |budget| {
            let size = memory::largest_fitting(side, budget, |s| need(s, 1));
            let enlarge = memory::largest_fitting(args.enlarge, budget, |e| need(1, e));
            match (size, enlarge) {
                (Some(s), Some(e)) => format!("--size {s} --enlarge {e} fit"),
                _ => "nothing fits".into(),
            }
        },
    )?;
    let start = Instant::now();
    let tmp = temp_dir_beside(&args.out)?;
    let dir = tmp.path();
    let bar = Bar::new(global);
    let step = |n: usize, what: &str| {
        if !global.quiet {
            eprintln!("demo [{n}/5] {what}");
        }
    };

    step(1, "generating the material (81 x 81 images)");
    let btf = Btf::synthetic(args.material, args.size, args.seed)?;
    io::write_ubo2003(
        &btf,
        &dir.join("material.zip"),
        ImageFormat::Jpeg { quality: 90 },
        &bar,
    )?;
    io::write_image(&dir.join("measured.png"), &measured_sheet(&btf)?)?;

    step(2, "fitting and measuring every method");
    let mut baselines = vec![DEMO_LPCA];
    baselines.extend(
        Baseline::defaults()
            .into_iter()
            .filter(|b| b.method != Method::Lpca),
    );
    let options = BenchOptions {
        seed: args.seed,
        baselines,
        other_material: Some(other_material(args.material, args.size, args.seed)?),
        ..BenchOptions::default()
    };
    let run = bench::run(
        &btf,
        &format!("{} {}x{}", args.material, args.size, args.size),
        &options,
        &bar,
    )?;
    let plots = run.report.write(&dir.join("bench"), &run.sheet)?;
    std::fs::create_dir(dir.join("models")).context("creating models/")?;
    for model in &run.baseline_models {
        let name = format!("{}.lpca", model.method().name());
        write_file_atomic(&dir.join("models").join(name), &model.to_bytes())?;
    }
    for model in &run.mrf_models {
        format::write(
            model,
            &dir.join("models")
                .join(format!("{}.btfm", model.kind().name())),
        )?;
    }

    step(3, "synthesizing the enlargement and the comparisons");
    let car2d = model_of(&run.mrf_models, ModelKind::Car2d)?;
    let enlarged = enlargement(car2d, args.enlarge, args.seed)?;
    let enlarged_file = format!("enlarged-2dcar-{0}x{0}.png", enlarged.dim().1);
    io::write_image(&dir.join(&enlarged_file), &enlarged)?;
    let lpca = options
        .baselines
        .iter()
        .position(|b| *b == DEMO_LPCA)
        .and_then(|i| run.baseline_models.get(i));
    let comparison = comparison(&btf, &run.mrf_models, lpca, args.seed)?;
    io::write_image(&dir.join("comparison.png"), &comparison)?;

    step(4, "rendering objects (wgpu)");
    let renders = renders(car2d, lpca, dir, &args)?;

    step(5, "writing the report");
    let plots: Vec<(&str, &str)> = plots
        .iter()
        .map(|(t, f)| (t.as_str(), f.as_str()))
        .collect();
    let mut md = report(
        &args,
        &run.report.markdown_body(&plots, "bench/"),
        &enlarged_file,
        start,
    );
    md.push_str(&renders);
    write_file_atomic(&dir.join("report.md"), md.as_bytes())?;
    publish_dir(tmp, &args.out)?;
    emit(format!(
        "demo: wrote {} in {:.0} s (report.md, measured.png, comparison.png, {enlarged_file}, bench/, models/)",
        args.out.display(),
        start.elapsed().as_secs_f64()
    ))?;
    Ok(())
}

/// A sphere and a cloth under three lights with bump and displacement mapping, and the sphere
/// with the LPCA model decoded per fragment (when given); returns the report's section (a
/// table of the images, with what each scene needed synthesized).
fn renders(
    model: &MaterialModel,
    lpca: Option<&LpcaModel>,
    dir: &Path,
    args: &Args,
) -> anyhow::Result<String> {
    let renderer = Renderer::new()?;
    // One tileable cache for every render: each subspace image is synthesized once, when a
    // scene first needs it, at the render size's power of two (at most 1024).
    let side = (args.render_size as usize)
        .next_power_of_two()
        .clamp(model.min_synthesis_side(), 1024);
    let cache = model.synthesis_cache(&SynthesisOptions {
        rows: side,
        cols: side,
        seed: args.seed,
        tileable: true,
    })?;
    let mut md = format!(
        "## Rendered on objects ({}, textures {side}^2)\n\n\
         The 2D CAR model on a sphere and a draped cloth, camera at (35, 270), point light at \
         distance 4. Only the subspace images the scenes' view/light pairs touch are \
         synthesized, each once, when a scene first needs it. The lpca rows decode the LPCA \
         model per fragment instead (nothing synthesized; the measured tile repeats).\n\n\
         | mesh | mapping | light | image | subspaces used | newly synthesized | synthesis s \
         | render s |\n|---|---|---|---|---:|---:|---:|---:|\n",
        renderer.ctx.describe()
    );
    std::fs::create_dir(dir.join("renders")).context("creating renders/")?;
    for kind in [MeshKind::Sphere, MeshKind::Cloth] {
        for mapping in [Mapping::Bump, Mapping::Displacement] {
            let detail = if mapping == Mapping::Displacement {
                384
            } else {
                64
            };
            let mesh = kind.build(detail, 1.0)?;
            for (theta, phi) in RENDER_LIGHTS {
                let scene = demo_scene(theta, phi, args.render_size);
                let r = renderer.render_cached(model, &cache, &mesh, &scene, mapping)?;
                let name = format!("renders/{kind}-{mapping}-light{theta:.0}-{phi:.0}.png");
                io::write_image(&dir.join(&name), &r.image)?;
                md.push_str(&format!(
                    "| {kind} | {mapping} | {theta:.0}, {phi:.0} | ![{name}]({name}) | {} of {} \
                     | {} | {:.2} | {:.3} |\n",
                    r.stats.plan.clusters.len(),
                    r.stats.subspaces_total,
                    r.stats.subspaces_synthesized,
                    r.stats.synthesis_seconds,
                    r.render_seconds
                ));
            }
        }
    }
    if let Some(lpca) = lpca {
        // The measured tile repeats so that a texel covers as much of the sphere as a texel of
        // the MRF textures above (the tiles are `side` texels wide, the measurement narrower).
        let repeats = (side as f32 / lpca.width().max(1) as f32).max(1.0);
        let mesh = MeshKind::Sphere.build(64, repeats)?;
        for (theta, phi) in RENDER_LIGHTS {
            let scene = demo_scene(theta, phi, args.render_size);
            let r = renderer.render_lpca(lpca, &mesh, &scene)?;
            let name = format!("renders/sphere-lpca-light{theta:.0}-{phi:.0}.png");
            io::write_image(&dir.join(&name), &r.image)?;
            md.push_str(&format!(
                "| sphere | lpca | {theta:.0}, {phi:.0} | ![{name}]({name}) | {} clusters, \
                 decoded | 0 | 0.00 | {:.3} |\n",
                lpca.clusters(),
                r.render_seconds
            ));
        }
    }
    md.push('\n');
    Ok(md)
}

/// The judge's different material: the next built-in material, frontal view and light.
fn other_material(
    material: SyntheticMaterial,
    size: u32,
    seed: u64,
) -> anyhow::Result<Array3<f32>> {
    let all = SyntheticMaterial::ALL;
    let next = all[(all.iter().position(|&m| m == material).unwrap_or(0) + 1) % all.len()];
    Ok(Btf::synthetic(next, size, seed)?.image(0, 0)?)
}

fn model_of(models: &[MaterialModel], kind: ModelKind) -> anyhow::Result<&MaterialModel> {
    models
        .iter()
        .find(|m| m.kind() == kind)
        .with_context(|| format!("no {kind} model was fitted"))
}

/// A seamless (tileable) enlargement, frontal view, light from 45 degrees.
fn enlargement(model: &MaterialModel, side: usize, seed: u64) -> anyhow::Result<Array3<f32>> {
    let step = model.min_synthesis_side();
    let side = side.div_ceil(step) * step;
    let o = SynthesisOptions {
        rows: side,
        cols: side,
        seed,
        tileable: true,
    };
    Ok(model.synthesize_image(&Direction::new(0.0, 0.0), &Direction::new(45.0, 90.0), &o)?)
}

/// What a BTF is, at a glance: rows are views (theta 0, 45, 75), columns are lights (the
/// comparison lights).
fn measured_sheet(btf: &Btf) -> anyhow::Result<Array3<f32>> {
    let mut rows = Vec::new();
    for theta in [0.0, 45.0, 75.0] {
        let v = btf
            .views()
            .find(&Direction::new(theta, 0.0), 0.01)
            .context("a Bonn view")?;
        let mut row = Vec::new();
        for (t, p) in LIGHTS {
            let l = btf
                .lights()
                .find(&Direction::new(t, p), 0.01)
                .context("a Bonn light")?;
            row.push(btf.image(v, l)?);
        }
        rows.push(row);
    }
    let rows: Vec<Vec<&Array3<f32>>> = rows.iter().map(|r| r.iter().collect()).collect();
    Ok(montage(&rows, 4))
}

/// Rows: the comparison lights; columns: the measured image tiled 2 x 2 (the built-in
/// materials are periodic), then each MRF model's synthesis at twice the measured size, so
/// that all panels show the surface at one scale, then the local-PCA reconstruction (tiled).
fn comparison(
    btf: &Btf,
    models: &[MaterialModel],
    lpca: Option<&LpcaModel>,
    seed: u64,
) -> anyhow::Result<Array3<f32>> {
    let (h, w) = (btf.height() as usize, btf.width() as usize);
    let o = SynthesisOptions {
        rows: 2 * h,
        cols: 2 * w,
        seed,
        tileable: false,
    };
    let caches = models
        .iter()
        .map(|m| m.synthesis_cache(&o))
        .collect::<Result<Vec<_>, _>>()?;
    let view = Direction::new(0.0, 0.0);
    let mut rows = Vec::new();
    for (theta, phi) in LIGHTS {
        let light = Direction::new(theta, phi);
        let (v, l) = (
            btf.views().find(&view, 0.01).context("frontal view")?,
            btf.lights()
                .find(&light, 0.01)
                .context("comparison light")?,
        );
        let mut row = vec![bench::tile(&btf.image(v, l)?, 2 * h, 2 * w)];
        for (m, cache) in models.iter().zip(&caches) {
            row.push(m.image_from_cache(cache, &view, &light)?);
        }
        if let Some(lpca) = lpca {
            row.push(bench::tile(&lpca.reconstruct(v, l)?, 2 * h, 2 * w));
        }
        rows.push(row);
    }
    let rows: Vec<Vec<&Array3<f32>>> = rows.iter().map(|r| r.iter().collect()).collect();
    Ok(montage(&rows, 6))
}

/// The demo's report.md; `bench` is the benchmark's report body
/// ([`btfmrf::eval::bench::BenchReport::markdown_body`]).
fn report(args: &Args, bench: &str, enlarged_file: &str, start: Instant) -> String {
    let mut md = format!(
        "# btfmrf demo: {material}\n\n\
         A procedural `{material}` material, rendered for all 81 x 81 Bonn view/light pairs at \
         {size}x{size} texels (`material.zip`, UBO2003 layout), analysed into three MRF models \
         and three PCA baselines (`models/`), and synthesized back. Seed {seed}; the whole run took {secs:.0} s on this \
         machine.\n\n\
         ## The measured material\n\n\
         Rows: views at theta 0, 45 and 75 degrees (phi 0); columns: lights (theta, phi) = \
         {lights:?}. The appearance changes with both: shadows, masking, highlights.\n\n\
         ![measured](measured.png)\n\n\
         ## Measured against synthesized\n\n\
         Frontal view; rows: lights (theta, phi) = {lights:?}; columns: the measured image \
         (tiled 2 x 2), then GMRF, 2D CAR and 3D CAR syntheses at twice the measured size, and \
         the local-PCA reconstruction ({lpca_clusters} clusters x {lpca_components} \
         components, tiled). The MRF models \
         reproduce colour and second-order statistics, not the shapes of large structures; \
         LPCA reproduces the measured pixels but cannot make new texture.\n\n\
         ![comparison](comparison.png)\n\n\
         ## Seamless enlargement\n\n\
         2D CAR, {side}x{side}, tileable, frontal view, light at (45, 90): \
         [{enlarged_file}]({enlarged_file}).\n\n",
        material = args.material,
        size = args.size,
        seed = args.seed,
        secs = start.elapsed().as_secs_f64(),
        lights = LIGHTS,
        side = args.enlarge,
        lpca_clusters = DEMO_LPCA.clusters,
        lpca_components = DEMO_LPCA.components,
    );
    // The benchmark's own report, one level down, its files in bench/.
    md.push_str("## Speed against error\n\n");
    md.push_str(bench);
    md
}

/// The demo's render set-up: camera at 35 deg elevation, a point light at (`theta`, `phi`)
/// 4 units away, a `size` x `size` image.
fn demo_scene(theta: f64, phi: f64, size: u32) -> Scene {
    Scene {
        camera: Camera::orbit(Direction::new(35.0, 270.0), 4.2),
        light: Light {
            direction: Direction::new(theta, phi),
            distance: Some(4.0),
        },
        width: size,
        height: size,
    }
}
