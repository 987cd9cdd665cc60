//! The strict readers of the tests (shared by sar-daemon's and sar-tests'
//! integration tests): on first use in a test process, runs
//! `scripts/setup-test-readers.sh` (idempotent, under a lock file) to
//! install them under `<target>/test-readers/`, then runs the checks with
//! them: Python `rosbags` (type store from the embedded schemas only) and the
//! Foxglove npm parsers. A missing python3/pip or node/npm fails the test
//! with what to install; `SAR_SKIP_PYTHON=1` / `SAR_SKIP_NODE=1` at build
//! time mark the tests that need them as ignored (build.rs).
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The repository's root.
pub fn repo_root() -> PathBuf {
    let mut dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    while !dir.join("scripts/setup-test-readers.sh").exists() {
        assert!(
            dir.pop(),
            "no scripts/setup-test-readers.sh above the crate"
        );
    }
    dir
}

/// `<target>/`: the parent of the integration tests' tmp dir.
fn target_dir() -> PathBuf {
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    tmp.parent().map(Path::to_path_buf).unwrap_or(tmp)
}

/// Which readers a test needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// rosbags, mcap, mcap-ros2-support, mcap-protobuf-support.
    Python,
    /// @foxglove/rosmsg, @foxglove/rosmsg2-serialization, @mcap/core, ...
    Node,
}

/// Installs `part` (once per process) and returns `<target>/test-readers`.
pub fn ensure(part: Part) -> PathBuf {
    static PY: OnceLock<PathBuf> = OnceLock::new();
    static NODE: OnceLock<PathBuf> = OnceLock::new();
    let cell = match part {
        Part::Python => &PY,
        Part::Node => &NODE,
    };
    cell.get_or_init(|| {
        let script = repo_root().join("scripts/setup-test-readers.sh");
        let mut cmd = Command::new("bash");
        cmd.arg(&script).arg(target_dir());
        // Only the part asked for: a Python test does not need node.
        match part {
            Part::Python => cmd.env("SAR_SKIP_NODE", "1").env_remove("SAR_SKIP_PYTHON"),
            Part::Node => cmd.env("SAR_SKIP_PYTHON", "1").env_remove("SAR_SKIP_NODE"),
        };
        let out = cmd
            .output()
            .unwrap_or_else(|e| panic!("bash {script:?}: {e}"));
        assert!(
            out.status.success(),
            "{} failed ({}): {}\nInstall what it names, or build the tests with \
             SAR_SKIP_PYTHON=1 / SAR_SKIP_NODE=1 to mark these tests ignored.",
            script.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
    })
    .clone()
}

/// `python3` with the installed packages on its path.
pub fn python() -> Command {
    let dir = ensure(Part::Python);
    let mut cmd = Command::new("python3");
    cmd.env("PYTHONPATH", dir.join("py"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("PYTHONNOUSERSITE", "1");
    cmd
}

/// `node` with `SAR_READERS_NODE` naming the installed packages.
pub fn node() -> Command {
    let dir = ensure(Part::Node);
    let mut cmd = Command::new("node");
    cmd.env("SAR_READERS_NODE", dir.join("node"));
    cmd
}

fn run_json(mut cmd: Command, what: &str) -> serde_json::Value {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{what}: not JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// Python `rosbags` over `files`: `{"files": [{"path", "schemas", "channels",
/// "messages", "failures", "errors", "topics"}]}`.
pub fn rosbags(files: &[PathBuf]) -> serde_json::Value {
    let mut cmd = python();
    cmd.arg(repo_root().join("scripts/test-readers/check_rosbags.py"))
        .args(files);
    run_json(cmd, "check_rosbags.py")
}

/// [`rosbags`] with `--scene`: each file also with "scene" (decoded
/// `/sar/scene` messages with the arrow shown, and the state of the same log
/// time) and "jazzy" (the scene's nested types that differ from rosbags'
/// ROS 2 Jazzy definitions).
pub fn rosbags_scene(files: &[PathBuf]) -> serde_json::Value {
    let mut cmd = python();
    cmd.arg(repo_root().join("scripts/test-readers/check_rosbags.py"))
        .arg("--scene")
        .args(files);
    run_json(cmd, "check_rosbags.py --scene")
}

/// The Foxglove parsers over `files`, with the layout's message paths
/// looked up: as [`rosbags`], with "profile" and "layout".
pub fn foxglove(files: &[PathBuf]) -> serde_json::Value {
    let mut cmd = node();
    cmd.arg(repo_root().join("scripts/test-readers/check_foxglove.mjs"))
        .arg("--layout")
        .arg(repo_root().join("deploy/foxglove-layout.json"))
        .args(files);
    run_json(cmd, "check_foxglove.mjs")
}

/// Totals of a check's output: (files, schemas, messages, failures).
pub fn totals(v: &serde_json::Value) -> (usize, u64, u64, u64) {
    let files = v["files"].as_array().unwrap();
    let sum = |k: &str| files.iter().map(|f| f[k].as_u64().unwrap()).sum::<u64>();
    (
        files.len(),
        sum("schemas"),
        sum("messages"),
        sum("failures"),
    )
}

/// Asserts no file of a check's output had a failure, each had messages and
/// schemas; returns the output's files.
pub fn assert_clean(v: &serde_json::Value, reader: &str) -> Vec<serde_json::Value> {
    let files = v["files"].as_array().unwrap().clone();
    assert!(!files.is_empty(), "{reader}: no file checked");
    for f in &files {
        assert_eq!(
            f["failures"].as_u64(),
            Some(0),
            "{reader}: {}: {}",
            f["path"],
            f["errors"]
        );
        assert!(f["messages"].as_u64().unwrap() > 0, "{reader}: {f}");
        assert!(f["schemas"].as_u64().unwrap() > 0, "{reader}: {f}");
    }
    files
}
