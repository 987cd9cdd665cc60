//! Force control in the loop (issue 15): `sarctl push --axial N`, `sarctl
//! hold --max-force N`, `sarctl position` and guarded moves (`sarctl
//! move-tip X Y Z --max-force N`: braked when the filtered tip force reaches
//! N, reporting where and at what force) through the real controller on
//! the simulator in simulated time, against a tissue that pushes back (the
//! simulator's spring-damper along the rod, breathing). The figures (RMS
//! error of the true axial force, overshoot, the hold's largest force beside
//! position mode's) are printed (`--nocapture`). Every mode ends at once on
//! a Stop; the runs replay bit for bit through a fresh step.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

// The force-control rig, and the other force-control tests in this binary
// (one binary: less to link).
#[path = "force/commands_round_trip.rs"]
mod commands_round_trip;
#[path = "force/drive_decel.rs"]
mod drive_decel;
#[path = "force/force_figures.rs"]
mod force_figures;
#[path = "force/force_properties.rs"]
mod force_properties;
#[path = "force/guarded_noise.rs"]
mod guarded_noise;
#[path = "force/late_cycles.rs"]
mod late_cycles;
#[path = "force/motion_figures.rs"]
mod motion_figures;
#[path = "force/plant_mismatch.rs"]
mod plant_mismatch;
#[path = "force/plant_range.rs"]
mod plant_range;
#[path = "force/rig.rs"]
mod rig;
#[path = "force/support_shift.rs"]
mod support_shift;
#[path = "force/support_watch.rs"]
mod support_watch;

use rig::{Rig, TIP_M, rms};
use sar_estimator::Vec3;
use sar_estimator::force_control::ForceMode;
use sar_estimator::guard::GuardState;
use sar_loop::control::{ReplyStatus, Request};
use sar_loop::step::{DriveAction, ReplyDetail};

#[test]
fn push_regulates_the_axial_force_against_a_breathing_tissue() {
    let axial_n = 3.0;
    for k in [100.0, 300.0, 1000.0, 3000.0] {
        let mut rig = Rig::new(k, 0.005, 0.003, Vec::new());
        let r = rig.request(1, Request::Push { axial_n });
        assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
        let mut errors = Vec::new();
        let mut largest_n = 0.0f64;
        let mut streamed = 0;
        // 20 s; settled after 10 s (the approach at 6 mm/s through the
        // 5 mm gap and up to 30 mm into the softest tissue).
        for i in 0..20_000 {
            let d = rig.step();
            assert!(
                !d.estimate.guard_state.is_halting(),
                "k {k}: {:?}",
                d.estimate.guard_reason
            );
            assert_eq!(d.force_mode, Some(ForceMode::Push { axial_n }), "k {k}");
            streamed += usize::from(matches!(d.action, DriveAction::Stream(_)));
            let f = rig.true_force_n().x;
            largest_n = largest_n.max(f);
            if i >= 10_000 {
                errors.push(f - axial_n);
            }
        }
        let rms_n = rms(&errors);
        let overshoot = (largest_n - axial_n).max(0.0) / axial_n * 100.0;
        println!(
            "push {axial_n} N into {k} N/m breathing 3 mm at 0.25 Hz: RMS error of the true axial force {rms_n:.3} N after settling, largest {largest_n:.2} N (overshoot {overshoot:.1} %), {streamed} set points streamed"
        );
        // Every cycle of the mode streams a set point.
        assert!(streamed > 19_000, "{streamed}");
        // Within the goal of 0.3 N RMS, with room for the breathing
        // at the stiffest tissue.
        assert!(rms_n < 0.5, "k {k}: RMS {rms_n:.3} N");
        assert!(largest_n < 8.0, "k {k}: {largest_n:.2} N (the warn limit)");
        if k == 300.0 {
            rig.replays_bit_for_bit();
        }
    }
}

