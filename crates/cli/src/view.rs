//! `btfmrf view`: the interactive viewer window.

use std::path::PathBuf;

use btfmrf::btf::Direction;
use btfmrf::memory;
use btfmrf::source::AnyModel;
use btfmrf_render::viewer::{ViewerOptions, run_viewer};
use btfmrf_render::{Mapping, MeshKind};

use super::render::tile_that_fits;
use super::synthesize::{parse_direction, parse_size};
use super::{Bar, Global};

/// Open a window showing a model on a mesh, rendered live.
///
/// Left drag orbits the camera, the wheel zooms; the arrow keys or a right drag move the
/// light; B and D switch to bump and displacement mapping; M shows the next mesh; Esc or Q
/// quits. The frame time is in the window title. Needs a display (X11 or Wayland; Xvfb works).
///
/// Examples:
///   btfmrf view sponge.btfm
///   btfmrf view sponge.btfm --mesh cloth --mapping displacement
///   btfmrf view sponge.btfm --frames 3 --screenshot shot.png
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The model file (.btfm).
    model: PathBuf,
    /// Window size: N (square) or WxH, pixels.
    #[arg(long, value_parser = parse_size, default_value = "800")]
    size: (usize, usize),
    /// The first mesh (then M cycles through sphere, cloth, torus, plane).
    #[arg(long, default_value = "sphere")]
    mesh: MeshKind,
    /// bump, displacement or plain (switch with B / D).
    #[arg(long, default_value = "bump")]
    mapping: Mapping,
    /// Initial camera direction "theta,phi", degrees.
    #[arg(long, value_parser = parse_direction, default_value = "30,270")]
    view: Direction,
    /// Initial light direction "theta,phi", degrees.
    #[arg(long, value_parser = parse_direction, default_value = "45,300")]
    light: Direction,
    /// Measured texels per texture repetition (a power of two; the same range as `render
    /// --tile`): the material's scale on the mesh. Every cluster is synthesized at this side
    /// when the window opens, and every measured pair's finish where the model keeps light
    /// tables or light weights (see `render --help`), so the start-up cost grows with its
    /// square times the clusters and pairs (the ready stones at 256: 20 clusters in 0.5 s,
    /// 81 finishes in 2.0 s on two cores).
    #[arg(
        long,
        visible_alias = "texture-size",
        value_name = "TEXELS",
        default_value_t = 256
    )]
    tile: usize,
    /// Seed of the synthesis.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Render this many frames, then exit.
    #[arg(long)]
    frames: Option<u64>,
    /// Save the window's contents to this PNG after the last frame (needs --frames).
    #[arg(long, requires = "frames")]
    screenshot: Option<PathBuf>,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let (rows, cols) = args.size;
    btfmrf_render::frame::check_size(u32::try_from(cols)?, u32::try_from(rows)?)?;
    let model = match AnyModel::open(&args.model)? {
        AnyModel::Mrf(model) => *model,
        AnyModel::Lpca(_) => anyhow::bail!(
            "{}: an LPCA model; the viewer shows .btfm models (render this one with btfmrf render)",
            args.model.display()
        ),
    };
    // Every cluster and every pair's finish at the tile's side, as `render` counts them.
    btfmrf_render::check_tile(&model, args.tile)?;
    let textures = model.subspaces().len() + model.pairs_with_own_parts().len();
    let threads = memory::worker_threads();
    let need = |tile| memory::render_bytes(rows * cols, tile, textures, threads);
    global.check_memory(
        format!("view with a {}^2 tile", args.tile),
        need(args.tile),
        |budget| tile_that_fits(need, budget),
    )?;
    let mut meshes = vec![args.mesh.clone()];
    for kind in [
        MeshKind::Sphere,
        MeshKind::Cloth,
        MeshKind::Torus,
        MeshKind::Plane,
    ] {
        if !meshes.contains(&kind) {
            meshes.push(kind);
        }
    }
    run_viewer(
        &model,
        ViewerOptions {
            width: cols as u32,
            height: rows as u32,
            tile: args.tile,
            seed: args.seed,
            meshes,
            mapping: args.mapping,
            view: args.view,
            light: args.light,
            frames: args.frames,
            screenshot: args.screenshot,
        },
        &Bar::new(global),
    )?;
    Ok(())
}
