//! The guard's drive action and what the drives must be for a request: a
//! halt's quick stop or fault reset, a reset held back from the estimator
//! (the drives in Fault, the axes moving), the drives released after an
//! accepted reset, and the one check that the guard is Ok, the drives
//! enabled and the axes at rest ([`LoopStep::ready_at_rest`]).

use super::LoopStep;
use super::answer::{Answer, ReplyDetail, ReplyStatus, command_reply};
use super::config::REST_SPEED_MPS;
use super::request::Request;
use super::trajectory::{Trajectory, TrajectoryChange};
use super::vocabulary::{DriveAction, LoopInput, Release};
use sar_estimator::cycle::{CommandAccepted, CycleOutput};
use sar_estimator::guard::GuardState;
use sar_hal::DriveState;

/// Why a reset is held back from the estimator in this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum HeldReset {
    /// The drives are in Fault: their fault is reset first (their positions
    /// are invalid until then, so the guard cannot judge the reset).
    DrivesFaulted,
    /// The axes still move: the reset waits until they are at rest.
    AxesMoving,
}

/// The estimator's command event, as the step acts on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CommandOutcome {
    /// The reply: the command's event.
    pub(super) reply: Answer,
    /// After an accepted reset: how the drives are brought back, and the
    /// axes held where they were measured (none without a valid sample).
    pub(super) released: Option<(DriveAction, TrajectoryChange)>,
}

impl LoopStep {
    /// Whether the cycle's reset is held back from the estimator: with the
    /// drives in Fault (their fault is reset first), or while the axes move.
    pub(super) fn held_reset(&self, input: &LoopInput) -> Option<HeldReset> {
        if input.request != Some(Request::Reset) {
            return None;
        }
        if matches!(input.drive_state, Some(DriveState::Fault { .. })) {
            Some(HeldReset::DrivesFaulted)
        } else if self.speed_mps > REST_SPEED_MPS {
            Some(HeldReset::AxesMoving)
        } else {
            None
        }
    }

    /// The reply to a held reset.
    pub(super) fn held_reply(&self, held: HeldReset, input: &LoopInput) -> Answer {
        match held {
            HeldReset::DrivesFaulted => (
                ReplyStatus::DrivesFaultReset,
                ReplyDetail::DrivesNotEnabled(input.drive_state),
            ),
            HeldReset::AxesMoving => (
                ReplyStatus::AxesMoving,
                ReplyDetail::AxesMoving {
                    speed_mps: self.speed_mps,
                },
            ),
        }
    }

    /// The guard's ready check for a motion the loop starts from rest (force
    /// control, an excitation): the guard Ok, the drives enabled, the axes
    /// at rest (measured, and `planned_mps`, the trajectory's own speed now,
    /// zero).
    pub(super) fn ready_at_rest(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        planned_mps: f64,
    ) -> Result<(), Answer> {
        if estimate.guard_state != GuardState::Ok {
            return Err((
                ReplyStatus::NotOk,
                ReplyDetail::NotInOk(estimate.guard_state),
            ));
        }
        if input.drive_state != Some(DriveState::Enabled) {
            return Err((
                ReplyStatus::DrivesRefused,
                ReplyDetail::DrivesNotEnabled(input.drive_state),
            ));
        }
        let speed_mps = self.speed_mps.max(planned_mps);
        if speed_mps > REST_SPEED_MPS || planned_mps > 0.0 {
            return Err((
                ReplyStatus::AxesMoving,
                ReplyDetail::AxesMoving { speed_mps },
            ));
        }
        Ok(())
    }
}

/// In Stop or Fault (`Some`: the trajectory is dropped) the drives get a
/// quick stop in the cycle that enters it and whenever they report
/// `Enabled`; else, for a reset held by their fault, a fault reset.
pub(super) fn halt(
    input: &LoopInput,
    estimate: &CycleOutput,
    held: Option<HeldReset>,
) -> Option<DriveAction> {
    if !estimate.guard_state.is_halting() {
        return None;
    }
    let entered_halt = estimate.transition.is_some_and(|t| t.to.is_halting());
    Some(
        if entered_halt || input.drive_state == Some(DriveState::Enabled) {
            DriveAction::QuickStop
        } else if held == Some(HeldReset::DrivesFaulted) {
            DriveAction::FaultReset
        } else {
            DriveAction::None
        },
    )
}

/// The estimator's command event is the reply; an accepted reset releases
/// the drives (the way depends on their state) and holds the axes where
/// they were measured.
pub(super) fn command_outcome(input: &LoopInput, estimate: &CycleOutput) -> Option<CommandOutcome> {
    let ev = estimate.command?;
    let released = matches!(ev.result, Ok(CommandAccepted::Reset)).then(|| {
        let hold = match (input.now_ns, input.joints.valid) {
            (Some(now_ns), true) => {
                TrajectoryChange::Replace(Trajectory::hold(now_ns, &input.joints.joints))
            }
            _ => TrajectoryChange::Drop,
        };
        (release(input.drive_state), hold)
    });
    Some(CommandOutcome {
        reply: command_reply(&ev.result),
        released,
    })
}

/// How the drives are released after an accepted reset, from their state.
fn release(drive_state: Option<DriveState>) -> DriveAction {
    match drive_state {
        Some(DriveState::QuickStop) => DriveAction::Release(Release::DisableEnable),
        Some(DriveState::Fault { .. }) => DriveAction::Release(Release::FaultResetEnable),
        Some(DriveState::Ready) => DriveAction::Release(Release::Enable),
        _ => DriveAction::None,
    }
}
