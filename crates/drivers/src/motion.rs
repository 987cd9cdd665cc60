//! How the axes move and how the rod slides in the support: shared by the
//! simulator ([`crate::sim`]), the scenario checks ([`crate::scenario`]) and the
//! runner ([`crate::runner`]), so that they agree by construction. It depends
//! on no other module of the crate but the small helpers.
//!
//! - Each axis moves on a time-optimal profile under a speed and an
//!   acceleration limit (the simulator's planner, `axes`); the time and the
//!   progress of a move from rest to rest come from that same planner.
//! - The rod slides in the support; the direction of its last slide fixes the
//!   sign of the support's friction (in the simulator) and identification's
//!   friction coefficient (followed by the runner), and changes only after a
//!   slide of [`SLIDE_THRESHOLD_M`] the other way, in both.

mod axes;

pub(crate) use axes::{AxisPlan, AxisState, Limits};

use crate::Vec3;
use sar_kinematics::{ActiveJoints, Calibration};

/// The slide of the rod in the support, m, against the direction of its last
/// slide, after which the rod counts as sliding the other way.
///
/// A real support's friction does not reverse the instant the rod does: the
/// contact first deforms over a small pre-sliding displacement (micro-slip),
/// during which the friction keeps the sign of the last slide. The simulator
/// reverses the support's friction only after a slide of this size the other
/// way, and the runner's [`SlideTracker`] calls the slide reversed after the
/// same (a few encoder counts of the article's axes, so that quantisation does
/// not flip it either): identification's friction coefficient is then the sign
/// of the friction actually in the readings. One constant for both.
pub const SLIDE_THRESHOLD_M: f64 = 5e-6;

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

/// The direction of the last slide of the rod in the support, from the
/// distance between the U-joint and the support along the rod: +1 when it last
/// shrank (A moved towards B, the rod slid along u, inserting), -1 when it last
/// grew, 0 before any slide. A slide counts once the distance has moved by more
/// than [`SLIDE_THRESHOLD_M`] from its extreme in the present direction (from
/// the first value before any slide).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct SlideDirection {
    /// The extreme of the distance in the present direction, m (the first
    /// value before any slide; `None` before any value).
    reference_m: Option<f64>,
    sign: f64,
}

impl SlideDirection {
    /// The sign of the last slide (+1, -1, or 0 before any).
    pub fn sign(&self) -> f64 {
        self.sign
    }

    /// Takes the next distance, m (non-finite values are ignored); returns
    /// true when the sign changed.
    pub fn update(&mut self, distance_m: f64) -> bool {
        if !distance_m.is_finite() {
            return false;
        }
        let Some(reference) = self.reference_m else {
            self.reference_m = Some(distance_m);
            return false;
        };
        let change = distance_m - reference;
        if (self.sign > 0.0 && change < 0.0) || (self.sign < 0.0 && change > 0.0) {
            self.reference_m = Some(distance_m);
            false
        } else if change.abs() > SLIDE_THRESHOLD_M {
            // Shrinking: A moves towards B, the rod slides along u (+1).
            let sign = -change.signum();
            self.reference_m = Some(distance_m);
            let changed = sign != self.sign;
            self.sign = sign;
            changed
        } else {
            false
        }
    }
}

/// Follows a = |B - A| over a sequence of positions and keeps the sign of the
/// last slide of the rod in the support: +1 when A last moved towards B (the
/// rod slid along u, inserting), -1 away, 0 before any slide. A reversal counts
/// once a has come back by more than [`SLIDE_THRESHOLD_M`] from its extreme
/// (the simulator's friction reverses after the same slide), so that encoder
/// quantisation does not flip it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlideTracker {
    support_m: Vec3,
    ujoint_at_zero_m: Vec3,
    direction: SlideDirection,
}

impl SlideTracker {
    /// A tracker for the geometry of `calibration` (B, P_home, a_off), with no
    /// position seen yet.
    pub fn new(calibration: &Calibration) -> Self {
        Self {
            support_m: calibration.support_m(),
            ujoint_at_zero_m: calibration.p_home_m() + calibration.ujoint_offset_m(),
            direction: SlideDirection::default(),
        }
    }

    /// The sign of the last slide (+1, -1, or 0 before any).
    pub fn sign(&self) -> f64 {
        self.direction.sign()
    }

    /// Takes the next position; returns true when the sign changed.
    pub fn update(&mut self, q: &ActiveJoints) -> bool {
        let a = (self.support_m - self.ujoint_at_zero_m - q.displacement_m()).norm();
        self.direction.update(a)
    }
}
