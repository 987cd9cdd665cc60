//! The reply to a cycle's request: its status ([`ReplyStatus`], the wire's)
//! and its exact cause ([`ReplyDetail`], what `sarctl` prints), and the
//! reply to each of the estimator's commands.

use super::config::{GUARDED_CONTACT_SIGMA, MAX_BACK_OUT_M};
use crate::excite::ExciteRefusal;
use sar_estimator::Vec3;
use sar_estimator::cycle::{CommandAccepted, CommandRefused};
use sar_estimator::guard::{GuardState, Reason};
use sar_hal::DriveState;
use sar_kinematics::{PoseError, Shown};

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
    /// Force control refused: the support watch named a shift of the
    /// support beyond its limit, not yet confirmed (issue 34 section 3).
    SupportShifted(SupportShifted),
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

/// [`ReplyDetail::DrivesNotEnabled`] in words.
fn drives_not_enabled(
    f: &mut core::fmt::Formatter<'_>,
    state: Option<&DriveState>,
) -> core::fmt::Result {
    match state {
        Some(s) => write!(f, "the drives are {}, not enabled", drive_state_words(s)),
        None => f.write_str("the drives' state could not be read"),
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
            Self::DrivesNotEnabled(state) => drives_not_enabled(f, state.as_ref()),
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
            Self::SupportShifted(s) => write!(f, "{s}"),
        }
    }
}

/// A shift of the support named and not confirmed ([`ReplyDetail::SupportShifted`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportShifted {
    /// The shift named, base frame, m.
    pub shift_m: Vec3,
    /// `[support] max_shift_m`.
    pub max_shift_m: f64,
}

impl core::fmt::Display for SupportShifted {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = self.shift_m * 1e3;
        write!(
            f,
            "the support has shifted by ({:.1}, {:.1}, {:.1}) mm, beyond its {:.1} mm \
             ([support] max_shift_m): the tip force is estimated about the wrong \
             fulcrum; re-calibrate (sarctl identify) or confirm (sarctl support confirm)",
            s.x,
            s.y,
            s.z,
            self.max_shift_m * 1e3
        )
    }
}

/// A reply's status and its exact cause.
pub(super) type Answer = (ReplyStatus, ReplyDetail);

/// The reply to an estimator command, with its exact cause.
pub(super) fn command_reply(
    result: &Result<CommandAccepted, CommandRefused>,
) -> (ReplyStatus, ReplyDetail) {
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
