//! `btfmrf synthesize`: images of any size from a `.btfm` model, or the measured tile rebuilt
//! from a `.lpca` model.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use btfmrf::btf::{Direction, DirectionSet, io};
use btfmrf::lpca;
use btfmrf::memory;
use btfmrf::source::{AnyModel, LpcaImages, ModelImages};
use btfmrf::synthesis::SynthesisOptions;

use super::{Bar, Global, emit, emit_json};

/// What `synthesize --json` prints.
#[derive(serde::Serialize)]
struct SynthesizeReport<'a> {
    out: &'a std::path::Path,
    images: usize,
    /// Subspace images synthesized for the request (MRF models only).
    #[serde(skip_serializing_if = "Option::is_none")]
    subspaces_synthesized: Option<usize>,
    /// Subspace images of the model (MRF models only).
    #[serde(skip_serializing_if = "Option::is_none")]
    subspaces_total: Option<usize>,
    synthesis_seconds: f64,
}

/// Synthesize from a model: any size, any view and light, seed-deterministic. Only the
/// subspace images that the requested (view, light) pairs need are synthesized.
///
/// With one --view and one --light and an --out ending in .png or .exr, writes that one image
/// (a direction may be omitted where the model measured only one, as for a photograph);
/// otherwise a zip (--out X.zip) or folder of every requested view x light (the model's
/// measured directions when none are given): with UBO2003 names when every direction is in
/// whole degrees (the names hold whole degrees only), else, for a single-view model such as
/// one of an RTI set, an RTI capture (images 000.png, ... and dirs.lp with the exact light
/// vectors). Directions that were not measured are interpolated from the nearest measured
/// pairs. A model with a range map relights the image by it (bump mapping, with cast shadows
/// where analysis chose them) and shows an oblique view its parallax and masking: the relief
/// hides what lies behind its bumps (a 1024x1024 image at 60 degrees: 1.40 s against 1.13 s
/// frontal, criterion medians on 2 cores).
///
/// Examples:
///   btfmrf synthesize stones.btfm --size 1024 --view 0,0 --light 45,90 --out lit.png
///   btfmrf synthesize stones.btfm --size 256 --out enlarged.zip
///   btfmrf synthesize gravel.btfm --size 2048 --out big.png    (a photograph's model)
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The model file (.btfm, or .lpca: recognised by its first bytes).
    model: PathBuf,
    /// Output size: N (square) or WxH, pixels. Required for .btfm; a .lpca model rebuilds
    /// its measured tile only, so for it the size may be omitted or must match.
    #[arg(long, value_parser = parse_size)]
    size: Option<(usize, usize)>,
    /// A view direction "theta,phi" in degrees (repeatable).
    #[arg(long, value_parser = parse_direction)]
    view: Vec<Direction>,
    /// A light direction "theta,phi" in degrees (repeatable).
    #[arg(long, value_parser = parse_direction)]
    light: Vec<Direction>,
    /// Seed of the driving noise: same seed, same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Make the images tile seamlessly (size must be divisible by 2^(levels-1)). Costs about
    /// as much as plain synthesis: 1.0x the CPU time for a 2D CAR model at 1024x1024 (median
    /// of 3, docs/BENCHMARKS.md).
    #[arg(long)]
    tileable: bool,
    /// Output: X.png or X.exr (one image), X.zip or a new folder (a BTF).
    #[arg(long)]
    out: PathBuf,
    /// Image format of the members of a zip or folder output.
    #[arg(long, value_enum, default_value_t = super::FormatArg::Png)]
    format: super::FormatArg,
    /// Print one JSON object (synthesis_seconds, images, subspaces_synthesized).
    #[arg(long)]
    json: bool,
}

/// Parses "N" or "WxH" into (rows, cols).
pub(super) fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let parse = |t: &str| {
        t.trim()
            .parse::<usize>()
            .map_err(|_| format!("'{s}' is not N or WxH"))
    };
    match s.split_once(['x', 'X']) {
        Some((w, h)) => Ok((parse(h)?, parse(w)?)),
        None => parse(s).map(|n| (n, n)),
    }
}