#[test]
fn hold_yields_to_a_breathing_tissue_where_position_mode_does_not() {
    // The surface at the tip, breathing 6 mm along the rod into it at
    // 1000 N/m: up to 6 N in position mode.
    let max_force_n = 2.0;
    let run = |hold: bool| {
        let mut rig = Rig::new(1000.0, 0.0, 0.006, Vec::new());
        if hold {
            let r = rig.request(1, Request::Hold { max_force_n });
            assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
        }
        let (mut largest_n, mut above, mut n) = (0.0f64, 0usize, 0usize);
        for _ in 0..12_000 {
            let d = rig.step();
            assert!(!d.estimate.guard_state.is_halting());
            let f = rig.true_force_n().norm();
            largest_n = largest_n.max(f);
            above += usize::from(f > max_force_n + 0.5);
            n += 1;
        }
        (largest_n, above as f64 / n as f64 * 100.0)
    };
    let (hold_n, hold_above) = run(true);
    let (position_n, position_above) = run(false);
    println!(
        "hold {max_force_n} N under a tissue breathing 6 mm at 1000 N/m: largest true |F| {hold_n:.2} N, {hold_above:.1} % of the time above {:.1} N; position mode: {position_n:.2} N, {position_above:.1} %",
        max_force_n + 0.5
    );
    assert!(position_n > 5.0, "{position_n}");
    assert!(
        hold_n < position_n - 2.0,
        "hold {hold_n} N, position {position_n} N"
    );
}

#[test]
fn position_ends_force_control_and_a_stop_ends_it_at_once() {
    // A push at 2 N; then `position`: the mode ends, the tip stays.
    let mut rig = Rig::new(300.0, 0.005, 0.0, Vec::new());
    assert_eq!(
        rig.request(1, Request::Push { axial_n: 2.0 }).status,
        ReplyStatus::Accepted
    );
    for _ in 0..8000 {
        rig.step();
    }
    // A move refused (out of reach) leaves the push as it was.
    let r = rig.request(
        5,
        Request::MoveTip {
            tip_m: Vec3::new(5.0, 0.2, 0.0),
        },
    );
    assert_eq!(r.status, ReplyStatus::Unreachable);
    assert_eq!(
        rig.c.decision().force_mode,
        Some(ForceMode::Push { axial_n: 2.0 })
    );
    let r = rig.request(2, Request::Position);
    assert_eq!(r.status, ReplyStatus::Accepted);
    assert_eq!(rig.c.decision().force_mode, None);
    let tip = rig.c.output().pose.unwrap().tip_m;
    for _ in 0..1000 {
        rig.step();
    }
    let moved = (rig.c.output().pose.unwrap().tip_m - tip).norm();
    assert!(moved < 0.0005, "moved {moved} m after position");

    // Bad setpoints are refused with their cause.
    for (request, max) in [
        (Request::Push { axial_n: 0.0 }, 8.0),
        (Request::Push { axial_n: 8.0 }, 8.0),
        (
            Request::Hold {
                max_force_n: f64::NAN,
            },
            10.0,
        ),
    ] {
        let r = rig.request(3, request);
        assert_eq!(r.status, ReplyStatus::BadArgument, "{request:?}");
        assert!(
            matches!(r.detail, ReplyDetail::BadForce { max_n, .. } if max_n == max),
            "{:?}",
            r.detail
        );
    }

    // A push, then a contact of 20 N on top (above the stop limit): the
    // guard stops, and the mode ends in that very cycle.
    let on_s = 1.1 + 0.003 + 3.0;
    let contact = sar_test_support::messages::contact_pulse(
        (on_s * 1e9) as u64,
        (on_s * 1e9) as u64 + 50_000_000,
        (on_s * 1e9) as u64 + 2_000_000_000,
        (on_s * 1e9) as u64 + 2_050_000_000,
        Vec3::new(20.0, 0.0, 0.0),
    );
    let mut rig = Rig::new(300.0, 0.005, 0.0, contact);
    assert_eq!(
        rig.request(4, Request::Push { axial_n: 2.0 }).status,
        ReplyStatus::Accepted
    );
    let stopped = (0..6000)
        .map(|_| rig.step())
        .find(|d| d.estimate.guard_state == GuardState::Stop)
        .expect("no Stop");
    assert_eq!(stopped.force_mode, None);
    assert_eq!(stopped.action, DriveAction::QuickStop);
    rig.replays_bit_for_bit();
}

