//! The Table 2 identification study (MODEL.md 5.1, 8, 9): the article's four
//! manipulators (L = 0.35 m, friction 0.3 N at the support, HEX-6 noise, K = 10
//! samples per pose, fixed seeds), identified with the configured support 2 mm
//! from the true one, under the article's protocol and the cone protocol, in four
//! cases: without/with support calibration, without/with the friction unknown.
//!
//! Run with `--nocapture` to see the table (relative errors of m and c with their
//! reported standard errors, the error of each component of B in mm with its
//! standard error or "held", the fitted friction, chi2_dof).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;

use common::*;
use nalgebra::{Matrix3, Vector3};
use sar_estimator::support::{SupportCalibration, SupportFit, SupportOptions};
use sar_estimator::{Calibration, CalibrationSpec, SensorNoise};

const FRICTION_N: f64 = 0.3;
const SAMPLES: u32 = 10;

fn true_support() -> Vector3<f64> {
    Vector3::new(0.45, 0.20, 0.0)
}

fn tare() -> Vector3<f64> {
    Vector3::new(0.4, -1.1, 0.25)
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Protocol {
    Article,
    Cone,
}

#[derive(Clone, Copy, Debug)]
struct Case {
    name: &'static str,
    calibrate_support: bool,
    friction: bool,
}

const CASES: [Case; 4] = [
    Case {
        name: "(a) B fixed",
        calibrate_support: false,
        friction: false,
    },
    Case {
        name: "(b) B fixed, f",
        calibrate_support: false,
        friction: true,
    },
    Case {
        name: "(c) B fit",
        calibrate_support: true,
        friction: false,
    },
    Case {
        name: "(d) B fit, f",
        calibrate_support: true,
        friction: true,
    },
];

/// The same simulated poses for every case of one manipulator and protocol.
fn poses(manipulator: usize, protocol: Protocol, samples: u32) -> Vec<sar_estimator::StaticPose> {
    let truth = table2_truth(manipulator, FRICTION_N);
    let protocol_poses = match protocol {
        Protocol::Article => article_protocol(),
        Protocol::Cone => cone_protocol(),
    };
    let seed = 7000
        + 10 * manipulator as u64
        + u64::from(protocol == Protocol::Cone)
        + 100 * u64::from(samples);
    let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, seed);
    simulate_static_poses(
        &truth,
        &Matrix3::identity(),
        &tare(),
        &protocol_poses,
        samples,
        &mut sensor,
    )
}

fn fit(poses: &[sar_estimator::StaticPose], configured: Vector3<f64>, case: Case) -> SupportFit {
    let cal = Calibration::new(&CalibrationSpec {
        p_home_m: Vector3::zeros(),
        ujoint_offset_m: Vector3::new(0.0, -0.08, 0.0),
        sensor_offset_m: Vector3::new(0.0, -0.03, 0.0),
        sensor_rotation: Matrix3::identity(),
        support_m: configured,
        gravity_mps2: gravity(),
    })
    .unwrap();
    // The comparison cases (B held, or friction left out) show how far off a
    // fit without support calibration or friction is: their chi-square is far
    // above the default bound, which would refuse them, so it is lifted for
    // them. The full fit keeps every default.
    let full = case.friction && case.calibrate_support;
    let options = SupportOptions {
        friction: case.friction,
        calibrate_support: case.calibrate_support,
        max_chi2_dof: if full {
            SupportOptions::DEFAULT_MAX_CHI2_DOF
        } else {
            f64::INFINITY
        },
        ..SupportOptions::default()
    };
    let mut support = SupportCalibration::new(&cal, &SensorNoise::hex6(), tare(), options).unwrap();
    for pose in poses {
        support.push(pose).unwrap();
    }
    support.fit().unwrap()
}

struct Row {
    manipulator: usize,
    case: Case,
    fit: SupportFit,
    m_err: f64,
    m_std: f64,
    c_err: f64,
    c_std: f64,
    b_err_m: Vector3<f64>,
}

