//! Identification of m and c (MODEL.md 5, 5.2): the streaming Givens solver
//! against an independent dense solve, on the simulator's noisy protocols, with
//! biases, friction, degenerate pose sets, and the article's line fit.
//!
//! Run with `--nocapture` to see the measured numbers.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;

use common::*;
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sar_estimator::identification::{
    Identification, IdentificationError, IdentificationOptions, IdentificationResult,
    MAX_CONDITION, bias_across_gravity_basis,
};
use sar_estimator::line_fit::LineFit;
use sar_estimator::{
    Calibration, CalibrationSpec, MIN_SUPPORT_DISTANCE_M, PoseInputError, SensorNoise, SlideSign,
    StaticPose,
};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

const ALL_OPTIONS: [IdentificationOptions; 4] = [
    IdentificationOptions {
        bias_across_gravity: false,
        friction: false,
    },
    IdentificationOptions {
        bias_across_gravity: false,
        friction: true,
    },
    IdentificationOptions {
        bias_across_gravity: true,
        friction: false,
    },
    IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    },
];

const FRICTION_ONLY: IdentificationOptions = IdentificationOptions {
    bias_across_gravity: false,
    friction: true,
};

const NO_EXTRAS: IdentificationOptions = IdentificationOptions {
    bias_across_gravity: false,
    friction: false,
};

fn support() -> V3 {
    V3::new(0.45, 0.2, 0.0)
}

/// A sensor mounted with some rotation, so that the HEX-6's weak Z axis is not
/// aligned with any base axis.
fn mounted_rotation() -> M3 {
    Rotation3::from_euler_angles(0.2, -0.35, 0.6).into_inner()
}

fn calibration(support_m: V3, rotation: M3, gravity_mps2: V3) -> Calibration {
    Calibration::new(&CalibrationSpec {
        p_home_m: V3::zeros(),
        ujoint_offset_m: V3::zeros(),
        sensor_offset_m: V3::zeros(),
        sensor_rotation: rotation,
        support_m,
        gravity_mps2,
    })
    .unwrap()
}

fn truth(mass_kg: f64, com_m: f64, friction_n: f64) -> Truth {
    Truth {
        mass_kg,
        com_m,
        length_m: 0.45,
        offset_m: 0.0,
        support_m: support(),
        gravity_mps2: gravity(),
        friction_n,
    }
}

fn identify(
    cal: &Calibration,
    tare: V3,
    options: IdentificationOptions,
    poses: &[StaticPose],
) -> Result<IdentificationResult, IdentificationError> {
    let mut ident = Identification::new(cal, &SensorNoise::hex6(), tare, options).unwrap();
    for pose in poses {
        ident.add(pose).unwrap();
    }
    ident.solve()
}

/// The protocol's poses without any noise: readings straight from the simulator's statics.
fn ideal_poses(
    truth: &Truth,
    rotation: &M3,
    bias_n: &V3,
    protocol: &[ProtocolPose],
) -> Vec<StaticPose> {
    protocol
        .iter()
        .map(|p| {
            let (a_m, f_a) = pose_at_rest(truth, p, |_, _| {
                truth.support_m - p.rod_dir * p.support_distance_m
            });
            static_pose(p, a_m, ideal_reading(rotation, &f_a, bias_n), 1)
        })
        .collect()
}

/// Rod 35 degrees below horizontal in three headings, each swept outward only
/// (the rod is retracted between poses: it slid against u, slide sign -1).
fn downward_retraction_protocol() -> Vec<ProtocolPose> {
    let tilt = 35f64.to_radians();
    let mut poses = Vec::new();
    for heading in [-0.35f64, 0.0, 0.35] {
        let rod_dir = V3::new(
            tilt.cos() * heading.cos(),
            -tilt.sin(),
            tilt.cos() * heading.sin(),
        );
        for &a in PROTOCOL_DISTANCES_M.iter() {
            poses.push(ProtocolPose {
                rod_dir,
                support_distance_m: a,
                slide_sign: -1.0,
            });
        }
    }
    poses
}

// ---------------------------------------------------------------------------
// The independent reference: dense weighted least squares, from MODEL.md 5.1's
// relation written in the base frame, whitened in the sensor frame.
// ---------------------------------------------------------------------------

/// The bias basis as documented on `bias_across_gravity_basis`, written again.
fn documented_bias_basis(rotation: &M3, gravity: &V3) -> [V3; 2] {
    let gs = rotation.transpose() * gravity / gravity.norm();
    let abs = [gs.x.abs(), gs.y.abs(), gs.z.abs()];
    let mut best = 0;
    for i in 1..3 {
        if abs[i] < abs[best] {
            best = i;
        }
    }
    let mut h = V3::zeros();
    h[best] = 1.0;
    let e1 = (h - gs * h.dot(&gs)).normalize();
    [e1, gs.cross(&e1)]
}

#[derive(Debug)]
struct Dense {
    theta: Vec<f64>,
    std: Vec<f64>,
    com: f64,
    com_std: f64,
    chi2_dof: f64,
    residual_rms: f64,
    condition: f64,
    raw_condition: f64,
}

