//! Validated calibration of the robot and profile of the manipulator (MODEL.md 2).
//!
//! Both types can only be built through constructors that check every value, so a
//! value of either type in hand is known to be finite and physically meaningful.

use crate::{Mat3, Vec3, check_finite};

/// Why a calibration or profile value was refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// A value is NaN or infinite.
    #[error("{field} is not a finite number ({value})")]
    NonFinite {
        /// Which value.
        field: &'static str,
        /// The offending value (the first non-finite component of a vector or matrix).
        value: f64,
    },
    /// `R_0s` is not orthonormal within [`ORTHONORMAL_TOLERANCE`].
    #[error("sensor_rotation is not orthonormal: |R^T R - I| reaches {deviation:e}")]
    RotationNotOrthonormal {
        /// Largest absolute entry of `R^T R - I`.
        deviation: f64,
    },
    /// `R_0s` is orthonormal but a reflection.
    #[error("sensor_rotation has determinant {det}, not +1 (a reflection)")]
    RotationNotProper {
        /// Its determinant.
        det: f64,
    },
    /// Gravity's magnitude is outside [`GRAVITY_RANGE_MPS2`].
    #[error("gravity has magnitude {magnitude_mps2} m/s^2, outside 0.1..100")]
    GravityOutOfRange {
        /// Its magnitude.
        magnitude_mps2: f64,
    },
    /// The rod length L is not positive.
    #[error("length_m must be > 0, got {length_m} m")]
    NonPositiveLength {
        /// The value given.
        length_m: f64,
    },
    /// The rod offset |d| is not below the rod length.
    #[error("offset_m must satisfy |d| < L, got d = {offset_m} m with L = {length_m} m")]
    OffsetTooLarge {
        /// The offset given.
        offset_m: f64,
        /// The length given.
        length_m: f64,
    },
    /// The mass is negative.
    #[error("mass_kg must be >= 0, got {mass_kg} kg")]
    NegativeMass {
        /// The value given.
        mass_kg: f64,
    },
}

impl ConfigError {
    /// The named field of [`CalibrationSpec`] or [`ProfileSpec`] that is
    /// wrong, as a configuration file names it (`p_home`, `length_m`, ...):
    /// a loader says the key from it, never from the message's text.
    pub fn field(&self) -> &'static str {
        match self {
            Self::NonFinite { field, .. } => field,
            Self::RotationNotOrthonormal { .. } | Self::RotationNotProper { .. } => {
                "sensor_rotation"
            }
            Self::GravityOutOfRange { .. } => "gravity",
            Self::NonPositiveLength { .. } => "length_m",
            Self::OffsetTooLarge { .. } => "offset_m",
            Self::NegativeMass { .. } => "mass_kg",
        }
    }
}

/// Largest accepted entry of `R^T R - I` for the sensor rotation.
pub const ORTHONORMAL_TOLERANCE: f64 = 1e-6;
/// Accepted range of the gravity magnitude, m/s^2.
pub const GRAVITY_RANGE_MPS2: (f64, f64) = (0.1, 100.0);

/// The robot's calibration: where things are, in the base frame {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    p_home_m: Vec3,
    ujoint_offset_m: Vec3,
    sensor_offset_m: Vec3,
    sensor_rotation: Mat3,
    support_m: Vec3,
    gravity_mps2: Vec3,
}

/// The named fields of a [`Calibration`], as a configuration file gives them.
///
/// A plain struct so that every value is named where it is written: a loader
/// cannot swap two vectors without the swap showing. Turned into a checked
/// [`Calibration`] by [`Calibration::new`] (or `TryFrom`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationSpec {
    /// P at q = 0, {0}, m.
    pub p_home_m: Vec3,
    /// a_off = A - P, {0}, m.
    pub ujoint_offset_m: Vec3,
    /// s_off = S - P, {0}, m.
    pub sensor_offset_m: Vec3,
    /// R_0s, whose columns are the sensor's axes in {0}.
    pub sensor_rotation: Mat3,
    /// B, the support point, {0}, m.
    pub support_m: Vec3,
    /// g in {0}, m/s^2.
    pub gravity_mps2: Vec3,
}

impl Calibration {
    /// Checks and builds a calibration from its named fields (see
    /// [`CalibrationSpec`]): every value finite, R_0s a proper rotation within
    /// [`ORTHONORMAL_TOLERANCE`], |g| within [`GRAVITY_RANGE_MPS2`].
    pub fn new(spec: &CalibrationSpec) -> Result<Self, ConfigError> {
        let CalibrationSpec {
            p_home_m,
            ujoint_offset_m,
            sensor_offset_m,
            sensor_rotation,
            support_m,
            gravity_mps2,
        } = *spec;
        for (field, v) in [
            ("p_home", &p_home_m),
            ("ujoint_offset", &ujoint_offset_m),
            ("sensor_offset", &sensor_offset_m),
            ("support", &support_m),
            ("gravity", &gravity_mps2),
        ] {
            check_finite(v, |value| ConfigError::NonFinite { field, value })?;
        }
        check_finite(&sensor_rotation, |value| ConfigError::NonFinite {
            field: "sensor_rotation",
            value,
        })?;
        let deviation = (sensor_rotation.transpose() * sensor_rotation - Mat3::identity()).amax();
        if deviation > ORTHONORMAL_TOLERANCE {
            return Err(ConfigError::RotationNotOrthonormal { deviation });
        }
        let det = sensor_rotation.determinant();
        if det <= 0.0 {
            return Err(ConfigError::RotationNotProper { det });
        }
        let magnitude_mps2 = gravity_mps2.norm();
        if !(GRAVITY_RANGE_MPS2.0..=GRAVITY_RANGE_MPS2.1).contains(&magnitude_mps2) {
            return Err(ConfigError::GravityOutOfRange { magnitude_mps2 });
        }
        Ok(Self {
            p_home_m,
            ujoint_offset_m,
            sensor_offset_m,
            sensor_rotation,
            support_m,
            gravity_mps2,
        })
    }

