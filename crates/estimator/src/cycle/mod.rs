//! The per-cycle path: input plausibility, kinematics, tip force, the
//! force-limit guard and the operator's commands, once per control cycle, with
//! no allocation, no panic and no I/O.
//!
//! Design rule: everything [`Estimator::cycle`] decides is a pure function of
//! the recorded inputs ([`CycleInput`]: the clock reading, the sensor sample
//! with its counter and status, the joint sample and the command of that
//! cycle) and of the estimator's state, which is itself built only from
//! earlier inputs. A recording of the inputs therefore replays to the same
//! decisions bit for bit. There is no other way to change the estimator's
//! state: a reset, a tare and a new bias are [`Command`]s of a cycle, judged on
//! that cycle's fresh input after it has been evaluated, and reported in its
//! [`CycleOutput::command`] as accepted or refused with a typed reason.
//!
//! Plausibility, decided from the inputs alone, each a latched Fault of its own
//! reason (limits in [`PlausibilityLimits`]): a clock that cannot be read or
//! does not advance; a cycle that comes longer after the previous one than
//! the sensor's accepted age (a stall; a late cycle within it is an input the
//! loop carries on from, issue 33); a sensor counter that jumps by more than
//! `max_counter_gap` beyond the samples the stamps' difference explains; a
//! sample whose counter has not changed for longer than
//! the guard's `max_sensor_age_ns` (the age runs from the stamp of the sample
//! that first carried the counter); a device status other than 0; a joint
//! that moves between two joint samples by more than `max_joint_speed_mps`
//! allows over their stamp difference plus `joint_margin_m`; a sensor torque
//! that disagrees with the model's prediction (MODEL.md 4)
//! `t = R_0s^T ((A - S) x (-F_A) - M_T n) + b_t` by more than `max_sigma`
//! standard deviations on any sensor axis.

use crate::filter::{FilterConfig, Filtered, TipFilter};
use crate::guard::{
    Axis, ForceLimits, Guard, GuardConfig, GuardInput, GuardState, Reason, RestResidual,
    SensorChannel, TipInput, Transition,
};
use crate::inertial::RodInertia;
use crate::motion::CarriageMotion;
use crate::tip_force::{TipForceConfig, TipForceError, TipForceEstimate, TipForceEstimator};
use crate::{
    Calibration, Mat3, Pose, Profile, SensorNoise, SettingError, Vec3, at_least,
    finite_non_negative, positive, require,
};
use sar_kinematics::{ActiveJoints, PoseError, forward};

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
/// jump beyond the spike threshold ([`SpikeLimits::is_jump`]). Recorded
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
    fn check(&self) -> Result<(), f64> {
        crate::check_finite(self.force_n.iter().chain(self.torque_nm.iter()), |v| v)
    }
}

/// An operator command, applied in the cycle whose input carries it, after
/// that cycle's input has been evaluated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Leave `Stop` or `Fault` for `Ok`: accepted only when nothing in this
    /// cycle's input would fault or stop (see [`Guard::reset`]).
    Reset,
    /// Model-based tare of force and torque over the mean at rest: the bias
    /// becomes such that the mean reading of the last
    /// [`TareLimits::window_samples`] new samples at rest gives zero tip
    /// force at this pose (the rod's weight stays in the model) and the
    /// mean measured torque equals the predicted one. Accepted only in
    /// `Ok`, with a valid, fresh, observable estimate whose every part (with
    /// the guard's margin) is below its warn limit (a tare cannot hide more
    /// than a warn-level force, and never acts on stale, invalid or
    /// unobservable input), once the mean is complete, while the readings'
    /// spread over it is within [`TareLimits::max_spread`] times the noise
    /// (at rest), and at least [`TareLimits::min_interval_ns`] after the
    /// last accepted tare.
    Tare,
    /// Sets the bias to values measured otherwise (e.g. with the rod
    /// detached). Same rules as [`Command::Tare`], and the values must be
    /// finite.
    SetBias(Bias),
    /// Replaces the guard's six force limits, in any state: accepted when
    /// they pass [`GuardConfig::with_force_limits`] (warn < stop, above the
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
        /// Samples it needs ([`TareLimits::window_samples`]).
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
        /// [`TareLimits::max_spread`] times the configured noise, N.
        allowed_n: f64,
    },
    /// Sooner than [`TareLimits::min_interval_ns`] after the last tare.
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

/// Where the commanded trajectory says the axes are at the joint sample's
/// stamp, and how far they may be from it: the following-error check
/// ([`Estimator::cycle_following`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowingReference {
    /// The commanded joints at the joint sample's stamp, m.
    pub joints: ActiveJoints,
    /// The accepted |measured - commanded| per axis, m (finite, > 0; anything
    /// else faults).
    pub tolerance_m: f64,
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
    /// Whether this cycle's new sample was a spike ([`SpikeLimits`]).
    pub spike: bool,
    /// Time since the last accepted tare (or the start bias, from the first
    /// cycle with a clock), ns; `None` before the first such cycle.
    pub tare_age_ns: Option<u64>,
}

/// The torque check's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueLimits {
    /// Torque noise, one standard deviation per sensor axis, N m (finite, > 0).
    pub noise_nm: Vec3,
    /// A residual beyond this many standard deviations on any axis is a
    /// Fault (finite, >= 1).
    pub max_sigma: f64,
}

impl TorqueLimits {
    /// Default torque noise, N m: the simulator's HEX-6 figures (0.01, 0.01,
    /// 0.002); set the real sensor's.
    pub const DEFAULT_NOISE_NM: [f64; 3] = [0.01, 0.01, 0.002];
    /// Default multiple: 7 standard deviations, i.e. about one false Fault in
    /// 10^11 samples per axis for Gaussian noise (years at 500 Hz).
    pub const DEFAULT_MAX_SIGMA: f64 = 7.0;
}

/// The limits of the input plausibility checks, as the caller fills them.
/// [`PlausibilityConfig::new`] checks them; [`PlausibilityLimits::default`]
/// gives the documented defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlausibilityLimits {
    /// The axes' speed limit, m/s (finite, > 0). Default 0.05 m/s (the
    /// simulator's axes); set the drives' configured limit.
    pub max_joint_speed_mps: f64,
    /// Added to the distance the speed allows between two joint samples, m
    /// (finite, >= 0): quantisation, stamp jitter. Default 0.2 mm.
    pub joint_margin_m: f64,
    /// The largest accepted step of the sensor counter between two new
    /// samples beyond the samples their stamps' difference explains
    /// (1 = no sample lost; >= 1). Default 3. A late cycle (the loop did not
    /// look) explains its samples by the time that passed: the newest sample
    /// then is `round(dt / sample_period_ns)` after the last one judged, and
    /// that many less one are added to the accepted step; the time itself is
    /// judged by the cycle gap ([`Reason::CycleGap`]).
    pub max_counter_gap: u32,
    /// The sensor's sample period, ns (> 0; `[tip] sample_rate_hz`):
    /// explains a counter step by the stamps' difference. Default 2 ms
    /// (500 Hz).
    pub sample_period_ns: u64,
    /// The torque check; `None` switches it off (a sensor without torque).
    /// Default on, with [`TorqueLimits`]' defaults.
    pub torque: Option<TorqueLimits>,
    /// The frozen-sensor check. Default on with
    /// [`FrozenCheck::DEFAULT_REPEATS`]; [`frozen_repeats`] derives the
    /// count from the sensor's noise and resolution.
    pub frozen: FrozenCheck,
    /// The sensor's measuring range (saturation check); `None` switches it
    /// off. Default the HEX-6 ([`SensorRange::HEX6`]).
    pub range: Option<SensorRange>,
    /// The spike check; `None` switches it off. Default on
    /// ([`SpikeLimits::default`]).
    pub spikes: Option<SpikeLimits>,
    /// The tare's age and the bias drift ([`TareLimits::default`]).
    pub tare: TareLimits,
    /// The first reset's check of the wrench at rest against the model;
    /// `None` switches it off. Default on ([`MountingLimits::default`]).
    pub mounting: Option<MountingLimits>,
}

impl Default for PlausibilityLimits {
    fn default() -> Self {
        let [x, y, z] = TorqueLimits::DEFAULT_NOISE_NM;
        Self {
            max_joint_speed_mps: 0.05,
            joint_margin_m: 2e-4,
            max_counter_gap: 3,
            sample_period_ns: 2_000_000,
            torque: Some(TorqueLimits {
                noise_nm: Vec3::new(x, y, z),
                max_sigma: TorqueLimits::DEFAULT_MAX_SIGMA,
            }),
            frozen: FrozenCheck::On {
                repeats: FrozenCheck::DEFAULT_REPEATS,
            },
            range: Some(SensorRange::HEX6),
            spikes: Some(SpikeLimits::default()),
            tare: TareLimits::default(),
            mounting: Some(MountingLimits::default()),
        }
    }
}

/// The frozen-sensor (stuck-at) check: N new samples in a row whose six
/// values repeat the previous new sample's bit for bit, while the counter
/// advances, are a Fault ([`Reason::SensorFrozen`]). A live sensor always
/// shows noise, so that a repeat of all six quantised channels is rare; how
/// rare is [`frozen_repeat_probability`], and [`frozen_repeats`] picks N.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrozenCheck {
    /// Fault after `repeats` (>= 1) identical new samples in a row.
    On {
        /// N.
        repeats: u32,
    },
    /// Off: said explicitly, because a sensor whose configured noise is 0,
    /// or whose resolution is far coarser than its noise, repeats by
    /// itself, and then the check cannot tell a frozen sensor from a live
    /// one. The daemon logs it at start.
    Off,
}

impl FrozenCheck {
    /// The default and smallest N that [`frozen_repeats`] returns: a device
    /// that sends a sample twice (an output rate above its converter's)
    /// must not trip it; 3 new samples are 6 ms at 500 Hz.
    pub const DEFAULT_REPEATS: u32 = 3;
    /// The largest accepted N (a larger one would in effect switch it off).
    pub const MAX_REPEATS: u32 = 1000;
}

