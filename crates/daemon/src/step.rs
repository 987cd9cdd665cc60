//! The daemon's pure per-cycle decision: [`LoopStep::step`] turns one cycle's
//! [`LoopInput`] (clock reading, sensor sample, joint sample, the drives'
//! state, the operator request applied in this cycle) into a [`LoopOutput`]:
//! the estimator's output, the commanded trajectory at the joint sample's
//! stamp (checked for following error), what the drives are told
//! ([`DriveAction`]) and the reply to the request. Nothing else enters a
//! decision: no device, no clock, no queue. So a recording of the inputs
//! (`/sar/cycle/input`) replays to the same outputs bit for bit, and the
//! controller ([`crate::control`]) only gathers inputs and carries out
//! [`DriveAction`]s.
//!
//! Rules carried here (the estimator carries the guard's):
//! - On Stop or Fault the drives get a quick stop in the same cycle, and again
//!   in every later cycle in which they report `Enabled`, until a reset is
//!   accepted; the commanded trajectory is dropped.
//! - An accepted reset brings the drives back (the way depends on their
//!   state) and holds the axes where they were measured.
//! - A move is planned here, with the time-optimal axis planner of
//!   [`sar_drivers::motion`] under the configured speed and acceleration,
//!   from where the trajectory is now. The drives get the plan's end point
//!   once, when it is planned (or braked), and run the same planner under the
//!   same limits (the simulator's axes and the CANopen host take theirs from
//!   `[axes]`), so that the loop's plan is the trajectory they follow within a
//!   period; drives that do otherwise (other limits, a blocked or slipping
//!   axis) leave it and fault. A move is refused while halted, while the
//!   drives are not enabled, outside the travel or the kinematics, and,
//!   above the warn limit, when it pushes the tip further along its force; a
//!   move under way that would push further along the force once the force
//!   is above the warn limit is braked.
//! - Following error: the measured joints against the trajectory at their
//!   stamp, beyond the tolerance, is a Fault ([`Reason::FollowingError`]).
//!
//! Fixed-size state; no allocation, no panic.

use sar_drivers::DriveState;
use sar_drivers::motion::{AxisPlan, AxisState, Limits};
use sar_estimator::cycle::{
    Bias, Command, CommandAccepted, CommandRefused, CycleInput, CycleOutput, Estimator,
    EstimatorConfig, FollowingReference, JointSample, SensorSample, TipOutcome,
};
use sar_estimator::guard::{ForceLimits, GuardState, Reason};
use sar_estimator::{SettingError, Vec3};
use sar_kinematics::{ActiveJoints, Calibration, Profile, inverse};

/// An operator request, applied in the cycle whose input carries it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// Leave Stop or Fault (judged on the cycle's input).
    Reset,
    /// Model-based tare.
    Tare,
    /// Move the tip to this point, base frame, m (inverse kinematics, then
    /// a limited-speed move planned by the loop).
    MoveTip {
        /// The wanted tip, base frame, m.
        tip_m: Vec3,
    },
    /// Replace the guard's force limits (within the configured ceilings).
    SetLimits(ForceLimits),
}

/// What became of a request. The numbers are the wire codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ReplyStatus {
    /// Done.
    Accepted = 0,
    /// A reset while nothing was latched.
    NothingToReset = 1,
    /// A reset refused: its cause persists (the reason code says which).
    ResetRefused = 2,
    /// A tare outside `Ok`.
    NotOk = 3,
    /// A tare with a force above a warn limit.
    AboveWarn = 4,
    /// A tare without an estimate, or whose bias cannot be solved.
    NoEstimate = 5,
    /// A move while the drives are halted (Stop or Fault not yet reset).
    Halted = 6,
    /// A move the kinematics cannot reach, or outside the travel.
    Unreachable = 7,
    /// A move deeper along the tip force while it is above the warn limit.
    TowardForce = 8,
    /// A move while the drives are not enabled (they report another state,
    /// or could not be read).
    DrivesRefused = 9,
    /// Refused for another reason.
    Refused = 10,
    /// Force limits that are invalid or above their configured ceiling.
    LimitsRefused = 11,
    /// A reset while the axes still move (braking after a quick stop, or
    /// drives that have not stopped): the trajectory to hold would not be
    /// theirs. Wait until they are at rest.
    AxesMoving = 12,
}

/// Below this speed (on every axis, between two joint samples) the axes are
/// at rest for a reset, m/s (well above the encoders' quantisation over one
/// period, well below any planned move).
pub const REST_SPEED_MPS: f64 = 0.002;

