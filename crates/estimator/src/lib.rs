//! The SAR's estimator core: tip force, identification of mass and centre of
//! mass, support calibration and the force-limit guard (MODEL.md 4-6), and
//! the tip force in motion with the rod's inertia compensated (MODEL.md 10,
//! [`inertial`]).
//!
//! Invariants (see `ARCHITECTURE.md`):
//! - `#![no_std]`, no `alloc`, no I/O, no panics on any input. All state is
//!   fixed-size and chosen at construction.
//! - Signs and frames are those of MODEL.md: F_A is what the robot applies to the
//!   rod at A, F_tip = -F_D is what the tip applies to the tissue, both in {0}.
//! - SI units, unit last in every name.
#![no_std]

pub mod article;
pub mod cycle;
pub mod error_measure;
pub mod filter;
pub mod force_control;
pub mod force_range;
pub mod guard;
pub mod identification;
pub mod inertia_watch;
pub mod inertial;
mod linalg;
pub mod line_fit;
pub mod motion;
pub mod support;
pub mod tip_force;

pub use sar_kinematics::{
    Calibration, CalibrationSpec, Mat3, Pose, Profile, ProfileSpec, SlideSign, Vec3,
};

/// Smallest accepted distance a = |B - A| between the U-joint centre and the
/// support, m: identification and support calibration refuse a pose closer
/// than this. The model's 1/a and 1/a^2 terms make closer poses meaningless.
pub const MIN_SUPPORT_DISTANCE_M: f64 = 0.005;

/// Why an estimator setting was refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SettingError {
    /// A value is NaN, infinite, or out of its allowed range.
    #[error("{field} = {value} is not allowed: {why}")]
    Invalid {
        /// Which setting.
        field: &'static str,
        /// The value given.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// The tip-force filter's settings were refused.
    #[error("filter: {0}")]
    Filter(#[from] filter::FilterError),
    /// The force loop would not keep its phase margin over the plant's
    /// range (issue 34; `force_range`).
    #[error(
        "{field}: the force control is not stable over the plant's range: {case} \
         (at least {min_deg} deg asked); narrow the range (servo_bandwidth_min_ratio, \
         servo_bandwidth_max_ratio, servo_damping_min, servo_damping_max, \
         servo_delay_max_s, inertia_perp_ratio_min, inertia_perp_ratio_max, \
         min_tip_depth_m) or slow the law (the part's damping and mass, filter_cutoff_hz)"
    )]
    NotStableOverRange {
        /// The range's bound (or the law's setting) the worst case sits at.
        field: &'static str,
        /// The worst case.
        case: force_range::RangeCase,
        /// The margin asked for, degrees.
        min_deg: f64,
    },
}

/// `Ok` if `ok`, else the setting error naming `field`, its value and what
/// it must be (`why`).
pub(crate) fn require(
    ok: bool,
    field: &'static str,
    value: f64,
    why: &'static str,
) -> Result<(), SettingError> {
    if ok {
        Ok(())
    } else {
        Err(SettingError::Invalid { field, value, why })
    }
}

/// A setting that must be finite and > 0.
pub(crate) fn positive(field: &'static str, value: f64) -> Result<(), SettingError> {
    require(
        value.is_finite() && value > 0.0,
        field,
        value,
        "must be finite and > 0",
    )
}

/// A setting that must be finite and >= 0.
pub(crate) fn finite_non_negative(field: &'static str, value: f64) -> Result<(), SettingError> {
    require(
        value.is_finite() && value >= 0.0,
        field,
        value,
        "must be finite and >= 0",
    )
}

/// A setting that must be finite and >= `lo` (`why` says so).
pub(crate) fn at_least(
    field: &'static str,
    value: f64,
    lo: f64,
    why: &'static str,
) -> Result<(), SettingError> {
    require(value.is_finite() && value >= lo, field, value, why)
}

/// The force sensor's noise: one standard deviation per sensor axis, N
/// (MODEL.md 7: the HEX-6 has 0.2, 0.2, 0.8).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    std_n: Vec3,
}

impl SensorNoise {
    /// The HEX-6 of the article.
    pub const HEX6_STD_N: [f64; 3] = [0.2, 0.2, 0.8];

    /// Checks each standard deviation is finite and > 0.
    pub fn new(std_n: Vec3) -> Result<Self, SettingError> {
        for &value in std_n.iter() {
            if !(value.is_finite() && value > 0.0) {
                return Err(SettingError::Invalid {
                    field: "noise_n",
                    value,
                    why: "each standard deviation must be finite and > 0",
                });
            }
        }
        Ok(Self { std_n })
    }

    /// The HEX-6 noise.
    pub fn hex6() -> Self {
        let [x, y, z] = Self::HEX6_STD_N;
        Self {
            std_n: Vec3::new(x, y, z),
        }
    }

    /// Standard deviation per sensor axis, N.
    pub fn std_n(&self) -> Vec3 {
        self.std_n
    }

    /// Covariance of one sample of F_A = -R_0s (f_s - b) in {0}, N^2.
    pub fn base_covariance_n2(&self, sensor_rotation: &Mat3) -> Mat3 {
        let var = Mat3::from_diagonal(&self.std_n.component_mul(&self.std_n));
        sensor_rotation * var * sensor_rotation.transpose()
    }
}

