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
    match cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