/// The fraction of the configured noise assumed for the difference of two
/// consecutive samples in [`frozen_repeat_probability`]: a device's internal
/// low-pass correlates consecutive samples (the difference of two samples
/// with correlation rho has std sigma sqrt(2 (1 - rho))); 1/4 is rho ~ 0.97,
/// and also covers a sensor quieter than configured.
pub const FROZEN_NOISE_FRACTION: f64 = 0.25;

/// New samples in ten years of 1 kHz operation: the false-alarm budget of
/// [`frozen_repeats`] is less than one alarm in that many samples.
pub const SAMPLES_IN_TEN_YEARS_1KHZ: f64 = 1000.0 * 3600.0 * 24.0 * 365.25 * 10.0;

/// The probability that one new sample repeats the previous one bit for bit
/// on every channel, for a live sensor at rest. Per channel with noise
/// sigma and resolution r (one count; 0 for a continuous reading, as the
/// simulator's), the difference of two samples has std
/// `sd = FROZEN_NOISE_FRACTION * sqrt(2) * sigma` and rounds to zero counts
/// with probability about `r / (sqrt(2 pi) sd)` (its density at 0 times one
/// count; capped at 1, and 1 when `sd < r / 2`); the channels are
/// independent, so the probabilities multiply. `noise_nm` `None` (no torque
/// channels configured) uses the three force channels only.
pub fn frozen_repeat_probability(
    noise_n: &Vec3,
    noise_nm: Option<&Vec3>,
    resolution_n: f64,
    resolution_nm: f64,
) -> f64 {
    let channel = |sigma: f64, resolution: f64| -> f64 {
        if resolution <= 0.0 {
            return 0.0;
        }
        let sd = FROZEN_NOISE_FRACTION * core::f64::consts::SQRT_2 * sigma;
        if sd.is_nan() || sd < resolution / 2.0 {
            return 1.0;
        }
        let density = 1.0 / (libm::sqrt(2.0 * core::f64::consts::PI) * sd);
        (density * resolution).min(1.0)
    };
    let mut p = 1.0;
    for sigma in noise_n.iter() {
        p *= channel(*sigma, resolution_n);
    }
    if let Some(nm) = noise_nm {
        for sigma in nm.iter() {
            p *= channel(*sigma, resolution_nm);
        }
    }
    p
}

/// Expected false alarms of the frozen check with N = `repeats` over ten
/// years of 1 kHz operation: `SAMPLES_IN_TEN_YEARS_1KHZ * p^repeats` for the
/// per-sample repeat probability `p` ([`frozen_repeat_probability`]).
pub fn frozen_false_alarms_in_ten_years(p: f64, repeats: u32) -> f64 {
    SAMPLES_IN_TEN_YEARS_1KHZ * libm::pow(p, f64::from(repeats))
}

/// N for the frozen check: the smallest N >= [`FrozenCheck::DEFAULT_REPEATS`]
/// with fewer than one expected false alarm in ten years of 1 kHz operation
/// ([`frozen_false_alarms_in_ten_years`] < 1); `None` when no N up to
/// [`FrozenCheck::MAX_REPEATS`] does (a sensor that repeats by itself: the
/// check cannot work and must be switched off explicitly).
///
/// Example, the HEX-6 over RDT (noise 0.2/0.2/0.8 N, 0.01/0.01/0.002 N m;
/// resolution 1e-4 N, 1e-5 N m, i.e. 10000 counts/N and 100000 counts/N m):
/// per channel 8e-4, 8e-4, 2e-4, 1.6e-3, 1.6e-3, 8e-3; p = 2.6e-18; with
/// N = 3 the expected false alarms in ten years are 5e-42.
pub fn frozen_repeats(
    noise_n: &Vec3,
    noise_nm: Option<&Vec3>,
    resolution_n: f64,
    resolution_nm: f64,
) -> Option<u32> {
    let p = frozen_repeat_probability(noise_n, noise_nm, resolution_n, resolution_nm);
    (FrozenCheck::DEFAULT_REPEATS..=FrozenCheck::MAX_REPEATS)
        .find(|n| frozen_false_alarms_in_ten_years(p, *n) < 1.0)
}

/// The sensor's measuring range per channel (sensor frame): a raw reading at
/// or beyond it (either sign) is a Fault ([`Reason::SensorSaturated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorRange {
    /// Fx, Fy, Fz range, N (finite, > 0).
    pub force_n: Vec3,
    /// Tx, Ty, Tz range, N m (finite, > 0).
    pub torque_nm: Vec3,
}

impl SensorRange {
    /// OnRobot HEX-E / HEX-H QC (the article's sensor): nominal capacity
    /// Fxy 200 N, Fz 200 N, Txy 10 N m, Tz 6.5 N m (OnRobot HEX-E/H QC
    /// datasheet, "Nominal capacity (N.C)").
    pub const HEX6: SensorRange = SensorRange {
        force_n: Vec3::new(200.0, 200.0, 200.0),
        torque_nm: Vec3::new(10.0, 10.0, 6.5),
    };
    /// ATI Mini45 SI-145-5 on a Net F/T box: Fxy 145 N, Fz 290 N, Txy 5 N m,
    /// Tz 5 N m (ATI Mini45 calibration table, SI-145-5).
    pub const ATI_MINI45_SI_145_5: SensorRange = SensorRange {
        force_n: Vec3::new(145.0, 145.0, 290.0),
        torque_nm: Vec3::new(5.0, 5.0, 5.0),
    };
}

/// The spike check: a new sample whose force jumps from the previous new
/// sample's by more than `jump_sigma * sqrt(2) * noise` on any sensor axis
/// is a spike. One spike changes no state: the guard's debounce is by design
/// the filter of single-sample noise, and a force that persists still stops
/// within the debounce time; it is counted and reported
/// ([`CycleOutput::spike`]). `max_spikes` spikes within `window_samples` new
/// samples of the first are a Fault ([`Reason::SensorSpikes`]): a sensor
/// that keeps jumping is not to be trusted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpikeLimits {
    /// The jump threshold in standard deviations of the difference of two
    /// samples (finite, >= 3).
    pub jump_sigma: f64,
    /// Spikes within the window that fault (>= 2).
    pub max_spikes: u32,
    /// The window, new samples (>= 1).
    pub window_samples: u32,
}

impl SpikeLimits {
    /// Whether `next` jumps from `previous` (forces, sensor frame, N) by
    /// more than `jump_sigma * sqrt(2)` times the noise `noise_n` on any
    /// axis: one formula for the estimator's own check and the loop's count
    /// of the samples it drains ([`DrainedSamples`]).
    pub fn is_jump(&self, noise_n: &Vec3, previous: &Vec3, next: &Vec3) -> bool {
        let threshold_n = noise_n * (self.jump_sigma * core::f64::consts::SQRT_2);
        let jump = (next - previous).abs();
        jump.iter().zip(threshold_n.iter()).any(|(j, t)| j > t)
    }
}

impl Default for SpikeLimits {
    /// 10 sigma (a Gaussian difference beyond it: 1.5e-23 per sample and
    /// axis), 10 spikes within 500 new samples (1 s at 500 Hz).
    fn default() -> Self {
        Self {
            jump_sigma: 10.0,
            max_spikes: 10,
            window_samples: 500,
        }
    }
}

/// The tare's age and the bias drift since the tare.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TareLimits {
    /// After this long since the last tare (or the start bias), the guard
    /// warns that a tare is due ([`Reason::TareDue`]), ns; `None`: never.
    pub max_age_ns: Option<u64>,
    /// The sensor's bias drift bound, N/s (finite, >= 0): every part is
    /// compared with its limits after adding `drift_n_per_s * age_s` besides
    /// the standard-deviation margin, so that a bias that drifted by up to
    /// that much since the tare cannot hide a force above a limit.
    pub drift_n_per_s: f64,
    /// A tare takes the mean reading of this many new samples at rest
    /// (1..=100000; beyond, an exponential mean of that length): with one
    /// sample it would carry that sample's noise into the bias (eight
    /// one-sample tares at rest moved the mean tip force by up to 0.17 N).
    /// Refused until the mean holds that many ([`TareRefused::NotAtRest`]).
    pub window_samples: u32,
    /// The readings' standard deviation over the mean, per sensor axis, may
    /// be at most this multiple of the sensor's configured noise (finite,
    /// at least 1): beyond, the robot is not at rest (a contact that
    /// changes, a vibration) and the tare is refused
    /// ([`TareRefused::NotSteady`]).
    pub max_spread: f64,
    /// Two accepted tares at least this far apart, ns
    /// ([`TareRefused::TooSoon`]); 0: no limit.
    pub min_interval_ns: u64,
}

impl Default for TareLimits {
    /// A tare due after one hour; a drift bound of 1e-4 N/s (0.36 N after
    /// the hour). The HEX-6's datasheet gives no drift over time: this is an
    /// assumption to replace by the sensor's measured drift (a recording at
    /// rest over an hour after warm-up). A tare over the mean of 500 samples
    /// at rest (1 s at 500 Hz), refused when the readings spread more than
    /// twice the configured noise, and at most one tare every 5 s.
    fn default() -> Self {
        Self {
            max_age_ns: Some(3_600_000_000_000),
            drift_n_per_s: 1e-4,
            window_samples: 500,
            max_spread: 2.0,
            min_interval_ns: 5_000_000_000,
        }
    }
}