/// What one guarded move into the tissue did.
struct Outcome {
    stop_force_n: f64,
    largest_true_n: f64,
    final_true_n: f64,
    stop_after_ms: u64,
}

fn guarded_move_into(k_n_per_m: f64, max_force_n: f64) -> (Rig, Outcome) {
    let gap_m = 0.005;
    let mut rig = Rig::new(k_n_per_m, gap_m, 0.0, Vec::new());
    // Along the rod, half as deep again into the tissue as the limit needs.
    let depth_m = 1.5 * max_force_n / k_n_per_m + 0.005;
    let target = Vec3::new(TIP_M[0] + gap_m + depth_m, TIP_M[1], TIP_M[2]);
    let r = rig.request(
        1,
        Request::GuardedMove {
            tip_m: target,
            max_force_n,
        },
    );
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let start = rig.cycle;
    let mut largest_true_n = 0.0f64;
    let mut stop = None;
    for _ in 0..6000 {
        let d = rig.step();
        largest_true_n = largest_true_n.max(rig.true_force_n().norm());
        assert!(
            !d.estimate.guard_state.is_halting(),
            "k {k_n_per_m}: halted: {:?}",
            d.estimate.guard_reason
        );
        if stop.is_none() {
            stop = d.guarded_stop;
        }
    }
    let stop = stop.unwrap_or_else(|| panic!("k {k_n_per_m}: never braked"));
    assert!(stop.cycle > start);
    // Braked when the force is anticipated to reach the limit (its rise
    // over the filter's lag and the braking: the filtered force then is
    // below it, the more so the faster it rises), not at random before:
    // at rest, the true force is near the limit.
    let final_n = rig.true_force_n().norm();
    assert!(
        final_n >= 0.75 * max_force_n,
        "k {k_n_per_m}: braked at {:.2} N (filtered), {final_n:.2} N at rest",
        stop.force_n.norm()
    );
    // It stopped short of the target, in the tissue.
    assert!(
        stop.tip_m.x > TIP_M[0] + gap_m && stop.tip_m.x < target.x - 0.001,
        "k {k_n_per_m}: braked at {:?}",
        stop.tip_m
    );
    let out = Outcome {
        stop_force_n: stop.force_n.norm(),
        largest_true_n,
        final_true_n: rig.true_force_n().norm(),
        stop_after_ms: stop.cycle - start,
    };
    (rig, out)
}

#[test]
fn a_guarded_move_into_tissue_is_braked_at_its_force() {
    let max_force_n = 4.0;
    for k in [100.0, 300.0, 1000.0, 3000.0] {
        let (rig, o) = guarded_move_into(k, max_force_n);
        println!(
            "guarded move at 20 mm/s into {k} N/m, --max-force {max_force_n}: braked {} ms after the command at |F| {:.2} N (filtered); largest true |F| {:.2} N; at rest after {:.2} N",
            o.stop_after_ms, o.stop_force_n, o.largest_true_n, o.final_true_n
        );
        // The overshoot: the filter's lag and the braking distance (20 mm/s
        // at 0.2 m/s^2: 1 mm) times the stiffness; below the warn limit
        // (8 N axial) up to 1000 N/m.
        if k <= 1000.0 {
            assert!(o.largest_true_n < 8.0, "k {k}: {:.2} N", o.largest_true_n);
        }
        assert!(o.final_true_n <= o.largest_true_n + 1e-9);
        if k == 300.0 {
            rig.replays_bit_for_bit();
        }
    }
}

