//! The physics simulator of the robot (placeholder: filled by its own change).

pub mod spec;
pub use spec::{AxesSpec, ContactKey, Fault, SensorSpec, SimSpec};
