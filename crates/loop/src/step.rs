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
//!   [`sar_hal::motion`] under the configured speed and acceleration,
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
//!   stamp, beyond the tolerance, is a Fault ([`Reason::FollowingError`]);
//!   during the drives' own quick stop (a halt begun under a trajectory),
//!   against the quick stop's profile at the configured deceleration
//!   ([`crate::motion::AxesMotion::halt_position`]): a drive that brakes
//!   weaker runs on beyond it and faults.
//! - Retreat (issue 14: the way back from a Stop whose force persists): a
//!   reset above the stop limit puts the guard in `Retreat`; then a move is
//!   accepted only when it reduces the tip force
//!   ([`sar_estimator::guard::reduces_force`]: against the force, or backing
//!   out along the rod, [`Request::BackOut`]), planned at `[axes]
//!   retreat_speed_mps` and streamed to the drives one set point per period
//!   ([`DriveAction::Stream`], cyclic synchronous position), so that they
//!   move at that speed. The guard stops again if the force rises.
//! - The carriage's motion (issue 26, [`crate::motion`]): each cycle the
//!   estimator is handed the velocity and acceleration of the commanded
//!   trajectory through a model of the drives' servo (the drives' own quick
//!   stop during a halt), where the sensor sample was measured. A guarded
//!   move brakes hard (`[axes] brake_decel_mps2`), streamed; the warn
//!   rule's brake stays at the planned deceleration.
//! - An excitation (issue 26, [`Request::Excite`], [`crate::excite`]):
//!   accepted in Ok with the drives enabled and the axes at rest, within
//!   `[identify]`'s limits (its fades' peaks included) and the travel;
//!   streamed one period ahead about
//!   where the axes rest. A Warn, a Stop or a new move ends it (braked from
//!   its position and velocity, or quick-stopped); so does a commanded
//!   speed or acceleration above the limits.
//! - A late cycle is an input, not a fault (issue 33): a cycle that comes
//!   more than a period after the last streamed set point delays the
//!   streamed trajectory by the excess before anything evaluates it
//!   ([`LoopStep::absorb_late_cycle`]), so that its set point follows the
//!   last one by one period of the trajectory's time: the drives, which
//!   held the last set point meanwhile, are never asked for a jump, and the
//!   servo model, which follows the set points as streamed, knows what
//!   they did. A late cycle beyond the sensor's accepted age is the
//!   estimator's `cycle_gap` Fault; the quick stop then starts from the axes
//!   as the model has them, so a reset is accepted once they rest.
//! - A guarded move anticipates its force's rise only once it is in contact
//!   (the force along its way significant against its noise:
//!   [`GUARDED_CONTACT_SIGMA`]), so that noise never brakes it; a limit
//!   within the noise is refused.
//! - A host fault: the publishing thread (the operator's commands and the
//!   published state) without progress for longer than the configured
//!   stall time is a Fault ([`Reason::PublisherStalled`]), from the
//!   recorded `LoopInput::publisher_idle_ns`.
//! - A move reply says accepted only when the move goes to the drives in
//!   the same cycle; every refusal carries its exact cause
//!   ([`ReplyDetail`]).
//!
//! Fixed-size state; no allocation, no panic.

use crate::excite::{Excitation, ExciteLimits, ExciteRefusal, ExciteRequest};
use crate::motion::{AxesMotion, MotionConfig, Told};
use sar_estimator::cycle::{
    Bias, Command, CommandAccepted, CommandRefused, CycleContext, CycleInput, CycleOutput,
    Estimator, EstimatorConfig, FollowingReference, JointSample, SensorSample, TipOutcome,
};
use sar_estimator::filter::{FilterConfig, TipFilter};
use sar_estimator::force_control::{ForceControlConfig, ForceController, ForceMode};
use sar_estimator::guard::{ForceLimits, GuardState, Reason, reduces_force};
use sar_estimator::motion::CarriageMotion;
use sar_estimator::{SettingError, Vec3};
use sar_hal::DriveState;
use sar_hal::motion::{AxisPlan, AxisState, Limits};
use sar_kinematics::{ActiveJoints, Calibration, PoseError, Profile, Shown, inverse};

/// An operator request, applied in the cycle whose input carries it: the
/// command table's (`sar_msgs::command`, where each is declared once).
pub use sar_msgs::command::Request;

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

pub use sar_msgs::wire::ReplyStatus;

/// The exact cause behind a reply: what `sarctl` prints (its `Display`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReplyDetail {
    /// Nothing to add.
    None,
    /// The guard's reason (a refused reset, a halted or warned move).
    Reason(Reason),
    /// Force limits refused: which limit, its value, why.
    Limits {
        /// The limit.
        field: &'static str,
        /// Its value, N.
        value: f64,
        /// What is wrong.
        why: &'static str,
    },
    /// A target outside an axis's travel.
    OutsideTravel {
        /// 1, 2 or 3 (q1, q2, q3).
        axis: u8,
        /// The axis position the target needs, m.
        value_m: f64,
        /// The travel, m.
        min_m: f64,
        /// The travel, m.
        max_m: f64,
    },
    /// The kinematics cannot reach the target.
    NoPose(PoseError),
    /// In Retreat, a move that does not reduce the force.
    NotReducing {
        /// The tip displacement asked for, base frame, m.
        step_m: Vec3,
        /// The tip force, base frame, N.
        force_n: Vec3,
    },
    /// The drives are not enabled (their state, if read).
    DrivesNotEnabled(Option<DriveState>),
    /// The axes still move, m/s.
    AxesMoving {
        /// The largest axis speed, m/s.
        speed_mps: f64,
    },
    /// A back-out distance that is not within 0 < d <= 0.1 m.
    BadDistance {
        /// The distance given, m.
        distance_m: f64,
    },
    /// No tip-force estimate or pose this cycle.
    NoEstimate,
    /// Judged acceptable but not given to the drives.
    NotCarriedOut,
    /// A guarded move's force limit that is not within 0 < N <= the total
    /// stop limit.
    BadMaxForce {
        /// The limit given, N.
        max_force_n: f64,
        /// The total stop limit in use, N.
        stop_n: f64,
    },
    /// A force-control setpoint out of its range.
    BadForce {
        /// The setpoint given, N.
        force_n: f64,
        /// The largest accepted (a warn limit), N.
        max_n: f64,
    },
    /// A force-control mode asked for outside Ok.
    NotInOk(GuardState),
    /// A tare refused by its mean at rest or its rate limit (not at rest
    /// long enough, not steady, too soon after the last). Shown without
    /// CommandRefused's own "tare refused: " (sarctl says it).
    Tare(sar_estimator::cycle::TareRefused),
    /// A guarded move asked for while the tip force already reaches its
    /// limit.
    AlreadyAtForce {
        /// The tip force now (filtered when the filter is on), N.
        force_n: f64,
        /// The move's limit, N.
        max_force_n: f64,
    },
    /// An excitation refused by its parameters or limits
    /// ([`crate::excite::judge`]).
    Excitation(ExciteRefusal),
    /// A guarded move's force limit within the tip force's noise (it would
    /// stop the move on noise).
    WithinNoise {
        /// The limit given, N.
        max_force_n: f64,
        /// [`GUARDED_CONTACT_SIGMA`] times the norm of the force's standard
        /// deviations now, N.
        noise_n: f64,
    },
}

