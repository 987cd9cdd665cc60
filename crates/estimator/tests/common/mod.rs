//! Test support: an independent simulator of the rod's statics and of the sensor.
//!
//! It solves the six equilibrium equations of MODEL.md 4 with a generic dense
//! least-squares solve (nalgebra dynamic matrices), so it shares no code with the
//! estimator's closed forms: each checks the other.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sar_estimator::StaticPose;

/// The true manipulator and support, as the simulator knows them.
#[derive(Debug, Clone, Copy)]
pub struct Truth {
    pub mass_kg: f64,
    pub com_m: f64,
    pub length_m: f64,
    pub offset_m: f64,
    pub support_m: Vector3<f64>,
    pub gravity_mps2: Vector3<f64>,
    /// Coulomb friction magnitude at the support, N (>= 0).
    pub friction_n: f64,
}

/// The article's Table 2 manipulators: (true m kg, true c m).
pub const TABLE2: [(f64, f64); 4] = [
    (1.611, 0.115),
    (2.593, 0.103),
    (3.198, 0.125),
    (4.159, 0.1456),
];

/// Gravity of MODEL.md 2.
pub fn gravity() -> Vector3<f64> {
    Vector3::new(0.0, -9.80665, 0.0)
}

/// u and w from q4, q5 (written here again on purpose, from MODEL.md 3).
pub fn rod_frame(q4: f64, q5: f64) -> (Vector3<f64>, Vector3<f64>) {
    let u = Vector3::new(q4.sin() * q5.cos(), q5.sin(), q4.cos() * q5.cos());
    let w = Vector3::new(q4.sin() * q5.sin(), -q5.cos(), q4.cos() * q5.sin());
    (u, w)
}

/// Any unit basis (e1, e2) across u.
pub fn basis_across(u: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if u.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = u.cross(&helper).normalize();
    let e2 = u.cross(&e1);
    (e1, e2)
}

/// What the robot applies to the rod at A (F_A, {0}, N) and the U-joint torsion
/// M_T (N m, along n = -(s4, 0, c4)), for a rod with U-joint centre `a_m`,
/// direction `u`, normal `w`, with the tip applying `tip_force_n` to the tissue
/// (F_D = -tip_force_n) and the support's friction acting on the rod as
/// `-slide_sign * friction_n * u`.
///
/// Unknowns: F_A (3), the support's reaction across u (2), M_T (1). Equations:
/// force balance (3) and moments about A (3).
pub fn ujoint_force(
    truth: &Truth,
    a_m: &Vector3<f64>,
    u: &Vector3<f64>,
    w: &Vector3<f64>,
    tip_force_n: &Vector3<f64>,
    slide_sign: f64,
) -> (Vector3<f64>, f64) {
    let d = truth.offset_m;
    let r_b = truth.support_m - a_m;
    // B on the rod axis: r_b = d w + s u.
    let s = r_b.dot(u);
    assert!(
        (r_b - (w * d + u * s)).norm() < 1e-9,
        "support not on the rod axis"
    );
    let r_c = w * d + u * truth.com_m;
    let r_d = w * d + u * truth.length_m;
    let (e1, e2) = basis_across(u);
    // n = -(s4, 0, c4) = Y0 x (u x w), right also when c5 < 0 (MODEL.md 4).
    let n = Vector3::y().cross(&u.cross(w));
    let weight = truth.gravity_mps2 * truth.mass_kg;
    let f_d = -tip_force_n;
    let friction = -u * (slide_sign * truth.friction_n);
    let mut k = DMatrix::<f64>::zeros(6, 6);
    let mut rhs = DVector::<f64>::zeros(6);
    // Force: F_A + b1 e1 + b2 e2 = -(m g + F_D + friction).
    let known_force = weight + f_d + friction;
    // Moment about A: b1 (r_b x e1) + b2 (r_b x e2) + M_T n = -(r_c x mg + r_d x F_D + r_b x friction).
    let known_moment = r_c.cross(&weight) + r_d.cross(&f_d) + r_b.cross(&friction);
    let (m1, m2) = (r_b.cross(&e1), r_b.cross(&e2));
    for i in 0..3 {
        k[(i, i)] = 1.0;
        k[(i, 3)] = e1[i];
        k[(i, 4)] = e2[i];
        rhs[i] = -known_force[i];
        k[(3 + i, 3)] = m1[i];
        k[(3 + i, 4)] = m2[i];
        k[(3 + i, 5)] = n[i];
        rhs[3 + i] = -known_moment[i];
    }
    let x = k
        .lu()
        .solve(&rhs)
        .expect("the equilibrium system is singular");
    (Vector3::new(x[0], x[1], x[2]), x[5])
}

