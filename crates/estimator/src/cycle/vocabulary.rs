//! The cycle's vocabulary: what one cycle consumes ([`CycleInput`]: the
//! clock, the sensor and joint samples, the operator's [`Command`]; and what
//! the caller derives beside it, [`CycleContext`]) and what it produces
//! ([`CycleOutput`]: the pose, the tip force, the torque residual, the
//! guard's decision, and what became of the command). Plain data: no
//! behaviour but the bias's finiteness check.

use crate::filter::Filtered;
use crate::guard::{Axis, ForceLimits, GuardState, Reason, Transition};
use crate::motion::CarriageMotion;
use crate::tip_force::{TipForceError, TipForceEstimate};
use crate::{Pose, Vec3};
use sar_kinematics::{ActiveJoints, PoseError};

/// One force/torque sample as the sensor driver delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSample {
    /// Force, sensor frame, N, after count scaling, before bias removal.
    pub force_n: Vec3,
    /// Torque, sensor frame, N m, before bias removal.
    pub torque_nm: Vec3,
    /// The device's own sample counter (wraps at `u32::MAX`). A new sample is
    /// one whose counter differs from the previous cycle's.
    pub counter: u32,
    /// The device's status word; 0 is all good, anything else is a Fault.
    pub status: u32,
    /// Host monotonic time the sample was received, ns.
    pub stamp_ns: u64,
    /// The driver's word that the sample is good (transport, framing).
    pub valid: bool,
    /// Every sample the driver received since the previous cycle, as the
    /// loop counted them for the spike check ([`DrainedSamples`]).
    pub drained: DrainedSamples,
}

/// The samples the sensor's driver received since the previous cycle, the
/// step's own among them (it reads only the newest), as the loop counted
/// them while draining the sensor (`sar_loop::control`): how many, and how
/// many steps between consecutive ones (from the previous cycle's last on)
/// jump beyond the spike threshold ([`super::SpikeLimits::is_jump`]). Recorded
/// with the cycle's input, so that the spike check sees every sample (a
/// late cycle reads several) and a replay makes the same decisions.
/// `counted` false (a caller that does not drain the sensor, a recording
/// older than the count): the check compares each new sample with the
/// previous new one itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DrainedSamples {
    /// Whether the loop counted them (the two counts are its).
    pub counted: bool,
    /// Samples received since the previous cycle.
    pub samples: u16,
    /// Steps between consecutive received samples beyond the threshold.
    pub jumps: u16,
}

/// One set of axis positions as the drive driver delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSample {
    /// q1, q2, q3, m.
    pub joints: ActiveJoints,
    /// Host monotonic time of the positions, ns.
    pub stamp_ns: u64,
    /// The driver's word that the positions are good.
    pub valid: bool,
}

/// The sensor's bias (tare), sensor frame: what the sensor reads beyond the
/// model's wrench (MODEL.md 4: `f_s = R_0s^T (-F_A) + b_f`,
/// `t_s = R_0s^T (...) + b_t`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bias {
    /// b_f, N.
    pub force_n: Vec3,
    /// b_t, N m.
    pub torque_nm: Vec3,
}

impl Bias {
    /// A force bias with no torque bias.
    pub fn force_only(force_n: Vec3) -> Self {
        Self {
            force_n,
            torque_nm: Vec3::zeros(),
        }
    }

    /// `Err` with the first NaN or infinite component.
    pub(super) fn check(&self) -> Result<(), f64> {
        crate::check_finite(self.force_n.iter().chain(self.torque_nm.iter()), |v| v)
    }
}

/// An operator command, applied in the cycle whose input carries it, after
/// that cycle's input has been evaluated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Leave `Stop` or `Fault` for `Ok`: accepted only when nothing in this
    /// cycle's input would fault or stop (see [`crate::guard::Guard::reset`]).
    Reset,
    /// Model-based tare of force and torque over the mean at rest: the bias
    /// becomes such that the mean reading of the last
    /// [`super::TareLimits::window_samples`] new samples at rest gives zero tip
    /// force at this pose (the rod's weight stays in the model) and the
    /// mean measured torque equals the predicted one. Accepted only in
    /// `Ok`, with a valid, fresh, observable estimate whose every part (with
    /// the guard's margin) is below its warn limit (a tare cannot hide more
    /// than a warn-level force, and never acts on stale, invalid or
    /// unobservable input), once the mean is complete, while the readings'
    /// spread over it is within [`super::TareLimits::max_spread`] times the noise
    /// (at rest), and at least [`super::TareLimits::min_interval_ns`] after the
    /// last accepted tare.
    Tare,
    /// Sets the bias to values measured otherwise (e.g. with the rod
    /// detached). Same rules as [`Command::Tare`], and the values must be
    /// finite.
    SetBias(Bias),
    /// Replaces the guard's six force limits, in any state: accepted when
    /// they pass [`crate::guard::GuardConfig::with_force_limits`] (warn < stop, above the
    /// hysteresis, each stop limit within the ceiling fixed at start). They
    /// act from the next cycle.
    SetLimits(ForceLimits),
}