fn dense_fit(
    cal: &Calibration,
    std_n: [f64; 3],
    tare: V3,
    options: IdentificationOptions,
    poses: &[StaticPose],
) -> Dense {
    let b = cal.support_m();
    let g = cal.gravity_mps2();
    let r = cal.sensor_rotation();
    let [e1, e2] = documented_bias_basis(&r, &g);
    let p = 2 + usize::from(options.friction) + 2 * usize::from(options.bias_across_gravity);
    // A pose whose slide sign is unknown gives, with friction estimated, only
    // the part of F_A across u (which f does not touch): 2 rows, whitened
    // with the covariance of that projection. Any basis of the plane gives
    // the same fit; this one is not the estimator's.
    let rows_of = |pose: &StaticPose| {
        if options.friction && !pose.slide_sign.is_known() {
            2
        } else {
            3
        }
    };
    let n: usize = poses.iter().map(rows_of).sum();
    let mut aw = DMatrix::<f64>::zeros(n, p);
    let mut yw = DVector::<f64>::zeros(n);
    let mut au = DMatrix::<f64>::zeros(n, p);
    let mut yu = DVector::<f64>::zeros(n);
    let mut row = 0;
    for pose in poses {
        let rv = b - pose.ujoint_m;
        let a = rv.norm();
        let u = rv / a;
        let f0 = -(r * (pose.mean_reading_n - tare));
        // F_A0 = -m g + M (g - (g.u) u) / a + sigma f u - R (b1 e1 + b2 e2).
        let mut cols = vec![-g, (g - u * g.dot(&u)) / a];
        if options.friction {
            cols.push(u * pose.slide_sign.sigma().unwrap_or(0.0));
        }
        if options.bias_across_gravity {
            cols.push(-(r * e1));
            cols.push(-(r * e2));
        }
        let ks = f64::from(pose.samples).sqrt();
        let k = rows_of(pose);
        // Rows of the observation (base frame) and their whitening.
        let (obs, w): (DMatrix<f64>, DMatrix<f64>) = if k == 3 {
            let w = M3::from_diagonal(&V3::new(ks / std_n[0], ks / std_n[1], ks / std_n[2]))
                * r.transpose();
            (
                DMatrix::identity(3, 3),
                DMatrix::from_column_slice(3, 3, w.as_slice()),
            )
        } else {
            let helper = if u.x.abs() < 0.9 { V3::x() } else { V3::y() };
            let q1 = u.cross(&helper).normalize();
            let q2 = u.cross(&q1);
            let q = DMatrix::from_row_slice(2, 3, &[q1.x, q1.y, q1.z, q2.x, q2.y, q2.z]);
            let var = M3::from_diagonal(&V3::new(
                std_n[0] * std_n[0],
                std_n[1] * std_n[1],
                std_n[2] * std_n[2],
            )) / (ks * ks);
            let cov3 = r * var * r.transpose();
            let cov3 = DMatrix::from_column_slice(3, 3, cov3.as_slice());
            let cov2 = &q * cov3 * q.transpose();
            let l = cov2.cholesky().unwrap().l();
            let w = l.solve_lower_triangular(&q).unwrap();
            (q, w)
        };
        for (j, col) in cols.iter().enumerate() {
            let col = DVector::from_column_slice(col.as_slice());
            let wc = &w * &col;
            let oc = &obs * &col;
            for i in 0..k {
                aw[(row + i, j)] = wc[i];
                au[(row + i, j)] = oc[i];
            }
        }
        let f0 = DVector::from_column_slice(f0.as_slice());
        let wy = &w * &f0;
        let oy = &obs * &f0;
        for i in 0..k {
            yw[row + i] = wy[i];
            yu[row + i] = oy[i];
        }
        row += k;
    }
    // Solved with the columns scaled to unit norm (then unscaled): the SVD is
    // norm-wise stable, so equilibrating keeps small columns accurate.
    let norms: Vec<f64> = (0..p).map(|j| aw.column(j).norm()).collect();
    let mut scaled = aw.clone();
    for (j, norm) in norms.iter().enumerate() {
        scaled.column_mut(j).scale_mut(1.0 / norm);
    }
    let svd = scaled.clone().svd(true, true);
    let theta_scaled = svd.solve(&yw, 0.0).unwrap();
    let theta = DVector::from_iterator(p, (0..p).map(|j| theta_scaled[j] / norms[j]));
    let v = svd.v_t.clone().unwrap().transpose();
    let inv_s2 = svd.singular_values.map(|s| 1.0 / (s * s));
    let cov_scaled = &v * DMatrix::from_diagonal(&inv_s2) * v.transpose();
    let cov_unit = DMatrix::from_fn(p, p, |i, j| cov_scaled[(i, j)] / (norms[i] * norms[j]));
    let chi2 = (&aw * &theta - &yw).norm_squared();
    let chi2_dof = chi2 / (n - p) as f64;
    // The documented rule: widen by the scatter, never narrow below the noise model.
    let cov = cov_unit * chi2_dof.max(1.0);
    let std: Vec<f64> = (0..p).map(|i| cov[(i, i)].sqrt()).collect();
    let (m, mm) = (theta[0], theta[1]);
    let com = mm / m;
    let com_var = (cov[(1, 1)] - 2.0 * com * cov[(0, 1)] + com * com * cov[(0, 0)]) / (m * m);
    let residual_rms = ((&au * &theta - &yu).norm_squared() / n as f64).sqrt();
    let ratio = |mat: &DMatrix<f64>| {
        let sv = mat.singular_values();
        sv.max() / sv.min()
    };
    Dense {
        theta: theta.iter().copied().collect(),
        std,
        com,
        com_std: com_var.sqrt(),
        chi2_dof,
        residual_rms,
        condition: ratio(&scaled),
        raw_condition: ratio(&aw),
    }
}

/// The accumulator's estimate in the dense solve's order: m, M, [f], [b1, b2].
fn as_vectors(r: &IdentificationResult) -> (Vec<f64>, Vec<f64>) {
    let mut theta = vec![r.mass_kg, r.moment_kgm];
    let mut std = vec![r.mass_std_kg, r.moment_std_kgm];
    if let (Some(f), Some(s)) = (r.friction_n, r.friction_std_n) {
        theta.push(f);
        std.push(s);
    }
    if let (Some(b), Some(s)) = (r.bias_across_n, r.bias_across_std_n) {
        theta.extend(b);
        std.extend(s);
    }
    (theta, std)
}

fn rel_close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(f64::MIN_POSITIVE)
}

/// Compares the accumulator with the dense solve: estimates to `tol` of
/// (|value| + its std error), everything else to `tol` relative.
fn assert_matches_dense(r: &IdentificationResult, d: &Dense, tol: f64, check_chi2: bool) {
    let (theta, std) = as_vectors(r);
    assert_eq!(theta.len(), d.theta.len());
    for i in 0..theta.len() {
        let scale = d.theta[i].abs() + d.std[i];
        assert!(
            (theta[i] - d.theta[i]).abs() <= tol * scale,
            "unknown {i}: {} vs dense {} (std {})",
            theta[i],
            d.theta[i],
            d.std[i]
        );
        if check_chi2 {
            assert!(
                rel_close(std[i], d.std[i], tol),
                "std {i}: {} vs {}",
                std[i],
                d.std[i]
            );
        }
    }
    assert!(
        (r.com_m - d.com).abs() <= tol * (d.com.abs() + d.com_std),
        "c {} vs {}",
        r.com_m,
        d.com
    );
    if check_chi2 {
        assert!(rel_close(r.com_std_m, d.com_std, tol));
        assert!(
            rel_close(r.chi2_dof, d.chi2_dof, tol),
            "chi2 {} vs {}",
            r.chi2_dof,
            d.chi2_dof
        );
        assert!(
            rel_close(r.residual_rms_n, d.residual_rms, tol),
            "rms {} vs {}",
            r.residual_rms_n,
            d.residual_rms
        );
    }
    assert!(
        rel_close(r.condition, d.condition, tol),
        "condition {} vs {}",
        r.condition,
        d.condition
    );
}

fn random_unit(rng: &mut ChaCha8Rng) -> V3 {
    let normal = Normal::new(0.0, 1.0).unwrap();
    loop {
        let v = V3::new(normal.sample(rng), normal.sample(rng), normal.sample(rng));
        if v.norm() > 1e-3 {
            return v.normalize();
        }
    }
}

struct Problem {
    cal: Calibration,
    std_n: [f64; 3],
    tare: V3,
    poses: Vec<StaticPose>,
}

