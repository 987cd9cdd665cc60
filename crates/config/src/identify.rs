//! `[identify]`: the limits of `sarctl identify --dynamic`'s excitation
//! (MODEL.md 10, issue 26 section 3), its own and not the operator's move
//! limits: `excitation_max_speed_mps` (0.02; at most `[axes]
//! max_speed_mps`, beyond which the drives refuse a streamed set point, and
//! below `[plausibility] max_joint_speed_mps`, whose check faults faster
//! joints), `excitation_max_accel_mps2` (1.0; at most 5),
//! `excitation_max_jerk_mps3` (10; at most 1000) and
//! `excitation_duration_s` (60; 10..=600). The loop judges every
//! excitation against them, fades included (`sar_loop::excite::judge`).

use crate::ConfigError;
use crate::toml_file::Ctx;
use serde::Deserialize;

/// `[identify]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct IdentifyToml {
    excitation_max_speed_mps: f64,
    excitation_max_accel_mps2: f64,
    excitation_max_jerk_mps3: f64,
    excitation_duration_s: f64,
}

impl Default for IdentifyToml {
    fn default() -> Self {
        let d = IdentifySettings::default();
        Self {
            excitation_max_speed_mps: d.excitation_max_speed_mps,
            excitation_max_accel_mps2: d.excitation_max_accel_mps2,
            excitation_max_jerk_mps3: d.excitation_max_jerk_mps3,
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
    /// Largest joint jerk of the excitation, m/s^3.
    pub excitation_max_jerk_mps3: f64,
    /// The excitation's duration, s.
    pub excitation_duration_s: f64,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self {
            excitation_max_speed_mps: 0.02,
            excitation_max_accel_mps2: 1.0,
            excitation_max_jerk_mps3: 10.0,
            excitation_duration_s: 60.0,
        }
    }
}

/// Largest `excitation_max_accel_mps2`, m/s^2 (the simulated servos' and
/// a ball-screw axis's own limit).
const MAX_EXCITATION_ACCEL_MPS2: f64 = 5.0;

/// Largest `excitation_max_jerk_mps3`, m/s^3.
const MAX_EXCITATION_JERK_MPS3: f64 = 1000.0;

/// Checks `[identify]` (each error names its key) against the speeds of
/// `[plausibility]` and `[axes]`.
pub(crate) fn identify(
    ctx: &Ctx<'_>,
    t: &IdentifyToml,
    max_joint_speed_mps: f64,
    axes_max_speed_mps: f64,
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
    if speed > axes_max_speed_mps {
        return Err(ctx.err(
            "identify.excitation_max_speed_mps",
            format!(
                "{speed} m/s is above axes.max_speed_mps ({axes_max_speed_mps} m/s): the drives refuse a streamed set point faster than that, so `sarctl identify --dynamic --live` would be refused; lower it or raise axes.max_speed_mps"
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
    let jerk = t.excitation_max_jerk_mps3;
    if !(jerk.is_finite() && jerk > 0.0 && jerk <= MAX_EXCITATION_JERK_MPS3) {
        return Err(ctx.err(
            "identify.excitation_max_jerk_mps3",
            format!("{jerk} m/s^3 must be > 0 and at most {MAX_EXCITATION_JERK_MPS3} m/s^3"),
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
        excitation_max_jerk_mps3: jerk,
        excitation_duration_s: duration,
    })
}
