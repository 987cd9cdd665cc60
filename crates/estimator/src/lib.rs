//! The SAR's estimator core: tip force, identification of mass and centre of
//! mass, support calibration and the force-limit guard (MODEL.md 4-6).
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
pub mod guard;
pub mod identification;
pub mod support;
pub mod tip_force;

pub use sar_kinematics::{Calibration, Mat3, Pose, Profile, Vec3};

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
    /// Sign of the last slide of the rod in the support before this pose:
    /// +1 (towards the tip, u), -1, or 0 when unknown/none. The coefficient of
    /// the friction unknown.
    pub slide_sign: f64,
}

/// `Err(error(value))` for the first NaN or infinite `value` among `values`.
#[inline]
pub(crate) fn check_finite<'a, E>(
    values: impl IntoIterator<Item = &'a f64>,
    error: impl FnOnce(f64) -> E,
) -> Result<(), E> {
    // A plain loop: `find` on nalgebra's iterators cost 12 ns on the per-cycle
    // path (tip force, d = 0).
    for &value in values {
        if !value.is_finite() {
            return Err(error(value));
        }
    }
    Ok(())
}
