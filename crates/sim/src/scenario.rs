//! A scenario, typed: a simulated robot (true geometry, manipulator, support,
//! axes, sensor, tip contact, tissues, faults; the simulator's [`SimSpec`])
//! and the motion script to run on it ([`MotionScript`], for
//! [`crate::runner`]).
//!
//! Scenario files (TOML, `scenarios/`, described in `scenarios/README.md`)
//! are read and checked into a [`Scenario`] by `sar_config::scenario`; this
//! crate only holds what the simulator and the runner consume (and tests may
//! build it by hand).

use crate::SimSpec;
use sar_hal::motion::{SlideSign, move_time_s};
use sar_kinematics::{ActiveJoints, Calibration};

/// A checked scenario: what to simulate and what to run on it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The `name` key.
    pub name: String,
    /// The `description` key ("" when absent).
    pub description: String,
    /// Where the scenario came from (the file's path, or the origin its text was given with).
    pub origin: String,
    /// `manipulator.name`, when given.
    pub manipulator_name: Option<String>,
    /// The simulated robot.
    pub spec: SimSpec,
    /// The motion to run on it.
    pub script: MotionScript,
}

/// The motion of a scenario: where the axes start and the targets in order.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionScript {
    /// Positions of the axes at start (equal to `spec.axes.start`).
    pub start: ActiveJoints,
    /// The steps, `[[motion]]` first, then the `[random_motion]` ones.
    pub steps: Vec<MotionStep>,
    /// The geometry the steps were computed with; the runner uses it to follow
    /// a = |B - A| and so the sign of each slide of the rod in the support.
    pub calibration: Calibration,
    /// Speed limit of each axis, m/s (bounds the wait for arrival).
    pub max_speed_mps: f64,
    /// Acceleration limit of each axis, m/s^2.
    pub max_accel_mps2: f64,
}

/// One step of the motion: go to `target`, then hold it for `hold_ns`.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionStep {
    /// Where the step comes from: `motion[3]` or `random_motion[2]`.
    pub key: String,
    /// Target positions of the axes, m.
    pub target: ActiveJoints,
    /// Time to hold the target after arriving, ns.
    pub hold_ns: u64,
    /// The sign of the last slide of the rod in the support once the step is
    /// done, if each axis moves on its own time-optimal trapezoid from rest to
    /// rest (as the simulator's do): inserting when A last moved towards B (the
    /// rod slid along u), retracting away, the previous step's sign when the
    /// step does not slide the rod, and unknown when nothing has slid yet.
    /// Followed with the same [`sar_hal::motion::SlideTracker`] as the runner's.
    pub planned_slide_sign: SlideSign,
}

impl MotionScript {
    /// A time the script needs at least with straight moves at the limits:
    /// the sum over the steps of the slowest axis's trapezoid and the hold, ns.
    pub fn nominal_duration_ns(&self) -> u64 {
        let mut from = self.start;
        let mut total_ns: u64 = 0;
        for step in &self.steps {
            let move_s = move_time_s(&from, &step.target, self.max_speed_mps, self.max_accel_mps2);
            total_ns = total_ns
                .saturating_add(seconds_to_ns_saturating(move_s))
                .saturating_add(step.hold_ns);
            from = step.target;
        }
        total_ns
    }
}

/// Seconds as ns, rounded to the nearest; 0 for a time that is not finite or
/// not positive (the times of a scenario are far below `u64::MAX` ns).
pub fn seconds_to_ns_saturating(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        // Saturating float-to-int cast; times here are far below u64::MAX ns.
        (s * 1e9).round() as u64
    } else {
        0
    }
}