impl ReplyDetail {
    /// The guard's reason code behind it (0 when it is not a guard reason).
    pub fn reason_code(&self) -> u16 {
        match self {
            Self::Reason(r) => r.code(),
            _ => 0,
        }
    }
}

/// The drives' state in words (for a refusal's detail).
fn drive_state_words(s: &DriveState) -> &'static str {
    match s {
        DriveState::Ready => "ready",
        DriveState::Enabled => "enabled",
        DriveState::QuickStop => "in quick stop",
        DriveState::Fault { .. } => "in fault",
    }
}

/// [`ReplyDetail::OutsideTravel`] in words: by how much, beyond which end.
fn outside_travel(
    f: &mut core::fmt::Formatter<'_>,
    axis: u8,
    value_m: f64,
    min_m: f64,
    max_m: f64,
) -> core::fmt::Result {
    let (by_m, end) = if value_m < min_m {
        (min_m - value_m, "below its lower end")
    } else {
        (value_m - max_m, "above its upper end")
    };
    write!(
        f,
        "q{axis} would be {} m, outside its travel {}..{} m ([axes] travel_m) by {} m \
         {end}; sarctl workspace shows the reachable region",
        Shown(value_m),
        Shown(min_m),
        Shown(max_m),
        Shown(by_m)
    )
}

/// [`ReplyDetail::AlreadyAtForce`] in words.
fn already_at_force(
    f: &mut core::fmt::Formatter<'_>,
    force_n: f64,
    max_force_n: f64,
) -> core::fmt::Result {
    write!(
        f,
        "the tip force is already {force_n:.2} N, at or above the move's {} N",
        Shown(max_force_n)
    )
}

/// [`ReplyDetail::WithinNoise`] in words.
fn within_noise(
    f: &mut core::fmt::Formatter<'_>,
    max_force_n: f64,
    noise_n: f64,
) -> core::fmt::Result {
    write!(
        f,
        "the guarded move's force {} N is within the tip force's noise here ({} N, {} \
         standard deviations): it would stop on noise; give a larger force",
        Shown(max_force_n),
        Shown(noise_n),
        Shown(GUARDED_CONTACT_SIGMA)
    )
}

impl core::fmt::Display for ReplyDetail {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::None => Ok(()),
            Self::Reason(r) => write!(f, "{r}"),
            Self::Limits { field, value, why } => write!(f, "{field} = {} N: {why}", Shown(*value)),
            Self::OutsideTravel {
                axis,
                value_m,
                min_m,
                max_m,
            } => outside_travel(f, *axis, *value_m, *min_m, *max_m),
            Self::NoPose(e) => write!(
                f,
                "no pose of the rod through the support reaches it: {e} (sarctl workspace \
                 shows the reachable region)"
            ),
            Self::NotReducing { step_m, force_n } => write!(
                f,
                "in retreat only motions against the tip force ({:.2}, {:.2}, {:.2}) N or back \
                 along the rod are accepted; this one moves the tip by ({:.4}, {:.4}, {:.4}) m",
                force_n.x, force_n.y, force_n.z, step_m.x, step_m.y, step_m.z
            ),
            Self::DrivesNotEnabled(state) => match state {
                Some(s) => write!(f, "the drives are {}, not enabled", drive_state_words(s)),
                None => f.write_str("the drives' state could not be read"),
            },
            Self::AxesMoving { speed_mps } => write!(
                f,
                "the axes still move at {:.1} mm/s (wait until they are at rest)",
                speed_mps * 1e3
            ),
            Self::BadDistance { distance_m } => write!(
                f,
                "the back-out distance must be within 0 < d <= {} m, got {} m",
                Shown(MAX_BACK_OUT_M),
                Shown(*distance_m)
            ),
            Self::NoEstimate => f.write_str("no tip-force estimate or pose in this cycle"),
            Self::NotCarriedOut => f.write_str("the move could not be given to the drives"),
            Self::BadMaxForce {
                max_force_n,
                stop_n,
            } => write!(
                f,
                "the guarded move's force must be within 0 < N <= {} N (the total stop limit), got {} N",
                Shown(*stop_n),
                Shown(*max_force_n)
            ),
            Self::BadForce { force_n, max_n } => write!(
                f,
                "the force must be within 0 < N < {} N (a warn limit), got {} N",
                Shown(*max_n),
                Shown(*force_n)
            ),
            Self::Tare(refusal) => write!(f, "{refusal}"),
            Self::NotInOk(state) => write!(
                f,
                "force control starts only in Ok (the guard is {state:?})"
            ),
            Self::AlreadyAtForce {
                force_n,
                max_force_n,
            } => already_at_force(f, *force_n, *max_force_n),
            Self::Excitation(refusal) => write!(f, "{refusal}"),
            Self::WithinNoise {
                max_force_n,
                noise_n,
            } => within_noise(f, *max_force_n, *noise_n),
        }
    }
}

/// Below this speed (on every axis, between two joint samples) the axes are
/// at rest for a reset, m/s (well above the encoders' quantisation over one
/// period, well below any planned move).
pub const REST_SPEED_MPS: f64 = 0.002;

/// The guarded force's rate is low-passed over this fraction of the
/// filter's lag.
pub const RATE_LAG_FRACTION: f64 = 0.125;

