//! The guard's decision ([`GuardState`]: Ok, Warn, Stop and Fault latched,
//! Retreat) and the rule of motion in `Retreat` ([`reduces_force`]).

use crate::Vec3;
use core::fmt;

/// The guard's decision. Deliberately not `#[non_exhaustive]` (see
/// [`super::Reason`]).
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

// Snapshots (issue 17): the state by its code.

sar_snapshot::snap_enum!(GuardState { 0 => Ok, 1 => Warn, 2 => Stop, 3 => Fault, 4 => Retreat });
