//! Criterion benchmarks of the estimator: the full per-cycle path (the 1 kHz
//! loop's budget) with d = 0 and with d != 0, a floor (plain f64 code giving the
//! same outputs with no validation, measured in the same run so that the
//! cycle/floor ratio can be read off), the cycle in motion (MODEL.md 10's
//! compensation) beside the one at rest, the cycle's parts (the tip force at
//! rest and in motion), and the identification update, solve and support fit.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

#[path = "../tests/common/mod.rs"]
mod common;

use common::*;
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use sar_estimator::cycle::{
    CycleContext, CycleInput, CycleOutput, Estimator, EstimatorConfig, JointSample, SensorSample,
    TipOutcome,
};
use sar_estimator::guard::{Guard, GuardConfig, GuardInput, GuardLimits, TipInput};
use sar_estimator::identification::{Identification, IdentificationOptions};
use sar_estimator::motion::CarriageMotion;
use sar_estimator::support::{SupportCalibration, SupportOptions};
use sar_estimator::tip_force::{TipForceConfig, TipForceEstimator};
use sar_estimator::{Calibration, Profile, ProfileSpec, SensorNoise};
use sar_kinematics::{ActiveJoints, Pose, forward};
use std::hint::black_box;
use std::time::{Duration, Instant};

const Q: [f64; 3] = [0.02, 0.25, 0.31];

/// The offset d of the d != 0 benchmarks, m.
const OFFSET_M: f64 = 0.004;

fn joints() -> ActiveJoints {
    ActiveJoints {
        q1_m: Q[0],
        q2_m: Q[1],
        q3_m: Q[2],
    }
}

/// Manipulator 2 with the rod's axis `offset_m` from the U-joint centre.
fn manipulator2_offset(offset_m: f64) -> Profile {
    Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m,
        mass_kg: 2.593,
        com_m: 0.103,
    })
    .unwrap()
}

/// The example robot with `profile` at the joints `Q` under `tip_force_n`,
/// from the independent simulator of `common`: the calibration, the pose,
/// and the force F_A (N) and torsion M_T (N m) at the U-joint.
fn ujoint_statics(
    profile: &Profile,
    tip_force_n: &Vector3<f64>,
) -> (Calibration, Pose, Vector3<f64>, f64) {
    let cal = example_calibration();
    let pose = forward(&cal, profile, &joints()).unwrap();
    let truth = Truth {
        offset_m: profile.offset_m(),
        ..manipulator2_truth()
    };
    let (f_a, torsion_nm) = ujoint_force(
        &truth,
        &pose.ujoint_m,
        &pose.rod_dir,
        &pose.rod_normal,
        tip_force_n,
        0.0,
    );
    (cal, pose, f_a, torsion_nm)
}

/// The raw torque reading (R_0s = I, no torque bias) that goes with `reading_for`:
/// (A - S) x (-F_A) - M_T n, with A - S = (0, -0.05, 0) on the example robot.
fn torque_for(profile: &Profile, tip_force_n: &Vector3<f64>) -> Vector3<f64> {
    let (_, pose, f_a, torsion_nm) = ujoint_statics(profile, tip_force_n);
    let n = Vector3::y().cross(&pose.rod_dir.cross(&pose.rod_normal));
    Vector3::new(0.0, -0.05, 0.0).cross(&(-f_a)) - n * torsion_nm
}

/// The raw reading (R_0s = I) of the example robot with `profile` at the
/// joints `Q`, from the independent simulator of `common`.
fn reading_for(
    profile: &Profile,
    tip_force_n: &Vector3<f64>,
    bias_n: &Vector3<f64>,
) -> Vector3<f64> {
    let (cal, _, f_a, _) = ujoint_statics(profile, tip_force_n);
    ideal_reading(&cal.sensor_rotation(), &f_a, bias_n)
}

/// A live sensor's noise: 64 fixed small offsets (a seeded LCG, 0.1 N and
/// 0.005 N m at most), one per cycle in turn, so that no two consecutive
/// samples repeat (a repeating reading is a frozen sensor, and the guard
/// would measure its Fault path) and no step is a spike.
fn noise(cycle: u64) -> (Vector3<f64>, Vector3<f64>) {
    let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ (cycle % 64);
    let mut next = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let f = Vector3::new(next(), next(), next()) * 0.1;
    let t = Vector3::new(next(), next(), next()) * 0.005;
    (f, t)
}

