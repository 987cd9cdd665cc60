//! The tip-force estimator (MODEL.md 4.1, 4.3) against the independent simulator
//! of `common`: accuracy over random poses and calibrations, the standard
//! deviation, the singularity, invalid input, and the MODEL.md 4.3 claim about
//! the support basis.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;

use common::{NoisySensor, Truth, ideal_reading, rod_frame, ujoint_force};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, SMatrix, Vector3};
use proptest::prelude::*;
use proptest::test_runner::{RngSeed, TestRunner};
use sar_estimator::tip_force::{
    TipForceConfig, TipForceError, TipForceEstimate, TipForceEstimator,
};
use sar_estimator::{SensorNoise, SettingError};
use sar_kinematics::{
    ActiveJoints, Calibration, CalibrationSpec, Pose, Profile, ProfileSpec, forward,
};
use std::cell::Cell;

const HEX6: [f64; 3] = SensorNoise::HEX6_STD_N;

fn config(cases: u32, seed: u64) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Everything random about one case.
#[derive(Debug, Clone)]
struct Params {
    p_home: [f64; 3],
    ujoint_offset: [f64; 3],
    sensor_offset: [f64; 3],
    support: [f64; 3],
    euler: [f64; 3],
    gravity_tilt: [f64; 2],
    length_m: f64,
    offset_m: f64,
    mass_kg: f64,
    com_frac: f64,
    q4: f64,
    q5: f64,
    /// s / L.
    support_frac: f64,
    tip_n: [f64; 3],
    bias_n: [f64; 3],
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

prop_compose! {
    fn params(offset: BoxedStrategy<f64>)(
        p_home in prop::array::uniform3(-0.5..0.5f64),
        ujoint_offset in prop::array::uniform3(-0.2..0.2f64),
        sensor_offset in prop::array::uniform3(-0.2..0.2f64),
        support in prop::array::uniform3(-0.5..0.5f64),
        euler in prop::array::uniform3(-3.1..3.1f64),
        gravity_tilt in prop::array::uniform2(-0.3..0.3f64),
        length_m in 0.2..0.5f64,
        offset_m in offset,
        mass_kg in 0.0..5.0f64,
        com_frac in -0.2..1.2f64,
        q4 in -3.1..3.1f64,
        q5 in -1.0..1.0f64,
        support_frac in 0.05..0.9f64,
        tip_n in prop::array::uniform3(-50.0..50.0f64),
        bias_n in prop::array::uniform3(-20.0..20.0f64),
    ) -> Params {
        Params {
            p_home, ujoint_offset, sensor_offset, support, euler, gravity_tilt, length_m,
            offset_m, mass_kg, com_frac, q4, q5, support_frac, tip_n, bias_n,
        }
    }
}

fn zero_offset() -> BoxedStrategy<f64> {
    Just(0.0).boxed()
}

fn nonzero_offset() -> BoxedStrategy<f64> {
    (0.001..0.03f64, any::<bool>())
        .prop_map(|(d, neg)| if neg { -d } else { d })
        .boxed()
}

/// Cases whose support lies ahead of A along the rod's heading: B - A = d w + s u
/// has a horizontal part along +heading. Otherwise (short s, steep rod, large d)
/// the line through B at offset d is the other kinematic branch (MODEL.md 3),
/// heading away from B, and the forward kinematics rightly give that one.
fn on_the_physical_branch(p: &Params) -> bool {
    let s = p.support_frac * p.length_m;
    s * p.q5.cos() + p.offset_m * p.q5.sin() > 0.2 * s
}

fn cases(offset: BoxedStrategy<f64>) -> impl Strategy<Value = Params> {
    params(offset).prop_filter("support ahead of A", on_the_physical_branch)
}

/// One scripted situation and what the simulator says the sensor reads.
#[derive(Debug, Clone)]
struct Case {
    cal: Calibration,
    profile: Profile,
    truth: Truth,
    pose: Pose,
    rotation: Matrix3<f64>,
    u: Vector3<f64>,
    w: Vector3<f64>,
    a_m: Vector3<f64>,
    tip_n: Vector3<f64>,
    f_a: Vector3<f64>,
    torsion_nm: f64,
    bias_n: Vector3<f64>,
    reading_n: Vector3<f64>,
}

/// Builds the calibration so that B lies on the rod: choose B, q4, q5 and s,
/// then A = B - d w - s u, and the active joints from A.
fn build(p: &Params) -> Case {
    let rotation = Rotation3::from_euler_angles(p.euler[0], p.euler[1], p.euler[2]).into_inner();
    let g_dir = Vector3::new(p.gravity_tilt[0], -1.0, p.gravity_tilt[1]).normalize();
    let support = v3(p.support) + Vector3::new(0.6, 0.0, 0.0);
    let cal = Calibration::new(&CalibrationSpec {
        p_home_m: v3(p.p_home),
        ujoint_offset_m: v3(p.ujoint_offset),
        sensor_offset_m: v3(p.sensor_offset),
        sensor_rotation: rotation,
        support_m: support,
        gravity_mps2: g_dir * 9.80665,
    })
    .unwrap();
    let com_m = p.com_frac * p.length_m;
    let profile = Profile::new(&ProfileSpec {
        length_m: p.length_m,
        offset_m: p.offset_m,
        mass_kg: p.mass_kg,
        com_m,
    })
    .unwrap();
    let s = p.support_frac * p.length_m;
    let (u, w) = rod_frame(p.q4, p.q5);
    let a_m = support - w * p.offset_m - u * s;
    let q = a_m - cal.ujoint_offset_m() - cal.p_home_m();
    let joints = ActiveJoints {
        q1_m: q.z,
        q2_m: q.y,
        q3_m: q.x,
    };
    let pose = forward(&cal, &profile, &joints).unwrap();
    // Premise: the kinematics put the rod where the test put it.
    assert!(
        (pose.rod_dir - u).norm() < 1e-9,
        "{:?} vs {u:?}",
        pose.rod_dir
    );
    assert!((pose.rod_normal - w).norm() < 1e-9);
    assert!((pose.support_along_rod_m - s).abs() < 1e-9);
    let truth = Truth {
        mass_kg: p.mass_kg,
        com_m,
        length_m: p.length_m,
        offset_m: p.offset_m,
        support_m: support,
        gravity_mps2: cal.gravity_mps2(),
        friction_n: 0.0,
    };
    let tip_n = v3(p.tip_n);
    let (f_a, torsion_nm) = ujoint_force(&truth, &a_m, &u, &w, &tip_n, 0.0);
    let bias_n = v3(p.bias_n);
    let reading_n = ideal_reading(&rotation, &f_a, &bias_n);
    Case {
        cal,
        profile,
        truth,
        pose,
        rotation,
        u,
        w,
        a_m,
        tip_n,
        f_a,
        torsion_nm,
        bias_n,
        reading_n,
    }
}

fn estimator(case: &Case, max_std_n: f64) -> TipForceEstimator {
    TipForceEstimator::new(
        &case.cal,
        &case.profile,
        &SensorNoise::hex6(),
        TipForceConfig { max_std_n },
    )
    .unwrap()
}

/// Force scale of a case: what round-off is relative to.
fn force_scale(case: &Case) -> f64 {
    1.0 + case.tip_n.norm() + case.f_a.norm() + case.truth.mass_kg * 9.80665
}

/// Relative tolerance against the simulator (its LU solve leaves residuals
/// near 1e-15 relative); the equilibrium residual below is the tighter check.
const SIMULATOR_TOLERANCE: f64 = 1e-9;

/// Relative tolerance of the six equilibrium equations with the estimate.
const EQUILIBRIUM_TOLERANCE: f64 = 1e-12;

/// Checks one estimate against the script (returns the relative force error),
/// and checks that the estimate (F_tip, M_T) with the measured F_A satisfies
/// MODEL.md 4 exactly: F_B = -(F_A + m g + F_D) is across u (frictionless),
/// and the moments about A vanish. Returns (error vs simulator, residual).
fn check_estimate(case: &Case, est: &TipForceEstimate) -> (f64, f64) {
    let scale = force_scale(case);
    let err = (est.force_n - case.tip_n).norm() / scale;
    assert!(
        err < SIMULATOR_TOLERANCE,
        "force {:?} vs {:?}",
        est.force_n,
        case.tip_n
    );
    assert!((est.ujoint_force_n - case.f_a).norm() / scale < 1e-12);
    let length = case.truth.length_m;
    let torsion_err = (est.torsion_nm - case.torsion_nm).abs() / (scale * length);
    assert!(
        torsion_err < SIMULATOR_TOLERANCE,
        "torsion {} vs {}",
        est.torsion_nm,
        case.torsion_nm
    );
    let axial = est.force_n.dot(&case.u);
    let lateral = (est.force_n - case.u * axial).norm();
    assert!((est.axial_n - axial).abs() / scale < 1e-12);
    assert!((est.lateral_n - lateral).abs() / scale < 1e-12);

    let residual = equilibrium_residual(case, &est.force_n, &est.ujoint_force_n, est.torsion_nm);
    assert!(
        residual < EQUILIBRIUM_TOLERANCE,
        "equilibrium residual {residual:e}"
    );
    (err, residual)
}

/// The largest residual of the six equations of MODEL.md 4, relative to the
/// force scale, for a tip force, F_A and torsion: F_B = -(F_A + m g + F_D) must
/// be across u (frictionless), and the moments about A must vanish.
fn equilibrium_residual(
    case: &Case,
    tip_n: &Vector3<f64>,
    f_a: &Vector3<f64>,
    torsion_nm: f64,
) -> f64 {
    let scale = force_scale(case);
    let t = &case.truth;
    let weight = t.gravity_mps2 * t.mass_kg;
    let f_d = -tip_n;
    let f_b = -(f_a + weight + f_d);
    let a_m = case.pose.ujoint_m;
    // MODEL.md 4: n = -(s4, 0, c4).
    let q4 = case.pose.q4_rad();
    let n = -Vector3::new(q4.sin(), 0.0, q4.cos());
    let moment = (t.support_m - a_m).cross(&f_b)
        + (case.pose.com_m - a_m).cross(&weight)
        + (case.pose.tip_m - a_m).cross(&f_d)
        + n * torsion_nm;
    (f_b.dot(&case.u).abs() / scale).max(moment.norm() / (scale * t.length_m))
}

/// Runs `test` over `cases` cases of `strategy` with a fixed seed.
fn run_cases<S: Strategy>(cases: u32, seed: u64, strategy: S, test: impl Fn(S::Value))
where
    S::Value: core::fmt::Debug,
{
    let mut runner = TestRunner::new(config(cases, seed));
    if let Err(e) = runner.run(&strategy, |v| {
        test(v);
        Ok(())
    }) {
        panic!("{e}");
    }
}

fn accuracy(offset: BoxedStrategy<f64>, seed: u64, label: &str) {
    // Worst: error vs simulator, residual of the estimate, residual of the simulator.
    let worst = Cell::new([0.0_f64; 3]);
    run_cases(2000, seed, cases(offset), |p| {
        let case = build(&p);
        let est = estimator(&case, 1e9)
            .estimate(&case.pose, &case.reading_n, &case.bias_n)
            .unwrap();
        let (err, residual) = check_estimate(&case, &est);
        if case.truth.offset_m == 0.0 {
            assert_eq!(est.torsion_nm, 0.0);
        }
        let simulator = equilibrium_residual(&case, &case.tip_n, &case.f_a, case.torsion_nm);
        let w = worst.get();
        worst.set([w[0].max(err), w[1].max(residual), w[2].max(simulator)]);
    });
    let [e, r, sim] = worst.get();
    println!(
        "{label}: worst relative error vs simulator {e:.2e}; worst equilibrium residual: \
         estimate {r:.2e}, simulator {sim:.2e}"
    );
}

/// d = 0: the closed form gives the scripted tip force, and zero torsion.
#[test]
fn closed_form_matches_the_simulator() {
    accuracy(zero_offset(), 0x7150_0001, "d = 0");
}

/// d != 0: the 6x6 solve gives the scripted tip force and torsion.
#[test]
fn offset_solve_matches_the_simulator() {
    accuracy(nonzero_offset(), 0x7150_0002, "d != 0");
}

/// Friction at the support cannot be told from an axial tip force (MODEL.md
/// 4.1): it shows up, whole, along u, and nowhere else.
#[test]
fn friction_reads_as_an_axial_tip_force() {
    let strategy = (cases(zero_offset()), 0.0..5.0f64, any::<bool>());
    run_cases(
        1000,
        0x7150_0003,
        strategy,
        |(p, friction_n, slide_positive)| {
            let mut case = build(&p);
            let slide_sign = if slide_positive { 1.0 } else { -1.0 };
            case.truth.friction_n = friction_n;
            let (f_a, _) = ujoint_force(
                &case.truth,
                &case.a_m,
                &case.u,
                &case.w,
                &case.tip_n,
                slide_sign,
            );
            let reading = ideal_reading(&case.rotation, &f_a, &case.bias_n);
            let est = estimator(&case, 1e9)
                .estimate(&case.pose, &reading, &case.bias_n)
                .unwrap();
            let expected = case.tip_n + case.u * (slide_sign * friction_n);
            assert!((est.force_n - expected).norm() < SIMULATOR_TOLERANCE * force_scale(&case));
        },
    );
}

/// dF_tip/d(reading) from the independent simulator: F_A is affine in the tip
/// force, F_A = M F_tip + const, so dF_tip/dF_A = M^-1 and
/// dF_tip/d(reading) = M^-1 (-R_0s).
fn simulator_jacobian(case: &Case) -> DMatrix<f64> {
    let (base, _) = ujoint_force(
        &case.truth,
        &case.a_m,
        &case.u,
        &case.w,
        &Vector3::zeros(),
        0.0,
    );
    let mut m = DMatrix::<f64>::zeros(3, 3);
    for j in 0..3 {
        let mut unit = Vector3::zeros();
        unit[j] = 1.0;
        let (f_a, _) = ujoint_force(&case.truth, &case.a_m, &case.u, &case.w, &unit, 0.0);
        let col = f_a - base;
        for i in 0..3 {
            m[(i, j)] = col[i];
        }
    }
    let r = DMatrix::from_fn(3, 3, |i, j| -case.rotation[(i, j)]);
    m.try_inverse().unwrap() * r
}

/// dF_tip/d(reading) of the estimator itself, by central differences.
fn estimator_jacobian(case: &Case, est: &TipForceEstimator) -> DMatrix<f64> {
    let h = 1.0;
    let mut jac = DMatrix::<f64>::zeros(3, 3);
    for j in 0..3 {
        let mut plus = case.reading_n;
        plus[j] += h;
        let mut minus = case.reading_n;
        minus[j] -= h;
        let fp = est
            .estimate(&case.pose, &plus, &case.bias_n)
            .unwrap()
            .force_n;
        let fm = est
            .estimate(&case.pose, &minus, &case.bias_n)
            .unwrap()
            .force_n;
        for i in 0..3 {
            jac[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
    jac
}

fn std_from_jacobian(jac: &DMatrix<f64>) -> Vector3<f64> {
    let var = DMatrix::from_diagonal(&DVector::from_iterator(3, HEX6.iter().map(|s| s * s)));
    let cov = jac * var * jac.transpose();
    Vector3::new(cov[(0, 0)].sqrt(), cov[(1, 1)].sqrt(), cov[(2, 2)].sqrt())
}

fn check_std(case: &Case) {
    let est = estimator(case, 1e9);
    let out = est
        .estimate(&case.pose, &case.reading_n, &case.bias_n)
        .unwrap();
    let own = estimator_jacobian(case, &est);
    let sim = simulator_jacobian(case);
    assert!(
        (&own - &sim).amax() < SIMULATOR_TOLERANCE * sim.amax(),
        "jacobians differ:\n{own}\n{sim}"
    );
    // The reported std is the covariance propagated through the map the
    // estimator applies (tight), which is the simulator's map (to its accuracy).
    for (jac, tol) in [(&own, 1e-9), (&sim, SIMULATOR_TOLERANCE)] {
        let expected = std_from_jacobian(jac);
        assert!(
            (out.std_n - expected).amax() < tol * expected.amax(),
            "std {:?} vs {expected:?}",
            out.std_n
        );
    }
}

/// The std (d = 0) is the sensor covariance propagated through the
/// simulator's own linear map, and the estimator's map is that map.
#[test]
fn closed_form_std_matches_the_simulator_jacobian() {
    run_cases(1000, 0x7150_0004, cases(zero_offset()), |p| {
        check_std(&build(&p))
    });
}

/// The same with d != 0.
#[test]
fn offset_std_matches_the_simulator_jacobian() {
    run_cases(1000, 0x7150_0005, cases(nonzero_offset()), |p| {
        check_std(&build(&p))
    });
}

/// Manipulator 2 of the article at a typical pose (a = 0.15 m).
fn base_params(q4: f64, q5: f64, euler: [f64; 3]) -> Params {
    Params {
        p_home: [0.0; 3],
        ujoint_offset: [0.0, -0.05, 0.0],
        sensor_offset: [0.0, 0.03, 0.0],
        support: [0.0, 0.2, 0.0],
        euler,
        gravity_tilt: [0.0, 0.0],
        length_m: 0.35,
        offset_m: 0.0,
        mass_kg: 2.593,
        com_frac: 0.103 / 0.35,
        q4,
        q5,
        support_frac: 0.15 / 0.35,
        tip_n: [1.0, 2.0, 3.0],
        bias_n: [1.0, -2.0, 0.5],
    }
}

fn typical(offset_m: f64, q4: f64, q5: f64, euler: [f64; 3], tip_n: [f64; 3]) -> Case {
    build(&Params {
        offset_m,
        tip_n,
        ..base_params(q4, q5, euler)
    })
}

const NOMINAL_Q4: f64 = core::f64::consts::FRAC_PI_2;

/// At the nominal pose (u = X0) with R_0s = I, J = diag(1, -k, -k) with
/// k = a / (L - a), so std = (s_x, k s_y, k s_z): derived by hand.
#[test]
fn typical_pose_std_is_the_hand_derived_one() {
    let case = typical(0.0, NOMINAL_Q4, 0.0, [0.0; 3], [2.0, -3.0, 1.0]);
    let out = estimator(&case, 5.0)
        .estimate(&case.pose, &case.reading_n, &case.bias_n)
        .unwrap();
    let k = 0.15 / (0.35 - 0.15);
    let expected = Vector3::new(HEX6[0], k * HEX6[1], k * HEX6[2]);
    assert!((out.std_n - expected).amax() < 1e-12, "{:?}", out.std_n);
    println!("typical pose, R_0s = I: std_n = {:?}", out.std_n);
    // Sensor hanging with its z axis vertical (along -Y0): the 0.8 N axis is Y0.
    let hanging = typical(
        0.0,
        NOMINAL_Q4,
        0.0,
        [core::f64::consts::FRAC_PI_2, 0.0, 0.0],
        [2.0, -3.0, 1.0],
    );
    let out = estimator(&hanging, 5.0)
        .estimate(&hanging.pose, &hanging.reading_n, &hanging.bias_n)
        .unwrap();
    let expected = Vector3::new(HEX6[0], k * HEX6[2], k * HEX6[1]);
    assert!((out.std_n - expected).amax() < 1e-12, "{:?}", out.std_n);
    println!("typical pose, sensor z vertical: std_n = {:?}", out.std_n);
    // Tilted and turned, for the record (checked against the simulator elsewhere).
    let tilted = typical(0.0, 1.2, 0.3, [0.3, -0.2, 0.1], [2.0, -3.0, 1.0]);
    let out = estimator(&tilted, 5.0)
        .estimate(&tilted.pose, &tilted.reading_n, &tilted.bias_n)
        .unwrap();
    println!("tilted pose (q4 1.2, q5 0.3): std_n = {:?}", out.std_n);
}

/// Monte-Carlo with the seeded HEX-6 noise: the sample standard deviation of
/// the estimates is the reported one, and the mean is the scripted force.
#[test]
fn monte_carlo_std_matches_the_reported_std() {
    for (offset_m, q4, q5, euler, seed) in [
        (0.0, NOMINAL_Q4, 0.0, [0.0; 3], 11),
        (0.0, 1.2, 0.3, [0.3, -0.2, 0.1], 12),
        (0.01, 1.9, -0.2, [-1.0, 0.5, 2.0], 13),
    ] {
        let case = typical(offset_m, q4, q5, euler, [2.0, -3.0, 1.0]);
        let est = estimator(&case, 5.0);
        let reported = est
            .estimate(&case.pose, &case.reading_n, &case.bias_n)
            .unwrap()
            .std_n;
        let mut sensor = NoisySensor::new(HEX6, seed);
        let n = 40_000;
        let mut sum = Vector3::zeros();
        let mut sum_sq = Vector3::zeros();
        for _ in 0..n {
            let reading = sensor.sample(&case.reading_n);
            let f = est
                .estimate(&case.pose, &reading, &case.bias_n)
                .unwrap()
                .force_n;
            let dev = f - case.tip_n;
            sum += dev;
            sum_sq += dev.component_mul(&dev);
        }
        let nf = f64::from(n);
        let mean = sum / nf;
        let sample_std = (sum_sq / nf - mean.component_mul(&mean)).map(f64::sqrt);
        for i in 0..3 {
            // Sampling error of a std over 40000 samples: 0.35 % (1 sigma).
            let rel = (sample_std[i] / reported[i] - 1.0).abs();
            assert!(
                rel < 0.02,
                "axis {i}: sample {sample_std:?} vs reported {reported:?}"
            );
            assert!(
                mean[i].abs() < 5.0 * reported[i] / nf.sqrt(),
                "bias {mean:?}"
            );
        }
    }
}

/// Near the singularity (a -> L) the std grows like a / (L - a), and past the
/// limit the estimator flags the number not observable (and keeps it).
#[test]
fn std_grows_like_a_over_lever_and_becomes_not_observable() {
    let length = 0.35;
    for (q4, q5, euler) in [
        (NOMINAL_Q4, 0.0, [0.0; 3]),
        (1.2, 0.3, [0.3, -0.2, 0.1]),
        (-2.0, -0.6, [2.0, 1.0, -0.4]),
    ] {
        let rotation = Rotation3::from_euler_angles(euler[0], euler[1], euler[2]).into_inner();
        let (u, _) = rod_frame(q4, q5);
        // The limit of std / k as k -> infinity: sqrt(diag(P C P)), P = I - u u^T.
        let p = Matrix3::identity() - u * u.transpose();
        let c = rotation * Matrix3::from_diagonal(&v3(HEX6).map(|s| s * s)) * rotation.transpose();
        let limit = (p * c * p).diagonal().map(f64::sqrt);
        let mut previous_gap = f64::INFINITY;
        for lever in [0.1, 0.01, 1e-3, 1e-4] {
            let a = length - lever;
            let params = build(&Params {
                support_frac: a / length,
                ..base_params(q4, q5, euler)
            });
            let k = a / lever;
            let out = estimator(&params, 1e12)
                .estimate(&params.pose, &params.reading_n, &params.bias_n)
                .unwrap();
            let ratio = out.std_n / k;
            let gap = (ratio - limit).amax();
            // The approach is O(1/k).
            assert!(gap < 2.0 / k, "lever {lever}: {ratio:?} vs {limit:?}");
            assert!(gap <= previous_gap);
            previous_gap = gap;
            // With the limit at 5 N this is reported as not observable as soon as
            // the largest std passes 5 N.
            let guarded =
                estimator(&params, 5.0).estimate(&params.pose, &params.reading_n, &params.bias_n);
            let worst = out.std_n.amax();
            // The number is kept (bit for bit the unlimited one); only the
            // flag says whether it is observable.
            let guarded = guarded.unwrap();
            assert_eq!(guarded.force_n, out.force_n, "lever {lever}");
            assert_eq!(guarded.std_n, out.std_n, "lever {lever}");
            assert_eq!(guarded.observable, worst <= 5.0, "lever {lever}: {worst}");
            assert!(out.observable);
        }
    }
}

/// A pose with the tip at or behind the support (a >= L) is singular: reported
/// as not observable with an infinite std, never as a number.
#[test]
fn lever_not_positive_is_not_observable() {
    let case = typical(0.0, NOMINAL_Q4, 0.0, [0.0; 3], [0.0; 3]);
    let est = estimator(&case, 5.0);
    for a in [0.35, 0.35 + 1e-12, 0.4, 10.0] {
        let mut pose = case.pose;
        pose.support_distance_m = a;
        pose.support_along_rod_m = a;
        match est.estimate(&pose, &case.reading_n, &case.bias_n) {
            Err(TipForceError::NotObservable { lever_m, std_max_n }) => {
                assert_eq!(lever_m, 0.35 - a);
                assert_eq!(std_max_n, f64::INFINITY);
            }
            other => panic!("a = {a}: {other:?}"),
        }
    }
    // Just short of L: finite but huge std: a number, flagged not observable.
    let mut pose = case.pose;
    pose.support_distance_m = 0.35 - 1e-9;
    let near = est.estimate(&pose, &case.reading_n, &case.bias_n).unwrap();
    assert!(!near.observable);
    assert!(near.std_n.amax() > 1e7, "{:?}", near.std_n);
}

/// The same singularity with d != 0 (the 6x6 path).
#[test]
fn offset_near_the_support_is_not_observable() {
    let length = 0.35;
    for lever in [0.01, 1e-3, 1e-5] {
        let case = build(&Params {
            offset_m: 0.005,
            support_frac: (length - lever) / length,
            ..base_params(1.2, 0.3, [0.3, -0.2, 0.1])
        });
        let out = estimator(&case, 5.0).estimate(&case.pose, &case.reading_n, &case.bias_n);
        match out {
            Ok(estimate) => {
                assert!(!estimate.observable, "lever {lever}");
                assert!(estimate.std_n.amax() > 5.0, "lever {lever}");
            }
            // Singular to the pivot check: no number at all.
            Err(TipForceError::NotObservable { lever_m, std_max_n }) => {
                assert!((lever_m - lever).abs() < 1e-9);
                assert_eq!(std_max_n, f64::INFINITY);
            }
            other => panic!("lever {lever}: {other:?}"),
        }
    }
    let case = build(&Params {
        offset_m: 0.005,
        ..base_params(1.2, 0.3, [0.3, -0.2, 0.1])
    });
    let est = estimator(&case, 5.0);
    for s in [0.35, 0.5] {
        let mut pose = case.pose;
        pose.support_along_rod_m = s;
        assert!(matches!(
            est.estimate(&pose, &case.reading_n, &case.bias_n),
            Err(TipForceError::NotObservable { std_max_n, .. }) if std_max_n == f64::INFINITY
        ));
    }
}

/// NaN or infinite input is a typed error, for every component of each input.
#[test]
fn non_finite_input_is_refused() {
    for offset_m in [0.0, 0.004] {
        let case = typical(offset_m, 1.2, 0.3, [0.3, -0.2, 0.1], [2.0, -3.0, 1.0]);
        let est = estimator(&case, 5.0);
        assert!(
            est.estimate(&case.pose, &case.reading_n, &case.bias_n)
                .is_ok()
        );
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for i in 0..3 {
                let mut reading = case.reading_n;
                reading[i] = bad;
                let out = est.estimate(&case.pose, &reading, &case.bias_n);
                assert!(
                    matches!(out, Err(TipForceError::NonFinite { input: "reading_n", value })
                        if value.to_bits() == bad.to_bits()),
                    "{out:?}"
                );
                let mut bias = case.bias_n;
                bias[i] = bad;
                let out = est.estimate(&case.pose, &case.reading_n, &bias);
                assert!(
                    matches!(out, Err(TipForceError::NonFinite { input: "bias_n", value })
                        if value.to_bits() == bad.to_bits()),
                    "{out:?}"
                );
                let mut pose = case.pose;
                pose.rod_dir[i] = bad;
                assert!(matches!(
                    est.estimate(&pose, &case.reading_n, &case.bias_n),
                    Err(TipForceError::NonFinite { .. })
                ));
            }
            let mut pose = case.pose;
            pose.support_distance_m = bad;
            pose.support_along_rod_m = bad;
            assert!(matches!(
                est.estimate(&pose, &case.reading_n, &case.bias_n),
                Err(TipForceError::NonFinite { .. })
            ));
        }
        // Finite but absurd: overflow is an error too, not an infinite force.
        let huge = Vector3::new(1e308, -1e308, 1e308);
        let out = est.estimate(&case.pose, &huge, &(-huge));
        assert!(out.is_err(), "{out:?}");
        // A pose that is not one: u not unit.
        let mut pose = case.pose;
        pose.rod_dir *= 1.01;
        assert!(matches!(
            est.estimate(&pose, &case.reading_n, &case.bias_n),
            Err(TipForceError::InvalidPose { .. })
        ));
    }
}

#[test]
fn invalid_config_is_refused() {
    let case = typical(0.0, NOMINAL_Q4, 0.0, [0.0; 3], [0.0; 3]);
    for max_std_n in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let out = TipForceEstimator::new(
            &case.cal,
            &case.profile,
            &SensorNoise::hex6(),
            TipForceConfig { max_std_n },
        );
        assert!(
            matches!(
                out,
                Err(SettingError::Invalid {
                    field: "max_std_n",
                    ..
                })
            ),
            "{max_std_n}: {out:?}"
        );
    }
}

/// The wrong variant of MODEL.md 4.3 (test only): the torsion is an unknown,
/// but the support force is written in the article's basis across r_AB
/// (u_B1 = g x r_AB / |..|, u_B2 = u_B1 x r_AB / |..|) instead of across u.
fn tip_force_basis_across_r_ab(case: &Case) -> Vector3<f64> {
    let t = &case.truth;
    let r_b = t.support_m - case.a_m;
    let r_c = case.w * t.offset_m + case.u * t.com_m;
    let r_d = case.w * t.offset_m + case.u * t.length_m;
    let g = t.gravity_mps2;
    let u_b1 = g.cross(&r_b).normalize();
    let u_b2 = u_b1.cross(&r_b).normalize();
    let n = -Vector3::new(case.u.x, 0.0, case.u.z).normalize();
    let weight = g * t.mass_kg;
    let mut k = DMatrix::<f64>::zeros(6, 6);
    let mut rhs = DVector::<f64>::zeros(6);
    for i in 0..3 {
        k[(i, i)] = 1.0;
        k[(i, 3)] = u_b1[i];
        k[(i, 4)] = u_b2[i];
        rhs[i] = -(case.f_a[i] + weight[i]);
    }
    let (m1, m2, known) = (r_b.cross(&u_b1), r_b.cross(&u_b2), r_c.cross(&weight));
    for i in 0..3 {
        for j in 0..3 {
            // (r_d x F_D)_i = sum_j [r_d]x_ij F_D_j
            let e = Vector3::ith(j, 1.0);
            k[(3 + i, j)] = r_d.cross(&e)[i];
        }
        k[(3 + i, 3)] = m1[i];
        k[(3 + i, 4)] = m2[i];
        k[(3 + i, 5)] = n[i];
        rhs[3 + i] = -known[i];
    }
    let x = k.lu().solve(&rhs).unwrap();
    -Vector3::new(x[0], x[1], x[2])
}

/// MODEL.md 4.3: with d != 0 the basis across r_AB gives errors of order
/// 0.5 N at d = 2 mm and 2.5 N at d = 10 mm; the basis across u is exact.
#[test]
fn basis_across_r_ab_is_wrong_with_an_offset() {
    let poses = [
        (NOMINAL_Q4, 0.0, [0.0, 0.0, 0.0]),
        (NOMINAL_Q4, 0.0, [5.0, 0.0, 0.0]),
        (NOMINAL_Q4, 0.0, [0.0, -5.0, 2.0]),
        (1.2, 0.3, [0.0, 0.0, 0.0]),
        (1.9, -0.4, [3.0, 2.0, -4.0]),
        (NOMINAL_Q4, 0.2, [0.0, -10.0, 0.0]),
    ];
    let mut worst = [0.0_f64; 2];
    for (q4, q5, tip) in poses {
        let mut errors = [0.0; 2];
        for (slot, d) in [0.002, 0.010].into_iter().enumerate() {
            let case = typical(d, q4, q5, [0.3, -0.2, 0.1], tip);
            let right = estimator(&case, 5.0)
                .estimate(&case.pose, &case.reading_n, &case.bias_n)
                .unwrap()
                .force_n;
            assert!((right - case.tip_n).norm() < 1e-9 * force_scale(&case));
            let wrong = tip_force_basis_across_r_ab(&case);
            errors[slot] = (wrong - case.tip_n).norm();
            worst[slot] = worst[slot].max(errors[slot]);
        }
        println!(
            "q4 {q4:.3} q5 {q5:.3} tip {tip:?}: basis across r_AB errs {:.3} N at d = 2 mm, {:.3} N at d = 10 mm",
            errors[0], errors[1]
        );
        // Proportional to d, to first order.
        let ratio = errors[1] / errors[0];
        assert!((4.0..6.5).contains(&ratio), "ratio {ratio}");
    }
    println!(
        "worst: {:.3} N at 2 mm, {:.3} N at 10 mm",
        worst[0], worst[1]
    );
    // The order of magnitude of MODEL.md 4.3 (loosely: within a factor 3).
    assert!((0.5 / 3.0..0.5 * 3.0).contains(&worst[0]), "{worst:?}");
    assert!((2.5 / 3.0..2.5 * 3.0).contains(&worst[1]), "{worst:?}");
}

/// d != 0 with the rod tilted up past the vertical (q5 = 1.8 rad, c5 < 0), a
/// pose the forward kinematics give when B is close above A: the torsion is
/// reported along MODEL.md's n = -(s4, 0, c4), not along -(ux, 0, uz)/|..|
/// (which is +(s4, 0, c4) here), matches the simulator's, and the six
/// equilibrium equations hold with it.
#[test]
fn torsion_follows_the_model_axis_when_c5_is_negative() {
    let case = build(&Params {
        offset_m: 0.03,
        support_frac: 0.05 / 0.35,
        ..base_params(1.2, 1.8, [0.3, -0.2, 0.1])
    });
    assert!(case.pose.q5_rad().cos() < 0.0);
    let est = estimator(&case, 1e9)
        .estimate(&case.pose, &case.reading_n, &case.bias_n)
        .unwrap();
    assert!((est.force_n - case.tip_n).norm() < 1e-9 * force_scale(&case));
    assert!(case.torsion_nm.abs() > 1e-3, "{}", case.torsion_nm);
    assert!(
        (est.torsion_nm - case.torsion_nm).abs() < 1e-9 * force_scale(&case),
        "{} vs {}",
        est.torsion_nm,
        case.torsion_nm
    );
    let residual = equilibrium_residual(&case, &est.force_n, &est.ujoint_force_n, est.torsion_nm);
    assert!(residual < EQUILIBRIUM_TOLERANCE, "{residual:e}");
}

/// Signs by hand, without the simulator: rod horizontal along +X0 (u = X0),
/// a = 0.15 m, L = 0.35 m, R_0s = I, no bias.
/// - Massless rod, the tip pushing 5 N into the tissue along +X0: the tissue
///   pushes back (F_D = -5 X0), the support takes nothing along u, so the robot
///   pushes F_A = +5 X0 and the sensor reads what the tool applies to it,
///   f_s = -F_A = (-5, 0, 0). That reading must give F_tip = (+5, 0, 0).
/// - Massless rod, the tip pushing 2 N sideways along +Z0: moments about A give
///   F_B = -(L / a) F_D, so F_A = -F_B - F_D = ((L - a) / a) F_D
///   = -(0.2 / 0.15) 2 Z0 and f_s = (0, 0, +8/3).
/// - A 2 kg rod with c = 0.1 m, nothing at the tip: F_A,y = m|g| - m c |g| / a
///   (MODEL.md 5.2), so f_s,y = -(2 - 0.2 / 0.15) |g| gives F_tip = 0.
#[test]
fn signs_by_hand_on_a_horizontal_rod() {
    let g = 9.80665;
    let support = Vector3::new(0.45, 0.2, 0.0);
    let cal = Calibration::new(&CalibrationSpec {
        p_home_m: Vector3::zeros(),
        ujoint_offset_m: Vector3::zeros(),
        sensor_offset_m: Vector3::zeros(),
        sensor_rotation: Matrix3::identity(),
        support_m: support,
        gravity_mps2: Vector3::new(0.0, -g, 0.0),
    })
    .unwrap();
    let joints = ActiveJoints {
        q1_m: 0.0,
        q2_m: 0.2,
        q3_m: 0.3,
    };
    for (mass_kg, reading, expected) in [
        (
            0.0,
            Vector3::new(-5.0, 0.0, 0.0),
            Vector3::new(5.0, 0.0, 0.0),
        ),
        (
            0.0,
            Vector3::new(0.0, 0.0, 8.0 / 3.0),
            Vector3::new(0.0, 0.0, 2.0),
        ),
        (
            2.0,
            Vector3::new(0.0, -(2.0 - 0.2 / 0.15) * g, 0.0),
            Vector3::zeros(),
        ),
    ] {
        let profile = Profile::new(&ProfileSpec {
            length_m: 0.35,
            offset_m: 0.0,
            mass_kg,
            com_m: 0.1,
        })
        .unwrap();
        let pose = forward(&cal, &profile, &joints).unwrap();
        assert!((pose.rod_dir - Vector3::x()).norm() < 1e-15);
        assert!((pose.support_distance_m - 0.15).abs() < 1e-15);
        let est = TipForceEstimator::new(
            &cal,
            &profile,
            &SensorNoise::hex6(),
            TipForceConfig { max_std_n: 5.0 },
        )
        .unwrap()
        .estimate(&pose, &reading, &Vector3::zeros())
        .unwrap();
        assert!(
            (est.force_n - expected).norm() < 1e-12,
            "reading {reading:?}: {:?} vs {expected:?}",
            est.force_n
        );
        assert!((est.axial_n - expected.x).abs() < 1e-12);
    }
}

// ---------------------------------------------------------------------------
// d != 0: the closed form against the dense 6x6 solve it replaced.

/// The dense reference of MODEL.md 4.3 (what the estimator computed before its
/// closed form): the six equilibrium equations, equilibrated so that every
/// entry is dimensionless (moment rows divided by L, the torsion unknown taken
/// as M_T / L), solved by LU for the measurement and for [I; 0], whose
/// solution's top block is dF_tip/dF_A. Returns (F_tip, per-axis std, M_T), or
/// None where a pivot is below 1e-12 (singular).
fn dense_reference(case: &Case) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    let pose = &case.pose;
    let (u, w, s) = (pose.rod_dir, pose.rod_normal, pose.support_along_rod_m);
    let length = case.profile.length_m();
    let d = case.profile.offset_m();
    let weight = case.cal.gravity_mps2() * case.profile.mass_kg();
    let rotation = case.cal.sensor_rotation();
    let f_a = -(rotation * (case.reading_n - case.bias_n));
    let n = Vector3::y().cross(&u.cross(&w));
    let (e1, e2) = (w, u.cross(&w));
    let r_b = (w * d + u * s) / length;
    let r_c = (w * d + u * case.profile.com_m()) / length;
    let r_d = (w * d + u * length) / length;
    let mut k = Matrix6::<f64>::zeros();
    k.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    k.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&r_d.cross_matrix());
    k.fixed_view_mut::<3, 1>(0, 3).copy_from(&e1);
    k.fixed_view_mut::<3, 1>(3, 3).copy_from(&r_b.cross(&e1));
    k.fixed_view_mut::<3, 1>(0, 4).copy_from(&e2);
    k.fixed_view_mut::<3, 1>(3, 4).copy_from(&r_b.cross(&e2));
    k.fixed_view_mut::<3, 1>(3, 5).copy_from(&n);
    let mut rhs = SMatrix::<f64, 6, 4>::zeros();
    rhs.fixed_view_mut::<3, 1>(0, 0)
        .copy_from(&(-(f_a + weight)));
    rhs.fixed_view_mut::<3, 1>(3, 0)
        .copy_from(&(-r_c.cross(&weight)));
    rhs.fixed_view_mut::<3, 3>(0, 1)
        .copy_from(&Matrix3::identity());
    let lu = k.lu();
    if lu.u().diagonal().amin() < 1e-12 {
        return None;
    }
    let x = lu.solve(&rhs)?;
    let force = -x.fixed_view::<3, 1>(0, 0).clone_owned();
    let jacobian: Matrix3<f64> = x.fixed_view::<3, 3>(0, 1).clone_owned();
    let covariance = SensorNoise::hex6().base_covariance_n2(&rotation);
    let std = (jacobian * covariance * jacobian.transpose())
        .diagonal()
        .map(f64::sqrt);
    Some((force, std, x[(5, 0)] * length))
}