/// F_A in {0}: what the robot applies to the rod at A, from a raw sensor
/// reading `reading_n` (sensor frame) and the force bias `bias_n` (sensor frame):
/// `F_A = -R_0s (f_s - b_f)` (MODEL.md 4).
pub fn ujoint_force_n(cal: &Calibration, reading_n: &Vec3, bias_n: &Vec3) -> Vec3 {
    -(cal.sensor_rotation() * (reading_n - bias_n))
}

/// One static pose of an identification run, with nothing touching the tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticPose {
    /// A, the U-joint centre, {0}, m (from the forward kinematics).
    pub ujoint_m: Vec3,
    /// The sensor's force reading averaged over the pose, sensor frame, N,
    /// before bias removal.
    pub mean_reading_n: Vec3,
    /// How many samples were averaged (>= 1).
    pub samples: u32,
    /// The direction of the last slide of the rod in the support before this
    /// pose (MODEL.md 5): its sigma is the coefficient of the friction unknown.
    /// A pose whose sign is [`SlideSign::Unknown`] never enters a friction fit
    /// with a coefficient: [`crate::identification`] drops its axial row (the
    /// only one that involves f) and [`crate::support`] refuses it when friction
    /// is estimated.
    pub slide_sign: SlideSign,
}

/// Why a [`StaticPose`]'s own values were refused ([`StaticPose::check`]).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PoseInputError {
    /// A value of the pose is NaN or infinite.
    #[error("{field} is not finite ({value})")]
    NonFinite {
        /// Which value: `"ujoint_m"` or `"mean_reading_n"`.
        field: &'static str,
        /// The offending value (the first non-finite component of a vector).
        value: f64,
    },
    /// No samples were averaged.
    #[error("samples = {samples}; at least 1 is needed")]
    NoSamples {
        /// The value given.
        samples: u32,
    },
}

impl StaticPose {
    /// Checks the pose's own values, in this order: `ujoint_m` and
    /// `mean_reading_n` finite, `samples` >= 1 (the slide sign is a type and
    /// cannot be wrong). Where A lies relative to the support
    /// ([`MIN_SUPPORT_DISTANCE_M`]) is for the user of the pose to check.
    pub fn check(&self) -> Result<(), PoseInputError> {
        let non_finite = |field| move |value| PoseInputError::NonFinite { field, value };
        check_finite(&self.ujoint_m, non_finite("ujoint_m"))?;
        check_finite(&self.mean_reading_n, non_finite("mean_reading_n"))?;
        if self.samples == 0 {
            return Err(PoseInputError::NoSamples {
                samples: self.samples,
            });
        }
        Ok(())
    }
}

/// A round-off negative variance as 0; NaN stays NaN (`f64::max(NaN, 0.0)` would
/// give 0, a standard error of zero, which the finiteness checks cannot catch).
pub(crate) fn non_negative(x: f64) -> f64 {
    if x < 0.0 { 0.0 } else { x }
}

/// First-order standard error of the centre of mass c = M / m, from the
/// variances of m and M and their covariance:
/// `var c = (var M - 2 c cov(m, M) + c^2 var m) / m^2`. A round-off negative
/// variance gives 0; NaN stays NaN.
pub(crate) fn com_std_m(
    mass_kg: f64,
    moment_kgm: f64,
    mass_var_kg2: f64,
    moment_var_kg2m2: f64,
    cov_kg2m: f64,
) -> f64 {
    let com_m = moment_kgm / mass_kg;
    let var_m2 = (moment_var_kg2m2 - 2.0 * com_m * cov_kg2m + com_m * com_m * mass_var_kg2)
        / (mass_kg * mass_kg);
    nalgebra::ComplexField::sqrt(non_negative(var_m2))
}

pub(crate) use sar_kinematics::check_finite;

#[cfg(test)]
mod tests {
    use super::*;

    /// The ratio form of `com_std_m` is the delta method g^T S g with the
    /// gradient g = (-M / m^2, 1 / m) of c = M / m; a round-off negative
    /// variance gives 0 and NaN stays NaN.
    #[test]
    fn com_std_is_the_delta_method() {
        for &(m, moment, vm, vmm, cov) in &[
            (1.611, 0.185, 4e-4, 9e-6, -5e-5),
            (2.593, -0.267, 1e-2, 3e-4, 1.5e-3),
            (0.3, 0.03, 1e-6, 1e-8, 0.0),
            (1e3, 1e2, 1.0, 1e-2, 0.09),
        ] {
            let (dm, dmm) = (-moment / (m * m), 1.0 / m);
            let var = dm * dm * vm + dmm * dmm * vmm + 2.0 * dm * dmm * cov;
            let expected = nalgebra::ComplexField::sqrt(var);
            let got = com_std_m(m, moment, vm, vmm, cov);
            assert!(
                (got - expected).abs() <= 1e-12 * expected,
                "{got} vs {expected}"
            );
        }
        // Perfectly correlated m and M with c = M / m exact: variance 0, or a
        // round-off negative one, gives 0.
        assert_eq!(com_std_m(2.0, 0.2, 1.0, 0.01 * (1.0 - 1e-12), 0.1), 0.0);
        assert!(com_std_m(2.0, 0.2, f64::NAN, 0.01, 0.1).is_nan());
        assert!(com_std_m(2.0, 0.2, 1.0, 0.01, f64::NAN).is_nan());
    }
}
