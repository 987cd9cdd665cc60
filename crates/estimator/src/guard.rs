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

/// The six force limits alone: what an operator may change at run time
/// ([`crate::cycle::Command::SetLimits`]), within the ceilings fixed at start
/// ([`GuardConfig::with_ceiling`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    /// Warn limit on |F_tip|, N.
    pub warn_total_n: f64,
    /// Stop limit on |F_tip|, N.
    pub stop_total_n: f64,
    /// Warn limit on the axial part, N.
    pub warn_axial_n: f64,
    /// Stop limit on the axial part, N.
    pub stop_axial_n: f64,
    /// Warn limit on the lateral part, N.
    pub warn_lateral_n: f64,
    /// Stop limit on the lateral part, N.
    pub stop_lateral_n: f64,
}

impl ForceLimits {
    /// In the order (warn, stop) total, axial, lateral (the wire's order).
    pub fn to_array(&self) -> [f64; 6] {
        [
            self.warn_total_n,
            self.stop_total_n,
            self.warn_axial_n,
            self.stop_axial_n,
            self.warn_lateral_n,
            self.stop_lateral_n,
        ]
    }

    /// From (warn, stop) total, axial, lateral.
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
    /// Warn limits in [`ForcePart::ALL`] order, N.
    warn_n: [f64; 3],
    /// Stop limits in [`ForcePart::ALL`] order, N.
    stop_n: [f64; 3],
    /// Warn limits minus the hysteresis, in [`ForcePart::ALL`] order, N.
    clear_n: [f64; 3],
    /// The largest stop limit a run-time change may set, in
    /// [`ForcePart::ALL`] order, N (default: the configured stop limits, so
    /// that limits can only be lowered).
    ceiling_n: [f64; 3],
}

fn invalid(field: &'static str, value: f64, why: &'static str) -> SettingError {
    SettingError::Invalid { field, value, why }
}

impl GuardConfig {
    /// Checks the limits: all finite; for each of total, axial and lateral
    /// 0 < warn < stop; 0 <= hysteresis < every warn limit; both maximum ages
    /// > 0; 1 <= debounce <= 100; 0 <= std_margin <= 10.
    pub fn new(limits: GuardLimits) -> Result<Self, SettingError> {
        let pairs = [
            (
                "warn_total_n",
                limits.warn_total_n,
                "stop_total_n",
                limits.stop_total_n,
            ),
            (
                "warn_axial_n",
                limits.warn_axial_n,
                "stop_axial_n",
                limits.stop_axial_n,
            ),
            (
                "warn_lateral_n",
                limits.warn_lateral_n,
                "stop_lateral_n",
                limits.stop_lateral_n,
            ),
        ];
        for (warn_field, warn, stop_field, stop) in pairs {
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
        let min_warn = limits
            .warn_total_n
            .min(limits.warn_axial_n)
            .min(limits.warn_lateral_n);
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
        let warn_n = [
            limits.warn_total_n,
            limits.warn_axial_n,
            limits.warn_lateral_n,
        ];
        let stop_n = [
            limits.stop_total_n,
            limits.stop_axial_n,
            limits.stop_lateral_n,
        ];
        let clear_n = warn_n.map(|w| w - h);
        Ok(Self {
            limits,
            warn_n,
            stop_n,
            clear_n,
            ceiling_n: stop_n,
        })
    }

    /// The checked limits.
    pub fn limits(&self) -> GuardLimits {
        self.limits
    }

    /// The six force limits in use.
    pub fn force_limits(&self) -> ForceLimits {
        let l = &self.limits;
        ForceLimits {
            warn_total_n: l.warn_total_n,
            stop_total_n: l.stop_total_n,
            warn_axial_n: l.warn_axial_n,
            stop_axial_n: l.stop_axial_n,
            warn_lateral_n: l.warn_lateral_n,
            stop_lateral_n: l.stop_lateral_n,
        }
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
            warn_total_n: force.warn_total_n,
            stop_total_n: force.stop_total_n,
            warn_axial_n: force.warn_axial_n,
            stop_axial_n: force.stop_axial_n,
            warn_lateral_n: force.warn_lateral_n,
            stop_lateral_n: force.stop_lateral_n,
            ..self.limits
        };
        let next = Self::new(limits)?;
        let fields = ["stop_total_n", "stop_axial_n", "stop_lateral_n"];
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
}

/// The guard's decision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GuardState {
    /// The robot may move.
    Ok,
    /// The robot may move; the tip force is near a stop limit.
    Warn,
    /// A stop limit was exceeded: the robot must stop. Latched until reset.
    Stop,
    /// The force cannot be trusted: the robot must stop. Latched until reset.
    Fault,
}

