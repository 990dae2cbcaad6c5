//! `btfmrf view`: the interactive viewer window.

use std::path::PathBuf;

use btfmrf::btf::Direction;
use btfmrf::model::format;
use btfmrf_render::viewer::{ViewerOptions, run_viewer};
use btfmrf_render::{Mapping, MeshKind};

use super::Global;
use super::synthesize::{parse_direction, parse_size};

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
    /// bump or displacement (switch with B / D; plain and lpca are for `render` only).
    #[arg(long, default_value = "bump")]
    mapping: Mapping,
    /// Initial camera direction "theta,phi", degrees.
    #[arg(long, value_parser = parse_direction, default_value = "30,270")]
    view: Direction,
    /// Initial light direction "theta,phi", degrees.
    #[arg(long, value_parser = parse_direction, default_value = "45,300")]
    light: Direction,
    /// Measured texels per texture repetition (a power of two), like `render --tile`: the
    /// material's scale on the mesh. Every cluster is synthesized at this side when the
    /// window opens, so the start-up cost grows with its square times the clusters.
    #[arg(long, default_value_t = 256)]
    texture_size: usize,
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

pub fn run(args: Args, _global: &Global) -> anyhow::Result<()> {
    let (rows, cols) = args.size;
    btfmrf_render::headless::check_size(u32::try_from(cols)?, u32::try_from(rows)?)?;
    let n = args.texture_size;
    if !n.is_power_of_two() || !(32..=4096).contains(&n) {
        anyhow::bail!("invalid --texture-size {n}: a power of two within 32..=4096");
    }
    let model = format::read(&args.model)?;
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
            texture_size: n.max(model.min_synthesis_side()),
            seed: args.seed,
            meshes,
            mapping: args.mapping,
            view: args.view,
            light: args.light,
            frames: args.frames,
            screenshot: args.screenshot,
        },
    )?;
    Ok(())
}
