//! The force-limit guard: a state machine fed once per control cycle with the
//! tip-force estimate F_tip (MODEL.md 4.1), its standard deviation and the age
//! and validity of every input. It decides whether the robot may keep moving.
//!
//! States, from least to most severe: [`GuardState::Ok`], [`GuardState::Warn`],
//! [`GuardState::Stop`] (latched), [`GuardState::Fault`] (latched).
//!
//! Each [`Guard::step`] first looks for a fault condition in a fixed order
//! (cycle order, a fault the caller found in the cycle's inputs (clock, sensor
//! counter and status, joint jump, sensor torque), sensor validity, sensor age,
//! joints validity, joints age, pose, invalid numbers, observability flag). Any
//! fault condition sends the guard to `Fault` at once, without debounce: NaN,
//! infinite, stale or unobservable input is never `Ok` or `Warn`. Otherwise the
//! tip force is split into three parts, total |F|, axial |F . u| and lateral
//! |F - (F . u) u|, each compared with its own warn and stop limits.
//!
//! Debounce: entering `Warn` or `Stop` and leaving `Warn` are decided by
//! up/down counts over NEW sensor samples (a cycle that repeats the previous
//! sample, [`GuardInput::new_sample`] false, counts nothing: a 500 Hz sensor
//! read by a 4 kHz loop gives one vote per sample, not eight). Each new sample
//! moves a count up by one when its condition holds and down by one when it
//! does not, within `0..=debounce_samples`; the state changes when the count
//! reaches `debounce_samples`. So a force that is above a limit in more than
//! half of the samples trips it (30, 30, 11 N repeating against a 12 N limit
//! stops on the fifth sample), where a count that restarted at 0 never would.
//! Worst case: a force continuously at or above a stop limit stops within
//! `debounce_samples` new samples, i.e. within
//! [`GuardConfig::stop_within_ns`] = `debounce_samples * max_sensor_age_ns`
//! (a sample older than `max_sensor_age_ns`, measured from when its counter
//! changed, is a Fault).
//!
//! `Stop` and `Fault` are left only through an accepted [`Guard::reset`], which
//! must name the cycle just stepped: it is judged on that cycle's input, never
//! on an older one.
//!
//! Real-time path: no allocation, no panic, O(1) per step, fixed-size state.

use core::fmt;

use crate::{SettingError, Vec3};

/// How far the norm of the rod direction u may be from 1.
pub const ROD_DIR_UNIT_TOLERANCE: f64 = 1e-6;

/// Bounds on the squared norm of u that match [`ROD_DIR_UNIT_TOLERANCE`] (no
/// square root on the good path).
const ROD_DIR_NORM2_MIN: f64 = (1.0 - ROD_DIR_UNIT_TOLERANCE) * (1.0 - ROD_DIR_UNIT_TOLERANCE);
const ROD_DIR_NORM2_MAX: f64 = (1.0 + ROD_DIR_UNIT_TOLERANCE) * (1.0 + ROD_DIR_UNIT_TOLERANCE);

/// Above this largest component magnitude (N) the force is scaled before its
/// norms are taken, so that no square overflows.
const SCALE_ABOVE_N: f64 = 1e150;

/// The limits of the guard, as the caller fills them (e.g. from a
/// configuration file). [`GuardConfig::new`] checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardLimits {
    /// The six force limits (warn and stop on the total, axial and lateral
    /// parts), N.
    pub force: ForceLimits,
    /// `Warn` clears only when every part is below its warn limit minus this, N.
    pub hysteresis_n: f64,
    /// The up/down count over new sensor samples at which `Warn` or `Stop` is
    /// entered and `Warn` left (see the module documentation), 1..=100.
    pub debounce_samples: u32,
    /// Largest accepted age of the force sensor reading, measured from the
    /// stamp of the sample whose counter is the current one (a re-stamped
    /// copy of an old sample does not make it younger), ns. Also the longest
    /// accepted interval between two new samples.
    pub max_sensor_age_ns: u64,
    /// Largest accepted age of the joint positions, ns.
    pub max_joints_age_ns: u64,
    /// k: each part is compared with its limits after adding `k |std_n|`
    /// (|std_n| bounds the standard deviation of every part), so that a force
    /// that may be above a limit counts as above it. 0 compares the estimate
    /// itself; 2 stops a force whose estimate is within two standard deviations
    /// below the limit. 0 <= k <= [`MAX_STD_MARGIN`].
    pub std_margin: f64,
}

impl GuardLimits {
    /// Example limits, for tests and examples (a robot's come from its
    /// configuration): total 10/15 N, axial 8/12 N, lateral 6/10 N (the
    /// default configuration's force limits), hysteresis 1 N, debounce 3 new
    /// samples, inputs at most 5 ms old, no margin.
    pub const EXAMPLE: GuardLimits = GuardLimits {
        force: ForceLimits::DEFAULT,
        hysteresis_n: 1.0,
        debounce_samples: 3,
        max_sensor_age_ns: 5_000_000,
        max_joints_age_ns: 5_000_000,
        std_margin: 0.0,
    };
}

/// The six force limits of the guard, the one type that holds them: in the
/// guard's limits ([`GuardLimits::force`]), what an operator may change at
/// run time ([`crate::cycle::Command::SetLimits`], within the ceilings
/// fixed at start, [`GuardConfig::with_ceiling`]), and, through
/// [`ForceLimits::to_array`] and [`ForceLimits::NAMES`], the wire's six
/// numbers and every name they are shown under (configuration keys, JSON
/// fields, the command line's options, the log).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    /// Warn limit on the total tip force |F_tip|, N.
    pub warn_total_n: f64,
    /// Stop limit on the total tip force |F_tip|, N.
    pub stop_total_n: f64,
    /// Warn limit on the axial part |F_tip . u|, N.
    pub warn_axial_n: f64,
    /// Stop limit on the axial part |F_tip . u|, N.
    pub stop_axial_n: f64,
    /// Warn limit on the lateral part |F_tip - (F_tip . u) u|, N.
    pub warn_lateral_n: f64,
    /// Stop limit on the lateral part |F_tip - (F_tip . u) u|, N.
    pub stop_lateral_n: f64,
}

impl ForceLimits {
    /// The default limits, the one place they are written (the
    /// configuration's `[guard]` defaults and [`GuardLimits::EXAMPLE`]):
    /// total 10/15 N, axial 8/12 N, lateral 6/10 N.
    pub const DEFAULT: ForceLimits = ForceLimits {
        warn_total_n: 10.0,
        stop_total_n: 15.0,
        warn_axial_n: 8.0,
        stop_axial_n: 12.0,
        warn_lateral_n: 6.0,
        stop_lateral_n: 10.0,
    };

    /// The six limits' names, in the order of [`ForceLimits::to_array`]
    /// (the wire's): (warn, stop) for total, axial, lateral. They are the
    /// keys of the configuration's `[guard]`, the fields of `sarctl`'s
    /// JSON, and (without `_n`, `-` for `_`) its options.
    pub const NAMES: [&'static str; 6] = [
        "warn_total_n",
        "stop_total_n",
        "warn_axial_n",
        "stop_axial_n",
        "warn_lateral_n",
        "stop_lateral_n",
    ];

    /// The names of the (warn, stop) limits of each part, in
    /// [`ForcePart::ALL`] order (from [`ForceLimits::NAMES`]).
    pub const fn pair_names() -> [(&'static str, &'static str); 3] {
        let [wt, st, wa, sa, wl, sl] = Self::NAMES;
        [(wt, st), (wa, sa), (wl, sl)]
    }

    /// In the order (warn, stop) total, axial, lateral (the wire's order,
    /// [`ForceLimits::NAMES`]).
    pub fn to_array(&self) -> [f64; 6] {
        let Self {
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        } = *self;
        [
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        ]
    }

    /// From (warn, stop) total, axial, lateral (the order of
    /// [`ForceLimits::to_array`]).
    pub fn from_array(v: [f64; 6]) -> Self {
        let [
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        ] = v;
        Self {
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        }
    }

    /// The warn limits in [`ForcePart::ALL`] order, N.
    pub fn warn_n(&self) -> [f64; 3] {
        [self.warn_total_n, self.warn_axial_n, self.warn_lateral_n]
    }

    /// The stop limits in [`ForcePart::ALL`] order, N.
    pub fn stop_n(&self) -> [f64; 3] {
        [self.stop_total_n, self.stop_axial_n, self.stop_lateral_n]
    }
}

/// As the log and `sarctl limits` print them: `warn/stop total 9/17 N,
/// axial 8/14 N, lateral 3/6 N`.
impl fmt::Display for ForceLimits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("warn/stop")?;
        let parts = ForcePart::ALL.iter().zip(self.warn_n()).zip(self.stop_n());
        for (i, ((part, warn), stop)) in parts.enumerate() {
            let sep = if i == 0 { " " } else { ", " };
            write!(f, "{sep}{part} {warn}/{stop} N")?;
        }
        Ok(())
    }
}

