//! The fixed-rate loop: absolute deadlines on the monotonic clock
//! (`clock_nanosleep`, `TIMER_ABSTIME`; never "sleep for the period"), one
//! [`Controller::step`] per deadline, then publishing. Every cycle is measured
//! (wake-up latency, compute time) into fixed-size histograms; a cycle that
//! ends after the next deadline is an overrun, counted and logged, and the
//! next cycle runs at once (the grid is kept: no cycle is skipped). Ends on
//! SIGTERM/SIGINT (or after `max_cycles`) with the drives halted.

use crate::config::LoopConfig;
use sar_drivers::{AxisDrives, ForceSensor};
use sar_estimator::cycle::TipOutcome;
use sar_loop::control::Controller;
use sar_loop::logq::{LogEvent, LogSender};
use sar_loop::notify::Watchdog;
use sar_loop::rt;
use sar_loop::stats::LoopStats;
use sar_loop::step::{LoopInput, LoopOutput};

/// One cycle as the loop hands it to publishers.
#[derive(Debug, Clone, Copy)]
pub struct Published<'a> {
    /// The cycle's whole input (what `/sar/cycle/input` records; the drive
    /// state as read in the cycle).
    pub loop_input: &'a LoopInput,
    /// The cycle's whole decision (the estimator's output in `estimate`).
    pub decision: &'a LoopOutput,
    /// The step after the cycle (the recorder snapshots its state).
    pub step: &'a sar_loop::step::LoopStep,
    /// Every sensor sample received since the previous cycle (the recorder
    /// writes each as `/sar/sensor/wrench`).
    pub sensor_samples: &'a [sar_drivers::WrenchSample],
    /// The loop's measurements.
    pub stats: &'a LoopStats,
    /// Quick stops so far.
    pub quick_stops: u64,
    /// Messages the recorder dropped so far (set by `record::live`).
    pub recorder_drops: u64,
    /// Whether a recording runs (set by `record::live`).
    pub recording: bool,
    /// The simulator's truth of this cycle, when simulated (set by
    /// `record::live`, which records it).
    pub truth: Option<sar_loop::publish::SimTruth>,
}

/// What the loop talks to around each cycle (shared memory).
pub trait Publish {
    /// Called on the loop thread before every cycle (take operator commands);
    /// must not block.
    fn before_cycle(&mut self) {}
    /// Called on the loop thread after every cycle; must not block.
    fn publish(&mut self, cycle: &Published<'_>);
}

/// No publisher.
impl Publish for () {
    fn publish(&mut self, _: &Published<'_>) {}
}

/// Options of a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunLimits {
    /// Stop after this many cycles (tests); `None`: until a signal.
    pub max_cycles: Option<u64>,
    /// Stall the loop on purpose after this many cycles (a test of the
    /// watchdog: the loop stops cycling until a signal).
    pub stall_after_cycles: Option<u64>,
}

/// Runs the loop until a stop is requested; the drives are halted at the end.
pub fn run<S: ForceSensor, D: AxisDrives, P: Publish>(
    controller: &mut Controller<S, D>,
    config: &LoopConfig,
    limits: RunLimits,
    stats: &mut LoopStats,
    publisher: &mut P,
    watchdog: &mut Watchdog,
    log: &LogSender,
) {
    let period_ns = config.period_ns;
    let mut next_ns = rt::monotonic_ns().unwrap_or(0).saturating_add(period_ns);
    let mut cycle: u64 = 0;
    while !rt::stop_requested() {
        if limits.max_cycles.is_some_and(|m| cycle >= m) {
            break;
        }
        if limits.stall_after_cycles.is_some_and(|m| cycle >= m) {
            // On purpose: no cycle, no publishing, no watchdog ping.
            rt::sleep_until_ns(rt::monotonic_ns().unwrap_or(0).saturating_add(10_000_000));
            continue;
        }
        rt::sleep_until_ns(next_ns);
        if rt::stop_requested() {
            break;
        }
        let woke = rt::monotonic_ns();
        let woke_ns = woke.unwrap_or(next_ns);
        stats.wakeup.record(woke_ns.saturating_sub(next_ns));
        cycle += 1;
        publisher.before_cycle();
        let out = *controller.step(cycle, rt::monotonic_ns);
        publisher.publish(&Published {
            loop_input: controller.loop_input(),
            decision: controller.decision(),
            step: controller.loop_step(),
            sensor_samples: controller.sensor_samples(),
            stats,
            quick_stops: controller.counts().quick_stops,
            recorder_drops: 0,
            recording: false,
            truth: None,
        });
        // The watchdog is fed from here, the loop itself: a stuck loop stops
        // feeding it.
        let estimate = matches!(out.tip, TipOutcome::Estimate(_));
        watchdog.after_cycle(cycle, out.guard_state, &out.guard_reason, estimate);
        let end_ns = rt::monotonic_ns().unwrap_or(woke_ns);
        stats.compute.record(end_ns.saturating_sub(woke_ns));
        stats.cycles = cycle;
        next_ns = next_ns.saturating_add(period_ns);
        if end_ns > next_ns {
            stats.overruns += 1;
            stats.note_overrun(cycle);
            log.send(LogEvent::Overrun {
                cycle,
                late_ns: end_ns - next_ns,
            });
        }
    }
    watchdog.stopping();
    controller.shutdown();
}
