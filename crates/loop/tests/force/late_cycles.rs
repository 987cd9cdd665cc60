//! A late cycle is an input, not a fault (issue 33): on the plant in motion
//! (the rod's inertia, servos of 30 Hz and 0.7, a 2 m/s^2 quick stop; the
//! HEX-6's noise), through the same controller as `sard --sim`, one cycle
//! comes late (the simulator runs on meanwhile) during each motion the loop
//! commands: a planned move, a guarded move's streamed brake, push, hold, an
//! excitation and a back-out in Retreat. Within the inputs' accepted age
//! (the demo's 50 ms; a robot's 10 ms with its counter gap of 3) the motion
//! carries on: no Stop or Fault, no drive refusal, no streamed set point
//! further from the last than the drives' speed allows over a period, the
//! estimate's error within a few of its standard deviations; a stall beyond
//! the age faults (`cycle_gap`), and once the axes are at rest a reset is
//! accepted, whatever the motion was. Every run replays bit for bit.

use crate::rig::{Plant, Rig, TIP_M, tissue};
use sar_config as config;
use sar_estimator::Vec3;
use sar_estimator::cycle::TipOutcome;
use sar_estimator::guard::{GuardState, Reason};
use sar_loop::control::{ReplyStatus, Request};
use sar_loop::excite::ExciteRequest;
use sar_loop::step::{DriveAction, LoopOutput};
use sar_sim::ContactKey;

/// The motions a late cycle may fall into.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    /// `move-tip` (the drives' own planner after one set point).
    Move,
    /// `move-tip --max-force 3` into 3000 N/m: the late cycle in its
    /// streamed brake.
    GuardedBrake,
    /// `push --axial 3` into 1000 N/m, breathing.
    Push,
    /// `hold --max-force 5` against 1000 N/m, breathing.
    Hold,
    /// The dynamic identification's excitation.
    Excite,
    /// A back-out in Retreat (streamed at the retreat speed).
    Retreat,
}

const MOTIONS: [Motion; 6] = [
    Motion::Move,
    Motion::GuardedBrake,
    Motion::Push,
    Motion::Hold,
    Motion::Excite,
    Motion::Retreat,
];

/// 20 N along the rod (+X0), scripted at the tip from 0.3 s after the rig
/// is ready, for 30 s: a Stop whose force persists (Retreat after a reset).
fn persisting_push() -> Vec<ContactKey> {
    let at = |ms: u64| 1_000_000_000 + (crate::rig::READY_MS + ms) * 1_000_000;
    sar_test_support::messages::contact_pulse(
        at(300),
        at(400),
        at(30_000),
        at(30_100),
        Vec3::new(20.0, 0.0, 0.0),
    )
}

