//! The mounting verdict: the first reset's check of the wrench at rest
//! against the model ([`super::MountingLimits`]). With the tip free, the
//! model predicts the whole sensor wrench, so the estimated F_tip and the
//! torque residual, averaged over the new samples since the joints last
//! moved ([`RestMean`]), are the model's residuals: a rod mounted otherwise
//! than calibrated, or a wrong profile, refuses the first reset.

use super::Estimator;
use super::input_checks::moved_since;
use super::plausibility::MountingLimits;
use super::vocabulary::TipOutcome;
use crate::Vec3;
use crate::guard::{Axis, Reason, RestResidual};
use sar_kinematics::ActiveJoints;

/// The means at rest for the first reset's check ([`MountingLimits`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct RestMean {
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
    pub(super) const EMPTY: RestMean = RestMean {
        count: 0,
        force_n: Vec3::new(0.0, 0.0, 0.0),
        torque_nm: Vec3::new(0.0, 0.0, 0.0),
        std_n: Vec3::new(0.0, 0.0, 0.0),
        std_nm: Vec3::new(0.0, 0.0, 0.0),
        joints: None,
    };
}

impl Estimator {
    /// The means at rest: one new sample's estimate and torque residual
    /// into them; joints that moved (beyond the joint margin) restart them,
    /// and so does a sample without an estimate.
    pub(super) fn update_rest_mean(&mut self, q: &ActiveJoints) {
        let Some(limits) = self.limits.mounting else {
            return;
        };
        let rest = &mut self.rest;
        let TipOutcome::Estimate(e) = self.last.tip else {
            *rest = RestMean::EMPTY;
            return;
        };
        if moved_since(rest.joints, q, self.limits.joint_margin_m) {
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

    /// The first reset's check of the wrench at rest ([`MountingLimits`]):
    /// the refusal's reason, or `None` when the residuals are within bounds
    /// (or there is no estimate: the guard's own blocker then refuses).
    /// Refused while the mean is not complete (`RestIncomplete`).
    pub(super) fn mounting_verdict(&self, limits: &MountingLimits) -> Option<Reason> {
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
}

sar_snapshot::snap_struct!(RestMean {
    count,
    force_n,
    torque_nm,
    std_n,
    std_nm,
    joints,
});
