//! Issue 15's property: no mode (position, guarded move, push, hold,
//! retreat) ever commands a motion deeper along a tip force above the warn
//! limit.
//!
//! "Deeper" (FORCE_CONTROL.md, MODEL.md 4): F_tip is what the tip applies to
//! the tissue, so moving the tip along +F_tip pushes deeper and raises the
//! force; a motion is deeper when its dot product with F_tip is > 0. The
//! force judged is the one the guard and the move rules judge: the cycle's
//! tip-force estimate (`TipOutcome::Estimate`), in the cycles in which the
//! guard reports it above a warn limit (Warn for a force, after its
//! debounce; Retreat, which is above the stop limit).
//!
//! Generated cases (seeded: deterministic) drive the pure step through the
//! real controller on the simulator: a mode, its set point, a tissue of 0,
//! 300 or 3000 N/m along the rod, and a scripted tip contact in any
//! direction rising above the warn limit (in Retreat above the stop limit,
//! then a reset), with moves asked for along and against the force while it
//! lasts. In every such cycle:
//! - force control's streamed set point (push, hold) moves the commanded
//!   tip (the forward kinematics of the set points) not along the force
//!   (within 1 nm per period, the kinematics' rounding; a period's motion is
//!   up to 6 um);
//! - a streamed move in Retreat is judged as a whole when it is accepted
//!   (below); its periods that lean along the force are counted and
//!   printed, not asserted: a back-out along the rod is accepted whatever
//!   the sign of the axial force (issue 14's `reduces_force`), and the
//!   axes' own time-optimal profiles bend the path;
//! - a move accepted in Warn does not go along the force, in Retreat it
//!   reduces it;
//! - a move under way that goes deeper is braked in the first such cycle,
//!   and every end point given then lies within the braking distance of
//!   the commanded trajectory (v^2 / 2a per axis, plus the motion until the
//!   cycle's time);
//! - force control does not start.
//!
//! It fails if the law's Warn rule is flipped or removed (checked by hand:
//! FORCE_CONTROL.md).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use crate::rig::{READY_MS, Rig, TIP_M, tissue};
use proptest::prelude::*;
use proptest::test_runner::{Config as ProptestConfig, RngSeed, TestRunner};
use sar_estimator::Vec3;
use sar_estimator::cycle::TipOutcome;
use sar_estimator::guard::{GuardState, Reason, reduces_force};
use sar_kinematics::{ActiveJoints, forward};
use sar_loop::control::{ReplyStatus, Request};
use sar_loop::step::DriveAction;

/// What the case asks for when the contact comes.
#[derive(Debug, Clone, Copy)]
enum Mode {
    /// A move of the tip by this much (position control).
    Position(Vec3),
    /// A guarded move by this much with this limit, N.
    Guarded(Vec3, f64),
    /// `push --axial N`.
    Push(f64),
    /// `hold --max-force N`.
    Hold(f64),
    /// A contact above the stop limit, a reset into Retreat, then moves.
    Retreat,
}

fn mode() -> impl Strategy<Value = Mode> {
    let offset = (-0.015..0.015f64, -0.015..0.015f64, -0.015..0.015f64)
        .prop_map(|(x, y, z)| Vec3::new(x, y, z));
    prop_oneof![
        offset.clone().prop_map(Mode::Position),
        (offset, 2.0..15.0f64).prop_map(|(o, n)| Mode::Guarded(o, n)),
        (0.5..7.5f64).prop_map(Mode::Push),
        (0.5..9.5f64).prop_map(Mode::Hold),
        Just(Mode::Retreat),
    ]
}

/// A unit vector from two uniform numbers (uniform on the sphere).
fn direction(z: f64, phi: f64) -> Vec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

#[derive(Debug, Default)]
struct Counts {
    checked_cycles: u64,
    streamed: u64,
    force_streamed: u64,
    back_out_periods_along: u64,
    move_periods_along: u64,
    move_along_max_m: f64,
    brakes: u64,
    warn_moves: u64,
}

/// The commanded tip of joint set points, m.
fn tip_of(rig: &Rig, q: &ActiveJoints) -> Vec3 {
    let e = &rig.cfg.estimator;
    forward(&e.calibration, &e.profile, q).unwrap().tip_m
}

