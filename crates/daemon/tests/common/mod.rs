//! Shared test helpers: deterministic messages of every topic, scratch dirs.
// Each test binary that includes this module uses a part of it.
#![allow(dead_code, unused_imports)]

pub mod readers;

use sar_test_support::files::scratch_in;
pub use sar_test_support::messages::*;
use std::path::PathBuf;

/// A fresh scratch directory under the target's tmp dir.
pub fn scratch(name: &str) -> PathBuf {
    scratch_in(env!("CARGO_TARGET_TMPDIR"), "sar-daemon", name)
}