/// A random, well-posed problem written straight from MODEL.md 5.1: random
/// sensor rotation, gravity direction, anisotropic noise, directions,
/// distances, sample counts and slide signs, with noise at the stated level.
fn random_problem(seed: u64, options: IdentificationOptions, count: usize) -> Problem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = random_unit(&mut rng) * rng.random_range(0.0..3.1);
    let rotation = Rotation3::from_scaled_axis(axis).into_inner();
    let gravity = random_unit(&mut rng) * 9.80665;
    let b = V3::new(
        rng.random_range(-0.5..0.5),
        rng.random_range(-0.5..0.5),
        rng.random_range(-0.5..0.5),
    );
    let std_n = [
        rng.random_range(0.05..1.0),
        rng.random_range(0.05..1.0),
        rng.random_range(0.05..1.0),
    ];
    let tare = V3::new(
        rng.random_range(-5.0..5.0),
        rng.random_range(-5.0..5.0),
        rng.random_range(-5.0..5.0),
    );
    let m = rng.random_range(0.5..5.0);
    let c = rng.random_range(0.05..0.3);
    let f = if options.friction {
        rng.random_range(0.0..1.0)
    } else {
        0.0
    };
    let [e1, e2] = documented_bias_basis(&rotation, &gravity);
    let delta = if options.bias_across_gravity {
        e1 * rng.random_range(-1.0..1.0) + e2 * rng.random_range(-1.0..1.0)
    } else {
        V3::zeros()
    };
    let unit_normal = Normal::new(0.0, 1.0).unwrap();
    let poses = (0..count)
        .map(|i| {
            let u = random_unit(&mut rng);
            let a = rng.random_range(0.03..0.4);
            let samples = rng.random_range(1..50u32);
            // A third of the poses (after the first two) have an unknown slide
            // sign: the support's friction still acts, one way or the other.
            let (slide_sign, sigma) = match i {
                0 => (SlideSign::Inserting, 1.0),
                1 => (SlideSign::Retracting, -1.0),
                _ => match rng.random_range(-1..=1i32) {
                    1 => (SlideSign::Inserting, 1.0),
                    -1 => (SlideSign::Retracting, -1.0),
                    _ => (
                        SlideSign::Unknown,
                        if rng.random_bool(0.5) { 1.0 } else { -1.0 },
                    ),
                },
            };
            let f_a =
                -gravity * m + (gravity - u * gravity.dot(&u)) * (m * c / a) + u * (sigma * f);
            let ideal = rotation.transpose() * (-f_a) + tare + delta;
            let k = f64::from(samples).sqrt();
            let noise = V3::new(
                std_n[0] * unit_normal.sample(&mut rng),
                std_n[1] * unit_normal.sample(&mut rng),
                std_n[2] * unit_normal.sample(&mut rng),
            ) / k;
            StaticPose {
                ujoint_m: b - u * a,
                mean_reading_n: ideal + noise,
                samples,
                slide_sign,
            }
        })
        .collect();
    Problem {
        cal: calibration(b, rotation, gravity),
        std_n,
        tare,
        poses,
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: RngSeed::Fixed(0x1de7_1f1c),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// The Givens accumulator gives the dense weighted least-squares answer:
    /// estimates, standard errors, c and its std, chi2, residual RMS and the
    /// scaled condition number, for every option combination.
    #[test]
    fn accumulator_matches_dense_solve(
        seed in any::<u64>(),
        which in 0usize..4,
        count in 3usize..16,
    ) {
        let options = ALL_OPTIONS[which];
        let problem = random_problem(seed, options, count);
        let noise = SensorNoise::new(V3::from(problem.std_n)).unwrap();
        let mut ident = Identification::new(&problem.cal, &noise, problem.tare, options).unwrap();
        for pose in &problem.poses {
            ident.add(pose).unwrap();
        }
        let dense = dense_fit(&problem.cal, problem.std_n, problem.tare, options, &problem.poses);
        prop_assume!(dense.condition < 1e6);
        let result = ident.solve().unwrap();
        prop_assert_eq!(result.poses as usize, count);
        let rows: usize = problem
            .poses
            .iter()
            .map(|p| if options.friction && !p.slide_sign.is_known() { 2 } else { 3 })
            .sum();
        prop_assert_eq!(result.rows as usize, rows);
        assert_matches_dense(&result, &dense, 1e-9, true);
    }
}

#[test]
fn documented_bias_basis_is_the_library_basis() {
    let cal = calibration(support(), M3::identity(), gravity());
    let [e1, e2] = bias_across_gravity_basis(&cal);
    assert!((e1 - V3::x()).norm() < 1e-15 && (e2 - V3::z()).norm() < 1e-15);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..100 {
        let rotation = Rotation3::from_scaled_axis(random_unit(&mut rng) * 2.0).into_inner();
        let g = random_unit(&mut rng) * 9.8;
        let cal = calibration(support(), rotation, g);
        let lib = bias_across_gravity_basis(&cal);
        let mine = documented_bias_basis(&rotation, &g);
        for k in 0..2 {
            assert!((lib[k] - mine[k]).norm() < 1e-12);
            assert!(lib[k].dot(&(rotation.transpose() * g)).abs() < 1e-12);
        }
    }
}

// ---------------------------------------------------------------------------
// Synthetic noisy protocols (the simulator of tests/common).
// ---------------------------------------------------------------------------

/// Every Table 2 manipulator, cone protocol, HEX-6 noise on a rotated sensor,
/// 10 samples per pose, friction 0.3 N with the friction unknown on: m, c and f
/// within 4 standard errors, chi2/dof near 1.
#[test]
fn table2_recovered_with_the_friction_unknown() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(0.7, -1.9, 0.4);
    for (i, &(m, c)) in TABLE2.iter().enumerate() {
        let t = truth(m, c, 0.3);
        let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 1000 + i as u64);
        let poses = simulate_static_poses(&t, &rotation, &tare, &cone_protocol(), 10, &mut sensor);
        let r = identify(&cal, tare, FRICTION_ONLY, &poses).unwrap();
        let f = r.friction_n.unwrap();
        let f_std = r.friction_std_n.unwrap();
        println!(
            "manipulator {}: m {:.5} kg ({:+.4} %, std {:.4} %), c {:.6} m ({:+.4} %, std {:.4} %), \
             f {:.4} N (std {:.4}), chi2/dof {:.3}, rms {:.4} N, condition {:.1}",
            i + 1,
            r.mass_kg,
            100.0 * (r.mass_kg - m) / m,
            100.0 * r.mass_std_kg / m,
            r.com_m,
            100.0 * (r.com_m - c) / c,
            100.0 * r.com_std_m / c,
            f,
            f_std,
            r.chi2_dof,
            r.residual_rms_n,
            r.condition
        );
        assert!((r.mass_kg - m).abs() < 4.0 * r.mass_std_kg);
        assert!((r.com_m - c).abs() < 4.0 * r.com_std_m);
        assert!((f - 0.3).abs() < 4.0 * f_std);
        assert!(r.mass_std_kg / m < 0.01 && r.com_std_m / c < 0.01);
        assert!((0.4..1.8).contains(&r.chi2_dof), "chi2/dof {}", r.chi2_dof);
    }
}

