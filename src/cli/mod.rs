//! Argument parsing (clap derive), one file per subcommand, and the terminal progress bar.

mod analyze;
mod bench;
mod convert;
mod demo;
mod features;
mod generate;
mod info;
mod lpca;
mod recognize;
mod render;
mod synthesize;
mod view;

use std::io::IsTerminal;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use btfmrf::btf::ImageFormat;
use btfmrf::progress::Progress;

/// btfmrf: measured BTFs to Markov-random-field models of a few tens of kilobytes, and back.
///
/// A BTF (bidirectional texture function) is a material photographed under many view and
/// light directions. This tool reads them (Bonn UBO2003 zips or folders, RTI folders with a
/// .lp file), generates procedural reference materials, and converts between layouts.
///
/// Examples:
///   btfmrf generate sponge --size 128 --out sponge.zip
///   btfmrf info sponge.zip
///   btfmrf convert sponge.zip --out sponge-exr --format exr
///   btfmrf analyze sponge.zip --model 2dcar --out sponge.btfm
///   btfmrf synthesize sponge.btfm --size 1024 --view 0,0 --light 45,90 --out big.png
///   btfmrf features brick.png --json
///   btfmrf recognize --out recognition.md
///   btfmrf render sponge.btfm --out sphere.png --mesh sphere --mapping bump
///   btfmrf lpca sponge.zip --clusters 32 --components 8 --out sponge.lpca
#[derive(Debug, Parser)]
#[command(name = "btfmrf", version, verbatim_doc_comment)]
pub struct Cli {
    #[command(flatten)]
    global: Global,
    #[command(subcommand)]
    command: Command,
}

/// Options every subcommand understands.
#[derive(Debug, clap::Args)]
pub struct Global {
    /// No progress bars (they are drawn on stderr only when it is a terminal anyway).
    #[arg(long, short, global = true)]
    quiet: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    Generate(generate::Args),
    Info(info::Args),
    Convert(convert::Args),
    Analyze(analyze::Args),
    Synthesize(synthesize::Args),
    Lpca(lpca::Args),
    Bench(bench::Args),
    Render(render::Args),
    View(view::Args),
    Features(features::Args),
    Recognize(recognize::Args),
    Demo(demo::Args),
}

/// Parses the command line and runs the subcommand.
pub fn run() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Generate(args) => generate::run(args, &cli.global),
        Command::Info(args) => info::run(args, &cli.global),
        Command::Convert(args) => convert::run(args, &cli.global),
        Command::Analyze(args) => analyze::run(args, &cli.global),
        Command::Synthesize(args) => synthesize::run(args, &cli.global),
        Command::Lpca(args) => lpca::run(args, &cli.global),
        Command::Bench(args) => bench::run(args, &cli.global),
        Command::Render(args) => render::run(args, &cli.global),
        Command::View(args) => view::run(args, &cli.global),
        Command::Features(args) => features::run(args, &cli.global),
        Command::Recognize(args) => recognize::run(args, &cli.global),
        Command::Demo(args) => demo::run(args, &cli.global),
    }
}

/// Image encodings accepted by `--format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// 8-bit sRGB JPEG, like the Bonn database (see --quality).
    Jpg,
    /// 8-bit sRGB PNG, lossless at 8 bits.
    Png,
    /// 32-bit float linear OpenEXR, lossless.
    Exr,
}

impl FormatArg {
    fn with_quality(self, quality: u8) -> ImageFormat {
        match self {
            FormatArg::Jpg => ImageFormat::Jpeg { quality },
            FormatArg::Png => ImageFormat::Png,
            FormatArg::Exr => ImageFormat::Exr,
        }
    }
}

/// Image format options shared by the commands that write BTFs.
#[derive(Debug, clap::Args)]
pub struct OutputFormat {
    /// Image format of the written BTF's members.
    #[arg(long, value_enum, default_value_t = FormatArg::Jpg)]
    format: FormatArg,
    /// JPEG quality, 1-100 (ignored for PNG and EXR).
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    quality: u8,
}

impl OutputFormat {
    fn image_format(&self) -> ImageFormat {
        self.format.with_quality(self.quality)
    }
}

/// An indicatif bar on stderr, hidden when stderr is not a terminal or with `--quiet`.
pub struct Bar {
    bar: ProgressBar,
}

impl Bar {
    pub fn new(global: &Global) -> Self {
        let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
        if global.quiet || !std::io::stderr().is_terminal() {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        }
        bar.set_style(
            ProgressStyle::with_template("{msg:>16} [{bar:40}] {pos}/{len} ({per_sec}, eta {eta})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        Self { bar }
    }
}

impl Progress for Bar {
    fn start(&self, task: &str, total: u64) {
        self.bar.reset();
        self.bar.set_length(total);
        self.bar.set_message(task.to_string());
    }

    fn advance(&self, n: u64) {
        self.bar.inc(n);
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// Prints one line on stdout; a closed pipe (`btfmrf info x.zip | head -1`) is not an error.
pub fn emit(line: impl std::fmt::Display) -> anyhow::Result<()> {
    use std::io::Write;
    match writeln!(std::io::stdout().lock(), "{line}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Bytes in a human-friendly unit.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}