/// The longest back-out a single request may ask for, m.
pub const MAX_BACK_OUT_M: f64 = 0.1;

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
                    | Request::Excite(_),
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
    /// The speed of moves in Retreat, m/s (> 0, at most the axes' speed).
    pub retreat_speed_mps: f64,
    /// The loop's period, ns: streamed set points are one period ahead.
    pub period_ns: u64,
    /// The publishing thread without progress for longer than this is a
    /// Fault, ns.
    pub publisher_stall_ns: u64,
    /// Force control's settings (`[force_control]`).
    pub force_control: ForceControlConfig,
    /// The drives as the loop models them: their servo, quick stop, and a
    /// guarded move's brake ([`crate::motion`]).
    pub motion: MotionConfig,
    /// An excitation's limits (`[identify]`, issue 26).
    pub excite: ExciteLimits,
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
    /// Streamed to the drives one set point per period (retreat moves at a
    /// reduced speed) rather than given as an end point.
    streamed: bool,
    /// A guarded move's force limit, N (braked when the force is
    /// anticipated to reach it).
    max_force_n: Option<f64>,
    /// An excitation under way: then it is the trajectory (`axes` hold
    /// its centre).
    excite: Option<Excitation>,
}

impl Trajectory {
    fn hold(now_ns: u64, q: &ActiveJoints) -> Self {
        Self {
            axes: joints_array(q).map(|x| AxisPlan::hold(now_ns, x)),
            target_tip_m: None,
            end_ns: now_ns,
            streamed: false,
            max_force_n: None,
            excite: None,
        }
    }

    fn at(&self, t_ns: u64) -> [AxisState; 3] {
        match &self.excite {
            Some(e) => e.at(t_ns).0,
            None => self.axes.map(|p| p.at(t_ns)),
        }
    }

    fn position(&self, t_ns: u64) -> ActiveJoints {
        let [a, b, c] = self.at(t_ns);
        ActiveJoints {
            q1_m: a.x_m,
            q2_m: b.x_m,
            q3_m: c.x_m,
        }
    }

    /// The same trajectory `dt_ns` later (issue 33): what a streamed
    /// trajectory becomes when the loop comes late, so that the late
    /// cycle's set point follows the last one by one period of the
    /// trajectory's time and never jumps by the time the loop was late.
    fn delay(&mut self, dt_ns: u64) {
        self.axes = self.axes.map(|p| p.delayed(dt_ns));
        self.end_ns = self.end_ns.saturating_add(dt_ns);
        if let Some(e) = &mut self.excite {
            e.start_ns = e.start_ns.saturating_add(dt_ns);
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
            streamed: false,
            max_force_n: None,
            excite: None,
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
    /// The drives' state in the previous cycle (a new drive fault is a
    /// guard Fault in the cycle it appears).
    last_drive_state: Option<DriveState>,
    /// The last guarded move's stop.
    guarded_stop: Option<GuardedStop>,
    /// The guarded force's magnitude at the last new sensor sample (its
    /// counter, N) and its rate since the sample before, N/s.
    guarded_last: Option<(u32, f64)>,
    guarded_rate_n_per_s: f64,
    /// The guarded force's filter: its group delay and sample period, s
    /// (0 and the sensor's period without a filter).
    guarded_lag_s: f64,
    sample_period_s: f64,
    /// Force control (its filter runs in every cycle; a mode when active).
    force: ForceController,
    /// How the axes move: the servo model, the drives' quick stop.
    motion: AxesMotion,
    /// The clock of the last cycle, if it streamed a set point: a streamed
    /// trajectory's time runs from it (issue 33, [`LoopStep::absorb_late_cycle`]).
    last_stream_ns: Option<u64>,
    out: LoopOutput,
    /// The fingerprint of the configuration parts, for snapshots (computed
    /// at construction: the configuration never changes after it).
    snapshot_fingerprint: u64,
}

/// A reply's status and its exact cause.
type Answer = (ReplyStatus, ReplyDetail);

/// What a cycle has decided so far (the step's phases fill it in).
#[derive(Debug, Clone, Copy)]
struct Decision {
    /// What the drives are told.
    action: DriveAction,
    /// The reply to the cycle's request.
    reply: Option<Answer>,
    /// A new plan (a move, or a brake) whose end point goes to the drives.
    planned: bool,
    /// An accepted move's replaced trajectory (restored when the move does
    /// not go to the drives in this cycle).
    undo_move: Option<Option<Trajectory>>,
    /// The carriage's motion handed to the estimator.
    motion: CarriageMotion,
}

/// Why a reset is held back from the estimator in this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum HeldReset {
    /// The drives are in Fault: their fault is reset first (their positions
    /// are invalid until then, so the guard cannot judge the reset).
    DrivesFaulted,
    /// The axes still move: the reset waits until they are at rest.
    AxesMoving,
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

impl StepConfig {
    /// The loop's settings checked one by one (the first out of range is
    /// the error).
    fn check(&self) -> Result<(), StepConfigError> {
        let invalid = |field, value, why| StepConfigError::Invalid { field, value, why };
        let l = self.axis_limits;
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
        let t = self.following_tolerance_m;
        if !(t.is_finite() && t > 0.0) {
            return Err(invalid(
                "following_tolerance_m",
                t,
                "must be finite and > 0",
            ));
        }
        for &(lo, hi) in &self.travel_m {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid("travel_m", lo, "must be finite with min < max"));
            }
        }
        let r = self.retreat_speed_mps;
        if !(r.is_finite() && r > 0.0 && r <= l.max_speed_mps) {
            return Err(invalid(
                "retreat_speed_mps",
                r,
                "must be finite, > 0 and at most max_speed_mps",
            ));
        }
        if self.period_ns == 0 {
            return Err(invalid("period_ns", 0.0, "must be > 0"));
        }
        if self.publisher_stall_ns == 0 {
            return Err(invalid("publisher_stall_ns", 0.0, "must be > 0"));
        }
        self.motion
            .check(l.max_accel_mps2)
            .map_err(|(field, value, why)| invalid(field, value, why))
    }
}

/// The guarded force's filter: its group delay and sample period, s. The
/// estimator has checked the filter; refused here the same way. No filter:
/// the guarded force is the estimate, whose rate is its noise; no
/// anticipation (a period of 0 marks it).
fn guarded_filter(filter: Option<FilterConfig>) -> Result<(f64, f64), StepConfigError> {
    let Some(f) = filter else {
        return Ok((0.0, 0.0));
    };
    match TipFilter::new(f) {
        Ok(t) => Ok((t.group_delay_s(), f.sample_period_s)),
        Err(_) => Err(StepConfigError::Invalid {
            field: "filter_cutoff_hz",
            value: f.cutoff_hz,
            why: "not a valid filter of the sensor's samples",
        }),
    }
}