/// Friction 0.3 N, the friction unknown off: how far m and c move (noise-free
/// data, HEX-6 weights), per protocol. The retraction protocol (tilted down,
/// always slid the same way) is biased far beyond its standard error; the
/// bias and the misfit (chi2) are printed for all three.
#[test]
fn ignoring_friction_biases_the_estimate() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::zeros();
    let (m, c) = TABLE2[0];
    let protocols = [
        ("article", article_protocol()),
        ("cone", cone_protocol()),
        ("downward retraction", downward_retraction_protocol()),
    ];
    for (name, protocol) in &protocols {
        let t = truth(m, c, 0.3);
        let clean = ideal_poses(&t, &rotation, &tare, protocol);
        let with_f = identify(&cal, tare, FRICTION_ONLY, &clean).unwrap();
        let without_f = identify(&cal, tare, NO_EXTRAS, &clean).unwrap();
        // With the friction unknown the noise-free data are fitted exactly.
        assert!((with_f.mass_kg - m).abs() < 1e-9 * m, "{name}");
        assert!((with_f.com_m - c).abs() < 1e-9 * c, "{name}");
        assert!((with_f.friction_n.unwrap() - 0.3).abs() < 1e-9, "{name}");
        // The same protocol with HEX-6 noise, K = 10: the friction-off estimate's
        // reported std error and chi2.
        let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 77);
        let noisy = simulate_static_poses(&t, &rotation, &tare, protocol, 10, &mut sensor);
        let noisy_without = identify(&cal, tare, NO_EXTRAS, &noisy).unwrap();
        let noisy_with = identify(&cal, tare, FRICTION_ONLY, &noisy).unwrap();
        let dm = without_f.mass_kg - m;
        let dc = without_f.com_m - c;
        println!(
            "{name}: friction unknown off moves m by {:+.4} % ({:+.2} std), c by {:+.4} % ({:+.2} std); \
             noisy chi2/dof {:.2} off vs {:.2} on",
            100.0 * dm / m,
            dm / noisy_with.mass_std_kg,
            100.0 * dc / c,
            dc / noisy_with.com_std_m,
            noisy_without.chi2_dof,
            noisy_with.chi2_dof
        );
        if *name == "downward retraction" {
            // All axial rows carry -f with u.g > 0: m looks heavier.
            assert!(dm > 5.0 * noisy_with.mass_std_kg, "dm {dm}");
            assert!(dm < 0.3 / (9.80665 * 35f64.to_radians().sin()) * 1.01);
            assert!((noisy_without.mass_kg - m).abs() > 5.0 * noisy_with.mass_std_kg);
            assert!(noisy_without.chi2_dof > 2.0 * noisy_with.chi2_dof);
        }
    }
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// Over 200 seeded runs the empirical spread of m and c matches the mean
/// reported standard error (within 20 %), and the estimates are unbiased.
#[test]
fn reported_standard_errors_are_honest() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(0.3, 0.2, -0.5);
    let (m, c) = TABLE2[0];
    let t = truth(m, c, 0.3);
    let cases = [
        (
            "cone, friction on, K = 10",
            cone_protocol(),
            FRICTION_ONLY,
            10u32,
        ),
        (
            "cone, friction + bias on, K = 1",
            cone_protocol(),
            IdentificationOptions {
                bias_across_gravity: true,
                friction: true,
            },
            1,
        ),
        (
            "article, friction on, K = 10",
            article_protocol(),
            FRICTION_ONLY,
            10,
        ),
    ];
    for (name, protocol, options, samples) in &cases {
        let runs = 200;
        let (mut ms, mut cs, mut m_stds, mut c_stds) = (vec![], vec![], vec![], vec![]);
        for seed in 0..runs {
            let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 50_000 + seed);
            let poses =
                simulate_static_poses(&t, &rotation, &tare, protocol, *samples, &mut sensor);
            let r = identify(&cal, tare, *options, &poses).unwrap();
            ms.push(r.mass_kg);
            cs.push(r.com_m);
            m_stds.push(r.mass_std_kg);
            c_stds.push(r.com_std_m);
        }
        let (m_mean, m_emp) = mean_std(&ms);
        let (c_mean, c_emp) = mean_std(&cs);
        let (m_rep, _) = mean_std(&m_stds);
        let (c_rep, _) = mean_std(&c_stds);
        println!(
            "{name}: m empirical std {:.3e} vs reported {:.3e} (ratio {:.3}), \
             c {:.3e} vs {:.3e} (ratio {:.3}); mean m error {:+.2e} %, c {:+.2e} %",
            m_emp,
            m_rep,
            m_emp / m_rep,
            c_emp,
            c_rep,
            c_emp / c_rep,
            100.0 * (m_mean - m) / m,
            100.0 * (c_mean - c) / c
        );
        assert!((0.8..1.2).contains(&(m_emp / m_rep)), "{name}: m");
        assert!((0.8..1.2).contains(&(c_emp / c_rep)), "{name}: c");
        let n = (runs as f64).sqrt();
        assert!((m_mean - m).abs() < 4.0 * m_emp / n, "{name}: m biased");
        assert!((c_mean - c).abs() < 4.0 * c_emp / n, "{name}: c biased");
    }
}

// ---------------------------------------------------------------------------
// Bias (MODEL.md 5: tare with the rod detached).
// ---------------------------------------------------------------------------

/// An untared bias on the sensor's vertical axis, -1.2 N on sensor Y (which
/// points up: +1.2 N along gravity, adding to the apparent weight), for
/// manipulator 1, frictionless support, noise off: m' = m + 1.2 / |g| exactly
/// and M unchanged, so c' = c m / m' (MODEL.md 5 says +7.6 % and -7.1 %). The
/// bias unknowns across gravity cannot absorb it.
#[test]
fn untared_bias_along_gravity_moves_m_and_c() {
    let rotation = M3::identity();
    let cal = calibration(support(), rotation, gravity());
    let (m, c) = TABLE2[0];
    let t = truth(m, c, 0.0);
    let bias = V3::new(0.0, -1.2, 0.0);
    let m_expected = m + 1.2 / 9.80665;
    let c_expected = c * m / m_expected;
    for (name, protocol) in [("article", article_protocol()), ("cone", cone_protocol())] {
        let poses = ideal_poses(&t, &rotation, &bias, &protocol);
        for options in [
            NO_EXTRAS,
            IdentificationOptions {
                bias_across_gravity: true,
                friction: false,
            },
        ] {
            // The estimator is told the sensor was tared to zero.
            let r = identify(&cal, V3::zeros(), options, &poses).unwrap();
            let dm = (r.mass_kg - m) / m;
            let dc = (r.com_m - c) / c;
            println!(
                "{name} {options:?}: untared -1.2 N on Y: m {:+.4} %, c {:+.4} %",
                100.0 * dm,
                100.0 * dc
            );
            assert!((r.mass_kg - m_expected).abs() < 1e-9 * m);
            assert!((r.com_m - c_expected).abs() < 1e-9 * c);
            assert!((100.0 * dm - 7.6).abs() < 0.05, "MODEL.md: +7.6 %");
            assert!((100.0 * dc + 7.1).abs() < 0.05, "MODEL.md: -7.1 %");
            if let Some(b) = r.bias_across_n {
                assert!(b[0].abs() < 1e-9 && b[1].abs() < 1e-9);
            }
        }
    }
}

/// A bias across gravity on top of the tare, on a rotated sensor: with the
/// bias unknowns on it is recovered within its standard errors, and m, c stay
/// right; without them m and c move (printed).
#[test]
fn bias_across_gravity_is_recovered() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(1.0, -2.0, 0.5);
    let [e1, e2] = documented_bias_basis(&rotation, &gravity());
    let true_bias = [0.8, -0.5];
    let actual_bias = tare + e1 * true_bias[0] + e2 * true_bias[1];
    let (m, c) = TABLE2[1];
    let t = truth(m, c, 0.3);
    let both = IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    };
    for (name, protocol) in [("cone", cone_protocol()), ("article", article_protocol())] {
        // Noise-free: exact.
        let clean = ideal_poses(&t, &rotation, &actual_bias, &protocol);
        let exact = identify(&cal, tare, both, &clean).unwrap();
        let b = exact.bias_across_n.unwrap();
        assert!((b[0] - true_bias[0]).abs() < 1e-9 && (b[1] - true_bias[1]).abs() < 1e-9);
        assert!((exact.mass_kg - m).abs() < 1e-9 * m && (exact.com_m - c).abs() < 1e-9 * c);
        // HEX-6 noise, K = 10.
        let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 4242);
        let poses = simulate_static_poses(&t, &rotation, &actual_bias, &protocol, 10, &mut sensor);
        let r = identify(&cal, tare, both, &poses).unwrap();
        let b = r.bias_across_n.unwrap();
        let s = r.bias_across_std_n.unwrap();
        for k in 0..2 {
            assert!((b[k] - true_bias[k]).abs() < 4.0 * s[k], "{name}: bias {k}");
        }
        assert!((r.mass_kg - m).abs() < 4.0 * r.mass_std_kg, "{name}");
        assert!((r.com_m - c).abs() < 4.0 * r.com_std_m, "{name}");
        let ignored = identify(&cal, tare, FRICTION_ONLY, &clean).unwrap();
        println!(
            "{name}: bias ({:+.3}, {:+.3}) N recovered as ({:+.3} +- {:.3}, {:+.3} +- {:.3}); \
             m {:+.3} %, c {:+.3} %; bias unknowns off (noise-free): m {:+.3} %, c {:+.3} %",
            true_bias[0],
            true_bias[1],
            b[0],
            s[0],
            b[1],
            s[1],
            100.0 * (r.mass_kg - m) / m,
            100.0 * (r.com_m - c) / c,
            100.0 * (ignored.mass_kg - m) / m,
            100.0 * (ignored.com_m - c) / c
        );
    }
}