/// The raw sensor reading (sensor frame, N) without noise: f_s = R^T (-F_A) + b.
pub fn ideal_reading(
    rotation: &Matrix3<f64>,
    f_a: &Vector3<f64>,
    bias_n: &Vector3<f64>,
) -> Vector3<f64> {
    rotation.transpose() * (-f_a) + bias_n
}

/// Seeded sensor noise of MODEL.md 7: independent normal noise per sensor axis.
pub struct NoisySensor {
    rng: ChaCha8Rng,
    normals: [Normal<f64>; 3],
}

impl NoisySensor {
    pub fn new(std_n: [f64; 3], seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            normals: std_n.map(|s| Normal::new(0.0, s).unwrap()),
        }
    }

    /// One noisy sample of `ideal`.
    pub fn sample(&mut self, ideal: &Vector3<f64>) -> Vector3<f64> {
        let mut v = *ideal;
        for i in 0..3 {
            v[i] += self.normals[i].sample(&mut self.rng);
        }
        v
    }

    /// The mean of `samples` noisy samples of `ideal`.
    pub fn mean(&mut self, ideal: &Vector3<f64>, samples: u32) -> Vector3<f64> {
        let mut sum = Vector3::zeros();
        for _ in 0..samples {
            sum += self.sample(ideal);
        }
        sum / f64::from(samples)
    }
}

/// One pose of a protocol: the rod direction and the distance a = |AB| (d = 0),
/// and the sign of the last slide (+1: the rod slid along u, -1: against).
#[derive(Debug, Clone, Copy)]
pub struct ProtocolPose {
    pub rod_dir: Vector3<f64>,
    pub support_distance_m: f64,
    pub slide_sign: f64,
}

/// The estimator's slide sign for the physics' sigma (+1 inserting, -1
/// retracting); any other value is a bug in the test.
#[allow(clippy::panic)]
pub fn slide_sign(sigma: f64) -> sar_estimator::SlideSign {
    match sigma {
        1.0 => sar_estimator::SlideSign::Inserting,
        -1.0 => sar_estimator::SlideSign::Retracting,
        other => panic!("sigma {other} is not +1 or -1"),
    }
}

/// The physics' sigma of a known slide sign.
#[allow(clippy::expect_used, dead_code)]
pub fn sigma(sign: sar_estimator::SlideSign) -> f64 {
    sign.sigma().expect("a known slide sign")
}

/// The distances of the identification protocols (MODEL.md 5.1).
pub const PROTOCOL_DISTANCES_M: [f64; 5] = [0.04, 0.07, 0.12, 0.20, 0.30];

/// The article's protocol (Sec. 5.2): rod horizontal along +X0 at the support's
/// height, a swept outward (the rod slides against u) and back inward (along u).
pub fn article_protocol() -> Vec<ProtocolPose> {
    let mut poses = Vec::new();
    for &a in PROTOCOL_DISTANCES_M.iter() {
        poses.push(ProtocolPose {
            rod_dir: Vector3::x(),
            support_distance_m: a,
            slide_sign: -1.0,
        });
    }
    for &a in PROTOCOL_DISTANCES_M.iter().rev() {
        poses.push(ProtocolPose {
            rod_dir: Vector3::x(),
            support_distance_m: a,
            slide_sign: 1.0,
        });
    }
    poses
}

/// The richer protocol of MODEL.md 5.1: four rod directions on a 35 degree cone
/// around X0, a in PROTOCOL_DISTANCES_M, sweeping alternately outward and inward.
pub fn cone_protocol() -> Vec<ProtocolPose> {
    let half_angle = 35f64.to_radians();
    let mut poses = Vec::new();
    for k in 0..4 {
        let phi = f64::from(k) * core::f64::consts::FRAC_PI_2;
        let u = Vector3::new(
            half_angle.cos(),
            half_angle.sin() * phi.cos(),
            half_angle.sin() * phi.sin(),
        );
        let outward = k % 2 == 0;
        let order: Vec<f64> = if outward {
            PROTOCOL_DISTANCES_M.to_vec()
        } else {
            PROTOCOL_DISTANCES_M.iter().rev().copied().collect()
        };
        for a in order {
            poses.push(ProtocolPose {
                rod_dir: u,
                support_distance_m: a,
                slide_sign: if outward { -1.0 } else { 1.0 },
            });
        }
    }
    poses
}

