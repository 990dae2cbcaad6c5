//! `btfmrf render`: a model on a mesh, rendered headless by the GPU (or Mesa lavapipe) to PNG.

use std::path::{Path, PathBuf};

use anyhow::Context;
use btfmrf::btf::{Direction, io};
use btfmrf::lpca;
use btfmrf::memory;
use btfmrf::model::format;
use btfmrf::progress::NoProgress;
use btfmrf::source::ModelFile;
use btfmrf_render::lut::DirectionLut;
use btfmrf_render::plan::plan_scene;
use btfmrf_render::{
    Camera, Light, Mapping, Material, MeshKind, ModelRenderOptions, RenderStats, Renderer, Scene,
};

use super::synthesize::{parse_direction, parse_size};
use super::{Bar, Global, emit, emit_json};

/// Render a model on a mesh to an image, headless (works without a GPU through Mesa's
/// software Vulkan driver, lavapipe).
///
/// One texture repetition holds --tile measured texels (the material's physical scale on
/// the mesh). Only the subspace images the visible surface needs are synthesized, always at
/// --tile texels a side, then sampled on the GPU at the resolution the screen footprint asks
/// for (a power of two, at most --max-texture-size and --tile): the relief looks the same at
/// every distance and texture size. Cost: the synthesis dominates and grows with the square
/// of --tile (4x per doubling) times the clusters the view touches; the texture size changes
/// only the (small) GPU cost.
/// Where a model keeps light tables or each light's own exemplar detail (near the view they
/// were measured in), the CPU also finishes each measured pair the surface draws on: one
/// --tile-sized image of what those parts add (as `synthesize` applies them), which the GPU
/// adds blended like the pairs. A render then equals `synthesize` at a measured light and
/// blends the nearest lights' finishes between them; each finish costs about a subspace
/// image's synthesis.
/// An LPCA model (.lpca, told by its magic bytes; also pca-rf) is decoded per fragment on
/// the GPU instead, on the mesh as it is (it has no range map, so no --mapping): nothing is
/// synthesized.
///
/// Examples:
///   btfmrf render sponge.btfm --out sphere.png --size 800x800 --mesh sphere --mapping bump
///   btfmrf render sponge.btfm --out cloth.png --mesh cloth --mapping displacement --light 60,200
///   btfmrf render sponge.btfm --out bunny.png --mesh bunny.obj --view 20,270 --json
///   btfmrf render sponge.lpca --out lpca.png --mesh sphere --light 60,200
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The model file (.btfm, or .lpca).
    model: PathBuf,
    /// Output image (.png, .jpg or .exr).
    #[arg(long)]
    out: PathBuf,
    /// Image size: N (square) or WxH, pixels.
    #[arg(long, value_parser = parse_size, default_value = "512")]
    size: (usize, usize),
    /// sphere, plane, cloth, torus, or an OBJ file (with texture coordinates).
    #[arg(long, default_value = "sphere")]
    mesh: MeshKind,
    /// How an MRF model (.btfm) meets the geometry: bump, displacement, or plain (one
    /// subspace image as a plain texture, no view or light dependence: the cost baseline).
    /// Default: bump. Not for an .lpca model.
    #[arg(long)]
    mapping: Option<Mapping>,
    /// Camera direction "theta,phi" in degrees, seen from the object (phi 270 = in front).
    #[arg(long, value_parser = parse_direction, default_value = "30,270")]
    view: Direction,
    /// Camera distance from the object's centre, world units (the sphere's radius is 1, the
    /// plane and cloth are 2 wide).
    #[arg(long, default_value_t = 3.5)]
    distance: f32,
    /// Light direction "theta,phi" in degrees, seen from the object.
    #[arg(long, value_parser = parse_direction, default_value = "45,300")]
    light: Direction,
    /// Point-light distance from the object's centre, world units like --distance; the
    /// irradiance falls off with the inverse square of the distance, 1 at the centre ("inf":
    /// a directional light, irradiance 1 everywhere).
    #[arg(long, default_value_t = 4.0)]
    light_distance: f32,
    /// Fixed GPU texture side (a power of two; at most --tile, larger is clamped to it);
    /// default: from the screen footprint. It sets how finely the tile is sampled, not how
    /// large the material appears.
    #[arg(long)]
    texture_size: Option<usize>,
    /// Largest texture side chosen from the footprint.
    #[arg(long, default_value_t = 2048)]
    max_texture_size: usize,
    /// Measured texels per texture repetition (a power of two): the material's physical
    /// scale on the mesh, and the side at which subspace images and range map are
    /// synthesized.
    #[arg(long, value_name = "TEXELS", default_value_t = btfmrf_render::headless::DEFAULT_TILE)]
    tile: usize,
    /// Texture repetitions per unit length of the built-in meshes.
    #[arg(long, default_value_t = 1.0)]
    repeats: f32,
    /// Mesh grid resolution (default: 64 for bump, 384 for displacement).
    #[arg(long)]
    detail: Option<u32>,
    /// Seed of the synthesis: same seed, same image.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object (timings in seconds, subspaces and texels synthesized).
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let (rows, cols) = args.size;
    let (width, height) = (u32::try_from(cols)?, u32::try_from(rows)?);
    btfmrf_render::frame::check_size(width, height)?;
    if !(args.distance.is_finite() && args.distance > 0.0) {
        anyhow::bail!("invalid --distance {}: must be positive", args.distance);
    }
    if args.light_distance.is_nan() || args.light_distance <= 0.0 {
        anyhow::bail!(
            "invalid --light-distance {}: must be positive",
            args.light_distance
        );
    }
    if !(args.repeats.is_finite() && args.repeats > 0.0 && args.repeats <= 1000.0) {
        anyhow::bail!(
            "invalid --repeats {}: must be within (0, 1000]",
            args.repeats
        );
    }
    if let Some(n) = args.texture_size
        && (!n.is_power_of_two() || n > btfmrf_render::MAX_RENDER_SIDE as usize)
    {
        anyhow::bail!(
            "invalid --texture-size {n}: a power of two within 1..={}",
            btfmrf_render::MAX_RENDER_SIDE
        );
    }
    let is_lpca = ModelFile::of(&args.model)? == Some(ModelFile::Lpca);
    if is_lpca && let Some(m) = args.mapping {
        anyhow::bail!(
            "invalid --mapping {m}: {} is an LPCA model, decoded on the mesh as it is \
             (--mapping applies to MRF models)",
            args.model.display()
        );
    }
    let mapping = args.mapping.unwrap_or(Mapping::Bump);
    let detail = args.detail.unwrap_or(match mapping {
        Mapping::Displacement => 384,
        Mapping::Bump | Mapping::Plain => 64,
    });
    let mesh = args.mesh.build(detail, args.repeats)?;
    let scene = Scene {
        camera: Camera::orbit(args.view, args.distance),
        light: Light {
            direction: args.light,
            distance: args
                .light_distance
                .is_finite()
                .then_some(args.light_distance),
        },
        width,
        height,
    };
    let out = if is_lpca {
        let model = lpca::format::read(&args.model)?;
        Renderer::new()?.render_material(Material::Lpca(&model), &mesh, &scene, &NoProgress)?
    } else {
        let model = format::read(&args.model)?;
        // Checked before the memory estimate squares it.
        btfmrf_render::check_tile(&model, args.tile)?;
        // The subspace images are synthesized at the tile's side, whatever the texture size,
        // and so are the finishes of the measured pairs with parts of their own that the
        // surface draws on (each about a subspace image's memory).
        let texture = args.tile;
        let threads = memory::worker_threads();
        let finishes = match mapping {
            Mapping::Plain => 0,
            Mapping::Bump | Mapping::Displacement => {
                let luts = (
                    DirectionLut::new(model.views())?,
                    DirectionLut::new(model.lights())?,
                );
                plan_scene(&model, &mesh, &scene, (&luts.0, &luts.1), (1, 1))
                    .finishes
                    .len()
            }
        };
        let need = |side| {
            memory::render_bytes(
                width as usize * height as usize,
                side,
                model.subspaces().len() + finishes,
                threads,
            )
        };
        global.check_memory(
            format!("render with a {texture}^2 tile"),
            need(texture),
            |budget| tile_that_fits(need, budget),
        )?;
        let options = ModelRenderOptions {
            mapping,
            seed: args.seed,
            texture_size: args.texture_size,
            max_texture_size: args.max_texture_size.clamp(32, 8192),
            tile: args.tile,
        };
        Renderer::new()?.render_material(
            Material::Mrf(&model, options),
            &mesh,
            &scene,
            &Bar::new(global),
        )?
    };
    io::write_image(&args.out, &out.image)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if args.json {
        let material = match &out.stats {
            RenderStats::Mrf(s) => MaterialReport::Mrf {
                mapping: mapping.name(),
                texture_size: s.plan.texture_size,
                tile: s.tile,
                clusters: &s.plan.clusters,
                finished_pairs: &s.plan.finishes,
                subspaces_synthesized: s.subspaces_synthesized,
                subspaces_total: s.subspaces_total,
                texels_synthesized: s.texels_synthesized,
                synthesis_seconds: s.synthesis_seconds,
            },
            RenderStats::Lpca(s) => MaterialReport::Lpca {
                method: s.method.name(),
                clusters: s.clusters,
                model_width: s.size.0,
                model_height: s.size.1,
            },
        };
        return emit_json(&RenderReport {
            out: &args.out,
            adapter: &out.adapter,
            mesh: args.mesh.to_string(),
            width,
            height,
            render_seconds: out.render_seconds,
            material,
        });
    }
    match &out.stats {
        RenderStats::Mrf(s) => emit(format!(
            "wrote {} ({}x{}, {} on {}; {} of {} subspace images synthesized at {}^2{} in {:.3} s, sampled at {}^2, rendered in {:.3} s)",
            args.out.display(),
            width,
            height,
            mapping,
            out.adapter,
            s.subspaces_synthesized,
            s.subspaces_total,
            s.tile,
            match s.plan.finishes.len() {
                0 => String::new(),
                n => format!(" and {n} measured pair(s) finished with their own parts"),
            },
            s.synthesis_seconds,
            s.plan.texture_size,
            out.render_seconds
        )),
        RenderStats::Lpca(s) => emit(format!(
            "wrote {} ({}x{}, {} model decoded per fragment on {}: {} cluster(s), a {}x{} tile; rendered in {:.3} s)",
            args.out.display(),
            width,
            height,
            s.method.name(),
            out.adapter,
            s.clusters,
            s.size.0,
            s.size.1,
            out.render_seconds
        )),
    }
}