/// d of either sign, |d| from 1 um up to 15 mm.
fn offset_up_to_15_mm() -> BoxedStrategy<f64> {
    (1e-6..0.015f64, any::<bool>())
        .prop_map(|(d, neg)| if neg { -d } else { d })
        .boxed()
}

/// The closed form of d != 0 gives the dense 6x6's tip force, per-axis std and
/// torsion to 1e-9 relative, over random poses, calibrations and tip forces
/// with |d| up to 15 mm of both signs; axial, lateral and the observability
/// flag follow.
#[test]
fn offset_closed_form_matches_the_dense_6x6() {
    // Worst relative differences: force, std (per axis), torsion.
    let worst = Cell::new([0.0_f64; 3]);
    let signs = Cell::new([0usize; 2]);
    run_cases(3000, 0x7150_0010, cases(offset_up_to_15_mm()), |p| {
        let case = build(&p);
        let (force, std, torsion) = dense_reference(&case).expect("not singular");
        let est = estimator(&case, 2.0)
            .estimate(&case.pose, &case.reading_n, &case.bias_n)
            .unwrap();
        let scale = force_scale(&case);
        let force_err = (est.force_n - force).norm() / scale;
        let std_err = (est.std_n - std).component_div(&std).amax();
        let torsion_err = (est.torsion_nm - torsion).abs() / (scale * case.truth.length_m);
        assert!(force_err < 1e-9, "{:?} vs {force:?}", est.force_n);
        assert!(std_err < 1e-9, "{:?} vs {std:?}", est.std_n);
        assert!(torsion_err < 1e-9, "{} vs {torsion}", est.torsion_nm);
        assert_eq!(est.observable, std.amax() <= 2.0, "{std:?}");
        let axial = force.dot(&case.u);
        assert!((est.axial_n - axial).abs() < 1e-9 * scale);
        assert!((est.lateral_n - (force - case.u * axial).norm()).abs() < 1e-9 * scale);
        let w = worst.get();
        worst.set([
            w[0].max(force_err),
            w[1].max(std_err),
            w[2].max(torsion_err),
        ]);
        let mut n = signs.get();
        n[usize::from(case.truth.offset_m > 0.0)] += 1;
        signs.set(n);
    });
    let [f, s, t] = worst.get();
    let [neg, pos] = signs.get();
    println!(
        "closed form vs dense 6x6 over {neg} cases d < 0 and {pos} d > 0: worst relative \
         difference force {f:.2e}, std {s:.2e}, torsion {t:.2e}"
    );
    assert!(neg > 500 && pos > 500);
}

