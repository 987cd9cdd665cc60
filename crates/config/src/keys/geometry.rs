//! `[geometry]`: the robot's calibration, through the kinematics' own checks
//! (every value finite, a proper rotation, the gravity's magnitude).

use crate::ConfigError;
use crate::decl::{each, key_of_field, magnitude};
use crate::keys::vec3;
use crate::toml_file::Ctx;
use sar_kinematics::calibration::ORTHONORMAL_TOLERANCE;
use sar_kinematics::{Calibration, CalibrationSpec, Mat3};

crate::section! {
    /// The robot's calibration: points in the base frame {0}, the sensor's frame.
    section "geometry";
    /// g in the base frame, m/s^2
    gravity: [f64; 3] = required([0.0, -9.80665, 0.0]),
        magnitude(9.7, 9.9, "m/s^2") => [CalibrationSpec.gravity_mps2];
    /// B, the support point, base frame, m
    support: [f64; 3] = required([0.45, 0.20, 0.0]),
        each(-2.0, 2.0, "m").also("closer than length_m to the U-joint's travel (axes.travel_m)")
        => [CalibrationSpec.support_m];
    /// P at q = 0, base frame (x, y, z), m
    p_home: [f64; 3] = required([0.0, 0.0, 0.0]),
        each(-2.0, 2.0, "m") => [CalibrationSpec.p_home_m];
    /// a_off = A - P, base frame, m
    ujoint_offset: [f64; 3] = required([0.0, -0.08, 0.0]),
        each(-0.5, 0.5, "m") => [CalibrationSpec.ujoint_offset_m];
    /// s_off = S - P, base frame, m
    sensor_offset: [f64; 3] = required([0.0, -0.03, 0.0]),
        each(-0.5, 0.5, "m") => [CalibrationSpec.sensor_offset_m];
    /// R_0s, row-major: its columns are the sensor's axes in the base frame
    sensor_rotation: [[f64; 3]; 3] = required([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        each(-1.0 - ORTHONORMAL_TOLERANCE, 1.0 + ORTHONORMAL_TOLERANCE, "")
            .also("a proper rotation (orthonormal, det +1)")
        => [CalibrationSpec.sensor_rotation];
}

/// The calibration, through the kinematics' own checks (each error under
/// its key).
pub(crate) fn build(ctx: &Ctx<'_>, g: &Section) -> Result<Calibration, ConfigError> {
    let r = g.sensor_rotation;
    let rotation = Mat3::from_row_slice(&[
        r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
    ]);
    Calibration::new(&CalibrationSpec {
        p_home_m: vec3(g.p_home),
        ujoint_offset_m: vec3(g.ujoint_offset),
        sensor_offset_m: vec3(g.sensor_offset),
        sensor_rotation: rotation,
        support_m: vec3(g.support),
        gravity_mps2: vec3(g.gravity),
    })
    .map_err(|e| {
        let key = key_of_field(&[KEYS], e.field()).map_or(SECTION, |d| d.key);
        ctx.err(key, e.to_string())
    })
}
