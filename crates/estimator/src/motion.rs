//! The carriage's commanded motion (MODEL.md 10): what the loop hands the
//! estimator each cycle so that the tip force is compensated for the rod's
//! inertia. The loop derives it from the trajectory it commands (planned moves,
//! streamed set points, the drives' own quick stop at their configured
//! deceleration), never from the encoders differentiated twice; so it is a pure
//! function of the recorded inputs and a recording replays bit for bit.

use crate::Vec3;

/// The carriage's velocity and acceleration, base frame {0}, at the sensor
/// sample's stamp. The carriage only translates: A' and A'' are these.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarriageMotion {
    /// A' = (q3', q2', q1'), base frame, m/s.
    pub velocity_mps: Vec3,
    /// A'' = (q3'', q2'', q1''), base frame, m/s^2.
    pub accel_mps2: Vec3,
    /// The standard deviation of each component of `accel_mps2` (how far the
    /// axes' real acceleration may be from it), m/s^2 (finite, >= 0).
    pub accel_std_mps2: f64,
}

impl CarriageMotion {
    /// At rest, known exactly (the static model of MODEL.md 4).
    pub const REST: Self = Self {
        velocity_mps: Vec3::new(0.0, 0.0, 0.0),
        accel_mps2: Vec3::new(0.0, 0.0, 0.0),
        accel_std_mps2: 0.0,
    };

    /// Whether every component is at rest and known exactly.
    pub fn is_rest(&self) -> bool {
        *self == Self::REST
    }
}

impl Default for CarriageMotion {
    fn default() -> Self {
        Self::REST
    }
}
