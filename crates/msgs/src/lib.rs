//! The SAR protocol (`sar-msgs`): what crosses a process or a file, as data.
//!
//! - [`wire`]: the shared-memory payloads (flat `#[repr(C)]`, numbers only)
//!   and their codes: guard states, reasons, drive states, commands,
//!   replies.
//! - [`cdr`]: the ROS 2 CDR encoder and decoder.
//! - [`msgs`]: the recording's ROS 2 messages, their `.msg` schemas
//!   (`msg/`) and topics.
//! - [`viz`]: the 3D scene's standard ROS 2 messages
//!   (`visualization_msgs/msg/MarkerArray`, `tf2_msgs/msg/TFMessage`).
//!
//! No I/O, no threads: the transport (iceoryx2) and the files (MCAP) are
//! above this crate.

pub mod cdr;
pub mod msgs;
pub mod viz;
pub mod wire;