/// Largest accepted `debounce_samples` (0.2 s at 500 Hz): a larger debounce
/// would in effect disable Stop.
pub const MAX_DEBOUNCE_SAMPLES: u32 = 100;

/// Largest accepted `std_margin`.
pub const MAX_STD_MARGIN: f64 = 10.0;

/// Checked guard limits. Exists only if valid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardConfig {
    limits: GuardLimits,
    /// Warn limits in [`ForcePart::ALL`] order, N: a cache, derived from
    /// `limits.force` ([`ForceLimits::warn_n`]) whenever it is set.
    warn_n: [f64; 3],
    /// Stop limits in [`ForcePart::ALL`] order, N: a cache, derived from
    /// `limits.force` ([`ForceLimits::stop_n`]).
    stop_n: [f64; 3],
    /// Warn limits minus the hysteresis, in [`ForcePart::ALL`] order, N: a
    /// cache, derived from `limits` too.
    clear_n: [f64; 3],
    /// The largest stop limit a run-time change may set, in
    /// [`ForcePart::ALL`] order, N (default: the configured stop limits, so
    /// that limits can only be lowered).
    ceiling_n: [f64; 3],
    /// In `Retreat`, how far a part's filtered value may rise above the
    /// lowest value it had since the retreat began before the guard stops
    /// again, N ([`GuardConfig::with_retreat_rise_n`]).
    retreat_rise_n: f64,
}

/// Default rise allowance in `Retreat`, N: well above the excursions of the
/// filtered tip force's noise (its standard deviation is about 0.1-0.3 N with
/// the HEX-6 and a 5 Hz filter at the nominal pose), so that a still, noisy
/// retreat never stops by itself, and well below any stop limit.
pub const DEFAULT_RETREAT_RISE_N: f64 = 2.0;

fn invalid(field: &'static str, value: f64, why: &'static str) -> SettingError {
    SettingError::Invalid { field, value, why }
}

impl GuardConfig {
    /// Checks the limits: all finite; for each of total, axial and lateral
    /// 0 < warn < stop; 0 <= hysteresis < every warn limit; both maximum ages
    /// > 0; 1 <= debounce <= 100; 0 <= std_margin <= 10.
    pub fn new(limits: GuardLimits) -> Result<Self, SettingError> {
        let force = &limits.force;
        let (warn_n, stop_n) = (force.warn_n(), force.stop_n());
        let names = ForceLimits::pair_names();
        for (((warn_field, stop_field), warn), stop) in names.into_iter().zip(warn_n).zip(stop_n) {
            if !(warn.is_finite() && warn > 0.0) {
                return Err(invalid(warn_field, warn, "must be finite and > 0"));
            }
            if !(stop.is_finite() && stop > warn) {
                return Err(invalid(
                    stop_field,
                    stop,
                    "must be finite and > its warn limit",
                ));
            }
        }
        let h = limits.hysteresis_n;
        let min_warn = force
            .warn_total_n
            .min(force.warn_axial_n)
            .min(force.warn_lateral_n);
        if !(h.is_finite() && h >= 0.0 && h < min_warn) {
            return Err(invalid(
                "hysteresis_n",
                h,
                "must be finite, >= 0 and < every warn limit",
            ));
        }
        if !(1..=MAX_DEBOUNCE_SAMPLES).contains(&limits.debounce_samples) {
            return Err(invalid(
                "debounce_samples",
                f64::from(limits.debounce_samples),
                "must be >= 1 and <= 100",
            ));
        }
        let k = limits.std_margin;
        if !(k.is_finite() && (0.0..=MAX_STD_MARGIN).contains(&k)) {
            return Err(invalid("std_margin", k, "must be finite, >= 0 and <= 10"));
        }
        if limits.max_sensor_age_ns == 0 {
            return Err(invalid("max_sensor_age_ns", 0.0, "must be > 0"));
        }
        if limits.max_joints_age_ns == 0 {
            return Err(invalid("max_joints_age_ns", 0.0, "must be > 0"));
        }
        let clear_n = warn_n.map(|w| w - h);
        Ok(Self {
            limits,
            warn_n,
            stop_n,
            clear_n,
            ceiling_n: stop_n,
            retreat_rise_n: DEFAULT_RETREAT_RISE_N,
        })
    }

    /// Sets the rise allowance of `Retreat` (finite, >= 0, below the smallest
    /// stop limit).
    pub fn with_retreat_rise_n(mut self, rise_n: f64) -> Result<Self, SettingError> {
        let smallest_stop_n = self.stop_n.iter().fold(f64::INFINITY, |a, b| a.min(*b));
        if !(rise_n.is_finite() && rise_n >= 0.0 && rise_n < smallest_stop_n) {
            return Err(invalid(
                "retreat_rise_n",
                rise_n,
                "must be finite, >= 0 and below every stop limit",
            ));
        }
        self.retreat_rise_n = rise_n;
        Ok(self)
    }

    /// The rise allowance of `Retreat`, N.
    pub fn retreat_rise_n(&self) -> f64 {
        self.retreat_rise_n
    }

    /// The checked limits.
    pub fn limits(&self) -> GuardLimits {
        self.limits
    }

    /// The six force limits in use.
    pub fn force_limits(&self) -> ForceLimits {
        self.limits.force
    }

    /// The ceilings of the stop limits (total, axial, lateral), N.
    pub fn ceiling_n(&self) -> [f64; 3] {
        self.ceiling_n
    }

    /// Sets the ceilings of the stop limits that a run-time change may set
    /// (total, axial, lateral), N: each finite and at least the configured
    /// stop limit.
    pub fn with_ceiling(mut self, ceiling_n: [f64; 3]) -> Result<Self, SettingError> {
        let fields = ["max_stop_total_n", "max_stop_axial_n", "max_stop_lateral_n"];
        for ((field, c), stop) in fields.into_iter().zip(ceiling_n).zip(self.stop_n) {
            if !(c.is_finite() && c >= stop) {
                return Err(invalid(
                    field,
                    c,
                    "must be finite and >= the configured stop limit",
                ));
            }
        }
        self.ceiling_n = ceiling_n;
        Ok(self)
    }

    /// This configuration with other force limits, checked as
    /// [`GuardConfig::new`] checks them and each stop limit at most its
    /// ceiling; the other settings (hysteresis, debounce, ages, margin) and
    /// the ceilings are kept.
    pub fn with_force_limits(&self, force: &ForceLimits) -> Result<Self, SettingError> {
        let limits = GuardLimits {
            force: *force,
            ..self.limits
        };
        let next = Self::new(limits)?;
        let fields = ForceLimits::pair_names().map(|(_, stop)| stop);
        for ((field, stop), ceiling) in fields.into_iter().zip(next.stop_n).zip(self.ceiling_n) {
            if stop > ceiling {
                return Err(invalid(
                    field,
                    stop,
                    "must be at most its configured ceiling",
                ));
            }
        }
        Ok(Self {
            ceiling_n: self.ceiling_n,
            retreat_rise_n: self.retreat_rise_n,
            ..next
        })
    }

    /// Worst-case time from the first new sample of a force continuously at
    /// or above a stop limit to `Stop`, ns: `debounce_samples` new samples,
    /// each at most `max_sensor_age_ns` after the previous one (a longer gap
    /// is a Fault). Saturates at `u64::MAX`. The sensor's latency comes on top.
    pub fn stop_within_ns(&self) -> u64 {
        u64::from(self.limits.debounce_samples).saturating_mul(self.limits.max_sensor_age_ns)
    }
}

/// What the tip-force estimator delivered this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TipInput {
    /// An estimate.
    Estimate {
        /// F_tip, what the tip applies to the tissue, {0}, N.
        force_n: Vec3,
        /// Standard deviation of each component of F_tip, {0}, N.
        std_n: Vec3,
        /// u, the unit rod direction, {0}.
        rod_dir: Vec3,
        /// The estimator's observability flag
        /// ([`crate::tip_force::TipForceEstimate::observable`]): false is a
        /// Fault ([`Reason::NotObservable`]).
        observable: bool,
        /// The observability limit the estimator applied, N (reported in the
        /// reason).
        max_std_n: f64,
    },
    /// The estimator said the force is not observable (near the singularity
    /// a -> L).
    NotObservable,
    /// The kinematics refused the pose (degenerate pose).
    PoseInvalid,
}

