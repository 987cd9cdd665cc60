//! Criterion benchmarks of the estimator: the full per-cycle path (the 1 kHz
//! loop's budget), its parts, and the identification update, solve and support fit.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

#[path = "../tests/common/mod.rs"]
mod common;

use common::*;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use sar_estimator::cycle::{CycleInput, Estimator, JointSample, SensorSample};
use sar_estimator::guard::{Guard, GuardConfig, GuardInput, TipInput};
use sar_estimator::identification::{Identification, IdentificationOptions};
use sar_estimator::support::{SupportCalibration, SupportOptions};
use sar_estimator::tip_force::{TipForceConfig, TipForceEstimator};
use sar_estimator::{Profile, SensorNoise};
use sar_kinematics::{ActiveJoints, forward};
use std::hint::black_box;

const Q: [f64; 3] = [0.02, 0.25, 0.31];

fn joints() -> ActiveJoints {
    ActiveJoints {
        q1_m: Q[0],
        q2_m: Q[1],
        q3_m: Q[2],
    }
}

fn per_cycle(c: &mut Criterion) {
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let reading = example_reading(Q, &Vector3::new(1.0, -0.5, 0.5), &bias_n);
    let mut estimator = Estimator::new(&example_estimator_config(), bias_n).unwrap();
    let mut cycle = 0u64;
    c.bench_function("cycle/full (kinematics + tip force + guard)", |b| {
        b.iter(|| {
            cycle += 1;
            let now_ns = 1_000_000 * cycle;
            let input = CycleInput {
                cycle,
                now_ns,
                sensor: SensorSample {
                    force_n: reading,
                    torque_nm: Vector3::zeros(),
                    stamp_ns: now_ns,
                    valid: true,
                },
                joints: JointSample {
                    joints: joints(),
                    stamp_ns: now_ns,
                    valid: true,
                },
            };
            black_box(estimator.cycle(black_box(&input)).guard_state)
        })
    });

    let cal = example_calibration();
    let profile = manipulator2();
    c.bench_function("cycle/part: forward kinematics", |b| {
        b.iter(|| black_box(forward(black_box(&cal), &profile, black_box(&joints()))))
    });
    let pose = forward(&cal, &profile, &joints()).unwrap();
    let tip = TipForceEstimator::new(
        &cal,
        &profile,
        &SensorNoise::hex6(),
        TipForceConfig { max_std_n: 2.0 },
    )
    .unwrap();
    c.bench_function("cycle/part: tip force, d = 0", |b| {
        b.iter(|| black_box(tip.estimate(black_box(&pose), black_box(&reading), &bias_n)))
    });
    let offset_profile = Profile::new(0.35, 0.004, 2.593, 0.103).unwrap();
    let offset_pose = forward(&cal, &offset_profile, &joints()).unwrap();
    let offset_tip = TipForceEstimator::new(
        &cal,
        &offset_profile,
        &SensorNoise::hex6(),
        TipForceConfig { max_std_n: 2.0 },
    )
    .unwrap();
    c.bench_function("cycle/part: tip force, d != 0 (6x6)", |b| {
        b.iter(|| {
            black_box(offset_tip.estimate(black_box(&offset_pose), black_box(&reading), &bias_n))
        })
    });
    let mut guard = Guard::new(GuardConfig::new(test_guard_limits()).unwrap());
    let mut cycle = 0u64;
    c.bench_function("cycle/part: guard step", |b| {
        b.iter(|| {
            cycle += 1;
            black_box(guard.step(black_box(&GuardInput {
                cycle,
                sensor_age_ns: 300_000,
                sensor_valid: true,
                joints_age_ns: 100_000,
                joints_valid: true,
                tip: TipInput::Estimate {
                    force_n: Vector3::new(1.0, -0.5, 0.5),
                    std_n: Vector3::new(0.2, 0.15, 0.6),
                    rod_dir: pose.rod_dir,
                },
            })))
        })
    });
}

fn identification(c: &mut Criterion) {
    let truth = Truth {
        friction_n: 0.3,
        ..manipulator2_truth()
    };
    let cal = example_calibration();
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 11);
    let poses = simulate_static_poses(
        &truth,
        &cal.sensor_rotation(),
        &bias_n,
        &cone_protocol(),
        10,
        &mut sensor,
    );
    let options = IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    };
    let mut ident = Identification::new(&cal, &SensorNoise::hex6(), bias_n, options).unwrap();
    for p in &poses {
        ident.add(p).unwrap();
    }
    let mut growing = ident;
    let mut k = 0usize;
    c.bench_function("identification/update (one pose, 5 unknowns)", |b| {
        b.iter(|| {
            k = (k + 1) % poses.len();
            black_box(growing.add(black_box(&poses[k])))
        })
    });
    c.bench_function("identification/solve (20 poses, 5 unknowns)", |b| {
        b.iter(|| black_box(black_box(&ident).solve()))
    });
    let mut support = SupportCalibration::new(
        &cal.with_support(cal.support_m() + Vector3::new(0.002, -0.002, 0.002))
            .unwrap(),
        &SensorNoise::hex6(),
        bias_n,
        SupportOptions::default(),
    )
    .unwrap();
    for p in &poses {
        support.push(p).unwrap();
    }
    c.bench_function("support/fit (20 poses, B 3.5 mm off)", |b| {
        b.iter(|| black_box(black_box(&support).fit()))
    });
    // The global search's case: the configured B 50 mm off.
    let mut far = SupportCalibration::new(
        &cal.with_support(cal.support_m() + Vector3::new(-0.03, 0.03, 0.0283))
            .unwrap(),
        &SensorNoise::hex6(),
        bias_n,
        SupportOptions::default(),
    )
    .unwrap();
    for p in &poses {
        far.push(p).unwrap();
    }
    assert!(far.fit().is_ok(), "{:?}", far.fit());
    c.bench_function("support/fit (20 poses, B 50 mm off)", |b| {
        b.iter(|| black_box(black_box(&far).fit()))
    });
}

criterion_group!(benches, per_cycle, identification);
criterion_main!(benches);