/// The same range of d against the independent simulator of `common` (tip
/// force, torsion, equilibrium residual) and its Jacobian (std).
#[test]
fn offset_up_to_15_mm_matches_the_simulator() {
    accuracy(offset_up_to_15_mm(), 0x7150_0011, "|d| <= 15 mm");
    run_cases(1000, 0x7150_0012, cases(offset_up_to_15_mm()), |p| {
        check_std(&build(&p))
    });
}

/// As d -> 0 the closed form of d != 0 becomes MODEL.md 4.1: at d = +-1e-9 m it
/// gives the d = 0 estimate (its own code path) to 1e-8 relative.
#[test]
fn offset_closed_form_tends_to_the_d0_closed_form() {
    for (q4, q5, euler) in [
        (NOMINAL_Q4, 0.0, [0.0; 3]),
        (1.2, 0.3, [0.3, -0.2, 0.1]),
        (-2.0, -0.6, [2.0, 1.0, -0.4]),
    ] {
        let zero = typical(0.0, q4, q5, euler, [2.0, -3.0, 1.0]);
        let at_zero = estimator(&zero, 5.0)
            .estimate(&zero.pose, &zero.reading_n, &zero.bias_n)
            .unwrap();
        for d in [1e-9, -1e-9] {
            let case = typical(d, q4, q5, euler, [2.0, -3.0, 1.0]);
            let est = estimator(&case, 5.0)
                .estimate(&case.pose, &case.reading_n, &case.bias_n)
                .unwrap();
            let scale = force_scale(&case);
            assert!((est.force_n - at_zero.force_n).norm() < 1e-8 * scale);
            assert!((est.std_n - at_zero.std_n).amax() < 1e-8 * at_zero.std_n.amax());
            assert!(est.torsion_nm.abs() < 1e-8 * scale);
        }
    }
}

