//! What the guard looks at in one control cycle ([`GuardInput`], with the
//! tip-force estimator's delivery [`TipInput`]) and its fault conditions,
//! in their fixed order: the caller's input fault, the samples' validity and
//! age, then the estimate's (a refused pose, the unobservable flag, a
//! non-finite number, a negative standard deviation, a rod direction not of
//! unit length, an unobservable force).

use super::limits::GuardLimits;
use super::parts::{Axis, TipField};
use super::reason::Reason;
use crate::Vec3;

/// How far the norm of the rod direction u may be from 1.
pub const ROD_DIR_UNIT_TOLERANCE: f64 = 1e-6;

/// Bounds on the squared norm of u that match [`ROD_DIR_UNIT_TOLERANCE`] (no
/// square root on the good path).
const ROD_DIR_NORM2_MIN: f64 = (1.0 - ROD_DIR_UNIT_TOLERANCE) * (1.0 - ROD_DIR_UNIT_TOLERANCE);
const ROD_DIR_NORM2_MAX: f64 = (1.0 + ROD_DIR_UNIT_TOLERANCE) * (1.0 + ROD_DIR_UNIT_TOLERANCE);

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

/// The samples' fault conditions in the fixed order: the caller's input
/// fault, the sensor's validity and age, the joints' validity and age.
#[inline]
pub(super) fn check_samples(input: &GuardInput, limits: &GuardLimits) -> Result<(), Reason> {
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
pub(super) fn check_estimate(tip: &TipInput) -> Result<(Vec3, Vec3, Vec3), Reason> {
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
