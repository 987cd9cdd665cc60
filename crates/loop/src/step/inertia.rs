//! The inertia watch's place in the step (issue 34 item 2,
//! [`sar_estimator::inertia_watch`]): each cycle with a new sample of a free
//! tip in motion feeds it the estimate and its sensitivities to I_perp and
//! m_s; every cycle reports its verdict in [`LoopOutput::inertia`]. It
//! decides nothing. Free: the guard Ok after this cycle's step, an
//! observable estimate, no force control, and a plain move or an excitation
//! under way (not a guarded move, whose end is a contact, nor a retreat's
//! streamed move, which starts in one), the carriage moving as commanded
//! (not at rest, not the drives' quick stop).
//!
//! [`LoopOutput::inertia`]: super::LoopOutput::inertia

use super::LoopStep;
use super::trajectory::Trajectory;
use sar_estimator::cycle::{CycleOutput, TipOutcome};
use sar_estimator::guard::GuardState;
use sar_estimator::inertia_watch::{InertiaVerdict, WatchSample};
use sar_estimator::motion::CarriageMotion;

impl LoopStep {
    /// Feeds the watch a free sample of this cycle, or reports its last
    /// verdict (see the module's doc).
    pub(super) fn watch_inertia(
        &mut self,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
        motion: &CarriageMotion,
    ) -> InertiaVerdict {
        let plain_move = trajectory
            .is_some_and(|t| t.max_force_n.is_none() && (!t.streamed || t.excite.is_some()));
        let free = estimate.new_sample
            && estimate.guard_state == GuardState::Ok
            && self.force.mode().is_none()
            && self.motion.halt.is_none()
            && plain_move
            && !motion.is_rest();
        match (free, &estimate.tip, &estimate.pose) {
            (true, TipOutcome::Estimate(e), Some(pose)) if e.observable => {
                let (d_inertia, d_adapter) = self
                    .estimator
                    .tip_estimator()
                    .inertia_sensitivity(pose, motion);
                self.inertia_watch.update(&WatchSample {
                    force_n: e.force_n,
                    std_n: e.std_n,
                    d_inertia,
                    d_adapter,
                })
            }
            _ => self.inertia_watch.idle(),
        }
    }
}
