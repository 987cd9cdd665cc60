//! A drive that does not brake at its configured deceleration (issue 26
//! section 5, SAFETY.md D5): the simulator's drives quick-stop at the
//! scenario's deceleration (`[axes] quick_stop_decel_mps2`, CiA 402
//! 0x6085), whatever the daemon assumes (`[drivers.axes]
//! quick_stop_decel_mps2`, 2 m/s^2). A Stop (a 20 N contact) during a
//! 20 mm/s move across the rod: how far the axes run on after the Stop, and
//! what the loop sees of it. During the drives' quick stop the following
//! check's reference is the quick stop's profile at the configured
//! deceleration (`AxesMotion::halt_position`): a drive that runs on beyond
//! it by more than the tolerance is a `FollowingError` Fault; one within it
//! (v^2 / 2a less than 1 mm apart) is not seen. In planned motion a drive
//! that accelerates or brakes otherwise than planned is a `FollowingError`
//! too (the second test: drives at a quarter of the planned acceleration).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use crate::rig::{Plant, Rig, TIP_M};
use sar_estimator::Vec3;
use sar_estimator::guard::{GuardState, Reason};
use sar_loop::control::{ReplyStatus, Request};
use sar_sim::ContactKey;

/// The carriage's position, m (q1, q2, q3).
fn joints_m(rig: &Rig) -> Vec3 {
    let q = rig.sim.truth().unwrap().joints;
    Vec3::new(q.q1_m, q.q2_m, q.q3_m)
}

/// A 20 mm/s move of the tip 30 mm across the rod, a 20 N contact at 1.6 s
/// (a Stop) with the drives' quick stop at `decel_mps2` (`None`: the
/// scenario's axes' acceleration): the distance the carriage runs after the
/// Stop's cycle, m, and the guard's state and reason 3 s later.
fn stop_during_a_move(decel_mps2: Option<f64>) -> (f64, GuardState, Reason) {
    let key = |t_ns: u64, x: f64| ContactKey {
        t_ns,
        force_n: Vec3::new(x, 0.0, 0.0),
    };
    let contact = vec![
        key(0, 0.0),
        key(1_600_000_000, 0.0),
        key(1_601_000_000, 20.0),
    ];
    let mut rig = Rig::with_scenario(Vec::new(), contact, Plant::Demo, |spec| {
        spec.plant.quick_stop_decel_mps2 = decel_mps2;
    });
    let target = Vec3::new(TIP_M[0], TIP_M[1] + 0.03, TIP_M[2]);
    let r = rig.request(1, Request::MoveTip { tip_m: target });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let stopped = rig
        .until(2000, |d| d.estimate.guard_state.is_halting())
        .expect("the contact stops it");
    assert_eq!(stopped.estimate.guard_state, GuardState::Stop);
    let at_stop_m = joints_m(&rig);
    for _ in 0..3000 {
        rig.step();
    }
    let out = rig.c.output();
    (
        (joints_m(&rig) - at_stop_m).norm(),
        out.guard_state,
        out.guard_reason,
    )
}

#[test]
fn a_weak_quick_stop_is_seen_by_the_following_check() {
    let mut runs = Vec::new();
    for decel in [None, Some(2.0), Some(0.05)] {
        let (run_on_m, state, reason) = stop_during_a_move(decel);
        println!(
            "quick stop at {}: the carriage runs on {:.3} mm after the Stop; 3 s later {state:?} ({reason})",
            decel.map_or(
                "the axes' acceleration (0.2 m/s^2)".to_string(),
                |a| format!("{a} m/s^2")
            ),
            run_on_m * 1e3
        );
        runs.push((run_on_m, state, reason));
    }
    // v^2 / 2a at 20 mm/s (the axes' speed across the rod is the tip's
    // times a/b: at most the planned 20 mm/s): 1 mm at 0.2 m/s^2, 0.1 mm
    // at 2 m/s^2, 4 mm at 0.05 m/s^2.
    assert!(runs[2].0 > 3.0 * runs[0].0, "{runs:?}");
    assert!(runs[1].0 < runs[0].0, "{runs:?}");
    // The drive that brakes as configured (2 m/s^2) stays a Stop; the one
    // at 0.05 m/s^2 runs on 4 mm, beyond the quick stop's profile by more
    // than the 1 mm tolerance: a following error, a Fault.
    assert_eq!(runs[1].1, GuardState::Stop, "{}", runs[1].2);
    assert_eq!(runs[2].1, GuardState::Fault, "{}", runs[2].2);
    assert!(
        matches!(runs[2].2, Reason::FollowingError { .. }),
        "{}",
        runs[2].2
    );
}

#[test]
fn a_drive_slower_than_planned_is_a_following_error_in_planned_motion() {
    let mut rig = Rig::with_scenario(Vec::new(), Vec::new(), Plant::Demo, |spec| {
        spec.axes.max_accel_mps2 = 0.05;
    });
    let target = Vec3::new(TIP_M[0], TIP_M[1] + 0.03, TIP_M[2]);
    let r = rig.request(1, Request::MoveTip { tip_m: target });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let fault = rig
        .until(3000, |d| d.estimate.guard_state.is_halting())
        .expect("the following check faults");
    println!(
        "drives at 0.05 m/s^2 under a plan at 0.2 m/s^2: {:?} after {} ms ({})",
        fault.estimate.guard_state,
        rig.cycle - 1100,
        fault.estimate.guard_reason
    );
    assert_eq!(fault.estimate.guard_state, GuardState::Fault);
    assert!(
        matches!(fault.estimate.guard_reason, Reason::FollowingError { .. }),
        "{}",
        fault.estimate.guard_reason
    );
}
