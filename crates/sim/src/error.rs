//! The simulator's errors: a refused specification, and the runtime errors of
//! its sensor and drives, each with the [`ErrorKind`] generic code acts on.

use sar_hal::{DriveState, Error, ErrorKind};
use sar_kinematics::{PoseError, Shown};

/// Why the simulator refused a specification or a command.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// A value of the specification is out of its allowed range.
    #[error("simulator spec: {field} = {value} is not allowed: {why}")]
    InvalidSpec {
        /// Which value.
        field: &'static str,
        /// The value given (as f64).
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// A contact keyframe is earlier than the one before it.
    #[error(
        "simulator spec: contact key {index} at {t_ns} ns is earlier than the key before it, \
         at {previous_ns} ns (keys must be sorted by time)"
    )]
    ContactNotSorted {
        /// Index of the out-of-order key (>= 1).
        index: usize,
        /// Its time, ns.
        t_ns: u64,
        /// The previous key's time, ns.
        previous_ns: u64,
    },
    /// A fault names an axis other than 0, 1, 2.
    #[error("simulator spec: fault {index} names axis {axis}; axes are 0 (q1), 1 (q2), 2 (q3)")]
    FaultAxis {
        /// Index of the fault in the list.
        index: usize,
        /// The axis given.
        axis: usize,
    },
    /// The start positions have no kinematic solution (or no statics).
    #[error("simulator spec: the start pose is not valid: {0}")]
    StartPose(PoseError),
    /// The start pose is kinematically valid but its statics are singular.
    #[error("simulator spec: the statics of the start pose are singular")]
    StartStaticsSingular,
    /// So many samples would be in flight at once (latency / period) that the
    /// simulator refuses to hold them.
    #[error(
        "simulator spec: latency {latency_ns} ns over sample period {period_ns} ns puts more \
         than {limit} samples in flight"
    )]
    LatencyTooLong {
        /// The latency, ns.
        latency_ns: u64,
        /// The sample period, ns.
        period_ns: u64,
        /// The largest accepted number of samples in flight.
        limit: u64,
    },
    /// A fault given at run time starts at or before the present time.
    #[error("fault at {at_ns} ns is not in the future (now {elapsed_ns} ns from start)")]
    FaultNotInFuture {
        /// When the fault would start, ns from start.
        at_ns: u64,
        /// The present time, ns from start.
        elapsed_ns: u64,
    },
    /// The clock could not be read.
    #[error(transparent)]
    Clock(#[from] sar_hal::ClockError),
    /// No sample arrived within the wait.
    #[error("no sensor sample within {timeout_ns} ns")]
    Timeout {
        /// The wait, ns.
        timeout_ns: u64,
    },
    /// The command is not allowed in the drives' present state.
    #[error("{command} is not allowed in drive state {state:?}")]
    InvalidState {
        /// The command.
        command: &'static str,
        /// The drives' state.
        state: DriveState,
    },
    /// A target is NaN or infinite.
    #[error("target of axis {axis} is not finite ({value_m})")]
    TargetNonFinite {
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// The value given, m.
        value_m: f64,
    },
    /// A target is outside the axis' travel.
    #[error(
        "target of axis {axis} = {} m is outside the travel {}..{} m",
        Shown(*.target_m),
        Shown(*.min_m),
        Shown(*.max_m)
    )]
    TargetOutOfTravel {
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// The value given, m.
        target_m: f64,
        /// Lower end of the travel, m.
        min_m: f64,
        /// Upper end of the travel, m.
        max_m: f64,
    },
    /// The targets put the rod in a pose that has no kinematic solution.
    #[error("the targets give no valid pose: {0}")]
    TargetPose(PoseError),
    /// A streamed set point is farther than the axis can go in one period.
    #[error(
        "set point of axis {axis} is {} m away, more than the {} m the speed \
         limit allows in one period",
        Shown(*.distance_m),
        Shown(*.reach_m)
    )]
    SetPointTooFar {
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// How far, m.
        distance_m: f64,
        /// How far it may be, m.
        reach_m: f64,
    },
    /// The simulated device has no such command.
    #[error("{command} is not supported by the simulated sensor")]
    Unsupported {
        /// The command.
        command: &'static str,
    },
    /// The present pose leaves the model (no kinematic solution), so there is
    /// no truth to give.
    #[error("the simulated pose is outside the model: {0}")]
    PoseOutOfModel(PoseError),
    /// The present pose has singular statics.
    #[error("the statics of the simulated pose are singular")]
    StaticsSingular,
    /// The simulator was called while it was already busy (re-entrant call).
    #[error("the simulator is already in use (re-entrant call)")]
    Busy,
}

impl Error for SimError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Timeout { .. } => ErrorKind::Timeout,
            Self::Clock(e) => sar_hal::Error::kind(e),
            Self::InvalidState { .. } => ErrorKind::InvalidState,
            Self::Unsupported { .. } => ErrorKind::Unsupported,
            Self::InvalidSpec { .. }
            | Self::ContactNotSorted { .. }
            | Self::FaultAxis { .. }
            | Self::StartPose(_)
            | Self::StartStaticsSingular
            | Self::LatencyTooLong { .. }
            | Self::FaultNotInFuture { .. }
            | Self::TargetNonFinite { .. }
            | Self::TargetOutOfTravel { .. }
            | Self::SetPointTooFar { .. }
            | Self::TargetPose(_) => ErrorKind::InvalidArgument,
            Self::PoseOutOfModel(_) | Self::StaticsSingular | Self::Busy => ErrorKind::Other,
        }
    }
}