/// d != 0 and a vertical rod (u = Y0, n . u = w_y = 0): the torsion has no part
/// along u, so the system is singular: no number, an infinite std. Rods a
/// round-off (cos(pi/2) = 6e-17) or 1e-9 rad from vertical give a number with
/// a huge std, flagged not observable.
#[test]
fn offset_vertical_rod_is_singular() {
    let case = typical(0.005, 1.2, 0.3, [0.3, -0.2, 0.1], [2.0, -3.0, 1.0]);
    let est = estimator(&case, 5.0);
    for q4 in [1.2_f64, -0.4] {
        let mut pose = case.pose;
        pose.rod_dir = Vector3::y();
        pose.rod_normal = Vector3::new(q4.sin(), 0.0, q4.cos());
        let out = est.estimate(&pose, &case.reading_n, &case.bias_n);
        assert!(
            matches!(out, Err(TipForceError::NotObservable { std_max_n, .. })
                if std_max_n == f64::INFINITY),
            "{out:?}"
        );
        for (q5, least_std_n) in [
            (core::f64::consts::FRAC_PI_2, 1e12),
            (core::f64::consts::FRAC_PI_2 - 1e-9, 1e5),
        ] {
            let (u, w) = rod_frame(q4, q5);
            assert!(w.y != 0.0);
            pose.rod_dir = u;
            pose.rod_normal = w;
            let out = est.estimate(&pose, &case.reading_n, &case.bias_n).unwrap();
            assert!(!out.observable);
            assert!(out.std_n.amax() > least_std_n, "{:?}", out.std_n);
        }
    }
}

