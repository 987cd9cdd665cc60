//! The 3D scene (`sar-scene`): pure drawing, no I/O. Every recording
//! (`sar-record`, on the recorder's thread) and the live view (`sarctl
//! view`) draw it from the same functions, as the same ROS 2 messages, so a
//! recording looks as the live view did.
//!
//! - [`geometry`]: the robot and manipulator as drawn, from the
//!   configuration.
//! - [`draw`]: one published state and the geometry to a
//!   `visualization_msgs/MarkerArray` ([`SCENE_TOPIC`]) and the frames as
//!   `tf2_msgs/TFMessage` ([`TF_STATIC_TOPIC`], [`TF_TOPIC`]); the messages
//!   are `sar_msgs::scene`'s.
//! - [`topics`]: the recordings' messages made from the published state, and
//!   the scene's state made from recorded messages.
//! - [`rate`]: decimation by the cycles' stamps (the scene's rate, the ROS 2
//!   bridge's per-topic rates).

pub mod draw;
pub mod geometry;
pub mod rate;
pub mod topics;

/// The 3D scene's topic (`visualization_msgs/msg/MarkerArray`).
pub const SCENE_TOPIC: &str = "/sar/scene";
/// The guard's figures at the scene's rate (`sar_msgs/msg/SceneStatus`).
pub const SCENE_STATUS_TOPIC: &str = "/sar/scene/status";
/// The fixed frames (`tf2_msgs/msg/TFMessage`, transient local): `world` ->
/// `base`.
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// The moving frames (`tf2_msgs/msg/TFMessage`): `carriage`, `rod`, `tip`.
pub const TF_TOPIC: &str = "/tf";
