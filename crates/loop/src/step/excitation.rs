//! The dynamic identification's excitation in the step (issue 26,
//! [`crate::excite`]): accepted in Ok with the drives enabled and the axes
//! at rest, within `[identify]`'s limits and the travel; streamed one
//! period ahead about where the axes rest; braked under a Warn or beyond
//! the limits; a hold at its centre at its end.

use super::LoopStep;
use super::answer::{Answer, ReplyDetail, ReplyStatus};
use super::trajectory::{Trajectory, TrajectoryChange, joints_array};
use super::vocabulary::LoopInput;
use crate::excite::{Excitation, ExciteRefusal, ExciteRequest};
use sar_estimator::cycle::CycleOutput;
use sar_estimator::guard::GuardState;

impl LoopStep {
    /// Starts an excitation ([`crate::excite`]): its trajectory, from the
    /// one under way (`trajectory`), when the guard is Ok, the drives
    /// enabled, the axes at rest; within `[identify]`'s limits and the
    /// travel about where they rest. It ends force control.
    pub(super) fn start_excitation(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
        request: &ExciteRequest,
    ) -> Result<Trajectory, Answer> {
        use ReplyStatus::Halted;
        let halted = estimate.guard_state.is_halting();
        let (Some(from), Some(now_ns), false) = (trajectory, input.now_ns, halted) else {
            return Err((Halted, ReplyDetail::Reason(estimate.guard_reason)));
        };
        let planned_mps = from
            .at(now_ns)
            .iter()
            .fold(0.0, |m: f64, s| m.max(s.v_mps.abs()));
        self.ready_at_rest(input, estimate, planned_mps)?;
        let centre_m = joints_array(&from.position(now_ns));
        let c = &self.config;
        crate::excite::judge(request, &centre_m, &c.travel_m, &c.excite).map_err(excite_refused)?;
        let excite = Excitation {
            request: *request,
            centre_m,
            start_ns: now_ns,
        };
        let mut t = Trajectory::hold(now_ns, &from.position(now_ns));
        t.end_ns = excite.end_ns();
        t.streamed = true;
        t.excite = Some(excite);
        self.force.stop();
        Ok(t)
    }

    /// An excitation under way is braked (from its position and velocity,
    /// at the planned deceleration) under a Warn or when its commanded
    /// speed or acceleration is above the limits; at its end it becomes a
    /// hold at its centre.
    pub(super) fn end_excitation_if_due(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
    ) -> TrajectoryChange {
        let (Some(t), Some(now_ns)) = (trajectory, input.now_ns) else {
            return TrajectoryChange::Keep;
        };
        let Some(e) = t.excite else {
            return TrajectoryChange::Keep;
        };
        if now_ns >= t.end_ns {
            let mut hold = Trajectory::hold(now_ns, &t.position(now_ns));
            (hold.streamed, hold.end_ns) = (true, t.end_ns);
            TrajectoryChange::Replace(hold)
        } else if estimate.guard_state == GuardState::Warn
            || !e.within_limits(now_ns, &self.config.excite)
        {
            TrajectoryChange::Replace(self.braked(t, now_ns, false))
        } else {
            TrajectoryChange::Keep
        }
    }
}

/// The answer to an excitation refused by [`crate::excite::judge`]: outside
/// the travel as a move's, else a bad argument.
fn excite_refused(refusal: ExciteRefusal) -> Answer {
    match refusal {
        ExciteRefusal::OutsideTravel {
            axis,
            value_m,
            min_m,
            max_m,
        } => (
            ReplyStatus::Unreachable,
            ReplyDetail::OutsideTravel {
                axis,
                value_m,
                min_m,
                max_m,
            },
        ),
        refusal => (ReplyStatus::BadArgument, ReplyDetail::Excitation(refusal)),
    }
}
