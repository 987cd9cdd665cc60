//! The fixed-rate loop: absolute deadlines on its clock ([`crate::time`]:
//! the monotonic clock's `clock_nanosleep`, `TIMER_ABSTIME`, never "sleep
//! for the period"; or simulated time), one
//! [`Controller::step`] per deadline, then the cycle handed to the sinks
//! ([`crate::sink`]). Every cycle is measured
//! (wake-up latency, compute time) into fixed-size histograms; a cycle that
//! ends after the next deadline is an overrun, counted and logged (one line,
//! with the periods skipped), and the next cycle runs at once; the periods
//! that passed entirely meanwhile (a stall) are skipped and counted, never
//! run back to back ([`next_deadline`]; the grid is kept, the cycle numbers
//! stay consecutive: a skipped period is no cycle). Ends on a stop signal
//! (`rt::STOP_SIGNALS`, or after `max_cycles`) with the drives halted.

use crate::control::{Controller, CycleTime};
use crate::logq::{LogEvent, LogSender};
use crate::notify::Watchdog;
use crate::publish::SimTruthFn;
use crate::rt;
use crate::sink::{Cycle, Sink, SinkHealth};
use crate::stats::LoopStats;
use crate::time::LoopClock;
use sar_estimator::cycle::TipOutcome;
use sar_hal::{AxisDrives, ForceSensor};

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

/// The next deadline after a cycle ([`next_deadline`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NextDeadline {
    /// When the next cycle runs, ns (on the grid of the first deadline).
    pub deadline_ns: u64,
    /// How far the cycle ended after the deadline that followed its own,
    /// ns (0: no overrun).
    pub late_ns: u64,
    /// Whole periods that passed entirely after that deadline: skipped,
    /// never run.
    pub skipped: u64,
}

/// The deadline after a cycle whose deadline was `deadline_ns` and which
/// ended at `end_ns`: the next point of the grid (`deadline_ns + period`).
/// A cycle that ended after it is an overrun: the next cycle runs at once
/// (late by less than a period), and the periods that passed entirely
/// since (a stall: SIGSTOP, a late wake-up, a stalled device call) are
/// skipped, counted in `skipped`, never run back to back; the grid is kept.
/// Integer arithmetic only (no allocation, no panic; saturating).
pub fn next_deadline(deadline_ns: u64, period_ns: u64, end_ns: u64) -> NextDeadline {
    let next_ns = deadline_ns.saturating_add(period_ns);
    if end_ns <= next_ns {
        return NextDeadline {
            deadline_ns: next_ns,
            late_ns: 0,
            skipped: 0,
        };
    }
    let late_ns = end_ns - next_ns;
    let skipped = late_ns.checked_div(period_ns).unwrap_or(0);
    NextDeadline {
        deadline_ns: next_ns.saturating_add(skipped.saturating_mul(period_ns)),
        late_ns,
        skipped,
    }
}

/// Runs the loop on `clock` until a stop is requested; the drives are
/// halted at the end. Returns the sinks' last health.
///
/// On a simulated clock ([`LoopClock::simulated`]) a cycle takes no
/// simulated time (no overrun, no wake-up latency), and the loop waits for
/// its sinks' room before each cycle ([`Sink::has_room`]) instead of letting
/// them drop: waiting costs no simulated time.
pub fn run<S: ForceSensor, D: AxisDrives, K: Sink, C: LoopClock>(
    controller: &mut Controller<S, D>,
    clock: &C,
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
    let mut next_ns = clock.now_ns().unwrap_or(0).saturating_add(period_ns);
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
        if clock.simulated() {
            wait_for_room(&sinks);
        }
        clock.sleep_until_ns(next_ns);
        if rt::stop_requested() {
            break;
        }
        let woke = clock.now_ns();
        let woke_ns = woke.unwrap_or(next_ns);
        stats.wakeup.record(woke_ns.saturating_sub(next_ns));
        cycle += 1;
        sinks.before_cycle();
        let out = *controller.step(cycle, || cycle_time(clock));
        let truth_now = truth.as_mut().and_then(|f| f());
        sinks.cycle(&Cycle::of(controller, stats, truth_now), &mut health);
        // The watchdog is fed from here, the loop itself: a stuck loop stops
        // feeding it.
        let estimate = matches!(out.tip, TipOutcome::Estimate(_));
        watchdog.after_cycle(cycle, out.guard_state, &out.guard_reason, estimate);
        let end_ns = clock.now_ns().unwrap_or(woke_ns);
        stats.compute.record(end_ns.saturating_sub(woke_ns));
        stats.cycles = cycle;
        let grid = next_deadline(next_ns, period_ns, end_ns);
        next_ns = grid.deadline_ns;
        count_overrun(&grid, cycle, stats, log);
    }
    watchdog.stopping();
    controller.shutdown();
    health
}