// ---------------------------------------------------------------------------
// In motion (MODEL.md 10): the compensation against a second, independent
// formulation, from positions only.

use sar_estimator::inertial::RodInertia;
use sar_estimator::motion::CarriageMotion;

/// A smooth carriage trajectory: each joint a constant plus a sum of sines
/// (amplitude m, angular frequency rad/s, phase rad).
struct SineTrajectory {
    q0: [f64; 3],
    sines: [[(f64, f64, f64); 3]; 3],
}

impl SineTrajectory {
    /// q, q' or q'' (`order` 0, 1, 2) at `t_s`.
    fn joints(&self, t_s: f64, order: u32) -> [f64; 3] {
        let mut q = if order == 0 { self.q0 } else { [0.0; 3] };
        for (qi, sines) in q.iter_mut().zip(&self.sines) {
            for &(amp, om, phase) in sines {
                let x = om * t_s + phase;
                *qi += match order {
                    0 => amp * x.sin(),
                    1 => amp * om * x.cos(),
                    _ => -amp * om * om * x.sin(),
                };
            }
        }
        q
    }

    fn pose(&self, cal: &Calibration, profile: &Profile, t_s: f64) -> Pose {
        let [q1_m, q2_m, q3_m] = self.joints(t_s, 0);
        forward(cal, profile, &ActiveJoints { q1_m, q2_m, q3_m }).unwrap()
    }

