//! Why the guard is in its state, or why a reset was refused: [`Reason`],
//! one table a row per reason (its stable code and name, its facts, its
//! sentence), and what the recordings and the wire make of the codes
//! ([`REASONS`], [`recorded_code`], [`reason_name`]).

use super::parts::{Axis, ForcePart, RestResidual, SensorChannel, TipField};
use core::fmt;

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
        /// [`super::ROD_DIR_UNIT_TOLERANCE`]).
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