/// The cycle's time on `clock`: one reading in real time (the loop's clock
/// is the host's), the host's own beside a simulated one.
fn cycle_time<C: LoopClock>(clock: &C) -> CycleTime {
    let now_ns = clock.now_ns();
    CycleTime {
        now_ns,
        host_ns: if clock.simulated() {
            clock.host_ns()
        } else {
            now_ns
        },
    }
}

/// An overrun (`grid.late_ns > 0`) counted and told in one log line.
fn count_overrun(grid: &NextDeadline, cycle: u64, stats: &mut LoopStats, log: &LogSender) {
    if grid.late_ns > 0 {
        stats.overruns += 1;
        stats.skipped_periods = stats.skipped_periods.saturating_add(grid.skipped);
        stats.note_overrun(cycle);
        log.send(LogEvent::Overrun {
            cycle,
            late_ns: grid.late_ns,
            skipped: grid.skipped,
        });
    }
}

/// Waits (in real time, a simulated clock standing still) until every
/// sink has room for a cycle, or a stop is requested.
fn wait_for_room<K: Sink>(sinks: &K) {
    while !sinks.has_room() && !rt::stop_requested() {
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: u64 = 1_000_000;

    #[test]
    fn on_time_the_next_deadline_is_one_period_on() {
        let d = next_deadline(5 * P, P, 5 * P + 300_000);
        assert_eq!(
            d,
            NextDeadline {
                deadline_ns: 6 * P,
                late_ns: 0,
                skipped: 0
            }
        );
        // Ending exactly at the next deadline is not an overrun.
        assert_eq!(next_deadline(5 * P, P, 6 * P).late_ns, 0);
    }

    #[test]
    fn an_overrun_of_less_than_a_period_runs_the_next_cycle_at_once() {
        let d = next_deadline(5 * P, P, 6 * P + 400_000);
        assert_eq!(d.deadline_ns, 6 * P);
        assert_eq!((d.late_ns, d.skipped), (400_000, 0));
    }

    /// A stall of 4.16 s (SIGSTOP, SIGCONT) at 1 kHz: 4159 whole periods
    /// skipped, one cycle at once on the grid, then on time again. The old
    /// runner ran them back to back (4160 cycles in 130 ms).
    #[test]
    fn a_stall_skips_the_whole_periods_and_keeps_the_grid() {
        let start = 1_000 * P;
        let end = start + 4_160 * P + 250_000;
        let d = next_deadline(start, P, end);
        assert_eq!(d.skipped, 4_159);
        assert_eq!(d.late_ns, 4_159 * P + 250_000);
        assert_eq!(d.deadline_ns, start + 4_160 * P);
        assert!(d.deadline_ns <= end && end - d.deadline_ns < P);
        // The cycle run at once ends in time for the next grid point.
        let after = next_deadline(d.deadline_ns, P, end + 100_000);
        assert_eq!((after.late_ns, after.skipped), (0, 0));
        assert_eq!(after.deadline_ns, start + 4_161 * P);
    }

    #[test]
    fn extreme_values_saturate_and_never_panic() {
        let d = next_deadline(u64::MAX - 10, P, u64::MAX);
        assert_eq!(d.deadline_ns, u64::MAX);
        assert_eq!(next_deadline(0, 0, 5).skipped, 0);
        let d = next_deadline(0, P, u64::MAX);
        assert_eq!(d.skipped, (u64::MAX - P) / P);
        assert!(d.deadline_ns > u64::MAX - P);
    }
}
