//! The fixed-rate loop: absolute deadlines on the monotonic clock
//! (`clock_nanosleep`, `TIMER_ABSTIME`; never "sleep for the period"), one
//! [`Controller::step`] per deadline, then the cycle handed to the sinks
//! ([`crate::sink`]). Every cycle is measured
//! (wake-up latency, compute time) into fixed-size histograms; a cycle that
//! ends after the next deadline is an overrun, counted and logged, and the
//! next cycle runs at once (the grid is kept: no cycle is skipped). Ends on
//! SIGTERM/SIGINT (or after `max_cycles`) with the drives halted.

use crate::control::Controller;
use crate::logq::{LogEvent, LogSender};
use crate::notify::Watchdog;
use crate::publish::SimTruthFn;
use crate::rt;
use crate::sink::{Cycle, Sink, SinkHealth};
use crate::stats::LoopStats;
use sar_drivers::{AxisDrives, ForceSensor};
use sar_estimator::cycle::TipOutcome;

/// The fixed-rate loop's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopConfig {
    /// Cycles per second (100..=10000).
    pub rate_hz: f64,
    /// The cycle period, ns.
    pub period_ns: u64,
    /// SCHED_FIFO priority of the loop thread (1..=99).
    pub priority: i32,
    /// The CPU the loop thread is pinned to, if any.
    pub cpu: Option<usize>,
    /// The publishing thread (the operator's commands and the published
    /// state) making no progress for this long while the loop hands it
    /// states is a Fault (`PublisherStalled`), ns.
    pub publisher_stall_ns: u64,
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

/// What a run hands each cycle to, besides the drives.
pub struct Edges<'a, K: Sink> {
    /// The sinks, in order (the recorder before the publisher).
    pub sinks: K,
    /// The simulator's truth, asked once per cycle (`None`: a real robot).
    pub truth: Option<SimTruthFn>,
    /// Fed after every cycle.
    pub watchdog: &'a mut Watchdog,
    /// Where overruns are told.
    pub log: &'a LogSender,
}

/// Runs the loop until a stop is requested; the drives are halted at the
/// end. Returns the sinks' last health.
pub fn run<S: ForceSensor, D: AxisDrives, K: Sink>(
    controller: &mut Controller<S, D>,
    config: &LoopConfig,
    limits: RunLimits,
    stats: &mut LoopStats,
    edges: Edges<'_, K>,
) -> SinkHealth {
    let Edges {
        mut sinks,
        mut truth,
        watchdog,
        log,
    } = edges;
    let mut health = SinkHealth::default();
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
        sinks.before_cycle();
        let out = *controller.step(cycle, rt::monotonic_ns);
        let truth_now = truth.as_mut().and_then(|f| f());
        sinks.cycle(&Cycle::of(controller, stats, truth_now), &mut health);
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
    health
}
