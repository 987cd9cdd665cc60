//! Conformance suites of the driver traits, one per trait, generic over a
//! harness (in the style of iceoryx2's generic tests): every implementation of
//! [`ForceSensor`] and of [`AxisDrives`] (the simulator now; the recording
//! replay and the real devices later) runs the same checks.
//!
//! A harness gives the device, a way to let time pass (a simulated clock
//! jumps; a real one sleeps) and the device's bounds. Time is measured in the
//! harness's own clock, so "does not block" and "within the timeout" hold for
//! simulated and real time alike (for real time, `call_slack_ns` absorbs the
//! cost of a call).
//!
//! Usage: `mod conformance;` in a test file, then one `#[test]` per check
//! function of [`sensor`] and [`drives`], each calling it with a fresh harness
//! (`tests/sim.rs` generates them with a macro).
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

pub mod drives;
pub mod sensor;

use sar_drivers::{AxisDrives, ForceSensor};
use sar_kinematics::ActiveJoints;

/// What the sensor suite needs from an implementation under test.
///
/// The harness hands out a sensor in normal operation (no fault scheduled,
/// sending at its nominal rate) that has not been polled yet.
pub trait SensorHarness {
    /// The sensor under test.
    type Sensor: ForceSensor;
    /// The sensor.
    fn sensor(&mut self) -> &mut Self::Sensor;
    /// Lets `ns` of the harness's time pass (sleep, or advance a simulated clock).
    fn let_time_pass(&mut self, ns: u64);
    /// The harness's time, ns (the time base of `received_ns`).
    fn now_ns(&self) -> u64;
    /// The nominal sample period, ns.
    fn period_ns(&self) -> u64;
    /// In normal operation, the longest time from any instant until the next
    /// sample is received, ns (period, latency jitter, ...).
    fn arrival_bound_ns(&self) -> u64;
    /// How much of the harness's time a call may take without counting as
    /// blocking, ns (0 for a simulated clock).
    fn call_slack_ns(&self) -> u64;
}

/// What the drives suite needs from an implementation under test.
///
/// The harness hands out drives in `Ready`, at rest, in normal operation.
pub trait DrivesHarness {
    /// The drives under test.
    type Drives: AxisDrives;
    /// The drives.
    fn drives(&mut self) -> &mut Self::Drives;
    /// Lets `ns` of the harness's time pass.
    fn let_time_pass(&mut self, ns: u64);
    /// The harness's time, ns (the time base of `stamp_ns`).
    fn now_ns(&self) -> u64;
    /// A target within travel, reachable from the start, at least a few
    /// millimetres from the start on some axis.
    fn reachable_target(&self) -> ActiveJoints;
    /// A finite target outside the travel (None if the device checks none).
    fn out_of_travel_target(&self) -> Option<ActiveJoints>;
    /// Within this time after `set_targets(reachable_target())` from rest the
    /// axes are at the target, within `tolerance_m`, ns.
    fn settle_bound_ns(&self) -> u64;
    /// How far reported positions at rest may be from a reached target, m
    /// (quantisation, following error).
    fn tolerance_m(&self) -> f64;
    /// The oldest a position report may be, ns (its period and transport).
    fn report_age_bound_ns(&self) -> u64;
    /// How much of the harness's time a call may take without counting as
    /// blocking, ns.
    fn call_slack_ns(&self) -> u64;
    /// The longest a commanded state change (enable, disable, quick stop,
    /// fault reset) may take to show in `state()`, ns (0: at once).
    fn transition_bound_ns(&self) -> u64;
    /// Provokes a transient drive fault (one that `fault_reset` clears) and
    /// lets it take effect; false if the harness cannot.
    fn provoke_fault(&mut self) -> bool {
        false
    }
}