/// The rig for `motion` on the plant in motion with `cfg`, the motion
/// started and under way: the cycles to its interesting part run.
fn under_way(motion: Motion, cfg: &config::Config) -> Rig {
    let (tissues, contact) = match motion {
        Motion::Move | Motion::Excite => (Vec::new(), Vec::new()),
        Motion::GuardedBrake => (vec![tissue(3000.0, 0.005, 0.0, Vec::new())], Vec::new()),
        Motion::Push | Motion::Hold => (vec![tissue(1000.0, 0.005, 0.002, Vec::new())], Vec::new()),
        Motion::Retreat => (Vec::new(), persisting_push()),
    };
    let mut rig = Rig::with_config(tissues, contact, Plant::Moving, cfg);
    let tip = Vec3::new(TIP_M[0], TIP_M[1], TIP_M[2]);
    let request = match motion {
        Motion::Move => Request::MoveTip {
            tip_m: tip + Vec3::new(0.0, 0.01, 0.01),
        },
        Motion::GuardedBrake => Request::GuardedMove {
            tip_m: tip + Vec3::new(0.015, 0.0, 0.0),
            max_force_n: 3.0,
        },
        Motion::Push => Request::Push { axial_n: 3.0 },
        Motion::Hold => Request::Hold { max_force_n: 5.0 },
        // q3 sweeps +-25 mm slowly (0.12 Hz: 19 mm/s), q1 and q2 fast
        // and small: 2.5 s in, q3 is 22 mm from the centre.
        Motion::Excite => Request::Excite(ExciteRequest {
            amplitude_m: [0.002, 0.0015, 0.025],
            freq_hz: [1.3, 1.7, 0.12],
            duration_s: 10.0,
            fade_s: 3.0,
        }),
        Motion::Retreat => {
            rig.until(2000, |d| d.estimate.guard_state == GuardState::Stop)
                .expect("never stopped");
            rig.until(300, |_| false);
            let r = rig.request(90, Request::Reset);
            assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
            assert_eq!(rig.c.output().guard_state, GuardState::Retreat);
            rig.until(50, |_| false);
            Request::BackOut { distance_m: 0.01 }
        }
    };
    let r = rig.request(1, request);
    assert_eq!(r.status, ReplyStatus::Accepted, "{motion:?}: {}", r.detail);
    match motion {
        // Into the brake (streamed from its first cycle).
        Motion::GuardedBrake => {
            rig.until(4000, |d| d.guarded_stop.is_some())
                .expect("never braked");
        }
        // Settled in contact.
        Motion::Push | Motion::Hold => {
            rig.until(3000, |_| false);
        }
        // Cruising.
        Motion::Move | Motion::Retreat => {
            rig.until(1500, |_| false);
        }
        // Far from the centre.
        Motion::Excite => {
            rig.until(2500, |_| false);
        }
    }
    rig
}

/// What a run after a late cycle showed.
#[derive(Debug, Default)]
struct AfterLate {
    /// The largest distance of a streamed set point from the previous one
    /// on any axis, m.
    largest_step_m: f64,
    /// The largest error of the estimate against the truth in its own
    /// standard deviations, any axis, new samples only.
    worst_sigma: f64,
    /// Cycles that streamed.
    streamed: usize,
}

/// Runs `cycles` cycles from the late one on, checking each: no halting
/// state, no drive error; the figures.
fn run_after(rig: &mut Rig, motion: Motion, cycles: usize) -> AfterLate {
    let mut out = AfterLate::default();
    let mut last_set: Option<[f64; 3]> = rig.log.iter().rev().find_map(|(_, d)| match d.action {
        DriveAction::Stream(q) => Some([q.q1_m, q.q2_m, q.q3_m]),
        _ => None,
    });
    let mut last_counter = rig.c.loop_input().sensor.counter;
    let mut check = |rig: &Rig, d: &LoopOutput| {
        assert!(
            !d.estimate.guard_state.is_halting(),
            "{motion:?}: {:?}",
            d.estimate.guard_reason
        );
        assert_eq!(rig.c.counts().drive_errors, 0, "{motion:?}");
        match d.action {
            DriveAction::Stream(q) => {
                let q = [q.q1_m, q.q2_m, q.q3_m];
                if let Some(p) = last_set {
                    for (a, b) in q.iter().zip(p) {
                        out.largest_step_m = out.largest_step_m.max((a - b).abs());
                    }
                }
                last_set = Some(q);
                out.streamed += 1;
            }
            _ => last_set = None,
        }
        let counter = rig.c.loop_input().sensor.counter;
        if counter != last_counter
            && let TipOutcome::Estimate(e) = d.estimate.tip
        {
            let err = e.force_n - rig.true_force_n();
            for (x, s) in err.iter().zip(e.std_n.iter()) {
                out.worst_sigma = out.worst_sigma.max(x.abs() / s);
            }
        }
        last_counter = counter;
    };
    let d = *rig.c.decision();
    check(rig, &d);
    for _ in 0..cycles {
        let d = rig.step();
        check(rig, &d);
    }
    out
}

