//! The control cycle allocates nothing: a counting global allocator around
//! many simulated cycles, with operator requests (reset, tare, moves), a Warn,
//! a Stop with its quick stop, a refused and an accepted reset, every force
//! control mode (hold, position, push, guarded move), and the snapshots of
//! the decision state taken between cycles; and on plants that are not the
//! model (issue 34), the paths the demo's matched plant never takes: the
//! servo observer engaged and the mismatch named, the inertia watch naming
//! the rod and the adapter, the support watch naming a shift.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_estimator::Vec3;
use sar_estimator::force_control::ForceMode;
use sar_estimator::guard::GuardState;
use sar_loop::control::{Controller, Envelope, Request};
use sar_test_support::counting::{Counting, process_allocations};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};

#[path = "force/rig.rs"]
mod rig;

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

/// The demo's plant in motion, changed by `edit`, no tissue and no
/// contact, running `cfg` (the simulated drives at its profile); ready.
fn mismatched(cfg: &sar_config::Config, edit: impl FnOnce(&mut sar_sim::SimSpec)) -> rig::Rig {
    let mut scenario = sar_daemon::sim::demo_scenario().unwrap();
    let spec = &mut scenario.spec;
    spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
    spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
    spec.contact = vec![sar_sim::ContactKey {
        t_ns: 0,
        force_n: Vec3::zeros(),
    }];
    spec.tissue = Vec::new();
    spec.plant = rig::Plant::Moving.spec(spec);
    edit(spec);
    let mut rig = rig::Rig(RigBuilder::new(&scenario).config(cfg).build());
    for _ in 0..rig::READY_MS {
        rig.step();
    }
    assert_eq!(rig.c.output().guard_state, GuardState::Ok);
    // Room for every cycle below: the rig's own log does not allocate in
    // the counted window.
    rig.log.reserve(40_000);
    rig
}

/// What the counted cycles showed.
#[derive(Default)]
struct Named {
    engaged: bool,
    servo: bool,
    inertia: bool,
    support: bool,
}

/// Steps `rig` `cycles` times, draining its log, noting what was named.
fn run(rig: &mut rig::Rig, cycles: u32, named: &mut Named) {
    for _ in 0..cycles {
        let d = rig.step();
        named.engaged |= d.servo_fit.engaged.iter().any(|&e| e);
        named.support |= d.support.verdict == sar_estimator::support::SupportVerdict::Shifted;
        while let Some(event) = rig.queue.pop() {
            match event {
                sar_loop::logq::LogEvent::ServoMismatch { .. } => named.servo = true,
                sar_loop::logq::LogEvent::InertiaNamed { .. } => named.inertia = true,
                _ => {}
            }
        }
        while rig.operator.replies.pop().is_some() {}
    }
}

/// A move of the tip to `tip_m` (accepted), then `cycles` cycles.
fn move_tip(rig: &mut rig::Rig, id: u64, tip_m: Vec3, cycles: u32, named: &mut Named) {
    rig.operator
        .requests
        .push(Envelope {
            id,
            request: Request::MoveTip { tip_m },
        })
        .unwrap();
    run(rig, cycles, named);
}

#[test]
fn the_observer_and_the_watches_allocate_nothing_when_they_name() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // The free moves of `plant_mismatch` (50 mm/s, 1 m/s^2).
    let mut fast = sar_config::builtin().unwrap();
    fast.axes.max_speed_mps = 0.05;
    fast.axes.max_accel_mps2 = 1.0;
    fast.axes.following_tolerance_m = 0.002;
    let mut servo = mismatched(&fast, |s| {
        let servo = s.plant.servo.unwrap();
        s.plant.servo = Some(sar_sim::ServoSpec {
            bandwidth_hz: 12.0,
            damping: 0.45,
            ..servo
        });
    });
    let mut rod = mismatched(&fast, |s| {
        let rod = s.plant.inertia.unwrap();
        s.plant.inertia = Some(sar_sim::RodInertia {
            inertia_perp_kgm2: 1.6 * rod.inertia_perp_kgm2,
            adapter_mass_kg: 0.35,
            ..rod
        });
    });
    // The support 10 mm up from 1.3 s, then the check's poses at the
    // built-in speed (`support_watch`).
    let builtin = sar_config::builtin().unwrap();
    let mut support = mismatched(&builtin, |s| {
        s.friction_n = 0.3;
        s.support_shifts = vec![sar_sim::SupportShift {
            t_ns: 1_300_000_000,
            shift_m: Vec3::new(0.0, 0.01, 0.0),
            duration_ns: 500_000_000,
        }];
    });
    let start = Vec3::new(rig::TIP_M[0], rig::TIP_M[1], rig::TIP_M[2]);
    let free = [
        start + Vec3::new(0.03, 0.015, -0.015),
        start + Vec3::new(-0.01, -0.02, 0.02),
        start,
    ];

    let before = process_allocations();
    let mut named = Named::default();
    for (id, tip_m) in (1..).zip(free) {
        move_tip(&mut servo, id, tip_m, 1500, &mut named);
    }
    let servo_named = (named.engaged, named.servo);
    let mut named = Named::default();
    for (id, tip_m) in (1..).zip(free) {
        move_tip(&mut rod, id, tip_m, 1500, &mut named);
    }
    let inertia_named = named.inertia;
    let mut named = Named::default();
    run(&mut support, 1300, &mut named);
    for (id, off) in (1..).zip(sar_loop::step::SUPPORT_CHECK_OFFSETS_M) {
        let tip_m = start + Vec3::new(off[0], off[1], off[2]);
        // Each pose reached, then held 0.3 s (as the check's moves).
        move_tip(&mut support, id, tip_m, 1, &mut named);
        for _ in 0..4000 {
            run(&mut support, 1, &mut named);
            let last = support
                .log
                .last()
                .map(|(_, d)| (d.reference, d.estimate.pose));
            if let Some((Some(_), Some(pose))) = last
                && (pose.tip_m - tip_m).norm() < 2e-4
            {
                break;
            }
        }
        run(&mut support, 300, &mut named);
    }
    let after = process_allocations();

    assert_eq!(servo_named, (true, true), "(observer engaged, servo named)");
    assert!(inertia_named, "the inertia watch named nothing");
    assert!(named.support, "the support watch named no shift");
    assert_eq!(
        after - before,
        0,
        "the cycles allocated {} times",
        after - before
    );
}
