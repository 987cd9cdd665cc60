//! What the bridge's tests share: the repository, the target directory and
//! the Python readers (`scripts/setup-test-readers.sh`).
#![allow(dead_code, clippy::unwrap_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

/// `<target>/`, the parent of the integration tests' tmp dir.
pub fn target_dir() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Installs the Python readers (not the Node ones; needs the network the
/// first time) and returns `<target>/test-readers`.
pub fn readers() -> PathBuf {
    let script = repo_root().join("scripts/setup-test-readers.sh");
    let out = Command::new("bash")
        .arg(&script)
        .arg(target_dir())
        .env("SAR_SKIP_NODE", "1")
        .env_remove("SAR_SKIP_PYTHON")
        .env_remove("SAR_SKIP_DDS")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{} failed ({}): {}\nInstall what it names, or build the tests with SAR_SKIP_PYTHON=1 \
         to mark these tests ignored.",
        script.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

/// The site-packages directory of a reader installed with `--prefix`.
pub fn prefix_site_packages(prefix: &Path) -> PathBuf {
    let lib = prefix.join("lib");
    std::fs::read_dir(&lib)
        .unwrap()
        .map(|e| e.unwrap().path().join("site-packages"))
        .find(|p| p.is_dir())
        .unwrap_or_else(|| panic!("no lib/python*/site-packages under {}", prefix.display()))
}