/// Simulates a protocol with nothing at the tip (d = 0): the averaged sensor
/// readings that the estimator's identification takes.
pub fn simulate_static_poses(
    truth: &Truth,
    rotation: &Matrix3<f64>,
    bias_n: &Vector3<f64>,
    protocol: &[ProtocolPose],
    samples: u32,
    sensor: &mut NoisySensor,
) -> Vec<StaticPose> {
    assert_eq!(truth.offset_m, 0.0, "the protocols are for d = 0");
    protocol
        .iter()
        .map(|p| {
            let (a_m, f_a) = pose_at_rest(truth, p, |_, _| {
                truth.support_m - p.rod_dir * p.support_distance_m
            });
            let ideal = ideal_reading(rotation, &f_a, bias_n);
            static_pose(p, a_m, sensor.mean(&ideal, samples), samples)
        })
        .collect()
}

/// The protocol pose `p` at rest (no tip force): its U-joint centre A (m),
/// placed by `ujoint` from the rod's frame (u, w) (MODEL.md 3), and the force
/// F_A (N) there from the statics.
pub fn pose_at_rest(
    truth: &Truth,
    p: &ProtocolPose,
    ujoint: impl FnOnce(&Vector3<f64>, &Vector3<f64>) -> Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let q4 = p.rod_dir.x.atan2(p.rod_dir.z);
    let q5 = p.rod_dir.y.asin();
    let (u, w) = rod_frame(q4, q5);
    let a_m = ujoint(&u, &w);
    let (f_a, _) = ujoint_force(truth, &a_m, &u, &w, &Vector3::zeros(), p.slide_sign);
    (a_m, f_a)
}

/// The static pose of the protocol pose `p` with the U-joint at `ujoint_m`
/// and the mean reading `mean_reading_n` (N) of `samples`.
pub fn static_pose(
    p: &ProtocolPose,
    ujoint_m: Vector3<f64>,
    mean_reading_n: Vector3<f64>,
    samples: u32,
) -> StaticPose {
    StaticPose {
        ujoint_m,
        mean_reading_n,
        samples,
        slide_sign: slide_sign(p.slide_sign),
    }
}

/// The calibration of INTERFACES.md 2's example file (R_0s = I).
pub fn example_calibration() -> sar_estimator::Calibration {
    sar_estimator::Calibration::new(&sar_estimator::CalibrationSpec {
        p_home_m: Vector3::zeros(),
        ujoint_offset_m: Vector3::new(0.0, -0.08, 0.0),
        sensor_offset_m: Vector3::new(0.0, -0.03, 0.0),
        sensor_rotation: Matrix3::identity(),
        support_m: Vector3::new(0.45, 0.20, 0.0),
        gravity_mps2: gravity(),
    })
    .unwrap()
}

/// Manipulator 2 of Table 2 (L = 0.35 m, d = 0).
pub fn manipulator2() -> sar_estimator::Profile {
    sar_estimator::Profile::new(&sar_estimator::ProfileSpec {
        length_m: 0.35,
        offset_m: 0.0,
        mass_kg: 2.593,
        com_m: 0.103,
    })
    .unwrap()
}

/// The truth behind `example_calibration` and `manipulator2`, frictionless.
pub fn manipulator2_truth() -> Truth {
    Truth {
        mass_kg: 2.593,
        com_m: 0.103,
        length_m: 0.35,
        offset_m: 0.0,
        support_m: Vector3::new(0.45, 0.20, 0.0),
        gravity_mps2: gravity(),
        friction_n: 0.0,
    }
}

/// Manipulator `manipulator` (0-based) of Table 2 on the example robot
/// (L = 0.35 m, d = 0, B = (0.45, 0.20, 0)) with `friction_n` of friction.
pub fn table2_truth(manipulator: usize, friction_n: f64) -> Truth {
    let (mass_kg, com_m) = TABLE2[manipulator];
    Truth {
        mass_kg,
        com_m,
        friction_n,
        ..manipulator2_truth()
    }
}

/// Guard limits for tests: total 10/15 N, axial 8/12 N, lateral 6/10 N,
/// hysteresis 1 N, debounce 3 new samples, inputs at most 5 ms old.
pub fn test_guard_limits() -> sar_estimator::guard::GuardLimits {
    sar_estimator::guard::GuardLimits::EXAMPLE
}