/// Everything the guard looks at in one control cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardInput {
    /// Control cycle number; must strictly increase from step to step.
    pub cycle: u64,
    /// A fault the caller found in this cycle's inputs before the estimate
    /// (clock, sensor counter and status, joint jump, sensor torque): checked
    /// right after the cycle order.
    pub input_fault: Option<Reason>,
    /// Whether the sensor sample of this cycle is a new one (its counter
    /// changed). Only new samples move the debounce counts.
    pub new_sample: bool,
    /// Age of the force sensor reading, ns.
    pub sensor_age_ns: u64,
    /// Whether the force sensor reported its reading valid.
    pub sensor_valid: bool,
    /// Age of the joint positions, ns.
    pub joints_age_ns: u64,
    /// Whether the joint positions are valid.
    pub joints_valid: bool,
    /// The tip-force estimate.
    pub tip: TipInput,
    /// Added to every part before it is compared with its limits, beside the
    /// standard-deviation margin, N (finite, >= 0; else it counts as
    /// infinite): the bound on the bias drift since the last tare
    /// (`drift_n_per_s * age_s`).
    pub extra_margin_n: f64,
    /// `Some(Reason::TareDue { .. })` when a tare is due: Ok becomes Warn.
    pub tare_due: Option<Reason>,
    /// The low-passed F_tip of this cycle ({0}, N), when there is one: what
    /// `Retreat` watches for a rising force (the unfiltered estimate's noise
    /// would make its lowest value drift down and stop a still retreat).
    /// Without it a reset above the stop limit is refused, as without
    /// `Retreat`.
    pub smoothed_force_n: Option<Vec3>,
}

/// The guard's decision. Deliberately not `#[non_exhaustive]` (see
/// [`Reason`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GuardState {
    /// The robot may move.
    Ok,
    /// The robot may move; the tip force is near a stop limit (or a tare is
    /// due).
    Warn,
    /// A stop limit was exceeded: the robot must stop. Latched until reset.
    Stop,
    /// The force cannot be trusted: the robot must stop. Latched until reset.
    Fault,
    /// The way back from a Stop whose force persists: the drives are
    /// released, but only motions that reduce the tip force are accepted
    /// (the loop's rule, [`reduces_force`]); a new fault is a Fault, a
    /// rising force a Stop; below the warn limits it is Ok again.
    Retreat,
}

impl GuardState {
    /// Every state, in code order.
    pub const ALL: [GuardState; 5] = [Self::Ok, Self::Warn, Self::Stop, Self::Fault, Self::Retreat];

    /// Whether the drives must be halted (Stop or Fault): a quick stop, no
    /// motion until an accepted reset.
    pub fn is_halting(self) -> bool {
        matches!(self, GuardState::Stop | GuardState::Fault)
    }

    /// The stable numeric code (wire, recordings): Ok 0, Warn 1, Stop 2,
    /// Fault 3, Retreat 4.
    pub const fn code(self) -> u8 {
        match self {
            Self::Ok => 0,
            Self::Warn => 1,
            Self::Stop => 2,
            Self::Fault => 3,
            Self::Retreat => 4,
        }
    }

    /// The state of a code, if any.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.code() == code)
    }
}

impl fmt::Display for GuardState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Ok => "ok",
            Self::Warn => "warn",
            Self::Stop => "stop",
            Self::Fault => "fault",
            Self::Retreat => "retreat",
        })
    }
}

/// Whether a wanted tip displacement `step_m` (base frame, m) reduces the
/// tip force `force_n` (F_tip: what the tip applies to the tissue, {0}) with
/// the rod along the unit `rod_dir` u: the rule of motion in
/// [`GuardState::Retreat`].
///
/// Sign convention: the tissue is pushed by F_tip, so moving the tip along
/// +F_tip pushes deeper and raises the force; moving against it relieves
/// it. Accepted: a step within 60 degrees of -F_tip (`step . F_tip <=
/// -cos 60 |step| |F_tip|`: mostly against the force, not a drag across
/// the tissue), or backing out along the rod (`step` within 8 degrees of
/// -u) whatever the force's direction: it withdraws the tip from the
/// tissue, which a lateral force (perpendicular to u) alone would not
/// allow. A zero step, a zero force (no direction to retreat from) or a
/// non-finite input is refused.
pub fn reduces_force(force_n: &Vec3, rod_dir: &Vec3, step_m: &Vec3) -> bool {
    /// cos(8 degrees): how close to -u a step must point to count as backing
    /// out along the rod.
    const BACK_OUT_COS: f64 = 0.990_268_068_741_570_3;
    /// cos(60 degrees).
    const AGAINST_COS: f64 = 0.5;
    let len = step_m.norm();
    let force = force_n.norm();
    let usable = len.is_finite()
        && len > 0.0
        && force.is_finite()
        && force > 0.0
        && rod_dir.iter().all(|v| v.is_finite());
    if !usable {
        return false;
    }
    let against_force = step_m.dot(force_n) <= -AGAINST_COS * len * force;
    let backing_out = -step_m.dot(rod_dir) / len >= BACK_OUT_COS;
    against_force || backing_out
}

/// One of the three parts of the tip force that have their own limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForcePart {
    /// |F_tip|.
    Total,
    /// |F_tip . u|, along the rod.
    Axial,
    /// |F_tip - (F_tip . u) u|, across the rod.
    Lateral,
}

impl ForcePart {
    /// The parts in the order they are checked (and reported when several
    /// exceed their limits in the same cycle).
    pub const ALL: [ForcePart; 3] = [Self::Total, Self::Axial, Self::Lateral];
}

impl fmt::Display for ForcePart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Total => "total",
            Self::Axial => "axial",
            Self::Lateral => "lateral",
        })
    }
}

/// A vector field of [`TipInput::Estimate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TipField {
    /// `force_n`.
    Force,
    /// `std_n`.
    Std,
    /// `rod_dir`.
    RodDir,
}

impl fmt::Display for TipField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Force => "force_n",
            Self::Std => "std_n",
            Self::RodDir => "rod_dir",
        })
    }
}

/// A component of a vector in {0}.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// X0.
    X,
    /// Y0.
    Y,
    /// Z0.
    Z,
}

impl Axis {
    /// X, Y, Z.
    pub const ALL: [Axis; 3] = [Self::X, Self::Y, Self::Z];
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::X => "x",
            Self::Y => "y",
            Self::Z => "z",
        })
    }
}

