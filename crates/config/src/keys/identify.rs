//! `[identify]`: the limits of `sarctl identify --dynamic`'s excitation
//! (MODEL.md 10, issue 26 section 3), its own and not the operator's move
//! limits. Its speed stays below `[plausibility] max_joint_speed_mps`,
//! whose check faults faster joints, and at most `[axes] max_speed_mps`,
//! beyond which the drives refuse a streamed set point (`crate::relations`).
//! The loop judges every excitation against them, fades included
//! (`sar_loop::excite::judge`).

use crate::decl::num;

/// Largest `excitation_max_accel_mps2`, m/s^2 (the simulated servos' and
/// a ball-screw axis's own limit).
const MAX_EXCITATION_ACCEL_MPS2: f64 = 5.0;

/// Largest `excitation_max_jerk_mps3`, m/s^3.
const MAX_EXCITATION_JERK_MPS3: f64 = 1000.0;

crate::section! {
    /// sarctl identify --dynamic: the excitation's own limits (not the move limits).
    section "identify";
    /// largest speed per joint, at most axes.max_speed_mps (the drives' streamed limit)
    excitation_max_speed_mps: f64 = value(IdentifySettings::default().excitation_max_speed_mps),
        num(1e-4, 1.0, "m/s")
            .also("below plausibility.max_joint_speed_mps, at most axes.max_speed_mps")
        => [IdentifySettings.excitation_max_speed_mps];
    /// largest acceleration per joint
    excitation_max_accel_mps2: f64 = value(IdentifySettings::default().excitation_max_accel_mps2),
        num(1e-4, MAX_EXCITATION_ACCEL_MPS2, "m/s^2") => [IdentifySettings.excitation_max_accel_mps2];
    /// largest jerk per joint (the loop judges the faded motion's peaks)
    excitation_max_jerk_mps3: f64 = value(IdentifySettings::default().excitation_max_jerk_mps3),
        num(1e-3, MAX_EXCITATION_JERK_MPS3, "m/s^3") => [IdentifySettings.excitation_max_jerk_mps3];
    /// the excitation's duration, with 3 s fades in and out
    excitation_duration_s: f64 = value(IdentifySettings::default().excitation_duration_s),
        num(10.0, 600.0, "s") => [IdentifySettings.excitation_duration_s];
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
    /// The defaults of `[identify]`.
    fn default() -> Self {
        Self {
            excitation_max_speed_mps: 0.02,
            excitation_max_accel_mps2: 1.0,
            excitation_max_jerk_mps3: 10.0,
            excitation_duration_s: 60.0,
        }
    }
}

/// The excitation's limits.
pub(crate) fn build(t: &Section) -> IdentifySettings {
    IdentifySettings {
        excitation_max_speed_mps: t.excitation_max_speed_mps,
        excitation_max_accel_mps2: t.excitation_max_accel_mps2,
        excitation_max_jerk_mps3: t.excitation_max_jerk_mps3,
        excitation_duration_s: t.excitation_duration_s,
    }
}
