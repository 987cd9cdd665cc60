//! The SAR protocol (`sar-msgs`): what crosses a process or a file, as data.
//!
//! - [`wire`]: the shared-memory payloads (flat `#[repr(C)]`, numbers only)
//!   and their codes: guard states, reasons, drive states, commands,
//!   replies.
//! - [`command`] (`msgs::command`, a part of the recording's messages that
//!   also owns the command's wire form, [`wire::CommandMsg`]): the
//!   operator's commands, declared once (the table their wire and recorded
//!   encoders and decoders, log text and help come from).
//! - [`cdr`]: the ROS 2 CDR encoder and decoder.
//! - [`msgs`]: the recording's ROS 2 messages, their `.msg` schemas
//!   (`msg/`) and topics.
//! - [`scene`]: the 3D scene's ROS 2 messages (`MarkerArray`, `TFMessage`).
//!
//! No I/O, no threads: the transport (iceoryx2) and the files (MCAP) are
//! above this crate.

pub mod cdr;
#[macro_use]
pub mod msgs;
pub use msgs::command;
pub mod scene;
pub mod wire;
