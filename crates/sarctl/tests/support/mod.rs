//! What the tests of `sarctl` against a running daemon share: where the
//! daemon's binary is.
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::LazyLock;

/// `sarctl`, this package's binary.
pub const SARCTL: &str = env!("CARGO_BIN_EXE_sarctl");

/// `sard`, sar-daemon's binary, in the same target directory as `sarctl`.
/// `cargo test --workspace` (the README's test command) builds every
/// package's binaries before any test runs, so it is this build's; run alone
/// (`cargo test -p sarctl`), build it first (`cargo build -p sar-daemon`).
pub static SARD: LazyLock<PathBuf> = LazyLock::new(|| {
    let sard = std::path::Path::new(SARCTL).with_file_name("sard");
    assert!(
        sard.exists(),
        "{} is missing: these tests run sar-daemon's binary; run `cargo test --workspace`, \
         or `cargo build -p sar-daemon` first",
        sard.display()
    );
    sard
});
