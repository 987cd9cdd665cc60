//! `[robot]` and `[manipulator]`: the true geometry and manipulator, checked
//! by the kinematics' own constructors (whose errors are mapped to the key).

use super::raw::{ManipulatorToml, RobotToml};
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_hal::Vec3;
use sar_kinematics::{
    Calibration, CalibrationSpec, ConfigError as KinematicsError, Mat3, Profile, ProfileSpec,
};

/// `[robot]` as the true calibration.
pub(super) fn calibration(ctx: &Ctx<'_>, r: &RobotToml) -> Result<Calibration, ConfigError> {
    let [r0, r1, r2] = r.sensor_rotation;
    let [[m00, m01, m02], [m10, m11, m12], [m20, m21, m22]] = [r0, r1, r2];
    let rotation = Mat3::new(m00, m01, m02, m10, m11, m12, m20, m21, m22);
    Calibration::new(&CalibrationSpec {
        p_home_m: Vec3::from(r.p_home),
        ujoint_offset_m: Vec3::from(r.ujoint_offset),
        sensor_offset_m: Vec3::from(r.sensor_offset),
        sensor_rotation: rotation,
        support_m: Vec3::from(r.support),
        gravity_mps2: Vec3::from(r.gravity),
    })
    .map_err(|e| ctx.err(&calibration_error_key(&e), e.to_string()))
}

/// `[manipulator]` as the true profile (its optional name must not be blank).
pub(super) fn profile(ctx: &Ctx<'_>, m: &ManipulatorToml) -> Result<Profile, ConfigError> {
    let profile = Profile::new(&ProfileSpec {
        length_m: m.length_m,
        offset_m: m.offset_m,
        mass_kg: m.mass_kg,
        com_m: m.com_m,
    })
    .map_err(|e| ctx.err(&profile_error_key(&e), e.to_string()))?;
    if m.name.as_deref().is_some_and(|n| n.trim().is_empty()) {
        return Err(ctx.err("manipulator.name", "must not be empty when given"));
    }
    Ok(profile)
}

fn calibration_error_key(e: &KinematicsError) -> String {
    match e {
        KinematicsError::NonFinite { field, .. } => format!("robot.{field}"),
        KinematicsError::RotationNotOrthonormal { .. }
        | KinematicsError::RotationNotProper { .. } => "robot.sensor_rotation".to_owned(),
        KinematicsError::GravityOutOfRange { .. } => "robot.gravity".to_owned(),
        _ => "robot".to_owned(),
    }
}

fn profile_error_key(e: &KinematicsError) -> String {
    match e {
        KinematicsError::NonFinite { field, .. } => format!("manipulator.{field}"),
        KinematicsError::NonPositiveLength { .. } => "manipulator.length_m".to_owned(),
        KinematicsError::OffsetTooLarge { .. } => "manipulator.offset_m".to_owned(),
        KinematicsError::NegativeMass { .. } => "manipulator.mass_kg".to_owned(),
        _ => "manipulator".to_owned(),
    }
}