/// The mean reading at rest a tare is taken over ([`TareLimits`]): the raw
/// force and torque (sensor frame, before the bias) of the new samples
/// since the joints last moved, and the force's spread. One recursion gives
/// the running mean and population variance of the first `window_samples`
/// samples, and an exponential mean and variance of that length beyond.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TareMean {
    /// New samples in the mean (at most `window_samples`).
    count: u32,
    /// Mean force reading, sensor frame, N.
    force_n: Vec3,
    /// Mean torque reading, sensor frame, N m.
    torque_nm: Vec3,
    /// Variance of the force reading per sensor axis, N^2.
    var_n2: Vec3,
    /// The joints the mean was taken at.
    joints: Option<ActiveJoints>,
}

impl TareMean {
    const EMPTY: TareMean = TareMean {
        count: 0,
        force_n: Vec3::new(0.0, 0.0, 0.0),
        torque_nm: Vec3::new(0.0, 0.0, 0.0),
        var_n2: Vec3::new(0.0, 0.0, 0.0),
        joints: None,
    };
}

/// The first reset's check of the wrench at rest: with the tip free, the
/// model predicts the whole sensor wrench, so the estimated F_tip and the
/// torque residual are the residuals of the model. Both are averaged over
/// the new samples since the joints last moved (at most `rest_samples`;
/// beyond, an exponential mean of that length), so that the noise of the
/// mean is small and the tolerances decide. The mean F_tip across the rod
/// must be within `sigma std/sqrt(n) + tolerance_n`, along the rod within
/// `sigma std/sqrt(n) + friction_n + tolerance_n` (the support's friction
/// acts along the rod, like an axial tip force), the mean torque residual on
/// each sensor axis within `sigma std/sqrt(n) + tolerance_nm`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountingLimits {
    /// Multiple of the mean's standard deviation (finite, >= 0).
    pub sigma: f64,
    /// The largest static friction of the support along the rod, N (finite,
    /// >= 0).
    pub friction_n: f64,
    /// What the force model may be off beyond noise and friction, N (finite,
    /// > 0).
    pub tolerance_n: f64,
    /// What the torque model may be off beyond noise, N m (finite, > 0).
    pub tolerance_nm: f64,
    /// The length of the mean, new samples (1..=100000).
    pub rest_samples: u32,
}

impl Default for MountingLimits {
    /// 4 sigma, 0.5 N friction, 1 N and 0.02 N m tolerance, a mean of 500
    /// samples (1 s at 500 Hz).
    fn default() -> Self {
        Self {
            sigma: 4.0,
            friction_n: 0.5,
            tolerance_n: 1.0,
            tolerance_nm: 0.02,
            rest_samples: 500,
        }
    }
}

/// The means at rest for the first reset's check ([`MountingLimits`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct RestMean {
    /// New samples in the mean (at most `rest_samples`).
    count: u32,
    /// Mean F_tip, {0}, N.
    force_n: Vec3,
    /// Mean torque residual, sensor frame, N m (zero without the torque check).
    torque_nm: Vec3,
    /// The latest per-sample standard deviations.
    std_n: Vec3,
    std_nm: Vec3,
    /// The joints the mean was taken at.
    joints: Option<ActiveJoints>,
}

impl RestMean {
    const EMPTY: RestMean = RestMean {
        count: 0,
        force_n: Vec3::new(0.0, 0.0, 0.0),
        torque_nm: Vec3::new(0.0, 0.0, 0.0),
        std_n: Vec3::new(0.0, 0.0, 0.0),
        std_nm: Vec3::new(0.0, 0.0, 0.0),
        joints: None,
    };
}

/// Checked plausibility limits. Exists only if valid (the default is
/// [`PlausibilityLimits::default`], which is valid).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlausibilityConfig {
    limits: PlausibilityLimits,
}

impl PlausibilityConfig {
    /// Checks: speed finite and > 0; margin finite and >= 0; counter gap >= 1;
    /// torque noise finite and > 0 per axis; max_sigma finite and >= 1.
    /// Then each optional check's settings, in the order of the fields.
    pub fn new(limits: PlausibilityLimits) -> Result<Self, SettingError> {
        positive("max_joint_speed_mps", limits.max_joint_speed_mps)?;
        finite_non_negative("joint_margin_m", limits.joint_margin_m)?;
        require(
            limits.max_counter_gap != 0,
            "max_counter_gap",
            0.0,
            "must be >= 1",
        )?;
        require(
            limits.sample_period_ns != 0,
            "sample_period_ns",
            0.0,
            "must be > 0",
        )?;
        if let Some(t) = limits.torque {
            t.check()?;
        }
        if let FrozenCheck::On { repeats } = limits.frozen {
            let ok = (1..=FrozenCheck::MAX_REPEATS).contains(&repeats);
            require(ok, "frozen.repeats", f64::from(repeats), "must be 1..=1000")?;
        }
        if let Some(r) = limits.range {
            for &v in r.force_n.iter().chain(r.torque_nm.iter()) {
                positive("range", v)?;
            }
        }
        if let Some(sp) = limits.spikes {
            sp.check()?;
        }
        limits.tare.check()?;
        if let Some(m) = limits.mounting {
            m.check()?;
        }
        Ok(Self { limits })
    }

    /// The checked limits.
    pub fn limits(&self) -> PlausibilityLimits {
        self.limits
    }
}

/// A count of samples that must be 1..=100000.
fn window(field: &'static str, samples: u32) -> Result<(), SettingError> {
    let ok = (1..=100_000).contains(&samples);
    require(ok, field, f64::from(samples), "must be 1..=100000")
}

impl TorqueLimits {
    /// Noise finite and > 0 per axis; max_sigma finite and >= 1.
    fn check(&self) -> Result<(), SettingError> {
        for &n in self.noise_nm.iter() {
            positive("torque.noise_nm", n)?;
        }
        at_least(
            "torque.max_sigma",
            self.max_sigma,
            1.0,
            "must be finite and >= 1",
        )
    }
}

impl SpikeLimits {
    /// Jump finite and >= 3 sigma; at least 2 spikes in a window of >= 1.
    fn check(&self) -> Result<(), SettingError> {
        at_least(
            "spikes.jump_sigma",
            self.jump_sigma,
            3.0,
            "must be finite and >= 3",
        )?;
        let n = f64::from(self.max_spikes);
        require(self.max_spikes >= 2, "spikes.max_spikes", n, "must be >= 2")?;
        require(
            self.window_samples != 0,
            "spikes.window_samples",
            0.0,
            "must be >= 1",
        )
    }
}

impl TareLimits {
    /// Drift finite and >= 0; an age bound > 0; a window of 1..=100000
    /// samples; a spread finite and >= 1.
    fn check(&self) -> Result<(), SettingError> {
        finite_non_negative("tare.drift_n_per_s", self.drift_n_per_s)?;
        require(
            self.max_age_ns != Some(0),
            "tare.max_age",
            0.0,
            "must be > 0",
        )?;
        window("tare.window_samples", self.window_samples)?;
        at_least(
            "tare.max_spread",
            self.max_spread,
            1.0,
            "must be finite and >= 1",
        )
    }
}

impl MountingLimits {
    /// Sigma and friction finite and >= 0; tolerances finite and > 0; a
    /// rest of 1..=100000 samples.
    fn check(&self) -> Result<(), SettingError> {
        finite_non_negative("mounting.sigma", self.sigma)?;
        finite_non_negative("mounting.friction_n", self.friction_n)?;
        positive("mounting.tolerance_n", self.tolerance_n)?;
        positive("mounting.tolerance_nm", self.tolerance_nm)?;
        window("mounting.rest_samples", self.rest_samples)
    }
}

/// Everything fixed at start for the per-cycle path.
#[derive(Debug, Clone, Copy)]
pub struct EstimatorConfig {
    /// The robot's calibration.
    pub calibration: Calibration,
    /// The manipulator in use.
    pub profile: Profile,
    /// The sensor's force noise.
    pub noise: SensorNoise,
    /// The tip-force estimator's settings (its observability limit; default
    /// [`TipForceConfig::DEFAULT_MAX_STD_N`]). The guard acts on its flag.
    pub tip: TipForceConfig,
    /// The force-limit guard.
    pub guard: GuardConfig,
    /// The input plausibility checks.
    pub plausibility: PlausibilityConfig,
    /// The tip-force low-pass beside the unfiltered estimate (`None`: none).
    /// Its `sample_period_s` is the sensor's sample period.
    pub filter: Option<FilterConfig>,
    /// The rod's inertia and the adapter's mass, for the tip force in motion
    /// ([`Estimator::cycle_in_motion`], MODEL.md 10). The stated default when
    /// nothing was measured: [`RodInertia::slender_rod`].
    pub inertia: RodInertia,
}

/// The torque check, fixed at construction.
#[derive(Debug, Clone, Copy)]
struct TorqueCheck {
    /// The residual's standard deviation per sensor axis with d = 0, N m.
    std_nm: Vec3,
    /// The lever's cross-product matrix [l]x, sensor frame.
    cross: Mat3,
    /// The force noise's variance per sensor axis, N^2.
    force_var_n2: Vec3,
    /// The torque noise's variance per sensor axis, N^2 m^2.
    torque_var_nm2: Vec3,
    /// d, m: with d != 0 the torsion's estimate carries force noise too.
    offset_m: f64,
    /// The configured multiple.
    max_sigma: f64,
}

impl TorqueCheck {
    fn new(
        cal: &Calibration,
        profile: &Profile,
        noise: &SensorNoise,
        limits: &TorqueLimits,
    ) -> Self {
        let lever_s_m = SensorFrame::new(cal).lever_s_m;
        // The prediction l x (f - b) carries the force noise through [l]x:
        // var_i = sigma_t,i^2 + sum_j [l]x_ij^2 sigma_f,j^2.
        let cross = lever_s_m.cross_matrix();
        let force_var = noise.std_n().component_mul(&noise.std_n());
        let torque_var = limits.noise_nm.component_mul(&limits.noise_nm);
        let var = torque_var + cross.component_mul(&cross) * force_var;
        Self {
            std_nm: var.map(nalgebra::ComplexField::sqrt),
            cross,
            force_var_n2: force_var,
            torque_var_nm2: torque_var,
            offset_m: profile.offset_m(),
            max_sigma: limits.max_sigma,
        }
    }
}

