//! The control cycle allocates nothing: a counting global allocator around
//! many simulated cycles, with operator requests (reset, tare, moves), a Warn,
//! a Stop with its quick stop, a refused and an accepted reset, every force
//! control mode (hold, position, push, guarded move), and the snapshots of
//! the decision state taken between cycles.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_estimator::Vec3;
use sar_estimator::force_control::ForceMode;
use sar_estimator::guard::GuardState;
use sar_loop::control::{Controller, Envelope, Request};
use sar_test_support::counting::{Counting, process_allocations};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The count is process-wide: the tests of this file run one at a time.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn a_cycle_allocates_nothing() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // Push on to the stop limit: 20 N along the rod at 12 s, then release at 20 s.
    let SimRig {
        mut c,
        clock,
        operator,
        queue,
        ..
    } = RigBuilder::demo(rod_push_20n([
        2_000_000_000,
        12_000_000_000,
        14_000_000_000,
        15_000_000_000,
    ]))
    .build();
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
    // The first reset needs the full mean at rest (500 samples: 1000 cycles).
    for _ in 0..1100 {
        step(&mut c);
    }
    assert_eq!(
        c.output().guard_state,
        GuardState::Ok,
        "{:?}",
        c.output().guard_reason
    );

    // The snapshot the loop takes between cycles (issue 17), made before.
    let mut snapshot = sar_snapshot::Snapshot::new();
    let mut snapshots = 0;
    let before = process_allocations();
    let mut seen_warn = false;
    let mut seen_stop = false;
    let mut seen_push = false;
    let mut seen_hold = false;
    let mut seen_back = false;
    let mut seen_excite = false;
    for i in 0..17_000u64 {
        if i % 1000 == 10 {
            let request = match (i / 1000) % 5 {
                0 => Request::Reset,
                4 => Request::Tare,
                2 => Request::SetLimits(c.decision().limits),
                3 => Request::MoveTip {
                    tip_m: Vec3::new(0.6, 0.2, 0.001),
                },
                // A guarded move along the rising contact force (+X0), its
                // limit 0.5 N above the filtered force now or just above
                // its noise (a limit within it is refused): reached on the
                // way (the contact rises 2 N/s; the move lasts 1.6 s), and
                // the move is braked.
                _ => Request::GuardedMove {
                    tip_m: Vec3::new(0.63, 0.2, 0.0),
                    max_force_n: c.output().filtered.map_or(2.0, |f| {
                        (f.force_n.norm() + 0.5)
                            .max(sar_loop::step::GUARDED_CONTACT_SIGMA * f.std_n.norm() + 0.1)
                    }),
                },
            };
            operator.requests.push(Envelope { id: i, request }).unwrap();
        }
        // Force control: a compliant hold, back to position mode, then a
        // push along the rod (ended by the move at 3010).
        let request = match i {
            400 => Some(Request::Hold { max_force_n: 5.0 }),
            700 => Some(Request::Position),
            1900 => Some(Request::Push { axial_n: 2.0 }),
            // The dynamic identification's excitation (issue 26), at rest
            // after the hold, ended before the contact.
            750 => Some(Request::Excite(sar_loop::excite::ExciteRequest {
                amplitude_m: [0.0002; 3],
                freq_hz: [3.0, 3.5, 2.5],
                duration_s: 0.25,
                fade_s: 0.12,
            })),
            _ => None,
        };
        if let Some(request) = request {
            operator.requests.push(Envelope { id: i, request }).unwrap();
        }
        let out = step(&mut c);
        seen_hold |= matches!(c.decision().force_mode, Some(ForceMode::Hold { .. }));
        seen_back |= i > 700 && i < 1000 && c.decision().force_mode.is_none();
        seen_excite |= i > 760
            && i < 880
            && matches!(c.decision().action, sar_loop::step::DriveAction::Stream(_));
        if i % 500 == 0 || c.decision().force_mode.is_some() && i % 50 == 0 {
            c.loop_step().snapshot(&mut snapshot).unwrap();
            snapshots += 1;
        }
        seen_push |= matches!(c.decision().force_mode, Some(ForceMode::Push { .. }));
        seen_warn |= out.guard_state == GuardState::Warn;
        seen_stop |= out.guard_state == GuardState::Stop;
    }
    let after = process_allocations();
    assert!(seen_warn && seen_stop, "warn {seen_warn} stop {seen_stop}");
    assert!(seen_push, "force control never ran");
    assert!(seen_excite, "the excitation never ran");
    assert!(
        seen_hold && seen_back,
        "hold {seen_hold}, position {seen_back}"
    );
    assert!(snapshots >= 34 && !snapshot.as_bytes().is_empty());
    assert!(
        c.decision().guarded_stop.is_some(),
        "no guarded move was braked: its path did not run"
    );
    assert!(c.counts().quick_stops >= 1);
    assert_eq!(
        after - before,
        0,
        "the cycles allocated {} times",
        after - before
    );
}

// Publishing (the loop's `Publish` calls on the daemon's shared memory) is
// proved allocation-free in `crates/shm/tests/no_alloc_publish.rs`.
