//! `btfmrf convert`: between zip, folder and EXR layouts.

use std::path::PathBuf;

use btfmrf::btf::{Btf, io};

use super::{Bar, Global, OutputFormat};

/// Convert a BTF between layouts: UBO2003 zip <-> folder, 8-bit JPEG/PNG <-> linear EXR.
/// Any readable BTF (including an RTI folder with whole-degree light angles) can be written.
///
/// Examples:
///   btfmrf convert wool.zip --out wool-exr --format exr     (a folder of EXR images)
///   btfmrf convert wool-exr --out wool-png.zip --format png
#[derive(Debug, clap::Args)]
#[command(verbatim_doc_comment)]
pub struct Args {
    /// The BTF to read: FILE.zip, a folder, or an RTI .lp file.
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
    io::write_ubo2003(&btf, &args.out, args.format.image_format(), &bar)?;
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