fn run(mode: Mode, force: Vec3, k_n_per_m: f64, ramp_ms: u64, hold_ms: u64, seed: u64) -> Counts {
    let start_ns = (READY_MS + 100) * 1_000_000;
    let on_ns = start_ns + ramp_ms * 1_000_000;
    let off_ns = on_ns + hold_ms * 1_000_000;
    let contact = sar_test_support::messages::contact_pulse(
        start_ns,
        on_ns,
        off_ns,
        off_ns + 300_000_000,
        force,
    );
    let tissues = if k_n_per_m > 0.0 {
        vec![tissue(k_n_per_m, 0.003, 0.0, Vec::new())]
    } else {
        Vec::new()
    };
    let mut rig = Rig::with(tissues, contact);
    let limits = rig.c.decision().limits;
    let tip0 = Vec3::new(TIP_M[0], TIP_M[1], TIP_M[2]);
    let first = match mode {
        Mode::Position(o) => Some(Request::MoveTip { tip_m: tip0 + o }),
        Mode::Guarded(o, n) => Some(Request::GuardedMove {
            tip_m: tip0 + o,
            max_force_n: n.min(limits.stop_total_n),
        }),
        Mode::Push(n) => Some(Request::Push { axial_n: n }),
        Mode::Hold(n) => Some(Request::Hold { max_force_n: n }),
        Mode::Retreat => None,
    };
    let mut c = Counts::default();
    // The last streamed set point (of the previous cycle), the accepted
    // move under way (its tip target and end point) and the last reference
    // with its joint stamp.
    let mut last_stream: Option<ActiveJoints> = None;
    let mut under_way: Option<(Vec3, ActiveJoints)> = None;
    let mut last_ref: Option<(ActiveJoints, u64)> = None;
    let mut id = 0u64;
    let total_ms = 100 + ramp_ms + hold_ms + 600;
    // In push and hold, moves (which end the mode) come late.
    let force_mode = matches!(mode, Mode::Push(_) | Mode::Hold(_));
    for t in 0..total_ms {
        let out = rig.c.decision().estimate;
        // The request of this cycle.
        let request = if t == 5 {
            first
        } else if t % 41 == 0 && t > 50 && (!force_mode || t > 100 + ramp_ms + hold_ms / 2) {
            let s = sar_test_support::messages::mix(seed ^ t);
            let r = |k: u64| unit(s ^ k);
            match (mode, out.guard_state, out.tip, out.pose) {
                (Mode::Retreat, GuardState::Stop, _, _) => Some(Request::Reset),
                (_, GuardState::Warn | GuardState::Retreat, TipOutcome::Estimate(e), Some(p)) => {
                    // Along or against the force, sideways, or back out.
                    let f = e.force_n.normalize();
                    let side = f.cross(&p.rod_dir).normalize();
                    let step = match s % 4 {
                        0 => Some(f * 0.004),
                        1 => Some(-f * 0.004),
                        2 => Some(side * 0.004 * (r(1) - 0.5)),
                        _ => None,
                    };
                    if let Some(step) = step.filter(|s| s.norm() > 0.0) {
                        if r(3) < 0.3 {
                            Some(Request::GuardedMove {
                                tip_m: p.tip_m + step,
                                max_force_n: limits.stop_total_n,
                            })
                        } else {
                            Some(Request::MoveTip {
                                tip_m: p.tip_m + step,
                            })
                        }
                    } else {
                        Some(Request::BackOut {
                            distance_m: 0.002 + 0.004 * r(2),
                        })
                    }
                }
                _ => None,
            }
        } else {
            None
        };
        if let Some(request) = request {
            id += 1;
            rig.operator
                .requests
                .push(sar_loop::control::Envelope { id, request })
                .unwrap();
        }
        let d = rig.step();
        let input = *rig.c.loop_input();
        let reply = rig.operator.replies.pop();
        let e = &d.estimate;
        let ctx = format!(
            "{mode:?} force {force:?} k {k_n_per_m} t {t} ms: {:?} {:?} {:?} {:?}",
            e.guard_state, e.guard_reason, d.action, reply
        );
        let above = match e.guard_state {
            GuardState::Warn => !matches!(e.guard_reason, Reason::TareDue { .. }),
            GuardState::Retreat => true,
            _ => false,
        };
        let accepted = reply.is_some_and(|r| r.status == ReplyStatus::Accepted);
        if let (true, TipOutcome::Estimate(est), Some(pose)) = (above, e.tip, e.pose) {
            c.checked_cycles += 1;
            let f = est.force_n;
            let retreat = e.guard_state == GuardState::Retreat;
            // A streamed set point: the commanded tip's motion this period.
            // Force control's must not go along the force; a streamed move's
            // (Retreat) was judged as a whole when it was accepted (below):
            // its axes run their own time-optimal profiles, so its path
            // bends and a period's motion may lean slightly along the
            // force; measured.
            if let (DriveAction::Stream(q), Some(p)) = (d.action, last_stream) {
                c.streamed += 1;
                let step_m = tip_of(&rig, &q) - tip_of(&rig, &p);
                let along_m = step_m.dot(&f.normalize());
                if d.force_mode.is_some() {
                    c.force_streamed += 1;
                    assert!(
                        along_m <= 1e-9,
                        "{ctx}: the commanded tip moves {:.4} um along the force",
                        along_m * 1e6
                    );
                } else if along_m > 0.0 {
                    // Backing out along the rod (issue 14's retreat rule
                    // accepts it whatever the force's axial sign), or not.
                    let back_out = -step_m.dot(&pose.rod_dir) >= 0.985 * step_m.norm();
                    if back_out {
                        c.back_out_periods_along += 1;
                    } else {
                        c.move_periods_along += 1;
                        c.move_along_max_m = c.move_along_max_m.max(along_m);
                    }
                }
            }
            // A move accepted now.
            if let Some(r) = reply.filter(|_| accepted) {
                let target = match r.request {
                    Request::MoveTip { tip_m } | Request::GuardedMove { tip_m, .. } => Some(tip_m),
                    Request::BackOut { distance_m } => Some(pose.tip_m - pose.rod_dir * distance_m),
                    Request::Push { .. } | Request::Hold { .. } => {
                        panic!("{ctx}: force control started above the warn limit")
                    }
                    _ => None,
                };
                if let Some(target) = target {
                    let step_m = target - pose.tip_m;
                    if retreat {
                        assert!(reduces_force(&f, &pose.rod_dir, &step_m), "{ctx}");
                    } else {
                        c.warn_moves += 1;
                        assert!(step_m.dot(&f) <= 0.0, "{ctx}: accepted along the force");
                    }
                }
            }
            // A move under way that goes deeper: braked now.
            if let (Some((target, end)), Some(r), false) = (under_way, d.reference, accepted)
                && !retreat
                && (target - pose.tip_m).dot(&f) > 0.0
                && r != end
            {
                assert!(
                    matches!(d.action, DriveAction::Setpoint(_) | DriveAction::Stream(_)),
                    "{ctx}: a move deeper along the force not braked"
                );
            }
            // Any end point given now: within the braking distance.
            if let (DriveAction::Setpoint(end), false, Some(r), Some((p, p_stamp))) =
                (d.action, accepted, d.reference, last_ref)
            {
                c.brakes += 1;
                let stamp = input.joints.stamp_ns;
                let dt_s = (stamp.saturating_sub(p_stamp)) as f64 * 1e-9;
                let ahead_s = (input.now_ns.unwrap() - stamp) as f64 * 1e-9;
                let a = rig.cfg.step_config().axis_limits.max_accel_mps2;
                for (x_end, (x_r, x_p)) in [end.q1_m, end.q2_m, end.q3_m].into_iter().zip([
                    (r.q1_m, p.q1_m),
                    (r.q2_m, p.q2_m),
                    (r.q3_m, p.q3_m),
                ]) {
                    // The speed then: the mean over the last joint period
                    // plus what the acceleration adds until the cycle's time.
                    let v_mean = if dt_s > 0.0 {
                        (x_r - x_p).abs() / dt_s
                    } else {
                        0.0
                    };
                    let v = v_mean + a * (dt_s + ahead_s);
                    let bound_m = v * ahead_s + v * v / (2.0 * a) + 1e-9;
                    assert!(
                        (x_end - x_r).abs() <= bound_m,
                        "{ctx}: an end point {:.3} mm away, braking bound {:.3} mm",
                        (x_end - x_r).abs() * 1e3,
                        bound_m * 1e3
                    );
                }
            }
        }
        // Bookkeeping for the next cycle.
        if e.guard_state.is_halting() {
            under_way = None;
        }
        match (d.action, reply) {
            (DriveAction::Setpoint(end), Some(r)) if r.status == ReplyStatus::Accepted => {
                under_way = match r.request {
                    Request::MoveTip { tip_m } | Request::GuardedMove { tip_m, .. } => {
                        Some((tip_m, end))
                    }
                    _ => None,
                }
            }
            (DriveAction::Setpoint(_), _) => under_way = None,
            // A guarded move's hard brake (issue 26) is streamed: the move
            // under way ends there too.
            (DriveAction::Stream(_), _) => under_way = None,
            _ => {}
        }
        last_stream = match d.action {
            DriveAction::Stream(q) => Some(q),
            _ => None,
        };
        last_ref = d.reference.map(|r| (r, input.joints.stamp_ns));
    }
    rig.replays_bit_for_bit();
    c
}

