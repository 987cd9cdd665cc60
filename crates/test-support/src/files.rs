//! Files of the tests: scratch directories, named pipes, a configuration
//! that records.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A fresh scratch directory `tmp_dir/group/name` (`tmp_dir`: the test's
/// `env!("CARGO_TARGET_TMPDIR")`, which only tests and benchmarks have).
pub fn scratch_in(tmp_dir: &str, group: &str, name: &str) -> PathBuf {
    let dir = PathBuf::from(tmp_dir).join(group).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A named pipe (FIFO) at `path` (`mkfifo`), a stale file there removed first.
pub fn mkfifo(path: &Path) {
    let _ = std::fs::remove_file(path);
    let made = Command::new("mkfifo").arg(path).status().unwrap().success();
    assert!(made, "mkfifo {}", path.display());
}

/// The built-in configuration with recording on into `dir/rec`, written to
/// `dir/sim.toml`: that file and the recordings' directory.
pub fn recording_config(dir: &Path) -> (PathBuf, PathBuf) {
    let rec_dir = dir.join("rec");
    let config = dir.join("sim.toml");
    let toml = sar_config::DEFAULT_TOML
        .replace("[record]\nenabled = false", "[record]\nenabled = true")
        .replace(
            "directory = \"recordings\"",
            &format!("directory = {:?}", rec_dir.display().to_string()),
        );
    assert_ne!(toml, sar_config::DEFAULT_TOML);
    std::fs::write(&config, toml).unwrap();
    (config, rec_dir)
}

/// The recording files of `dir`, sorted.
pub fn recordings(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
}
