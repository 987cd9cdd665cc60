//! The SAR daemon's library: the recording (MCAP files of ROS 2 messages,
//! INTERFACES.md 1). The binaries `sard` and `sarctl` build on it.

pub mod record;
