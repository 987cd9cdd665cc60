//! Recording (INTERFACES.md 1): the ROS 2 messages of the daemon's topics in
//! MCAP files (profile `ros2`, `ros2msg` schemas, `cdr` messages, zstd
//! chunks), written by a recorder that never makes the control loop wait,
//! rotated by size or duration, read back by topic, and recovered after a
//! crash.
//!
//! The messages, their CDR and topics are `sar_msgs::{cdr, msgs}`.
//! - [`file`]: MCAP files and their rotation.
//! - [`recorder`]: the bounded queue and the writer thread.
//! - [`reader`]: reading (up to the last complete chunk) and [`recover`].
//! - [`rosbag2`]: a rosbag2 directory (`metadata.yaml`) of recordings.
//! - [`convert`]: the loop's cycle as recorded messages, and back.
//! - [`lean`]: the lean recording mode's batches of cycle inputs.
//! - [`output`]: the files the tools write: never an input, written
//!   whole or not at all, within the disk's free space.
//! - [`live`]: the loop's recording sink and the recordings' manager.
//! - [`replay`]: bit-exact replay of recordings and rotated sets.

pub mod convert;
pub mod file;
pub mod lean;
pub mod live;
pub mod output;
pub mod reader;
pub mod recorder;
pub mod replay;
pub mod rosbag2;

pub use file::{
    FileOptions, OFFERED_QOS_PROFILES, OFFERED_QOS_PROFILES_LATCHED, QOS_METADATA_KEY,
    RotatingWriter, SceneOptions, WriteError,
};
pub use reader::{
    McapReader, MessageRef, RawMessage, ReadError, RecoverError, RecoverReport, read_file, recover,
};
pub use recorder::{Recorder, RecorderConfig, RecorderError, RecordingReport};
pub use sar_msgs::msgs::{Outgoing, RosMessage, Topic};
