//! Helpers of the CLI's integration tests: the library tests' helpers (tests/common at the
//! repository root) and running the real `btfmrf` binary.
#![allow(dead_code)] // each test binary uses a different subset

use std::process::{Command, Output};

#[path = "../../../../tests/common/mod.rs"]
mod shared;
pub use shared::*;

/// The real `btfmrf` binary built for these tests.
pub fn btfmrf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_btfmrf"))
        .args(args)
        .output()
        .expect("the btfmrf binary runs")
}

/// Stdout of a run that must succeed.
pub fn ok(args: &[&str]) -> String {
    let out = btfmrf(args);
    assert!(
        out.status.success(),
        "btfmrf {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

/// Stderr of a run that must fail cleanly: non-zero exit, one `error:` line, no panic.
pub fn fails(args: &[&str]) -> String {
    let out = btfmrf(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "btfmrf {args:?} should fail");
    assert!(
        !stderr.contains("panicked"),
        "btfmrf {args:?} panicked:\n{stderr}"
    );
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "expected one error line, got:\n{stderr}");
    errors[0].to_string()
}

/// A test that needs something this machine lacks (a GPU adapter, a virtual X server) skips
/// with a message on a developer's machine, but fails in CI (`CI` set): a green CI run must
/// mean the renderer and the viewer were tested.
pub fn skip_unless_ci(missing: &str) {
    if std::env::var_os("CI").is_some() {
        panic!("{missing}, and CI is set: the test cannot run (run scripts/setup)");
    }
    eprintln!("skipping: {missing} (scripts/setup installs it)");
}