// ---------------------------------------------------------------------------
// Numerical stability, degenerate sets, streaming, refused poses.
// ---------------------------------------------------------------------------

/// Columns whose norms differ by orders of magnitude (|g| = 100, a from 1.1 to
/// 5 times [`MIN_SUPPORT_DISTANCE_M`], c of the same order, K = 10^4): the
/// accumulator still gives the dense answer, and its condition number is the
/// column-scaled one, far below the raw one.
#[test]
fn badly_scaled_columns_match_the_dense_solve() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let rotation = mounted_rotation();
    let g = V3::new(0.0, -100.0, 0.0);
    let b = support();
    let cal = calibration(b, rotation, g);
    let tare = V3::new(3.0, 1.0, -2.0);
    let std_n = SensorNoise::HEX6_STD_N;
    let (m, c, f) = (2.0, 1.2 * MIN_SUPPORT_DISTANCE_M, 0.3);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let poses: Vec<StaticPose> = (0..30)
        .map(|i| {
            let u = random_unit(&mut rng);
            let a = rng.random_range(1.1 * MIN_SUPPORT_DISTANCE_M..5.0 * MIN_SUPPORT_DISTANCE_M);
            let sigma = if i % 2 == 0 { 1.0 } else { -1.0 };
            let f_a = -g * m + (g - u * g.dot(&u)) * (m * c / a) + u * (sigma * f);
            let samples = 10_000;
            let noise = V3::new(
                normal.sample(&mut rng) * std_n[0],
                normal.sample(&mut rng) * std_n[1],
                normal.sample(&mut rng) * std_n[2],
            ) / 100.0;
            StaticPose {
                ujoint_m: b - u * a,
                mean_reading_n: rotation.transpose() * (-f_a) + tare + noise,
                samples,
                slide_sign: slide_sign(sigma),
            }
        })
        .collect();
    for options in ALL_OPTIONS {
        let r = identify(&cal, tare, options, &poses).unwrap();
        let d = dense_fit(&cal, std_n, tare, options, &poses);
        println!(
            "badly scaled {options:?}: scaled condition {:.3e}, raw condition {:.3e}",
            r.condition, d.raw_condition
        );
        // With m and M alone the columns' norms differ by about 1/a (in 1/m),
        // which the minimum distance bounds (36 times here, 180 with the 1 mm
        // minimum of before); the friction and bias columns (coefficient 1
        // against |g| / a) are far worse scaled.
        let factor = if options == NO_EXTRAS { 10.0 } else { 100.0 };
        assert!(d.raw_condition > factor * r.condition);
        assert_matches_dense(&r, &d, 1e-9, true);
    }
}

type ErrorCheck = fn(&IdentificationError) -> bool;

fn is_ill_conditioned(e: &IdentificationError) -> bool {
    matches!(e, IdentificationError::IllConditioned { condition, limit }
        if *limit == MAX_CONDITION && !condition.is_nan() && *condition > MAX_CONDITION)
}

/// Pose sets that cannot tell the unknowns apart give the typed error, never NaN.
#[test]
fn rank_deficient_sets_are_typed_errors() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::zeros();
    let t = truth(1.611, 0.115, 0.0);
    let article = ideal_poses(&t, &rotation, &tare, &article_protocol());

    // Nothing yet.
    let empty = Identification::new(&cal, &SensorNoise::hex6(), tare, NO_EXTRAS).unwrap();
    assert!(matches!(
        empty.solve(),
        Err(IdentificationError::TooFewRows {
            rows: 0,
            poses: 0,
            needed: 2
        })
    ));
    // A single horizontal pose: (M/a - m) is all it tells.
    let e = identify(&cal, tare, NO_EXTRAS, &article[..1]).unwrap_err();
    assert!(is_ill_conditioned(&e), "{e:?}");
    // A single pose against 5 unknowns: too few rows.
    let all = IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    };
    let e = identify(&cal, tare, all, &article[..1]).unwrap_err();
    assert!(matches!(
        e,
        IdentificationError::TooFewRows {
            rows: 3,
            poses: 1,
            needed: 5
        }
    ));
    // The same horizontal pose ten times, with noise: one a and direction.
    let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 3);
    let horizontal: Vec<ProtocolPose> = (0..10).map(|_| article_protocol()[2]).collect();
    let poses = simulate_static_poses(&t, &rotation, &tare, &horizontal, 5, &mut sensor);
    let e = identify(&cal, tare, NO_EXTRAS, &poses).unwrap_err();
    assert!(is_ill_conditioned(&e), "{e:?}");
    // The same tilted pose ten times: its axial row gives m and its moment rows
    // M, but with the friction unknown (one slide sign) m and f mix.
    let cone = cone_protocol();
    let tilted: Vec<ProtocolPose> = (0..10).map(|_| cone[0]).collect();
    let poses = simulate_static_poses(&t, &rotation, &tare, &tilted, 5, &mut sensor);
    assert!(identify(&cal, tare, NO_EXTRAS, &poses).is_ok());
    let e = identify(&cal, tare, FRICTION_ONLY, &poses).unwrap_err();
    assert!(is_ill_conditioned(&e), "{e:?}");
    // The friction unknown with no slide recorded: its column is zero.
    let unsigned: Vec<StaticPose> = ideal_poses(&t, &rotation, &tare, &cone)
        .into_iter()
        .map(|p| StaticPose {
            slide_sign: SlideSign::Unknown,
            ..p
        })
        .collect();
    let e = identify(&cal, tare, FRICTION_ONLY, &unsigned).unwrap_err();
    assert!(
        matches!(e, IdentificationError::IllConditioned { condition, .. } if condition == f64::INFINITY),
        "{e:?}"
    );
    // Friction with every pose slid the same way on the horizontal protocol:
    // f and the axial bias component cannot be told apart.
    let same_way: Vec<StaticPose> = article
        .iter()
        .map(|p| StaticPose {
            slide_sign: SlideSign::Inserting,
            ..*p
        })
        .collect();
    let e = identify(&cal, tare, all, &same_way).unwrap_err();
    assert!(is_ill_conditioned(&e), "{e:?}");
    // Without friction the same poses are fine.
    assert!(identify(&cal, tare, NO_EXTRAS, &same_way).is_ok());
}

/// The estimate is available after every add, and equals the dense solve of
/// the poses so far (or is a typed error while they are too few).
#[test]
fn streaming_result_after_every_pose() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(0.1, 0.2, 0.3);
    let t = truth(3.198, 0.125, 0.3);
    let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 11);
    let poses = simulate_static_poses(&t, &rotation, &tare, &cone_protocol(), 3, &mut sensor);
    for options in ALL_OPTIONS {
        let mut ident = Identification::new(&cal, &SensorNoise::hex6(), tare, options).unwrap();
        let mut solved = 0;
        for (k, pose) in poses.iter().enumerate() {
            ident.add(pose).unwrap();
            assert_eq!(ident.poses() as usize, k + 1);
            match ident.solve() {
                Ok(r) => {
                    let d = dense_fit(&cal, SensorNoise::HEX6_STD_N, tare, options, &poses[..=k]);
                    assert_matches_dense(&r, &d, 1e-9, r.rows > ident.unknowns());
                    solved += 1;
                }
                Err(e) => {
                    assert!(
                        is_ill_conditioned(&e)
                            || matches!(e, IdentificationError::TooFewRows { .. }),
                        "{e:?}"
                    );
                    assert!(k < 5, "still no estimate after {} poses: {e:?}", k + 1);
                }
            }
        }
        assert!(solved >= 15, "{options:?}: {solved}");
    }
}