impl fmt::Display for GuardState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Ok => "ok",
            Self::Warn => "warn",
            Self::Stop => "stop",
            Self::Fault => "fault",
        })
    }
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

/// Why the guard is in its state, or why a reset was refused. Carries the facts
/// (values, limits, which part or field); its `Display` is a short sentence.
#[non_exhaustive]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reason {
    /// No input has been stepped yet (the initial state).
    NoInputYet,
    /// The cycle number did not increase.
    CycleOutOfOrder {
        /// The largest cycle accepted before.
        previous: u64,
        /// The cycle received.
        got: u64,
    },
    /// The clock could not be read this cycle (no time, no age, no trust).
    ClockFailed,
    /// The clock did not advance since the previous cycle (stuck, or gone
    /// back): every age would be meaningless.
    ClockNotAdvancing {
        /// The largest time seen before, ns.
        previous_ns: u64,
        /// The time of this cycle, ns.
        now_ns: u64,
    },
    /// The sensor's counter jumped by more than the accepted gap (samples
    /// lost, or the counter went back, which wraps to a huge gap).
    SensorCounterGap {
        /// The previous counter.
        previous: u32,
        /// This cycle's counter.
        got: u32,
        /// The largest accepted step.
        max_gap: u32,
    },
    /// The sensor's device status word is not 0 (all good).
    SensorStatus {
        /// The status word.
        status: u32,
    },
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
    },
    /// The joint sample's stamp is older than the previous joint sample's.
    JointsStampBackwards {
        /// The previous stamp, ns.
        previous_ns: u64,
        /// This cycle's stamp, ns.
        got_ns: u64,
    },
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
    },
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
    },
    /// A reset named another cycle than the one just stepped (it must be
    /// judged on the input of the current cycle).
    ResetNotCurrent {
        /// The cycle last stepped.
        last: u64,
        /// The cycle the reset named.
        got: u64,
    },
    /// The force sensor flagged its reading invalid.
    SensorInvalid,
    /// The force sensor reading is too old.
    SensorStale {
        /// Its age, ns.
        age_ns: u64,
        /// The largest accepted age, ns.
        max_age_ns: u64,
    },
    /// The joint positions are flagged invalid.
    JointsInvalid,
    /// The joint positions are too old.
    JointsStale {
        /// Their age, ns.
        age_ns: u64,
        /// The largest accepted age, ns.
        max_age_ns: u64,
    },
    /// The kinematics refused the pose.
    PoseInvalid,
    /// A component of the estimate is NaN or infinite.
    NonFinite {
        /// Which vector.
        field: TipField,
        /// Which component.
        axis: Axis,
    },
    /// A standard deviation is negative.
    NegativeStd {
        /// Which component.
        axis: Axis,
        /// Its value, N.
        std_n: f64,
    },
    /// The rod direction is not a unit vector (within
    /// [`ROD_DIR_UNIT_TOLERANCE`]).
    RodDirNotUnit {
        /// Its norm (finite or +inf, never NaN).
        norm: f64,
    },
    /// The estimator said the tip force is not observable.
    EstimatorNotObservable,
    /// The tip force is not observable: the estimator flagged it (a standard
    /// deviation above its observability limit).
    NotObservable {
        /// The largest per-axis standard deviation, N.
        std_max_n: f64,
        /// The estimator's observability limit, N.
        max_std_n: f64,
    },
    /// A part of the tip force is at or above its stop limit.
    AboveStop {
        /// Which part.
        part: ForcePart,
        /// Its value plus the margin `std_margin |std_n|`, N (finite or +inf,
        /// never NaN).
        force_n: f64,
        /// Its stop limit, N.
        limit_n: f64,
    },
    /// A part of the tip force is at or above its warn limit.
    AboveWarn {
        /// Which part.
        part: ForcePart,
        /// Its value plus the margin `std_margin |std_n|`, N (finite or +inf,
        /// never NaN).
        force_n: f64,
        /// Its warn limit, N.
        limit_n: f64,
    },
    /// Every part has been below its warn limit minus the hysteresis for the
    /// debounce time.
    BelowWarn,
    /// An accepted reset.
    Reset,
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NoInputYet => f.write_str("no input has been received yet"),
            Self::CycleOutOfOrder { previous, got } => {
                write!(f, "cycle {got} does not follow cycle {previous}")
            }
            Self::ClockFailed => f.write_str("the clock could not be read"),
            Self::ClockNotAdvancing {
                previous_ns,
                now_ns,
            } => write!(
                f,
                "the clock did not advance: {now_ns} ns after {previous_ns} ns"
            ),
            Self::SensorCounterGap {
                previous,
                got,
                max_gap,
            } => write!(
                f,
                "the sensor counter went from {previous} to {got} (max step {max_gap})"
            ),
            Self::FollowingError {
                axis,
                error_m,
                tolerance_m,
            } => write!(
                f,
                "q{axis} is {:.3} mm off the commanded trajectory (tolerance {:.3} mm)",
                error_m * 1e3,
                tolerance_m * 1e3
            ),
            Self::SensorStatus { status } => {
                write!(f, "the force sensor reports status {status:#x}")
            }
            Self::JointJump {
                axis,
                moved_m,
                allowed_m,
            } => write!(
                f,
                "q{axis} moved {moved_m:.6} m between two samples (max {allowed_m:.6} m)"
            ),
            Self::JointsStampBackwards {
                previous_ns,
                got_ns,
            } => write!(
                f,
                "the joint stamp went back from {previous_ns} ns to {got_ns} ns"
            ),
            Self::TorqueImplausible {
                axis,
                residual_nm,
                std_nm,
                max_sigma,
            } => write!(
                f,
                "sensor torque {axis} is {residual_nm:.4} N m off the model (std {std_nm:.4} N m, \
                 max {max_sigma} std)"
            ),
            Self::ResetNotCurrent { last, got } => write!(
                f,
                "a reset for cycle {got} is not a reset of the current cycle {last}"
            ),
            Self::SensorInvalid => f.write_str("the force sensor reading is invalid"),
            Self::SensorStale { age_ns, max_age_ns } => write!(
                f,
                "the force sensor reading is {age_ns} ns old (max {max_age_ns} ns)"
            ),
            Self::JointsInvalid => f.write_str("the joint positions are invalid"),
            Self::JointsStale { age_ns, max_age_ns } => write!(
                f,
                "the joint positions are {age_ns} ns old (max {max_age_ns} ns)"
            ),
            Self::PoseInvalid => f.write_str("the kinematics refused the pose"),
            Self::NonFinite { field, axis } => {
                write!(f, "{field}.{axis} of the tip estimate is not finite")
            }
            Self::NegativeStd { axis, std_n } => {
                write!(f, "std_n.{axis} = {std_n} N is negative")
            }
            Self::RodDirNotUnit { norm } => {
                write!(f, "the rod direction has norm {norm}, not 1")
            }
            Self::EstimatorNotObservable => {
                f.write_str("the estimator says the tip force is not observable")
            }
            Self::NotObservable {
                std_max_n,
                max_std_n,
            } => write!(
                f,
                "the tip force is not observable: std {std_max_n:.3} N > limit {max_std_n:.3} N"
            ),
            Self::AboveStop {
                part,
                force_n,
                limit_n,
            } => write!(
                f,
                "{part} tip force {force_n:.3} N is at or above the stop limit {limit_n:.3} N"
            ),
            Self::AboveWarn {
                part,
                force_n,
                limit_n,
            } => write!(
                f,
                "{part} tip force {force_n:.3} N is at or above the warn limit {limit_n:.3} N"
            ),
            Self::BelowWarn => {
                f.write_str("every tip force part is below its warn limit minus the hysteresis")
            }
            Self::Reset => f.write_str("reset accepted"),
        }
    }
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
    /// input is needed before the robot may move.
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
        }
    }

    /// The current state.
    pub fn state(&self) -> GuardState {
        self.state
    }

    /// Why the guard is in its current state (the latched first reason for
    /// `Stop` and `Fault`; the entering reason for `Warn`; `Reset` or
    /// `BelowWarn` for `Ok`).
    pub fn reason(&self) -> Reason {
        self.reason
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
    /// anything: a fault condition, a part at or above its stop limit, or
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

    /// Feeds one control cycle. Returns `Some` only when the state changed.
    #[inline]
    pub fn step(&mut self, input: &GuardInput) -> Option<Transition> {
        let cycle = input.cycle;
        let parts_n = match self.evaluate(input) {
            Err(fault) => {
                self.blocker = Some(fault);
                self.above_warn = Some(fault);
                self.stop_count = 0;
                self.warn_count = 0;
                self.clear_count = 0;
                return self.enter(GuardState::Fault, fault, cycle);
            }
            Ok(parts_n) => parts_n,
        };
        let cfg = &self.config;
        let stop_hit = first_at_or_above(&parts_n, &cfg.stop_n);
        let warn_hit = first_at_or_above(&parts_n, &cfg.warn_n);
        let clear = parts_n
            .iter()
            .zip(cfg.clear_n.iter())
            .all(|(value, limit)| *value < *limit);
        let debounce = cfg.limits.debounce_samples;

        if input.new_sample {
            let vote = |count: u32, holds: bool| {
                if holds {
                    count.saturating_add(1).min(debounce)
                } else {
                    count.saturating_sub(1)
                }
            };
            self.stop_count = vote(self.stop_count, stop_hit.is_some());
            self.warn_count = vote(self.warn_count, warn_hit.is_some());
            self.clear_count = vote(self.clear_count, clear);
        }
        self.blocker = stop_hit.map(|(part, force_n, limit_n)| Reason::AboveStop {
            part,
            force_n,
            limit_n,
        });
        self.above_warn = warn_hit.map(|(part, force_n, limit_n)| Reason::AboveWarn {
            part,
            force_n,
            limit_n,
        });

        match self.state {
            GuardState::Stop | GuardState::Fault => None,
            GuardState::Ok | GuardState::Warn => {
                if let Some((part, force_n, limit_n)) = stop_hit
                    && self.stop_count >= debounce
                {
                    let reason = Reason::AboveStop {
                        part,
                        force_n,
                        limit_n,
                    };
                    return self.enter(GuardState::Stop, reason, cycle);
                }
                if self.state == GuardState::Ok {
                    if let Some((part, force_n, limit_n)) = warn_hit
                        && self.warn_count >= debounce
                    {
                        let reason = Reason::AboveWarn {
                            part,
                            force_n,
                            limit_n,
                        };
                        // Leaving Warn needs a fresh run of clear samples.
                        self.clear_count = 0;
                        return self.enter(GuardState::Warn, reason, cycle);
                    }
                } else if clear && self.clear_count >= debounce {
                    // Re-entering Warn needs a fresh run of warn samples.
                    self.warn_count = 0;
                    return self.enter(GuardState::Ok, Reason::BelowWarn, cycle);
                }
                None
            }
        }
    }

    /// Asks to leave `Stop` or `Fault` for `Ok`, judged on the input of
    /// `cycle`, which must be the cycle just stepped (else refused with
    /// [`Reason::ResetNotCurrent`]; before any step with
    /// [`Reason::NoInputYet`]): call it right after [`Guard::step`] of the same
    /// cycle (as [`crate::cycle::Estimator::cycle`] does for a reset command).
    /// In `Ok` or `Warn` it does nothing (`Ok(None)`). Refused while the cause
    /// persists in that input: any fault condition, any part at or above its
    /// stop limit (not debounced). An accepted reset clears the debounce
    /// counts.
    pub fn reset(&mut self, cycle: u64) -> Result<Option<Transition>, ResetRefused> {
        match self.state {
            GuardState::Ok | GuardState::Warn => Ok(None),
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
                if let Some(reason) = self.blocker {
                    return Err(ResetRefused { reason });
                }
                self.stop_count = 0;
                self.warn_count = 0;
                self.clear_count = 0;
                Ok(self.enter(GuardState::Ok, Reason::Reset, cycle))
            }
        }
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

    /// The first fault condition of `input` in the fixed order, or the force
    /// parts. Records the cycle if it is in order.
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

        if let Some(fault) = input.input_fault {
            return Err(fault);
        }
        let limits = &self.config.limits;
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
        let (force_n, std_n, rod_dir, observable, max_std_n) = match input.tip {
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
        // The margin: k |std| bounds k standard deviations of every part.
        let margin_n = if limits.std_margin > 0.0 {
            limits.std_margin * std_n.norm()
        } else {
            0.0
        };
        Ok(force_parts_n(&force_n, &rod_dir).map(|part_n| part_n + margin_n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(debounce_samples: u32) -> GuardLimits {
        GuardLimits {
            warn_total_n: 9.0,
            stop_total_n: 17.0,
            warn_axial_n: 8.0,
            stop_axial_n: 15.0,
            warn_lateral_n: 6.0,
            stop_lateral_n: 10.0,
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