/// Defines [`Reason`] from one list, a row per reason: the variant (its docs
/// and fields), `= code, "name"`, and `=> sentence` (its `Display`, written
/// to the formatter named in `formatter`, with the fields bound by name).
/// From the rows: the enum, [`REASONS`] (code and name, in code order),
/// [`Reason::code`] and `Display`, and the snapshot's `Snap` (tagged by the
/// code, the fields in their listed order). The codes must rise from row to
/// row and fit the recordings' `uint8` below `REASON_OTHER` (checked at
/// compile time).
macro_rules! reasons {
    (
        formatter $f:ident;
        $(#[$m:meta])*
        pub enum $name:ident {
            $(
                $(#[$vm:meta])*
                $v:ident $({ $( $(#[$fm:meta])* $field:ident: $fty:ty ),* $(,)? })?
                    = $code:literal, $rname:literal => $text:expr
            ),* $(,)?
        }
    ) => {
        $(#[$m])*
        pub enum $name {
            $( $(#[$vm])* $v $({ $( $(#[$fm])* $field: $fty ),* })?, )*
        }

        /// Every reason's stable code and name, in code order (recordings,
        /// the wire and `sarctl` use the codes; SAFETY.md names every
        /// reason). Codes never change meaning; a new reason gets the next
        /// free code.
        pub const REASONS: [(u16, &str); [$($code),*].len()] = [$(($code, $rname)),*];

        // Codes rise from row to row (so they are unique and `REASONS` is in
        // code order) and stay below `REASON_OTHER`.
        const _: () = assert!(codes_rise_below(&REASONS, CODE_OTHER as u16));

        impl $name {
            /// The stable numeric code (see [`REASONS`]): the one place a
            /// reason's code is computed. Exhaustive: a new variant does not
            /// compile until it has one.
            pub const fn code(&self) -> u16 {
                match self {
                    $( Self::$v { .. } => $code, )*
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, $f: &mut fmt::Formatter<'_>) -> fmt::Result {
                match *self {
                    $( Self::$v $({ $($field),* })? => $text, )*
                }
            }
        }

        // Snapshots (issue 17): the tag of a reason is its code.
        sar_snapshot::snap_enum!($name {
            $( $code => $v $({ $($field),* })?, )*
        });
    };
}

reasons! {
    formatter f;
    /// Why the guard is in its state, or why a reset was refused. Carries the facts
    /// (values, limits, which part or field); its `Display` is a short sentence.
    ///
    /// Deliberately not `#[non_exhaustive]`: every crate that turns a reason into
    /// a code, a name or a sentence matches it exhaustively, so a new reason
    /// fails to compile until it is given a code ([`Reason::code`]) and a row in
    /// [`REASONS`].
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub enum Reason {
        /// No input has been stepped yet (the initial state).
        NoInputYet = 1, "no_input_yet" => f.write_str("no input has been received yet"),
        /// The cycle number did not increase.
        CycleOutOfOrder {
            /// The largest cycle accepted before.
            previous: u64,
            /// The cycle received.
            got: u64,
        } = 2, "cycle_out_of_order" => write!(f, "cycle {got} does not follow cycle {previous}"),
        /// The clock could not be read this cycle (no time, no age, no trust).
        ClockFailed = 3, "clock_failed" => f.write_str("the clock could not be read"),
        /// The clock did not advance since the previous cycle (stuck, or gone
        /// back): every age would be meaningless.
        ClockNotAdvancing {
            /// The largest time seen before, ns.
            previous_ns: u64,
            /// The time of this cycle, ns.
            now_ns: u64,
        } = 4, "clock_not_advancing" => write!(
            f,
            "the clock did not advance: {now_ns} ns after {previous_ns} ns"
        ),
        /// The sensor's counter jumped by more than the accepted gap (samples
        /// lost, or the counter went back, which wraps to a huge gap).
        SensorCounterGap {
            /// The previous counter.
            previous: u32,
            /// This cycle's counter.
            got: u32,
            /// The largest accepted step.
            max_gap: u32,
        } = 5, "sensor_counter_gap" => write!(
            f,
            "the sensor counter went from {previous} to {got} (max step {max_gap})"
        ),
        /// The sensor's device status word is not 0 (all good).
        SensorStatus {
            /// The status word.
            status: u32,
        } = 6, "sensor_status" => write!(f, "the force sensor reports status {status:#x}"),
        /// A joint moved between two joint samples by more than the axes' speed
        /// limit allows over their stamp difference plus the margin (an encoder
        /// jump, a slipping axis), or the joint stamp went back.
        JointJump {
            /// 1, 2 or 3 (q1, q2, q3).
            axis: u8,
            /// How far it moved, m (absolute value).
            moved_m: f64,
            /// How far it may move, m.
            allowed_m: f64,
        } = 7, "joint_jump" => write!(
            f,
            "q{axis} moved {moved_m:.6} m between two samples (max {allowed_m:.6} m)"
        ),
        /// The joint sample's stamp is older than the previous joint sample's.
        JointsStampBackwards {
            /// The previous stamp, ns.
            previous_ns: u64,
            /// This cycle's stamp, ns.
            got_ns: u64,
        } = 8, "joints_stamp_backwards" => write!(
            f,
            "the joint stamp went back from {previous_ns} ns to {got_ns} ns"
        ),
        /// The sensor torque differs from the model's prediction by more than the
        /// configured multiple of its standard deviation (an untared or faulty
        /// sensor, a wrong geometry; with d != 0 also a wrong support or contact
        /// along the shaft).
        TorqueImplausible {
            /// Which sensor-frame axis (the first beyond the limit).
            axis: Axis,
            /// Measured minus predicted torque on that axis, N m.
            residual_nm: f64,
            /// Its standard deviation, N m.
            std_nm: f64,
            /// The configured multiple.
            max_sigma: f64,
        } = 9, "torque_implausible" => write!(
            f,
            "sensor torque {axis} is {residual_nm:.4} N m off the model (std {std_nm:.4} N m, \
             max {max_sigma} std)"
        ),
        /// A reset named another cycle than the one just stepped (it must be
        /// judged on the input of the current cycle).
        ResetNotCurrent {
            /// The cycle last stepped.
            last: u64,
            /// The cycle the reset named.
            got: u64,
        } = 10, "reset_not_current" => write!(
            f,
            "a reset for cycle {got} is not a reset of the current cycle {last}"
        ),
        /// The force sensor flagged its reading invalid.
        SensorInvalid = 11, "sensor_invalid" => f.write_str("the force sensor reading is invalid"),
        /// The force sensor reading is too old.
        SensorStale {
            /// Its age, ns.
            age_ns: u64,
            /// The largest accepted age, ns.
            max_age_ns: u64,
        } = 12, "sensor_stale" => write!(
            f,
            "the force sensor reading is {age_ns} ns old (max {max_age_ns} ns)"
        ),
        /// The joint positions are flagged invalid.
        JointsInvalid = 13, "joints_invalid" => f.write_str("the joint positions are invalid"),
        /// The joint positions are too old.
        JointsStale {
            /// Their age, ns.
            age_ns: u64,
            /// The largest accepted age, ns.
            max_age_ns: u64,
        } = 14, "joints_stale" => write!(
            f,
            "the joint positions are {age_ns} ns old (max {max_age_ns} ns)"
        ),
        /// The kinematics refused the pose.
        PoseInvalid = 15, "pose_invalid" => f.write_str("the kinematics refused the pose"),
        /// A component of the estimate is NaN or infinite.
        NonFinite {
            /// Which vector.
            field: TipField,
            /// Which component.
            axis: Axis,
        } = 16, "non_finite" => write!(f, "{field}.{axis} of the tip estimate is not finite"),
        /// A standard deviation is negative.
        NegativeStd {
            /// Which component.
            axis: Axis,
            /// Its value, N.
            std_n: f64,
        } = 17, "negative_std" => write!(f, "std_n.{axis} = {} N is negative", sar_kinematics::Shown(std_n)),
        /// The rod direction is not a unit vector (within
        /// [`ROD_DIR_UNIT_TOLERANCE`]).
        RodDirNotUnit {
            /// Its norm (finite or +inf, never NaN).
            norm: f64,
        } = 18, "rod_dir_not_unit" => write!(f, "the rod direction has norm {norm}, not 1"),
        /// The estimator said the tip force is not observable.
        EstimatorNotObservable = 19, "estimator_not_observable" => {
            f.write_str("the estimator says the tip force is not observable")
        },
        /// The tip force is not observable: the estimator flagged it (a standard
        /// deviation above its observability limit).
        NotObservable {
            /// The largest per-axis standard deviation, N.
            std_max_n: f64,
            /// The estimator's observability limit, N.
            max_std_n: f64,
        } = 20, "not_observable" => write!(
            f,
            "the tip force is not observable: std {std_max_n:.3} N > limit {max_std_n:.3} N"
        ),
        /// A part of the tip force is at or above its stop limit.
        AboveStop {
            /// Which part.
            part: ForcePart,
            /// Its value plus the margin `std_margin |std_n|`, N (finite or +inf,
            /// never NaN).
            force_n: f64,
            /// Its stop limit, N.
            limit_n: f64,
        } = 21, "above_stop" => write!(
            f,
            "{part} tip force {force_n:.3} N is at or above the stop limit {limit_n:.3} N"
        ),
        /// A part of the tip force is at or above its warn limit.
        AboveWarn {
            /// Which part.
            part: ForcePart,
            /// Its value plus the margin `std_margin |std_n|`, N (finite or +inf,
            /// never NaN).
            force_n: f64,
            /// Its warn limit, N.
            limit_n: f64,
        } = 22, "above_warn" => write!(
            f,
            "{part} tip force {force_n:.3} N is at or above the warn limit {limit_n:.3} N"
        ),
        /// Every part has been below its warn limit minus the hysteresis for the
        /// debounce time.
        BelowWarn = 23, "below_warn" => {
            f.write_str("every tip force part is below its warn limit minus the hysteresis")
        },
        /// An accepted reset.
        Reset = 24, "reset" => f.write_str("reset accepted"),
        /// A joint left the commanded trajectory by more than the tolerance (a
        /// jumping encoder, a slipping axis, a collision), or the reference it is
        /// compared with is not finite.
        FollowingError {
            /// 1, 2 or 3 (q1, q2, q3).
            axis: u8,
            /// |measured - commanded|, m (NaN when a value is not finite).
            error_m: f64,
            /// The accepted error, m.
            tolerance_m: f64,
        } = 25, "following_error" => write!(
            f,
            "q{axis} is {:.3} mm off the commanded trajectory (tolerance {:.3} mm)",
            error_m * 1e3,
            tolerance_m * 1e3
        ),
        /// The initial latch after good input: nothing faults, the guard waits
        /// for the operator's first reset (`sarctl reset`) before the robot may
        /// move.
        AwaitingFirstReset = 26, "awaiting_first_reset" => f.write_str(
            "waiting for the first reset: check that the tip is free, then reset (sarctl reset)",
        ),
        /// The sensor's six readings repeated bit for bit over `repeats` new
        /// samples while its counter advanced (a frozen, stuck-at sensor: a live
        /// one always shows noise).
        SensorFrozen {
            /// Consecutive new samples identical to the one before them.
            repeats: u32,
        } = 27, "sensor_frozen" => write!(
            f,
            "the force sensor is frozen: {repeats} new samples repeated the same six values"
        ),
        /// A raw reading (before bias removal) is at or beyond the sensor's
        /// measuring range: the true force is unknown.
        SensorSaturated {
            /// Which sensor channel.
            channel: SensorChannel,
            /// The reading, N or N m.
            value: f64,
            /// The range of that channel, N or N m.
            range: f64,
        } = 28, "sensor_saturated" => write!(
            f,
            "the force sensor is saturated: {channel} reads {value:.3}, range {range:.3}"
        ),
        /// Too many single-sample jumps far beyond the noise within a window of
        /// new samples (an unreliable sensor: interference, a loose connector).
        SensorSpikes {
            /// Spikes counted in the window.
            spikes: u32,
            /// The window, new samples.
            window: u32,
        } = 29, "sensor_spikes" => write!(
            f,
            "the force sensor is unreliable: {spikes} spikes within {window} samples"
        ),
        /// The last tare is older than the configured age: the bias may have
        /// drifted; a tare is due (a Warn).
        TareDue {
            /// Time since the last tare, s.
            age_s: f64,
            /// The configured largest age, s.
            max_age_s: f64,
        } = 30, "tare_due" => write!(
            f,
            "a tare is due: the last one is {age_s:.0} s old (max {max_age_s:.0} s)"
        ),
        /// A tare was accepted while a tare was due: back to Ok.
        Tared = 31, "tared" => f.write_str("tare accepted"),
        /// The first reset was refused: at rest, with the tip free, the measured
        /// wrench differs from the model (the mean estimated tip force and the
        /// mean torque residual over the samples at rest are the residuals): a
        /// sensor mounted or scaled otherwise than configured, an untared
        /// sensor, another manipulator than the configured one, or something
        /// touching the tip.
        MountingMismatch {
            /// Which residual.
            residual: RestResidual,
            /// Its magnitude (mean over the samples at rest), N or N m.
            value: f64,
            /// What is accepted (noise of the mean, friction, tolerance), N or N m.
            allowed: f64,
        } = 32, "mounting_mismatch" => write!(
            f,
            "at rest the {residual} differs from the model by {value:.3} (allowed \
             {allowed:.3}): free the tip, tare the sensor with the rod detached, check \
             sensor_rotation, counts_per_n and the manipulator profile"
        ),
        /// A reset accepted while a part is still at or above its stop limit:
        /// the guard enters `Retreat` (only motions that reduce the force).
        RetreatEntered {
            /// The part at or above its stop limit.
            part: ForcePart,
            /// Its value with the margin, N.
            force_n: f64,
            /// Its stop limit, N.
            limit_n: f64,
        } = 33, "retreat_entered" => write!(
            f,
            "retreat: {part} tip force {force_n:.2} N is above the stop limit {limit_n:.2} N; \
             only motions that reduce it are accepted"
        ),
        /// In `Retreat` the (filtered) force rose above the bound: back to Stop.
        ForceRising {
            /// Which part.
            part: ForcePart,
            /// Its filtered value, N.
            force_n: f64,
            /// The bound it passed: max(stop limit, lowest since entry + rise
            /// allowance), N.
            bound_n: f64,
        } = 34, "force_rising" => write!(
            f,
            "the {part} tip force rose to {force_n:.2} N during the retreat (bound {bound_n:.2} N)"
        ),
        /// A host fault that the daemon passes in (its publishing thread, which
        /// carries the operator's commands and the published state, has made no
        /// progress for too long).
        PublisherStalled {
            /// How long without progress, ms.
            stalled_ms: u32,
        } = 35, "publisher_stalled" => write!(
            f,
            "the publishing thread made no progress for {stalled_ms} ms: no commands, no state"
        ),
        /// The drives reported a fault (a drive's own fault, an EMCY, a lost
        /// heartbeat on the CANopen path): the guard latches Fault in the cycle
        /// the drives enter it; an accepted reset brings them back (fault reset,
        /// enable).
        DriveFault {
            /// 1, 2 or 3 (q1, q2, q3); 0 when the drives cannot tell.
            axis: u8,
            /// The device's fault code.
            code: u16,
        } = 36, "drive_fault" => {
            if axis == 0 {
                write!(f, "the drives faulted (code {code:#06x})")
            } else {
                write!(f, "the drive of q{axis} faulted (code {code:#06x})")
            }
        },
        /// The first reset came before the mean of the wrench at rest was
        /// complete (the daemon has just started, or the robot moved): the
        /// mounting check's stated tolerances hold only for the full mean, so
        /// the first reset is refused until the robot has been still that long.
        RestIncomplete {
            /// Samples at rest so far.
            samples: u32,
            /// Samples the mean needs (`[plausibility] rest_samples`).
            needed: u32,
        } = 37, "rest_incomplete" => write!(
            f,
            "the wrench at rest is still being measured ({samples} of {needed} samples): keep the robot still and reset again"
        ),
        /// The loop ran longer after its previous cycle than the sensor
        /// sample's accepted age (`[guard] max_sensor_age_s`): for that long
        /// nothing was judged (a stalled host, a suspended process). A late
        /// cycle within the age is an input the loop carries on from (issue
        /// 33); this is the stall beyond it.
        CycleGap {
            /// Time since the previous cycle, ns.
            gap_ns: u64,
            /// The accepted age, ns.
            max_ns: u64,
        } = 38, "cycle_gap" => write!(
            f,
            "the loop ran {} ms after its previous cycle, longer than the sensor's accepted age of {} ms: nothing was judged meanwhile",
            sar_kinematics::Shown(gap_ns as f64 * 1e-6),
            sar_kinematics::Shown(max_ns as f64 * 1e-6)
        ),
    }
}

/// A residual of the wrench at rest against the model (the first reset's
/// check).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestResidual {
    /// The tip force along the rod, N.
    Axial,
    /// The tip force across the rod, N.
    Lateral,
    /// The sensor torque on one sensor axis, N m.
    Torque(Axis),
}

impl fmt::Display for RestResidual {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Axial => f.write_str("axial force"),
            Self::Lateral => f.write_str("lateral force"),
            Self::Torque(axis) => write!(f, "torque {axis}"),
        }
    }
}

/// A channel of the force/torque sensor, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorChannel {
    /// Force x.
    Fx,
    /// Force y.
    Fy,
    /// Force z.
    Fz,
    /// Torque x.
    Tx,
    /// Torque y.
    Ty,
    /// Torque z.
    Tz,
}

impl SensorChannel {
    /// Fx, Fy, Fz, Tx, Ty, Tz.
    pub const ALL: [SensorChannel; 6] =
        [Self::Fx, Self::Fy, Self::Fz, Self::Tx, Self::Ty, Self::Tz];
}

impl fmt::Display for SensorChannel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Fx => "Fx",
            Self::Fy => "Fy",
            Self::Fz => "Fz",
            Self::Tx => "Tx",
            Self::Ty => "Ty",
            Self::Tz => "Tz",
        })
    }
}

/// Whether the codes of `rows` rise from row to row, from above 0 to below
/// `end` (the compile-time check of the reason table).
const fn codes_rise_below(mut rows: &[(u16, &str)], end: u16) -> bool {
    let mut previous = 0;
    while let [(code, _), rest @ ..] = rows {
        if *code <= previous || *code >= end {
            return false;
        }
        previous = *code;
        rows = rest;
    }
    true
}

/// The recordings' byte for a code that does not fit one (`REASON_OTHER`
/// of `GuardEvent.msg`; no reason has one: the codes stay below it).
pub const CODE_OTHER: u8 = 255;

/// A reason code as the recordings' `uint8` carries it: the same number
/// (every code is below [`CODE_OTHER`]); a number beyond is [`CODE_OTHER`].
pub fn recorded_code(code: u32) -> u8 {
    u8::try_from(code).unwrap_or(CODE_OTHER)
}

impl Reason {
    /// The stable name of the reason (snake case, as in [`REASONS`]).
    pub fn name(&self) -> &'static str {
        reason_name(self.code())
    }

    /// [`Reason::code`] as the recordings' `uint8` carries it (the same
    /// number, [`recorded_code`]).
    pub fn recorded_code(&self) -> u8 {
        recorded_code(u32::from(self.code()))
    }
}

/// The name of a reason code ([`REASONS`]), or `"unknown"`.
pub fn reason_name(code: u16) -> &'static str {
    REASONS
        .iter()
        .find(|(c, _)| *c == code)
        .map_or("unknown", |(_, name)| name)
}