/// Every invalid pose is refused with its typed error and leaves the state
/// (and so the estimate) exactly as it was.
#[test]
fn refused_poses_leave_the_state_unchanged() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::zeros();
    let t = truth(1.611, 0.115, 0.3);
    let poses = ideal_poses(&t, &rotation, &tare, &cone_protocol());
    let options = IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    };
    let mut ident = Identification::new(&cal, &SensorNoise::hex6(), tare, options).unwrap();
    for p in &poses[..8] {
        ident.add(p).unwrap();
    }
    let before = ident;
    let estimate = ident.solve().unwrap();
    let good = poses[8];
    let nan = f64::NAN;
    let cases: Vec<(StaticPose, ErrorCheck)> = vec![
        (
            StaticPose {
                ujoint_m: V3::new(nan, 0.0, 0.0),
                ..good
            },
            |e| {
                matches!(
                    e,
                    IdentificationError::Pose(PoseInputError::NonFinite {
                        field: "ujoint_m",
                        ..
                    })
                )
            },
        ),
        (
            StaticPose {
                mean_reading_n: V3::new(0.0, f64::INFINITY, 0.0),
                ..good
            },
            |e| {
                matches!(
                    e,
                    IdentificationError::Pose(PoseInputError::NonFinite {
                        field: "mean_reading_n",
                        ..
                    })
                )
            },
        ),
        (StaticPose { samples: 0, ..good }, |e| {
            matches!(
                e,
                IdentificationError::Pose(PoseInputError::NoSamples { samples: 0 })
            )
        }),
        (
            StaticPose {
                ujoint_m: support() - V3::x() * 0.5 * MIN_SUPPORT_DISTANCE_M,
                ..good
            },
            |e| {
                matches!(e, IdentificationError::SupportTooClose { distance_m, min_m }
                    if (*distance_m - 0.5 * MIN_SUPPORT_DISTANCE_M).abs() < 1e-12
                        && *min_m == MIN_SUPPORT_DISTANCE_M)
            },
        ),
        (
            StaticPose {
                ujoint_m: support(),
                ..good
            },
            |e| matches!(e, IdentificationError::SupportTooClose { .. }),
        ),
        (
            // Finite, but its whitened rows overflow.
            StaticPose {
                mean_reading_n: V3::new(1e308, -1e308, 1e308),
                ..good
            },
            |e| matches!(e, IdentificationError::NonFinite { .. }),
        ),
    ];
    for (pose, expected) in &cases {
        let e = ident.add(pose).expect_err(&format!("accepted {pose:?}"));
        assert!(expected(&e), "{pose:?}: {e:?}");
        assert_eq!(ident, before);
        assert_eq!(ident.solve().unwrap(), estimate);
    }
    // The good pose is still accepted afterwards.
    ident.add(&good).unwrap();
    assert_eq!(ident.poses(), 9);
    // A non-finite tare is refused at construction.
    assert!(matches!(
        Identification::new(&cal, &SensorNoise::hex6(), V3::new(0.0, nan, 0.0), options),
        Err(IdentificationError::NonFinite {
            field: "bias_n",
            ..
        })
    ));
    // A noise too small to square.
    let tiny = SensorNoise::new(V3::new(1e-200, 0.2, 0.2)).unwrap();
    assert!(matches!(
        Identification::new(&cal, &tiny, tare, options),
        Err(IdentificationError::NoiseOutOfRange { std_n } ) if std_n == 1e-200
    ));
}

/// A rod whose readings say it pushes up (negative mass) is reported, not divided by.
#[test]
fn non_positive_mass_is_reported() {
    let rotation = M3::identity();
    let cal = calibration(support(), rotation, gravity());
    let mut t = truth(1.0, 0.1, 0.0);
    t.mass_kg = -0.5;
    let poses = ideal_poses(&t, &rotation, &V3::zeros(), &cone_protocol());
    let e = identify(&cal, V3::zeros(), NO_EXTRAS, &poses).unwrap_err();
    match e {
        IdentificationError::NonPositiveMass { mass_kg } => {
            assert!((mass_kg + 0.5).abs() < 1e-9)
        }
        other => panic!("{other:?}"),
    }
    // A zero reading everywhere: no mass at all.
    let zero: Vec<StaticPose> = poses
        .iter()
        .map(|p| StaticPose {
            mean_reading_n: V3::zeros(),
            ..*p
        })
        .collect();
    let e = identify(&cal, V3::zeros(), NO_EXTRAS, &zero).unwrap_err();
    assert!(
        matches!(e, IdentificationError::NonPositiveMass { .. }),
        "{e:?}"
    );
}

// ---------------------------------------------------------------------------
// The article's line fit (MODEL.md 5.2).
// ---------------------------------------------------------------------------

fn line_fit(cal: &Calibration, tare: V3, poses: &[StaticPose]) -> LineFit {
    let mut fit = LineFit::new(cal, tare, 1e-6).unwrap();
    for p in poses {
        fit.add(p).unwrap();
    }
    fit
}

/// Noise-free, frictionless, article protocol: the line gives m and c back to
/// 1e-9, with b1 = -M |g| (negative: the article's sign is wrong).
#[test]
fn line_fit_recovers_m_and_c_noise_free() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(-0.4, 1.1, 0.2);
    for &(m, c) in TABLE2.iter() {
        let t = truth(m, c, 0.0);
        let poses = ideal_poses(&t, &rotation, &tare, &article_protocol());
        let r = line_fit(&cal, tare, &poses).solve().unwrap();
        assert!((r.mass_kg - m).abs() < 1e-9 * m, "{} vs {m}", r.mass_kg);
        assert!((r.com_m - c).abs() < 1e-9 * c, "{} vs {c}", r.com_m);
        assert!((r.b0_n - m * 9.80665).abs() < 1e-9 * m * 9.80665);
        assert!((r.b1_nm + m * c * 9.80665).abs() < 1e-9 * m * c * 9.80665);
        assert!(r.b1_nm < 0.0);
        assert_eq!(r.poses, 10);
        // ssr = syy - b1 sxy cancels at a perfect fit: about half the digits of
        // syy are lost (irrelevant at noise level, 0.2 N).
        assert!(r.residual_rms_n < 1e-6, "{}", r.residual_rms_n);
    }
}

/// With HEX-6 noise (K = 1 and K = 10) the line's m and c are within 4 of its
/// own standard errors, for every Table 2 manipulator; compared with the
/// weighted identification on the same data.
#[test]
fn line_fit_with_noise_within_its_std() {
    let rotation = M3::identity();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::zeros();
    for samples in [1u32, 10] {
        for (i, &(m, c)) in TABLE2.iter().enumerate() {
            let t = truth(m, c, 0.3);
            let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 900 + i as u64);
            let poses = simulate_static_poses(
                &t,
                &rotation,
                &tare,
                &article_protocol(),
                samples,
                &mut sensor,
            );
            let r = line_fit(&cal, tare, &poses).solve().unwrap();
            let w = identify(&cal, tare, FRICTION_ONLY, &poses).unwrap();
            println!(
                "K={samples} manipulator {}: line m {:+.3} % (std {:.3} %), c {:+.3} % (std {:.3} %); \
                 weighted m {:+.3} % (std {:.3} %), c {:+.3} % (std {:.3} %)",
                i + 1,
                100.0 * (r.mass_kg - m) / m,
                100.0 * r.mass_std_kg / m,
                100.0 * (r.com_m - c) / c,
                100.0 * r.com_std_m / c,
                100.0 * (w.mass_kg - m) / m,
                100.0 * w.mass_std_kg / m,
                100.0 * (w.com_m - c) / c,
                100.0 * w.com_std_m / c
            );
            assert!((r.mass_kg - m).abs() < 4.0 * r.mass_std_kg);
            assert!((r.com_m - c).abs() < 4.0 * r.com_std_m);
            assert!(r.mass_std_kg > 0.0 && r.com_std_m > 0.0);
        }
    }
}

