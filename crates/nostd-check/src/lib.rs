//! A `#![no_std]` static library that uses the per-cycle path of the core crates.
//! It exists only to fail the build if std (or alloc) enters their dependency tree.
#![no_std]

use sar_kinematics::{ActiveJoints, Calibration, Profile, Vec3, forward};

/// One forward kinematics call through a C ABI, so that it is code-generated.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_check(q1_m: f64, q2_m: f64, q3_m: f64) -> f64 {
    let Ok(cal) = Calibration::new(
        Vec3::zeros(),
        Vec3::new(0.0, -0.08, 0.0),
        Vec3::new(0.0, -0.03, 0.0),
        sar_kinematics::Mat3::identity(),
        Vec3::new(0.45, 0.2, 0.0),
        Vec3::new(0.0, -9.80665, 0.0),
    ) else {
        return f64::NAN;
    };
    let Ok(profile) = Profile::new(0.35, 0.0, 2.593, 0.103) else {
        return f64::NAN;
    };
    match forward(&cal, &profile, &ActiveJoints { q1_m, q2_m, q3_m }) {
        Ok(pose) => pose.q5_rad,
        Err(_) => f64::NAN,
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}