/// A change of state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// The input's cycle (for a reset, the cycle passed to it).
    pub cycle: u64,
    /// The state left.
    pub from: GuardState,
    /// The state entered.
    pub to: GuardState,
    /// Why.
    pub reason: Reason,
}

/// A reset was refused because its cause persists in the most recent input.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("reset refused: {reason}")]
pub struct ResetRefused {
    /// The cause that persists.
    pub reason: Reason,
}

/// The force-limit guard. Fixed-size; see the module documentation. Not
/// `Copy`, so that a copy cannot be stepped by mistake instead of the original.
#[derive(Debug, Clone, PartialEq)]
pub struct Guard {
    config: GuardConfig,
    state: GuardState,
    reason: Reason,
    /// The largest cycle stepped so far (None before the first step).
    last_cycle: Option<u64>,
    /// What in the most recent input would refuse a reset (a fault condition,
    /// a part at or above its stop limit, or no input yet).
    blocker: Option<Reason>,
    /// What in the most recent input is at or above a warn limit (or a fault
    /// condition, or no input yet): what refuses a tare.
    above_warn: Option<Reason>,
    /// Up/down count over new samples of a part at or above its stop limit.
    stop_count: u32,
    /// Up/down count over new samples of a part at or above its warn limit.
    warn_count: u32,
    /// Up/down count over new samples of every part below warn minus hysteresis.
    clear_count: u32,
    /// Still in the initial latch (no reset accepted yet).
    initial: bool,
    /// The filtered parts of the most recent input (no margin), N.
    smoothed_parts_n: Option<[f64; 3]>,
    /// In `Retreat`: the lowest filtered value of each part since it began, N.
    retreat_min_n: [f64; 3],
}

