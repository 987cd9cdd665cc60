//! The control cycle allocates nothing: a counting global allocator around
//! many simulated cycles, with operator requests (reset, tare, moves), a Warn,
//! a Stop with its quick stop, a refused and an accepted reset.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use sar_daemon::control::{Controller, Envelope, Operator, Request};
use sar_daemon::{config, logq, sim};
use sar_drivers::SimClock;
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator, only counting.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The count is process-wide: the tests of this file run one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn a_cycle_allocates_nothing() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let cfg = config::builtin().unwrap();
    let mut scenario = sim::demo_scenario().unwrap();
    // Push on to the stop limit: 20 N along the rod at 12 s, then release at 20 s.
    scenario.spec.contact = common::contact_pulse(
        2_000_000_000,
        12_000_000_000,
        14_000_000_000,
        15_000_000_000,
        Vec3::new(20.0, 0.0, 0.0),
    );
    let clock = SimClock::new(1_000_000_000);
    let (_sim, sensor, drives, bias) = sim::simulated(&scenario, clock.clone()).unwrap();
    let operator = Operator::new();
    let (log, _thread, queue) = logq::channel(false);
    let mut c = Controller::new(
        &cfg.estimator,
        bias,
        cfg.step_config(),
        sensor,
        drives,
        operator.clone(),
        log,
        true,
    )
    .unwrap();
    // Warm-up: the first cycles (and the start-up reset) may touch lazily
    // made state in the simulator.
    let mut cycle = 0;
    let mut step = |c: &mut Controller<_, _>| {
        cycle += 1;
        clock.advance_ns(1_000_000);
        let now = clock.now_ns();
        let out = *c.step(cycle, || Some(now));
        while queue.pop().is_some() {}
        while operator.replies.pop().is_some() {}
        out
    };
    for _ in 0..500 {
        step(&mut c);
    }
    assert_eq!(
        c.output().guard_state,
        GuardState::Ok,
        "{:?}",
        c.output().guard_reason
    );

    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut seen_warn = false;
    let mut seen_stop = false;
    for i in 0..17_000u64 {
        if i % 1000 == 10 {
            let request = match (i / 1000) % 4 {
                0 => Request::Reset,
                1 => Request::Tare,
                2 => Request::SetLimits(c.decision().limits),
                _ => Request::MoveTip {
                    tip_m: Vec3::new(0.6, 0.2, 0.001),
                },
            };
            operator.requests.push(Envelope { id: i, request }).unwrap();
        }
        let out = step(&mut c);
        seen_warn |= out.guard_state == GuardState::Warn;
        seen_stop |= out.guard_state == GuardState::Stop;
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(seen_warn && seen_stop, "warn {seen_warn} stop {seen_stop}");
    assert!(c.counts().quick_stops >= 1);
    assert_eq!(
        after - before,
        0,
        "the cycles allocated {} times",
        after - before
    );
}

/// Publishing through iceoryx2 0.10 is NOT allocation-free: its
/// `Publisher::loan_uninit` (and `send_copy`, which uses it) puts each
/// sample's shared state in a new `SingleThreaded` Arc (48 bytes,
/// `ChunkMutSharedState::new`), one heap allocation per published sample.
/// Taking commands (an idle `Server::receive`), the event's `notify` and the
/// daemon's own code allocate nothing. This test pins that: exactly one
/// allocation per cycle, so that any other allocation on the path fails it.
#[test]
fn publishing_allocates_only_iceoryx2s_one_per_sample() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    use sar_daemon::runloop::{Publish, Published};
    use sar_daemon::shm::{Client, DaemonShm};
    use sar_daemon::stats::LoopStats;
    use sar_daemon::wire::limits_array;

    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let clock = SimClock::new(1_000_000_000);
    let (_sim, sensor, drives, bias) = sim::simulated(&scenario, clock.clone()).unwrap();
    let operator = Operator::new();
    let (log, _thread, queue) = logq::channel(false);
    let prefix = format!("sar-noalloc-{}", std::process::id());
    let mut shm = DaemonShm::create(
        &prefix,
        operator.clone(),
        limits_array(&cfg.estimator.guard.limits()),
        None,
    )
    .unwrap();
    let client = Client::new(&prefix).unwrap();
    let sub = client.subscribe().unwrap();
    let mut c = Controller::new(
        &cfg.estimator,
        bias,
        cfg.step_config(),
        sensor,
        drives,
        operator,
        log,
        true,
    )
    .unwrap();
    let stats = LoopStats::default();
    let mut cycle = 0;
    let mut run = |c: &mut Controller<_, _>, shm: &mut DaemonShm, n: u64| {
        for _ in 0..n {
            cycle += 1;
            clock.advance_ns(1_000_000);
            shm.before_cycle();
            let out = *c.step(cycle, || Some(clock.now_ns()));
            shm.publish(&Published {
                input: c.input(),
                loop_input: c.loop_input(),
                decision: c.decision(),
                output: &out,
                stats: &stats,
                drive_state: c.drive_state(),
                halted: c.halted(),
                quick_stops: c.counts().quick_stops,
                recorder_drops: 0,
                recording: false,
            });
            while queue.pop().is_some() {}
        }
    };
    run(&mut c, &mut shm, 200);
    let mut received = 0;
    sub.drain(|_| received += 1);
    assert!(received > 0);
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    run(&mut c, &mut shm, 2000);
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    // The subscriber is slow (it reads nothing meanwhile): the loop goes on.
    let mut late = 0;
    sub.drain(|_| late += 1);
    assert_eq!(late, sar_daemon::shm::STATE_BUFFER);
    assert_eq!(
        after - before,
        2000,
        "2000 published cycles allocated {} times (iceoryx2's loan: 2000)",
        after - before
    );
}