/// The per-cycle estimator of the example robot with manipulator 2 and HEX-6 noise.
pub fn example_estimator_config() -> sar_estimator::cycle::EstimatorConfig {
    sar_estimator::cycle::EstimatorConfig {
        calibration: example_calibration(),
        profile: manipulator2(),
        noise: sar_estimator::SensorNoise::hex6(),
        tip: sar_estimator::tip_force::TipForceConfig::default(),
        guard: sar_estimator::guard::GuardConfig::new(test_guard_limits()).unwrap(),
        // The default checks, without the torque check: `example_reading`
        // gives no torque (the cycle tests add it where they check it), and
        // without the checks that need a live, noisy sensor (see
        // `scripted_checks_only`).
        plausibility: sar_estimator::cycle::PlausibilityConfig::new(
            sar_estimator::cycle::PlausibilityLimits {
                torque: None,
                ..scripted_checks_only()
            },
        )
        .unwrap(),
        // A 20 Hz low-pass of 1 kHz samples beside the estimate: every cycle
        // test runs the filter too.
        filter: Some(sar_estimator::filter::FilterConfig {
            cutoff_hz: 20.0,
            sample_period_s: 0.001,
        }),
        inertia: sar_estimator::inertial::RodInertia::slender_rod(&manipulator2()),
    }
}

/// The default plausibility limits without the checks that a scripted,
/// noiseless or exactly repeated reading would trip by design: the frozen
/// sensor, the spikes (scripted steps of the tip force), the first reset's
/// wrench at rest (scripted contacts at start), the tare's age and drift
/// margin (exact thresholds). `tests/failure_modes.rs` tests those with a
/// live, noisy sensor.
pub fn scripted_checks_only() -> sar_estimator::cycle::PlausibilityLimits {
    sar_estimator::cycle::PlausibilityLimits {
        frozen: sar_estimator::cycle::FrozenCheck::Off,
        spikes: None,
        mounting: None,
        // One-sample tares, no rate limit: the scripted readings are
        // exact (the mean at rest is tested with a live sensor).
        tare: sar_estimator::cycle::TareLimits {
            max_age_ns: None,
            drift_n_per_s: 0.0,
            window_samples: 1,
            max_spread: 2.0,
            min_interval_ns: 0,
        },
        ..Default::default()
    }
}

/// The sensor reading (sensor frame, R_0s = I, bias `bias_n`) for the example
/// robot at active joints `q` = (q1, q2, q3) with `tip_force_n` at the tip.
pub fn example_reading(
    q: [f64; 3],
    tip_force_n: &Vector3<f64>,
    bias_n: &Vector3<f64>,
) -> Vector3<f64> {
    let truth = manipulator2_truth();
    let a_m = Vector3::new(q[2], q[1] - 0.08, q[0]);
    let r = truth.support_m - a_m;
    let u = r / r.norm();
    let (_, w) = rod_frame(u.x.atan2(u.z), u.y.asin());
    let (f_a, _) = ujoint_force(&truth, &a_m, &u, &w, tip_force_n, 0.0);
    ideal_reading(&Matrix3::identity(), &f_a, bias_n)
}

/// The joints' sample of the active joints `q` (m), stamped `stamp_ns`, valid.
pub fn joint_sample(q: [f64; 3], stamp_ns: u64) -> sar_estimator::cycle::JointSample {
    sar_estimator::cycle::JointSample {
        joints: sar_kinematics::ActiveJoints {
            q1_m: q[0],
            q2_m: q[1],
            q3_m: q[2],
        },
        stamp_ns,
        valid: true,
    }
}

/// What an identification of manipulator 2 (with 0.3 N of friction) on the
/// example calibration starts from: the truth, the calibration, the bias (N)
/// and the cone protocol's poses, 10 samples each of a HEX-6 sensor seeded
/// `seed`.
pub fn cone_identification_inputs(
    seed: u64,
) -> (
    Truth,
    sar_estimator::Calibration,
    Vector3<f64>,
    Vec<StaticPose>,
) {
    let truth = Truth {
        friction_n: 0.3,
        ..manipulator2_truth()
    };
    let cal = example_calibration();
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let mut sensor = NoisySensor::new(sar_estimator::SensorNoise::HEX6_STD_N, seed);
    let poses = simulate_static_poses(
        &truth,
        &cal.sensor_rotation(),
        &bias_n,
        &cone_protocol(),
        10,
        &mut sensor,
    );
    (truth, cal, bias_n, poses)
}
