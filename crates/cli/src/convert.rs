//! `btfmrf convert`: between zip, folder and EXR layouts.

use std::path::PathBuf;

use btfmrf::btf::{Btf, io};

use super::{Bar, Global, OutputFormat};

/// Convert a BTF between layouts: zip <-> folder, 8-bit JPEG/PNG <-> linear EXR.
///
/// A BTF whose directions are all in whole degrees is written with UBO2003 names
/// (`00017 tl015 pl060 tv000 pv000.jpg`, which hold whole degrees only); an RTI set (one view,
/// lights in any direction) is written as an RTI capture: images 000.jpg, 001.jpg, ... and
/// dirs.lp with the exact light vectors. Both read back with `btfmrf info`.
///
/// Examples:
///   btfmrf convert wool.zip --out wool-exr --format exr     (a folder of EXR images)
///   btfmrf convert wool-exr --out wool-png.zip --format png
///   btfmrf convert rti/clay-leaf --out leaf.zip --format png  (an RTI zip with dirs.lp)
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The BTF to read: FILE.zip (UBO2003, or RTI with a .lp member), a folder, or an RTI .lp
    /// file.
    input: PathBuf,
    /// Output: FILE.zip, or a folder that does not exist yet.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    format: OutputFormat,
}

pub fn run(args: Args, global: &Global) -> anyhow::Result<()> {
    let btf = Btf::open(&args.input)?;
    for w in btf.warnings() {
        eprintln!("warning: {w}");
    }
    let bar = Bar::new(global);
    io::write_btf(&btf, &args.out, args.format.image_format(), &bar)?;
    if !global.quiet {
        eprintln!(
            "wrote {} ({} images of {}x{})",
            args.out.display(),
            btf.image_count(),
            btf.width(),
            btf.height()
        );
    }
    Ok(())
}
