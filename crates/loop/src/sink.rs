//! What the loop hands each cycle to: its sinks (the shared-memory
//! publisher, the recorder), through one interface, with one shared
//! [`SinkHealth`] for their counters. A sink reads the cycle and writes only
//! its own counters in the health; the sinks after it read them (the
//! publisher puts the recorder's in the published state). No sink wraps
//! another and none patches the loop's output.
//!
//! Sinks run on the loop's thread, in order (`(recorder, publisher)` runs
//! the recorder first): they must not block, allocate or panic.

use crate::control::Controller;
use crate::publish::SimTruth;
use crate::stats::LoopStats;
use crate::step::{LoopInput, LoopOutput, LoopStep};
use sar_hal::{AxisDrives, ForceSensor, WrenchSample};

/// One cycle as the loop hands it to its sinks.
#[derive(Debug, Clone, Copy)]
pub struct Cycle<'a> {
    /// The cycle's whole input (what `/sar/cycle/input` records; the drive
    /// state as read in the cycle).
    pub loop_input: &'a LoopInput,
    /// The cycle's whole decision (the estimator's output in `estimate`).
    pub decision: &'a LoopOutput,
    /// The step after the cycle (the recorder snapshots its state).
    pub step: &'a LoopStep,
    /// Every sensor sample received since the previous cycle (the recorder
    /// writes each as `/sar/sensor/wrench`).
    pub sensor_samples: &'a [WrenchSample],
    /// The loop's measurements.
    pub stats: &'a LoopStats,
    /// Quick stops so far.
    pub quick_stops: u64,
    /// The simulator's truth of this cycle, asked once by the loop when
    /// simulated (`None`: a real robot).
    pub truth: Option<SimTruth>,
}

impl<'a> Cycle<'a> {
    /// The cycle `controller` has just stepped, as `run` hands it on.
    pub fn of<S: ForceSensor, D: AxisDrives>(
        controller: &'a Controller<S, D>,
        stats: &'a LoopStats,
        truth: Option<SimTruth>,
    ) -> Self {
        Self {
            loop_input: controller.loop_input(),
            decision: controller.decision(),
            step: controller.loop_step(),
            sensor_samples: controller.sensor_samples(),
            stats,
            quick_stops: controller.counts().quick_stops,
            truth,
        }
    }
}

/// The sinks' counters, one struct shared by all of them. Each field has one
/// writer, named on it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SinkHealth {
    /// Messages the recorder dropped so far, over every recording (the
    /// recorder).
    pub recorder_drops: u64,
    /// The recording's state, `sar_msgs::wire::recording_code` (on, off,
    /// or failed with its OS error) (the recorder).
    pub recording: u64,
    /// States the publisher's queue dropped so far (the publisher).
    pub publish_queue_drops: u64,
}

/// Something the loop hands each cycle to.
pub trait Sink {
    /// Called on the loop thread before every cycle (take operator
    /// commands); must not block.
    fn before_cycle(&mut self) {}
    /// Called on the loop thread after every cycle; must not block. Writes
    /// only its own counters in `health`.
    fn cycle(&mut self, cycle: &Cycle<'_>, health: &mut SinkHealth);
    /// Whether the sink can take a cycle without dropping. Asked only on a
    /// simulated clock, where the loop waits for it ([`crate::time`]); in
    /// real time a full sink drops and counts.
    fn has_room(&self) -> bool {
        true
    }
}

/// No sink.
impl Sink for () {
    fn cycle(&mut self, _: &Cycle<'_>, _: &mut SinkHealth) {}
}

/// Two sinks, the first first (and a list of them, nested).
impl<A: Sink, B: Sink> Sink for (A, B) {
    fn before_cycle(&mut self) {
        self.0.before_cycle();
        self.1.before_cycle();
    }
    fn cycle(&mut self, cycle: &Cycle<'_>, health: &mut SinkHealth) {
        self.0.cycle(cycle, health);
        self.1.cycle(cycle, health);
    }
    fn has_room(&self) -> bool {
        self.0.has_room() && self.1.has_room()
    }
}

/// A sink borrowed.
impl<T: Sink + ?Sized> Sink for &mut T {
    fn before_cycle(&mut self) {
        (**self).before_cycle();
    }
    fn cycle(&mut self, cycle: &Cycle<'_>, health: &mut SinkHealth) {
        (**self).cycle(cycle, health);
    }
    fn has_room(&self) -> bool {
        (**self).has_room()
    }
}