/// Over 200 seeded runs the line fit's reported std errors match its spread.
#[test]
fn line_fit_standard_errors_are_honest() {
    let rotation = M3::identity();
    let cal = calibration(support(), rotation, gravity());
    let (m, c) = TABLE2[0];
    let t = truth(m, c, 0.0);
    let (mut ms, mut cs, mut m_stds, mut c_stds) = (vec![], vec![], vec![], vec![]);
    for seed in 0..200 {
        let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 70_000 + seed);
        let poses = simulate_static_poses(
            &t,
            &rotation,
            &V3::zeros(),
            &article_protocol(),
            1,
            &mut sensor,
        );
        let r = line_fit(&cal, V3::zeros(), &poses).solve().unwrap();
        ms.push(r.mass_kg);
        cs.push(r.com_m);
        m_stds.push(r.mass_std_kg);
        c_stds.push(r.com_std_m);
    }
    let (_, m_emp) = mean_std(&ms);
    let (_, c_emp) = mean_std(&cs);
    let (m_rep, _) = mean_std(&m_stds);
    let (c_rep, _) = mean_std(&c_stds);
    println!(
        "line fit, K = 1: m empirical/reported std {:.3}, c {:.3}",
        m_emp / m_rep,
        c_emp / c_rep
    );
    // 8 degrees of freedom: the mean reported std is biased low by ~3 %.
    assert!((0.8..1.25).contains(&(m_emp / m_rep)));
    assert!((0.8..1.25).contains(&(c_emp / c_rep)));
}

/// A tilted pose, a pose at the support, too few poses, one distance only, a
/// bad tolerance: typed errors, state unchanged.
#[test]
fn line_fit_refusals() {
    let rotation = M3::identity();
    let cal = calibration(support(), rotation, gravity());
    let t = truth(1.611, 0.115, 0.0);
    let article = ideal_poses(&t, &rotation, &V3::zeros(), &article_protocol());
    let cone = ideal_poses(&t, &rotation, &V3::zeros(), &cone_protocol());
    let mut fit = LineFit::new(&cal, V3::zeros(), 1e-3).unwrap();
    for p in &article[..4] {
        fit.add(p).unwrap();
    }
    let before = fit;
    // cone_protocol()[0] is tilted 35 degrees up.
    match fit.add(&cone[0]) {
        Err(IdentificationError::NotHorizontal {
            tilt_rad,
            tolerance_rad,
        }) => {
            assert!((tilt_rad - 35f64.to_radians()).abs() < 1e-9);
            assert_eq!(tolerance_rad, 1e-3);
        }
        other => panic!("{other:?}"),
    }
    // A rod tilted 2 mrad (A 0.2 mm below the support at a = 0.1 m).
    let slightly = StaticPose {
        ujoint_m: support() - V3::new(0.1, 0.0002, 0.0),
        ..article[0]
    };
    assert!(matches!(
        fit.add(&slightly),
        Err(IdentificationError::NotHorizontal { .. })
    ));
    assert!(matches!(
        fit.add(&StaticPose {
            samples: 0,
            ..article[0]
        }),
        Err(IdentificationError::Pose(PoseInputError::NoSamples {
            samples: 0
        }))
    ));
    assert!(matches!(
        fit.add(&StaticPose {
            ujoint_m: support(),
            ..article[0]
        }),
        Err(IdentificationError::SupportTooClose { .. })
    ));
    assert_eq!(fit, before);
    assert!(
        LineFit::new(&cal, V3::zeros(), 0.5)
            .unwrap()
            .add(&slightly)
            .is_ok()
    );

    let mut two = LineFit::new(&cal, V3::zeros(), 1e-3).unwrap();
    two.add(&article[0]).unwrap();
    two.add(&article[1]).unwrap();
    assert!(matches!(
        two.solve(),
        Err(IdentificationError::TooFewRows { needed: 3, .. })
    ));
    // article[0] and article[9] are both at a = 0.04 m.
    let mut same = LineFit::new(&cal, V3::zeros(), 1e-3).unwrap();
    for p in [article[0], article[9], article[0]] {
        same.add(&p).unwrap();
    }
    let e = same.solve().unwrap_err();
    assert!(is_ill_conditioned(&e), "{e:?}");

    for bad in [-0.1, f64::NAN, core::f64::consts::FRAC_PI_2, 3.0] {
        assert!(matches!(
            LineFit::new(&cal, V3::zeros(), bad),
            Err(IdentificationError::InvalidTolerance { .. })
        ));
    }
}

/// MODEL.md 5: a pose whose slide sign is unknown (the first pose of a
/// procedure, before any slide) is left out of the friction fit. With friction
/// estimated it adds only its two moment rows, so the friction that actually
/// acts on it, either way, does not move the estimate; without the friction
/// unknown it adds all three rows. (The old `slide_sign: 0.0` gave f the
/// coefficient 0 in the axial row: the pose's real friction then went into m.)
#[test]
fn unknown_slide_sign_leaves_the_pose_out_of_the_friction_fit() {
    let rotation = mounted_rotation();
    let cal = calibration(support(), rotation, gravity());
    let tare = V3::new(0.1, -0.2, 0.3);
    let t = truth(2.593, 0.103, 0.3);
    let cone = cone_protocol();
    let mut results = Vec::new();
    for physics_sigma in [1.0, -1.0] {
        let mut protocol = cone.clone();
        protocol[0].slide_sign = physics_sigma;
        let mut poses = ideal_poses(&t, &rotation, &tare, &protocol);
        poses[0].slide_sign = SlideSign::Unknown;
        let mut ident =
            Identification::new(&cal, &SensorNoise::hex6(), tare, FRICTION_ONLY).unwrap();
        ident.add(&poses[0]).unwrap();
        assert_eq!(ident.rows(), 2, "only the moment rows");
        for pose in &poses[1..] {
            ident.add(pose).unwrap();
        }
        assert_eq!(ident.rows(), 3 * 20 - 1);
        let r = ident.solve().unwrap();
        assert!((r.mass_kg - t.mass_kg).abs() < 1e-9 * t.mass_kg, "{r:?}");
        assert!((r.com_m - t.com_m).abs() < 1e-9 * t.com_m, "{r:?}");
        assert!((r.friction_n.unwrap() - 0.3).abs() < 1e-9, "{r:?}");
        results.push(r);
        // Without the friction unknown the pose gives its three rows.
        let mut plain = Identification::new(&cal, &SensorNoise::hex6(), tare, NO_EXTRAS).unwrap();
        plain.add(&poses[0]).unwrap();
        assert_eq!(plain.rows(), 3);
    }
    assert!((results[0].mass_kg - results[1].mass_kg).abs() < 1e-12);
    // Every sign unknown: f has no row at all.
    let unknown: Vec<StaticPose> = ideal_poses(&t, &rotation, &tare, &cone)
        .into_iter()
        .map(|p| StaticPose {
            slide_sign: SlideSign::Unknown,
            ..p
        })
        .collect();
    let e = identify(&cal, tare, FRICTION_ONLY, &unknown).unwrap_err();
    assert!(
        matches!(e, IdentificationError::IllConditioned { condition, .. } if condition == f64::INFINITY),
        "{e:?}"
    );
}