impl LoopOutput {
    /// The output before the first cycle: the estimator's, nothing decided.
    fn first(estimator: &Estimator) -> Self {
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
        }
    }
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
        config.check()?;
        let (calibration, profile) = (estimator.calibration, estimator.profile);
        let filter = estimator.filter;
        let estimator = Estimator::with_bias(estimator, bias)?;
        let (guarded_lag_s, sample_period_s) = guarded_filter(filter)?;
        let out = LoopOutput::first(&estimator);
        let mut step = Self {
            calibration,
            profile,
            estimator,
            config,
            trajectory: None,
            last_joints: None,
            speed_mps: 0.0,
            last_drive_state: None,
            guarded_stop: None,
            guarded_last: None,
            guarded_rate_n_per_s: 0.0,
            guarded_lag_s,
            sample_period_s,
            force: ForceController::new(config.force_control)?,
            motion: AxesMotion::default(),
            last_stream_ns: None,
            out,
            snapshot_fingerprint: 0,
        };
        // Hashed once here, not on the loop at every snapshot.
        step.snapshot_fingerprint = sar_snapshot::fingerprint(&step);
        Ok(step)
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
        // A late cycle: the streamed trajectory waits for it.
        self.absorb_late_cycle(input);
        // Gather: what the estimator judges (a held reset is not passed on).
        let reference = self.following_reference(input);
        self.measure_speed(&input.joints);
        let held = self.held_reset(input);
        let mut cycle_input = input.cycle_input();
        if held.is_some() {
            cycle_input.command = None;
        }
        let host_fault = self.host_fault(input);
        let motion = self.carriage_motion(input);
        let plans_before = self.trajectory.map(|t| t.axes);
        // Judge: the estimator and its guard.
        let context = CycleContext {
            reference,
            host_fault,
            motion,
        };
        let estimate = *self.estimator.cycle(&cycle_input, &context);
        // Decide: the answer to the guard, then to the request, force
        // control's period, a brake.
        let mut d = Decision {
            action: self.halt(input, &estimate, held),
            reply: held.map(|h| self.held_reply(h, input)),
            planned: false,
            undo_move: None,
            motion,
        };
        self.command_outcome(input, &estimate, &mut d);
        self.observe_force(input, &estimate);
        self.answer_request(input, &estimate, &mut d);
        if self.force.mode().is_some() && !estimate.guard_state.is_halting() {
            self.force_period(input, &estimate);
        }
        self.update_guarded_rate(input, &estimate);
        d.planned |= self.brake_if_due(input, &estimate);
        self.end_excitation_if_due(input, &estimate);
        // Act: what the drives are told of the trajectory.
        self.motion_action(input, &estimate, &mut d);
        self.undo_move_not_carried_out(&mut d);
        if let Some(now_ns) = input.now_ns {
            let period_ns = self.config.period_ns;
            let told = match d.action {
                DriveAction::Stream(q) => Told::Streamed(joints_array(&q)),
                DriveAction::None | DriveAction::FaultReset => Told::Nothing,
                DriveAction::Setpoint(_) | DriveAction::QuickStop | DriveAction::Release(_) => {
                    Told::Other
                }
            };
            self.motion
                .commanded(told, now_ns, plans_before.as_ref(), period_ns);
        }
        self.last_stream_ns = match d.action {
            DriveAction::Stream(_) => input.now_ns,
            _ => None,
        };
        self.finish(estimate, reference, d)
    }

    /// A cycle later than one period after the last streamed set point:
    /// the streamed trajectory is delayed by the excess, before anything
    /// evaluates it, so that this cycle's set point is one period of its
    /// time after the last one (the drives held that one meanwhile, as the
    /// servo model knows: it follows the set points as streamed). The
    /// set points never jump by the time the loop was late; the trajectory
    /// ends that much later. An early cycle delays nothing (its set point
    /// comes less than a period after the last: slower, never faster).
    fn absorb_late_cycle(&mut self, input: &LoopInput) {
        let (Some(last_ns), Some(now_ns)) = (self.last_stream_ns, input.now_ns) else {
            return;
        };
        let late_ns = now_ns
            .saturating_sub(last_ns)
            .saturating_sub(self.config.period_ns);
        if let Some(t) = &mut self.trajectory
            && t.streamed
            && late_ns > 0
        {
            t.delay(late_ns);
        }
    }

    /// The carriage's motion where the sensor sample was measured (its
    /// stamp less the sensor's latency), from the trajectory commanded so
    /// far and the drives' quick stop ([`crate::motion`]).
    fn carriage_motion(&mut self, input: &LoopInput) -> CarriageMotion {
        if let Some(m) = self.excitation_motion(input) {
            return m;
        }
        let plans = self.trajectory.as_ref().map(|t| &t.axes);
        self.motion.motion(
            &self.config.motion,
            self.config.axis_limits.max_accel_mps2,
            plans,
            input.drive_state,
            input
                .sensor
                .stamp_ns
                .saturating_sub(self.config.motion.sensor_latency_ns),
            self.speed_mps <= REST_SPEED_MPS,
        )
    }

    /// An excitation's own motion for ideal drives (no servo model, which
    /// otherwise follows its streamed set points), at the sensor sample's
    /// instant; `None` otherwise.
    fn excitation_motion(&self, input: &LoopInput) -> Option<CarriageMotion> {
        let e = self.trajectory?.excite?;
        let ideal = self.config.motion.servo_wn_rad_s() <= 0.0;
        let enabled = input.drive_state == Some(DriveState::Enabled);
        let stamp_ns = (input.sensor.stamp_ns).saturating_sub(self.config.motion.sensor_latency_ns);
        (ideal && enabled && self.motion.halt.is_none()).then(|| e.carriage_motion(stamp_ns))
    }

    /// The trajectory at the joint sample's stamp, which the estimator
    /// checks the joints against (following error), or during the drives'
    /// quick stop its profile; none without either or a valid sample.
    fn following_reference(&self, input: &LoopInput) -> Option<FollowingReference> {
        let tolerance_m = self.config.following_tolerance_m;
        if !input.joints.valid {
            return None;
        }
        let stamp_ns = input.joints.stamp_ns;
        if let Some(t) = self.trajectory {
            return Some(FollowingReference {
                joints: t.position(stamp_ns),
                tolerance_m,
            });
        }
        // During the drives' own quick stop: its profile at the configured
        // deceleration (a drive that brakes weaker runs on beyond it).
        if input.drive_state != Some(DriveState::QuickStop) {
            return None;
        }
        self.motion
            .halt_position(stamp_ns)
            .map(|[q1_m, q2_m, q3_m]| FollowingReference {
                joints: ActiveJoints { q1_m, q2_m, q3_m },
                tolerance_m,
            })
    }

    /// The axes' speed, from the last two valid joint samples.
    fn measure_speed(&mut self, joints: &JointSample) {
        let q = &joints.joints;
        if joints.valid && [q.q1_m, q.q2_m, q.q3_m].iter().all(|v| v.is_finite()) {
            if let Some((p, stamp_ns)) = self.last_joints
                && joints.stamp_ns > stamp_ns
            {
                let dt_s = (joints.stamp_ns - stamp_ns) as f64 * 1e-9;
                self.speed_mps = [q.q1_m - p.q1_m, q.q2_m - p.q2_m, q.q3_m - p.q3_m]
                    .iter()
                    .fold(0.0, |m: f64, d| m.max(d.abs() / dt_s));
            }
            self.last_joints = Some((*q, joints.stamp_ns));
        }
    }

    /// Whether the cycle's reset is held back from the estimator: with the
    /// drives in Fault (their fault is reset first), or while the axes move.
    fn held_reset(&self, input: &LoopInput) -> Option<HeldReset> {
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
    fn held_reply(&self, held: HeldReset, input: &LoopInput) -> Answer {
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

    /// The host's own faults: the publishing thread stalled; the drives
    /// entering Fault (latched by the guard in that cycle only: the reset
    /// that leaves it is what resets the drives). Remembers the drives'
    /// state for the next cycle.
    fn host_fault(&mut self, input: &LoopInput) -> Option<Reason> {
        let drive_fault = match (self.last_drive_state, input.drive_state) {
            (Some(DriveState::Fault { .. }), _) => None,
            (_, Some(DriveState::Fault { axis, code })) => Some(Reason::DriveFault {
                axis: axis.map_or(0, |a| a.saturating_add(1)),
                code,
            }),
            _ => None,
        };
        self.last_drive_state = input.drive_state;
        (input.publisher_idle_ns > self.config.publisher_stall_ns)
            .then(|| Reason::PublisherStalled {
                stalled_ms: u32::try_from(input.publisher_idle_ns / 1_000_000).unwrap_or(u32::MAX),
            })
            .or(drive_fault)
    }

    /// In Stop or Fault the trajectory is dropped and the drives get a
    /// quick stop in the cycle that enters it and whenever they report
    /// `Enabled`; else, for a reset held by their fault, a fault reset.
    fn halt(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        held: Option<HeldReset>,
    ) -> DriveAction {
        if !estimate.guard_state.is_halting() {
            return DriveAction::None;
        }
        let plans = self.trajectory.take().map(|t| t.axes);
        let entered_halt = estimate.transition.is_some_and(|t| t.to.is_halting());
        if entered_halt || input.drive_state == Some(DriveState::Enabled) {
            if let Some(now_ns) = input.now_ns {
                self.motion
                    .start_halt(&self.config.motion, plans.as_ref(), now_ns);
            }
            DriveAction::QuickStop
        } else if held == Some(HeldReset::DrivesFaulted) {
            DriveAction::FaultReset
        } else {
            DriveAction::None
        }
    }

    /// The estimator's command event is the reply; an accepted reset
    /// releases the drives (the way depends on their state) and holds the
    /// axes where they were measured.
    fn command_outcome(&mut self, input: &LoopInput, estimate: &CycleOutput, d: &mut Decision) {
        let Some(ev) = estimate.command else {
            return;
        };
        d.reply = Some(command_reply(&ev.result));
        if matches!(ev.result, Ok(CommandAccepted::Reset)) {
            d.action = release(input.drive_state);
            self.motion.restart();
            self.trajectory = match (input.now_ns, input.joints.valid) {
                (Some(now_ns), true) => Some(Trajectory::hold(now_ns, &input.joints.joints)),
                _ => None,
            };
        }
    }

    /// Force control's filter sees every cycle's estimate; a halt or a
    /// Retreat ends any mode at once.
    fn observe_force(&mut self, input: &LoopInput, estimate: &CycleOutput) {
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

    /// Answers the loop's own requests: force control and moves (the
    /// estimator's commands are answered by their event).
    fn answer_request(&mut self, input: &LoopInput, estimate: &CycleOutput, d: &mut Decision) {
        let target = match input.request {
            Some(Request::Hold { max_force_n }) => {
                d.reply = Some(self.start_force(input, estimate, ForceMode::Hold { max_force_n }));
                return;
            }
            Some(Request::Push { axial_n }) => {
                d.reply = Some(self.start_force(input, estimate, ForceMode::Push { axial_n }));
                return;
            }
            Some(Request::Position) => {
                self.end_force(input.now_ns);
                d.reply = Some((ReplyStatus::Accepted, ReplyDetail::None));
                return;
            }
            Some(Request::Excite(r)) => {
                let before = self.trajectory;
                let answer = self.start_excitation(input, estimate, &r);
                if answer.0 == ReplyStatus::Accepted {
                    d.undo_move = Some(before);
                }
                d.reply = Some(answer);
                return;
            }
            Some(Request::MoveTip { tip_m }) => MoveTarget::Tip(tip_m, None),
            Some(Request::GuardedMove { tip_m, max_force_n }) => {
                MoveTarget::Tip(tip_m, Some(max_force_n))
            }
            Some(Request::BackOut { distance_m }) => MoveTarget::BackOut(distance_m),
            Some(Request::Reset | Request::Tare | Request::SetLimits(_)) | None => return,
        };
        let before_move = self.trajectory;
        let answer = self.plan_move(input, estimate, target);
        // An accepted move ends force control (it was planned from the last
        // set point); a refused one leaves the mode as it was.
        if answer.0 == ReplyStatus::Accepted {
            d.undo_move = Some(before_move);
            d.planned = true;
            self.force.stop();
        }
        d.reply = Some(answer);
    }

    /// The force-control mode's period: the law's commanded tip, through
    /// the inverse kinematics, streamed to the drives (one set point per
    /// period, which the following check then holds the axes to). Under the
    /// warn rule no motion goes deeper along the force. No estimate, no
    /// pose or an unreachable tip ends the mode, holding the last set point.
    fn force_period(&mut self, input: &LoopInput, estimate: &CycleOutput) {
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
                self.trajectory = Some(t);
            }
            None => self.end_force(input.now_ns),
        }
    }

    /// The guarded force's rate, per new sensor sample.
    fn update_guarded_rate(&mut self, input: &LoopInput, estimate: &CycleOutput) {
        match guarded_force(estimate).filter(|_| self.sample_period_s > 0.0) {
            Some((f, _)) => {
                let counter = input.sensor.counter;
                let m = f.norm();
                match self.guarded_last {
                    Some((c, last)) if c != counter => {
                        // Low-passed over an eighth of the filter's lag (a
                        // difference of one sample is mostly noise; over the
                        // whole lag, the rate comes too late on a stiff
                        // tissue, whose force rises within that lag).
                        let dt_s = f64::from(counter.wrapping_sub(c)) * self.sample_period_s;
                        let alpha = dt_s / (dt_s + RATE_LAG_FRACTION * self.guarded_lag_s);
                        self.guarded_rate_n_per_s +=
                            alpha * ((m - last) / dt_s - self.guarded_rate_n_per_s);
                        self.guarded_last = Some((counter, m));
                    }
                    Some(_) => {}
                    None => {
                        self.guarded_rate_n_per_s = 0.0;
                        self.guarded_last = Some((counter, m));
                    }
                }
            }
            None => {
                self.guarded_last = None;
                self.guarded_rate_n_per_s = 0.0;
            }
        }
    }

    /// Brakes a move under way whose force stops it: a guarded move's force
    /// anticipated to reach its limit, or, under the warn rule, a move
    /// toward a tip further along the force. A guarded move braked either
    /// way records where and at what force. `true` when braked (a new plan).
    fn brake_if_due(&mut self, input: &LoopInput, estimate: &CycleOutput) -> bool {
        let (Some(t), Some(now_ns), Some(pose)) = (self.trajectory, input.now_ns, estimate.pose)
        else {
            return false;
        };
        if now_ns >= t.end_ns {
            return false;
        }
        let guarded = self.guarded_limit_reached(&t, now_ns, estimate);
        let Some(force_n) =
            guarded.or_else(|| pushes_along_warned_force(&t, &pose.tip_m, estimate))
        else {
            return false;
        };
        self.brake(&t, now_ns, guarded.is_some());
        if let Some(max_force_n) = t.max_force_n {
            self.guarded_stop = Some(GuardedStop {
                cycle: input.cycle,
                tip_m: pose.tip_m,
                force_n,
                max_force_n,
            });
        }
        true
    }

    /// A guarded move's force, when it is anticipated to reach the move's
    /// limit: the magnitude of the filtered tip force when the filter is on
    /// (the unfiltered one's noise would stop it early at random), plus its
    /// rise over the filter's lag, the drives' lag (`2 zeta / wn`) and the
    /// braking (at `brake_decel_mps2`, v / 2a at the mean speed), once the
    /// move is in contact ([`in_contact`]).
    fn guarded_limit_reached(
        &self,
        t: &Trajectory,
        now_ns: u64,
        estimate: &CycleOutput,
    ) -> Option<Vec3> {
        let max_force_n = t.max_force_n?;
        let (force_n, std_n) = guarded_force(estimate)?;
        let speed_mps = t
            .at(now_ns)
            .iter()
            .fold(0.0, |m: f64, s| m.max(s.v_mps.abs()));
        let drives = &self.config.motion;
        let horizon_s =
            self.guarded_lag_s + drives.servo_lag_s() + speed_mps / (2.0 * drives.brake_decel_mps2);
        let m = force_n.norm();
        let contact = estimate
            .pose
            .zip(t.target_tip_m)
            .is_some_and(|(pose, target)| {
                in_contact(&force_n, &std_n, &(target - pose.tip_m), max_force_n)
            });
        let rise_n = if contact {
            self.guarded_rate_n_per_s.max(0.0) * horizon_s
        } else {
            0.0
        };
        (m + rise_n >= max_force_n).then_some(force_n)
    }

    /// The one brake: the trajectory under way stopped from where it is at
    /// `now_ns`: `hard` (a guarded move's force) at `[axes]
    /// brake_decel_mps2`, streamed to the drives (their own planner runs the
    /// planned acceleration); else (the warn rule) at the planned
    /// deceleration, streamed if the move was.
    fn brake(&mut self, t: &Trajectory, now_ns: u64, hard: bool) {
        let mut limits = self.config.axis_limits;
        if hard {
            limits.max_accel_mps2 = self.config.motion.brake_decel_mps2;
        }
        let axes = t.at(now_ns).map(|s| AxisPlan::brake(now_ns, s, limits));
        let mut braked = Trajectory::from_plans(now_ns, axes, None);
        braked.streamed = t.streamed || hard;
        self.trajectory = Some(braked);
    }

    /// What the drives are told of the trajectory when nothing else is said
    /// to them (not halting, the drives enabled): a streamed trajectory one
    /// period ahead, every cycle until the period after its end; a new plan
    /// its end point, once.
    fn motion_action(&self, input: &LoopInput, estimate: &CycleOutput, d: &mut Decision) {
        let enabled = input.drive_state == Some(DriveState::Enabled);
        if !estimate.guard_state.is_halting()
            && d.action == DriveAction::None
            && enabled
            && let (Some(t), Some(now_ns)) = (self.trajectory, input.now_ns)
        {
            if t.streamed {
                let ahead_ns = now_ns.saturating_add(self.config.period_ns);
                if now_ns <= t.end_ns.saturating_add(self.config.period_ns) {
                    d.action = DriveAction::Stream(t.position(ahead_ns));
                }
            } else if d.planned {
                let [q1_m, q2_m, q3_m] = t.axes.map(|p| p.end_m());
                d.action = DriveAction::Setpoint(ActiveJoints { q1_m, q2_m, q3_m });
            }
        }
    }

    /// "Accepted" only for a move that goes to the drives now: else the
    /// trajectory it replaced is restored and the reply says so.
    fn undo_move_not_carried_out(&mut self, d: &mut Decision) {
        if let Some(before_move) = d.undo_move
            && !matches!(d.action, DriveAction::Setpoint(_) | DriveAction::Stream(_))
        {
            self.trajectory = before_move;
            d.reply = Some((ReplyStatus::NotCarriedOut, ReplyDetail::NotCarriedOut));
        }
    }

    /// The cycle's output, readable as [`LoopStep::last`].
    fn finish(
        &mut self,
        estimate: CycleOutput,
        reference: Option<FollowingReference>,
        d: Decision,
    ) -> &LoopOutput {
        let reply = d.reply;
        let (reply, reply_detail) = match reply {
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
        };
        &self.out
    }

    /// Starts a force-control mode (Ok only, the drives enabled, the axes at
    /// rest, a filtered force to act on; the setpoint below its warn limit).
    fn start_force(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        mode: ForceMode,
    ) -> (ReplyStatus, ReplyDetail) {
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
        if estimate.guard_state != GuardState::Ok {
            return (
                ReplyStatus::NotOk,
                ReplyDetail::NotInOk(estimate.guard_state),
            );
        }
        if input.drive_state != Some(DriveState::Enabled) {
            return (
                ReplyStatus::DrivesRefused,
                ReplyDetail::DrivesNotEnabled(input.drive_state),
            );
        }
        if self.speed_mps > REST_SPEED_MPS {
            return (
                ReplyStatus::AxesMoving,
                ReplyDetail::AxesMoving {
                    speed_mps: self.speed_mps,
                },
            );
        }
        let (Some(pose), Some(_)) = (estimate.pose, self.force.filtered_force_n()) else {
            return (ReplyStatus::NoEstimate, ReplyDetail::NoEstimate);
        };
        self.force.start(mode, pose.tip_m);
        (ReplyStatus::Accepted, ReplyDetail::None)
    }

    /// Starts an excitation ([`crate::excite`]): Ok only, the drives
    /// enabled, the axes at rest; within `[identify]`'s limits and the
    /// travel about where they rest. It ends force control.
    fn start_excitation(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        request: &ExciteRequest,
    ) -> Answer {
        use ReplyStatus::Halted;
        let halted = estimate.guard_state.is_halting();
        let (Some(from), Some(now_ns), false) = (self.trajectory, input.now_ns, halted) else {
            return (Halted, ReplyDetail::Reason(estimate.guard_reason));
        };
        if estimate.guard_state != GuardState::Ok {
            return (
                ReplyStatus::NotOk,
                ReplyDetail::NotInOk(estimate.guard_state),
            );
        }
        if input.drive_state != Some(DriveState::Enabled) {
            return (
                ReplyStatus::DrivesRefused,
                ReplyDetail::DrivesNotEnabled(input.drive_state),
            );
        }
        let planned_mps = from
            .at(now_ns)
            .iter()
            .fold(0.0, |m: f64, s| m.max(s.v_mps.abs()));
        let speed_mps = self.speed_mps.max(planned_mps);
        if speed_mps > REST_SPEED_MPS || planned_mps > 0.0 {
            return (
                ReplyStatus::AxesMoving,
                ReplyDetail::AxesMoving { speed_mps },
            );
        }
        let centre_m = joints_array(&from.position(now_ns));
        let c = &self.config;
        if let Err(refusal) = crate::excite::judge(request, &centre_m, &c.travel_m, &c.excite) {
            return excite_refused(refusal);
        }
        let excite = Excitation {
            request: *request,
            centre_m,
            start_ns: now_ns,
        };
        let mut t = Trajectory::hold(now_ns, &from.position(now_ns));
        t.end_ns = excite.end_ns();
        t.streamed = true;
        t.excite = Some(excite);
        self.trajectory = Some(t);
        self.force.stop();
        (ReplyStatus::Accepted, ReplyDetail::None)
    }

    /// An excitation under way is braked (from its position and velocity,
    /// at the planned deceleration) under a Warn or when its commanded
    /// speed or acceleration is above the limits; at its end it becomes a
    /// hold at its centre.
    fn end_excitation_if_due(&mut self, input: &LoopInput, estimate: &CycleOutput) {
        let (Some(t), Some(now_ns)) = (self.trajectory, input.now_ns) else {
            return;
        };
        let Some(e) = t.excite else {
            return;
        };
        if now_ns >= t.end_ns {
            let mut hold = Trajectory::hold(now_ns, &t.position(now_ns));
            (hold.streamed, hold.end_ns) = (true, t.end_ns);
            self.trajectory = Some(hold);
        } else if estimate.guard_state == GuardState::Warn
            || !e.within_limits(now_ns, &self.config.excite)
        {
            self.brake(&t, now_ns, false);
        }
    }

    /// Ends force control, holding the last set point.
    fn end_force(&mut self, now_ns: Option<u64>) {
        if self.force.mode().is_none() {
            return;
        }
        self.force.stop();
        if let (Some(t), Some(now_ns)) = (self.trajectory, now_ns) {
            let mut hold = Trajectory::hold(now_ns, &t.position(now_ns));
            hold.streamed = t.streamed;
            self.trajectory = Some(hold);
        }
    }

    /// The axes for a tip, within their travel.
    fn reachable(&self, tip_m: &Vec3) -> Result<ActiveJoints, ReplyDetail> {
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

    /// Judges a move and, if accepted, plans it from where the trajectory is
    /// now (in Retreat: only a move that reduces the force, at the retreat
    /// speed, streamed).
    fn plan_move(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        target: MoveTarget,
    ) -> Answer {
        match self.judge_move(input, estimate, target) {
            Ok(accepted) => {
                self.trajectory = Some(self.planned_move(&accepted, estimate));
                (ReplyStatus::Accepted, ReplyDetail::None)
            }
            Err(refused) => refused,
        }
    }

    /// Judges a move: not halted, with a trajectory to start from, the
    /// drives enabled, the target's tip (a guarded move's limit checked)
    /// reachable within the travel, and its direction allowed (the warn
    /// rule, Retreat).
    fn judge_move(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        target: MoveTarget,
    ) -> Result<AcceptedMove, Answer> {
        let halted = estimate.guard_state.is_halting();
        let (Some(from), Some(now_ns), false) = (self.trajectory, input.now_ns, halted) else {
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
fn no_deeper_along(estimate: &CycleOutput) -> Result<Option<Vec3>, ()> {
    match (warned_by_force(estimate), &estimate.tip) {
        (false, _) => Ok(None),
        (true, TipOutcome::Estimate(e)) => Ok(Some(e.force_n)),
        (true, _) => Err(()),
    }
}

/// Under the warn rule, a move under way toward a tip further along the
/// tip force (from `tip_m`, the tip now): that force.
fn pushes_along_warned_force(t: &Trajectory, tip_m: &Vec3, estimate: &CycleOutput) -> Option<Vec3> {
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
fn judge_direction(estimate: &CycleOutput, tip_m: &Vec3) -> Result<(), Answer> {
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
fn back_out_tip(estimate: &CycleOutput, distance_m: f64) -> Result<Vec3, Answer> {
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

/// How the drives are released after an accepted reset, from their state.
fn release(drive_state: Option<DriveState>) -> DriveAction {
    match drive_state {
        Some(DriveState::QuickStop) => DriveAction::Release(Release::DisableEnable),
        Some(DriveState::Fault { .. }) => DriveAction::Release(Release::FaultResetEnable),
        Some(DriveState::Ready) => DriveAction::Release(Release::Enable),
        _ => DriveAction::None,
    }
}

/// The tip force a guarded move watches and its standard deviation per
/// axis: the filtered one when the filter is on, else this cycle's
/// estimate; `None` without either.
fn guarded_force(estimate: &CycleOutput) -> Option<(Vec3, Vec3)> {
    match (estimate.filtered, estimate.tip) {
        (Some(f), _) => Some((f.force_n, f.std_n)),
        (None, TipOutcome::Estimate(e)) => Some((e.force_n, e.std_n)),
        (None, _) => None,
    }
}

/// The significance, in standard deviations, at which a guarded move's
/// force along its way says that it is in contact, and its anticipated rise
/// counts (issue 33 section 3; [`in_contact`]).
pub const GUARDED_CONTACT_SIGMA: f64 = 6.0;

/// Whether a guarded move whose tip still has `to_target_m` to go is in
/// contact: the tip force's component along its way (what a passive tissue
/// it drives into pushes back with: the tip does work on it, `F . v > 0`) at
/// least a quarter of the move's limit and [`GUARDED_CONTACT_SIGMA`] of that
/// component's standard deviation (bounded by `sum |u_i| std_i`, whatever
/// the axes' correlation). Before it, the force's rate (its noise's
/// derivative, amplified by the horizon) anticipates nothing: in free air
/// the component is the filtered noise, a Gaussian process that crosses
/// `z sigma` upwards `f_c exp(-z^2 / 2)` times per second (Rice; for the
/// second-order Butterworth the ratio of the derivative's deviation to the
/// process's is `2 pi f_c`): at the 5 Hz filter and z = 6, 7.6e-8 per
/// second, 2.7e-4 per hour of guarded moves, and a crossing is needed, not
/// sufficient, to brake. The level alone (`|F| >= N`) brakes in any case.
fn in_contact(force_n: &Vec3, std_n: &Vec3, to_target_m: &Vec3, max_force_n: f64) -> bool {
    let distance_m = to_target_m.norm();
    // Arrived (or no finite way): no direction to be in contact along.
    if distance_m.is_nan() || distance_m <= 0.0 {
        return false;
    }
    let way = to_target_m / distance_m;
    let along_n = force_n.dot(&way);
    let std_along_n = way.abs().dot(std_n);
    along_n >= (0.25 * max_force_n).max(GUARDED_CONTACT_SIGMA * std_along_n)
}

/// Where a move goes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum MoveTarget {
    /// The tip to this point, base frame, m; with a guarded move's limit, N.
    Tip(Vec3, Option<f64>),
    /// The tip back along the rod by this distance, m.
    BackOut(f64),
}

/// The reply to an estimator command, with its exact cause.
fn command_reply(result: &Result<CommandAccepted, CommandRefused>) -> (ReplyStatus, ReplyDetail) {
    match result {
        Ok(CommandAccepted::NothingToReset) => (ReplyStatus::NothingToReset, ReplyDetail::None),
        Ok(_) => (ReplyStatus::Accepted, ReplyDetail::None),
        Err(CommandRefused::Reset { reason }) => {
            (ReplyStatus::ResetRefused, ReplyDetail::Reason(*reason))
        }
        Err(CommandRefused::NotOk { reason, .. }) => {
            (ReplyStatus::NotOk, ReplyDetail::Reason(*reason))
        }
        Err(CommandRefused::AboveWarn { reason }) => {
            (ReplyStatus::AboveWarn, ReplyDetail::Reason(*reason))
        }
        Err(CommandRefused::NoEstimate | CommandRefused::Unsolvable) => {
            (ReplyStatus::NoEstimate, ReplyDetail::NoEstimate)
        }
        Err(CommandRefused::Limits { field, value, why }) => (
            ReplyStatus::LimitsRefused,
            ReplyDetail::Limits {
                field,
                value: *value,
                why,
            },
        ),
        Err(CommandRefused::Tare(refusal)) => (ReplyStatus::Refused, ReplyDetail::Tare(*refusal)),
        Err(CommandRefused::BiasNonFinite { value }) => (
            ReplyStatus::Refused,
            ReplyDetail::Limits {
                field: "bias",
                value: *value,
                why: "not finite",
            },
        ),
    }
}

// Snapshots (issue 17): the whole decision state, restorable into a step
// built from the same configuration ([`LoopStep::snapshot`]). `out` is the
// latest cycle's result, rewritten whole by every cycle.
sar_snapshot::snap_struct!(GuardedStop {
    cycle,
    tip_m,
    force_n,
    max_force_n,
});
sar_snapshot::snap_struct!(Trajectory {
    axes,
    target_tip_m,
    end_ns,
    streamed,
    max_force_n,
    excite,
});
// The configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(StepConfig {
    travel_m,
    axis_limits,
    following_tolerance_m,
    retreat_speed_mps,
    period_ns,
    publisher_stall_ns,
    force_control,
    motion,
    excite,
});
sar_snapshot::snap_state!(LoopStep {
    state: [
        trajectory,
        last_joints,
        speed_mps,
        last_drive_state,
        guarded_stop,
        guarded_last,
        guarded_rate_n_per_s,
        motion,
        last_stream_ns,
    ],
    nested: [estimator, force],
    config: [calibration, profile, config, guarded_lag_s, sample_period_s],
    output: [out],
    derived: [snapshot_fingerprint],
});

/// The kind number of a [`LoopStep`] snapshot (the snapshot header's kind).
pub const SNAPSHOT_KIND_LOOP_STEP: u16 = 1;

impl LoopStep {
    /// Writes the whole decision state into `out`, between two cycles. No
    /// allocation; the configuration is not stored: its fingerprint, hashed
    /// once at construction, is.
    pub fn snapshot(
        &self,
        out: &mut sar_snapshot::Snapshot,
    ) -> Result<(), sar_snapshot::SnapshotError> {
        sar_snapshot::take_with(
            self,
            SNAPSHOT_KIND_LOOP_STEP,
            self.snapshot_fingerprint,
            out,
        )
    }

    /// Restores a snapshot taken by [`LoopStep::snapshot`] of a step built
    /// from the same configuration: from the next cycle on this step decides
    /// exactly what that one did. Every check of the bytes is made first;
    /// on an error the step is unchanged.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), sar_snapshot::SnapshotError> {
        let fingerprint = self.snapshot_fingerprint;
        sar_snapshot::restore_with(self, SNAPSHOT_KIND_LOOP_STEP, fingerprint, bytes)
    }
}
