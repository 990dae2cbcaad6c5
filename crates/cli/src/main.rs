//! The `btfmrf` command line: a thin shell over the `btfmrf` library and the
//! `btfmrf-render` renderer. Argument parsing (clap derive), one file per subcommand, and the
//! terminal progress bar.

mod allocator;

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
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use btfmrf::btf::ImageFormat;
use btfmrf::memory::{self, Budget, OverBudget};
use btfmrf::progress::Progress;

/// btfmrf: measured BTFs to Markov-random-field models of a few tens of kilobytes, and back.
///
/// A BTF (bidirectional texture function) is a material photographed under many view and
/// light directions. This tool reads them (Bonn UBO2003 zips or folders, RTI folders or zips
/// with a .lp file), generates procedural reference materials, and converts between layouts.
///
/// Examples:
///   btfmrf generate sponge --size 128 --out sponge.zip
///   btfmrf info sponge.zip
///   btfmrf convert sponge.zip --out sponge-exr --format exr
///   btfmrf analyze sponge.zip --model 2dcar --out sponge.btfm
///   btfmrf synthesize sponge.btfm --size 1024 --view 0,0 --light 45,90 --out big.png
///   btfmrf features brick.png --json
///   btfmrf recognize --data DIR --out recognition.md
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
    /// Memory analyze, lpca, synthesize, render, bench and demo may use, e.g. 2G or 512M:
    /// they estimate their peak before starting and refuse (exit status 2) above it.
    /// Default: half this machine's memory.
    #[arg(long, global = true, value_name = "SIZE", value_parser = memory::parse_bytes)]
    memory_limit: Option<u64>,
}

impl Global {
    /// Refuses `need` bytes over the memory budget; `hint` gets the budget and names an
    /// option value that fits.
    pub fn check_memory(
        &self,
        what: impl Into<String>,
        need: u64,
        hint: impl FnOnce(u64) -> String,
    ) -> Result<(), OverBudget> {
        Budget::new(self.memory_limit).check(what, need, hint)
    }

    /// Refuses a `rows` x `cols` synthesis drawing on `subspaces` subspace images over the
    /// budget (`bytes` is [`memory::synthesis_bytes`] or [`memory::btf_synthesis_bytes`] on this
    /// process's worker threads),
    /// naming the largest square `option` size that fits.
    pub fn check_synthesis(
        &self,
        option: &str,
        (rows, cols): (usize, usize),
        subspaces: usize,
        bytes: impl Fn(usize, usize, usize) -> u64,
    ) -> Result<(), OverBudget> {
        let need = bytes(rows, cols, subspaces);
        self.check_memory(format!("{option} {cols}x{rows}"), need, |budget| {
            let fit = memory::largest_fitting(rows.max(cols), budget, |s| bytes(s, s, subspaces));
            fit.map_or("nothing fits".into(), |s| format!("{option} {s} fits"))
        })
    }
}

/// The error's line for the terminal: its chain of causes joined by ": ", a cause that the
/// message before it already quotes left out (I/O errors carry their source in their text),
/// and control characters escaped so that a file or member name cannot forge a line.
pub fn error_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line.chars()
        .flat_map(|c| {
            let escaped: Vec<char> = if c.is_control() {
                c.escape_default().collect()
            } else {
                vec![c]
            };
            escaped
        })
        .collect()
}

/// Exit status 2 for a request refused by the memory budget, 1 for any other error.
pub fn exit_code(e: &anyhow::Error) -> std::process::ExitCode {
    if e.chain().any(|c| c.is::<OverBudget>()) {
        std::process::ExitCode::from(2)
    } else {
        std::process::ExitCode::FAILURE
    }
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

/// Prints a report as one line of JSON ([`emit`]).
pub fn emit_json(report: &impl serde::Serialize) -> anyhow::Result<()> {
    emit(serde_json::to_string(report)?)
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

/// mimalloc keeps freed pages for reuse. Synthesis allocates and frees many large planes, and
/// the system allocator handed them back to the kernel each time: page faults were a quarter of
/// a 1024 x 1024 synthesis (docs/BENCHMARKS.md). [`allocator::keep_freed_memory`]
/// keeps them for good.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    allocator::keep_freed_memory();
    let runtime = private_runtime_dir();
    on_interrupt_remove_temporaries(runtime.clone());
    let code = match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_line(&e));
            exit_code(&e)
        }
    };
    if let Some(dir) = runtime {
        let _ = std::fs::remove_dir_all(dir);
    }
    code
}

/// Without `XDG_RUNTIME_DIR` (a plain ssh or container shell), the Vulkan driver's Wayland
/// probe prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." on every
/// GPU start, which reads as a failure of a run that succeeded. When neither it nor a Wayland
/// display is set, point it at a fresh private directory (mode 0700), removed at exit; the
/// probe then finds no display and says nothing. `None` when the environment already has one.
fn private_runtime_dir() -> Option<std::path::PathBuf> {
    use std::os::unix::fs::DirBuilderExt;
    if std::env::var_os("XDG_RUNTIME_DIR").is_some()
        || std::env::var_os("WAYLAND_DISPLAY").is_some()
    {
        return None;
    }
    let dir = std::env::temp_dir().join(format!("btfmrf-runtime-{}", std::process::id()));
    std::fs::DirBuilder::new().mode(0o700).create(&dir).ok()?;
    // SAFETY: called first thing in `main`, before any other thread exists that could read
    // the environment concurrently.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    Some(dir)
}

/// SIGINT, SIGTERM or SIGHUP: delete the half-written outputs (`.btfmrf-partial-*`) and the
/// private runtime directory, say so on one error line, and exit with status 130 (the shell's
/// code for an interrupted command).
fn on_interrupt_remove_temporaries(runtime: Option<std::path::PathBuf>) {
    // Without a handler the default action (exit, leaving temporaries) still applies.
    let _ = ctrlc::set_handler(move || {
        if let Some(dir) = &runtime {
            let _ = std::fs::remove_dir_all(dir);
        }
        let removed = btfmrf::io::partial::remove_registered();
        eprintln!("error: interrupted; removed {removed} partial output(s)");
        std::process::exit(130);
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_lines_are_one_line_without_repeats() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        let e = anyhow::Error::new(btfmrf::btf::BtfError::Io {
            path: "a.zip".into(),
            source: io,
        });
        assert_eq!(error_line(&e), "a.zip: No such file");
        let e = anyhow::anyhow!("bad member 'x\n\u{1b}[31merror: forged'").context("reading");
        let line = error_line(&e);
        assert_eq!(line, "reading: bad member 'x\\n\\u{1b}[31merror: forged'");
        assert!(!line.contains('\n') && !line.contains('\u{1b}'));
    }

    #[test]
    fn the_allocator_purge_delay_option_is_found_and_set() {
        // The first call finds mimalloc's default at the index and sets it; after that the
        // option no longer holds the default.
        assert!(allocator::keep_freed_memory());
        assert!(!allocator::keep_freed_memory());
    }
}