/// The per-cycle estimator: owns the tip-force estimator, the bias, the
/// guard and what the plausibility checks remember of earlier cycles.
#[derive(Debug, Clone)]
pub struct Estimator {
    calibration: Calibration,
    profile: Profile,
    tip: TipForceEstimator,
    frame: SensorFrame,
    filter: Option<TipFilter>,
    guard: Guard,
    limits: PlausibilityLimits,
    torque: Option<TorqueCheck>,
    bias: Bias,
    last: CycleOutput,
    /// The largest `now_ns` seen: time must advance from cycle to cycle.
    last_now_ns: Option<u64>,
    /// The sensor counter of the previous cycle.
    last_counter: Option<u32>,
    /// The stamp of the sample that first carried `last_counter`, ns.
    counter_stamp_ns: u64,
    /// The previous valid, finite joint sample and its stamp.
    last_joints: Option<(ActiveJoints, u64)>,
    /// The force noise per sensor axis, N (the spike threshold's unit).
    noise_n: Vec3,
    /// The six values of the previous new sample, as bits (frozen check).
    last_values: Option<[u64; 6]>,
    /// New samples in a row identical to the one before them.
    repeats: u32,
    /// The force of the previous new finite sample, sensor frame, N (spikes).
    last_force_n: Option<Vec3>,
    /// Spikes in the current window.
    spikes: u32,
    /// New samples left in the current spike window (0: no window open).
    spike_window_left: u32,
    /// `now_ns` of the cycle whose tare (or start bias) is in use.
    tare_ns: Option<u64>,
    /// The means at rest, kept until the first reset is accepted.
    rest: RestMean,
    /// The mean reading at rest a tare is taken over.
    tare_mean: TareMean,
    /// `now_ns` of the last accepted tare (the rate limit).
    last_tare_ns: Option<u64>,
}

/// What the checks of the sensor's own values found in one new sample.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SampleVerdict {
    fault: Option<Reason>,
    spike: bool,
}

/// What the plausibility checks of one cycle's inputs found
/// ([`Estimator::check_inputs`]): the clock, the sensor's counter, status and
/// values, the joints. Each fault is kept apart, so that the guard gets the
/// first in the fixed order ([`InputChecks::first_fault`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct InputChecks {
    /// The clock's reading, when it can be trusted (read, and advancing).
    now_ns: Option<u64>,
    clock_fault: Option<Reason>,
    /// The sensor sample is a new one (its counter changed).
    new_sample: bool,
    /// The counter jumped beyond what the time explains (the filter
    /// restarts; an explained gap is stepped over, [`TipFilter::update_counted`]).
    lost_samples: bool,
    counter_fault: Option<Reason>,
    status_fault: Option<Reason>,
    values: SampleVerdict,
    joint_fault: Option<Reason>,
}

impl InputChecks {
    /// The guard's input fault: the first of clock, counter, status, the
    /// sensor's values, the host's fault, joints, torque.
    fn first_fault(
        &self,
        host_fault: Option<Reason>,
        torque_fault: Option<Reason>,
    ) -> Option<Reason> {
        self.clock_fault
            .or(self.counter_fault)
            .or(self.status_fault)
            .or(self.values.fault)
            .or(host_fault)
            .or(self.joint_fault)
            .or(torque_fault)
    }
}

/// How old the inputs are and whether they may be used
/// ([`Estimator::freshness`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Freshness {
    /// now - stamp of the sample that first carried the current counter, ns.
    sensor_age_ns: Option<u64>,
    /// now - joints stamp, ns.
    joints_age_ns: Option<u64>,
    /// Marked valid, stamped no later than now, and finite.
    sensor_valid: bool,
    /// Marked valid and stamped no later than now.
    joints_valid: bool,
}

/// The tare's age and what follows from it ([`Estimator::tare_status`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct TareStatus {
    /// Time since the tare in use, ns.
    age_ns: Option<u64>,
    /// The drift bound since the tare, added to the guard's margin, N.
    extra_margin_n: f64,
    /// The warning that a tare is due.
    due: Option<Reason>,
}

/// ns to s.
fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// The following-error verdict of finite joints `q` against `r`.
fn following_fault(q: &ActiveJoints, r: &FollowingReference) -> Option<Reason> {
    let errors = [
        (1, (q.q1_m - r.joints.q1_m).abs()),
        (2, (q.q2_m - r.joints.q2_m).abs()),
        (3, (q.q3_m - r.joints.q3_m).abs()),
    ];
    let tolerance_m = r.tolerance_m;
    let tolerance_ok = tolerance_m.is_finite() && tolerance_m > 0.0;
    errors
        .into_iter()
        // NaN compares false: a non-finite reference faults.
        .find(|(_, error_m)| !(tolerance_ok && *error_m <= tolerance_m))
        .map(|(axis, error_m)| Reason::FollowingError {
            axis,
            error_m,
            tolerance_m,
        })
}

/// The largest |dq| over the three axes, with its axis (1, 2, 3).
fn largest_move(a: &ActiveJoints, b: &ActiveJoints) -> (u8, f64) {
    let moves = [
        (1, (a.q1_m - b.q1_m).abs()),
        (2, (a.q2_m - b.q2_m).abs()),
        (3, (a.q3_m - b.q3_m).abs()),
    ];
    moves
        .into_iter()
        .fold((1, 0.0), |acc, m| if m.1 > acc.1 { m } else { acc })
}

impl Estimator {
    /// Builds the estimator with a force bias `bias_n` (sensor frame, N) and
    /// no torque bias.
    pub fn new(config: &EstimatorConfig, bias_n: Vec3) -> Result<Self, SettingError> {
        Self::with_bias(config, Bias::force_only(bias_n))
    }

    /// Builds the estimator with the sensor's bias (sensor frame).
    pub fn with_bias(config: &EstimatorConfig, bias: Bias) -> Result<Self, SettingError> {
        bias.check().map_err(|value| SettingError::Invalid {
            field: "bias",
            value,
            why: "the tare must be finite",
        })?;
        let guard = Guard::new(config.guard);
        let limits = config.plausibility.limits();
        let last = CycleOutput {
            cycle: 0,
            pose: None,
            tip: TipOutcome::SensorInvalid,
            sensor_age_ns: None,
            joints_age_ns: None,
            new_sample: false,
            torque: None,
            guard_state: guard.state(),
            guard_reason: guard.reason(),
            transition: None,
            command: None,
            filtered: None,
            spike: false,
            tare_age_ns: None,
        };
        let filter = match config.filter {
            Some(filter) => Some(TipFilter::new(filter)?),
            None => None,
        };
        Ok(Self {
            calibration: config.calibration,
            profile: config.profile,
            tip: TipForceEstimator::new(
                &config.calibration,
                &config.profile,
                &config.noise,
                config.tip,
            )?
            .with_inertia(config.inertia)?,
            frame: SensorFrame::new(&config.calibration),
            filter,
            guard,
            limits,
            torque: limits
                .torque
                .map(|t| TorqueCheck::new(&config.calibration, &config.profile, &config.noise, &t)),
            bias,
            last,
            last_now_ns: None,
            last_counter: None,
            counter_stamp_ns: 0,
            last_joints: None,
            noise_n: config.noise.std_n(),
            last_values: None,
            repeats: 0,
            last_force_n: None,
            spikes: 0,
            spike_window_left: 0,
            tare_ns: None,
            rest: RestMean::EMPTY,
            tare_mean: TareMean::EMPTY,
            last_tare_ns: None,
        })
    }

    /// Runs one control cycle and returns its result, which stays readable as
    /// [`Estimator::last`] until the next cycle (written in place: no copy of
    /// the large output on the loop's path).
    pub fn cycle(&mut self, input: &CycleInput) -> &CycleOutput {
        self.cycle_following(input, None)
    }

    /// [`Estimator::cycle`] with the following-error check: with a
    /// `reference`, a valid joint sample farther than its tolerance from it
    /// on any axis (or a reference that is not finite) is a Fault
    /// ([`Reason::FollowingError`]).
    pub fn cycle_following(
        &mut self,
        input: &CycleInput,
        reference: Option<&FollowingReference>,
    ) -> &CycleOutput {
        self.cycle_checked(input, reference, None)
    }

    /// [`Estimator::cycle_following`] with a fault of the host that runs the
    /// loop (e.g. [`Reason::PublisherStalled`]), which the caller derives
    /// from inputs it records: a Fault like any input fault, checked after
    /// the clock and the sensor's own checks.
    pub fn cycle_checked(
        &mut self,
        input: &CycleInput,
        reference: Option<&FollowingReference>,
        host_fault: Option<Reason>,
    ) -> &CycleOutput {
        self.cycle_in_motion(input, reference, host_fault, &CarriageMotion::REST)
    }

