//! What the simulator simulates: a validated, plain description of the true
//! robot, manipulator, support, axes, sensor, contact script and faults.
//! Scenario files ([`crate::scenario`]) are parsed and checked into this.
//!
//! Times are nanoseconds from the simulator's start (the clock's time when the
//! simulator was made).

use crate::Vec3;
use sar_kinematics::{ActiveJoints, Calibration, Profile};

/// Everything the simulator needs; built by [`crate::scenario`] (or by hand in tests).
#[derive(Debug, Clone, PartialEq)]
pub struct SimSpec {
    /// Seed of every random number (sensor noise): same seed and spec, same samples.
    pub seed: u64,
    /// The TRUE geometry (the support point B here is the real one; the
    /// daemon's configuration may differ, which is the point of calibration).
    pub calibration: Calibration,
    /// The TRUE manipulator (L, d, m, c).
    pub profile: Profile,
    /// Coulomb friction of the support along the rod, N (>= 0).
    pub friction_n: f64,
    /// The axes and their encoders.
    pub axes: AxesSpec,
    /// The force/torque sensor.
    pub sensor: SensorSpec,
    /// Tip force keyframes, piecewise linear in time, zero before the first
    /// and held after the last. Sorted by time.
    pub contact: Vec<ContactKey>,
    /// A known mass hung at the tip (the article's Table 3), kg (0: none).
    pub tip_mass_kg: f64,
    /// Faults on demand.
    pub faults: Vec<Fault>,
    /// Step of the physics integration, ns (e.g. 100_000). Results do not depend
    /// on when the simulator is polled, only on this grid.
    pub physics_step_ns: u64,
}

/// The three prismatic axes (q1, q2, q3; index 0, 1, 2 in arrays).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxesSpec {
    /// Speed limit of each axis, m/s.
    pub max_speed_mps: f64,
    /// Acceleration limit of each axis, m/s^2.
    pub max_accel_mps2: f64,
    /// Screw lead, metres per motor turn.
    pub lead_m_per_turn: f64,
    /// Encoder counts per motor turn (4096 = 12 bits).
    pub counts_per_turn: u32,
    /// Period at which positions are reported, ns.
    pub position_period_ns: u64,
    /// Travel of each axis, (min, max) metres; targets outside are refused.
    pub travel_m: [(f64, f64); 3],
    /// Positions at start, m.
    pub start: ActiveJoints,
}

/// The force/torque sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSpec {
    /// Sample period, ns (2_000_000 for 500 Hz).
    pub period_ns: u64,
    /// From the instant a sample measures to its host receive time, ns.
    pub latency_ns: u64,
    /// Force noise std per sensor axis, N (HEX-6: 0.2, 0.2, 0.8).
    pub noise_n: Vec3,
    /// Torque noise std per sensor axis, N m.
    pub noise_nm: Vec3,
    /// Force bias at start, sensor frame, N.
    pub bias_n: Vec3,
    /// Torque bias at start, sensor frame, N m.
    pub bias_nm: Vec3,
    /// Slow drift of the force bias, N/s.
    pub drift_n_per_s: Vec3,
    /// Whether the device has a device-side tare command.
    pub has_tare: bool,
}

/// One keyframe of the tip force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactKey {
    /// Time from start, ns.
    pub t_ns: u64,
    /// F_tip: the force the tip applies to the tissue, base frame, N.
    pub force_n: Vec3,
}

/// A fault on demand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The sensor sends nothing from `from_ns` until `until_ns` (or forever).
    SensorSilent {
        /// Start, ns from start.
        from_ns: u64,
        /// End, ns from start; `None`: never comes back.
        until_ns: Option<u64>,
    },
    /// The first sample measured at or after `at_ns` carries NaN values.
    NanSample {
        /// When, ns from start.
        at_ns: u64,
    },
    /// From `at_ns`, the encoder of one axis reads `jump_m` off (the axis
    /// itself does not move).
    EncoderJump {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// The jump, m.
        jump_m: f64,
    },
    /// At `at_ns` the drives fault with `code` and stop; `fault_reset` clears it.
    DriveFault {
        /// When, ns from start.
        at_ns: u64,
        /// Fault code.
        code: u16,
    },
}