// ---------------------------------------------------------------------------
// Identification of the inertia (MODEL.md 10, identification::dynamic).

mod dynamic {
    use super::*;
    use sar_estimator::identification::dynamic::{DynamicIdentification, MotionSample};

    /// The excitation: per axis (amplitude m, frequency Hz, phase rad)
    /// around the nominal A = (0.25, 0.2, 0) of manipulator 2 (MODEL.md 10),
    /// speeds up to 0.04 m/s: a slow sweep of 8 cm along the rod (a from
    /// 0.12 to 0.28 m, which tells m from M as the static poses do) and
    /// faster sines across it (the rod's turning, which tells J_A).
    const SINES: [(f64, f64, f64); 3] = [
        (0.08, 0.07, 0.0),
        (0.04 / (2.0 * core::f64::consts::PI * 1.7), 1.7, 0.7),
        (0.04 / (2.0 * core::f64::consts::PI * 2.3), 2.3, 1.9),
    ];

    fn nominal_a() -> V3 {
        V3::new(0.25, 0.2, 0.0)
    }

    /// A(t), A'(t), A''(t).
    fn carriage(t: f64) -> (V3, V3, V3) {
        let mut p = nominal_a();
        let (mut v, mut a) = (V3::zeros(), V3::zeros());
        for (k, (amp, f, phase)) in SINES.iter().enumerate() {
            let w = 2.0 * core::f64::consts::PI * f;
            let arg = w * t + phase;
            p[k] += amp * (arg.sin() - phase.sin());
            v[k] = amp * w * arg.cos();
            a[k] = -amp * w * w * arg.sin();
        }
        (p, v, a)
    }

    /// An independent Newton-Euler: the COM's acceleration and the change of
    /// the angular momentum about the COM by central differences of
    /// positions only, moments about the COM (not A as the identification
    /// writes them). Returns F_A, {0}.
    fn newton_euler_force_a(t: f64, m: f64, c: f64, i_perp: f64, b: &V3, g: &V3) -> V3 {
        let u_at = |t: f64| {
            let r = b - carriage(t).0;
            r / r.norm()
        };
        let com_at = |t: f64| carriage(t).0 + u_at(t) * c;
        let h = 1e-4;
        let a_c = (com_at(t + h) - com_at(t) * 2.0 + com_at(t - h)) / (h * h);
        let u_dot = |t: f64| (u_at(t + h) - u_at(t - h)) / (2.0 * h);
        let momentum = |t: f64| u_at(t).cross(&u_dot(t)) * i_perp;
        let h_dot = (momentum(t + h) - momentum(t - h)) / (2.0 * h);
        let u = u_at(t);
        let rho = (b - carriage(t).0).norm();
        let k = (a_c - g) * m; // F_A + F_B
        // Moments about C: (A - C) x F_A + (B - C) x F_B = H', F_A = K - F_B.
        let rhs = h_dot + u.cross(&k) * c;
        let f_b = (rhs / rho).cross(&u);
        k - f_b
    }

    /// Identifies a rod with I_perp = `factor` m L^2 / 12 from 60 s of the
    /// excitation at 500 Hz, HEX-6 noise in a mounted sensor, seeded.
    fn run(factor: f64, seed: u64) -> (f64, sar_estimator::identification::dynamic::DynamicResult) {
        let (m, c, l) = (2.593, 0.103, 0.35);
        let i_perp = factor * m * l * l / 12.0;
        let rotation = mounted_rotation();
        let cal = calibration(support(), rotation, gravity());
        let mut id =
            DynamicIdentification::new(&cal, &SensorNoise::hex6(), V3::zeros(), 0.0, false)
                .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise: Vec<Normal<f64>> = SensorNoise::HEX6_STD_N
            .iter()
            .map(|&s| Normal::new(0.0, s).unwrap())
            .collect();
        for k in 0..30_000 {
            let t = f64::from(k) * 0.002;
            let (p, v, a) = carriage(t);
            let f_a = newton_euler_force_a(t, m, c, i_perp, &support(), &gravity());
            let mut reading = rotation.transpose() * (-f_a);
            for (x, n) in reading.iter_mut().zip(&noise) {
                *x += n.sample(&mut rng);
            }
            id.add(&MotionSample {
                ujoint_m: p,
                velocity_mps: v,
                accel_mps2: a,
                reading_n: reading,
            })
            .unwrap();
        }
        (i_perp, id.solve(1e8).unwrap())
    }

    /// Three rods whose I_perp is m L^2 / 12 times 0.7, 1 and 1.5 (seeds
    /// 2601, 2602, 2603): I_perp within 5 % and within 3 standard errors;
    /// m and c within 3 standard errors and within 0.1 %
    /// (the static identification's accuracy, MODEL.md 5.1: 0.1 %, 0.07 %).
    #[test]
    fn three_rods_from_an_independent_newton_euler_with_hex6_noise() {
        for (factor, seed) in [(0.7, 2601), (1.0, 2602), (1.5, 2603)] {
            let (i_true, r) = run(factor, seed);
            let i_err = r.inertia_perp_kgm2 / i_true - 1.0;
            let m_err = r.mass_kg / 2.593 - 1.0;
            let c_err = r.com_m / 0.103 - 1.0;
            println!(
                "I_perp x{factor}: I {:.5} (true {i_true:.5}) err {:+.2} % std {:.2} % (model {:.2} %), m err {:+.3} % std {:.3} %, c err {:+.3} % std {:.3} %, condition {:.1}, chi2/dof {:.3}, residual {:.3} N",
                r.inertia_perp_kgm2,
                100.0 * i_err,
                100.0 * r.inertia_perp_std_kgm2 / i_true,
                100.0 * r.inertia_perp_model_std_kgm2 / i_true,
                100.0 * m_err,
                100.0 * r.mass_std_kg / 2.593,
                100.0 * c_err,
                100.0 * r.com_std_m / 0.103,
                r.condition,
                r.chi2_dof,
                r.residual_rms_n
            );
            assert!(i_err.abs() < 0.05, "I_perp x{factor}: {i_err}");
            assert!(
                (r.inertia_perp_kgm2 - i_true).abs() < 3.0 * r.inertia_perp_std_kgm2,
                "I_perp x{factor}"
            );
            assert!(
                (r.mass_kg - 2.593).abs() < 3.0 * r.mass_std_kg,
                "m x{factor}"
            );
            assert!((r.com_m - 0.103).abs() < 3.0 * r.com_std_m, "c x{factor}");
            assert!(m_err.abs() < 1e-3 && c_err.abs() < 1e-3, "m, c x{factor}");
            assert!((r.chi2_dof - 1.0).abs() < 0.05, "chi2/dof {}", r.chi2_dof);
        }
    }

    /// No motion: J_A has no information: refused with its condition number.
    #[test]
    fn no_motion_is_refused_as_ill_conditioned() {
        let cal = calibration(support(), M3::identity(), gravity());
        let mut id =
            DynamicIdentification::new(&cal, &SensorNoise::hex6(), V3::zeros(), 0.0, false)
                .unwrap();
        for k in 0..100 {
            let p = nominal_a() + V3::new(0.001 * f64::from(k % 7), 0.0, 0.0);
            id.add(&MotionSample {
                ujoint_m: p,
                velocity_mps: V3::zeros(),
                accel_mps2: V3::zeros(),
                reading_n: V3::new(0.0, 25.0, 0.0),
            })
            .unwrap();
        }
        match id.solve(1e8) {
            Err(IdentificationError::IllConditioned { condition, .. }) => {
                assert!(condition > 1e8, "{condition}")
            }
            other => panic!("{other:?}"),
        }
    }
}