    /// [`Estimator::cycle_checked`] with the carriage's commanded motion at
    /// the sensor sample's stamp (MODEL.md 10): the tip force is compensated
    /// for the rod's inertia with it
    /// ([`crate::tip_force::TipForceEstimator::estimate_in_motion`]; its
    /// standard deviation, which the guard's margin uses, grows with the
    /// acceleration's and the inertia's), and so is the torsion in the
    /// torque check's prediction. With [`CarriageMotion::REST`] exactly
    /// [`Estimator::cycle_checked`]. The loop derives `motion` from the
    /// trajectory it commands (a pure function of the recorded inputs).
    pub fn cycle_in_motion(
        &mut self,
        input: &CycleInput,
        reference: Option<&FollowingReference>,
        host_fault: Option<Reason>,
        motion: &CarriageMotion,
    ) -> &CycleOutput {
        let checks = self.check_inputs(input, reference);
        let sensor = &input.sensor;
        let joints = &input.joints;
        let fresh = self.freshness(checks.now_ns, sensor, joints);
        let tare = self.tare_status(checks.now_ns);
        self.begin_output(input.cycle, &checks, &fresh, &tare);
        let (tip_input, torque_fault) = self.estimate_tip(
            &joints.joints,
            fresh.joints_valid,
            fresh.sensor_valid,
            sensor,
            motion,
        );
        self.step_filter(checks.lost_samples, sensor.counter);
        if checks.new_sample && self.guard.awaiting_first_reset() {
            self.update_rest_mean(&joints.joints);
        }
        if checks.new_sample {
            self.update_tare_mean(&joints.joints, sensor);
        }
        self.last.transition = self.guard.step(&GuardInput {
            cycle: input.cycle,
            input_fault: checks.first_fault(host_fault, torque_fault),
            new_sample: checks.new_sample,
            sensor_age_ns: fresh.sensor_age_ns.unwrap_or(0),
            sensor_valid: fresh.sensor_valid,
            joints_age_ns: fresh.joints_age_ns.unwrap_or(0),
            joints_valid: fresh.joints_valid,
            tip: tip_input,
            extra_margin_n: tare.extra_margin_n,
            tare_due: tare.due,
            smoothed_force_n: self.last.filtered.map(|f| f.force_n),
        });
        if let Some(command) = input.command {
            let result = self.apply(command, input, checks.now_ns);
            self.last.command = Some(CommandEvent { command, result });
        }
        self.finish_output();
        &self.last
    }

    /// The plausibility checks of the inputs, in their fixed order (each
    /// moves its own memory of earlier cycles): clock, sensor counter,
    /// device status, the sensor's values, joints (with the following error
    /// against `reference`).
    fn check_inputs(
        &mut self,
        input: &CycleInput,
        reference: Option<&FollowingReference>,
    ) -> InputChecks {
        let (now_ns, clock_fault) = self.check_clock(input.now_ns);
        let sensor = &input.sensor;
        let (new_sample, lost_samples, counter_fault) = self.check_counter(sensor);
        let status_fault = (sensor.status != 0).then_some(Reason::SensorStatus {
            status: sensor.status,
        });
        let values = self.check_values(sensor, new_sample);
        let joint_fault = self.check_joints(&input.joints, reference);
        InputChecks {
            now_ns,
            clock_fault,
            new_sample,
            lost_samples,
            counter_fault,
            status_fault,
            values,
            joint_fault,
        }
    }

    /// The inputs' ages and validity at `now_ns` (none without a trusted
    /// clock). A sample stamped in the future, or not finite, is invalid
    /// whatever the driver said; so are joints stamped in the future.
    fn freshness(
        &self,
        now_ns: Option<u64>,
        sensor: &SensorSample,
        joints: &JointSample,
    ) -> Freshness {
        match now_ns {
            Some(now) => Freshness {
                sensor_age_ns: Some(now.saturating_sub(self.counter_stamp_ns)),
                joints_age_ns: Some(now.saturating_sub(joints.stamp_ns)),
                sensor_valid: sensor.valid
                    && self.counter_stamp_ns <= now
                    && sensor.force_n.iter().all(|x| x.is_finite())
                    && sensor.torque_nm.iter().all(|x| x.is_finite()),
                joints_valid: joints.valid && joints.stamp_ns <= now,
            },
            None => Freshness {
                sensor_age_ns: None,
                joints_age_ns: None,
                sensor_valid: false,
                joints_valid: false,
            },
        }
    }

    /// The tare's age (its clock starts at the first trusted reading), the
    /// drift bound since it, and whether a tare is due.
    fn tare_status(&mut self, now_ns: Option<u64>) -> TareStatus {
        if let (Some(now), None) = (now_ns, self.tare_ns) {
            self.tare_ns = Some(now);
        }
        let age_ns = now_ns
            .zip(self.tare_ns)
            .map(|(now, tare)| now.saturating_sub(tare));
        let tare = self.limits.tare;
        let extra_margin_n = age_ns.map_or(0.0, |age| tare.drift_n_per_s * ns_to_s(age));
        let due = match (tare.max_age_ns, age_ns) {
            (Some(max_ns), Some(age_ns)) if age_ns > max_ns => Some(Reason::TareDue {
                age_s: ns_to_s(age_ns),
                max_age_s: ns_to_s(max_ns),
            }),
            _ => None,
        };
        TareStatus {
            age_ns,
            extra_margin_n,
            due,
        }
    }

    /// The output's fields known before the estimate; the torque check and
    /// the command are cleared (this cycle writes them if it has them).
    fn begin_output(
        &mut self,
        cycle: u64,
        checks: &InputChecks,
        fresh: &Freshness,
        tare: &TareStatus,
    ) {
        let out = &mut self.last;
        out.cycle = cycle;
        out.sensor_age_ns = fresh.sensor_age_ns;
        out.joints_age_ns = fresh.joints_age_ns;
        out.new_sample = checks.new_sample;
        out.torque = None;
        out.command = None;
        out.spike = checks.values.spike;
        out.tare_age_ns = tare.age_ns;
    }

    /// The guard's state and reason after the step and the command, into the
    /// output; in debug builds, the output's coherence.
    fn finish_output(&mut self) {
        self.last.guard_state = self.guard.state();
        self.last.guard_reason = self.guard.reason();
        self.debug_check_output();
    }

    /// What a reader of [`CycleOutput`] may rely on, checked in debug builds
    /// after every cycle: a pose exactly when the kinematics gave one (an
    /// estimate, a refusal of the estimator and an invalid sensor sample
    /// come with one); the torque residual and the filtered force only
    /// beside an estimate (the filtered one beside an observable one); a
    /// spike only in a new sample; the guard's state as the guard holds it.
    #[inline]
    fn debug_check_output(&self) {
        let out = &self.last;
        let with_pose = matches!(
            out.tip,
            TipOutcome::Estimate(_) | TipOutcome::Refused(_) | TipOutcome::SensorInvalid
        );
        debug_assert_eq!(out.pose.is_some(), with_pose, "pose vs {:?}", out.tip);
        debug_assert!(
            out.torque.is_none() || matches!(out.tip, TipOutcome::Estimate(_)),
            "a torque residual without an estimate"
        );
        debug_assert!(
            out.filtered.is_none() || matches!(out.tip, TipOutcome::Estimate(e) if e.observable),
            "a filtered force without an observable estimate"
        );
        debug_assert!(!out.spike || out.new_sample, "a spike in a repeated sample");
        debug_assert_eq!(out.guard_state, self.guard.state());
    }

    /// The clock: no reading, or one that does not advance, trusts nothing;
    /// a cycle later after the previous one than the sensor's accepted age
    /// is a Fault of its own (a stall: nothing was judged meanwhile), its
    /// time trusted.
    fn check_clock(&mut self, now_ns: Option<u64>) -> (Option<u64>, Option<Reason>) {
        match now_ns {
            None => (None, Some(Reason::ClockFailed)),
            Some(now_ns) => match self.last_now_ns {
                Some(previous_ns) if now_ns <= previous_ns => (
                    None,
                    Some(Reason::ClockNotAdvancing {
                        previous_ns,
                        now_ns,
                    }),
                ),
                previous => {
                    self.last_now_ns = Some(now_ns);
                    let max_ns = self.guard.config().limits().max_sensor_age_ns;
                    let gap = previous
                        .map(|p| now_ns - p)
                        .filter(|&gap_ns| gap_ns > max_ns)
                        .map(|gap_ns| Reason::CycleGap { gap_ns, max_ns });
                    (Some(now_ns), gap)
                }
            },
        }
    }

    /// The sensor counter: a new sample, a gap, or the same sample again
    /// (whose age runs from its first stamp, however it was re-stamped).
    /// Returns (new sample, samples lost beyond what the time explains,
    /// fault).
    fn check_counter(&mut self, sensor: &SensorSample) -> (bool, bool, Option<Reason>) {
        let new_sample = self.last_counter != Some(sensor.counter);
        let mut fault = None;
        if new_sample {
            if let Some(previous) = self.last_counter {
                // Samples the time since the last one explains (a late
                // cycle): that many, less the one step of no loss.
                let explained = sensor
                    .stamp_ns
                    .saturating_sub(self.counter_stamp_ns)
                    .saturating_add(self.limits.sample_period_ns / 2);
                let explained = explained / self.limits.sample_period_ns.max(1);
                let explained = u32::try_from(explained).unwrap_or(u32::MAX);
                let max_gap = self
                    .limits
                    .max_counter_gap
                    .saturating_add(explained.saturating_sub(1));
                if sensor.counter.wrapping_sub(previous) > max_gap {
                    fault = Some(Reason::SensorCounterGap {
                        previous,
                        got: sensor.counter,
                        max_gap,
                    });
                }
            }
            self.last_counter = Some(sensor.counter);
            self.counter_stamp_ns = sensor.stamp_ns;
        }
        (new_sample, fault.is_some(), fault)
    }

    /// The sensor's own values: saturation (this cycle's sample), frozen
    /// (identical new samples in a row), spikes (jumps far beyond the noise
    /// between new samples). The frozen and spike memories move only with
    /// new samples; their faults hold as long as their cause does, so that a
    /// reset is judged on them in every cycle.
    fn check_values(&mut self, sensor: &SensorSample, new_sample: bool) -> SampleVerdict {
        let f = &sensor.force_n;
        let t = &sensor.torque_nm;
        let finite = f.iter().chain(t.iter()).all(|v| v.is_finite());
        let mut fault = None;
        if finite && let Some(range) = self.limits.range {
            let values = [f.x, f.y, f.z, t.x, t.y, t.z];
            let ranges = [
                range.force_n.x,
                range.force_n.y,
                range.force_n.z,
                range.torque_nm.x,
                range.torque_nm.y,
                range.torque_nm.z,
            ];
            fault = SensorChannel::ALL
                .iter()
                .zip(values.iter().zip(ranges.iter()))
                .find(|(_, (value, range))| value.abs() >= **range)
                .map(|(channel, (value, range))| Reason::SensorSaturated {
                    channel: *channel,
                    value: *value,
                    range: *range,
                });
        }
        let spike = self.new_values(sensor, new_sample, finite);
        if let FrozenCheck::On { repeats } = self.limits.frozen
            && self.repeats >= repeats
        {
            fault = fault.or(Some(Reason::SensorFrozen {
                repeats: self.repeats,
            }));
        }
        if let Some(limits) = self.limits.spikes
            && self.spike_window_left > 0
            && self.spikes >= limits.max_spikes
        {
            fault = fault.or(Some(Reason::SensorSpikes {
                spikes: self.spikes,
                window: limits.window_samples,
            }));
        }
        SampleVerdict { fault, spike }
    }

