//! `sarctl view`: the live view in Foxglove. A separate process subscribes to
//! the daemon's state over iceoryx2 (a subscriber like any other: the state
//! service overflows safely, so a slow or absent view never makes the loop
//! wait) and serves it over the Foxglove WebSocket protocol with the
//! Foxglove SDK's server (`foxglove` crate, websocket feature, no TLS),
//! behind a relay ([`front`]) that also accepts clients offering only the
//! subprotocol `foxglove.websocket.v1`.
//!
//! Channels:
//! - the recordings' topics (INTERFACES.md 1, `ros2msg` schemas and `cdr`
//!   messages from [`sar_msgs::msgs`]) that the state holds, every
//!   state ([`topics`]);
//! - the 3D scene as the recordings hold it (`ros2msg`/`cdr`, drawn by
//!   `sar_scene::draw`): `sar_scene::SCENE_TOPIC`
//!   (`visualization_msgs/msg/MarkerArray`), `sar_scene::TF_TOPIC` and
//!   `sar_scene::TF_STATIC_TOPIC` (`tf2_msgs/msg/TFMessage`; the fixed
//!   frames with every scene: a WebSocket has no transient_local),
//!   decimated to `scene_hz` by the state's clock;
//! - [`STATUS_TOPIC`] (JSON: |F_tip|, the guard's limits and state, the
//!   loop's figures, the states the view lost), at the scene's rate.
//!
//! Every message's log time is the cycle's monotonic `now_ns`, as in the
//! recordings. Read-only: the server offers no client publishing, services
//! or parameters. Messages for a client wait in the SDK's per-client queue
//! (`BACKLOG` messages; a stalled client loses the oldest).
//!
//! The Foxglove SDK brings tokio, prost and tungstenite: only `sarctl`
//! links them (`sard` is another crate, which does not depend on this one).

pub mod front;
mod live;

pub use live::*;

/// The default address.
pub const DEFAULT_BIND: &str = "127.0.0.1:8765";
/// The default scene rate, Hz.
pub const DEFAULT_SCENE_HZ: f64 = 30.0;