/// Magnitudes of the total, axial and lateral parts of `force_n` for the unit
/// direction `rod_dir` (both finite), in [`ForcePart::ALL`] order. Never NaN;
/// +inf only when the magnitude exceeds `f64::MAX`.
fn force_parts_n(force_n: &Vec3, rod_dir: &Vec3) -> [f64; 3] {
    let largest = force_n.x.abs().max(force_n.y.abs()).max(force_n.z.abs());
    let (f, scale) = if largest > SCALE_ABOVE_N {
        (force_n / largest, largest)
    } else {
        (*force_n, 1.0)
    };
    let along = f.dot(rod_dir);
    let lateral = f - rod_dir * along;
    [
        f.norm() * scale,
        along.abs() * scale,
        lateral.norm() * scale,
    ]
}

/// The first part (in [`ForcePart::ALL`] order) at or above its limit, with
/// its value and limit. A NaN value would count as above (conservative).
fn first_at_or_above(parts_n: &[f64; 3], limits_n: &[f64; 3]) -> Option<(ForcePart, f64, f64)> {
    ForcePart::ALL
        .iter()
        .zip(parts_n.iter().zip(limits_n.iter()))
        .find(|(_, (value, limit))| value.is_nan() || **value >= **limit)
        .map(|(part, (value, limit))| (*part, *value, *limit))
}

impl Guard {
    /// A guard in `Fault` with [`Reason::NoInputYet`]: a reset after a good
    /// input is needed before the robot may move (while it waits, with good
    /// input, its reason is [`Reason::AwaitingFirstReset`]).
    pub fn new(config: GuardConfig) -> Self {
        Self {
            config,
            state: GuardState::Fault,
            reason: Reason::NoInputYet,
            last_cycle: None,
            blocker: Some(Reason::NoInputYet),
            above_warn: Some(Reason::NoInputYet),
            stop_count: 0,
            warn_count: 0,
            clear_count: 0,
            initial: true,
            smoothed_parts_n: None,
            retreat_min_n: [0.0; 3],
        }
    }

    /// The current state.
    pub fn state(&self) -> GuardState {
        self.state
    }

    /// Why the guard is in its current state (the latched first reason for
    /// `Stop` and `Fault`, except in the initial latch, which shows this
    /// cycle's fault or [`Reason::AwaitingFirstReset`]; the entering reason
    /// for `Warn` and `Retreat`; `Reset`, `BelowWarn` or `Tared` for `Ok`).
    pub fn reason(&self) -> Reason {
        self.reason
    }

    /// Whether no reset has been accepted yet (the initial latch).
    pub fn awaiting_first_reset(&self) -> bool {
        self.initial
    }

    /// The configuration.
    pub fn config(&self) -> &GuardConfig {
        &self.config
    }

    /// Replaces the six force limits (checked by
    /// [`GuardConfig::with_force_limits`]: within the ceilings); returns the
    /// previous ones. The state, its reason and the debounce counts are
    /// kept: the new limits act from the next step.
    pub fn set_force_limits(&mut self, limits: &ForceLimits) -> Result<ForceLimits, SettingError> {
        let next = self.config.with_force_limits(limits)?;
        let previous = self.config.force_limits();
        self.config = next;
        Ok(previous)
    }

    /// What in the most recent input would make [`Guard::reset`] refuse, if
    /// anything: a fault condition, a part at or above its stop limit (which
    /// a reset turns into `Retreat` when a filtered force is available), or
    /// [`Reason::NoInputYet`].
    pub fn reset_blocker(&self) -> Option<Reason> {
        self.blocker
    }

    /// What in the most recent input is at or above a warn limit (with the
    /// margin), or a fault condition, or [`Reason::NoInputYet`]; `None` when
    /// every part was below its warn limit.
    pub fn warn_blocker(&self) -> Option<Reason> {
        self.above_warn
    }

    /// Feeds one control cycle. Returns `Some` only when the state (or, in
    /// `Warn`, its reason) changed.
    #[inline]
    pub fn step(&mut self, input: &GuardInput) -> Option<Transition> {
        let transition = self.step_state(input);
        self.debug_check();
        transition
    }

    /// The invariants a reader of the guard would otherwise have to trust,
    /// checked in debug builds after every step and reset: each debounce
    /// count within `0..=debounce_samples` (a vote never passes the
    /// threshold); the initial latch only in `Fault` (nothing leaves it but
    /// an accepted reset, which ends the latch).
    #[inline]
    fn debug_check(&self) {
        let debounce = self.config.limits.debounce_samples;
        debug_assert!(
            self.stop_count <= debounce
                && self.warn_count <= debounce
                && self.clear_count <= debounce,
            "debounce counts {}/{}/{} above {debounce}",
            self.stop_count,
            self.warn_count,
            self.clear_count
        );
        debug_assert!(
            !self.initial || self.state == GuardState::Fault,
            "the initial latch in {}",
            self.state
        );
    }

    /// [`Guard::step`] without the invariants' check: judge the input (a
    /// fault condition latches Fault), count the votes of its force parts,
    /// then decide the move of the state it is in.
    #[inline]
    fn step_state(&mut self, input: &GuardInput) -> Option<Transition> {
        let cycle = input.cycle;
        let parts_n = match self.evaluate(input) {
            Err(fault) => return self.on_fault(fault, cycle),
            Ok(parts_n) => parts_n,
        };
        if self.initial && self.state == GuardState::Fault {
            self.reason = Reason::AwaitingFirstReset;
        }
        self.smoothed_parts_n = match (input.smoothed_force_n, input.tip) {
            (Some(f), TipInput::Estimate { rod_dir, .. }) if f.iter().all(|v| v.is_finite()) => {
                Some(force_parts_n(&f, &rod_dir))
            }
            _ => None,
        };
        let hits = self.count_votes(&parts_n, input.new_sample);
        match self.state {
            GuardState::Stop | GuardState::Fault => None,
            GuardState::Retreat => self.step_retreat(&parts_n, hits.clear, cycle),
            GuardState::Ok | GuardState::Warn => self.step_ok_warn(&hits, input.tare_due, cycle),
        }
    }

    /// A fault condition in this cycle's input: it blocks a reset and a
    /// tare, clears the votes and the filtered parts, and latches Fault (in
    /// the initial latch it becomes the reason shown, without a transition).
    #[inline]
    fn on_fault(&mut self, fault: Reason, cycle: u64) -> Option<Transition> {
        self.blocker = Some(fault);
        self.above_warn = Some(fault);
        self.smoothed_parts_n = None;
        self.stop_count = 0;
        self.warn_count = 0;
        self.clear_count = 0;
        if self.initial && self.state == GuardState::Fault {
            // The initial latch shows what blocks the first reset now.
            self.reason = fault;
            return None;
        }
        self.enter(GuardState::Fault, fault, cycle)
    }

    /// Compares the parts (margin included) with the stop, warn and clear
    /// limits; a new sample moves each up/down count by one; what is at or
    /// above a stop (warn) limit becomes what blocks a reset (a tare).
    #[inline]
    fn count_votes(&mut self, parts_n: &[f64; 3], new_sample: bool) -> Hits {
        let cfg = &self.config;
        let hits = Hits {
            stop: first_at_or_above(parts_n, &cfg.stop_n),
            warn: first_at_or_above(parts_n, &cfg.warn_n),
            clear: parts_n
                .iter()
                .zip(cfg.clear_n.iter())
                .all(|(value, limit)| *value < *limit),
        };
        let debounce = cfg.limits.debounce_samples;
        if new_sample {
            let vote = |count: u32, holds: bool| {
                if holds {
                    count.saturating_add(1).min(debounce)
                } else {
                    count.saturating_sub(1)
                }
            };
            self.stop_count = vote(self.stop_count, hits.stop.is_some());
            self.warn_count = vote(self.warn_count, hits.warn.is_some());
            self.clear_count = vote(self.clear_count, hits.clear);
        }
        self.blocker = hits.stop.map(|(part, force_n, limit_n)| Reason::AboveStop {
            part,
            force_n,
            limit_n,
        });
        self.above_warn = hits.warn.map(|(part, force_n, limit_n)| Reason::AboveWarn {
            part,
            force_n,
            limit_n,
        });
        hits
    }

