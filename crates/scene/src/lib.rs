//! The 3D scene (`sar-scene`): pure drawing, no I/O, no allocation. The
//! recordings (every one: the recorder draws it on its thread) and the live
//! view (`sarctl view`) draw it with the same functions into the same ROS 2
//! messages, so a recording looks as the live view did.
//!
//! - [`geometry`]: the robot and manipulator as drawn, from the
//!   configuration.
//! - [`draw`]: one published state and the geometry to a
//!   `visualization_msgs/msg/MarkerArray`, and the frames as
//!   `tf2_msgs/msg/TFMessage`.
//! - [`topics`]: the recordings' messages made from the published state, and
//!   a state made from recorded messages.

pub mod draw;
pub mod geometry;
pub mod topics;

/// The 3D scene's topic (`visualization_msgs/msg/MarkerArray`).
pub const SCENE_TOPIC: &str = "/sar/scene";
/// The moving frames' topic (`tf2_msgs/msg/TFMessage`).
pub const TF_TOPIC: &str = "/tf";
/// The fixed frames' topic (`tf2_msgs/msg/TFMessage`, durability
/// transient_local: written at the start of every recording file).
pub const TF_STATIC_TOPIC: &str = "/tf_static";