    /// A' and A'' = (q3', q2', q1') and (q3'', q2'', q1''), exact.
    fn motion(&self, t_s: f64) -> CarriageMotion {
        let [v1, v2, v3] = self.joints(t_s, 1);
        let [a1, a2, a3] = self.joints(t_s, 2);
        CarriageMotion {
            velocity_mps: Vector3::new(v3, v2, v1),
            accel_mps2: Vector3::new(a3, a2, a1),
            accel_std_mps2: 0.0,
        }
    }
}

/// The 8th-order centred stencils, offsets 1..=4: first and second
/// derivative (the second's centre weight apart).
const D1: [f64; 4] = [4.0 / 5.0, -1.0 / 5.0, 4.0 / 105.0, -1.0 / 280.0];
const D2: [f64; 4] = [8.0 / 5.0, -1.0 / 5.0, 8.0 / 315.0, -1.0 / 560.0];
const D2_CENTRE: f64 = -205.0 / 72.0;
const STEP_S: f64 = 1e-3;

/// d/dt of `f` at `t_s` by the centred stencil.
fn d1<T>(f: &impl Fn(f64) -> T, t_s: f64) -> T
where
    T: core::ops::Sub<Output = T> + core::ops::Mul<f64, Output = T> + core::ops::Add<Output = T>,
{
    let mut sum = (f(t_s + STEP_S) - f(t_s - STEP_S)) * (D1[0] / STEP_S);
    for (k, c) in D1.iter().enumerate().skip(1) {
        let h = (k + 1) as f64 * STEP_S;
        sum = sum + (f(t_s + h) - f(t_s - h)) * (c / STEP_S);
    }
    sum
}

/// d2/dt2 of `f` at `t_s` by the centred stencil.
fn d2(f: &impl Fn(f64) -> Vector3<f64>, t_s: f64) -> Vector3<f64> {
    let mut sum = f(t_s) * D2_CENTRE;
    for (k, c) in D2.iter().enumerate() {
        let h = (k + 1) as f64 * STEP_S;
        sum += (f(t_s + h) + f(t_s - h)) * *c;
    }
    sum / (STEP_S * STEP_S)
}

/// The rod's frame [u w v] at a pose: R' R^T = [omega]x.
fn rod_rotation(pose: &Pose) -> Matrix3<f64> {
    let (u, w) = (pose.rod_dir, pose.rod_normal);
    Matrix3::from_columns(&[u, w, u.cross(&w)])
}

/// From positions only: the COM's acceleration and H_C' (the rod's angular
/// velocity from the frame's rotation, its angular momentum differentiated).
fn inertial_by_differences(
    traj: &SineTrajectory,
    cal: &Calibration,
    profile: &Profile,
    inertia: &RodInertia,
    t_s: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    let com = |t: f64| traj.pose(cal, profile, t).com_m;
    let momentum = |t: f64| {
        let rot = |tau: f64| rod_rotation(&traj.pose(cal, profile, tau));
        let skew = d1(&rot, t) * rot(t).transpose();
        let omega = Vector3::new(
            skew[(2, 1)] - skew[(1, 2)],
            skew[(0, 2)] - skew[(2, 0)],
            skew[(1, 0)] - skew[(0, 1)],
        ) * 0.5;
        let u = traj.pose(cal, profile, t).rod_dir;
        let along = u.dot(&omega);
        (omega - u * along) * inertia.inertia_perp_kgm2 + u * (along * inertia.inertia_axial_kgm2)
    };
    (d2(&com, t_s), d1(&momentum, t_s))
}