/// The numeric code of a guard reason (stable: recordings and `sarctl` use
/// it): the estimator's one table, `Reason::code`.
pub fn reason_code(reason: &Reason) -> u16 {
    reason.code()
}

/// [`reason_code`] in a recording's `uint8` field (`sar_msgs` `REASON_*`:
/// the same numbers; a code beyond 254 would be `REASON_OTHER`, 255).
pub fn recorded_reason_code(reason: &Reason) -> u8 {
    u8::try_from(reason.code()).unwrap_or(u8::MAX)
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
                Some(Request::MoveTip { .. }) | None => None,
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
}

/// The decision of one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopOutput {
    /// The estimator's output (tip force, guard, command event).
    pub estimate: CycleOutput,
    /// The commanded trajectory at the joint sample's stamp, which the joints
    /// were checked against (`None`: no trajectory: halted, or not yet
    /// released).
    pub reference: Option<ActiveJoints>,
    /// What the drives are told.
    pub action: DriveAction,
    /// The reply to the cycle's request, with the guard's reason code behind
    /// a refusal (0 otherwise); `None` without a request.
    pub reply: Option<(ReplyStatus, u16)>,
    /// The force limits in use after this cycle.
    pub limits: ForceLimits,
}

/// The loop's settings beyond the estimator's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepConfig {
    /// (min, max) of q1, q2, q3, m.
    pub travel_m: [(f64, f64); 3],
    /// Speed and acceleration of the moves the loop plans.
    pub axis_limits: Limits,
    /// The accepted following error per axis, m.
    pub following_tolerance_m: f64,
}

/// Why a [`StepConfig`] cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StepConfigError {
    /// The estimator refused its configuration.
    #[error(transparent)]
    Estimator(#[from] SettingError),
    /// A loop setting is out of range.
    #[error("{field} = {value}: {why}")]
    Invalid {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        why: &'static str,
    },
}

/// The commanded trajectory: one plan per axis, and the tip it ends at (for
/// the warn-limit rule; `None` for a hold or a brake).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Trajectory {
    axes: [AxisPlan; 3],
    target_tip_m: Option<Vec3>,
    end_ns: u64,
}

impl Trajectory {
    fn hold(now_ns: u64, q: &ActiveJoints) -> Self {
        Self {
            axes: joints_array(q).map(|x| AxisPlan::hold(now_ns, x)),
            target_tip_m: None,
            end_ns: now_ns,
        }
    }

    fn at(&self, t_ns: u64) -> [AxisState; 3] {
        self.axes.map(|p| p.at(t_ns))
    }

    fn position(&self, t_ns: u64) -> ActiveJoints {
        let [a, b, c] = self.at(t_ns);
        ActiveJoints {
            q1_m: a.x_m,
            q2_m: b.x_m,
            q3_m: c.x_m,
        }
    }

    fn from_plans(start_ns: u64, axes: [AxisPlan; 3], target_tip_m: Option<Vec3>) -> Self {
        let longest_s = axes.iter().map(AxisPlan::duration_s).fold(0.0, f64::max);
        // Saturating float-to-int: a non-finite duration ends "never".
        let end_ns = start_ns.saturating_add((longest_s * 1e9).ceil() as u64);
        Self {
            axes,
            target_tip_m,
            end_ns,
        }
    }
}

