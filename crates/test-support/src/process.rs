//! Running a program of the tests (`sard`, `sarctl`, a reader, `mount`) and
//! insisting that it succeeded: one place that says, on failure, what ran,
//! its exit status and both of its outputs.

use std::borrow::BorrowMut;
use std::process::{Command, Output};

/// Runs `cmd` to its end and returns its output; panics, naming `what`, the
/// command, its status, stdout and stderr, unless it exited 0.
#[allow(clippy::panic)] // a test helper: failing is its job
pub fn run_ok(mut cmd: impl BorrowMut<Command>, what: &str) -> Output {
    let cmd = cmd.borrow_mut();
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{what}: {cmd:?} exited {}\nstdout: {}\nstderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
