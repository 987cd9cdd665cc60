//! The commanded trajectory ([`Trajectory`]: one time-optimal plan per
//! axis, or an excitation) and what a phase of the step decides of it
//! ([`TrajectoryChange`]). The step owns one trajectory; its phases read the
//! cycle's working copy and return a change, and the step's one commit point
//! (`step/commit.rs`) is its only writer.

use crate::excite::Excitation;
use sar_estimator::Vec3;
use sar_hal::motion::{AxisPlan, AxisState};
use sar_kinematics::ActiveJoints;

/// The commanded trajectory: one plan per axis, and the tip it ends at (for
/// the warn-limit rule; `None` for a hold or a brake).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Trajectory {
    pub(super) axes: [AxisPlan; 3],
    pub(super) target_tip_m: Option<Vec3>,
    pub(super) end_ns: u64,
    /// Streamed to the drives one set point per period (retreat moves at a
    /// reduced speed) rather than given as an end point.
    pub(super) streamed: bool,
    /// A guarded move's force limit, N (braked when the force is
    /// anticipated to reach it).
    pub(super) max_force_n: Option<f64>,
    /// An excitation under way: then it is the trajectory (`axes` hold
    /// its centre).
    pub(super) excite: Option<Excitation>,
}

impl Trajectory {
    pub(super) fn hold(now_ns: u64, q: &ActiveJoints) -> Self {
        Self {
            axes: joints_array(q).map(|x| AxisPlan::hold(now_ns, x)),
            target_tip_m: None,
            end_ns: now_ns,
            streamed: false,
            max_force_n: None,
            excite: None,
        }
    }

    pub(super) fn at(&self, t_ns: u64) -> [AxisState; 3] {
        match &self.excite {
            Some(e) => e.at(t_ns).0,
            None => self.axes.map(|p| p.at(t_ns)),
        }
    }

    pub(super) fn position(&self, t_ns: u64) -> ActiveJoints {
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
    pub(super) fn delay(&mut self, dt_ns: u64) {
        self.axes = self.axes.map(|p| p.delayed(dt_ns));
        self.end_ns = self.end_ns.saturating_add(dt_ns);
        if let Some(e) = &mut self.excite {
            e.start_ns = e.start_ns.saturating_add(dt_ns);
        }
    }

    pub(super) fn from_plans(
        start_ns: u64,
        axes: [AxisPlan; 3],
        target_tip_m: Option<Vec3>,
    ) -> Self {
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

pub(super) fn joints_array(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

/// What a phase of the step decides of the commanded trajectory: the step
/// applies each phase's change in turn to the cycle's working copy, and
/// commits the result once.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(
    clippy::large_enum_variant,
    reason = "no allocation on the loop's path: a change is a value, like the trajectory it carries"
)]
pub(super) enum TrajectoryChange {
    /// As it is.
    Keep,
    /// None from now on (a halt; a reset without a valid joint sample).
    Drop,
    /// This one from now on (a hold, a planned or braked move, an
    /// excitation, force control's set point).
    Replace(Trajectory),
}

impl TrajectoryChange {
    /// `trajectory` after the change.
    pub(super) fn applied_to(self, trajectory: Option<Trajectory>) -> Option<Trajectory> {
        match self {
            Self::Keep => trajectory,
            Self::Drop => None,
            Self::Replace(t) => Some(t),
        }
    }
}
