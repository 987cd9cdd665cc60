//! `sarctl`, the operator's tool, as a library (the binary is `main.rs`):
//!
//! - [`cli`]: the subcommands' bodies (record, replay, recover, export,
//!   identify, workspace).
//! - [`identify`]: `sarctl identify`, the manipulator's mass, centre of mass
//!   and support from static poses (live or from a recording).
//! - [`view`]: `sarctl view`, the live view in Foxglove.
//!
//! It talks to `sard` only through the shared-memory transport (`sar-shm`)
//! and reads recordings through `sar-record`; it never links the daemon.

pub mod cli;
pub mod identify;
pub mod view;