    /// `Ok` or `Warn`: Stop once a stop limit is debounced; from Ok (or a
    /// tare's Warn) Warn once a warn limit is debounced, else the tare's
    /// warning begins or ends; from a force's Warn, Ok once every part is
    /// debounced clear.
    #[inline]
    fn step_ok_warn(
        &mut self,
        hits: &Hits,
        tare_due: Option<Reason>,
        cycle: u64,
    ) -> Option<Transition> {
        let debounce = self.config.limits.debounce_samples;
        if let Some((part, force_n, limit_n)) = hits.stop
            && self.stop_count >= debounce
        {
            let reason = Reason::AboveStop {
                part,
                force_n,
                limit_n,
            };
            return self.enter(GuardState::Stop, reason, cycle);
        }
        let warn_due = hits.warn.filter(|_| self.warn_count >= debounce);
        let tare_warn = matches!(self.reason, Reason::TareDue { .. });
        if self.state == GuardState::Ok || tare_warn {
            if let Some((part, force_n, limit_n)) = warn_due {
                let reason = Reason::AboveWarn {
                    part,
                    force_n,
                    limit_n,
                };
                // Leaving Warn needs a fresh run of clear samples.
                self.clear_count = 0;
                return self.enter_reason(GuardState::Warn, reason, cycle);
            }
            return match (self.state, tare_due) {
                (GuardState::Ok, Some(due)) => self.enter(GuardState::Warn, due, cycle),
                // The tare was done: the tare warning is over.
                (GuardState::Warn, None) => self.enter(GuardState::Ok, Reason::Tared, cycle),
                _ => None,
            };
        }
        if hits.clear && self.clear_count >= debounce {
            // Re-entering Warn needs a fresh run of warn samples.
            self.warn_count = 0;
            return self.enter(GuardState::Ok, Reason::BelowWarn, cycle);
        }
        None
    }

    /// `Retreat`: Stop when a filtered part rises above
    /// max(stop limit, its lowest value since the retreat began + the rise
    /// allowance); Ok when every part has been below its warn limit minus
    /// the hysteresis for the debounce.
    fn step_retreat(&mut self, parts_n: &[f64; 3], clear: bool, cycle: u64) -> Option<Transition> {
        // Without a filtered value (the filter restarting after lost
        // samples) the unfiltered parts, margin included, stand in.
        let watched = self.smoothed_parts_n.unwrap_or(*parts_n);
        let rise_n = self.config.retreat_rise_n;
        let mut rising = None;
        for (((part, value), lowest), stop) in ForcePart::ALL
            .iter()
            .zip(watched.iter())
            .zip(self.retreat_min_n.iter_mut())
            .zip(self.config.stop_n.iter())
        {
            *lowest = lowest.min(*value);
            let bound_n = stop.max(*lowest + rise_n);
            // NaN counts as rising (conservative).
            if rising.is_none() && (value.is_nan() || *value > bound_n) {
                rising = Some(Reason::ForceRising {
                    part: *part,
                    force_n: *value,
                    bound_n,
                });
            }
        }
        if let Some(reason) = rising {
            return self.enter(GuardState::Stop, reason, cycle);
        }
        if clear && self.clear_count >= self.config.limits.debounce_samples {
            self.warn_count = 0;
            self.stop_count = 0;
            return self.enter(GuardState::Ok, Reason::BelowWarn, cycle);
        }
        None
    }

    /// Asks to leave `Stop` or `Fault`, judged on the input of `cycle`, which
    /// must be the cycle just stepped (else refused with
    /// [`Reason::ResetNotCurrent`]; before any step with
    /// [`Reason::NoInputYet`]): call it right after [`Guard::step`] of the same
    /// cycle (as [`crate::cycle::Estimator::cycle`] does for a reset command).
    /// In `Ok`, `Warn` or `Retreat` it does nothing (`Ok(None)`). Refused
    /// while a fault condition persists in that input. With every part below
    /// its stop limit it goes to `Ok`; with a part still at or above its
    /// stop limit (not debounced) it goes to `Retreat` when a filtered force
    /// was given this cycle, and is refused otherwise. An accepted reset
    /// clears the debounce counts.
    pub fn reset(&mut self, cycle: u64) -> Result<Option<Transition>, ResetRefused> {
        match self.state {
            GuardState::Ok | GuardState::Warn | GuardState::Retreat => Ok(None),
            GuardState::Stop | GuardState::Fault => {
                let Some(last) = self.last_cycle else {
                    return Err(ResetRefused {
                        reason: Reason::NoInputYet,
                    });
                };
                if cycle != last {
                    return Err(ResetRefused {
                        reason: Reason::ResetNotCurrent { last, got: cycle },
                    });
                }
                let (to, reason) = match (self.blocker, self.smoothed_parts_n) {
                    (None, _) => (GuardState::Ok, Reason::Reset),
                    (
                        Some(Reason::AboveStop {
                            part,
                            force_n,
                            limit_n,
                        }),
                        Some(smoothed),
                    ) => {
                        self.retreat_min_n = smoothed;
                        (
                            GuardState::Retreat,
                            Reason::RetreatEntered {
                                part,
                                force_n,
                                limit_n,
                            },
                        )
                    }
                    (Some(reason), _) => return Err(ResetRefused { reason }),
                };
                self.stop_count = 0;
                self.warn_count = 0;
                self.clear_count = 0;
                self.initial = false;
                let transition = self.enter(to, reason, cycle);
                self.debug_check();
                Ok(transition)
            }
        }
    }

    /// Like [`Guard::enter`], but a change of reason within the same state
    /// is a transition too (Warn for a due tare becoming Warn for a force).
    fn enter_reason(&mut self, to: GuardState, reason: Reason, cycle: u64) -> Option<Transition> {
        if self.state == to {
            let from = self.state;
            self.reason = reason;
            return Some(Transition {
                cycle,
                from,
                to,
                reason,
            });
        }
        self.enter(to, reason, cycle)
    }

    /// Moves to `to` with `reason` unless already there (a latched state keeps
    /// its first reason).
    fn enter(&mut self, to: GuardState, reason: Reason, cycle: u64) -> Option<Transition> {
        if self.state == to {
            return None;
        }
        let from = self.state;
        self.state = to;
        self.reason = reason;
        Some(Transition {
            cycle,
            from,
            to,
            reason,
        })
    }

    /// The first fault condition of `input` in the fixed order (cycle
    /// order, the caller's input fault, the samples' validity and age, the
    /// estimate), or the force parts with their margin. Records the cycle if
    /// it is in order.
    #[inline]
    fn evaluate(&mut self, input: &GuardInput) -> Result<[f64; 3], Reason> {
        if let Some(previous) = self.last_cycle
            && input.cycle <= previous
        {
            return Err(Reason::CycleOutOfOrder {
                previous,
                got: input.cycle,
            });
        }
        self.last_cycle = Some(input.cycle);
        check_samples(input, &self.config.limits)?;
        let (force_n, std_n, rod_dir) = check_estimate(&input.tip)?;
        let limits = &self.config.limits;
        // The margin: k |std| bounds k standard deviations of every part.
        let mut margin_n = if limits.std_margin > 0.0 {
            limits.std_margin * std_n.norm()
        } else {
            0.0
        };
        // The drift bound: a negative or NaN one counts as unbounded.
        margin_n += if input.extra_margin_n >= 0.0 {
            input.extra_margin_n
        } else {
            f64::INFINITY
        };
        Ok(force_parts_n(&force_n, &rod_dir).map(|part_n| part_n + margin_n))
    }
}

/// What one cycle's force parts hit: the first part at or above its stop
/// limit and the first at or above its warn limit (part, value, limit), and
/// whether every part is below its clear limit.
struct Hits {
    stop: Option<(ForcePart, f64, f64)>,
    warn: Option<(ForcePart, f64, f64)>,
    clear: bool,
}

