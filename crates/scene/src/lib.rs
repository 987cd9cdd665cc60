//! The 3D scene (`sar-scene`): pure drawing, no I/O. The live view
//! (`sarctl view`) and the recordings' companion files (`NAME.scene.mcap`)
//! both draw it from the same functions, so a recording looks as the live
//! view did.
//!
//! - [`geometry`]: the robot and manipulator as drawn, from the
//!   configuration (always built: the recording's settings carry it).
//! - [`draw`]: one published state and the geometry to a
//!   `foxglove.SceneUpdate`, and its MCAP schema and encoding (cargo feature
//!   `draw`: the Foxglove SDK's message types, which bring prost; `sard` is
//!   built without it).
//! - [`topics`]: the recordings' messages made from the published state, and
//!   a state made from recorded messages.

pub mod geometry;
pub mod topics;

#[cfg(feature = "draw")]
pub mod draw;

/// The 3D scene's topic.
pub const SCENE_TOPIC: &str = "/sar/scene";
/// The scene's transform `world` -> `base`.
pub const TF_TOPIC: &str = "/sar/scene/tf";