/// A uniform number in [0, 1) from a seed.
fn unit(seed: u64) -> f64 {
    (sar_test_support::messages::mix(seed) >> 11) as f64 / (1u64 << 53) as f64
}

/// The contact's magnitude along `dir` (the rod along +X0): `frac` of the
/// way across the band between its warn and its stop limits (the largest
/// warn ratio of its parts, and 2.5 N of the estimate's noise below the
/// smallest stop ratio); in Retreat 3 N above the stop.
fn magnitude_n(dir: &Vec3, frac: f64, retreat: bool) -> f64 {
    let axial = dir.x.abs().max(1e-9);
    let lateral = (1.0 - dir.x * dir.x).max(1e-18).sqrt();
    let warn_n = (10.0f64).min(8.0 / axial).min(6.0 / lateral);
    let stop_n = (15.0f64).min(12.0 / axial).min(10.0 / lateral);
    if retreat {
        stop_n + 3.0
    } else {
        let (lo, hi) = (warn_n + 1.0, (stop_n - 2.5).max(warn_n + 1.2));
        lo + frac * (hi - lo)
    }
}

#[test]
fn no_mode_commands_a_motion_deeper_along_a_force_above_warn() {
    let strategy = (
        mode(),
        (-1.0..1.0f64, 0.0..std::f64::consts::TAU, 0.0..1.0f64),
        prop_oneof![Just(0.0), Just(300.0), Just(3000.0)],
        (50u64..400, 600u64..1500),
        any::<u64>(),
    );
    let mut runner = TestRunner::new(ProptestConfig {
        cases: 40,
        rng_seed: RngSeed::Fixed(0x015f_04ce),
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    let totals = std::cell::RefCell::new(Counts::default());
    let by_mode = std::cell::RefCell::new([0u64; 5]);
    let result = runner.run(
        &strategy,
        |(mode, (z, phi, frac), k_n_per_m, (ramp_ms, hold_ms), seed)| {
            let dir = direction(z, phi);
            let force = dir * magnitude_n(&dir, frac, matches!(mode, Mode::Retreat));
            let c = run(mode, force, k_n_per_m, ramp_ms, hold_ms, seed);
            let mut t = totals.borrow_mut();
            t.checked_cycles += c.checked_cycles;
            t.streamed += c.streamed;
            t.force_streamed += c.force_streamed;
            t.move_periods_along += c.move_periods_along;
            t.back_out_periods_along += c.back_out_periods_along;
            t.move_along_max_m = t.move_along_max_m.max(c.move_along_max_m);
            t.brakes += c.brakes;
            t.warn_moves += c.warn_moves;
            let m = match mode {
                Mode::Position(_) => 0,
                Mode::Guarded(..) => 1,
                Mode::Push(_) => 2,
                Mode::Hold(_) => 3,
                Mode::Retreat => 4,
            };
            by_mode.borrow_mut()[m] += c.checked_cycles;
            println!("{mode:?} |F| {:.2} N k {k_n_per_m}: {c:?}", force.norm());
            Ok(())
        },
    );
    if let Err(e) = result {
        panic!("{e}");
    }
    let t = totals.into_inner();
    let by_mode = by_mode.into_inner();
    println!(
        "all cases: {t:?}; cycles above warn by mode (position, guarded, push, hold, retreat): {by_mode:?}"
    );
    // Every mode spent cycles above the warn limit, force control streamed
    // in them, moves were judged and brakes given there.
    assert!(by_mode.iter().all(|&n| n > 500), "{by_mode:?}");
    assert!(t.force_streamed > 2000, "{t:?}");
    assert!(t.warn_moves > 5 && t.brakes > 5, "{t:?}");
}