/// `render --json`: the frame, then what its material needed.
#[derive(serde::Serialize)]
struct RenderReport<'a> {
    out: &'a Path,
    adapter: &'a str,
    mesh: String,
    width: u32,
    height: u32,
    render_seconds: f64,
    #[serde(flatten)]
    material: MaterialReport<'a>,
}

/// The material's part of [`RenderReport`], tagged `"material": "mrf" | "lpca"`.
#[derive(serde::Serialize)]
#[serde(tag = "material", rename_all = "lowercase")]
enum MaterialReport<'a> {
    Mrf {
        mapping: &'static str,
        texture_size: usize,
        tile: usize,
        clusters: &'a [usize],
        /// The measured (view, light) pairs finished with their own parts.
        finished_pairs: &'a [(usize, usize)],
        subspaces_synthesized: usize,
        subspaces_total: usize,
        texels_synthesized: u64,
        synthesis_seconds: f64,
    },
    Lpca {
        method: &'static str,
        clusters: usize,
        model_width: usize,
        model_height: usize,
    },
}

/// The hint of a refused `render` or `view`: the largest `--tile` (32 to 8192 texels) whose
/// peak `need` is within `budget`, or that nothing fits.
pub(super) fn tile_that_fits(need: impl Fn(usize) -> u64, budget: u64) -> String {
    let fits = (5..=13)
        .map(|p| 1usize << p)
        .rev()
        .find(|&s| need(s) <= budget);
    fits.map_or("nothing fits".into(), |s| format!("--tile {s} fits"))
}
