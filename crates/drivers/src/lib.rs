//! The SAR's hardware edge: small traits for the force/torque sensor and the
//! axis drives, and their implementations.
//!
//! The daemon talks only to [`ForceSensor`] and [`AxisDrives`]; it does not know
//! whether a real robot, the [`sim`] physics simulator or (later) a recording
//! is behind them. In the spirit of embedded-hal / embedded-can: small traits,
//! non-blocking calls or waits with an explicit bound, and errors that carry a
//! `#[non_exhaustive]` [`ErrorKind`] so generic code can react without knowing
//! the implementation. Every implementation passes the same conformance suite
//! (`tests/conformance/`).

pub mod canopen;
pub mod clock;
mod convert;
pub mod drives;
pub mod error;
pub mod join;
pub mod motion;
pub mod rdt;
pub mod runner;
pub mod scenario;
pub mod sensor;
pub mod sim;

pub use clock::{Clock, ClockError, MonotonicClock, SimClock};
pub use drives::{AxisDrives, DriveState, JointPositions};
pub use error::{Error, ErrorKind};
pub use sensor::{Channels, Drained, ForceSensor, Rail, SensorStatus, WrenchSample};

/// A 3-vector of `f64` (frame given by the name or doc).
pub type Vec3 = nalgebra::Vector3<f64>;
