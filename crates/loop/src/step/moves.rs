//! A move judged and planned: not halted, from the trajectory under way,
//! the drives enabled, the target reachable within the travel (a guarded
//! move's limit checked), its direction allowed (the warn rule, Retreat);
//! then one time-optimal plan per axis under the configured speed and
//! acceleration ([`sar_hal::motion`]), at the retreat speed and streamed in
//! Retreat.

use super::LoopStep;
use super::answer::{Answer, ReplyDetail, ReplyStatus};
use super::config::GUARDED_CONTACT_SIGMA;
use super::guarded::guarded_force;
use super::retreat::{back_out_tip, judge_direction};
use super::trajectory::{Trajectory, joints_array};
use super::vocabulary::LoopInput;
use sar_estimator::Vec3;
use sar_estimator::cycle::CycleOutput;
use sar_estimator::guard::GuardState;
use sar_hal::DriveState;
use sar_hal::motion::AxisPlan;
use sar_kinematics::{ActiveJoints, inverse};

/// Where a move goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum MoveTarget {
    /// The tip to this point, base frame, m; with a guarded move's limit, N.
    Tip(Vec3, Option<f64>),
    /// The tip back along the rod by this distance, m.
    BackOut(f64),
}

/// A move judged acceptable, to be planned.
#[derive(Debug, Clone, Copy)]
struct AcceptedMove {
    /// The trajectory it starts from.
    from: Trajectory,
    /// The cycle's clock, ns.
    now_ns: u64,
    /// The tip it ends at, base frame, m.
    tip_m: Vec3,
    /// The axes there, m.
    q: ActiveJoints,
    /// A guarded move's force limit, N.
    max_force_n: Option<f64>,
}

impl LoopStep {
    /// The axes for a tip, within their travel.
    pub(super) fn reachable(&self, tip_m: &Vec3) -> Result<ActiveJoints, ReplyDetail> {
        let q = inverse(&self.calibration, &self.profile, tip_m).map_err(ReplyDetail::NoPose)?;
        let v = [q.q1_m, q.q2_m, q.q3_m];
        for (i, (v, (lo, hi))) in v.iter().zip(self.config.travel_m.iter()).enumerate() {
            if !(v >= lo && v <= hi) {
                return Err(ReplyDetail::OutsideTravel {
                    axis: u8::try_from(i + 1).unwrap_or(0),
                    value_m: *v,
                    min_m: *lo,
                    max_m: *hi,
                });
            }
        }
        Ok(q)
    }

    /// Judges a move and, if accepted, plans it (its trajectory) from where
    /// the trajectory is now (in Retreat: only a move that reduces the force, at the retreat
    /// speed, streamed).
    pub(super) fn plan_move(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
        target: MoveTarget,
    ) -> Result<Trajectory, Answer> {
        let accepted = self.judge_move(input, estimate, trajectory, target)?;
        Ok(self.planned_move(&accepted, estimate))
    }

    /// Judges a move: not halted, with a trajectory to start from, the
    /// drives enabled, the target's tip (a guarded move's limit checked)
    /// reachable within the travel, and its direction allowed (the warn
    /// rule, Retreat).
    fn judge_move(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
        target: MoveTarget,
    ) -> Result<AcceptedMove, Answer> {
        let halted = estimate.guard_state.is_halting();
        let (Some(&from), Some(now_ns), false) = (trajectory, input.now_ns, halted) else {
            return Err((
                ReplyStatus::Halted,
                ReplyDetail::Reason(estimate.guard_reason),
            ));
        };
        if input.drive_state != Some(DriveState::Enabled) {
            return Err((
                ReplyStatus::DrivesRefused,
                ReplyDetail::DrivesNotEnabled(input.drive_state),
            ));
        }
        let (tip_m, max_force_n) = match target {
            MoveTarget::Tip(tip_m, None) => (tip_m, None),
            MoveTarget::Tip(tip_m, Some(max_force_n)) => {
                (tip_m, Some(self.judge_guarded(estimate, max_force_n)?))
            }
            MoveTarget::BackOut(distance_m) => (back_out_tip(estimate, distance_m)?, None),
        };
        let q = self
            .reachable(&tip_m)
            .map_err(|detail| (ReplyStatus::Unreachable, detail))?;
        judge_direction(estimate, &tip_m)?;
        Ok(AcceptedMove {
            from,
            now_ns,
            tip_m,
            q,
            max_force_n,
        })
    }

    /// A guarded move's limit: within 0 < N <= the total stop limit, above
    /// the force now.
    fn judge_guarded(&self, estimate: &CycleOutput, max_force_n: f64) -> Result<f64, Answer> {
        let stop_n = self.estimator.guard_config().force_limits().stop_total_n;
        if !(max_force_n > 0.0 && max_force_n <= stop_n) {
            return Err((
                ReplyStatus::BadArgument,
                ReplyDetail::BadMaxForce {
                    max_force_n,
                    stop_n,
                },
            ));
        }
        let Some((force_n, std_n)) = guarded_force(estimate) else {
            return Err((ReplyStatus::NoEstimate, ReplyDetail::NoEstimate));
        };
        if force_n.norm() >= max_force_n {
            return Err((
                ReplyStatus::Refused,
                ReplyDetail::AlreadyAtForce {
                    force_n: force_n.norm(),
                    max_force_n,
                },
            ));
        }
        // A limit within the force's noise would stop the move on noise:
        // |F| crosses z |std| with probability at most 2 Phi(-z) per sample
        // whatever the axes' correlation (Szekely and Bakirov 2003).
        let noise_n = GUARDED_CONTACT_SIGMA * std_n.norm();
        if max_force_n < noise_n {
            return Err((
                ReplyStatus::BadArgument,
                ReplyDetail::WithinNoise {
                    max_force_n,
                    noise_n,
                },
            ));
        }
        Ok(max_force_n)
    }

    /// An accepted move's trajectory: one time-optimal plan per axis from
    /// where the trajectory is now (at the retreat speed in Retreat). A
    /// retreat move, or any move while a streamed one runs, streams.
    fn planned_move(&self, m: &AcceptedMove, estimate: &CycleOutput) -> Trajectory {
        let retreat = estimate.guard_state == GuardState::Retreat;
        let now_ns = m.now_ns;
        let mut limits = self.config.axis_limits;
        if retreat {
            limits.max_speed_mps = self.config.retreat_speed_mps;
        }
        let states = m.from.at(now_ns);
        let mut axes = [AxisPlan::hold(now_ns, 0.0); 3];
        for ((plan, state), target_m) in axes.iter_mut().zip(states).zip(joints_array(&m.q)) {
            *plan = AxisPlan::to_target(now_ns, state, target_m, limits);
        }
        let mut planned = Trajectory::from_plans(now_ns, axes, Some(m.tip_m));
        planned.streamed = retreat || m.from.streamed && now_ns <= m.from.end_ns;
        planned.max_force_n = m.max_force_n;
        planned
    }
}