    /// A cycle's sample for the frozen and spike memories: whether it is a
    /// spike. The memories move with new samples (a NaN restarts them);
    /// when the loop counted the samples it drained since the previous
    /// cycle, the spike check takes its counts (new sample or not).
    fn new_values(&mut self, sensor: &SensorSample, new_sample: bool, finite: bool) -> bool {
        let (f, t) = (&sensor.force_n, &sensor.torque_nm);
        let mut spike = false;
        if new_sample {
            if finite {
                let bits = [f.x, f.y, f.z, t.x, t.y, t.z].map(f64::to_bits);
                self.repeats = if self.last_values == Some(bits) {
                    self.repeats.saturating_add(1)
                } else {
                    0
                };
                self.last_values = Some(bits);
                if let Some(limits) = self.limits.spikes
                    && !sensor.drained.counted
                {
                    spike = self.count_spike(&limits, f);
                }
                self.last_force_n = Some(*f);
            } else {
                // NaN is a fault of its own; the memories restart after it.
                self.last_values = None;
                self.repeats = 0;
                self.last_force_n = None;
            }
        }
        // The loop counted every sample received since the previous cycle:
        // the check takes its counts (new sample or not).
        if let Some(limits) = self.limits.spikes
            && sensor.drained.counted
        {
            spike = self.count_drained(&limits, sensor.drained);
        }
        spike
    }

    /// The samples the loop drained this cycle for the spike check: the
    /// window moves by them, and their jumps (counted at the last of them)
    /// open or fill it, as [`Estimator::count_spike`] does one new sample
    /// at a time. Whether any jumped.
    fn count_drained(&mut self, limits: &SpikeLimits, drained: DrainedSamples) -> bool {
        let samples = u32::from(drained.samples);
        // At most one jump per sample received.
        let jumps = u32::from(drained.jumps).min(samples);
        if self.spike_window_left > 0 {
            self.spike_window_left = self.spike_window_left.saturating_sub(samples);
            if self.spike_window_left == 0 {
                self.spikes = 0;
            }
        }
        if jumps == 0 {
            return false;
        }
        if self.spike_window_left == 0 {
            self.spike_window_left = limits.window_samples;
            self.spikes = 0;
        }
        self.spikes = self.spikes.saturating_add(jumps).min(limits.window_samples);
        true
    }

    /// One new finite sample for the spike check: whether it is a spike.
    fn count_spike(&mut self, limits: &SpikeLimits, force_n: &Vec3) -> bool {
        if self.spike_window_left > 0 {
            self.spike_window_left -= 1;
            if self.spike_window_left == 0 {
                self.spikes = 0;
            }
        }
        let Some(previous) = self.last_force_n else {
            return false;
        };
        let spike = limits.is_jump(&self.noise_n, &previous, force_n);
        if spike {
            if self.spike_window_left == 0 {
                self.spike_window_left = limits.window_samples;
                self.spikes = 0;
            }
            self.spikes = self.spikes.saturating_add(1);
        }
        // A window holds at most `window_samples` new samples, so at most
        // that many spikes.
        debug_assert!(self.spike_window_left <= limits.window_samples);
        debug_assert!(
            self.spikes <= limits.window_samples,
            "{} spikes in a window of {}",
            self.spikes,
            limits.window_samples
        );
        spike
    }

    /// The joints: no faster than the axes can move, the stamp not going
    /// back, and (with a reference) within the following tolerance.
    fn check_joints(
        &mut self,
        joints: &JointSample,
        reference: Option<&FollowingReference>,
    ) -> Option<Reason> {
        let q = &joints.joints;
        if !(joints.valid && q.q1_m.is_finite() && q.q2_m.is_finite() && q.q3_m.is_finite()) {
            return None;
        }
        let mut fault = None;
        if let Some((previous, previous_ns)) = self.last_joints {
            if joints.stamp_ns < previous_ns {
                fault = Some(Reason::JointsStampBackwards {
                    previous_ns,
                    got_ns: joints.stamp_ns,
                });
            } else {
                let dt_s = (joints.stamp_ns - previous_ns) as f64 * 1e-9;
                let allowed_m = self.limits.max_joint_speed_mps * dt_s + self.limits.joint_margin_m;
                let (axis, moved_m) = largest_move(q, &previous);
                if moved_m > allowed_m {
                    fault = Some(Reason::JointJump {
                        axis,
                        moved_m,
                        allowed_m,
                    });
                }
            }
        }
        self.last_joints = Some((*q, joints.stamp_ns));
        fault.or_else(|| reference.and_then(|r| following_fault(q, r)))
    }

    /// The pose, the tip force and the torque check, written into
    /// `self.last`; returns what the guard gets and the torque's verdict.
    fn estimate_tip(
        &mut self,
        q: &ActiveJoints,
        joints_valid: bool,
        sensor_valid: bool,
        sensor: &SensorSample,
        motion: &CarriageMotion,
    ) -> (TipInput, Option<Reason>) {
        let out = &mut self.last;
        let pose = if joints_valid {
            Some(forward(&self.calibration, &self.profile, q))
        } else {
            None
        };
        let mut torque_fault = None;
        let out_pose = match pose {
            None => {
                out.pose = None;
                out.tip = TipOutcome::JointsInvalid;
                return (TipInput::NotObservable, None);
            }
            Some(Err(e)) => {
                out.pose = None;
                out.tip = TipOutcome::PoseInvalid(e);
                return (TipInput::PoseInvalid, None);
            }
            Some(Ok(pose)) => out.pose.insert(pose),
        };
        if !sensor_valid {
            out.tip = TipOutcome::SensorInvalid;
            return (TipInput::NotObservable, None);
        }
        match self
            .tip
            .estimate_in_motion(out_pose, &sensor.force_n, &self.bias.force_n, motion)
        {
            Ok(estimate) => {
                out.tip = TipOutcome::Estimate(estimate);
                if let Some(check) = &self.torque {
                    let residual = torque_residual(
                        check,
                        &self.frame,
                        out_pose,
                        sensor,
                        &self.bias,
                        estimate.torsion_nm,
                    );
                    let residual = widened(residual, estimate.torsion_std_nm, || {
                        self.frame.torsion_axis_s(out_pose)
                    });
                    torque_fault = torque_verdict(check, &residual);
                    out.torque = Some(residual);
                }
                let tip_input = TipInput::Estimate {
                    force_n: estimate.force_n,
                    std_n: estimate.std_n,
                    rod_dir: out_pose.rod_dir,
                    observable: estimate.observable,
                    max_std_n: self.tip.max_std_n(),
                };
                (tip_input, torque_fault)
            }
            Err(e) => {
                out.tip = TipOutcome::Refused(e);
                (TipInput::NotObservable, None)
            }
        }
    }

    /// The filter: stepped with each new sample's observable estimate (a
    /// gap the time explains stepped over with the sample held), reset when
    /// there is none or samples were lost (no stale state carried over).
    fn step_filter(&mut self, lost_samples: bool, counter: u32) {
        let out = &mut self.last;
        out.filtered = None;
        if let Some(filter) = &mut self.filter {
            if lost_samples {
                filter.reset();
            }
            match out.tip {
                TipOutcome::Estimate(e) if e.observable => {
                    // A refused input resets the filter: no output then.
                    out.filtered = filter.update_counted(counter, &e.force_n, &e.std_n).ok();
                }
                _ => filter.reset(),
            }
        }
    }

    /// The means at rest: one new sample's estimate and torque residual
    /// into them; joints that moved (beyond the joint margin) restart them,
    /// and so does a sample without an estimate.
    fn update_rest_mean(&mut self, q: &ActiveJoints) {
        let Some(limits) = self.limits.mounting else {
            return;
        };
        let rest = &mut self.rest;
        let TipOutcome::Estimate(e) = self.last.tip else {
            *rest = RestMean::EMPTY;
            return;
        };
        let moved = rest
            .joints
            .is_some_and(|p| largest_move(q, &p).1 > self.limits.joint_margin_m);
        if moved || rest.joints.is_none() {
            *rest = RestMean {
                joints: Some(*q),
                ..RestMean::EMPTY
            };
        }
        rest.count = rest.count.saturating_add(1).min(limits.rest_samples);
        debug_assert!(rest.count >= 1 && rest.count <= limits.rest_samples);
        let k = 1.0 / f64::from(rest.count);
        rest.force_n += (e.force_n - rest.force_n) * k;
        rest.std_n = e.std_n;
        if let Some(t) = self.last.torque {
            rest.torque_nm += (t.residual_nm - rest.torque_nm) * k;
            rest.std_nm = t.std_nm;
        }
    }

