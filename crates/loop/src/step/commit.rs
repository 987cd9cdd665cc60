//! The cycle's decision and the step's one commit point. The phases of
//! [`LoopStep::step`] return what they decide; the step gathers it in a
//! [`Decision`] (the trajectory as a working copy: each phase's
//! [`TrajectoryChange`] applied in turn), and [`LoopStep::commit`] alone
//! writes it into the step's state: the trajectory (its only writer), the
//! model of the axes, the drives' state remembered, a guarded move's stop,
//! the streaming clock, the output.

use super::LoopStep;
use super::answer::{Answer, ReplyDetail, ReplyStatus};
use super::trajectory::{Trajectory, TrajectoryChange, joints_array};
use super::vocabulary::{DriveAction, GuardedStop, LoopInput, LoopOutput, SupportNote};
use crate::motion::{AxesMotion, Told};
use sar_estimator::cycle::{CycleOutput, FollowingReference};
use sar_estimator::motion::CarriageMotion;

/// What the cycle does to the loop's model of the axes, beyond following
/// the trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum AxesEvent {
    /// Nothing.
    None,
    /// The drives' quick stop commanded (a halt).
    QuickStop,
    /// The drives released after an accepted reset: the halt is over.
    Released,
}

/// What a cycle has decided so far (the step's phases return their parts;
/// the step puts them here; [`LoopStep::commit`] applies it).
#[derive(Debug, Clone, Copy)]
pub(super) struct Decision {
    /// What the drives are told.
    pub(super) action: DriveAction,
    /// The reply to the cycle's request.
    pub(super) reply: Option<Answer>,
    /// The trajectory as the cycle found it (a late cycle absorbed): what
    /// the cycle keeps when an accepted move or excitation does not go to
    /// the drives.
    pub(super) found: Option<Trajectory>,
    /// The trajectory as decided so far.
    pub(super) decided: Option<Trajectory>,
    /// A new plan (a move, or a brake) whose end point goes to the drives.
    pub(super) planned: bool,
    /// A move or an excitation accepted in this cycle: it stands only if it
    /// goes to the drives in this cycle.
    pub(super) accepted_motion: bool,
    /// What the cycle does to the model of the axes.
    pub(super) axes: AxesEvent,
    /// The model of the axes advanced to the sensor sample (by the
    /// carriage's motion).
    pub(super) axes_model: AxesMotion,
    /// A guarded move braked in this cycle: where and at what force.
    pub(super) guarded_stop: Option<GuardedStop>,
    /// The carriage's motion handed to the estimator.
    pub(super) motion: CarriageMotion,
    /// The support's status to log in this cycle.
    pub(super) support_note: Option<SupportNote>,
}

impl Decision {
    /// Nothing decided yet: the trajectory as found.
    pub(super) fn new(
        found: Option<Trajectory>,
        motion: CarriageMotion,
        axes_model: AxesMotion,
    ) -> Self {
        Self {
            action: DriveAction::None,
            reply: None,
            found,
            decided: found,
            planned: false,
            accepted_motion: false,
            axes: AxesEvent::None,
            axes_model,
            guarded_stop: None,
            motion,
            support_note: None,
        }
    }

    /// A phase's change of the trajectory, applied to the working copy.
    pub(super) fn change(&mut self, change: TrajectoryChange) {
        self.decided = change.applied_to(self.decided);
    }
}

impl LoopStep {
    /// The one commit point: the cycle's decision written into the step's
    /// state, and the cycle's output, readable as [`LoopStep::last`].
    /// "Accepted" stands only for a move or an excitation that goes to the
    /// drives now: else the cycle keeps the trajectory it found and the
    /// reply says so.
    pub(super) fn commit(
        &mut self,
        input: &LoopInput,
        estimate: CycleOutput,
        reference: Option<FollowingReference>,
        mut d: Decision,
    ) -> &LoopOutput {
        let carried_out = matches!(d.action, DriveAction::Setpoint(_) | DriveAction::Stream(_));
        if d.accepted_motion && !carried_out {
            d.decided = d.found;
            d.reply = Some((ReplyStatus::NotCarriedOut, ReplyDetail::NotCarriedOut));
        }
        self.trajectory = d.decided;
        let was_named = self.motion.fit.named;
        self.commit_axes(input, &d);
        self.last_drive_state = input.drive_state;
        if d.guarded_stop.is_some() {
            self.guarded_stop = d.guarded_stop;
        }
        self.last_stream_ns = match d.action {
            DriveAction::Stream(_) => input.now_ns,
            _ => None,
        };
        let (reply, reply_detail) = match d.reply {
            Some((status, detail)) => (Some((status, detail.reason_code())), detail),
            None => (None, ReplyDetail::None),
        };
        self.out = LoopOutput {
            estimate,
            reference: reference.map(|r| r.joints),
            action: d.action,
            reply,
            reply_detail,
            limits: self.estimator.guard_config().force_limits(),
            guarded_stop: self.guarded_stop,
            force_mode: self.force.mode(),
            motion: d.motion,
            inertia: self.out.inertia,
            support: self.support.status(),
            support_limits_m: (
                self.support.config().max_shift_m,
                self.support.config().max_std_m,
            ),
            support_note: d.support_note,
            servo_fit: self.motion.fit,
            encoder_count_m: self.config.motion.encoder_count_m,
            servo_named_now: self.motion.fit.named && !was_named,
        };
        &self.out
    }

    /// The model of the axes: advanced to the sensor sample, then the
    /// drives' quick stop begun (from the trajectory the cycle found) or the
    /// model restarted on a release, then what the drives were told.
    fn commit_axes(&mut self, input: &LoopInput, d: &Decision) {
        self.motion = d.axes_model;
        let plans = d.found.map(|t| t.axes);
        match (d.axes, input.now_ns) {
            (AxesEvent::QuickStop, Some(now_ns)) => {
                self.motion
                    .start_halt(&self.config.motion, plans.as_ref(), now_ns);
            }
            (AxesEvent::Released, _) => self.motion.restart(),
            _ => {}
        }
        let Some(now_ns) = input.now_ns else {
            return;
        };
        let told = match d.action {
            DriveAction::Stream(q) => Told::Streamed(joints_array(&q)),
            DriveAction::None | DriveAction::FaultReset => Told::Nothing,
            DriveAction::Setpoint(_) | DriveAction::QuickStop | DriveAction::Release(_) => {
                Told::Other
            }
        };
        self.motion
            .commanded(told, now_ns, plans.as_ref(), self.config.period_ns);
    }
}