/// The built-in configuration with a robot's input ages (10 ms) and
/// counter gap (3).
fn robot_ages() -> config::Config {
    let text = config::DEFAULT_TOML
        .replace(
            "max_sensor_age_s = 0.05                # DEMO (default 0.01)",
            "max_sensor_age_s = 0.01",
        )
        .replace(
            "max_joints_age_s = 0.05                # DEMO (default 0.01)",
            "max_joints_age_s = 0.01",
        )
        .replace(
            "max_counter_gap = 25                   # DEMO (default 3)",
            "max_counter_gap = 3",
        );
    assert_ne!(text, config::DEFAULT_TOML);
    config::parse(&text, "robot ages").unwrap()
}

#[test]
fn a_late_cycle_within_the_ages_is_carried_on_in_every_motion() {
    let demo = config::builtin().unwrap();
    let robot = robot_ages();
    // (configuration, name, how late the cycle comes: the period and more).
    let cases = [
        (&demo, "demo (50 ms)", 9_600_000u64),
        (&demo, "demo (50 ms)", 49_000_000),
        (&robot, "robot (10 ms, gap 3)", 9_000_000),
    ];
    for motion in MOTIONS {
        for (cfg, name, dt_ns) in cases {
            let mut rig = under_way(motion, cfg);
            let before = rig.c.counts();
            let d = rig.step_after(dt_ns);
            assert!(
                !d.estimate.guard_state.is_halting(),
                "{motion:?}, {name}, {dt_ns} ns: {:?}",
                d.estimate.guard_reason
            );
            let after = run_after(&mut rig, motion, 1500);
            let reach_m = cfg.axes.max_speed_mps * 1e-3;
            println!(
                "late cycle ({} ms after the last) in {motion:?}, {name}: largest streamed step {:.1} um (the drives' reach {:.1} um), estimate within {:.2} sigma of the truth, {} set points streamed after",
                dt_ns as f64 * 1e-6,
                after.largest_step_m * 1e6,
                reach_m * 1e6,
                after.worst_sigma,
                after.streamed
            );
            assert_eq!(rig.c.counts().drive_errors, before.drive_errors);
            assert!(
                after.largest_step_m <= reach_m * (1.0 + 1e-9),
                "{motion:?}: a streamed step of {} m",
                after.largest_step_m
            );
            assert!(after.worst_sigma < 6.0, "{motion:?}: {}", after.worst_sigma);
            rig.replays_bit_for_bit();
        }
    }
}

/// A stall beyond the accepted age (the demo's 50 ms) during each motion:
/// Fault (`cycle_gap`) and the drives' quick stop; once the axes are at
/// rest the reset is accepted (not refused by a reference the axes never
/// followed), and Ok again, or Retreat while the force persists.
#[test]
fn after_a_stall_in_any_motion_a_reset_is_accepted_at_rest() {
    let demo = config::builtin().unwrap();
    for motion in MOTIONS {
        for stall_ns in [120_000_000u64, 1_000_000_000] {
            let mut rig = under_way(motion, &demo);
            let d = rig.step_after(stall_ns);
            assert_eq!(d.estimate.guard_state, GuardState::Fault, "{motion:?}");
            assert!(
                matches!(d.estimate.guard_reason, Reason::CycleGap { .. }),
                "{motion:?}: {:?}",
                d.estimate.guard_reason
            );
            assert_eq!(d.action, DriveAction::QuickStop, "{motion:?}");
            // The drives brake to rest (from 40 mm/s at 2 m/s^2: 20 ms).
            rig.until(300, |_| false);
            let r = rig.request(2, Request::Reset);
            assert_eq!(
                r.status,
                ReplyStatus::Accepted,
                "{motion:?}, stall {} ms: {}",
                stall_ns / 1_000_000,
                r.detail
            );
            let wanted = if motion == Motion::Retreat {
                GuardState::Retreat
            } else {
                GuardState::Ok
            };
            assert_eq!(rig.c.output().guard_state, wanted, "{motion:?}");
            // And it holds there.
            let settled = rig.until(500, |d| d.estimate.guard_state != wanted);
            assert!(settled.is_none(), "{motion:?}: {settled:?}");
            println!(
                "stall of {} ms in {motion:?}: Fault ({}), reset accepted at rest",
                stall_ns / 1_000_000,
                d.estimate.guard_reason
            );
            rig.replays_bit_for_bit();
        }
    }
}
