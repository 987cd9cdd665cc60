//! How the axes move and how the rod slides in the support: shared by the
//! loop's plans (`sar_loop::step`), the simulator (`sar_sim`), the CANopen
//! drives (`sar_canopen`), the scenario checks (`sar_config::scenario`) and
//! the runner (`sar_sim::runner`), so that they agree by construction. It
//! depends on no other module of the crate but the small helpers.
//!
//! - Each axis moves on a time-optimal profile under a speed and an
//!   acceleration limit (the simulator's planner, `axes`); the time and the
//!   progress of a move from rest to rest come from that same planner.
//! - The rod slides in the support; the direction of its last slide fixes the
//!   sign of the support's friction (in the simulator) and identification's
//!   friction coefficient (followed by the runner), and changes only after a
//!   slide of [`SLIDE_THRESHOLD_M`] the other way, in both. The slide tracker
//!   is pure kinematics: it lives in `sar_kinematics::slide` (no_std) and is
//!   re-exported here, so that the simulator and the runner share the one
//!   implementation.

mod axes;

pub use axes::{AxisPlan, AxisState, Limits};
pub use sar_kinematics::slide::{SLIDE_THRESHOLD_M, SlideDirection, SlideSign, SlideTracker};

use sar_kinematics::ActiveJoints;

/// The plan of a move of `distance_m` from rest to rest, from 0 at time 0;
/// `None` when the distance is not finite or a limit is not > 0.
fn rest_to_rest(distance_m: f64, max_speed_mps: f64, max_accel_mps2: f64) -> Option<AxisPlan> {
    if !(distance_m.is_finite() && max_speed_mps > 0.0 && max_accel_mps2 > 0.0) {
        return None;
    }
    let rest = AxisState {
        x_m: 0.0,
        v_mps: 0.0,
    };
    let limits = Limits {
        max_speed_mps,
        max_accel_mps2,
    };
    Some(AxisPlan::to_target(0, rest, distance_m, limits))
}

/// Time for one axis to move `distance_m` from rest to rest with a speed and an
/// acceleration limit (trapezoid, or triangle for short moves), s; 0 when the
/// distance is not finite or a limit is not > 0.
pub fn axis_move_time_s(distance_m: f64, max_speed_mps: f64, max_accel_mps2: f64) -> f64 {
    rest_to_rest(distance_m, max_speed_mps, max_accel_mps2).map_or(0.0, |p| p.duration_s())
}

/// How far an axis has gone, m, `t_s` after starting from rest a move of
/// `distance_m` (signed) with a speed and an acceleration limit (the
/// time-optimal trapezoid or triangle of [`axis_move_time_s`]; the whole
/// distance after the end).
pub fn axis_progress_m(distance_m: f64, max_speed_mps: f64, max_accel_mps2: f64, t_s: f64) -> f64 {
    let Some(plan) = rest_to_rest(distance_m, max_speed_mps, max_accel_mps2) else {
        return 0.0;
    };
    let total_s = plan.duration_s();
    if t_s.is_nan() || t_s <= 0.0 || total_s <= 0.0 {
        return 0.0;
    }
    if t_s >= total_s {
        return plan.end_m();
    }
    plan.after_s(t_s).x_m
}

/// Time of the slowest axis for a move from `from` to `to`, s.
pub fn move_time_s(
    from: &ActiveJoints,
    to: &ActiveJoints,
    max_speed_mps: f64,
    max_accel_mps2: f64,
) -> f64 {
    (to.displacement_m() - from.displacement_m())
        .iter()
        .map(|d| axis_move_time_s(*d, max_speed_mps, max_accel_mps2))
        .fold(0.0, f64::max)
}
