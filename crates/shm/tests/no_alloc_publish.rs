//! The loop's whole per-cycle path allocates nothing, publishing included:
//! `Publish::before_cycle`, `Controller::step`, `Publish::publish` of the
//! daemon's real shared memory (`DaemonShm`), with a subscriber reading and
//! a client sending commands (reset, tare, a move, limits set and queried)
//! that the loop judges and answers meanwhile.
//!
//! The counting allocator counts only on a thread that asked for it, and the
//! loop thread asks only around the calls the real loop makes each cycle: the
//! client, the subscriber and the daemon's own publishing thread may allocate
//! (they are not on the loop's path); the loop may not.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config as config;
use sar_daemon::sim;
use sar_loop::control::{Controller, Operator, ReplyStatus};
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_loop::stats::LoopStats;
use sar_loop::{logq, rt};
use sar_msgs::wire::{CommandMsg, command_kind};
use sar_shm::{Client, DaemonShm};
use sar_test_support::rig::{RigBuilder, SimRig, controller};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use sar_test_support::counting::{Counting, allocations, counted};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The daemon's real shared memory with `cfg`'s limits, under a prefix of
/// this process and `name`: the prefix and the daemon's side.
fn daemon_shm(name: &str, operator: &Operator, cfg: &config::Config) -> (String, DaemonShm) {
    let prefix = format!("sar-noalloc-{name}-{}", std::process::id());
    let limits = cfg.estimator.guard.force_limits().to_array();
    let shm = DaemonShm::create(&prefix, operator.clone(), limits).unwrap();
    (prefix, shm)
}

#[test]
fn the_counter_sees_an_allocation_on_the_loop_thread() {
    let before = allocations();
    let v = counted(|| std::hint::black_box(vec![1u8; 48]));
    assert_eq!(v.len(), 48);
    assert!(allocations() > before);
}

#[test]
fn a_published_cycle_with_commands_allocates_nothing_on_the_loop_thread() {
    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let SimRig {
        mut c,
        clock,
        operator,
        queue,
        ..
    } = RigBuilder::new(&scenario).config(&cfg).build();
    let (prefix, mut shm) = daemon_shm("pub", &operator, &cfg);
    let stats = LoopStats::default();
    let mut cycle = 0u64;
    // One cycle exactly as `runloop::run` makes it; only the calls of the
    // loop's path are counted.
    let mut one = |c: &mut Controller<_, _>, shm: &mut DaemonShm| {
        cycle += 1;
        clock.advance_ns(1_000_000);
        counted(|| {
            shm.before_cycle();
            c.step(cycle, || Some(clock.now_ns()));
            shm.cycle(&Cycle::of(c, &stats, None), &mut SinkHealth::default());
        });
        while queue.pop().is_some() {}
    };
    // Warm-up (lazily made state in the simulator, the first samples).
    for _ in 0..200 {
        one(&mut c, &mut shm);
    }

    // A subscriber and a client in their own threads; the loop runs at 1 kHz
    // of real time (absolute deadlines, as sard) until the client has its
    // replies. Nothing here depends on the timing: the pacing only gives the
    // other threads time to work.
    let done = Arc::new(AtomicBool::new(false));
    let received = Arc::new(AtomicU64::new(0));
    let client_thread = {
        let (prefix, done, received) = (prefix.clone(), done.clone(), received.clone());
        std::thread::spawn(move || {
            let client = Client::new(&prefix).unwrap();
            let sub = client.subscribe().unwrap();
            let mut replies = Vec::new();
            // A move's tip (its three arguments), or the limits to set
            // (their six).
            let mut send = |kind: u32, limits_n: [f64; 6]| {
                let n = sub.wait(Duration::from_millis(100), |_| {});
                received.fetch_add(n as u64, Ordering::SeqCst);
                let mut args = [0.0; sar_msgs::command::COMMAND_ARGS];
                if kind == command_kind::SET_LIMITS {
                    args[..6].copy_from_slice(&limits_n);
                } else {
                    args[..3].copy_from_slice(&[0.6, 0.2, 0.001]);
                }
                let reply = client
                    .command(
                        CommandMsg {
                            kind,
                            id: replies.len() as u64 + 1,
                            args,
                            ..CommandMsg::default()
                        },
                        Duration::from_secs(10),
                    )
                    .unwrap();
                replies.push(reply);
                reply
            };
            let limits = send(command_kind::LIMITS, [0.0; 6]).limits_n;
            for kind in [
                command_kind::RESET,
                command_kind::TARE,
                command_kind::MOVE_TIP,
                command_kind::RESET,
            ] {
                send(kind, [0.0; 6]);
            }
            // Lowered limits: the reply and the next query carry them.
            let lowered = limits.map(|l| l * 0.9);
            send(command_kind::SET_LIMITS, lowered);
            send(command_kind::LIMITS, [0.0; 6]);
            let n = sub.wait(Duration::from_millis(100), |_| {});
            received.fetch_add(n as u64, Ordering::SeqCst);
            done.store(true, Ordering::SeqCst);
            replies
        })
    };
    let before = allocations();
    let mut next_ns = rt::monotonic_ns().unwrap();
    let mut cycles = 0u64;
    while !done.load(Ordering::SeqCst) {
        assert!(
            cycles < 60_000,
            "the client got no replies in 60 000 cycles"
        );
        next_ns += 1_000_000;
        rt::sleep_until_ns(next_ns);
        one(&mut c, &mut shm);
        cycles += 1;
    }
    let after = allocations();
    let replies = client_thread.join().unwrap();
    assert_eq!(replies.len(), 7);
    for (i, r) in replies.iter().enumerate() {
        assert_eq!(r.id, i as u64 + 1, "{r:?}");
    }
    // Judged by the loop (a cycle number) except the limits queries.
    assert!(replies[1..6].iter().all(|r| r.cycle > 0), "{replies:?}");
    let lowered = replies[0].limits_n.map(|l| l * 0.9);
    assert_eq!(
        replies[5].status,
        ReplyStatus::Accepted as u32,
        "{replies:?}"
    );
    assert_eq!(replies[5].limits_n, lowered);
    assert_eq!(replies[6].limits_n, lowered);
    assert!(received.load(Ordering::SeqCst) > 0, "no state received");
    assert_eq!(
        after - before,
        0,
        "{cycles} published cycles with 7 commands allocated {} times on the loop thread",
        after - before
    );
}

