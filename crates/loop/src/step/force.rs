//! Force control (issue 15, FORCE_CONTROL.md) in the step: the controller
//! observes every cycle's estimate; a mode starts from rest in Ok, streams
//! the law's commanded tip one set point per period, and ends (holding the
//! last set point) on a halt, a Retreat, a move, `Position` or when it has
//! nothing to act on. The controller is its own state machine
//! ([`ForceController`](sar_estimator::force_control::ForceController)),
//! driven here by commands; what a mode decides of the trajectory is
//! returned, for the commit point.

use super::LoopStep;
use super::answer::{Answer, ReplyDetail, ReplyStatus, SupportShifted};
use super::retreat::no_deeper_along;
use super::trajectory::{Trajectory, TrajectoryChange};
use super::vocabulary::LoopInput;
use sar_estimator::cycle::{CycleOutput, TipOutcome};
use sar_estimator::force_control::ForceMode;
use sar_estimator::guard::GuardState;
use sar_hal::DriveState;

impl LoopStep {
    /// Force control's filter sees every cycle's estimate; a halt or a
    /// Retreat ends any mode at once.
    pub(super) fn observe_force(&mut self, input: &LoopInput, estimate: &CycleOutput) {
        match &estimate.tip {
            TipOutcome::Estimate(e) => {
                self.force
                    .observe(Some((input.sensor.counter, &e.force_n, &e.std_n)));
            }
            _ => self.force.observe(None),
        }
        if estimate.guard_state.is_halting() || estimate.guard_state == GuardState::Retreat {
            self.force.stop();
        }
    }

    /// Starts a force-control mode (Ok only, the drives enabled, the axes at
    /// rest, a filtered force to act on; the setpoint below its warn limit).
    pub(super) fn start_force(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        mode: ForceMode,
    ) -> Answer {
        let limits = self.estimator.guard_config().force_limits();
        let (force_n, max_n) = match mode {
            ForceMode::Hold { max_force_n } => (max_force_n, limits.warn_total_n),
            ForceMode::Push { axial_n } => (axial_n, limits.warn_axial_n),
        };
        if !(force_n > 0.0 && force_n < max_n) {
            return (
                ReplyStatus::BadArgument,
                ReplyDetail::BadForce { force_n, max_n },
            );
        }
        if let Some(s) = self.support_refuses_force() {
            return (
                ReplyStatus::Refused,
                ReplyDetail::SupportShifted(SupportShifted {
                    shift_m: s.named_m.unwrap_or(s.shift_m),
                    max_shift_m: self.support.config().max_shift_m,
                }),
            );
        }
        if let Err(refused) = self.ready_at_rest(input, estimate, 0.0) {
            return refused;
        }
        let (Some(pose), Some(_)) = (estimate.pose, self.force.filtered_force_n()) else {
            return (ReplyStatus::NoEstimate, ReplyDetail::NoEstimate);
        };
        self.force.start(mode, pose.tip_m);
        (ReplyStatus::Accepted, ReplyDetail::None)
    }

    /// The force-control mode's period: the law's commanded tip, through
    /// the inverse kinematics, streamed to the drives (one set point per
    /// period, which the following check then holds the axes to). Under the
    /// warn rule no motion goes deeper along the force. No estimate, no
    /// pose or an unreachable tip ends the mode, holding the last set point.
    pub(super) fn force_period(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
    ) -> TrajectoryChange {
        let next = match (
            input.now_ns,
            estimate.pose,
            input.drive_state,
            no_deeper_along(estimate),
        ) {
            (Some(now_ns), Some(pose), Some(DriveState::Enabled), Ok(along)) => self
                .force
                .step(&pose.rod_dir, along.as_ref())
                .ok()
                .and_then(|out| self.reachable(&out.tip_m).ok())
                .map(|q| (now_ns, q)),
            _ => None,
        };
        match next {
            Some((now_ns, q)) => {
                let mut t = Trajectory::hold(now_ns, &q);
                t.streamed = true;
                TrajectoryChange::Replace(t)
            }
            None => self.end_force(input.now_ns, trajectory),
        }
    }

    /// Ends force control, holding the last set point.
    pub(super) fn end_force(
        &mut self,
        now_ns: Option<u64>,
        trajectory: Option<&Trajectory>,
    ) -> TrajectoryChange {
        if self.force.mode().is_none() {
            return TrajectoryChange::Keep;
        }
        self.force.stop();
        match (trajectory, now_ns) {
            (Some(t), Some(now_ns)) => {
                let mut hold = Trajectory::hold(now_ns, &t.position(now_ns));
                hold.streamed = t.streamed;
                TrajectoryChange::Replace(hold)
            }
            _ => TrajectoryChange::Keep,
        }
    }
}