/// Newton-Euler with moments about A (the reference, a dense solve): with
/// the tip applying `tip_n`, the rod's F_A, the torsion M_T, and the raw
/// reading f = R_0s^T (-F_A - m_s A'') + b.
#[allow(clippy::too_many_arguments)]
fn reading_in_motion(
    cal: &Calibration,
    profile: &Profile,
    inertia: &RodInertia,
    pose: &Pose,
    (com_accel, h_dot): (Vector3<f64>, Vector3<f64>),
    accel: &Vector3<f64>,
    tip_n: &Vector3<f64>,
    bias_n: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>, f64) {
    let a = pose.ujoint_m;
    let (w, v) = (pose.rod_normal, pose.rod_dir.cross(&pose.rod_normal));
    let n = Vector3::y().cross(&v);
    let (r_b, r_c, r_d) = (cal.support_m() - a, pose.com_m - a, pose.tip_m - a);
    let m = profile.mass_kg();
    let weight = cal.gravity_mps2() * m;
    let f_d = -tip_n;
    // b1 (r_b x w) + b2 (r_b x v) + M_T n = H' + r_c x m (a_C - g) - r_d x F_D
    let k = Matrix3::from_columns(&[r_b.cross(&w), r_b.cross(&v), n]);
    let rhs = h_dot + r_c.cross(&(com_accel * m - weight)) - r_d.cross(&f_d);
    let x = k.lu().solve(&rhs).unwrap();
    let f_b = w * x[0] + v * x[1];
    let f_a = com_accel * m - weight - f_d - f_b;
    let on_sensor = -f_a - accel * inertia.adapter_mass_kg;
    (
        cal.sensor_rotation().transpose() * on_sensor + bias_n,
        f_a,
        x[2],
    )
}

/// A calibration with a turned sensor (the reading's frame matters).
fn turned_calibration() -> Calibration {
    Calibration::new(&CalibrationSpec {
        sensor_rotation: *Rotation3::from_euler_angles(0.3, -0.2, 0.5).matrix(),
        ..common::example_calibration().spec()
    })
    .unwrap()
}

fn profile_with_offset(offset_m: f64) -> Profile {
    Profile::new(&ProfileSpec {
        offset_m,
        ..common::manipulator2().spec()
    })
    .unwrap()
}

/// Joints that put A at `a_m` with the example calibration (A = A(0) +
/// (q3, q2, q1)).
fn joints_at(cal: &Calibration, profile: &Profile, a_m: Vector3<f64>) -> [f64; 3] {
    let q = a_m - cal.p_home_m() - cal.ujoint_offset_m();
    let [q1_m, q2_m, q3_m] = [q.z, q.y, q.x];
    let pose = forward(cal, profile, &ActiveJoints { q1_m, q2_m, q3_m }).unwrap();
    assert!((pose.ujoint_m - a_m).norm() < 1e-12);
    [q1_m, q2_m, q3_m]
}

fn in_motion_estimator(
    cal: &Calibration,
    profile: &Profile,
    inertia: RodInertia,
) -> TipForceEstimator {
    TipForceEstimator::new(
        cal,
        profile,
        &SensorNoise::hex6(),
        TipForceConfig { max_std_n: 1e9 },
    )
    .unwrap()
    .with_inertia(inertia)
    .unwrap()
}

/// The compensated estimate recovers the imposed tip force, F_A and the
/// torsion along a smooth trajectory (up to 3 m/s^2, 0.25 m/s), for d = 0
/// and d != 0, with I_axial and an adapter: the estimator's closed forms
/// against finite differences of positions and a dense Newton-Euler solve.
#[test]
fn compensation_matches_differences_of_positions() {
    let cal = turned_calibration();
    let bias = Vector3::new(1.5, -2.0, 0.7);
    let tip = Vector3::new(2.0, -1.5, 0.8);
    let cases = [
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.35),
        (0.0, 0.002, 0.0),
        (0.01, 0.0, 0.0),
        (-0.008, 0.003, 0.35),
    ];
    let mut worst_n: f64 = 0.0;
    for (d, i_axial, m_s) in cases {
        let profile = profile_with_offset(d);
        let inertia = RodInertia {
            inertia_perp_kgm2: 0.031,
            inertia_perp_std_kgm2: 0.0,
            inertia_axial_kgm2: i_axial,
            adapter_mass_kg: m_s,
        };
        let est = in_motion_estimator(&cal, &profile, inertia);
        let traj = SineTrajectory {
            q0: joints_at(&cal, &profile, Vector3::new(0.23, 0.17, 0.03)),
            sines: [
                [(0.02, 9.0, 0.3), (0.005, 17.0, 1.0), (0.0, 1.0, 0.0)],
                [(0.015, 11.0, -0.5), (0.004, 5.0, 2.0), (0.0, 1.0, 0.0)],
                [(0.02, 7.0, 1.3), (0.006, 13.0, -1.0), (0.0, 1.0, 0.0)],
            ],
        };
        for k in 0..12 {
            let t = 0.037 * f64::from(k);
            let pose = traj.pose(&cal, &profile, t);
            let motion = traj.motion(t);
            // The trajectory's A' is the U-joint's velocity.
            let a_dot = d1(&|t| traj.pose(&cal, &profile, t).ujoint_m, t);
            assert!((a_dot - motion.velocity_mps).norm() < 1e-9);
            let loads = inertial_by_differences(&traj, &cal, &profile, &inertia, t);
            let (reading, f_a, torsion) = reading_in_motion(
                &cal,
                &profile,
                &inertia,
                &pose,
                loads,
                &motion.accel_mps2,
                &tip,
                &bias,
            );
            let out = est
                .estimate_in_motion(&pose, &reading, &bias, &motion)
                .unwrap();
            let err = (out.force_n - tip).norm();
            worst_n = worst_n.max(err);
            assert!(
                err < 1e-6,
                "d {d} I_axial {i_axial} m_s {m_s} t {t}: {err} N"
            );
            assert!((out.ujoint_force_n - f_a).norm() < 1e-6);
            assert!(
                (out.torsion_nm - torsion).abs() < 1e-7,
                "{} vs {torsion}",
                out.torsion_nm
            );
            // The motion is large: uncompensated, the same reading is far off.
            let still = est.estimate(&pose, &reading, &bias).unwrap();
            assert!((still.force_n - tip).norm() > 0.3, "{:?}", still.force_n);
        }
    }
    println!("compensation vs differences of positions: worst {worst_n:.2e} N");
}

/// The example robot's nominal pose (A = (0.25, 0.2, 0), u = X0, a = 0.2 m).
fn nominal(profile: &Profile) -> (Calibration, Pose) {
    let cal = common::example_calibration();
    let [q1_m, q2_m, q3_m] = joints_at(&cal, profile, Vector3::new(0.25, 0.2, 0.0));
    let pose = forward(&cal, profile, &ActiveJoints { q1_m, q2_m, q3_m }).unwrap();
    assert!((pose.rod_dir - Vector3::x()).norm() < 1e-12);
    (cal, pose)
}

/// The reading at the nominal pose at rest in velocity, accelerating at
/// `accel`, nothing at the tip (I_perp, H' and a_C in closed form:
/// u'' = -A''_perp / a, a_C = A'' + c u'', H' = I_perp u x u'').
fn nominal_reading(
    profile: &Profile,
    inertia: &RodInertia,
    accel: Vector3<f64>,
) -> (Calibration, Pose, Vector3<f64>) {
    let (cal, pose) = nominal(profile);
    let u = pose.rod_dir;
    let u2 = -(accel - u * u.dot(&accel)) / pose.support_distance_m;
    let loads = (
        accel + u2 * profile.com_m(),
        u.cross(&u2) * inertia.inertia_perp_kgm2,
    );
    let zero = Vector3::zeros();
    let (reading, _, _) =
        reading_in_motion(&cal, profile, inertia, &pose, loads, &accel, &zero, &zero);
    (cal, pose, reading)
}

fn accelerating(accel: Vector3<f64>, accel_std_mps2: f64) -> CarriageMotion {
    CarriageMotion {
        velocity_mps: Vector3::zeros(),
        accel_mps2: accel,
        accel_std_mps2,
    }
}

/// MODEL.md 10's table: at the nominal pose the static closed form reads
/// 2.59 N per m/s^2 along X0 and 1.70 across (0.81 + 33.3 I_perp); the
/// compensation reads nothing.
#[test]
fn phantom_tip_force_of_model_10_is_compensated() {
    let profile = common::manipulator2();
    let inertia = RodInertia::slender_rod(&profile);
    for (accel, phantom_n) in [
        (Vector3::x(), 2.59),
        (Vector3::y(), 1.70),
        (Vector3::z(), 1.70),
    ] {
        let (cal, pose, reading) = nominal_reading(&profile, &inertia, accel);
        let est = in_motion_estimator(&cal, &profile, inertia);
        let zero = Vector3::zeros();
        let still = est.estimate(&pose, &reading, &zero).unwrap();
        assert!(
            (still.force_n.norm() - phantom_n).abs() < 0.005,
            "{accel:?}: {:?}",
            still.force_n
        );
        let across = 0.81 + 33.3 * inertia.inertia_perp_kgm2;
        if accel.x == 0.0 {
            assert!((still.force_n.norm() - across).abs() < 0.01);
        }
        let moving = est
            .estimate_in_motion(&pose, &reading, &zero, &accelerating(accel, 0.0))
            .unwrap();
        assert!(moving.force_n.norm() < 1e-12, "{:?}", moving.force_n);
    }
}