/// What one cycle consumes: everything that the cycle decides from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleInput {
    /// The cycle number; strictly increasing.
    pub cycle: u64,
    /// Host monotonic time now, ns; `None` when the clock could not be read
    /// (a Fault, [`Reason::ClockFailed`]).
    pub now_ns: Option<u64>,
    /// Latest sensor sample.
    pub sensor: SensorSample,
    /// Latest joint positions.
    pub joints: JointSample,
    /// The operator command applied in this cycle, if any.
    pub command: Option<Command>,
}

/// What the caller adds to a cycle's recorded input ([`super::Estimator::cycle`]),
/// each part derived from inputs the caller records itself, so that a replay
/// derives the same: the loop from the trajectory it commands and from its
/// host's state; a tool offline and a test pass [`CycleContext::AT_REST`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleContext {
    /// Where the commanded trajectory says the axes are at the joint
    /// sample's stamp: with it, a valid joint sample farther than its
    /// tolerance from it on any axis (or a reference that is not finite) is
    /// a Fault ([`Reason::FollowingError`]); `None`: no following-error check.
    pub reference: Option<FollowingReference>,
    /// A fault of the host that runs the loop (e.g.
    /// [`Reason::PublisherStalled`]), which the caller derives from inputs it
    /// records: a Fault like any input fault, checked after the clock and the
    /// sensor's own checks.
    pub host_fault: Option<Reason>,
    /// The carriage's commanded motion at the sensor sample's stamp
    /// (MODEL.md 10): the tip force is compensated for the rod's inertia
    /// with it ([`crate::tip_force::TipForceEstimator::estimate_in_motion`];
    /// its standard deviation, which the guard's margin uses, grows with the
    /// acceleration's and the inertia's), and so is the torsion in the
    /// torque check's prediction. [`CarriageMotion::REST`]: the static model
    /// of MODEL.md 4, to the bit.
    pub motion: CarriageMotion,
}

impl CycleContext {
    /// No following reference, no host fault, the carriage at rest: the
    /// cycle of a caller that commands no motion (a tool offline, a test, a
    /// recording of the inputs alone).
    pub const AT_REST: CycleContext = CycleContext {
        reference: None,
        host_fault: None,
        motion: CarriageMotion::REST,
    };
}

impl Default for CycleContext {
    fn default() -> Self {
        Self::AT_REST
    }
}

/// Where the commanded trajectory says the axes are at the joint sample's
/// stamp, and how far they may be from it: the following-error check
/// ([`CycleContext::reference`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowingReference {
    /// The commanded joints at the joint sample's stamp, m.
    pub joints: ActiveJoints,
    /// The accepted |measured - commanded| per axis, m (finite, > 0; anything
    /// else faults).
    pub tolerance_m: f64,
}

/// The tip force of one cycle, or why there is none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TipOutcome {
    /// A number, with its standard deviation and observability flag.
    Estimate(TipForceEstimate),
    /// The estimator could not give a number.
    Refused(TipForceError),
    /// The kinematics refused the pose.
    PoseInvalid(PoseError),
    /// The sensor sample was marked invalid, stamped in the future, not
    /// finite, or the clock failed.
    SensorInvalid,
    /// The joint positions were marked invalid or stamped in the future, or
    /// the clock failed: no pose, no estimate.
    JointsInvalid,
}

/// A command accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CommandAccepted {
    /// The guard left `Stop` or `Fault` for `Ok` (the transition is in
    /// [`CycleOutput::transition`]).
    Reset,
    /// A reset in `Ok` or `Warn`: nothing to do.
    NothingToReset,
    /// The bias was replaced (by [`Command::Tare`] or [`Command::SetBias`]);
    /// it applies from the next cycle.
    BiasSet {
        /// The bias before.
        previous: Bias,
        /// The bias now.
        bias: Bias,
    },
    /// The force limits were replaced ([`Command::SetLimits`]); they apply
    /// from the next cycle.
    LimitsSet {
        /// The limits before.
        previous: ForceLimits,
        /// The limits now.
        limits: ForceLimits,
    },
}