    /// The named fields this calibration was built from.
    pub fn spec(&self) -> CalibrationSpec {
        CalibrationSpec {
            p_home_m: self.p_home_m,
            ujoint_offset_m: self.ujoint_offset_m,
            sensor_offset_m: self.sensor_offset_m,
            sensor_rotation: self.sensor_rotation,
            support_m: self.support_m,
            gravity_mps2: self.gravity_mps2,
        }
    }

    /// The same calibration with another support point B (used by support
    /// calibration, which estimates B).
    pub fn with_support(&self, support_m: Vec3) -> Result<Self, ConfigError> {
        check_finite(&support_m, |value| ConfigError::NonFinite {
            field: "support",
            value,
        })?;
        Ok(Self { support_m, ..*self })
    }

    /// P at q = 0, {0}, m.
    pub fn p_home_m(&self) -> Vec3 {
        self.p_home_m
    }
    /// a_off = A - P, {0}, m.
    pub fn ujoint_offset_m(&self) -> Vec3 {
        self.ujoint_offset_m
    }
    /// s_off = S - P, {0}, m.
    pub fn sensor_offset_m(&self) -> Vec3 {
        self.sensor_offset_m
    }
    /// R_0s: maps sensor coordinates to base coordinates.
    pub fn sensor_rotation(&self) -> Mat3 {
        self.sensor_rotation
    }
    /// B, the support point, {0}, m.
    pub fn support_m(&self) -> Vec3 {
        self.support_m
    }
    /// g, {0}, m/s^2.
    pub fn gravity_mps2(&self) -> Vec3 {
        self.gravity_mps2
    }
}

/// The manipulator in use: a straight rod hanging in the U-joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    length_m: f64,
    offset_m: f64,
    mass_kg: f64,
    com_m: f64,
}

/// The named fields of a [`Profile`], as a configuration file gives them.
/// Turned into a checked [`Profile`] by [`Profile::new`] (or `TryFrom`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileSpec {
    /// L > 0: A to the tip along the rod, m.
    pub length_m: f64,
    /// d, |d| < L: the rod axis from A along w, m.
    pub offset_m: f64,
    /// m >= 0, kg.
    pub mass_kg: f64,
    /// c: A to the centre of mass along the rod (any finite value), m.
    pub com_m: f64,
}

impl Profile {
    /// Checks and builds a profile from its named fields (see [`ProfileSpec`]):
    /// `length_m` L > 0, `offset_m` d with |d| < L, `mass_kg` m >= 0, `com_m` c
    /// finite.
    pub fn new(spec: &ProfileSpec) -> Result<Self, ConfigError> {
        let ProfileSpec {
            length_m,
            offset_m,
            mass_kg,
            com_m,
        } = *spec;
        for (field, x) in [
            ("length_m", length_m),
            ("offset_m", offset_m),
            ("mass_kg", mass_kg),
            ("com_m", com_m),
        ] {
            check_finite(&[x], |value| ConfigError::NonFinite { field, value })?;
        }
        if length_m <= 0.0 {
            return Err(ConfigError::NonPositiveLength { length_m });
        }
        if offset_m.abs() >= length_m {
            return Err(ConfigError::OffsetTooLarge { offset_m, length_m });
        }
        if mass_kg < 0.0 {
            return Err(ConfigError::NegativeMass { mass_kg });
        }
        Ok(Self {
            length_m,
            offset_m,
            mass_kg,
            com_m,
        })
    }

    /// The named fields this profile was built from.
    pub fn spec(&self) -> ProfileSpec {
        ProfileSpec {
            length_m: self.length_m,
            offset_m: self.offset_m,
            mass_kg: self.mass_kg,
            com_m: self.com_m,
        }
    }

    /// L, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }
    /// d, m.
    pub fn offset_m(&self) -> f64 {
        self.offset_m
    }
    /// m, kg.
    pub fn mass_kg(&self) -> f64 {
        self.mass_kg
    }
    /// c, m.
    pub fn com_m(&self) -> f64 {
        self.com_m
    }
}

// The snapshot's configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(Calibration {
    p_home_m,
    ujoint_offset_m,
    sensor_offset_m,
    sensor_rotation,
    support_m,
    gravity_mps2,
});
sar_snapshot::config_struct!(Profile {
    length_m,
    offset_m,
    mass_kg,
    com_m,
});
