//! The SAR daemon's library: configuration, the fixed-rate loop's runner
//! (the loop itself is `sar-loop`, the payloads `sar-msgs`),
//! and the recording (MCAP files of ROS 2 messages, INTERFACES.md 1). The
//! binaries `sard` and `sarctl` are thin shells over it.

pub mod cli;
pub mod devices;
pub mod identify;
pub mod sim;
pub mod view;