    /// The tare's mean at rest: one new sample's reading into it; joints
    /// that moved (beyond the joint margin) restart it, and so does a
    /// sample without an estimate (no pose, invalid or stale input).
    fn update_tare_mean(&mut self, q: &ActiveJoints, sensor: &SensorSample) {
        let window = self.limits.tare.window_samples.max(1);
        let mean = &mut self.tare_mean;
        if !matches!(self.last.tip, TipOutcome::Estimate(_)) {
            *mean = TareMean::EMPTY;
            return;
        }
        let moved = mean
            .joints
            .is_some_and(|p| largest_move(q, &p).1 > self.limits.joint_margin_m);
        if moved || mean.joints.is_none() {
            *mean = TareMean {
                joints: Some(*q),
                ..TareMean::EMPTY
            };
        }
        mean.count = mean.count.saturating_add(1).min(window);
        let k = 1.0 / f64::from(mean.count);
        // Welford's recursion with weight k: the population variance of the
        // first `window` samples, an exponential one beyond.
        let d = sensor.force_n - mean.force_n;
        mean.force_n += d * k;
        mean.var_n2 = (mean.var_n2 + d.component_mul(&d) * k) * (1.0 - k);
        mean.torque_nm += (sensor.torque_nm - mean.torque_nm) * k;
    }

    /// Whether a tare may be taken now: the rate limit, a full mean at
    /// rest, a spread within the noise; the mean reading when it may.
    fn tare_reading(
        &self,
        sensor: &SensorSample,
        now_ns: Option<u64>,
    ) -> Result<SensorSample, TareRefused> {
        let limits = self.limits.tare;
        if let (Some(last), Some(now)) = (self.last_tare_ns, now_ns) {
            let since_ns = now.saturating_sub(last);
            if since_ns < limits.min_interval_ns {
                return Err(TareRefused::TooSoon {
                    since_s: ns_to_s(since_ns),
                    min_interval_s: ns_to_s(limits.min_interval_ns),
                });
            }
        }
        let mean = &self.tare_mean;
        let needed = limits.window_samples.max(1);
        if mean.count < needed {
            return Err(TareRefused::NotAtRest {
                samples: mean.count,
                needed,
            });
        }
        let axes = [Axis::X, Axis::Y, Axis::Z];
        for ((axis, var), noise) in axes.iter().zip(mean.var_n2.iter()).zip(self.noise_n.iter()) {
            let std_n = libm::sqrt(*var);
            let allowed_n = limits.max_spread * noise;
            // NaN counts as beyond.
            if std_n.is_nan() || std_n > allowed_n {
                return Err(TareRefused::NotSteady {
                    axis: *axis,
                    std_n,
                    allowed_n,
                });
            }
        }
        Ok(SensorSample {
            force_n: mean.force_n,
            torque_nm: mean.torque_nm,
            ..*sensor
        })
    }

    /// The first reset's check of the wrench at rest ([`MountingLimits`]):
    /// the refusal's reason, or `None` when the residuals are within bounds
    /// (or there is no estimate: the guard's own blocker then refuses).
    /// Refused while the mean is not complete (`RestIncomplete`).
    fn mounting_verdict(&self, limits: &MountingLimits) -> Option<Reason> {
        let (TipOutcome::Estimate(_), Some(pose)) = (self.last.tip, self.last.pose) else {
            return None;
        };
        let rest = &self.rest;
        // The tolerances below are stated for the full mean; a first reset
        // before it (just started, or moved) waits: never a verdict on fewer
        // samples, with a wider allowance.
        if rest.count < limits.rest_samples {
            return Some(Reason::RestIncomplete {
                samples: rest.count,
                needed: limits.rest_samples,
            });
        }
        let root_n = libm::sqrt(f64::from(rest.count));
        let u = pose.rod_dir;
        let f = rest.force_n;
        let axial_n = f.dot(&u).abs();
        let lateral_n = (f - u * f.dot(&u)).norm();
        let noise_n = limits.sigma * rest.std_n.norm() / root_n;
        let checks = [
            (
                RestResidual::Lateral,
                lateral_n,
                noise_n + limits.tolerance_n,
            ),
            (
                RestResidual::Axial,
                axial_n,
                noise_n + limits.friction_n + limits.tolerance_n,
            ),
            (
                RestResidual::Torque(Axis::X),
                rest.torque_nm.x.abs(),
                limits.sigma * rest.std_nm.x / root_n + limits.tolerance_nm,
            ),
            (
                RestResidual::Torque(Axis::Y),
                rest.torque_nm.y.abs(),
                limits.sigma * rest.std_nm.y / root_n + limits.tolerance_nm,
            ),
            (
                RestResidual::Torque(Axis::Z),
                rest.torque_nm.z.abs(),
                limits.sigma * rest.std_nm.z / root_n + limits.tolerance_nm,
            ),
        ];
        // NaN counts as beyond (conservative).
        checks
            .into_iter()
            .find(|(_, value, allowed)| value.is_nan() || value > allowed)
            .map(|(residual, value, allowed)| Reason::MountingMismatch {
                residual,
                value,
                allowed,
            })
    }

    /// Applies `command` after this cycle's step (whose output is in
    /// `self.last`).
    fn apply(
        &mut self,
        command: Command,
        input: &CycleInput,
        now_ns: Option<u64>,
    ) -> Result<CommandAccepted, CommandRefused> {
        if let Command::SetBias(bias) = command {
            bias.check()
                .map_err(|value| CommandRefused::BiasNonFinite { value })?;
        }
        if let Command::SetLimits(limits) = command {
            return self.set_limits(limits);
        }
        if command == Command::Reset {
            return self.reset(input);
        }
        let pose = self.bias_allowed()?;
        let bias = match command {
            Command::SetBias(bias) => bias,
            _ => self.tare_now(&pose, input, now_ns)?,
        };
        let previous = self.bias;
        self.bias = bias;
        // The tare's age restarts (a clock is known: the guard is not Ok
        // without one).
        self.tare_ns = now_ns.or(self.tare_ns);
        Ok(CommandAccepted::BiasSet { previous, bias })
    }

    /// The operator's new force limits, handed to the guard.
    fn set_limits(&mut self, limits: ForceLimits) -> Result<CommandAccepted, CommandRefused> {
        match self.guard.set_force_limits(&limits) {
            Ok(previous) => Ok(CommandAccepted::LimitsSet { previous, limits }),
            Err(SettingError::Invalid { field, value, why }) => {
                Err(CommandRefused::Limits { field, value, why })
            }
            Err(_) => Err(CommandRefused::Limits {
                field: "limits",
                value: f64::NAN,
                why: "refused",
            }),
        }
    }

    /// The operator's reset. The first one: the wrench at rest must match
    /// the model, unless a fault blocks it anyway (the guard then names it).
    fn reset(&mut self, input: &CycleInput) -> Result<CommandAccepted, CommandRefused> {
        let fault_blocks = self
            .guard
            .reset_blocker()
            .is_some_and(|r| !matches!(r, Reason::AboveStop { .. }));
        if self.guard.awaiting_first_reset()
            && self.guard.state().is_halting()
            && !fault_blocks
            && let Some(limits) = self.limits.mounting
            && let Some(reason) = self.mounting_verdict(&limits)
        {
            return Err(CommandRefused::Reset { reason });
        }
        match self.guard.reset(input.cycle) {
            Ok(Some(t)) => {
                self.last.transition = Some(t);
                Ok(CommandAccepted::Reset)
            }
            Ok(None) => Ok(CommandAccepted::NothingToReset),
            Err(e) => Err(CommandRefused::Reset { reason: e.reason }),
        }
    }

    /// Whether a tare or a bias may be set now: only in Ok (or the Warn of a
    /// due tare), below every warn limit, on this cycle's estimate (whose
    /// pose it returns).
    fn bias_allowed(&self) -> Result<Pose, CommandRefused> {
        let state = self.guard.state();
        let tare_warn =
            state == GuardState::Warn && matches!(self.guard.reason(), Reason::TareDue { .. });
        if state != GuardState::Ok && !tare_warn {
            return Err(CommandRefused::NotOk {
                state,
                reason: self.guard.reason(),
            });
        }
        if let Some(reason) = self.guard.warn_blocker() {
            return Err(CommandRefused::AboveWarn { reason });
        }
        let (TipOutcome::Estimate(_), Some(pose)) = (self.last.tip, self.last.pose) else {
            return Err(CommandRefused::NoEstimate);
        };
        Ok(pose)
    }

    /// The tare's bias at `pose` from the reading at rest. Not at rest: the
    /// mean starts again (its spread would otherwise remember the motion for
    /// a few windows), so the next tare needs a fresh window.
    fn tare_now(
        &mut self,
        pose: &Pose,
        input: &CycleInput,
        now_ns: Option<u64>,
    ) -> Result<Bias, CommandRefused> {
        let reading = match self.tare_reading(&input.sensor, now_ns) {
            Ok(reading) => reading,
            Err(refused) => {
                if matches!(refused, TareRefused::NotSteady { .. }) {
                    self.tare_mean = TareMean {
                        joints: self.tare_mean.joints,
                        ..TareMean::EMPTY
                    };
                }
                return Err(CommandRefused::Tare(refused));
            }
        };
        let bias = self
            .tare(pose, &reading)
            .ok_or(CommandRefused::Unsolvable)?;
        self.last_tare_ns = now_ns.or(self.last_tare_ns);
        Ok(bias)
    }

    /// The bias for which this reading (the mean at rest) gives zero tip
    /// force at this pose, and the torque bias for which the measured torque
    /// is the predicted one. The estimate is affine in the force bias,
    /// F_tip(b + x) = F_tip(b) + J x: J from three unit steps, then
    /// x = -J^-1 F_tip(b). `None` when J is singular or a result is not
    /// finite.
    fn tare(&self, pose: &Pose, sensor: &SensorSample) -> Option<Bias> {
        let b = self.bias.force_n;
        let reading = &sensor.force_n;
        let estimate = self.tip.estimate(pose, reading, &b).ok()?;
        let column = |unit: Vec3| -> Option<Vec3> {
            let e = self.tip.estimate(pose, reading, &(b + unit)).ok()?;
            Some(e.force_n - estimate.force_n)
        };
        let j = Mat3::from_columns(&[column(Vec3::x())?, column(Vec3::y())?, column(Vec3::z())?]);
        let step = j.try_inverse()? * (-estimate.force_n);
        let force_n = b + step;
        let tared = self.tip.estimate(pose, reading, &force_n).ok()?;
        let torque_nm = sensor.torque_nm
            - predicted_torque_nm(&self.frame, reading, &force_n, tared.torsion_nm, || {
                self.frame.torsion_axis_s(pose)
            });
        let bias = Bias { force_n, torque_nm };
        bias.check().ok()?;
        Some(bias)
    }

