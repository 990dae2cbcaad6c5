//! The `btfmrf` command line: a thin shell over the `btfmrf` library.

mod cli;

use std::process::ExitCode;

/// mimalloc keeps freed pages for reuse. Synthesis allocates and frees many large planes, and
/// the system allocator handed them back to the kernel each time: page faults were a quarter of
/// a 1024 x 1024 synthesis (docs/BENCHMARKS.md). [`btfmrf::allocator::keep_freed_memory`]
/// keeps them for good.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    btfmrf::allocator::keep_freed_memory();
    on_interrupt_remove_temporaries();
    match cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", cli::error_line(&e));
            cli::exit_code(&e)
        }
    }
}

/// SIGINT, SIGTERM or SIGHUP: delete the half-written outputs (`.btfmrf-partial-*`), say so on
/// one error line, and exit with status 130 (the shell's code for an interrupted command).
fn on_interrupt_remove_temporaries() {
    // Without a handler the default action (exit, leaving temporaries) still applies.
    let _ = ctrlc::set_handler(|| {
        let removed = btfmrf::btf::io::partial::remove_registered();
        eprintln!("error: interrupted; removed {removed} partial output(s)");
        std::process::exit(130);
    });
}