/// Parses "theta,phi" in degrees.
pub(super) fn parse_direction(s: &str) -> Result<Direction, String> {
    let (t, p) = s
        .split_once(',')
        .ok_or_else(|| format!("'{s}' is not theta,phi"))?;
    let theta: f64 = t
        .trim()
        .parse()
        .map_err(|_| format!("'{t}' is not a number"))?;
    let phi: f64 = p
        .trim()
        .parse()
        .map_err(|_| format!("'{p}' is not a number"))?;
    if !(0.0..=90.0).contains(&theta) || !phi.is_finite() {
        return Err(format!("theta {theta} must be within 0..=90 degrees"));
    }
    Ok(Direction::new(theta, phi))
}

/// Farther than this from every measured direction, a requested direction is extrapolated
/// (degrees; the Bonn sampling's step in elevation).
const EXTRAPOLATION_DEG: f64 = 15.0;

/// A warning when `requested` is more than [`EXTRAPOLATION_DEG`] from every direction of
/// `measured`: the model has no data there and shows the nearest measured appearance (e.g. any
/// oblique view of a single-view RTI model).
pub(super) fn extrapolation_warning(
    what: &str,
    requested: &Direction,
    measured: &DirectionSet,
) -> Option<String> {
    let (nearest, angle) = measured
        .iter()
        .map(|m| (m, requested.angle_to(m)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (angle > EXTRAPOLATION_DEG).then(|| {
        format!(
            "{what} {},{} is {angle:.0} deg from the nearest measured {what} ({:.0},{:.0}); the \
             model has no data there and shows the appearance of the measured {what}s nearby",
            requested.theta_deg, requested.phi_deg, nearest.theta_deg, nearest.phi_deg
        )
    })
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let model = match AnyModel::open(&args.model)? {
        AnyModel::Mrf(model) => *model,
        AnyModel::Lpca(model) => return run_lpca(*model, args, global),
    };
    let Some((rows, cols)) = args.size else {
        bail!(
            "--size is required for a .btfm model ({})",
            args.model.display()
        );
    };
    let options = SynthesisOptions {
        rows,
        cols,
        seed: args.seed,
        tileable: args.tileable,
    };
    for (what, requested, measured) in [
        ("view", &args.view, model.views()),
        ("light", &args.light, model.lights()),
    ] {
        for d in requested {
            if let Some(w) = extrapolation_warning(what, d, measured) {
                eprintln!("warning: {w}");
            }
        }
    }
    let start = Instant::now();
    if let Some((view, light)) = single_pair(&args, model.views(), model.lights())? {
        let subspaces = model.subspace_weights(&view, &light)?.len();
        global.check_synthesis("--size", (rows, cols), subspaces, memory::synthesis_bytes)?;
        let image = model.synthesize_image(&view, &light, &options)?;
        let seconds = start.elapsed().as_secs_f64();
        io::write_image(&args.out, &image)
            .with_context(|| format!("writing {}", args.out.display()))?;
        report(
            args.json,
            &args.out,
            1,
            subspaces,
            model.subspaces().len(),
            seconds,
        )?;
        return Ok(());
    }
    let views = requested(&args.view, model.views())?;
    let lights = requested(&args.light, model.lights())?;
    let total = model.subspaces().len();
    // The subspace images these pairs draw on: exactly what the cache will synthesize.
    let mut needed = std::collections::BTreeSet::new();
    for v in &views {
        for l in &lights {
            needed.extend(model.subspace_weights(v, l)?.into_keys());
        }
    }
    let threads = memory::worker_threads();
    let bytes = |rows, cols, subspaces| memory::btf_synthesis_bytes(rows, cols, subspaces, threads);
    global.check_synthesis("--size", (rows, cols), needed.len(), bytes)?;
    let btf = ModelImages::into_btf(model, views, lights, &options)?;
    io::write_btf(
        &btf,
        &args.out,
        args.format.with_quality(90),
        &Bar::new(global),
    )?;
    let seconds = start.elapsed().as_secs_f64();
    report(
        args.json,
        &args.out,
        btf.image_count(),
        needed.len(),
        total,
        seconds,
    )
}

fn report(
    json: bool,
    out: &std::path::Path,
    images: usize,
    used: usize,
    total: usize,
    seconds: f64,
) -> anyhow::Result<()> {
    if json {
        emit_json(&SynthesizeReport {
            out,
            images,
            subspaces_synthesized: Some(used),
            subspaces_total: Some(total),
            synthesis_seconds: seconds,
        })
    } else {
        emit(format!(
            "wrote {} ({images} image(s); {used} of {total} subspace images synthesized) in {seconds:.3} s",
            out.display()
        ))
    }
}

/// `synthesize` for a `.lpca` model: the measured tile rebuilt under the requested (or all
/// measured) directions.
fn run_lpca(model: lpca::LpcaModel, args: Args, global: &Global) -> anyhow::Result<()> {
    let (h, w) = (model.height(), model.width());
    if let Some((rows, cols)) = args.size
        && (rows, cols) != (h, w)
    {
        bail!(
            "{}: --size {cols}x{rows} differs from the model's {w}x{h}; an LPCA model rebuilds \
             its measured tile only (omit --size)",
            args.model.display()
        );
    }
    if args.tileable {
        bail!(
            "{}: --tileable does not apply to an LPCA model (it rebuilds the measured tile)",
            args.model.display()
        );
    }
    let start = Instant::now();
    let images = if let Some((view, light)) = single_pair(&args, model.views(), model.lights())? {
        let image = model.reconstruct_direction(&view, &light)?;
        io::write_image(&args.out, &image)
            .with_context(|| format!("writing {}", args.out.display()))?;
        1
    } else {
        let btf = if args.view.is_empty() && args.light.is_empty() {
            model.into_btf()?
        } else {
            let views = requested(&args.view, model.views())?;
            let lights = requested(&args.light, model.lights())?;
            LpcaImages::into_btf(model, views, lights)?
        };
        io::write_btf(
            &btf,
            &args.out,
            args.format.with_quality(90),
            &Bar::new(global),
        )?;
        btf.image_count()
    };
    let seconds = start.elapsed().as_secs_f64();
    if args.json {
        emit_json(&SynthesizeReport {
            out: &args.out,
            images,
            subspaces_synthesized: None,
            subspaces_total: None,
            synthesis_seconds: seconds,
        })
    } else {
        emit(format!(
            "wrote {} ({images} image(s) rebuilt from the LPCA model) in {seconds:.3} s",
            args.out.display()
        ))
    }
}

/// Image extensions this tool does not write (refused for `--out`, not taken as folder names).
const OTHER_IMAGE_EXTENSIONS: [&str; 9] = [
    "tif", "tiff", "bmp", "gif", "webp", "hdr", "tga", "heic", "avif",
];

/// The one (view, light) pair to write when `--out` names a single image (.png, .exr, .jpg,
/// .jpeg), given or, where the model measured only one, the measured one; `None` when `--out`
/// names a BTF (zip or folder).
fn single_pair(
    args: &Args,
    views: &DirectionSet,
    lights: &DirectionSet,
) -> anyhow::Result<Option<(Direction, Direction)>> {
    let out_name = args.out.to_string_lossy().to_ascii_lowercase();
    if io::ImageFormat::from_name(&out_name).is_none() {
        // An image-like name we cannot write would otherwise become a folder of that name.
        let ext = out_name.rsplit_once('.').map_or("", |(_, e)| e);
        if OTHER_IMAGE_EXTENSIONS.contains(&ext) {
            bail!(
                "--out {}: .{ext} images are not supported; use .png, .jpg, .jpeg or .exr",
                args.out.display()
            );
        }
        return Ok(None);
    }
    // A direction may be omitted where the model measured only one (a photograph's model).
    let one = |given: &[Direction], measured: &DirectionSet| match given {
        [d] => Some(*d),
        [] if measured.len() == 1 => measured.iter().next().copied(),
        _ => None,
    };
    match (one(&args.view, views), one(&args.light, lights)) {
        (Some(view), Some(light)) => Ok(Some((view, light))),
        _ => bail!(
            "one image (--out {}) needs exactly one --view and one --light (they may be \
             omitted only where the model measured a single view or light)",
            args.out.display()
        ),
    }
}

/// The directions asked for with `--view` / `--light`, or all the model's measured ones.
fn requested(given: &[Direction], measured: &DirectionSet) -> anyhow::Result<DirectionSet> {
    Ok(if given.is_empty() {
        measured.clone()
    } else {
        DirectionSet::new(given.to_vec())?
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_directions_parse() {
        assert_eq!(parse_size("512"), Ok((512, 512)));
        assert_eq!(parse_size("640x480"), Ok((480, 640)));
        assert!(parse_size("x").is_err());
        assert_eq!(
            parse_direction("45, 90").unwrap(),
            Direction::new(45.0, 90.0)
        );
        assert!(parse_direction("95,0").is_err());
        assert!(parse_direction("45").is_err());
    }
}