#[test]
fn guarded_move_limits_are_checked() {
    let mut rig = Rig::new(300.0, 0.010, 0.0, Vec::new());
    let target = Vec3::new(TIP_M[0] + 0.005, TIP_M[1], TIP_M[2]);
    for bad in [0.0, -1.0, f64::NAN, 1e3] {
        let r = rig.request(
            2,
            Request::GuardedMove {
                tip_m: target,
                max_force_n: bad,
            },
        );
        assert_eq!(r.status, ReplyStatus::BadArgument, "{bad}");
        assert!(matches!(r.detail, ReplyDetail::BadMaxForce { .. }), "{bad}");
        assert!(r.detail.to_string().contains("stop limit"), "{}", r.detail);
    }
    // A limit below the force there is already (the estimate's own noise
    // and bias are above 0.01 N): refused, saying so.
    let r = rig.request(
        3,
        Request::GuardedMove {
            tip_m: target,
            max_force_n: 0.001,
        },
    );
    assert_eq!(r.status, ReplyStatus::Refused);
    assert!(
        matches!(r.detail, ReplyDetail::AlreadyAtForce { .. }),
        "{:?}",
        r.detail
    );
    // Nothing moved.
    assert!(rig.log.iter().all(|(_, d)| d.guarded_stop.is_none()));
}

#[test]
fn a_recorded_guarded_move_decodes_to_the_same_request() {
    let mut rig = Rig::new(300.0, 0.010, 0.0, Vec::new());
    let request = Request::GuardedMove {
        tip_m: Vec3::new(0.61, 0.2, 0.0),
        max_force_n: 2.5,
    };
    rig.request(4, request);
    let (input, decision) = *rig.log.last().unwrap();
    let msg = sar_record::convert::cycle_input_msg(&input, &decision);
    assert_eq!(msg.move_max_force_n, 2.5);
    let back = sar_record::convert::loop_input(&msg);
    assert_eq!(back.request, Some(request));
    // And a plain move stays plain.
    let plain = Request::MoveTip {
        tip_m: Vec3::new(0.6, 0.2, 0.001),
    };
    rig.request(5, plain);
    let (input, decision) = *rig.log.last().unwrap();
    let msg = sar_record::convert::cycle_input_msg(&input, &decision);
    assert_eq!(msg.move_max_force_n, 0.0);
    assert_eq!(sar_record::convert::loop_input(&msg).request, Some(plain));
}

#[test]
fn a_guarded_move_in_free_space_is_not_braked_by_the_noise() {
    // The anticipation (the force's rate over the lag and the braking)
    // acts on the filtered force's rate, not on noise: 15 mm along and
    // across the rod with a 1 N limit, no tissue, reach their targets.
    for (k, step) in [
        Vec3::new(0.015, 0.0, 0.0),
        Vec3::new(0.0, 0.015, 0.0),
        Vec3::new(-0.01, 0.0, 0.01),
    ]
    .into_iter()
    .enumerate()
    {
        // The static plant: the rod's phantom force while it accelerates
        // (MODEL.md 10) is the estimator's compensation's to remove (issue
        // 26), not this test's noise.
        let mut rig = Rig::without_inertia(Vec::new(), Vec::new());
        let target = Vec3::new(TIP_M[0], TIP_M[1], TIP_M[2]) + step;
        let r = rig.request(
            1,
            Request::GuardedMove {
                tip_m: target,
                max_force_n: 1.0,
            },
        );
        assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
        for _ in 0..2000 {
            let d = rig.step();
            assert_eq!(d.guarded_stop, None, "move {k}");
        }
        let tip = rig.c.output().pose.unwrap().tip_m;
        assert!((tip - target).norm() < 2e-4, "move {k}: {tip:?}");
    }
}
