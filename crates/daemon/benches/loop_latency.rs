//! Wake-up latency of the daemon's loop at 1 kHz against a bare
//! `clock_nanosleep` loop with the same scheduling, side by side in one run
//! (3 s each; SCHED_FIFO and mlockall when permitted). Prints p50, p99, max
//! and the ratio of the p99s (goal: the daemon within 1.2x of the bare loop).
//! `cargo bench -p sar-daemon --bench loop_latency`

#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

mod support;

use sar_config as config;
use sar_daemon::sim;
use sar_hal::MonotonicClock;
use sar_loop::control::Operator;
use sar_loop::notify::Watchdog;
use sar_loop::runloop::{self, Edges, RunLimits};
use sar_loop::stats::{Histogram, LoopStats};
use sar_loop::{logq, rt};

const CYCLES: u64 = 3000;
const PERIOD_NS: u64 = 1_000_000;

fn bare() -> Histogram {
    let mut h = Histogram::default();
    let mut next = rt::monotonic_ns().unwrap() + PERIOD_NS;
    for _ in 0..CYCLES {
        rt::sleep_until_ns(next);
        let woke = rt::monotonic_ns().unwrap();
        h.record(woke.saturating_sub(next));
        next += PERIOD_NS;
    }
    h
}

fn daemon() -> LoopStats {
    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let (log, thread, _q) = logq::channel(true);
    let clock = MonotonicClock::new().unwrap();
    let (_sim, mut c, _bias) =
        support::sim_controller(&cfg, &scenario, clock, Operator::new(), log.clone());
    let mut stats = LoopStats::default();
    runloop::run(
        &mut c,
        &sar_loop::time::RealTime,
        &cfg.loop_,
        RunLimits {
            max_cycles: Some(CYCLES),
            stall_after_cycles: None,
        },
        &mut stats,
        Edges {
            sinks: (),
            truth: None,
            watchdog: &mut Watchdog::new(None, 100),
            log: &log,
        },
    );
    if let Some(t) = thread {
        t.finish();
    }
    stats
}

fn line(name: &str, h: &Histogram) {
    println!(
        "{name:>28}: p50 {:>6} ns  p99 {:>8} ns  max {:>9} ns  ({} cycles)",
        h.quantile_ns(0.5),
        h.quantile_ns(0.99),
        h.max_ns(),
        h.count()
    );
}

fn main() {
    let fifo = rt::set_fifo(80).is_ok();
    let locked = rt::lock_memory().is_ok();
    println!("SCHED_FIFO 80: {fifo}, mlockall: {locked}; 1 kHz, {CYCLES} cycles each");
    let b = bare();
    let d = daemon();
    line("bare clock_nanosleep loop", &b);
    line("sard loop (with simulator)", &d.wakeup);
    line("sard compute per cycle", &d.compute);
    println!(
        "wake-up p99 ratio sard / bare: {:.2}; overruns {}",
        d.wakeup.quantile_ns(0.99) as f64 / b.quantile_ns(0.99).max(1) as f64,
        d.overruns
    );
}
