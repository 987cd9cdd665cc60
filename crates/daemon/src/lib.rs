//! The SAR daemon's library: configuration, the fixed-rate loop and its parts,
//! and the recording (MCAP files of ROS 2 messages, INTERFACES.md 1). The
//! binaries `sard` and `sarctl` are thin shells over it.

pub mod cli;
pub mod config;
pub mod control;
pub mod devices;
pub mod identify;
pub mod logq;
pub mod notify;
pub mod record;
pub mod rt;
pub mod runloop;
pub mod shm;
pub mod sim;
pub mod stats;
pub mod step;
pub mod view;
pub mod wire;
