//! The SAR's hardware layer: the small traits the loop talks to the robot
//! through, and what every implementation of them shares.
//!
//! - [`ForceSensor`] and [`AxisDrives`]: the force/torque sensor and the axis
//!   drives. In the spirit of embedded-hal / embedded-can: small traits,
//!   non-blocking calls or waits with an explicit bound, and errors that
//!   carry a `#[non_exhaustive]` [`ErrorKind`] so generic code can react
//!   without knowing the implementation.
//! - [`Clock`]: now and sleep-until (`MonotonicClock`, the host's;
//!   `SimClock`, one that moves only when told).
//! - [`motion`]: the axis plan under speed and acceleration limits, and
//!   [`servo`]: the one model of a drive's position loop; shared by the
//!   loop, the simulator and the drivers, so that they agree by
//!   construction.
//! - [`join`]: bounded joins of the threads a daemon (or a driver) starts.
//! - `conformance` (feature `conformance`, for tests): one suite per trait
//!   that every implementation runs.
//!
//! The implementations are crates of their own above this one: the
//! simulator (`sar-sim`), the RDT sensor (`sar-rdt`) and the CANopen drives
//! (`sar-canopen`); the loop depends on this crate alone.

pub mod clock;
#[cfg(feature = "conformance")]
pub mod conformance;
pub mod convert;
pub mod drives;
pub mod error;
pub mod join;
pub mod motion;
pub mod sensor;
pub mod servo;

pub use clock::{Clock, ClockError, MonotonicClock, SimClock};
pub use drives::{AxisDrives, DriveState, JointPositions};
pub use error::{Error, ErrorKind};
pub use sensor::{Channels, Drained, ForceSensor, Rail, SensorStatus, WrenchSample};

/// A 3-vector of `f64` (frame given by the name or doc).
pub type Vec3 = nalgebra::Vector3<f64>;
