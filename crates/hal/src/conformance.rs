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
//! A test harness, never shipped: behind the feature `conformance`, which
//! only the implementations' `dev-dependencies` turn on. Usage: one `#[test]`
//! per check function of [`sensor`] and [`drives`], each calling it with a
//! fresh harness (`crates/sim/tests/sim.rs` generates them with a macro).
//!
//! No check passes by doing nothing. What a check needs beyond the trait (a
//! fault on demand, a target outside the travel, a steady load to tare) the
//! harness must answer with a [`Capability`], with no default: `Ready` runs the
//! check, `NotApplicable { why }` (the device has no such thing: no travel
//! check, no tare) passes it and prints why, and `Unable { why }` (the device
//! has it but the harness cannot provoke it) FAILS the check with the reason.
//! The simulator's harnesses are `Ready` for everything (`crates/sim/tests/sim.rs`
//! checks that).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

pub mod drives;
pub mod sensor;

use crate::{AxisDrives, ForceSensor};
use sar_kinematics::ActiveJoints;

/// Whether a harness can give what a check needs.
#[derive(Debug, Clone, PartialEq)]
pub enum Capability<T> {
    /// It can: the check runs with this.
    Ready(T),
    /// The check does not apply to the device (it has no such feature): the
    /// check passes, and prints why.
    NotApplicable {
        /// Why not.
        why: &'static str,
    },
    /// The device has the feature but the harness cannot exercise it: the
    /// check FAILS with this reason.
    Unable {
        /// Why not.
        why: &'static str,
    },
}

impl<T> Capability<T> {
    /// `Some` to run the check; `None` (after printing why) when it does not
    /// apply; panics when the harness is unable.
    pub fn require(self, check: &str) -> Option<T> {
        match self {
            Capability::Ready(t) => Some(t),
            Capability::NotApplicable { why } => {
                println!("{check}: not applicable to this device: {why}");
                None
            }
            Capability::Unable { why } => {
                panic!("{check}: the harness cannot run this check: {why}")
            }
        }
    }

    /// Whether the check can run.
    pub fn is_ready(&self) -> bool {
        matches!(self, Capability::Ready(_))
    }
}

/// How to check that a tare takes effect: the load on the sensor stays as it
/// is while the check runs (at rest, no contact), and the device's noise
/// allows telling a tared reading from an untared one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TareCheck {
    /// How long after `tare` or `clear_tare` samples may still have been
    /// measured before it (latency, filtering), ns.
    pub takes_effect_ns: u64,
    /// How many samples to average for each reading.
    pub samples: usize,
    /// Largest accepted distance of an averaged force from what it should be
    /// (0 after a tare; the pre-tare reading after `clear_tare`), per axis, N.
    pub tolerance_n: f64,
    /// The same for the torque, N m.
    pub tolerance_nm: f64,
}

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
    /// Whether (and how) the tare check can run: `NotApplicable` only for a
    /// device without a tare command (whose `tare` and `clear_tare` must then
    /// be `Unsupported`).
    fn tare_check(&self) -> Capability<TareCheck>;
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
    /// A finite target outside the travel; `NotApplicable` only for a device
    /// that checks no travel.
    fn out_of_travel_target(&self) -> Capability<ActiveJoints>;
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
    /// lets it take effect. No default: a harness that cannot says `Unable`
    /// (and the fault check fails) or, for a source that has no faults to
    /// provoke, `NotApplicable`.
    fn provoke_fault(&mut self) -> Capability<()>;
}
