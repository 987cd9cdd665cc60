//! Helpers shared by the record-and-replay integration tests of this folder:
//! where the fixtures and the scenarios are.

use std::path::PathBuf;

/// The folder of the committed MCAP fixtures (`tests/fixtures`).
pub fn fixtures_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures")
}

/// The folder of the simulator's scenario files (`scenarios`).
pub fn scenarios_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

pub mod dynamic_recordings;
pub mod identify_fixtures;

/// The folder of the replay fixtures (`tests/fixtures/replay`).
pub fn replay_dir() -> PathBuf {
    fixtures_dir().join("replay")
}
