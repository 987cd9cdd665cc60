//! The tissue at the tip: where its surface is at a time (rest point,
//! breathing, sudden shifts) and the force of its unilateral spring-damper on
//! the tip ([`Tissue`]'s doc has the law).
//!
//! Pure functions of the time and of the tip's position and velocity: the
//! tissue has no state of its own. The tip is carried by the axes'
//! positions (closed-form profiles, exact at any instant), so the law is
//! evaluated, never integrated: no physics step, however long, makes the
//! contact unstable, whatever the stiffness. The tip's velocity comes from
//! the forward kinematics' derivative along the joints' velocity (a central
//! difference of the closed form, not of time samples).

use super::spec::{Tissue, TissueModel};
use sar_hal::Vec3;
use sar_hal::convert::ns_to_s;
use sar_kinematics::{ActiveJoints, Calibration, Profile, forward};

/// Joint-space step of the central difference that gives the tip's velocity,
/// s (the joints move by their velocity times this): small beside any change
/// of the kinematics' curvature, large beside the rounding of positions.
const VELOCITY_STEP_S: f64 = 1e-3;

impl Tissue {
    /// The rest point (a point of the surface) at `t_ns` (ns from start), {0}, m,
    /// and its velocity, m/s.
    pub fn rest_at(&self, t_ns: u64) -> (Vec3, Vec3) {
        let mut rest_m = self.rest_m;
        let mut velocity_mps = Vec3::zeros();
        if let Some(b) = &self.breathing {
            let omega = core::f64::consts::TAU * b.hz;
            let phase = omega * ns_to_s(t_ns);
            rest_m += b.direction * (b.amplitude_m * phase.sin());
            velocity_mps += b.direction * (b.amplitude_m * omega * phase.cos());
        }
        let after = self.shifts.partition_point(|s| s.t_ns <= t_ns);
        if let Some(shift) = after.checked_sub(1).and_then(|i| self.shifts.get(i)) {
            rest_m += self.direction * shift.offset_m;
        }
        (rest_m, velocity_mps)
    }

    /// The penetration of a tip at `tip_m` at `t_ns`: (delta, m, > 0 inside;
    /// its rate for a tip moving at `tip_velocity_mps`, m/s).
    pub fn penetration_at(&self, t_ns: u64, tip_m: &Vec3, tip_velocity_mps: &Vec3) -> (f64, f64) {
        let (rest_m, rest_velocity_mps) = self.rest_at(t_ns);
        (
            (tip_m - rest_m).dot(&self.direction),
            (tip_velocity_mps - rest_velocity_mps).dot(&self.direction),
        )
    }

    /// The spring's force at a penetration `delta_m` (0 outside), N.
    pub fn spring_n(&self, delta_m: f64) -> f64 {
        if delta_m <= 0.0 {
            return 0.0;
        }
        match self.model {
            TissueModel::Linear { stiffness_n_per_m } => stiffness_n_per_m * delta_m,
            TissueModel::Exponential {
                stiffness_n_per_m,
                beta_per_m,
            } => stiffness_n_per_m / beta_per_m * (beta_per_m * delta_m).exp_m1(),
        }
    }

    /// F_tip of this tissue (what the tip applies to it) for a tip at `tip_m`
    /// moving at `tip_velocity_mps` at `t_ns`, {0}, N: zero outside, never
    /// pulling inside.
    pub fn force_n(&self, t_ns: u64, tip_m: &Vec3, tip_velocity_mps: &Vec3) -> Vec3 {
        let (delta_m, rate_mps) = self.penetration_at(t_ns, tip_m, tip_velocity_mps);
        if delta_m <= 0.0 {
            return Vec3::zeros();
        }
        let total_n = self.spring_n(delta_m) + self.damping_n_s_per_m * rate_mps;
        self.direction * total_n.max(0.0)
    }
}

/// The tip's velocity, {0}, m/s, for joints `q` moving at `speeds_mps` (q1,
/// q2, q3): the forward kinematics' central difference along the velocity,
/// one-sided where one side leaves the model, zero where both do (only at
/// the model's edge, where the pose itself is about to be refused).
pub(crate) fn tip_velocity_mps(
    calibration: &Calibration,
    profile: &Profile,
    q: &ActiveJoints,
    speeds_mps: [f64; 3],
    tip_m: &Vec3,
) -> Vec3 {
    if speeds_mps == [0.0; 3] {
        return Vec3::zeros();
    }
    let h = VELOCITY_STEP_S;
    let moved = |sign: f64| {
        let [v1, v2, v3] = speeds_mps;
        let p = ActiveJoints {
            q1_m: q.q1_m + sign * h * v1,
            q2_m: q.q2_m + sign * h * v2,
            q3_m: q.q3_m + sign * h * v3,
        };
        forward(calibration, profile, &p)
            .ok()
            .map(|pose| pose.tip_m)
    };
    match (moved(1.0), moved(-1.0)) {
        (Some(ahead), Some(behind)) => (ahead - behind) / (2.0 * h),
        (Some(ahead), None) => (ahead - tip_m) / h,
        (None, Some(behind)) => (tip_m - behind) / h,
        (None, None) => Vec3::zeros(),
    }
}

/// F_tip of every tissue for the tip at `tip_m` moving at `tip_velocity_mps`
/// at `t_ns`, summed, {0}, N.
pub(crate) fn force_n(
    tissues: &[Tissue],
    t_ns: u64,
    tip_m: &Vec3,
    tip_velocity_mps: &Vec3,
) -> Vec3 {
    tissues
        .iter()
        .map(|t| t.force_n(t_ns, tip_m, tip_velocity_mps))
        .sum()
}