/// MODEL.md 10 "Accuracy": I_perp off by 5 % and m by 0.2 % leave about
/// 0.01 N along the rod and 0.1 N across it at a 2 m/s^2 stop at the
/// nominal pose (beyond what the same errors give at rest).
#[test]
fn compensation_error_is_its_inputs_error() {
    let truth_profile = common::manipulator2();
    let truth = RodInertia::slender_rod(&truth_profile);
    let wrong_profile = Profile::new(&ProfileSpec {
        mass_kg: truth_profile.mass_kg() * 1.002,
        ..truth_profile.spec()
    })
    .unwrap();
    let wrong = RodInertia {
        inertia_perp_kgm2: truth.inertia_perp_kgm2 * 1.05,
        ..truth
    };
    let mut residual_n = [0.0; 2];
    for (i, direction) in [Vector3::x(), Vector3::y()].into_iter().enumerate() {
        let stop = direction * -2.0;
        let (cal, pose, reading) = nominal_reading(&truth_profile, &truth, stop);
        let (_, _, at_rest) = nominal_reading(&truth_profile, &truth, Vector3::zeros());
        let est = in_motion_estimator(&cal, &wrong_profile, wrong);
        let zero = Vector3::zeros();
        let moving = est
            .estimate_in_motion(&pose, &reading, &zero, &accelerating(stop, 0.0))
            .unwrap();
        let still = est.estimate(&pose, &at_rest, &zero).unwrap();
        residual_n[i] = (moving.force_n - still.force_n).norm();
    }
    println!("2 m/s^2 stop, m +0.2 %, I_perp +5 %: {residual_n:?} N (along, across)");
    assert!((residual_n[0] - 0.0104).abs() < 0.001, "{residual_n:?}");
    assert!(
        residual_n[1] > 0.05 && residual_n[1] < 0.12,
        "{residual_n:?}"
    );
}

/// The standard deviation grows with the acceleration's and I_perp's, by the
/// exact Jacobians (F_tip is affine in A'' and linear in I_perp: their
/// differences are exact), for d = 0 and d != 0.
#[test]
fn std_grows_with_the_acceleration_and_inertia_uncertainty() {
    let cal = turned_calibration();
    let bias = Vector3::new(0.5, 1.0, -2.0);
    let reading = Vector3::new(3.0, 22.0, -1.0);
    for d in [0.0, 0.006] {
        let profile = profile_with_offset(d);
        let [q1_m, q2_m, q3_m] = joints_at(&cal, &profile, Vector3::new(0.22, 0.15, 0.04));
        let pose = forward(&cal, &profile, &ActiveJoints { q1_m, q2_m, q3_m }).unwrap();
        let base = RodInertia {
            inertia_perp_std_kgm2: 0.0,
            adapter_mass_kg: 0.2,
            ..RodInertia::slender_rod(&profile)
        };
        let motion = CarriageMotion {
            velocity_mps: Vector3::new(0.05, -0.02, 0.03),
            accel_mps2: Vector3::new(1.5, -0.7, 0.9),
            accel_std_mps2: 0.0,
        };
        let run = |inertia: RodInertia, m: CarriageMotion| {
            in_motion_estimator(&cal, &profile, inertia)
                .estimate_in_motion(&pose, &reading, &bias, &m)
                .unwrap()
        };
        let exact = run(base, motion);
        // A'' known to 0.3 m/s^2 per component.
        let sigma_a = 0.3;
        let uncertain = run(
            base,
            CarriageMotion {
                accel_std_mps2: sigma_a,
                ..motion
            },
        );
        assert_eq!(uncertain.force_n, exact.force_n);
        let mut expected = exact.std_n.component_mul(&exact.std_n);
        let mut torsion_var = 0.0;
        for e in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let moved = run(
                base,
                CarriageMotion {
                    accel_mps2: motion.accel_mps2 + e,
                    ..motion
                },
            );
            let col = (moved.force_n - exact.force_n) * sigma_a;
            expected += col.component_mul(&col);
            let torsion = (moved.torsion_nm - exact.torsion_nm) * sigma_a;
            torsion_var += torsion * torsion;
        }
        // The torsion's deviation likewise (with d != 0 the adapter moves
        // M_T; with d = 0 and no axial inertia nothing does).
        assert!(
            (uncertain.torsion_std_nm - torsion_var.sqrt()).abs() <= 1e-12,
            "d {d}: {} vs {}",
            uncertain.torsion_std_nm,
            torsion_var.sqrt()
        );
        assert_eq!(exact.torsion_std_nm, 0.0);
        assert_eq!(uncertain.torsion_std_nm > 0.0, d != 0.0);
        let got = uncertain.std_n.component_mul(&uncertain.std_n);
        assert!(
            (got - expected).amax() < 1e-9 * expected.amax(),
            "d {d}: {got:?} vs {expected:?}"
        );
        assert!(
            uncertain.std_n.min() > exact.std_n.min(),
            "{:?}",
            uncertain.std_n
        );
        // I_perp known to 0.01 kg m^2.
        let sigma_i = 0.01;
        let unsure = run(
            RodInertia {
                inertia_perp_std_kgm2: sigma_i,
                ..base
            },
            motion,
        );
        let heavier = run(
            RodInertia {
                inertia_perp_kgm2: base.inertia_perp_kgm2 + 1.0,
                ..base
            },
            motion,
        );
        let col = (heavier.force_n - exact.force_n) * sigma_i;
        let expected = exact.std_n.component_mul(&exact.std_n) + col.component_mul(&col);
        let got = unsure.std_n.component_mul(&unsure.std_n);
        assert!(
            (got - expected).amax() < 1e-9 * expected.amax(),
            "d {d}: {got:?} vs {expected:?}"
        );
        assert!(col.amax() > 1e-4, "{col:?}");
    }
}

/// At rest the motion path is the static one, to the bit; a motion that is
/// not finite, or a negative deviation, is refused with its name.
#[test]
fn rest_is_the_static_estimate_and_bad_motion_is_refused() {
    let cal = turned_calibration();
    let profile = profile_with_offset(0.004);
    let [q1_m, q2_m, q3_m] = joints_at(&cal, &profile, Vector3::new(0.22, 0.15, 0.04));
    let pose = forward(&cal, &profile, &ActiveJoints { q1_m, q2_m, q3_m }).unwrap();
    let est = in_motion_estimator(&cal, &profile, RodInertia::slender_rod(&profile));
    let (reading, bias) = (Vector3::new(3.0, 22.0, -1.0), Vector3::new(0.1, 0.2, 0.3));
    assert_eq!(
        est.estimate_in_motion(&pose, &reading, &bias, &CarriageMotion::REST),
        est.estimate(&pose, &reading, &bias)
    );
    let bad = [
        CarriageMotion {
            accel_std_mps2: -0.1,
            ..CarriageMotion::REST
        },
        CarriageMotion {
            accel_std_mps2: f64::NAN,
            ..CarriageMotion::REST
        },
        CarriageMotion {
            accel_mps2: Vector3::new(0.0, f64::INFINITY, 0.0),
            ..CarriageMotion::REST
        },
        CarriageMotion {
            velocity_mps: Vector3::new(f64::NAN, 0.0, 0.0),
            ..CarriageMotion::REST
        },
    ];
    for m in bad {
        let out = est.estimate_in_motion(&pose, &reading, &bias, &m);
        assert!(
            matches!(
                out,
                Err(TipForceError::InvalidMotion {
                    quantity: "accel_std_mps2",
                    ..
                }) | Err(TipForceError::NonFinite {
                    input: "motion.accel_mps2" | "motion.velocity_mps",
                    ..
                })
            ),
            "{m:?}: {out:?}"
        );
    }
    let refused = TipForceEstimator::new(
        &cal,
        &profile,
        &SensorNoise::hex6(),
        TipForceConfig::default(),
    )
    .unwrap()
    .with_inertia(RodInertia {
        adapter_mass_kg: -1.0,
        ..RodInertia::NONE
    });
    assert!(matches!(
        refused,
        Err(SettingError::Invalid {
            field: "adapter_mass_kg",
            ..
        })
    ));
}
