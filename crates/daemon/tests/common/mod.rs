//! Shared test helpers: deterministic messages of every topic, scratch dirs.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

pub mod readers;

pub use sar_test_support::messages::*;
use std::path::PathBuf;

/// A fresh scratch directory under the target's tmp dir.
pub fn scratch(name: &str) -> PathBuf {
    scratch_in(env!("CARGO_TARGET_TMPDIR"), "sar-daemon", name)
}
