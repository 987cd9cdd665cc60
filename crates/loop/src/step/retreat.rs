//! Which way a motion may go near a force: the warn rule (above a warn
//! limit no move, set point or trajectory goes further along the tip force)
//! and Retreat (issue 14: only a move that reduces the force, against it or
//! back out along the rod, [`Request::BackOut`](super::Request::BackOut)).

use super::answer::{Answer, ReplyDetail, ReplyStatus};
use super::config::MAX_BACK_OUT_M;
use super::trajectory::Trajectory;
use sar_estimator::Vec3;
use sar_estimator::cycle::{CycleOutput, TipOutcome};
use sar_estimator::guard::{GuardState, Reason, reduces_force};

/// The warn rule: the guard's Warn for a force above a warn limit (a Warn
/// for a due tare has no force to push along). Under it no move, set point
/// or trajectory goes further along the tip force.
fn warned_by_force(estimate: &CycleOutput) -> bool {
    estimate.guard_state == GuardState::Warn
        && !matches!(estimate.guard_reason, Reason::TareDue { .. })
}

/// The force force control must not go deeper along: under the warn rule,
/// the force the guard judged (this cycle's estimate, the one a move is
/// judged against; `Err` without one: it ends the mode); `Ok(None)` else.
pub(super) fn no_deeper_along(estimate: &CycleOutput) -> Result<Option<Vec3>, ()> {
    match (warned_by_force(estimate), &estimate.tip) {
        (false, _) => Ok(None),
        (true, TipOutcome::Estimate(e)) => Ok(Some(e.force_n)),
        (true, _) => Err(()),
    }
}

/// Under the warn rule, a move under way toward a tip further along the
/// tip force (from `tip_m`, the tip now): that force.
pub(super) fn pushes_along_warned_force(
    t: &Trajectory,
    tip_m: &Vec3,
    estimate: &CycleOutput,
) -> Option<Vec3> {
    let (true, Some(target), TipOutcome::Estimate(e)) =
        (warned_by_force(estimate), t.target_tip_m, estimate.tip)
    else {
        return None;
    };
    ((target - tip_m).dot(&e.force_n) > 0.0).then_some(e.force_n)
}

/// A move's direction: under the warn rule not further along the tip
/// force; in Retreat only one that reduces it (against the force, or back
/// along the rod).
pub(super) fn judge_direction(estimate: &CycleOutput, tip_m: &Vec3) -> Result<(), Answer> {
    let retreat = estimate.guard_state == GuardState::Retreat;
    let warn = warned_by_force(estimate);
    if !(warn || retreat) {
        return Ok(());
    }
    let (TipOutcome::Estimate(e), Some(pose)) = (estimate.tip, estimate.pose) else {
        return Err((ReplyStatus::NoEstimate, ReplyDetail::NoEstimate));
    };
    let step_m = tip_m - pose.tip_m;
    if warn && step_m.dot(&e.force_n) > 0.0 {
        return Err((
            ReplyStatus::TowardForce,
            ReplyDetail::Reason(estimate.guard_reason),
        ));
    }
    if retreat && !reduces_force(&e.force_n, &pose.rod_dir, &step_m) {
        return Err((
            ReplyStatus::NotReducing,
            ReplyDetail::NotReducing {
                step_m,
                force_n: e.force_n,
            },
        ));
    }
    Ok(())
}

/// A back-out's tip: `distance_m` (0 < d <= [`MAX_BACK_OUT_M`]) back along
/// the rod from the tip now.
pub(super) fn back_out_tip(estimate: &CycleOutput, distance_m: f64) -> Result<Vec3, Answer> {
    if !(distance_m > 0.0 && distance_m <= MAX_BACK_OUT_M) {
        return Err((
            ReplyStatus::BadArgument,
            ReplyDetail::BadDistance { distance_m },
        ));
    }
    let Some(pose) = estimate.pose else {
        return Err((ReplyStatus::NoEstimate, ReplyDetail::NoEstimate));
    };
    Ok(pose.tip_m - pose.rod_dir * distance_m)
}