fn cycle_input(cycle: u64, reading: &Vector3<f64>, torque_nm: &Vector3<f64>) -> CycleInput {
    let now_ns = 1_000_000 * cycle;
    let (noise_n, noise_nm) = noise(cycle);
    CycleInput {
        cycle,
        now_ns: Some(now_ns),
        sensor: SensorSample {
            force_n: *reading + noise_n,
            torque_nm: *torque_nm + noise_nm,
            counter: cycle as u32,
            status: 0,
            stamp_ns: now_ns,
            valid: true,
            drained: sar_estimator::cycle::DrainedSamples::default(),
        },
        joints: JointSample {
            joints: joints(),
            stamp_ns: now_ns,
            valid: true,
        },
        command: None,
    }
}

type V = [f64; 3];

fn dot(a: &V, b: &V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The floor: what the cycle computes, as plain f64 code with everything that
/// does not change fixed beforehand, and no validation at all (no finiteness,
/// no unit checks, no degenerate poses, no guard state).
struct Floor {
    /// P_home + a_off.
    ujoint_home: V,
    support: V,
    /// R_0s, rows.
    rotation: [V; 3],
    /// C = R_0s diag(std^2) R_0s^T, rows.
    covariance: [V; 3],
    /// F = R_0s diag(std) (C = F F^T), rows.
    factor: [V; 3],
    weight: V,
    length: f64,
    com: f64,
    offset: f64,
    bias: V,
    /// Stop limits: total, axial, lateral.
    limits: V,
}

/// The floor's outputs: F_tip, its per-axis deviation, and the three limit
/// tests (total, axial, lateral at or above the stop limit).
struct FloorOut {
    force: V,
    std: V,
    above: [bool; 3],
}

impl Floor {
    fn new(config: &EstimatorConfig, limits: &GuardLimits, bias: &Vector3<f64>) -> Self {
        let cal: &Calibration = &config.calibration;
        let a0 = cal.p_home_m() + cal.ujoint_offset_m();
        let r = cal.sensor_rotation();
        let c = config.noise.base_covariance_n2(&r);
        let f = r * nalgebra::Matrix3::from_diagonal(&config.noise.std_n());
        let w = cal.gravity_mps2() * config.profile.mass_kg();
        let row = |m: &nalgebra::Matrix3<f64>, i: usize| [m[(i, 0)], m[(i, 1)], m[(i, 2)]];
        Self {
            ujoint_home: [a0.x, a0.y, a0.z],
            support: [cal.support_m().x, cal.support_m().y, cal.support_m().z],
            rotation: [row(&r, 0), row(&r, 1), row(&r, 2)],
            covariance: [row(&c, 0), row(&c, 1), row(&c, 2)],
            factor: [row(&f, 0), row(&f, 1), row(&f, 2)],
            weight: [w.x, w.y, w.z],
            length: config.profile.length_m(),
            com: config.profile.com_m(),
            offset: config.profile.offset_m(),
            bias: [bias.x, bias.y, bias.z],
            limits: [
                limits.force.stop_total_n,
                limits.force.stop_axial_n,
                limits.force.stop_lateral_n,
            ],
        }
    }

    /// F_A = -R_0s (reading - bias).
    fn ujoint_force(&self, reading: &V) -> V {
        let f = [
            reading[0] - self.bias[0],
            reading[1] - self.bias[1],
            reading[2] - self.bias[2],
        ];
        [
            -dot(&self.rotation[0], &f),
            -dot(&self.rotation[1], &f),
            -dot(&self.rotation[2], &f),
        ]
    }

    /// B - A for the active joints q = (q1, q2, q3) (A = P_home + a_off + (q3, q2, q1)).
    fn support_from_ujoint(&self, q: &V) -> V {
        [
            self.support[0] - self.ujoint_home[0] - q[2],
            self.support[1] - self.ujoint_home[1] - q[1],
            self.support[2] - self.ujoint_home[2] - q[0],
        ]
    }

    fn finish(&self, u: &V, force: V, var: V) -> FloorOut {
        let axial = dot(&force, u);
        let lat = [
            force[0] - axial * u[0],
            force[1] - axial * u[1],
            force[2] - axial * u[2],
        ];
        let total = dot(&force, &force).sqrt();
        let lateral = dot(&lat, &lat).sqrt();
        FloorOut {
            force,
            std: [var[0].sqrt(), var[1].sqrt(), var[2].sqrt()],
            above: [
                total >= self.limits[0],
                axial.abs() >= self.limits[1],
                lateral >= self.limits[2],
            ],
        }
    }

    /// d = 0: u = r / |r|, a = |r|, MODEL.md 4.1.
    fn cycle_d0(&self, q: &V, reading: &V) -> FloorOut {
        let r = self.support_from_ujoint(q);
        let a = dot(&r, &r).sqrt();
        let inv_a = 1.0 / a;
        let u = [r[0] * inv_a, r[1] * inv_a, r[2] * inv_a];
        let fa = self.ujoint_force(reading);
        let g = &self.weight;
        let inv_lever = 1.0 / (self.length - a);
        let k = a * inv_lever;
        let axial = dot(&fa, &u) + dot(g, &u);
        // F_tip = (F_A + m g) . u u - (a F_A + (a - c) m g)_perp / (L - a)
        let m = [
            a * fa[0] + (a - self.com) * g[0],
            a * fa[1] + (a - self.com) * g[1],
            a * fa[2] + (a - self.com) * g[2],
        ];
        let mu = dot(&m, &u);
        let force = [
            u[0] * axial - (m[0] - u[0] * mu) * inv_lever,
            u[1] * axial - (m[1] - u[1] * mu) * inv_lever,
            u[2] * axial - (m[2] - u[2] * mu) * inv_lever,
        ];
        // diag(J C J^T) with J = (1 + k) u u^T - k I
        let c = &self.covariance;
        let cu = [dot(&c[0], &u), dot(&c[1], &u), dot(&c[2], &u)];
        let ucu = dot(&u, &cu);
        let p = 1.0 + k;
        let (k2, kp2, p2ucu) = (k * k, 2.0 * k * p, p * p * ucu);
        let mut var = [0.0; 3];
        for i in 0..3 {
            var[i] = k2 * c[i][i] - kp2 * u[i] * cu[i] + p2ucu * u[i] * u[i];
        }
        self.finish(&u, force, var)
    }

    /// d != 0: u, w from r without trigonometry (MODEL.md 3), then the closed
    /// form of tip_force.rs in its (u, w, v = u x w) components.
    fn cycle_offset(&self, q: &V, reading: &V) -> FloorOut {
        let d = self.offset;
        let r = self.support_from_ujoint(q);
        let rho2 = dot(&r, &r);
        let r_h = (r[0] * r[0] + r[2] * r[2]).sqrt();
        let s = (rho2 - d * d).sqrt();
        let inv_rho2 = 1.0 / rho2;
        let inv_r_h = 1.0 / r_h;
        let (s4, c4) = (r[0] * inv_r_h, r[2] * inv_r_h);
        let c5 = (s * r_h - d * r[1]) * inv_rho2;
        let s5 = (s * r[1] + d * r_h) * inv_rho2;
        let u = [s4 * c5, s5, c4 * c5];
        let w = [s4 * s5, -c5, c4 * s5];
        let v = [c4, 0.0, -s4];
        let fa = self.ujoint_force(reading);
        let g = &self.weight;
        let inv_lever = 1.0 / (self.length - s);
        let (fu, fv, gu) = (dot(&fa, &u), dot(&fa, &v), dot(g, &u));
        // gamma - beta = d u_y / (w_y lever) = -d tan q5 / lever
        let tan5 = s5 / c5;
        let alpha = d * inv_lever;
        let beta = -s * inv_lever;
        let delta = -d * tan5 * inv_lever;
        let sc = (s - self.com) * inv_lever;
        let g_along = gu * (1.0 + sc);
        // J = beta I + p u^T + q v^T; C = F F^T
        let f = &self.factor;
        let a = [
            f[0][0] * u[0] + f[1][0] * u[1] + f[2][0] * u[2],
            f[0][1] * u[0] + f[1][1] * u[1] + f[2][1] * u[2],
            f[0][2] * u[0] + f[1][2] * u[1] + f[2][2] * u[2],
        ];
        let b = [
            f[0][0] * v[0] + f[2][0] * v[2],
            f[0][1] * v[0] + f[2][1] * v[2],
            f[0][2] * v[0] + f[2][2] * v[2],
        ];
        let mut force = [0.0; 3];
        let mut var = [0.0; 3];
        for i in 0..3 {
            let p = (1.0 - beta) * u[i] + alpha * w[i];
            let q = delta * v[i];
            force[i] = beta * fa[i] + p * fu + q * fv + g_along * u[i] - sc * g[i];
            let x = [
                beta * f[i][0] + p * a[0] + q * b[0],
                beta * f[i][1] + p * a[1] + q * b[1],
                beta * f[i][2] + p * a[2] + q * b[2],
            ];
            var[i] = dot(&x, &x);
        }
        self.finish(&u, force, var)
    }
}

/// The floor agrees with the cycle (checked once, before measuring).
fn check_floor(out: &FloorOut, tip: &TipOutcome, limits: &GuardLimits) {
    let TipOutcome::Estimate(e) = tip else {
        panic!("no estimate: {tip:?}");
    };
    for i in 0..3 {
        assert!((out.force[i] - e.force_n[i]).abs() < 1e-9 * (1.0 + e.force_n.norm()));
        assert!((out.std[i] - e.std_n[i]).abs() < 1e-9 * e.std_n.norm());
    }
    let stop = [
        e.force_n.norm() >= limits.force.stop_total_n,
        e.axial_n.abs() >= limits.force.stop_axial_n,
        e.lateral_n >= limits.force.stop_lateral_n,
    ];
    assert_eq!(out.above, stop);
}

/// Registers `f` twice: as plain criterion `cycle/<name>` (the mean of each
/// sample, which includes any time that other processes take the core), and
/// as `cycle-min/<name>`: in each sample, the fastest of its batches of 200
/// calls, per call. On a loaded machine the second is what the code itself
/// costs; on an idle one the two agree.
fn bench_both<O>(c: &mut Criterion, name: &str, mut f: impl FnMut() -> O) {
    c.bench_function(&format!("cycle/{name}"), |b| b.iter(&mut f));
    c.bench_function(&format!("cycle-min/{name}"), |b| {
        b.iter_custom(|iters| {
            const BATCH: u64 = 200;
            let mut best_s = f64::INFINITY;
            let mut done = 0;
            while done < iters {
                let n = BATCH.min(iters - done);
                let start = Instant::now();
                for _ in 0..n {
                    black_box(f());
                }
                best_s = best_s.min(start.elapsed().as_secs_f64() / n as f64);
                done += n;
            }
            Duration::from_secs_f64(best_s * iters as f64)
        })
    });
}

/// Leaves the initial Fault so that the good path is measured: the inputs at
/// rest until the first reset's mean at rest is complete (the mounting
/// check's `rest_samples`), then a reset, which must be accepted. Returns the
/// last cycle number used.
fn start(estimator: &mut Estimator, reading: &Vector3<f64>, torque: &Vector3<f64>) -> u64 {
    let mut cycle = 0u64;
    loop {
        cycle += 1;
        let mut input = cycle_input(cycle, reading, torque);
        input.command = Some(sar_estimator::cycle::Command::Reset);
        let out = estimator.cycle(&input, &CycleContext::AT_REST);
        if out.guard_state == sar_estimator::guard::GuardState::Ok {
            return cycle;
        }
        assert!(cycle < 10_000, "the reset is never accepted: {out:?}");
    }
}

/// Benchmarks `name`: the full cycle of `estimator` on the good path (after
/// [`start`]), one new input of `cycle_input` with `(reading, torque)` per
/// iteration, keeping what `pick` takes of the output. Returns the last
/// cycle number used.
fn bench_good_path<O>(
    c: &mut Criterion,
    name: &str,
    estimator: &mut Estimator,
    (reading, torque): (&Vector3<f64>, &Vector3<f64>),
    pick: impl Fn(&CycleOutput) -> O,
) -> u64 {
    let mut cycle = start(estimator, reading, torque);
    bench_both(c, name, || {
        cycle += 1;
        let input = cycle_input(cycle, reading, torque);
        black_box(pick(
            estimator.cycle(black_box(&input), black_box(&CycleContext::AT_REST)),
        ))
    });
    cycle
}

/// The carriage's motion of the "in motion" benchmarks: a move at about
/// 0.6 m/s^2 with an uncertain acceleration (MODEL.md 10), small enough that
/// the compensated force stays on the good path.
const MOTION: CarriageMotion = CarriageMotion {
    velocity_mps: Vector3::new(0.02, 0.01, -0.01),
    accel_mps2: Vector3::new(0.5, -0.3, 0.2),
    accel_std_mps2: 0.05,
};

/// The cycle's context with the carriage moving at [`MOTION`].
const IN_MOTION: CycleContext = CycleContext {
    motion: MOTION,
    ..CycleContext::AT_REST
};

/// [`bench_good_path`] with the carriage moving ([`MOTION`]): the cycle's
/// tip force compensated for the rod's inertia.
fn bench_good_path_in_motion(
    c: &mut Criterion,
    name: &str,
    estimator: &mut Estimator,
    (reading, torque): (&Vector3<f64>, &Vector3<f64>),
) {
    let mut cycle = start(estimator, reading, torque);
    bench_both(c, name, || {
        cycle += 1;
        let input = cycle_input(cycle, reading, torque);
        let out = estimator.cycle(black_box(&input), black_box(&IN_MOTION));
        black_box(out.guard_state)
    });
    assert_eq!(
        estimator.last().guard_state,
        sar_estimator::guard::GuardState::Ok
    );
}

fn per_cycle(c: &mut Criterion) {
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let tip_n = Vector3::new(1.0, -0.5, 0.5);
    let limits = test_guard_limits();
    for (label, profile) in [
        ("d = 0", manipulator2()),
        ("d != 0", manipulator2_offset(OFFSET_M)),
    ] {
        let reading = reading_for(&profile, &tip_n, &bias_n);
        let torque = torque_for(&profile, &tip_n);
        // The checks that existed before issue 14 (silence, counter, status,
        // joints, torque, observability) without the new ones (frozen,
        // range, spikes, tare age and drift, the first reset's mounting
        // check): the new checks' cost is the difference, in one run.
        let scripted = EstimatorConfig {
            profile,
            plausibility: sar_estimator::cycle::PlausibilityConfig::new(
                sar_estimator::cycle::PlausibilityLimits {
                    frozen: sar_estimator::cycle::FrozenCheck::Off,
                    range: None,
                    spikes: None,
                    mounting: None,
                    tare: sar_estimator::cycle::TareLimits {
                        max_age_ns: None,
                        drift_n_per_s: 0.0,
                        ..sar_estimator::cycle::TareLimits::default()
                    },
                    ..Default::default()
                },
            )
            .unwrap(),
            filter: None,
            ..example_estimator_config()
        };
        let mut estimator = Estimator::new(&scripted, bias_n).unwrap();
        bench_good_path(
            c,
            &format!("full, {label}, scripted checks only (before issue 14)"),
            &mut estimator,
            (&reading, &torque),
            |out| out.guard_state,
        );
        // Every plausibility check on, the torque check included; the filter
        // (not a check: a display and recording output) is measured apart.
        // The tare's age is checked every cycle but falls due only after ten
        // years, and the drift bound is 0 (the same arithmetic): criterion
        // runs hours of simulated time, in which the default 1e-4 N/s adds
        // newtons of margin and takes the guard to Warn and Stop, and the
        // good path is what is measured.
        let all = sar_estimator::cycle::PlausibilityLimits::default();
        let config = EstimatorConfig {
            profile,
            plausibility: sar_estimator::cycle::PlausibilityConfig::new(
                sar_estimator::cycle::PlausibilityLimits {
                    tare: sar_estimator::cycle::TareLimits {
                        max_age_ns: Some(10 * 365 * 86_400 * 1_000_000_000),
                        drift_n_per_s: 0.0,
                        ..sar_estimator::cycle::TareLimits::default()
                    },
                    ..all
                },
            )
            .unwrap(),
            filter: None,
            ..example_estimator_config()
        };
        let mut estimator = Estimator::new(&config, bias_n).unwrap();
        // Leave the initial Fault (no input yet): the good path is measured.
        let cycle = bench_good_path(
            c,
            &format!("full, {label} (kinematics + tip force + guard)"),
            &mut estimator,
            (&reading, &torque),
            |out| out.guard_state,
        );
        // The same, in motion (MODEL.md 10's compensation), in the same run.
        let mut moving = Estimator::new(&config, bias_n).unwrap();
        bench_good_path_in_motion(
            c,
            &format!("full, {label}, in motion (compensated)"),
            &mut moving,
            (&reading, &torque),
        );
        let floor = Floor::new(&config, &limits, &bias_n);
        let reading_v: V = [reading.x, reading.y, reading.z];
        let cycle_fn = if profile.offset_m() == 0.0 {
            Floor::cycle_d0
        } else {
            Floor::cycle_offset
        };
        let out = cycle_fn(&floor, &Q, &reading_v);
        // One sample without the noise, to compare with the floor.
        let mut exact = cycle_input(cycle + 1, &reading, &torque);
        exact.sensor.force_n = reading;
        exact.sensor.torque_nm = torque;
        let full = estimator.cycle(&exact, &CycleContext::AT_REST);
        // Every check passed: the benchmark measures the good path.
        assert_eq!(
            full.guard_state,
            sar_estimator::guard::GuardState::Ok,
            "{full:?}"
        );
        let tip = full.tip;
        check_floor(&out, &tip, &limits);
        bench_both(c, &format!("floor, {label} (plain f64, no checks)"), || {
            let out = cycle_fn(black_box(&floor), black_box(&Q), black_box(&reading_v));
            black_box((out.force, out.std, out.above))
        });
        // The same cycle with the filtered tip force on (a new sample every
        // cycle: the filter steps every time).
        let filtered = EstimatorConfig {
            filter: example_estimator_config().filter,
            ..config
        };
        let mut estimator = Estimator::new(&filtered, bias_n).unwrap();
        bench_good_path(
            c,
            &format!("full + filter, {label}"),
            &mut estimator,
            (&reading, &torque),
            |out| out.filtered,
        );
    }

    let cal = example_calibration();
    for (label, profile) in [
        ("d = 0", manipulator2()),
        ("d != 0", manipulator2_offset(OFFSET_M)),
    ] {
        bench_both(c, &format!("part: forward kinematics, {label}"), || {
            black_box(forward(black_box(&cal), &profile, black_box(&joints())))
        });
        let reading = reading_for(&profile, &tip_n, &bias_n);
        let pose = forward(&cal, &profile, &joints()).unwrap();
        let tip = TipForceEstimator::new(
            &cal,
            &profile,
            &SensorNoise::hex6(),
            TipForceConfig { max_std_n: 2.0 },
        )
        .unwrap();
        bench_both(c, &format!("part: tip force, {label}"), || {
            black_box(tip.estimate(black_box(&pose), black_box(&reading), &bias_n))
        });
        bench_both(c, &format!("part: tip force in motion, {label}"), || {
            black_box(tip.estimate_in_motion(
                black_box(&pose),
                black_box(&reading),
                &bias_n,
                black_box(&MOTION),
            ))
        });
    }
    let pose = forward(&cal, &manipulator2(), &joints()).unwrap();
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
                input_fault: None,
                new_sample: true,
                tip: TipInput::Estimate {
                    force_n: Vector3::new(1.0, -0.5, 0.5),
                    std_n: Vector3::new(0.2, 0.15, 0.6),
                    rod_dir: pose.rod_dir,
                    observable: true,
                    max_std_n: 2.0,
                },
                extra_margin_n: 0.0,
                tare_due: None,
                smoothed_force_n: None,
            })))
        })
    });
}

fn identification(c: &mut Criterion) {
    let (_, cal, bias_n, poses) = cone_identification_inputs(11);
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
