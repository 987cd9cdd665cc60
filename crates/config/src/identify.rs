//! `[identify]`: the limits of `sarctl identify --dynamic`'s excitation
//! (MODEL.md 10, issue 26 section 3), its own and not the operator's move
//! limits: `excitation_max_speed_mps` (0.04; below `[plausibility]
//! max_joint_speed_mps`, whose check faults faster joints),
//! `excitation_max_accel_mps2` (1.0; at most 5) and `excitation_duration_s`
//! (60; 10..=600).

use crate::ConfigError;
use crate::toml_file::Ctx;
use serde::Deserialize;

/// `[identify]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct IdentifyToml {
    excitation_max_speed_mps: f64,
    excitation_max_accel_mps2: f64,
    excitation_duration_s: f64,
}

impl Default for IdentifyToml {
    fn default() -> Self {
        let d = IdentifySettings::default();
        Self {
            excitation_max_speed_mps: d.excitation_max_speed_mps,
            excitation_max_accel_mps2: d.excitation_max_accel_mps2,
            excitation_duration_s: d.excitation_duration_s,
        }
    }
}

/// The excitation's limits (`[identify]`), checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifySettings {
    /// Largest joint speed of the excitation, m/s.
    pub excitation_max_speed_mps: f64,
    /// Largest joint acceleration of the excitation, m/s^2.
    pub excitation_max_accel_mps2: f64,
    /// The excitation's duration, s.
    pub excitation_duration_s: f64,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self {
            excitation_max_speed_mps: 0.04,
            excitation_max_accel_mps2: 1.0,
            excitation_duration_s: 60.0,
        }
    }
}

/// Largest `excitation_max_accel_mps2`, m/s^2 (the simulated servos' and
/// a ball-screw axis's own limit).
const MAX_EXCITATION_ACCEL_MPS2: f64 = 5.0;

/// Checks `[identify]` (each error names its key).
pub(crate) fn identify(
    ctx: &Ctx<'_>,
    t: &IdentifyToml,
    max_joint_speed_mps: f64,
) -> Result<IdentifySettings, ConfigError> {
    let speed = t.excitation_max_speed_mps;
    if !(speed.is_finite() && speed > 0.0 && speed < max_joint_speed_mps) {
        return Err(ctx.err(
            "identify.excitation_max_speed_mps",
            format!(
                "{speed} m/s must be > 0 and below plausibility.max_joint_speed_mps ({max_joint_speed_mps} m/s), whose check faults faster joints"
            ),
        ));
    }
    let accel = t.excitation_max_accel_mps2;
    if !(accel.is_finite() && accel > 0.0 && accel <= MAX_EXCITATION_ACCEL_MPS2) {
        return Err(ctx.err(
            "identify.excitation_max_accel_mps2",
            format!("{accel} m/s^2 must be > 0 and at most {MAX_EXCITATION_ACCEL_MPS2} m/s^2"),
        ));
    }
    let duration = t.excitation_duration_s;
    if !(duration.is_finite() && (10.0..=600.0).contains(&duration)) {
        return Err(ctx.err(
            "identify.excitation_duration_s",
            format!("{duration} s must be within 10..=600 s"),
        ));
    }
    Ok(IdentifySettings {
        excitation_max_speed_mps: speed,
        excitation_max_accel_mps2: accel,
        excitation_duration_s: duration,
    })
}