fn row(manipulator: usize, case: Case, fit: SupportFit) -> Row {
    let (m, c) = TABLE2[manipulator];
    Row {
        manipulator,
        case,
        fit,
        m_err: (fit.mass_kg - m) / m,
        m_std: fit.mass_std_kg / m,
        c_err: (fit.com_m - c) / c,
        c_std: fit.com_std_m / c,
        b_err_m: fit.support_m - true_support(),
    }
}

fn print_header(title: &str) {
    println!("\n== {title} ==");
    println!(
        "{:<4}{:<15}{:>15}{:>15}   {:<14}{:<14}{:<14}{:>7}{:>8}",
        "man",
        "case",
        "m err % (std)",
        "c err % (std)",
        "Bx mm (std)",
        "By mm (std)",
        "Bz mm (std)",
        "f N",
        "chi2"
    );
}

fn print_row(r: &Row) {
    let b = (0..3)
        .map(|k| {
            let std =
                r.fit.support_std_m[k].map_or("held".to_string(), |s| format!("{:.3}", s * 1e3));
            format!("{:+.3}({std:>5})", r.b_err_m[k] * 1e3)
        })
        .collect::<Vec<_>>();
    println!(
        "{:<4}{:<15}{:>+7.3} ({:5.3}){:>+7.3} ({:5.3})   {:<14}{:<14}{:<14}{:>7}{:>8.2}",
        r.manipulator + 1,
        r.case.name,
        r.m_err * 100.0,
        r.m_std * 100.0,
        r.c_err * 100.0,
        r.c_std * 100.0,
        b[0],
        b[1],
        b[2],
        r.fit.friction_n.map_or("-".into(), |f| format!("{f:.3}")),
        r.fit.chi2_dof
    );
}

/// Runs the four cases for every manipulator; prints and returns the rows.
fn study(protocol: Protocol, offset_m: Vector3<f64>, samples: u32, title: &str) -> Vec<Row> {
    print_header(title);
    let mut rows = Vec::new();
    for manipulator in 0..4 {
        let data = poses(manipulator, protocol, samples);
        for case in CASES {
            let r = row(
                manipulator,
                case,
                fit(&data, true_support() + offset_m, case),
            );
            print_row(&r);
            rows.push(r);
        }
    }
    rows
}

fn diagonal_2mm() -> Vector3<f64> {
    Vector3::new(1.0, -1.0, 1.0).normalize() * 2e-3
}

const BOUND_REL: f64 = 3e-3;
const BOUND_B_M: f64 = 0.3e-3;

/// The cone protocol with support calibration and the friction unknown meets
/// 0.3 % on m and c and 0.3 mm on every component of B; without calibration the
/// 2 mm error in B moves m by more than 1 % and chi-square says so.
#[test]
fn table2_cone_protocol() {
    let rows = study(
        Protocol::Cone,
        diagonal_2mm(),
        SAMPLES,
        "cone protocol, configured B 2 mm along (1,-1,1)/sqrt3, K = 10",
    );
    for r in &rows {
        let who = format!("manipulator {} {}", r.manipulator + 1, r.case.name);
        if r.case.calibrate_support {
            assert_eq!(r.fit.held, [false; 3], "{who}");
        } else {
            assert!(r.m_err.abs() > 0.01, "{who}: m err {}", r.m_err);
            assert!(r.fit.chi2_dof > 5.0, "{who}: chi2 {}", r.fit.chi2_dof);
        }
        if r.case.calibrate_support && r.case.friction {
            assert!(r.m_err.abs() < BOUND_REL, "{who}: m err {}", r.m_err);
            assert!(r.c_err.abs() < BOUND_REL, "{who}: c err {}", r.c_err);
            for k in 0..3 {
                assert!(
                    r.b_err_m[k].abs() < BOUND_B_M,
                    "{who}: B[{k}] err {}",
                    r.b_err_m[k]
                );
            }
            assert!(r.fit.chi2_dof < 2.0, "{who}: chi2 {}", r.fit.chi2_dof);
            let f = r.fit.friction_n.unwrap();
            assert!(
                (f - FRICTION_N).abs() < 3.0 * r.fit.friction_std_n.unwrap(),
                "{who}: f {f}"
            );
        }
        if r.case.calibrate_support && !r.case.friction {
            // The unmodelled friction shows in chi-square.
            assert!(r.fit.chi2_dof > 3.0, "{who}: chi2 {}", r.fit.chi2_dof);
        }
    }
}

