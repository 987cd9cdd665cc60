//! A `#![no_std]` static library that uses the per-cycle path, the
//! identification, the support calibration and the snapshots of the core
//! crates. It exists only to fail the build if std (or alloc) enters their dependency tree: its
//! own `#[panic_handler]` then collides with std's.
#![no_std]

use sar_estimator::cycle::{
    Command, CycleContext, CycleInput, Estimator, EstimatorConfig, JointSample, PlausibilityConfig, SensorSample,
};
use sar_estimator::filter::{FilterConfig, TipFilter};
use sar_estimator::guard::{GuardConfig, GuardLimits};
use sar_estimator::identification::{Identification, IdentificationOptions};
use sar_estimator::inertial::RodInertia;
use sar_estimator::motion::CarriageMotion;
use sar_estimator::support::{SupportCalibration, SupportOptions};
use sar_estimator::tip_force::TipForceConfig;
use sar_estimator::{SensorNoise, SlideSign, StaticPose};
use sar_kinematics::{
    ActiveJoints, Calibration, CalibrationSpec, Mat3, Profile, ProfileSpec, Vec3,
};

fn config() -> Option<EstimatorConfig> {
    let calibration = Calibration::new(&CalibrationSpec {
        p_home_m: Vec3::zeros(),
        ujoint_offset_m: Vec3::new(0.0, -0.08, 0.0),
        sensor_offset_m: Vec3::new(0.0, -0.03, 0.0),
        sensor_rotation: Mat3::identity(),
        support_m: Vec3::new(0.45, 0.2, 0.0),
        gravity_mps2: Vec3::new(0.0, -9.80665, 0.0),
    })
    .ok()?;
    let guard = GuardConfig::new(GuardLimits::EXAMPLE).ok()?;
    let profile = Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m: 0.0,
        mass_kg: 2.593,
        com_m: 0.103,
    })
    .ok()?;
    Some(EstimatorConfig {
        calibration,
        profile,
        noise: SensorNoise::hex6(),
        tip: TipForceConfig::default(),
        guard,
        plausibility: PlausibilityConfig::default(),
        filter: Some(FilterConfig {
            cutoff_hz: 5.0,
            sample_period_s: 0.002,
        }),
        inertia: RodInertia::slender_rod(&profile),
    })
}

/// The first cycle of `estimator` at `joints` with the reading `force_n`
/// (and the torque the model predicts: (A - S) x f with A - S = (0, -0.05,
/// 0)), a reset requested: the guard state as a number.
fn reset_cycle(estimator: &mut Estimator, joints: ActiveJoints, force_n: Vec3) -> i32 {
    let input = CycleInput {
        cycle: 1,
        now_ns: Some(1_000),
        sensor: SensorSample {
            force_n,
            torque_nm: Vec3::new(0.0, -0.05, 0.0).cross(&force_n),
            counter: 1,
            status: 0,
            stamp_ns: 1_000,
            valid: true,
            drained: sar_estimator::cycle::DrainedSamples::default(),
        },
        joints: JointSample {
            joints,
            stamp_ns: 1_000,
            valid: true,
        },
        command: Some(Command::Reset),
    };
    let out = estimator.cycle(&input, &CycleContext::AT_REST);
    out.guard_state as i32
}

/// One estimator cycle through a C ABI, so that the whole path is code-generated.
/// Returns the guard state as a number, or -1.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_cycle(
    q1_m: f64,
    q2_m: f64,
    q3_m: f64,
    fx_n: f64,
    fy_n: f64,
    fz_n: f64,
) -> i32 {
    let Some(config) = config() else { return -1 };
    let Ok(mut estimator) = Estimator::new(&config, Vec3::zeros()) else {
        return -1;
    };
    reset_cycle(
        &mut estimator,
        ActiveJoints { q1_m, q2_m, q3_m },
        Vec3::new(fx_n, fy_n, fz_n),
    )
}