/// The same through `runloop::run` itself, the whole of it counted from its
/// first cycle to its return (stats, watchdog, overrun logging, the drives
/// halted at the end): at the configured rate on the monotonic clock, the
/// simulator on the same clock, a client's commands meanwhile; the client
/// ends the run (as a signal would) once it has its replies.
#[test]
fn the_run_loop_with_publishing_allocates_nothing_on_its_thread() {
    use sar_hal::MonotonicClock;
    use sar_loop::notify::Watchdog;
    use sar_loop::runloop::{self, Edges, RunLimits};

    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let (_sim, sensor, drives, bias) =
        sim::simulated(&scenario, MonotonicClock::new().unwrap()).unwrap();
    let operator = Operator::new();
    let (log, log_thread, _queue) = logq::channel(true);
    let (prefix, mut shm) = daemon_shm("run", &operator, &cfg);
    let mut c = controller(&cfg, bias, sensor, drives, operator, log.clone()).unwrap();
    let client_thread = {
        let prefix = prefix.clone();
        std::thread::spawn(move || {
            let client = Client::new(&prefix).unwrap();
            let sub = client.subscribe().unwrap();
            // The loop has run a while (start-up reset, first samples).
            let mut last = 0;
            let start = std::time::Instant::now();
            while last < 300 {
                if start.elapsed() > Duration::from_secs(60) {
                    rt::request_stop();
                    panic!("no state of cycle 300 within 60 s");
                }
                sub.wait(Duration::from_millis(100), |s| last = s.cycle);
            }
            let mut replies = Vec::new();
            // (A failed command stops the loop too, then fails the test.)
            for (id, kind) in [
                command_kind::LIMITS,
                command_kind::TARE,
                command_kind::RESET,
                command_kind::MOVE_TIP,
            ]
            .into_iter()
            .enumerate()
            {
                let reply = client.command(
                    CommandMsg {
                        kind,
                        id: id as u64 + 1,
                        args: [0.6, 0.2, 0.001, 0.0, 0.0, 0.0, 0.0, 0.0],
                        ..CommandMsg::default()
                    },
                    Duration::from_secs(10),
                );
                if reply.is_err() {
                    rt::request_stop();
                }
                replies.push(reply.unwrap());
            }
            rt::request_stop();
            replies
        })
    };
    let mut stats = LoopStats::default();
    let mut watchdog = Watchdog::new(None, 100);
    let before = allocations();
    counted(|| {
        runloop::run(
            &mut c,
            &sar_loop::time::RealTime,
            &cfg.loop_,
            RunLimits {
                max_cycles: Some(120_000),
                stall_after_cycles: None,
            },
            &mut stats,
            Edges {
                sinks: &mut shm,
                truth: None,
                watchdog: &mut watchdog,
                log: &log,
            },
        );
    });
    let after = allocations();
    let replies = client_thread.join().unwrap();
    if let Some(t) = log_thread {
        t.finish();
    }
    assert_eq!(replies.len(), 4);
    assert!(replies[1..].iter().all(|r| r.cycle > 0), "{replies:?}");
    assert!(stats.cycles > 300);
    assert_eq!(shm.publish_queue_drops(), 0);
    assert_eq!(
        after - before,
        0,
        "runloop::run of {} cycles allocated {} times on its thread",
        stats.cycles,
        after - before
    );
}