    /// The result of the last cycle (before the first: no pose, no input, the
    /// guard's initial state).
    pub fn last(&self) -> &CycleOutput {
        &self.last
    }

    /// The bias in use (sensor frame).
    pub fn bias(&self) -> Bias {
        self.bias
    }

    /// The guard's state.
    pub fn guard_state(&self) -> GuardState {
        self.guard.state()
    }

    /// The guard's configuration (its worst-case stop time:
    /// [`GuardConfig::stop_within_ns`]).
    pub fn guard_config(&self) -> &GuardConfig {
        self.guard.config()
    }
}

/// The model's sensor torque without the torque bias, sensor frame:
/// `R_0s^T ((A - S) x (-F_A) - M_T n)` with `-F_A = R_0s (f - b_f)`, i.e.
/// `(R_0s^T (A - S)) x (f - b_f) - R_0s^T n M_T` (MODEL.md 4), N m.
/// `torsion_axis_s` gives R_0s^T n ([`SensorFrame::torsion_axis_s`]); it is
/// called only when the torsion is not 0 (never with d = 0), so that a caller
/// which has it already passes it, and one which has not pays only when needed.
fn predicted_torque_nm(
    frame: &SensorFrame,
    reading_n: &Vec3,
    bias_n: &Vec3,
    torsion_nm: f64,
    torsion_axis_s: impl FnOnce() -> Vec3,
) -> Vec3 {
    let wrench = frame.lever_s_m.cross(&(reading_n - bias_n));
    if torsion_nm == 0.0 {
        wrench
    } else {
        wrench - torsion_axis_s() * torsion_nm
    }
}

/// What the torque model needs of the calibration, fixed at construction.
#[derive(Debug, Clone, Copy)]
struct SensorFrame {
    /// R_0s^T.
    r_t: Mat3,
    /// R_0s^T (A - S): the lever from S to A in the sensor frame (constant:
    /// both are fixed offsets of the carriage), m.
    lever_s_m: Vec3,
}

impl SensorFrame {
    fn new(cal: &Calibration) -> Self {
        let r_t = cal.sensor_rotation().transpose();
        Self {
            r_t,
            lever_s_m: r_t * (cal.ujoint_offset_m() - cal.sensor_offset_m()),
        }
    }

    /// R_0s^T n: the torsion axis of `pose` in the sensor frame.
    fn torsion_axis_s(&self, pose: &Pose) -> Vec3 {
        self.r_t * torsion_axis(&rod_cross(pose))
    }
}

/// v = u x w, the q5 axis (c4, 0, -s4), as the tip-force estimator forms it.
fn rod_cross(pose: &Pose) -> Vec3 {
    pose.rod_dir.cross(&pose.rod_normal)
}

/// n = -(s4, 0, c4) = Y0 x v, from v = u x w ([`rod_cross`]), as the
/// tip-force estimator forms it.
fn torsion_axis(v: &Vec3) -> Vec3 {
    Vec3::y().cross(v)
}

/// Measured minus predicted torque, with its standard deviation.
fn torque_residual(
    check: &TorqueCheck,
    frame: &SensorFrame,
    pose: &Pose,
    sensor: &SensorSample,
    bias: &Bias,
    torsion_nm: f64,
) -> TorqueResidual {
    if check.offset_m == 0.0 {
        // d = 0: the torsion is 0 and the deviation a constant. The same
        // prediction as the tare's (one model of the sensor torque).
        let predicted =
            predicted_torque_nm(frame, &sensor.force_n, &bias.force_n, torsion_nm, || {
                frame.torsion_axis_s(pose)
            }) + bias.torque_nm;
        return TorqueResidual {
            residual_nm: sensor.torque_nm - predicted,
            std_nm: check.std_nm,
        };
    }
    // d != 0: v and n = Y0 x v in the sensor frame, once for the prediction
    // and the deviation.
    let r_t = &frame.r_t;
    let v = rod_cross(pose);
    let n_s = r_t * torsion_axis(&v);
    let predicted = predicted_torque_nm(frame, &sensor.force_n, &bias.force_n, torsion_nm, || n_s)
        + bias.torque_nm;
    // The prediction also holds -R_0s^T n M_T, with the torsion's estimate
    // M_T = d (F_A . v) / w_y and F_A = -R_0s (f - b_f), so its Jacobian in
    // the reading f is J = [l]x + (d / w_y) (R_0s^T n) (R_0s^T v)^T, and
    // var_i = sigma_t,i^2 + sum_j J_ij^2 sigma_f,j^2.
    // Written out per entry (no 3x3 temporaries), in nalgebra's order of
    // operations for `[l]x + n_s v_s^T k` and `(J o J) sigma_f^2`, so the
    // result is the same to the bit.
    let v_s = r_t * v;
    let k = check.offset_m / pose.rod_normal.y;
    let (l, fv, tv) = (&check.cross, &check.force_var_n2, &check.torque_var_nm2);
    // Row i of J: l_i + n_i k v_s^T, squared per entry, against sigma_f^2.
    let std = |l_i: [f64; 3], n_i: f64, tv_i: f64| {
        let sq = |l_ic: f64, v_c: f64| {
            let j_ic = l_ic + n_i * v_c * k;
            j_ic * j_ic
        };
        let [l0, l1, l2] = l_i;
        let sum = sq(l0, v_s.x) * fv.x + sq(l1, v_s.y) * fv.y + sq(l2, v_s.z) * fv.z;
        nalgebra::ComplexField::sqrt(tv_i + sum)
    };
    TorqueResidual {
        residual_nm: sensor.torque_nm - predicted,
        std_nm: Vec3::new(
            std([l.m11, l.m12, l.m13], n_s.x, tv.x),
            std([l.m21, l.m22, l.m23], n_s.y, tv.y),
            std([l.m31, l.m32, l.m33], n_s.z, tv.z),
        ),
    }
}

/// `r` with the torsion's standard deviation in motion, `torsion_std_nm`
/// along the torsion axis `axis_s` (sensor frame), added to its deviation
/// per sensor axis; unchanged when it is 0 (at rest: to the bit).
fn widened(
    r: TorqueResidual,
    torsion_std_nm: f64,
    axis_s: impl FnOnce() -> Vec3,
) -> TorqueResidual {
    if torsion_std_nm == 0.0 {
        return r;
    }
    let spread = axis_s() * torsion_std_nm;
    TorqueResidual {
        std_nm: (r.std_nm.component_mul(&r.std_nm) + spread.component_mul(&spread))
            .map(nalgebra::ComplexField::sqrt),
        ..r
    }
}

/// A Fault for the first sensor axis whose residual is beyond `max_sigma`
/// standard deviations (NaN counts as beyond).
fn torque_verdict(check: &TorqueCheck, r: &TorqueResidual) -> Option<Reason> {
    for ((axis, residual_nm), std_nm) in Axis::ALL
        .iter()
        .zip(r.residual_nm.iter())
        .zip(r.std_nm.iter())
    {
        let within = residual_nm.abs() <= check.max_sigma * std_nm;
        if !within {
            return Some(Reason::TorqueImplausible {
                axis: *axis,
                residual_nm: *residual_nm,
                std_nm: *std_nm,
                max_sigma: check.max_sigma,
            });
        }
    }
    None
}

// Snapshots (issue 17). `last` is the latest cycle's result: every field of
// it is written by each cycle before anything reads it, so it is output.
sar_snapshot::snap_struct!(Bias { force_n, torque_nm });
sar_snapshot::snap_struct!(RestMean {
    count,
    force_n,
    torque_nm,
    std_n,
    std_nm,
    joints,
});
// The configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(PlausibilityLimits {
    max_joint_speed_mps,
    joint_margin_m,
    max_counter_gap,
    sample_period_ns,
    torque,
    frozen,
    range,
    spikes,
    tare,
    mounting,
});
sar_snapshot::config_struct!(TorqueLimits {
    noise_nm,
    max_sigma
});
sar_snapshot::config_enum!(FrozenCheck { On { repeats }, Off });
sar_snapshot::config_struct!(SensorRange { force_n, torque_nm });
sar_snapshot::config_struct!(SpikeLimits {
    jump_sigma,
    max_spikes,
    window_samples,
});
sar_snapshot::config_struct!(TareLimits {
    max_age_ns,
    drift_n_per_s,
    window_samples,
    max_spread,
    min_interval_ns,
});
sar_snapshot::snap_struct!(TareMean {
    count,
    force_n,
    torque_nm,
    var_n2,
    joints,
});
sar_snapshot::config_struct!(MountingLimits {
    sigma,
    friction_n,
    tolerance_n,
    tolerance_nm,
    rest_samples,
});
sar_snapshot::config_struct!(TorqueCheck {
    std_nm,
    cross,
    force_var_n2,
    torque_var_nm2,
    offset_m,
    max_sigma,
});
sar_snapshot::config_struct!(SensorFrame { r_t, lever_s_m });
sar_snapshot::snap_state!(Estimator {
    state: [
        guard,
        bias,
        last_now_ns,
        last_counter,
        counter_stamp_ns,
        last_joints,
        last_values,
        repeats,
        last_force_n,
        spikes,
        spike_window_left,
        tare_ns,
        rest,
        tare_mean,
        last_tare_ns,
    ],
    nested: [filter],
    config: [calibration, profile, tip, frame, limits, torque, noise_n],
    output: [last],
});