/// The samples' fault conditions in the fixed order: the caller's input
/// fault, the sensor's validity and age, the joints' validity and age.
#[inline]
fn check_samples(input: &GuardInput, limits: &GuardLimits) -> Result<(), Reason> {
    if let Some(fault) = input.input_fault {
        return Err(fault);
    }
    if !input.sensor_valid {
        return Err(Reason::SensorInvalid);
    }
    if input.sensor_age_ns > limits.max_sensor_age_ns {
        return Err(Reason::SensorStale {
            age_ns: input.sensor_age_ns,
            max_age_ns: limits.max_sensor_age_ns,
        });
    }
    if !input.joints_valid {
        return Err(Reason::JointsInvalid);
    }
    if input.joints_age_ns > limits.max_joints_age_ns {
        return Err(Reason::JointsStale {
            age_ns: input.joints_age_ns,
            max_age_ns: limits.max_joints_age_ns,
        });
    }
    Ok(())
}

/// The estimate's fault conditions in the fixed order: a refused pose, the
/// estimator's unobservable flag, a non-finite number, a negative standard
/// deviation, a rod direction not of unit length, an unobservable force.
/// Else its force, standard deviation and rod direction.
#[inline]
fn check_estimate(tip: &TipInput) -> Result<(Vec3, Vec3, Vec3), Reason> {
    let (force_n, std_n, rod_dir, observable, max_std_n) = match *tip {
        TipInput::PoseInvalid => return Err(Reason::PoseInvalid),
        TipInput::NotObservable => return Err(Reason::EstimatorNotObservable),
        TipInput::Estimate {
            force_n,
            std_n,
            rod_dir,
            observable,
            max_std_n,
        } => (force_n, std_n, rod_dir, observable, max_std_n),
    };
    for (field, vector) in [
        (TipField::Force, &force_n),
        (TipField::Std, &std_n),
        (TipField::RodDir, &rod_dir),
    ] {
        for (axis, value) in Axis::ALL.iter().zip(vector.iter()) {
            if !value.is_finite() {
                return Err(Reason::NonFinite { field, axis: *axis });
            }
        }
    }
    for (axis, value) in Axis::ALL.iter().zip(std_n.iter()) {
        if *value < 0.0 {
            return Err(Reason::NegativeStd {
                axis: *axis,
                std_n: *value,
            });
        }
    }
    let norm2 = rod_dir.norm_squared();
    if !(ROD_DIR_NORM2_MIN..=ROD_DIR_NORM2_MAX).contains(&norm2) {
        return Err(Reason::RodDirNotUnit {
            norm: rod_dir.norm(),
        });
    }
    if !observable {
        return Err(Reason::NotObservable {
            std_max_n: std_n.x.max(std_n.y).max(std_n.z),
            max_std_n,
        });
    }
    Ok((force_n, std_n, rod_dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(debounce_samples: u32) -> GuardLimits {
        GuardLimits {
            force: ForceLimits {
                warn_total_n: 9.0,
                stop_total_n: 17.0,
                warn_axial_n: 8.0,
                stop_axial_n: 15.0,
                warn_lateral_n: 6.0,
                stop_lateral_n: 10.0,
            },
            hysteresis_n: 1.0,
            debounce_samples,
            max_sensor_age_ns: 1_000_000,
            max_joints_age_ns: 1_000_000,
            std_margin: 0.0,
        }
    }

    fn input(cycle: u64, force_n: Vec3) -> GuardInput {
        GuardInput {
            cycle,
            input_fault: None,
            new_sample: true,
            sensor_age_ns: 0,
            sensor_valid: true,
            joints_age_ns: 0,
            joints_valid: true,
            tip: TipInput::Estimate {
                force_n,
                std_n: Vec3::zeros(),
                rod_dir: Vec3::x(),
                observable: true,
                max_std_n: 2.0,
            },
            extra_margin_n: 0.0,
            tare_due: None,
            smoothed_force_n: None,
        }
    }

    #[test]
    fn counts_stay_within_the_debounce_and_repeats_do_not_count() {
        let mut g = Guard::new(GuardConfig::new(limits(MAX_DEBOUNCE_SAMPLES)).unwrap());
        g.step(&input(0, Vec3::zeros()));
        g.reset(0).unwrap();
        let high = Vec3::new(20.0, 0.0, 0.0);
        // In Stop (latched) the counts keep voting but never pass the debounce.
        g.state = GuardState::Stop;
        for c in 1..300 {
            assert_eq!(g.step(&input(c, high)), None);
        }
        assert_eq!((g.stop_count, g.warn_count), (100, 100));
        assert_eq!(g.clear_count, 0);
        // A repeated sample (no new counter) moves nothing.
        let mut repeat = input(300, Vec3::zeros());
        repeat.new_sample = false;
        g.step(&repeat);
        assert_eq!((g.stop_count, g.warn_count, g.clear_count), (100, 100, 0));
        g.step(&input(301, Vec3::zeros()));
        assert_eq!((g.stop_count, g.warn_count, g.clear_count), (99, 99, 1));
    }

    #[test]
    fn force_parts_are_continuous_across_the_scaling_threshold() {
        let u = Vec3::new(0.6, 0.0, 0.8);
        let dir = Vec3::new(0.3, -0.5, 0.2).normalize();
        for k in [0.999_999, 1.0, 1.000_001] {
            let f = dir * (SCALE_ABOVE_N * k / dir.amax());
            let p = force_parts_n(&f, &u);
            let mag = SCALE_ABOVE_N * k / dir.amax();
            let axial = dir.dot(&u).abs() * mag;
            let lateral = newton_sqrt(1.0 - dir.dot(&u) * dir.dot(&u)) * mag;
            assert!((p[0] / mag - 1.0).abs() < 1e-12, "{p:?}");
            assert!((p[1] / axial - 1.0).abs() < 1e-12, "{p:?}");
            assert!((p[2] / lateral - 1.0).abs() < 1e-12, "{p:?}");
        }
        let p = force_parts_n(&Vec3::new(f64::MAX, f64::MAX, f64::MAX), &u);
        assert!(p.iter().all(|x| !x.is_nan()));
        assert_eq!(p[0], f64::INFINITY);
    }

    /// sqrt by Newton's method, so the check does not reuse the norm under test.
    fn newton_sqrt(x: f64) -> f64 {
        let mut y = if x > 1.0 { x } else { 1.0 };
        for _ in 0..100 {
            y = 0.5 * (y + x / y);
        }
        y
    }
}

// Snapshots (issue 17): the guard is stored whole, its limits included
// (an operator may change them at run time). The tags of `Reason` are its
// codes ([`REASONS`]; its `Snap` is made by `reasons!`).
// `GuardLimits` stores its `ForceLimits` first: the same bytes as when
// the six were its own first fields.
sar_snapshot::snap_struct!(GuardLimits {
    force,
    hysteresis_n,
    debounce_samples,
    max_sensor_age_ns,
    max_joints_age_ns,
    std_margin,
});
sar_snapshot::snap_struct!(GuardConfig {
    limits,
    warn_n,
    stop_n,
    clear_n,
    ceiling_n,
    retreat_rise_n,
});
sar_snapshot::snap_struct!(ForceLimits {
    warn_total_n,
    stop_total_n,
    warn_axial_n,
    stop_axial_n,
    warn_lateral_n,
    stop_lateral_n,
});
sar_snapshot::snap_enum!(GuardState { 0 => Ok, 1 => Warn, 2 => Stop, 3 => Fault, 4 => Retreat });
sar_snapshot::snap_enum!(ForcePart { 0 => Total, 1 => Axial, 2 => Lateral });
sar_snapshot::snap_enum!(TipField { 0 => Force, 1 => Std, 2 => RodDir });
sar_snapshot::snap_enum!(Axis { 0 => X, 1 => Y, 2 => Z });
sar_snapshot::snap_enum!(SensorChannel { 0 => Fx, 1 => Fy, 2 => Fz, 3 => Tx, 4 => Ty, 5 => Tz });

impl sar_snapshot::Snap for RestResidual {
    fn put(&self, w: &mut sar_snapshot::Writer<'_>) {
        match self {
            Self::Axial => w.put_u8(0),
            Self::Lateral => w.put_u8(1),
            Self::Torque(axis) => {
                w.put_u8(2);
                axis.put(w);
            }
        }
    }
    fn get(r: &mut sar_snapshot::Reader<'_>) -> Result<Self, sar_snapshot::SnapshotError> {
        let at = r.position();
        match r.get_u8()? {
            0 => Ok(Self::Axial),
            1 => Ok(Self::Lateral),
            2 => Ok(Self::Torque(sar_snapshot::Snap::get(r)?)),
            value => Err(sar_snapshot::SnapshotError::BadTag {
                what: "RestResidual",
                value,
                at,
            }),
        }
    }
}

sar_snapshot::snap_struct!(Guard {
    config,
    state,
    reason,
    last_cycle,
    blocker,
    above_warn,
    stop_count,
    warn_count,
    clear_count,
    initial,
    smoothed_parts_n,
    retreat_min_n,
});