/// Why a command was refused. Not `#[non_exhaustive]`: the daemon turns
/// each into its exact reply, and a new one must not fall into "other".
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CommandRefused {
    /// The reset's cause persists in this cycle's input.
    #[error("reset refused: {reason}")]
    Reset {
        /// The cause.
        reason: Reason,
    },
    /// A tare or bias change outside `Ok`.
    #[error("tare refused: the guard is {state} ({reason})")]
    NotOk {
        /// The guard's state.
        state: GuardState,
        /// Why it is in that state.
        reason: Reason,
    },
    /// A tare or bias change while a part of the tip force is at or above
    /// its warn limit.
    #[error("tare refused: {reason}")]
    AboveWarn {
        /// The part, its value and its limit.
        reason: Reason,
    },
    /// No tip-force estimate this cycle (cannot happen in `Ok`; kept so that
    /// the rule never depends on that).
    #[error("tare refused: no tip-force estimate this cycle")]
    NoEstimate,
    /// The tare's linear solve failed (a singular or non-finite system).
    #[error("tare refused: the bias for zero tip force cannot be solved")]
    Unsolvable,
    /// A tare refused by its mean at rest or its rate limit.
    #[error("tare refused: {0}")]
    Tare(TareRefused),
    /// A bias component is NaN or infinite.
    #[error("bias refused: {value} is not finite")]
    BiasNonFinite {
        /// The offending value.
        value: f64,
    },
    /// Force limits that are not valid, or above their ceiling.
    #[error("limits refused: {field} = {} N: {why}", sar_kinematics::Shown(*.value))]
    Limits {
        /// The offending limit.
        field: &'static str,
        /// Its value, N.
        value: f64,
        /// What is wrong.
        why: &'static str,
    },
}

/// Why a tare was refused by its mean at rest or its rate limit (in
/// [`CommandRefused::Tare`], which adds "tare refused: "; the loop's reply
/// shows this text alone).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TareRefused {
    /// The mean at rest holds fewer than `window_samples` samples (just
    /// started, or the joints moved, or the estimate was lost).
    #[error(
        "{samples} of {needed} samples at rest in the mean: keep the robot still and tare again"
    )]
    NotAtRest {
        /// Samples in the mean.
        samples: u32,
        /// Samples it needs ([`super::TareLimits::window_samples`]).
        needed: u32,
    },
    /// The readings spread more than the noise allows: the robot is not at
    /// rest.
    #[error(
        "the force on sensor axis {axis:?} spreads by {std_n:.3} N (std) over the mean, more than {allowed_n:.3} N: the robot is not at rest"
    )]
    NotSteady {
        /// The sensor axis.
        axis: Axis,
        /// The readings' standard deviation over the mean, N.
        std_n: f64,
        /// [`super::TareLimits::max_spread`] times the configured noise, N.
        allowed_n: f64,
    },
    /// Sooner than [`super::TareLimits::min_interval_ns`] after the last tare.
    #[error(
        "{since_s:.3} s since the last tare, at least {min_interval_s} s apart ([sensor] tare_min_interval_s)"
    )]
    TooSoon {
        /// Since the last accepted tare, s.
        since_s: f64,
        /// The minimum interval, s.
        min_interval_s: f64,
    },
}

/// A command of this cycle and what became of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandEvent {
    /// The command.
    pub command: Command,
    /// Accepted, or refused with the reason.
    pub result: Result<CommandAccepted, CommandRefused>,
}

/// The sensor torque against the model's prediction, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueResidual {
    /// Measured minus predicted torque, N m.
    pub residual_nm: Vec3,
    /// Its standard deviation per axis (torque noise and force noise through
    /// the lever, and for d != 0 through the torsion's estimate as well), N m.
    pub std_nm: Vec3,
}

/// What one cycle produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The cycle number of the input.
    pub cycle: u64,
    /// The pose, when the kinematics gave one.
    pub pose: Option<Pose>,
    /// The tip force.
    pub tip: TipOutcome,
    /// now - stamp of the sample that first carried the current counter, ns
    /// (0 for a stamp in the future, which is also invalid); `None` when the
    /// clock failed or did not advance.
    pub sensor_age_ns: Option<u64>,
    /// now - joints stamp, ns; `None` likewise.
    pub joints_age_ns: Option<u64>,
    /// Whether the sensor sample is a new one (its counter changed).
    pub new_sample: bool,
    /// The torque check, when it is configured and there was an estimate.
    pub torque: Option<TorqueResidual>,
    /// The guard's state after this cycle (and its command).
    pub guard_state: GuardState,
    /// Why the guard is in that state.
    pub guard_reason: Reason,
    /// The guard's transition in this cycle, if any.
    pub transition: Option<Transition>,
    /// The command of this cycle and its result.
    pub command: Option<CommandEvent>,
    /// The causal low-passed tip force (when a filter is configured), stepped
    /// once per new sensor sample; `None` while there is no observable
    /// estimate (the filter is then reset, and restarts at the next one). The
    /// guard never acts on it: it acts on the unfiltered estimate (except
    /// `Retreat`, which watches the filtered force for a rise).
    pub filtered: Option<Filtered>,
    /// Whether this cycle's new sample was a spike ([`super::SpikeLimits`]).
    pub spike: bool,
    /// Time since the last accepted tare (or the start bias, from the first
    /// cycle with a clock), ns; `None` before the first such cycle.
    pub tare_age_ns: Option<u64>,
}

sar_snapshot::snap_struct!(Bias { force_n, torque_nm });
