//! A `#![no_std]` static library that uses the per-cycle path, the
//! identification and the support calibration of the core crates. It exists
//! only to fail the build if std (or alloc) enters their dependency tree: its
//! own `#[panic_handler]` then collides with std's.
#![no_std]

use sar_estimator::cycle::{CycleInput, Estimator, EstimatorConfig, JointSample, SensorSample};
use sar_estimator::guard::{GuardConfig, GuardLimits};
use sar_estimator::identification::{Identification, IdentificationOptions};
use sar_estimator::support::{SupportCalibration, SupportOptions};
use sar_estimator::{SensorNoise, SlideSign, StaticPose};
use sar_kinematics::{ActiveJoints, Calibration, Mat3, Profile, Vec3};

fn config() -> Option<EstimatorConfig> {
    let calibration = Calibration::new(
        Vec3::zeros(),
        Vec3::new(0.0, -0.08, 0.0),
        Vec3::new(0.0, -0.03, 0.0),
        Mat3::identity(),
        Vec3::new(0.45, 0.2, 0.0),
        Vec3::new(0.0, -9.80665, 0.0),
    )
    .ok()?;
    let guard = GuardConfig::new(GuardLimits {
        warn_total_n: 10.0,
        stop_total_n: 15.0,
        warn_axial_n: 8.0,
        stop_axial_n: 12.0,
        warn_lateral_n: 6.0,
        stop_lateral_n: 10.0,
        hysteresis_n: 1.0,
        debounce_cycles: 3,
        max_sensor_age_ns: 5_000_000,
        max_joints_age_ns: 5_000_000,
        max_std_n: 2.0,
        std_margin: 0.0,
    })
    .ok()?;
    Some(EstimatorConfig {
        calibration,
        profile: Profile::new(0.35, 0.0, 2.593, 0.103).ok()?,
        noise: SensorNoise::hex6(),
        guard,
    })
}

/// One estimator cycle through a C ABI, so that the whole path is code-generated.
/// Returns the guard state as a number, or -1.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_cycle(q1_m: f64, q2_m: f64, q3_m: f64, fx_n: f64, fy_n: f64, fz_n: f64) -> i32 {
    let Some(config) = config() else { return -1 };
    let Ok(mut estimator) = Estimator::new(&config, Vec3::zeros()) else {
        return -1;
    };
    let out = estimator.cycle(&CycleInput {
        cycle: 1,
        now_ns: 1_000,
        sensor: SensorSample {
            force_n: Vec3::new(fx_n, fy_n, fz_n),
            torque_nm: Vec3::zeros(),
            stamp_ns: 1_000,
            valid: true,
        },
        joints: JointSample { joints: ActiveJoints { q1_m, q2_m, q3_m }, stamp_ns: 1_000, valid: true },
    });
    out.guard_state as i32
}

/// One identification and one support fit over a single pose (which is too few:
/// the point is only to compile them without std).
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_identify(ax_m: f64, ay_m: f64, az_m: f64) -> f64 {
    let Some(config) = config() else { return f64::NAN };
    let pose = StaticPose {
        ujoint_m: Vec3::new(ax_m, ay_m, az_m),
        mean_reading_n: Vec3::new(0.0, -20.0, 0.0),
        samples: 10,
        slide_sign: SlideSign::Inserting,
    };
    let options = IdentificationOptions { bias_across_gravity: false, friction: true };
    let Ok(mut ident) = Identification::new(&config.calibration, &config.noise, Vec3::zeros(), options)
    else {
        return f64::NAN;
    };
    let support_options = SupportOptions::default();
    let Ok(mut support) =
        SupportCalibration::new(&config.calibration, &config.noise, Vec3::zeros(), support_options)
    else {
        return f64::NAN;
    };
    if ident.add(&pose).is_err() || support.push(&pose).is_err() {
        return f64::NAN;
    }
    match (ident.solve(), support.fit()) {
        (Ok(a), Ok(b)) => a.mass_kg + b.mass_kg,
        _ => f64::NAN,
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}