fn joints_array(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

/// The pure per-cycle decision of the daemon (see the module documentation).
#[derive(Debug, Clone)]
pub struct LoopStep {
    estimator: Estimator,
    calibration: Calibration,
    profile: Profile,
    config: StepConfig,
    trajectory: Option<Trajectory>,
    /// The last valid joint sample (for the axes' speed).
    last_joints: Option<(ActiveJoints, u64)>,
    /// The largest axis speed between the last two joint samples, m/s.
    speed_mps: f64,
    out: LoopOutput,
}

impl LoopStep {
    /// Builds the step: the estimator with the sensor's bias, no trajectory
    /// (the guard starts in Fault; the first accepted reset holds the axes
    /// where they are).
    pub fn new(
        estimator: &EstimatorConfig,
        bias: Bias,
        config: StepConfig,
    ) -> Result<Self, StepConfigError> {
        let invalid = |field, value, why| StepConfigError::Invalid { field, value, why };
        let l = config.axis_limits;
        if !(l.max_speed_mps.is_finite() && l.max_speed_mps > 0.0) {
            return Err(invalid(
                "max_speed_mps",
                l.max_speed_mps,
                "must be finite and > 0",
            ));
        }
        if !(l.max_accel_mps2.is_finite() && l.max_accel_mps2 > 0.0) {
            return Err(invalid(
                "max_accel_mps2",
                l.max_accel_mps2,
                "must be finite and > 0",
            ));
        }
        let t = config.following_tolerance_m;
        if !(t.is_finite() && t > 0.0) {
            return Err(invalid(
                "following_tolerance_m",
                t,
                "must be finite and > 0",
            ));
        }
        for &(lo, hi) in &config.travel_m {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid("travel_m", lo, "must be finite with min < max"));
            }
        }
        let (calibration, profile) = (estimator.calibration, estimator.profile);
        let estimator = Estimator::with_bias(estimator, bias)?;
        let out = LoopOutput {
            estimate: *estimator.last(),
            reference: None,
            action: DriveAction::None,
            reply: None,
            limits: estimator.guard_config().force_limits(),
        };
        Ok(Self {
            calibration,
            profile,
            estimator,
            config,
            trajectory: None,
            last_joints: None,
            speed_mps: 0.0,
            out,
        })
    }

    /// The output of the last cycle.
    pub fn last(&self) -> &LoopOutput {
        &self.out
    }

    /// The estimator (its bias, guard configuration).
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// The settings.
    pub fn config(&self) -> &StepConfig {
        &self.config
    }

    /// Decides one cycle (see the module documentation). The result stays
    /// readable as [`LoopStep::last`] until the next cycle.
    pub fn step(&mut self, input: &LoopInput) -> &LoopOutput {
        // The trajectory at the joint sample's stamp.
        let tolerance_m = self.config.following_tolerance_m;
        let reference =
            self.trajectory
                .filter(|_| input.joints.valid)
                .map(|t| FollowingReference {
                    joints: t.position(input.joints.stamp_ns),
                    tolerance_m,
                });
        // The axes' speed, from the joint samples.
        let q = &input.joints.joints;
        if input.joints.valid && [q.q1_m, q.q2_m, q.q3_m].iter().all(|v| v.is_finite()) {
            if let Some((p, stamp_ns)) = self.last_joints
                && input.joints.stamp_ns > stamp_ns
            {
                let dt_s = (input.joints.stamp_ns - stamp_ns) as f64 * 1e-9;
                self.speed_mps = [q.q1_m - p.q1_m, q.q2_m - p.q2_m, q.q3_m - p.q3_m]
                    .iter()
                    .fold(0.0, |m: f64, d| m.max(d.abs() / dt_s));
            }
            self.last_joints = Some((*q, input.joints.stamp_ns));
        }
        // A reset waits until the axes are at rest: it is not passed on.
        let mut cycle_input = input.cycle_input();
        let reset_while_moving =
            input.request == Some(Request::Reset) && self.speed_mps > REST_SPEED_MPS;
        if reset_while_moving {
            cycle_input.command = None;
        }
        let estimate = *self
            .estimator
            .cycle_following(&cycle_input, reference.as_ref());
        let mut action = DriveAction::None;
        let mut reply = reset_while_moving.then_some((ReplyStatus::AxesMoving, 0));

        let halting = matches!(estimate.guard_state, GuardState::Stop | GuardState::Fault);
        let entered_halt = estimate
            .transition
            .is_some_and(|t| matches!(t.to, GuardState::Stop | GuardState::Fault));
        if halting {
            self.trajectory = None;
            if entered_halt || input.drive_state == Some(DriveState::Enabled) {
                action = DriveAction::QuickStop;
            }
        }

        // The estimator's commands: their event is the reply.
        if let Some(ev) = estimate.command {
            reply = Some(command_reply(&ev.result));
            if matches!(ev.result, Ok(CommandAccepted::Reset)) {
                action = match input.drive_state {
                    Some(DriveState::QuickStop) => DriveAction::Release(Release::DisableEnable),
                    Some(DriveState::Fault { .. }) => {
                        DriveAction::Release(Release::FaultResetEnable)
                    }
                    Some(DriveState::Ready) => DriveAction::Release(Release::Enable),
                    _ => DriveAction::None,
                };
                self.trajectory = match (input.now_ns, input.joints.valid) {
                    (Some(now_ns), true) => Some(Trajectory::hold(now_ns, &input.joints.joints)),
                    _ => None,
                };
            }
        }

        let mut planned = false;
        if let Some(Request::MoveTip { tip_m }) = input.request {
            let r = self.plan_move(input, &estimate, &tip_m);
            planned = r.0 == ReplyStatus::Accepted;
            reply = Some(r);
        }

        // A move under way that pushes further along a force above the warn
        // limit is braked.
        if estimate.guard_state == GuardState::Warn
            && let (Some(t), Some(now_ns)) = (self.trajectory, input.now_ns)
            && let (Some(target), Some(pose), TipOutcome::Estimate(e)) =
                (t.target_tip_m, estimate.pose, estimate.tip)
            && now_ns < t.end_ns
            && (target - pose.tip_m).dot(&e.force_n) > 0.0
        {
            let limits = self.config.axis_limits;
            let states = t.at(now_ns);
            let axes = states.map(|s| AxisPlan::brake(now_ns, s, limits));
            self.trajectory = Some(Trajectory::from_plans(now_ns, axes, None));
            planned = true;
        }

        // A new plan: its end point to the drives.
        if planned
            && !halting
            && action == DriveAction::None
            && input.drive_state == Some(DriveState::Enabled)
            && let Some(t) = self.trajectory
        {
            let [q1_m, q2_m, q3_m] = t.axes.map(|p| p.end_m());
            action = DriveAction::Setpoint(ActiveJoints { q1_m, q2_m, q3_m });
        }

        self.out = LoopOutput {
            estimate,
            reference: reference.map(|r| r.joints),
            action,
            reply,
            limits: self.estimator.guard_config().force_limits(),
        };
        &self.out
    }

    /// Judges a move and, if accepted, plans it from where the trajectory is
    /// now.
    fn plan_move(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        tip_m: &Vec3,
    ) -> (ReplyStatus, u16) {
        let halted = matches!(estimate.guard_state, GuardState::Stop | GuardState::Fault);
        let (Some(trajectory), Some(now_ns), false) = (self.trajectory, input.now_ns, halted)
        else {
            return (ReplyStatus::Halted, reason_code(&estimate.guard_reason));
        };
        if input.drive_state != Some(DriveState::Enabled) {
            return (ReplyStatus::DrivesRefused, 0);
        }
        let Ok(target) = inverse(&self.calibration, &self.profile, tip_m) else {
            return (ReplyStatus::Unreachable, 0);
        };
        let q = [target.q1_m, target.q2_m, target.q3_m];
        if q.iter()
            .zip(self.config.travel_m.iter())
            .any(|(v, (lo, hi))| !(v >= lo && v <= hi))
        {
            return (ReplyStatus::Unreachable, 0);
        }
        // Above the warn limit, only moves that do not push the tip further
        // along its force are allowed.
        if estimate.guard_state == GuardState::Warn {
            let (TipOutcome::Estimate(e), Some(pose)) = (estimate.tip, estimate.pose) else {
                return (
                    ReplyStatus::TowardForce,
                    reason_code(&estimate.guard_reason),
                );
            };
            if (tip_m - pose.tip_m).dot(&e.force_n) > 0.0 {
                return (
                    ReplyStatus::TowardForce,
                    reason_code(&estimate.guard_reason),
                );
            }
        }
        let limits = self.config.axis_limits;
        let states = trajectory.at(now_ns);
        let mut axes = [AxisPlan::hold(now_ns, 0.0); 3];
        for ((plan, state), target_m) in axes.iter_mut().zip(states).zip(q) {
            *plan = AxisPlan::to_target(now_ns, state, target_m, limits);
        }
        self.trajectory = Some(Trajectory::from_plans(now_ns, axes, Some(*tip_m)));
        (ReplyStatus::Accepted, 0)
    }
}

/// The reply to an estimator command.
fn command_reply(result: &Result<CommandAccepted, CommandRefused>) -> (ReplyStatus, u16) {
    match result {
        Ok(CommandAccepted::NothingToReset) => (ReplyStatus::NothingToReset, 0),
        Ok(_) => (ReplyStatus::Accepted, 0),
        Err(CommandRefused::Reset { reason }) => (ReplyStatus::ResetRefused, reason_code(reason)),
        Err(CommandRefused::NotOk { reason, .. }) => (ReplyStatus::NotOk, reason_code(reason)),
        Err(CommandRefused::AboveWarn { reason }) => (ReplyStatus::AboveWarn, reason_code(reason)),
        Err(CommandRefused::NoEstimate | CommandRefused::Unsolvable) => {
            (ReplyStatus::NoEstimate, 0)
        }
        Err(CommandRefused::Limits { .. }) => (ReplyStatus::LimitsRefused, 0),
        Err(_) => (ReplyStatus::Refused, 0),
    }
}
