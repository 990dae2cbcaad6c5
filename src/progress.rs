//! Progress reporting from long library work, without tying the library to a terminal.
//!
//! The library calls a [`Progress`]; the CLI implements it with an indicatif bar on stderr.
//! Implementations must be `Sync` because work is spread over threads with rayon.

/// Receives progress of one long task (a few calls per second at most matter to a user).
pub trait Progress: Sync {
    /// A task named `task` starts with `total` units of work.
    fn start(&self, _task: &str, _total: u64) {}
    /// `n` more units of the current task are done.
    fn advance(&self, _n: u64) {}
    /// The current task is over (successfully or not).
    fn finish(&self) {}
}

/// Reports nothing: the default for library callers that do not care.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {}
