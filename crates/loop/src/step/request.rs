//! The operator's requests to the loop: what a cycle's input may carry
//! ([`super::LoopInput::request`]), each answered in that cycle.

#[cfg(doc)]
use super::LoopOutput;
use crate::excite::ExciteRequest;
use sar_estimator::Vec3;
use sar_estimator::guard::ForceLimits;

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
    /// Back the tip out along the rod by this distance, m (0 < d <= 0.1):
    /// a move to `tip - d u`, accepted in Retreat too (it reduces the force).
    BackOut {
        /// How far, m.
        distance_m: f64,
    },
    /// A guarded move (force control, issue 15): as `MoveTip`, but braked
    /// (hard: at `[axes] brake_decel_mps2`, streamed; issue 26) in the cycle
    /// in which the magnitude of the tip force (filtered when the filter is
    /// on) is anticipated to reach `max_force_n`: the force plus its rise
    /// (its rate, low-passed) over the filter's lag, the drives' lag and the
    /// braking, once it is a quarter of the limit; where and at what force
    /// is reported
    /// ([`LoopOutput::guarded_stop`]).
    GuardedMove {
        /// The wanted tip, base frame, m.
        tip_m: Vec3,
        /// The force that stops it, N (0 < N <= the total stop limit).
        max_force_n: f64,
    },
    /// Force control (issue 15, FORCE_CONTROL.md): hold the tip while the
    /// tip force is below `max_force_n`, yield along it above.
    Hold {
        /// N (0 < N <= the total warn limit).
        max_force_n: f64,
    },
    /// Force control: regulate the axial tip force to `axial_n`, the
    /// lateral position held.
    Push {
        /// N (0 < N < the axial warn limit).
        axial_n: f64,
    },
    /// End force control: hold the tip where it is (position control).
    Position,
    /// The dynamic identification's excitation about where the axes rest
    /// (issue 26, [`crate::excite`]).
    Excite(ExciteRequest),
    /// The operator confirms the support as it is now (issue 34 section 3):
    /// a named shift becomes the acknowledged one, and force control is
    /// no longer refused for it (`sarctl support confirm`).
    SupportConfirm,
}
