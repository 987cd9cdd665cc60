//! What one cycle of the step consumes and produces: [`LoopInput`] in,
//! [`LoopOutput`] out, with what the drives are told ([`DriveAction`]) and
//! where a guarded move stopped ([`GuardedStop`]).

use super::answer::{ReplyDetail, ReplyStatus};
use super::request::Request;
use crate::observer::ServoFit;
use sar_estimator::Vec3;
use sar_estimator::cycle::{
    Command, CycleInput, CycleOutput, Estimator, JointSample, SensorSample,
};
use sar_estimator::force_control::ForceMode;
use sar_estimator::guard::{ForceLimits, Reason};
use sar_estimator::inertia_watch::InertiaVerdict;
use sar_estimator::motion::CarriageMotion;
use sar_estimator::support::SupportStatus;
use sar_hal::DriveState;
use sar_kinematics::ActiveJoints;

/// Where a guarded move stopped, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardedStop {
    /// The cycle that braked it.
    pub cycle: u64,
    /// The tip then, base frame, m.
    pub tip_m: Vec3,
    /// The tip force that stopped it (filtered when the filter is on), N.
    pub force_n: Vec3,
    /// The move's limit, N.
    pub max_force_n: f64,
}

/// The numeric code of a guard reason (stable: recordings and `sarctl` use
/// it): the estimator's one table, `Reason::code`.
pub fn reason_code(reason: &Reason) -> u16 {
    reason.code()
}

/// [`reason_code`] in a recording's `uint8` field (`sar_msgs` `REASON_*`:
/// the same numbers): the estimator's `Reason::recorded_code`.
pub fn recorded_reason_code(reason: &Reason) -> u8 {
    reason.recorded_code()
}

/// Everything one cycle decides from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopInput {
    /// The cycle number; strictly increasing.
    pub cycle: u64,
    /// The monotonic clock read after the inputs were gathered, ns; `None`
    /// when it could not be read.
    pub now_ns: Option<u64>,
    /// The newest sensor sample.
    pub sensor: SensorSample,
    /// The newest joint sample.
    pub joints: JointSample,
    /// The drives' state as read this cycle (`None`: it could not be read).
    pub drive_state: Option<DriveState>,
    /// The operator request applied in this cycle.
    pub request: Option<Request>,
    /// How long the publishing thread had made no progress when this cycle's
    /// inputs were gathered, ns (0: it keeps up, or there is none).
    pub publisher_idle_ns: u64,
}

impl LoopInput {
    /// The estimator's part of the input.
    pub fn cycle_input(&self) -> CycleInput {
        CycleInput {
            cycle: self.cycle,
            now_ns: self.now_ns,
            sensor: self.sensor,
            joints: self.joints,
            command: match self.request {
                Some(Request::Reset) => Some(Command::Reset),
                Some(Request::Tare) => Some(Command::Tare),
                Some(Request::SetLimits(l)) => Some(Command::SetLimits(l)),
                Some(
                    Request::MoveTip { .. }
                    | Request::BackOut { .. }
                    | Request::GuardedMove { .. }
                    | Request::Hold { .. }
                    | Request::Push { .. }
                    | Request::Position
                    | Request::Excite(_)
                    | Request::SupportConfirm,
                )
                | None => None,
            },
        }
    }
}

/// How the drives are brought back after an accepted reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Release {
    /// From `Ready`: enable.
    Enable,
    /// From `QuickStop`: disable, then enable.
    DisableEnable,
    /// From `Fault`: fault reset, then enable.
    FaultResetEnable,
}

/// What the drives are told this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriveAction {
    /// Nothing.
    None,
    /// Quick stop.
    QuickStop,
    /// Bring them back after an accepted reset.
    Release(Release),
    /// Move to this end point, m (the end of the trajectory just planned or
    /// braked: the drives run the same time-optimal profile to it).
    Setpoint(ActiveJoints),
    /// A streamed set point: the trajectory one period ahead, m (cyclic
    /// synchronous position: the drives reach it in one period).
    Stream(ActiveJoints),
    /// Reset the drives' fault only (they go to Ready; the guard's reset
    /// comes with the next request).
    FaultReset,
}

/// The decision of one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopOutput {
    /// The estimator's output (tip force, guard, command event).
    pub estimate: CycleOutput,
    /// The commanded trajectory at the joint sample's stamp, which the joints
    /// were checked against; during the drives' quick stop its profile
    /// (`None`: no trajectory nor quick stop of a known state, or not yet
    /// released).
    pub reference: Option<ActiveJoints>,
    /// What the drives are told.
    pub action: DriveAction,
    /// The reply to the cycle's request, with the guard's reason code behind
    /// a refusal (0 otherwise); `None` without a request.
    pub reply: Option<(ReplyStatus, u16)>,
    /// The exact cause behind the reply (what `sarctl` prints).
    pub reply_detail: ReplyDetail,
    /// The force limits in use after this cycle.
    pub limits: ForceLimits,
    /// The last guarded move's stop (kept until the next one stops).
    pub guarded_stop: Option<GuardedStop>,
    /// The force-control mode after this cycle (`None`: position control).
    pub force_mode: Option<ForceMode>,
    /// The carriage's motion handed to the estimator in this cycle
    /// ([`crate::motion`]).
    pub motion: CarriageMotion,
    /// The inertia watch's verdict after this cycle (issue 34: I_perp and
    /// the adapter's mass as the free motion implies them, what is named).
    pub inertia: InertiaVerdict,
    /// The support watch's status after this cycle (issue 34 section 3).
    pub support: SupportStatus,
    /// `[support] max_shift_m` and `max_std_m`, m ((0, 0) before the first
    /// cycle).
    pub support_limits_m: (f64, f64),
    /// The support's status to log in this cycle (the first reset, a
    /// verdict's change, a confirmation).
    pub support_note: Option<SupportNote>,
    /// How far the axes follow the servo model, the servo observer's
    /// state and whether the mismatch is named ([`crate::observer`]).
    pub servo_fit: ServoFit,
    /// One encoder count, m (the fit's unit; 0 before the first cycle).
    pub encoder_count_m: f64,
    /// The servo mismatch was named in this cycle (the controller logs it
    /// once).
    pub servo_named_now: bool,
}

impl LoopOutput {
    /// The output before the first cycle: the estimator's, nothing decided.
    pub(super) fn first(estimator: &Estimator, inertia: InertiaVerdict) -> Self {
        Self {
            estimate: *estimator.last(),
            reference: None,
            action: DriveAction::None,
            reply: None,
            reply_detail: ReplyDetail::None,
            limits: estimator.guard_config().force_limits(),
            guarded_stop: None,
            force_mode: None,
            motion: CarriageMotion::REST,
            inertia,
            support: SupportStatus::NONE,
            support_limits_m: (0.0, 0.0),
            support_note: None,
            servo_fit: ServoFit::default(),
            encoder_count_m: 0.0,
            servo_named_now: false,
        }
    }
}

/// Why the controller logs the support's status in a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SupportWhy {
    /// The first reset was accepted: what the mean at rest said.
    FirstReset,
    /// The verdict changed (a shift named, the check could not run, ...).
    Verdict,
    /// The operator confirmed the support as it is.
    Confirmed,
}

/// A support status the controller logs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportNote {
    /// The cycle.
    pub cycle: u64,
    /// Why.
    pub why: SupportWhy,
    /// The status then.
    pub status: SupportStatus,
    /// The limit, m (`[support] max_shift_m`).
    pub max_shift_m: f64,
    /// A component with a larger standard error is not determined, m.
    pub max_std_m: f64,
}