/// The article's protocol with support calibration and the friction unknown:
/// B_z is held; B_x, B_y, m and c are within 0.3 mm / 0.3 % OR within three of
/// their reported standard errors where those exceed a third of the bound.
///
/// Why the 0.3 % bound alone cannot be asserted: with the rod horizontal, B_x
/// enters only through a = B_x - A_x in F_y = m |g| - M |g| / a, so m, M and
/// B_x are fitted from one curve through five distances and are strongly
/// correlated. Fitting B_x about doubles the standard error of m (manipulator 1,
/// K = 10: 0.22 % -> 0.42 %, the scatter over 300 seeds agrees) so 0.3 % is
/// below one standard error for the light manipulators. The standard errors
/// themselves are checked against the scatter in `tests/support.rs`.
#[test]
fn table2_article_protocol() {
    let rows = study(
        Protocol::Article,
        diagonal_2mm(),
        SAMPLES,
        "article protocol, configured B 2 mm along (1,-1,1)/sqrt3, K = 10",
    );
    for r in &rows {
        let who = format!("manipulator {} {}", r.manipulator + 1, r.case.name);
        if r.case.calibrate_support {
            assert_eq!(r.fit.held, [false, false, true], "{who}");
        } else {
            assert!(r.m_err.abs() > 0.01, "{who}: m err {}", r.m_err);
            assert!(r.fit.chi2_dof > 5.0, "{who}: chi2 {}", r.fit.chi2_dof);
        }
        if r.case.calibrate_support && r.case.friction {
            let m_bound = BOUND_REL.max(3.0 * r.m_std);
            let c_bound = BOUND_REL.max(3.0 * r.c_std);
            assert!(
                r.m_err.abs() < m_bound,
                "{who}: m err {} > {m_bound}",
                r.m_err
            );
            assert!(
                r.c_err.abs() < c_bound,
                "{who}: c err {} > {c_bound}",
                r.c_err
            );
            for k in 0..2 {
                let bound = BOUND_B_M.max(3.0 * r.fit.support_std_m[k].unwrap());
                assert!(
                    r.b_err_m[k].abs() < bound,
                    "{who}: B[{k}] err {}",
                    r.b_err_m[k]
                );
            }
            assert!(r.fit.chi2_dof < 2.0, "{who}: chi2 {}", r.fit.chi2_dof);
        }
    }
}

/// Exploration only (printed, not asserted): the configured error along x and
/// along y alone, and the article protocol with K = 100.
#[test]
#[ignore = "exploration: prints tables, asserts nothing; run with --ignored --nocapture"]
fn table2_exploration() {
    for (name, offset) in [
        ("x", Vector3::new(2e-3, 0.0, 0.0)),
        ("y", Vector3::new(0.0, 2e-3, 0.0)),
    ] {
        for protocol in [Protocol::Article, Protocol::Cone] {
            study(
                protocol,
                offset,
                SAMPLES,
                &format!("{protocol:?} protocol, configured B 2 mm along {name}, K = 10"),
            );
        }
    }
    study(
        Protocol::Article,
        diagonal_2mm(),
        100,
        "article protocol, configured B 2 mm along (1,-1,1)/sqrt3, K = 100",
    );
}