/// One identification and one support fit over a single pose (which is too few:
/// the point is only to compile them without std).
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_identify(ax_m: f64, ay_m: f64, az_m: f64) -> f64 {
    let Some(config) = config() else {
        return f64::NAN;
    };
    let pose = StaticPose {
        ujoint_m: Vec3::new(ax_m, ay_m, az_m),
        mean_reading_n: Vec3::new(0.0, -20.0, 0.0),
        samples: 10,
        slide_sign: SlideSign::Inserting,
    };
    let options = IdentificationOptions {
        bias_across_gravity: false,
        friction: true,
    };
    let Ok(mut ident) =
        Identification::new(&config.calibration, &config.noise, Vec3::zeros(), options)
    else {
        return f64::NAN;
    };
    let support_options = SupportOptions::default();
    let Ok(mut support) = SupportCalibration::new(
        &config.calibration,
        &config.noise,
        Vec3::zeros(),
        support_options,
    ) else {
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

/// The tip-force filter through a C ABI: steps a 5 Hz filter (500 Hz samples)
/// `n` times with the same force and returns its x component, or NaN.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_filter(fx_n: f64, std_n: f64, n: u32) -> f64 {
    let Ok(mut filter) = TipFilter::new(FilterConfig {
        cutoff_hz: 5.0,
        sample_period_s: 0.002,
    }) else {
        return f64::NAN;
    };
    let mut out = f64::NAN;
    for _ in 0..n {
        match filter.update(&Vec3::new(fx_n, 0.0, 0.0), &Vec3::repeat(std_n)) {
            Ok(f) => out = f.force_n.x,
            Err(_) => return f64::NAN,
        }
    }
    out
}

/// One estimator cycle with the rod's axis `offset_m` from the U-joint centre
/// (d != 0: the closed form of MODEL.md 4.3). Returns the guard state as a
/// number, or -1.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_cycle_offset(
    offset_m: f64,
    q1_m: f64,
    q2_m: f64,
    q3_m: f64,
    fx_n: f64,
    fy_n: f64,
    fz_n: f64,
) -> i32 {
    let Some(mut config) = config() else {
        return -1;
    };
    let Ok(profile) = Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m,
        mass_kg: 2.593,
        com_m: 0.103,
    }) else {
        return -1;
    };
    config.profile = profile;
    let Ok(mut estimator) = Estimator::new(&config, Vec3::zeros()) else {
        return -1;
    };
    reset_cycle(
        &mut estimator,
        ActiveJoints { q1_m, q2_m, q3_m },
        Vec3::new(fx_n, fy_n, fz_n),
    )
}

/// One estimator cycle while the carriage accelerates at (`ax_mps2`, 0, 0)
/// with the rod's axis `offset_m` from the U-joint centre, an axial inertia
/// and an adapter (MODEL.md 10: the compensation's general path, or the
/// slender rod's with everything 0). Returns the guard state as a number, or -1.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_cycle_in_motion(
    offset_m: f64,
    inertia_axial_kgm2: f64,
    ax_mps2: f64,
    q1_m: f64,
    q2_m: f64,
    q3_m: f64,
) -> i32 {
    let Some(mut config) = config() else {
        return -1;
    };
    let Ok(profile) = Profile::new(&ProfileSpec {
        offset_m,
        ..config.profile.spec()
    }) else {
        return -1;
    };
    config.profile = profile;
    config.inertia = RodInertia {
        inertia_axial_kgm2,
        adapter_mass_kg: 0.1,
        ..RodInertia::slender_rod(&profile)
    };
    let Ok(mut estimator) = Estimator::new(&config, Vec3::zeros()) else {
        return -1;
    };
    let context = CycleContext {
        motion: CarriageMotion {
            velocity_mps: Vec3::new(0.01, 0.0, 0.0),
            accel_mps2: Vec3::new(ax_mps2, 0.0, 0.0),
            accel_std_mps2: 0.05,
        },
        ..CycleContext::AT_REST
    };
    let out = estimator.cycle(
        &CycleInput {
            cycle: 1,
            now_ns: Some(1_000),
            sensor: SensorSample {
                force_n: Vec3::new(0.0, 20.0, 0.0),
                torque_nm: Vec3::zeros(),
                counter: 1,
                status: 0,
                stamp_ns: 1_000,
                valid: true,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: JointSample {
                joints: ActiveJoints { q1_m, q2_m, q3_m },
                stamp_ns: 1_000,
                valid: true,
            },
            command: None,
        },
        &context,
    );
    out.guard_state as i32
}

/// A snapshot of the estimator's decision state, taken and restored
/// (issue 17): its length in bytes, or -1.
#[unsafe(no_mangle)]
pub extern "C" fn sar_nostd_snapshot(fx_n: f64) -> i32 {
    let Some(config) = config() else { return -1 };
    let Ok(mut estimator) = Estimator::new(&config, Vec3::new(fx_n, 0.0, 0.0)) else {
        return -1;
    };
    let mut snap = sar_snapshot::Snapshot::new();
    if sar_snapshot::take(&estimator, 1, &mut snap).is_err() {
        return -1;
    }
    let bytes = snap.as_bytes();
    match sar_snapshot::restore(&mut estimator, 1, bytes) {
        Ok(()) => i32::try_from(bytes.len()).unwrap_or(-1),
        Err(_) => -1,
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}
