//! Scenario files and the runner, without the simulator: every shipped file
//! loads and implements the protocol it claims (checked with the kinematics,
//! independently of how the loader built it); every kind of bad file is
//! refused with a message naming the file and the key; the runner does what
//! its doc says on simple fake drives and a fake sensor. (Here, beside the
//! loader, since `sar-sim`, the runner's crate, reads no TOML.)
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use proptest::prelude::*;
use proptest::test_runner::{Config as ProptestConfig, RngSeed};
use sar_config::ConfigError;
use sar_config::scenario::{Scenario, load, parse};
use sar_hal::motion::{
    SLIDE_THRESHOLD_M, SlideTracker, axis_move_time_s, axis_progress_m, move_time_s,
};
use sar_hal::{
    AxisDrives, DriveState, ErrorKind, ForceSensor, JointPositions, Rail, SensorStatus, SimClock,
    Vec3, WrenchSample,
};
use sar_kinematics::{ActiveJoints, SlideSign, forward};
use sar_sim::runner::{EndReason, RunError, RunEvent, RunOptions, run};
use sar_sim::{
    Breathing, Fault, PlantSpec, RodInertia, ServoSpec, Simulator, Tissue, TissueModel, TissueShift,
};
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::rc::Rc;

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios")
}

fn shipped() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(scenarios_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

fn load_named(file: &str) -> Scenario {
    load(&scenarios_dir().join(file)).unwrap_or_else(|e| panic!("{e}"))
}

/// Table 2 of the article: (m, c) of manipulators 1-4.
const TABLE2: [(f64, f64); 4] = [
    (1.611, 0.115),
    (2.593, 0.103),
    (3.198, 0.125),
    (4.159, 0.1456),
];
const PROTOCOL_A_M: [f64; 5] = [0.04, 0.07, 0.12, 0.20, 0.30];

#[test]
fn every_shipped_scenario_loads_with_a_unique_name() {
    let files = shipped();
    assert!(
        files.len() >= 13,
        "expected at least 13 files, found {files:?}"
    );
    let mut names = Vec::new();
    for f in &files {
        let s = load(f).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.origin, f.display().to_string());
        assert!(!s.script.steps.is_empty());
        // The example geometry of INTERFACES.md 2, as every file says.
        let cal = &s.spec.calibration;
        assert_eq!(cal.support_m(), Vec3::new(0.45, 0.20, 0.0), "{}", s.name);
        assert_eq!(cal.ujoint_offset_m(), Vec3::new(0.0, -0.08, 0.0));
        assert_eq!(cal.sensor_offset_m(), Vec3::new(0.0, -0.03, 0.0));
        assert_eq!(s.spec.profile.length_m(), 0.35);
        assert_eq!(s.spec.sensor.noise_n, Vec3::new(0.2, 0.2, 0.8));
        assert_eq!(s.spec.sensor.period_ns, 2_000_000);
        assert_eq!(s.spec.axes.start, s.script.start);
        assert!(!names.contains(&s.name), "duplicate name {}", s.name);
        names.push(s.name);
    }
}

/// The held poses of a scenario: (A, u, a) from the forward kinematics, with the
/// planned slide sign.
fn held_poses(s: &Scenario) -> Vec<(Vec3, Vec3, f64, SlideSign)> {
    s.script
        .steps
        .iter()
        .filter(|st| st.hold_ns > 0)
        .map(|st| {
            let pose = forward(&s.spec.calibration, &s.spec.profile, &st.target).unwrap();
            (
                pose.ujoint_m,
                pose.rod_dir,
                pose.support_distance_m,
                st.planned_slide_sign,
            )
        })
        .collect()
}

#[test]
fn identification_files_follow_the_articles_protocol() {
    for (k, (mass_kg, com_m)) in TABLE2.iter().enumerate() {
        let s = load_named(&format!("identify_manipulator_{}.toml", k + 1));
        assert_eq!(s.spec.profile.mass_kg(), *mass_kg);
        assert_eq!(s.spec.profile.com_m(), *com_m);
        assert_eq!(s.spec.profile.offset_m(), 0.0);
        assert_eq!(s.spec.friction_n, 0.3);
        assert_eq!(s.spec.tip_mass_kg, 0.0);
        assert!(s.spec.contact.is_empty() && s.spec.faults.is_empty());
        let poses = held_poses(&s);
        let outward: Vec<f64> = PROTOCOL_A_M.to_vec();
        let inward: Vec<f64> = PROTOCOL_A_M.iter().rev().copied().collect();
        let expected: Vec<f64> = outward.iter().chain(inward.iter()).copied().collect();
        assert_eq!(poses.len(), 10);
        for (i, ((a_m, u, a, slide), want_a)) in poses.iter().zip(&expected).enumerate() {
            // Rod horizontal along +X0, A at the support's height.
            assert!((u - Vec3::x()).norm() < 1e-12, "pose {i}: u = {u:?}");
            assert!((a_m.y - 0.20).abs() < 1e-12);
            assert!((a - want_a).abs() < 1e-12, "pose {i}: a = {a}");
            // Outward first (the rod slides against u), then inward.
            let want_slide = if i < 5 {
                SlideSign::Retracting
            } else {
                SlideSign::Inserting
            };
            assert_eq!(*slide, want_slide, "pose {i}");
        }
    }
}

#[test]
fn table3_files_hang_the_articles_masses_on_manipulator_2() {
    for (file, mass) in [
        ("table3_mass_0_51kg.toml", 0.51),
        ("table3_mass_1_03kg.toml", 1.03),
        ("table3_mass_2_04kg.toml", 2.04),
    ] {
        let s = load_named(file);
        assert_eq!(s.spec.tip_mass_kg, mass);
        assert_eq!(
            (s.spec.profile.mass_kg(), s.spec.profile.com_m()),
            TABLE2[1]
        );
        let reference = load_named("identify_manipulator_2.toml");
        assert_eq!(
            s.script.steps, reference.script.steps,
            "{file}: same protocol"
        );
    }
}

#[test]
fn cone_file_follows_model_5_1() {
    let s = load_named("identify_cone_manipulator_2.toml");
    let poses = held_poses(&s);
    assert_eq!(poses.len(), 20);
    let mut directions: Vec<Vec3> = Vec::new();
    for (i, (_, u, a, slide)) in poses.iter().enumerate() {
        // 35 degrees from X0.
        assert!((u.x - 35f64.to_radians().cos()).abs() < 1e-9, "pose {i}");
        let k = i / 5;
        let outward = k % 2 == 0;
        let j = i % 5;
        let want_a = if outward {
            PROTOCOL_A_M[j]
        } else {
            PROTOCOL_A_M[4 - j]
        };
        assert!((a - want_a).abs() < 1e-9, "pose {i}: a = {a}");
        let want_slide = if outward {
            SlideSign::Retracting
        } else {
            SlideSign::Inserting
        };
        assert_eq!(*slide, want_slide, "pose {i}");
        if directions.iter().all(|d| (d - u).norm() > 1e-6) {
            directions.push(*u);
        }
    }
    assert_eq!(directions.len(), 4);
    // Four directions a quarter turn apart around X0.
    for w in directions.windows(2) {
        let (p, q) = (
            Vec3::new(0.0, w[0].y, w[0].z),
            Vec3::new(0.0, w[1].y, w[1].z),
        );
        assert!(p.dot(&q).abs() < 1e-9);
    }
}

#[test]
fn contact_file_has_random_motion_and_a_push_above_15_n() {
    let s = load_named("random_contact_manipulator_2.toml");
    assert!(
        s.script
            .steps
            .iter()
            .filter(|st| st.key.starts_with("random_motion"))
            .count()
            >= 5
    );
    for st in &s.script.steps {
        let pose = forward(&s.spec.calibration, &s.spec.profile, &st.target).unwrap();
        let beyond = pose.tip_beyond_support_m;
        assert!(st.hold_ns > 0);
        assert!(
            (0.12 - 1e-9..=0.2 + 1e-9).contains(&beyond),
            "{}: {beyond}",
            st.key
        );
        assert!(
            pose.rod_dir.x >= 20f64.to_radians().cos() - 1e-9,
            "{}",
            st.key
        );
    }
    let peak = s
        .spec
        .contact
        .iter()
        .map(|k| k.force_n.norm())
        .fold(0.0, f64::max);
    assert!(peak > 15.0, "peak {peak}");
    // The push comes before the script's nominal end, so a run covers it.
    let last = s.spec.contact.last().unwrap();
    assert!(last.t_ns < s.script.nominal_duration_ns());
    // The random targets depend on the seed.
    let text =
        std::fs::read_to_string(scenarios_dir().join("random_contact_manipulator_2.toml")).unwrap();
    let reseeded = parse(&text.replace("seed = 401", "seed = 402"), "reseeded").unwrap();
    assert_ne!(reseeded.script.steps, s.script.steps);
    assert_eq!(parse(&text, "again").unwrap().script, s.script);
}

#[test]
fn fault_files_have_one_fault_each() {
    type Check = fn(&Fault) -> bool;
    let cases: [(&str, Check); 13] = [
        ("fault_sensor_silent.toml", |f| {
            matches!(
                f,
                Fault::SensorSilent {
                    from_ns: 2_000_000_000,
                    until_ns: Some(2_500_000_000)
                }
            )
        }),
        ("fault_nan_sample.toml", |f| {
            matches!(
                f,
                Fault::NanSample {
                    at_ns: 2_000_000_000
                }
            )
        }),
        (
            "fault_encoder_jump.toml",
            |f| matches!(f, Fault::EncoderJump { at_ns: 2_000_000_000, axis: 2, jump_m } if *jump_m == 0.002),
        ),
        ("fault_drive_fault.toml", |f| {
            matches!(
                f,
                Fault::DriveFault {
                    at_ns: 2_000_000_000,
                    code: 0x2310
                }
            )
        }),
        ("fault_sensor_frozen.toml", |f| {
            matches!(
                f,
                Fault::SensorFrozen {
                    from_ns: 2_000_000_000,
                    until_ns: None
                }
            )
        }),
        ("fault_sensor_saturated.toml", |f| {
            matches!(
                f,
                Fault::SensorSaturated {
                    from_ns: 2_000_000_000,
                    until_ns: Some(2_500_000_000),
                    channels: [false, false, true, false, false, false],
                    rail: None,
                }
            )
        }),
        (
            "fault_sensor_spike.toml",
            |f| matches!(f, Fault::SensorSpike { at_ns: 2_000_000_000, force_n, torque_nm, samples: 1 } if *force_n == Vec3::new(0.0, 0.0, 30.0) && *torque_nm == Vec3::zeros()),
        ),
        (
            "fault_sensor_drift.toml",
            |f| matches!(f, Fault::SensorDrift { from_ns: 2_000_000_000, drift_n_per_s, drift_nm_per_s } if *drift_n_per_s == Vec3::new(0.0, 0.0, 1.0) && *drift_nm_per_s == Vec3::zeros()),
        ),
        (
            "fault_sensor_scale.toml",
            |f| matches!(f, Fault::SensorScale { from_ns: 2_000_000_000, factor } if *factor == 1.1),
        ),
        ("fault_encoder_frozen.toml", |f| {
            matches!(
                f,
                Fault::EncoderFrozen {
                    at_ns: 1_200_000_000,
                    axis: 2,
                    until_ns: None
                }
            )
        }),
        ("fault_encoder_count_loss.toml", |f| {
            matches!(
                f,
                Fault::EncoderCountLoss {
                    at_ns: 2_000_000_000,
                    axis: 2,
                    counts: 820
                }
            )
        }),
        ("fault_drive_heartbeat_loss.toml", |f| {
            matches!(
                f,
                Fault::DriveHeartbeatLoss {
                    at_ns: 2_000_000_000,
                    axis: 1
                }
            )
        }),
        ("fault_drive_emcy.toml", |f| {
            matches!(
                f,
                Fault::DriveEmcy {
                    at_ns: 2_000_000_000,
                    axis: 2,
                    code: 0x4310
                }
            )
        }),
    ];
    for (file, check) in cases {
        let s = load_named(file);
        assert_eq!(s.spec.faults.len(), 1, "{file}");
        assert!(check(&s.spec.faults[0]), "{file}: {:?}", s.spec.faults);
    }
}

#[test]
fn the_encoder_frozen_file_freezes_q3_while_it_moves() {
    // The fault must come during a move, where only the following check can
    // see it: the first move runs from 1.0 s for the slowest axis's time.
    let s = load_named("fault_encoder_frozen.toml");
    let first_move_s = sar_hal::motion::move_time_s(
        &s.script.start,
        &s.script.steps[1].target,
        s.script.max_speed_mps,
        s.script.max_accel_mps2,
    );
    assert!(first_move_s > 0.4, "{first_move_s}");
    let Fault::EncoderFrozen { at_ns, .. } = s.spec.faults[0] else {
        panic!("{:?}", s.spec.faults)
    };
    let at_s = at_ns as f64 * 1e-9;
    assert!(1.0 < at_s && at_s < 1.0 + first_move_s, "{at_s} s");
    let dq3 = s.script.steps[1].target.q3_m - s.script.start.q3_m;
    assert!(dq3.abs() > 0.01, "q3 moves {dq3} m");
}

/// The rotation by `angle` about the unit `axis` (Rodrigues).
fn rotation(axis: Vec3, angle: f64) -> nalgebra::Matrix3<f64> {
    *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle).matrix()
}

#[test]
fn mounting_files_differ_from_the_configured_robot_only_where_they_say() {
    // The reference: the fault files' robot without contact or fault, which
    // is the example configuration's robot (INTERFACES.md 2).
    let reference = load_named("fault_nan_sample.toml");
    let five = 5f64.to_radians();
    for (file, axis) in [
        ("mount_sensor_rotated_about_rod_5deg.toml", Vec3::x()),
        ("mount_sensor_rotated_about_vertical_5deg.toml", Vec3::y()),
    ] {
        let s = load_named(file);
        let r = s.spec.calibration.sensor_rotation();
        assert!((r - rotation(axis, five)).amax() < 1e-15, "{file}: {r}");
        // The rod at the nominal pose lies along X0.
        let pose = forward(&s.spec.calibration, &s.spec.profile, &s.script.start).unwrap();
        assert!((pose.rod_dir - Vec3::x()).norm() < 1e-12);
        assert_eq!(s.spec.profile, reference.spec.profile, "{file}");
        assert!(
            s.spec.contact.is_empty() && s.spec.faults.is_empty(),
            "{file}"
        );
        assert_eq!(s.script.steps, reference.script.steps, "{file}");
    }
    let s = load_named("mount_manipulator_mass_plus_10pct.toml");
    assert!((s.spec.profile.mass_kg() - 1.1 * TABLE2[1].0).abs() < 1e-12);
    assert_eq!(s.spec.profile.com_m(), TABLE2[1].1);
    assert_eq!(s.spec.calibration, reference.spec.calibration);
    assert!(s.spec.contact.is_empty() && s.spec.faults.is_empty());
}

#[test]
fn the_tissue_file_is_a_breathing_tissue_at_the_tip() {
    let s = load_named("tissue_breathing.toml");
    assert_eq!(
        s.spec.tissue,
        vec![Tissue {
            direction: Vec3::x(),
            rest_m: Vec3::new(0.6, 0.2, 0.0),
            model: TissueModel::Linear {
                stiffness_n_per_m: 300.0
            },
            damping_n_s_per_m: 5.0,
            breathing: Some(Breathing {
                amplitude_m: 0.003,
                hz: 0.25,
                direction: Vec3::x(),
            }),
            shifts: vec![TissueShift {
                t_ns: 12_000_000_000,
                offset_m: -0.002,
            }],
        }]
    );
    assert!(s.spec.contact.is_empty());
    // At the nominal pose the tip is at the surface at rest: the breathing
    // alone makes the contact (the surface nearest at 3 s, 0.9 N).
    let clock = SimClock::new(0);
    let sim = Simulator::new(s.spec.clone(), clock.clone()).unwrap();
    let t = sim.truth().unwrap();
    assert!((t.pose.tip_m - Vec3::new(0.6, 0.2, 0.0)).norm() < 1e-12);
    sar_hal::Clock::sleep_until_ns(&clock, 1_000_000_000);
    assert_eq!(sim.truth().unwrap().tissue_force_n, Vec3::zeros());
    sar_hal::Clock::sleep_until_ns(&clock, 3_000_000_000);
    let f = sim.truth().unwrap().tissue_force_n;
    assert!((f - Vec3::new(0.9, 0.0, 0.0)).norm() < 1e-9, "{f}");
}

#[test]
fn every_tissue_key_is_read() {
    let text = format!(
        "{MINIMAL}
[[tissue]]
direction = [0.0, 0.0, -2.0]
rest_m = [0.6, 0.2, 0.01]
model = \"exponential\"
stiffness_n_per_m = 500.0
beta_per_m = 80.0
damping_n_s_per_m = 3.0
breathing_amplitude_m = 0.002
breathing_hz = 0.2
breathing_direction = [0.0, 3.0, -4.0]

[[tissue.shift]]
t_s = 1.0
offset_m = 0.001

[[tissue.shift]]
t_s = 1.0
offset_m = 0.002

[[tissue]]
direction = [1.0, 0.0, 0.0]
rest_m = [0.7, 0.2, 0.0]
stiffness_n_per_m = 100.0
"
    );
    let s = parse(&text, ORIGIN).unwrap();
    assert_eq!(s.spec.tissue.len(), 2);
    let t = &s.spec.tissue[0];
    // Directions are normalised.
    assert_eq!(t.direction, Vec3::new(0.0, 0.0, -1.0));
    assert_eq!(
        t.model,
        TissueModel::Exponential {
            stiffness_n_per_m: 500.0,
            beta_per_m: 80.0
        }
    );
    assert_eq!(t.damping_n_s_per_m, 3.0);
    let b = t.breathing.unwrap();
    assert_eq!((b.amplitude_m, b.hz), (0.002, 0.2));
    assert!((b.direction - Vec3::new(0.0, 0.6, -0.8)).norm() < 1e-15);
    assert_eq!(t.shifts.len(), 2, "equal times: a step, the later key wins");
    // The second: the defaults (linear, no damping, no breathing).
    let u = &s.spec.tissue[1];
    assert_eq!(
        u.model,
        TissueModel::Linear {
            stiffness_n_per_m: 100.0
        }
    );
    assert_eq!((u.damping_n_s_per_m, u.breathing), (0.0, None));
    // The sensor's range: the HEX-E's by default, the file's when given.
    assert_eq!(s.spec.sensor.range_n, Vec3::new(200.0, 200.0, 200.0));
    assert_eq!(s.spec.sensor.range_nm, Vec3::new(10.0, 10.0, 13.0));
    let ranged = replaced(
        "noise_n = [0.2, 0.2, 0.8]",
        "noise_n = [0.2, 0.2, 0.8]\nrange_n = [290.0, 290.0, 580.0]\nrange_nm = [10.0, 10.0, 10.0]",
    );
    let s = parse(&ranged, ORIGIN).unwrap();
    assert_eq!(s.spec.sensor.range_n, Vec3::new(290.0, 290.0, 580.0));
    // A saturation with its rail.
    let railed = format!(
        "{MINIMAL}\n[[fault]]\nkind = \"sensor_saturated\"\nfrom_s = 1.0\naxes = [\"tz\", \"fx\"]\nrail = \"negative\"\n"
    );
    assert_eq!(
        parse(&railed, ORIGIN).unwrap().spec.faults,
        vec![Fault::SensorSaturated {
            from_ns: 1_000_000_000,
            until_ns: None,
            channels: [true, false, false, false, false, true],
            rail: Some(Rail::Negative),
        }]
    );
}

// ---------------------------------------------------------------------------
// Bad files.

const MINIMAL: &str = r#"
name = "minimal"
seed = 7

[robot]
gravity = [0.0, -9.80665, 0.0]
support = [0.45, 0.20, 0.0]
p_home = [0.0, 0.0, 0.0]
ujoint_offset = [0.0, -0.08, 0.0]
sensor_offset = [0.0, -0.03, 0.0]
sensor_rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

[manipulator]
length_m = 0.35
offset_m = 0.0
mass_kg = 2.593
com_m = 0.103

[sensor]
noise_n = [0.2, 0.2, 0.8]

[[motion]]
joints = [0.0, 0.28, 0.25]
hold_s = 1.0

[[motion]]
ujoint = [0.30, 0.20, 0.0]
hold_s = 1.0

[[motion]]
tip = [0.62, 0.21, 0.01]
hold_s = 1.0

[[motion]]
rod_dir = [1.0, 0.0, 0.0]
support_distance_m = 0.2
hold_s = 1.0

[[contact]]
t_s = 1.0
force_n = [1.0, 0.0, 0.0]

[[contact]]
t_s = 2.0
force_n = [0.0, 0.0, 0.0]
"#;

const ORIGIN: &str = "scenarios/under_test.toml";

/// The minimal file with a linear tissue, `from` replaced by `to` in the
/// tissue's table.
fn tissue(from: &str, to: &str) -> String {
    let table = "\n[[tissue]]\ndirection = [1.0, 0.0, 0.0]\nrest_m = [0.6, 0.2, 0.0]\nstiffness_n_per_m = 300.0\n";
    assert!(table.contains(from), "the tissue table has no {from:?}");
    format!("{MINIMAL}{}", table.replacen(from, to, 1))
}

/// The minimal file with one `[[fault]]` table of `body`.
fn fault(body: &str) -> String {
    format!("{MINIMAL}\n[[fault]]\n{body}")
}

fn replaced(from: &str, to: &str) -> String {
    assert!(MINIMAL.contains(from), "the base file has no {from:?}");
    MINIMAL.replacen(from, to, 1)
}

fn refused(text: &str) -> ConfigError {
    match parse(text, ORIGIN) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e,
    }
}

#[test]
fn the_minimal_file_is_good_and_its_targets_resolve() {
    let s = parse(MINIMAL, ORIGIN).unwrap();
    let targets: Vec<ActiveJoints> = s.script.steps.iter().map(|st| st.target).collect();
    let cal = &s.spec.calibration;
    let profile = &s.spec.profile;
    // joints as given.
    assert_eq!(
        targets[0],
        ActiveJoints {
            q1_m: 0.0,
            q2_m: 0.28,
            q3_m: 0.25
        }
    );
    // ujoint: A where asked.
    let a1 = forward(cal, profile, &targets[1]).unwrap().ujoint_m;
    assert!((a1 - Vec3::new(0.30, 0.20, 0.0)).norm() < 1e-12);
    // tip: D where asked.
    let d2 = forward(cal, profile, &targets[2]).unwrap().tip_m;
    assert!((d2 - Vec3::new(0.62, 0.21, 0.01)).norm() < 1e-12);
    // rod_dir + a: u and a as asked.
    let p3 = forward(cal, profile, &targets[3]).unwrap();
    assert!((p3.rod_dir - Vec3::x()).norm() < 1e-12);
    assert!((p3.support_distance_m - 0.2).abs() < 1e-12);
    // Defaults: the article's axes and the HEX-6.
    assert_eq!(s.spec.axes.max_speed_mps, 0.05);
    assert_eq!(s.spec.axes.position_period_ns, 1_000_000);
    assert_eq!(s.spec.sensor.latency_ns, 1_000_000);
    assert_eq!(s.spec.physics_step_ns, 100_000);
    assert_eq!(s.spec.friction_n, 0.0);
    // No start given: the first target.
    assert_eq!(s.script.start, targets[0]);
    assert_eq!(s.spec.contact[0].t_ns, 1_000_000_000);
}

/// (what is wrong, the file, the key the message must name, a fragment of the problem)
fn bad_files() -> Vec<(&'static str, String, &'static str, &'static str)> {
    vec![
        (
            "missing key",
            replaced("mass_kg = 2.593\n", ""),
            "manipulator.mass_kg",
            "missing key",
        ),
        (
            "missing top-level key",
            replaced("name = \"minimal\"\n", ""),
            "name",
            "missing key",
        ),
        (
            "missing table",
            replaced("[robot]", "[robt]"),
            "robt",
            "unknown key",
        ),
        (
            "unknown key (typo)",
            replaced("noise_n =", "noise ="),
            "sensor.noise",
            "unknown key",
        ),
        (
            "unknown key in a step",
            replaced(
                "hold_s = 1.0\n\n[[motion]]\nujoint",
                "hold = 1.0\n\n[[motion]]\nujoint",
            ),
            "motion[0].hold",
            "unknown key",
        ),
        (
            "wrong type",
            replaced("com_m = 0.103", "com_m = \"0.103\""),
            "manipulator.com_m",
            "invalid type",
        ),
        (
            "wrong type in an array",
            replaced("support = [0.45, 0.20, 0.0]", "support = [0.45, true, 0.0]"),
            "robot.support[1]",
            "invalid type",
        ),
        (
            "wrong array length",
            replaced("p_home = [0.0, 0.0, 0.0]", "p_home = [0.0, 0.0]"),
            "robot.p_home",
            "length",
        ),
        (
            // Issue 25: serde's arrays ignored the elements past their length.
            "array too long",
            replaced(
                "support = [0.45, 0.20, 0.0]",
                "support = [0.45, 0.2, 0.0, 7.0]",
            ),
            "robot.support",
            "invalid length 4, expected an array of length 3",
        ),
        (
            "a row too many",
            replaced("[0.0, 0.0, 1.0]]", "[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]"),
            "robot.sensor_rotation",
            "invalid length 4",
        ),
        (
            "an optional array too long",
            replaced(
                "noise_n = [0.2, 0.2, 0.8]",
                "noise_n = [0.2, 0.2, 0.8, 0.8]",
            ),
            "sensor.noise_n",
            "invalid length 4",
        ),
        (
            "NaN",
            replaced("support = [0.45, 0.20, 0.0]", "support = [0.45, nan, 0.0]"),
            "robot.support[1]",
            "not a finite number",
        ),
        (
            "infinity",
            replaced("t_s = 2.0", "t_s = inf"),
            "contact[1].t_s",
            "not a finite number",
        ),
        (
            "rotation not orthonormal",
            replaced(
                "[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
                "[0.0, 1.0, 0.1], [0.0, 0.0, 1.0]]",
            ),
            "robot.sensor_rotation",
            "not orthonormal",
        ),
        (
            "rotation a reflection",
            replaced("[0.0, 0.0, 1.0]]", "[0.0, 0.0, -1.0]]"),
            "robot.sensor_rotation",
            "determinant",
        ),
        (
            "gravity out of range",
            replaced(
                "gravity = [0.0, -9.80665, 0.0]",
                "gravity = [0.0, 0.0, 0.0]",
            ),
            "robot.gravity",
            "magnitude",
        ),
        (
            "negative mass",
            replaced("mass_kg = 2.593", "mass_kg = -2.593"),
            "manipulator.mass_kg",
            ">= 0",
        ),
        (
            "non-positive length",
            replaced("length_m = 0.35", "length_m = 0.0"),
            "manipulator.length_m",
            "> 0",
        ),
        (
            "negative noise",
            replaced("noise_n = [0.2, 0.2, 0.8]", "noise_n = [0.2, 0.2, -0.8]"),
            "sensor.noise_n[2]",
            ">= 0",
        ),
        (
            "negative seed",
            replaced("seed = 7", "seed = -7"),
            "seed",
            "u64",
        ),
        (
            "negative hold",
            replaced(
                "support_distance_m = 0.2\nhold_s = 1.0",
                "support_distance_m = 0.2\nhold_s = -1.0",
            ),
            "motion[3].hold_s",
            ">= 0",
        ),
        (
            "unsorted contact keys",
            replaced("t_s = 2.0", "t_s = 0.5"),
            "contact[1].t_s",
            "sorted",
        ),
        (
            "step with no target",
            replaced("ujoint = [0.30, 0.20, 0.0]\n", ""),
            "motion[1]",
            "no target",
        ),
        (
            "step with two targets",
            replaced(
                "ujoint = [0.30, 0.20, 0.0]\n",
                "ujoint = [0.30, 0.20, 0.0]\njoints = [0.0, 0.28, 0.30]\n",
            ),
            "motion[1]",
            "2 targets",
        ),
        (
            "a distance without rod_dir",
            replaced(
                "ujoint = [0.30, 0.20, 0.0]\n",
                "ujoint = [0.30, 0.20, 0.0]\nsupport_distance_m = 0.1\n",
            ),
            "motion[1].support_distance_m",
            "only allowed with rod_dir",
        ),
        (
            "rod_dir without a distance",
            replaced("support_distance_m = 0.2\n", ""),
            "motion[3].support_distance_m",
            "missing key",
        ),
        (
            "zero rod_dir",
            replaced("rod_dir = [1.0, 0.0, 0.0]", "rod_dir = [0.0, 0.0, 0.0]"),
            "motion[3].rod_dir",
            "zero",
        ),
        (
            "tip the rod cannot reach",
            replaced("tip = [0.62, 0.21, 0.01]", "tip = [0.85, 0.20, 0.0]"),
            "motion[2].tip",
            "kinematics",
        ),
        (
            "U-joint at the support",
            replaced("ujoint = [0.30, 0.20, 0.0]", "ujoint = [0.45, 0.20, 0.0]"),
            "motion[1].ujoint",
            "kinematics refuses",
        ),
        (
            "vertical rod",
            replaced("ujoint = [0.30, 0.20, 0.0]", "ujoint = [0.45, 0.00, 0.0]"),
            "motion[1].ujoint",
            "vertical",
        ),
        (
            "a path through the support",
            replaced("tip = [0.62, 0.21, 0.01]", "ujoint = [0.60, 0.20, 0.0]"),
            "motion[2]",
            "from the support",
        ),
        (
            "a path through the vertical",
            replaced(
                "tip = [0.62, 0.21, 0.01]",
                "ujoint = [0.44, 0.10, 0.0]\nhold_s = 0.0\n\n[[motion]]\nujoint = [0.46, 0.10, 0.0]",
            ),
            "motion[3]",
            "vertical",
        ),
        (
            "outside the travel",
            replaced("joints = [0.0, 0.28, 0.25]", "joints = [0.0, 0.28, 0.65]"),
            "motion[0].joints",
            "outside the travel",
        ),
        (
            "start outside the travel",
            replaced("[sensor]", "[axes]\nstart = [0.5, 0.28, 0.25]\n\n[sensor]"),
            "axes.start",
            "outside the travel",
        ),
        (
            "empty travel",
            replaced(
                "[sensor]",
                "[axes]\ntravel_m = [[-0.3, 0.3], [0.6, 0.0], [0.0, 0.6]]\n\n[sensor]",
            ),
            "axes.travel_m[1]",
            "min must be below max",
        ),
        (
            "zero speed",
            replaced("[sensor]", "[axes]\nmax_speed_mps = 0.0\n\n[sensor]"),
            "axes.max_speed_mps",
            "> 0",
        ),
        (
            "negative friction",
            replaced("[sensor]", "[support]\nfriction_n = -0.3\n\n[sensor]"),
            "support.friction_n",
            ">= 0",
        ),
        (
            "empty support table",
            replaced("[sensor]", "[support]\n\n[sensor]"),
            "support.friction_n",
            "missing key",
        ),
        (
            "negative tip mass",
            format!("{MINIMAL}\n[tip_mass]\nmass_kg = -0.5\n"),
            "tip_mass.mass_kg",
            ">= 0",
        ),
        (
            "no steps",
            MINIMAL.split("[[motion]]").next().unwrap().to_owned(),
            "motion",
            "no steps",
        ),
        (
            "unknown fault kind",
            format!("{MINIMAL}\n[[fault]]\nkind = \"sensor_stuck\"\nat_s = 1.0\n"),
            "fault[0].kind",
            "unknown variant",
        ),
        (
            "a key of another fault kind",
            format!("{MINIMAL}\n[[fault]]\nkind = \"nan_sample\"\nat_s = 1.0\ncode = 3\n"),
            "fault[0].code",
            "not a key of a nan_sample fault",
        ),
        (
            "fault missing its time",
            format!("{MINIMAL}\n[[fault]]\nkind = \"drive_fault\"\ncode = 3\n"),
            "fault[0].at_s",
            "missing key",
        ),
        (
            "silence ending before it starts",
            format!(
                "{MINIMAL}\n[[fault]]\nkind = \"sensor_silent\"\nfrom_s = 2.0\nuntil_s = 1.0\n"
            ),
            "fault[0].until_s",
            "after from_s",
        ),
        (
            "bad axis name",
            format!(
                "{MINIMAL}\n[[fault]]\nkind = \"encoder_jump\"\nat_s = 1.0\naxis = \"q4\"\njump_m = 0.001\n"
            ),
            "fault[0].axis",
            "unknown variant",
        ),
        (
            "fault code out of range",
            format!("{MINIMAL}\n[[fault]]\nkind = \"drive_fault\"\nat_s = 1.0\ncode = 70000\n"),
            "fault[0].code",
            "u16",
        ),
        (
            "random motion past the tip",
            format!(
                "{MINIMAL}\n[random_motion]\ncount = 3\nmax_angle_deg = 10.0\nbeyond_m = [0.1, 0.4]\nhold_s = 1.0\n"
            ),
            "random_motion.beyond_m",
            "< L",
        ),
        (
            "physics step too long",
            replaced("seed = 7", "seed = 7\nphysics_step_s = 0.5"),
            "physics_step_s",
            "0.01",
        ),
        (
            "sensor rate zero",
            replaced(
                "noise_n = [0.2, 0.2, 0.8]",
                "noise_n = [0.2, 0.2, 0.8]\nrate_hz = 0.0",
            ),
            "sensor.rate_hz",
            "Hz",
        ),
        (
            // Accepted by every key's own check; refused by the simulator.
            "latency that puts too many samples in flight",
            replaced(
                "noise_n = [0.2, 0.2, 0.8]",
                "noise_n = [0.2, 0.2, 0.8]\nlatency_s = 200.0",
            ),
            "sensor.latency_s",
            "in flight",
        ),
        (
            "negative sensor range",
            replaced(
                "noise_n = [0.2, 0.2, 0.8]",
                "noise_n = [0.2, 0.2, 0.8]\nrange_n = [200.0, -1.0, 200.0]",
            ),
            "sensor.range_n[1]",
            "> 0",
        ),
        (
            "zero tissue direction",
            tissue("direction = [1.0, 0.0, 0.0]", "direction = [0.0, 0.0, 0.0]"),
            "tissue[0].direction",
            "zero vector",
        ),
        (
            "tissue stiffness zero",
            tissue("stiffness_n_per_m = 300.0", "stiffness_n_per_m = 0.0"),
            "tissue[0].stiffness_n_per_m",
            "N/m",
        ),
        (
            "tissue key typo",
            tissue("stiffness_n_per_m", "stifness_n_per_m"),
            "tissue[0].stifness_n_per_m",
            "unknown key",
        ),
        (
            "unknown tissue model",
            tissue("rest_m", "model = \"quadratic\"\nrest_m"),
            "tissue[0].model",
            "unknown variant",
        ),
        (
            "NaN tissue rest point",
            tissue("rest_m = [0.6,", "rest_m = [nan,"),
            "tissue[0].rest_m[0]",
            "not a finite number",
        ),
        (
            "beta with a linear tissue",
            tissue("rest_m", "beta_per_m = 10.0\nrest_m"),
            "tissue[0].beta_per_m",
            "only allowed with model = \"exponential\"",
        ),
        (
            "exponential tissue without beta",
            tissue("rest_m", "model = \"exponential\"\nrest_m"),
            "tissue[0].beta_per_m",
            "missing key",
        ),
        (
            "negative damping",
            tissue("rest_m", "damping_n_s_per_m = -1.0\nrest_m"),
            "tissue[0].damping_n_s_per_m",
            "must be in [0,",
        ),
        (
            "breathing without amplitude",
            tissue("rest_m", "breathing_hz = 0.25\nrest_m"),
            "tissue[0].breathing_hz",
            "only allowed with breathing_amplitude_m",
        ),
        (
            "breathing without frequency",
            tissue("rest_m", "breathing_amplitude_m = 0.003\nrest_m"),
            "tissue[0].breathing_hz",
            "missing key",
        ),
        (
            "breathing too fast",
            tissue(
                "rest_m",
                "breathing_amplitude_m = 0.003\nbreathing_hz = 25.0\nrest_m",
            ),
            "tissue[0].breathing_hz",
            "Hz",
        ),
        (
            "unsorted tissue shifts",
            format!(
                "{}\n[[tissue.shift]]\nt_s = 2.0\noffset_m = 0.001\n\n[[tissue.shift]]\nt_s = 1.0\noffset_m = 0.0\n",
                tissue("", "")
            ),
            "tissue[0].shift[1].t_s",
            "sorted",
        ),
        (
            "tissue shift too far",
            format!(
                "{}\n[[tissue.shift]]\nt_s = 2.0\noffset_m = 1.5\n",
                tissue("", "")
            ),
            "tissue[0].shift[0].offset_m",
            "at most 1 m",
        ),
        (
            "saturation without channels",
            fault("kind = \"sensor_saturated\"\nfrom_s = 1.0\n"),
            "fault[0].axes",
            "missing key",
        ),
        (
            "saturation of no channel",
            fault("kind = \"sensor_saturated\"\nfrom_s = 1.0\naxes = []\n"),
            "fault[0].axes",
            "at least one channel",
        ),
        (
            "a channel named twice",
            fault("kind = \"sensor_saturated\"\nfrom_s = 1.0\naxes = [\"fz\", \"fz\"]\n"),
            "fault[0].axes[1]",
            "names fz twice",
        ),
        (
            "unknown channel",
            fault("kind = \"sensor_saturated\"\nfrom_s = 1.0\naxes = [\"fw\"]\n"),
            "fault[0].axes[0]",
            "unknown variant",
        ),
        (
            "unknown rail",
            fault("kind = \"sensor_saturated\"\nfrom_s = 1.0\naxes = [\"fz\"]\nrail = \"up\"\n"),
            "fault[0].rail",
            "unknown variant",
        ),
        (
            "a spike of nothing",
            fault("kind = \"sensor_spike\"\nat_s = 1.0\nforce_n = [0.0, 0.0, 0.0]\n"),
            "fault[0].force_n",
            "changes nothing",
        ),
        (
            "a spike of no samples",
            fault("kind = \"sensor_spike\"\nat_s = 1.0\nforce_n = [0.0, 0.0, 9.0]\nsamples = 0\n"),
            "fault[0].samples",
            ">= 1",
        ),
        (
            "a drift without its rate",
            fault("kind = \"sensor_drift\"\nfrom_s = 1.0\n"),
            "fault[0].drift_n_per_s",
            "missing key",
        ),
        (
            "a zero gain",
            fault("kind = \"sensor_scale\"\nfrom_s = 1.0\nfactor = 0.0\n"),
            "fault[0].factor",
            "must be in",
        ),
        (
            "a frozen encoder thawing before it freezes",
            fault("kind = \"encoder_frozen\"\nat_s = 2.0\naxis = \"q1\"\nuntil_s = 1.0\n"),
            "fault[0].until_s",
            "after at_s = 2 s",
        ),
        (
            "no counts lost",
            fault("kind = \"encoder_count_loss\"\nat_s = 1.0\naxis = \"q2\"\ncounts = 0\n"),
            "fault[0].counts",
            "non-zero",
        ),
        (
            "more than a metre of counts lost",
            fault("kind = \"encoder_count_loss\"\nat_s = 1.0\naxis = \"q2\"\ncounts = 1000000\n"),
            "fault[0].counts",
            "at most 1 m",
        ),
        (
            "an EMCY with code 0",
            fault("kind = \"drive_emcy\"\nat_s = 1.0\naxis = \"q2\"\ncode = 0\n"),
            "fault[0].code",
            "must not be 0",
        ),
        (
            "a heartbeat loss with a code",
            fault("kind = \"drive_heartbeat_loss\"\nat_s = 1.0\naxis = \"q2\"\ncode = 1\n"),
            "fault[0].code",
            "not a key of a drive_heartbeat_loss fault",
        ),
        (
            "a heartbeat loss without its axis",
            fault("kind = \"drive_heartbeat_loss\"\nat_s = 1.0\n"),
            "fault[0].axis",
            "missing key",
        ),
        (
            // Apart in seconds, equal once in ns.
            "silent window of zero length in ns",
            format!(
                "{MINIMAL}\n[[fault]]\nkind = \"sensor_silent\"\nfrom_s = 1.0\nuntil_s = 1.0000000001\n"
            ),
            "fault",
            "until_ns",
        ),
        (
            "negative rod inertia",
            replaced(
                "com_m = 0.103\n",
                "com_m = 0.103\ninertia_perp_kgm2 = -0.01\n",
            ),
            "manipulator.inertia_perp_kgm2",
            "must be >= 0",
        ),
        (
            "infinite axial inertia",
            replaced(
                "com_m = 0.103\n",
                "com_m = 0.103\ninertia_axial_kgm2 = inf\n",
            ),
            "manipulator.inertia_axial_kgm2",
            "finite",
        ),
        (
            "negative adapter mass",
            replaced(
                "noise_n = [0.2, 0.2, 0.8]",
                "noise_n = [0.2, 0.2, 0.8]\nadapter_mass_kg = -0.1",
            ),
            "sensor.adapter_mass_kg",
            "must be >= 0",
        ),
        (
            "servo without bandwidth",
            format!("{MINIMAL}\n[axes]\nservo_bandwidth_hz = 0.0\n"),
            "axes.servo_bandwidth_hz",
            "must be > 0",
        ),
        (
            "servo faster than the physics step samples",
            format!("{MINIMAL}\n[axes]\nservo_bandwidth_hz = 1000.0\n"),
            "axes.servo_bandwidth_hz",
            "physics step",
        ),
        (
            "servo without damping",
            format!("{MINIMAL}\n[axes]\nservo_damping = -0.7\n"),
            "axes.servo_damping",
            "must be > 0",
        ),
        (
            "servo without acceleration",
            format!("{MINIMAL}\n[axes]\nservo_max_accel_mps2 = 0.0\n"),
            "axes.servo_max_accel_mps2",
            "must be > 0",
        ),
        (
            "servo with a negative delay",
            format!("{MINIMAL}\n[axes]\nservo_delay_s = -0.001\n"),
            "axes.servo_delay_s",
            "must be >= 0",
        ),
        (
            "servo with a delay beyond the simulator's",
            format!("{MINIMAL}\n[axes]\nservo_delay_s = 0.05\n"),
            "axes.servo_delay_s",
            "at most 0.02 s",
        ),
        (
            "servo with a negative inner loop",
            format!("{MINIMAL}\n[axes]\nservo_inner_loop_hz = -40.0\n"),
            "axes.servo_inner_loop_hz",
            "must be >= 0",
        ),
        (
            "quick stop without deceleration",
            format!("{MINIMAL}\n[axes]\nquick_stop_decel_mps2 = 0.0\n"),
            "axes.quick_stop_decel_mps2",
            "must be > 0",
        ),
    ]
}

/// The plant in motion is opt-in: without its keys, none of it; with one
/// key of a group, the group with its stated defaults (I_perp = m L^2 / 12).
#[test]
fn the_plant_keys_are_opt_in_with_stated_defaults() {
    assert_eq!(
        parse(MINIMAL, ORIGIN).unwrap().spec.plant,
        PlantSpec::default()
    );
    let adapter = replaced(
        "noise_n = [0.2, 0.2, 0.8]",
        "noise_n = [0.2, 0.2, 0.8]\nadapter_mass_kg = 0.2",
    );
    let text = format!("{adapter}\n[axes]\nservo_damping = 0.8\n");
    let plant = parse(&text, ORIGIN).unwrap().spec.plant;
    assert_eq!(
        plant.inertia,
        Some(RodInertia {
            inertia_perp_kgm2: 2.593 * 0.35f64.powi(2) / 12.0,
            inertia_axial_kgm2: 0.0,
            adapter_mass_kg: 0.2,
        })
    );
    assert_eq!(
        plant.servo,
        Some(ServoSpec {
            bandwidth_hz: 30.0,
            damping: 0.8,
            max_accel_mps2: 5.0,
            delay_ns: 0,
            inner_loop_hz: 0.0,
        })
    );
    assert_eq!(plant.quick_stop_decel_mps2, None);
    let every = replaced(
        "com_m = 0.103\n",
        "com_m = 0.103\ninertia_perp_kgm2 = 0.03\ninertia_axial_kgm2 = 0.001\n",
    );
    let text = format!(
        "{every}\n[axes]\nservo_bandwidth_hz = 20.0\nservo_max_accel_mps2 = 8.0\nquick_stop_decel_mps2 = 2.0\nservo_delay_s = 0.0015\nservo_inner_loop_hz = 40.0\n"
    );
    let plant = parse(&text, ORIGIN).unwrap().spec.plant;
    assert_eq!(
        plant,
        PlantSpec {
            inertia: Some(RodInertia {
                inertia_perp_kgm2: 0.03,
                inertia_axial_kgm2: 0.001,
                adapter_mass_kg: 0.0,
            }),
            servo: Some(ServoSpec {
                bandwidth_hz: 20.0,
                damping: 0.7,
                max_accel_mps2: 8.0,
                delay_ns: 1_500_000,
                inner_loop_hz: 40.0,
            }),
            quick_stop_decel_mps2: Some(2.0),
        }
    );
}

#[test]
fn each_kind_of_bad_file_is_refused_naming_the_file_the_key_and_the_problem() {
    for (what, text, key, problem) in bad_files() {
        let e = refused(&text);
        let message = e.to_string();
        assert!(
            message.starts_with(&format!("{ORIGIN}: {key}")),
            "{what}: the message does not start with the file and key {key:?}: {message}"
        );
        assert_eq!(e.key(), Some(key), "{what}: {message}");
        assert_eq!(e.origin(), ORIGIN);
        assert!(
            message.contains(problem),
            "{what}: the message does not say {problem:?}: {message}"
        );
        assert!(!message.contains('\n'), "{what}: one line: {message}");
    }
}

#[test]
fn errors_give_the_line_of_the_key() {
    let text = replaced(
        "hold_s = 1.0\n\n[[motion]]\ntip",
        "hold_s = -3.0\n\n[[motion]]\ntip",
    );
    let line = text.lines().position(|l| l == "hold_s = -3.0").unwrap() + 1;
    let e = refused(&text);
    assert_eq!(e.key(), Some("motion[1].hold_s"));
    assert!(e.to_string().contains(&format!("(line {line})")), "{e}");
}

#[test]
fn syntax_errors_keep_tomls_line_and_column() {
    let text = replaced("support = [0.45, 0.20, 0.0]", "support = [0.45, 0.20 0.0]");
    let e = refused(&text);
    assert!(matches!(e, ConfigError::Syntax { .. }), "{e:?}");
    let line = text
        .lines()
        .position(|l| l.starts_with("support ="))
        .unwrap()
        + 1;
    let message = e.to_string();
    assert!(message.starts_with(ORIGIN), "{message}");
    assert!(
        message.contains(&format!("line {line}, column")),
        "{message}"
    );
}

#[test]
fn load_names_the_path_for_a_missing_and_for_a_bad_file() {
    let dir = std::env::temp_dir().join(format!("sar-scenario-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("does_not_exist.toml");
    let e = load(&missing).unwrap_err();
    assert!(matches!(e, ConfigError::Read { .. }));
    assert!(
        e.to_string().starts_with(&missing.display().to_string()),
        "{e}"
    );
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, replaced("mass_kg = 2.593", "mass_kg = -1.0")).unwrap();
    let e = load(&bad).unwrap_err();
    assert!(
        e.to_string()
            .starts_with(&format!("{}: manipulator.mass_kg", bad.display())),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 300,
        rng_seed: RngSeed::Fixed(0x5ce7_a210),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Any edit of a good file either still loads or is refused with a
    /// one-line-or-toml message that starts with the file's name; never a panic.
    #[test]
    fn any_edit_loads_or_is_refused_naming_the_file(
        at in 0usize..MINIMAL.len(),
        cut in 0usize..4,
        insert in prop::sample::select(vec!["", "x", "-", "1", "\"", "[", "]", "=", ".", "\n", "nan", "[[motion]]\n"]),
    ) {
        let mut text = MINIMAL.to_owned();
        let at = (0..=at).rev().find(|i| text.is_char_boundary(*i)).unwrap();
        let end = (at + cut).min(text.len());
        text.replace_range(at..end, insert);
        match parse(&text, ORIGIN) {
            Err(e) => prop_assert!(e.to_string().starts_with(&format!("{ORIGIN}: ")), "{}", e),
            // A file that loads is one the simulator accepts.
            Ok(s) => prop_assert!(
                Simulator::new(s.spec, SimClock::new(0)).is_ok(),
                "loaded but refused by the simulator:\n{}",
                text
            ),
        }
    }
}

// ---------------------------------------------------------------------------
// Motion timing.

#[test]
fn axis_profile_is_time_optimal_and_ends_at_the_target() {
    let (v, a) = (0.05, 0.5);
    for d in [0.0, 1e-4, 0.004, 0.005, 0.02, 0.3, -0.1] {
        let total = axis_move_time_s(d, v, a);
        // Trapezoid or triangle, by hand.
        let want = if d.abs() >= v * v / a {
            d.abs() / v + v / a
        } else {
            2.0 * (d.abs() / a).sqrt()
        };
        assert!((total - want).abs() < 1e-12, "d = {d}");
        assert_eq!(axis_progress_m(d, v, a, total), d);
        assert_eq!(axis_progress_m(d, v, a, 0.0), 0.0);
        // Monotone, within the speed limit, half way at half time (symmetric).
        let mut last = 0.0f64;
        let n = 1000;
        for k in 1..=n {
            let t = total * f64::from(k) / f64::from(n);
            let x = axis_progress_m(d, v, a, t);
            assert!(x.abs() >= last.abs() - 1e-15);
            assert!((x - last).abs() <= v * total / f64::from(n) + 1e-12);
            last = x;
        }
        assert!((axis_progress_m(d, v, a, total / 2.0) - d / 2.0).abs() < 1e-12);
    }
}

#[test]
fn nominal_duration_sums_moves_and_holds() {
    let s = parse(MINIMAL, ORIGIN).unwrap();
    let mut from = s.script.start;
    let mut total_s = 0.0;
    for st in &s.script.steps {
        total_s += move_time_s(&from, &st.target, 0.05, 0.5) + st.hold_ns as f64 * 1e-9;
        from = st.target;
    }
    let got_s = s.script.nominal_duration_ns() as f64 * 1e-9;
    assert!((got_s - total_s).abs() < 1e-6, "{got_s} vs {total_s}");
    assert!(got_s > 4.0);
}

#[test]
fn slide_tracker_follows_the_last_slide_with_hysteresis() {
    let s = parse(MINIMAL, ORIGIN).unwrap();
    let mut t = SlideTracker::new(&s.spec.calibration);
    // Along X0 at the support's height: a = 0.45 - q3.
    let at = |q3: f64| ActiveJoints {
        q1_m: 0.0,
        q2_m: 0.28,
        q3_m: q3,
    };
    t.update(&at(0.25));
    assert_eq!(t.sign(), SlideSign::Unknown);
    // Less than the threshold: nothing yet.
    t.update(&at(0.25 + 0.5 * SLIDE_THRESHOLD_M));
    assert_eq!(t.sign(), SlideSign::Unknown);
    // Towards B (a shrinks): the rod slides along u.
    assert!(t.update(&at(0.26)));
    assert_eq!(t.sign(), SlideSign::Inserting);
    // A back-step within the threshold (quantisation) does not flip it.
    assert!(!t.update(&at(0.26 - 0.5 * SLIDE_THRESHOLD_M)));
    assert_eq!(t.sign(), SlideSign::Inserting);
    // A real retreat does.
    assert!(t.update(&at(0.25)));
    assert_eq!(t.sign(), SlideSign::Retracting);
}

// ---------------------------------------------------------------------------
// The runner on fakes: drives that move each axis at constant speed and report
// positions every millisecond; a sensor that sends a numbered sample every 2 ms.

#[derive(Debug, Clone, PartialEq)]
struct FakeError(ErrorKind);

impl std::fmt::Display for FakeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "fake: {}", self.0)
    }
}

impl sar_hal::Error for FakeError {
    fn kind(&self) -> ErrorKind {
        self.0
    }
}

struct FakeDrives {
    clock: SimClock,
    speed_mps: f64,
    /// Per axis: (position at `since_ns`, target).
    axes: [(f64, f64); 3],
    since_ns: u64,
    state: DriveState,
    fault_at_ns: Option<u64>,
    stuck: bool,
    refuse_enable: bool,
    refuse_targets: bool,
    commands: Rc<RefCell<Vec<(u64, ActiveJoints)>>>,
}

impl FakeDrives {
    fn new(clock: &SimClock, start: ActiveJoints) -> Self {
        Self {
            clock: clock.clone(),
            speed_mps: 0.05,
            axes: [
                (start.q1_m, start.q1_m),
                (start.q2_m, start.q2_m),
                (start.q3_m, start.q3_m),
            ],
            since_ns: clock.now_ns(),
            state: DriveState::Ready,
            fault_at_ns: None,
            stuck: false,
            refuse_enable: false,
            refuse_targets: false,
            commands: Rc::default(),
        }
    }

    fn at(&self, t_ns: u64) -> [f64; 3] {
        let dt = (t_ns.saturating_sub(self.since_ns)) as f64 * 1e-9;
        self.axes.map(|(x, target)| {
            if self.stuck {
                return x;
            }
            let step = self.speed_mps * dt;
            if (target - x).abs() <= step {
                target
            } else {
                x + step * (target - x).signum()
            }
        })
    }

    fn update_fault(&mut self) {
        if let Some(at) = self.fault_at_ns
            && self.clock.now_ns() >= at
            && !matches!(self.state, DriveState::Fault { .. })
        {
            let now = self.at(at);
            self.axes = [(now[0], now[0]), (now[1], now[1]), (now[2], now[2])];
            self.since_ns = at;
            self.state = DriveState::Fault {
                axis: None,
                code: 0x2310,
            };
        }
    }
}

impl AxisDrives for FakeDrives {
    type Error = FakeError;

    fn positions(&mut self) -> Result<JointPositions, FakeError> {
        self.update_fault();
        let stamp_ns = self.clock.now_ns() / 1_000_000 * 1_000_000;
        let [q1_m, q2_m, q3_m] = self.at(stamp_ns.max(self.since_ns));
        Ok(JointPositions {
            joints: ActiveJoints { q1_m, q2_m, q3_m },
            stamp_ns,
            valid: !matches!(self.state, DriveState::Fault { .. }),
        })
    }

    fn state(&mut self) -> Result<DriveState, FakeError> {
        self.update_fault();
        Ok(self.state)
    }

    fn enable(&mut self) -> Result<(), FakeError> {
        if self.refuse_enable {
            return Err(FakeError(ErrorKind::InvalidState));
        }
        self.state = DriveState::Enabled;
        Ok(())
    }

    fn disable(&mut self) -> Result<(), FakeError> {
        self.state = DriveState::Ready;
        Ok(())
    }

    fn stream(&mut self, _targets: ActiveJoints, _period_ns: u64) -> Result<(), FakeError> {
        // The runner never streams.

        Err(FakeError(ErrorKind::Unsupported))
    }

    fn set_targets(&mut self, targets: ActiveJoints) -> Result<(), FakeError> {
        self.update_fault();
        if self.state != DriveState::Enabled {
            return Err(FakeError(ErrorKind::InvalidState));
        }
        if self.refuse_targets {
            return Err(FakeError(ErrorKind::InvalidArgument));
        }
        let now = self.clock.now_ns();
        let x = self.at(now);
        self.axes = [
            (x[0], targets.q1_m),
            (x[1], targets.q2_m),
            (x[2], targets.q3_m),
        ];
        self.since_ns = now;
        self.commands.borrow_mut().push((now, targets));
        Ok(())
    }

    fn quick_stop(&mut self) -> Result<(), FakeError> {
        self.state = DriveState::QuickStop;
        Ok(())
    }

    fn fault_reset(&mut self) -> Result<(), FakeError> {
        self.state = DriveState::Ready;
        Ok(())
    }
}

struct FakeSensor {
    clock: SimClock,
    last_k: Option<u64>,
    period_ns: u64,
}

impl ForceSensor for FakeSensor {
    type Error = FakeError;

    fn poll(&mut self) -> Result<Option<WrenchSample>, FakeError> {
        let k = self.clock.now_ns() / self.period_ns;
        if self.last_k == Some(k) {
            return Ok(None);
        }
        self.last_k = Some(k);
        Ok(Some(WrenchSample {
            force_n: Vec3::new(k as f64, 0.0, 0.0),
            torque_nm: Vec3::zeros(),
            counter: k as u32,
            status: SensorStatus::OK,
            received_ns: k * self.period_ns,
        }))
    }

    fn wait(&mut self, _timeout_ns: u64) -> Result<WrenchSample, FakeError> {
        Err(FakeError(ErrorKind::Unsupported))
    }

    fn tare(&mut self) -> Result<(), FakeError> {
        Err(FakeError(ErrorKind::Unsupported))
    }

    fn clear_tare(&mut self) -> Result<(), FakeError> {
        Err(FakeError(ErrorKind::Unsupported))
    }

    fn drain(&mut self, _out: &mut [WrenchSample]) -> Result<sar_hal::Drained, FakeError> {
        Err(FakeError(ErrorKind::Unsupported))
    }
}

fn fakes(s: &Scenario) -> (SimClock, FakeSensor, FakeDrives) {
    let clock = SimClock::new(5_000_000_000);
    let sensor = FakeSensor {
        clock: clock.clone(),
        last_k: None,
        period_ns: 2_000_000,
    };
    let drives = FakeDrives::new(&clock, s.script.start);
    (clock, sensor, drives)
}

#[test]
fn runner_goes_through_the_script_and_records_everything() {
    let s = load_named("identify_manipulator_2.toml");
    let (clock, mut sensor, mut drives) = fakes(&s);
    let commands = Rc::clone(&drives.commands);
    let options = RunOptions::for_script(&s.script, 1_000_000);
    let r = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap();
    assert_eq!(r.end, EndReason::ScriptDone);
    assert_eq!(r.start_ns, 5_000_000_000);
    assert_eq!(r.end_ns, clock.now_ns());
    assert!(r.events.is_empty(), "{:?}", r.events);
    // Each step commanded once, in order, after the previous hold.
    let commands = commands.borrow();
    assert_eq!(commands.len(), s.script.steps.len());
    for (c, st) in commands.iter().zip(&s.script.steps) {
        assert_eq!(c.1, st.target);
    }
    // Every sample, once, in order: a 2 ms grid with no gap.
    for w in r.sensor_samples.windows(2) {
        assert_eq!(w[1].counter, w[0].counter + 1);
    }
    for w in r.positions.windows(2) {
        assert_eq!(w[1].stamp_ns, w[0].stamp_ns + 1_000_000);
    }
    let elapsed = r.end_ns - r.start_ns;
    assert_eq!(r.positions.len() as u64, elapsed / 1_000_000 + 1);
    // Holds: one per step with a hold time, as long as asked, at the target.
    let held: Vec<usize> = (0..s.script.steps.len())
        .filter(|&i| s.script.steps[i].hold_ns > 0)
        .collect();
    assert_eq!(r.holds.iter().map(|h| h.step).collect::<Vec<_>>(), held);
    for h in &r.holds {
        let step = &s.script.steps[h.step];
        assert!(h.arrived);
        assert!(h.end_ns - h.start_ns >= step.hold_ns);
        assert!(h.end_ns - h.start_ns < step.hold_ns + 2_000_000);
        let record = &r.steps[h.step];
        assert_eq!(record.arrived_ns, Some(h.start_ns));
        for p in r.positions_in(h.start_ns, h.end_ns) {
            let d = p.joints.displacement_m() - step.target.displacement_m();
            assert!(d.amax() <= options.arrival_tolerance_m, "{d:?}");
        }
        // The measured slide sign is the planned one.
        assert_eq!(h.slide_sign, step.planned_slide_sign, "step {}", h.step);
        assert_eq!(r.slide_sign_at(h.start_ns), h.slide_sign);
        // The samples of the hold are the ones received in it.
        let samples = r.sensor_samples_in(h.start_ns, h.end_ns);
        assert!(samples.len() as u64 >= step.hold_ns / 2_000_000 - 1);
        assert!(
            samples
                .iter()
                .all(|x| (h.start_ns..h.end_ns).contains(&x.received_ns))
        );
    }
    // Arrival takes the constant-speed time of the fake (0.05 m/s) to the ms.
    for (i, st) in r.steps.iter().enumerate() {
        let from = if i == 0 {
            s.script.start
        } else {
            s.script.steps[i - 1].target
        };
        let d = (s.script.steps[i].target.displacement_m() - from.displacement_m()).amax();
        let took = st.arrived_ns.unwrap() - st.commanded_ns;
        let want = (d / 0.05 * 1e9) as u64;
        assert!(
            took + 1_000_000 >= want && took <= want + 2_000_000,
            "step {i}: {took} vs {want}"
        );
    }
}

#[test]
fn runner_stops_at_max_duration() {
    let s = load_named("identify_manipulator_1.toml");
    let (clock, mut sensor, mut drives) = fakes(&s);
    let options = RunOptions {
        max_duration_ns: 3_000_000_000,
        ..RunOptions::for_script(&s.script, 1_000_000)
    };
    let r = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap();
    assert_eq!(r.end, EndReason::MaxDuration);
    assert_eq!(r.end_ns - r.start_ns, 3_000_000_000);
    assert!(r.holds.len() < 10);
}

#[test]
fn runner_ends_after_a_drive_fault_with_its_code() {
    let s = load_named("identify_manipulator_1.toml");
    let (clock, mut sensor, mut drives) = fakes(&s);
    drives.fault_at_ns = Some(clock.now_ns() + 2_500_000_000);
    let options = RunOptions::for_script(&s.script, 1_000_000);
    let r = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap();
    assert_eq!(r.end, EndReason::DriveFault { code: 0x2310 });
    let seen = r
        .events
        .iter()
        .find_map(|e| match e {
            RunEvent::DriveFault { at_ns, code } => Some((*at_ns, *code)),
            _ => None,
        })
        .unwrap();
    assert_eq!(seen, (r.start_ns + 2_500_000_000, 0x2310));
    // It kept recording the linger time, with invalid positions.
    assert_eq!(r.end_ns, seen.0 + options.linger_after_fault_ns);
    assert!(r.positions.last().is_some_and(|p| !p.valid));
    assert!(r.sensor_samples.last().unwrap().received_ns + 2_000_000 > r.end_ns);
}

#[test]
fn runner_bounds_the_wait_for_an_axis_that_never_arrives() {
    let s = load_named("identify_manipulator_1.toml");
    let (clock, mut sensor, mut drives) = fakes(&s);
    drives.stuck = true;
    let options = RunOptions::for_script(&s.script, 1_000_000);
    let r = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap();
    // Every step that moves times out; the holds still happen, marked.
    let timeouts = r
        .events
        .iter()
        .filter(|e| matches!(e, RunEvent::ArrivalTimeout { .. }))
        .count();
    assert!(timeouts >= 2);
    assert_eq!(timeouts, r.steps.len());
    assert!(r.holds.iter().all(|h| !h.arrived));
    assert!(r.steps.iter().all(|st| st.arrived_ns.is_none()));
    // Each wait is 1.5 times the nominal move plus 1 s, from where the axes are.
    for st in &r.steps {
        let d = (s.script.steps[st.step].target.displacement_m() - s.script.start.displacement_m())
            .amax();
        let limit_ns = (1.5 * axis_move_time_s(d, 0.05, 0.5) * 1e9) as u64 + 1_000_000_000;
        let next = r
            .steps
            .get(st.step + 1)
            .map_or(r.end_ns, |n| n.commanded_ns);
        let hold = s.script.steps[st.step].hold_ns;
        assert!(next - st.commanded_ns <= limit_ns + hold + 2_000_000);
    }
    // The whole run is bounded by max_duration.
    assert!(matches!(
        r.end,
        EndReason::ScriptDone | EndReason::MaxDuration
    ));
    assert!(r.end_ns - r.start_ns <= options.max_duration_ns);
}

#[test]
fn runner_refuses_bad_options_and_reports_drives_that_refuse() {
    let s = load_named("identify_manipulator_1.toml");
    let (clock, mut sensor, mut drives) = fakes(&s);
    let mut options = RunOptions::for_script(&s.script, 0);
    assert!(matches!(
        run(&s.script, &mut sensor, &mut drives, &clock, &options),
        Err(RunError::InvalidOptions {
            field: "period_ns",
            ..
        })
    ));
    options.period_ns = 1_000_000;
    options.arrival_tolerance_m = f64::NAN;
    assert!(matches!(
        run(&s.script, &mut sensor, &mut drives, &clock, &options),
        Err(RunError::InvalidOptions {
            field: "arrival_tolerance_m",
            ..
        })
    ));
    options.arrival_tolerance_m = 1e-5;
    drives.refuse_enable = true;
    let e = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap_err();
    assert!(
        matches!(
            e,
            RunError::Enable {
                kind: ErrorKind::InvalidState,
                ..
            }
        ),
        "{e}"
    );
    drives.refuse_enable = false;
    drives.refuse_targets = true;
    let e = run(&s.script, &mut sensor, &mut drives, &clock, &options).unwrap_err();
    assert!(
        matches!(&e, RunError::Target { step: 0, key, kind: ErrorKind::InvalidArgument, .. } if key == "motion[0]"),
        "{e}"
    );
    assert!(e.to_string().contains("motion[0]"));
}

/// `[[support_shift]]` (issue 26): the true support moving; none by
/// default; each key checked under its name.
#[test]
fn support_shifts_are_read_and_checked() {
    assert!(
        parse(MINIMAL, ORIGIN)
            .unwrap()
            .spec
            .support_shifts
            .is_empty()
    );
    let text = format!(
        "{MINIMAL}\n[[support_shift]]\nt_s = 2.0\nshift_m = [0.0, 0.005, 0.0]\nduration_s = 0.5\n\n[[support_shift]]\nt_s = 4.0\nshift_m = [0.0, 0.0, -0.02]\n"
    );
    let shifts = parse(&text, ORIGIN).unwrap().spec.support_shifts;
    assert_eq!(
        shifts,
        vec![
            sar_sim::SupportShift {
                t_ns: 2_000_000_000,
                shift_m: Vec3::new(0.0, 0.005, 0.0),
                duration_ns: 500_000_000,
            },
            sar_sim::SupportShift {
                t_ns: 4_000_000_000,
                shift_m: Vec3::new(0.0, 0.0, -0.02),
                duration_ns: 0,
            },
        ]
    );
    // Half-way through its ramp, half of it; done, all of it.
    assert!((shifts[0].at(2_250_000_000) - shifts[0].shift_m * 0.5).norm() < 1e-15);
    assert_eq!(shifts[0].at(1_999_999_999), Vec3::zeros());
    assert_eq!(shifts[1].at(4_000_000_000), shifts[1].shift_m);
    for (body, key, problem) in [
        (
            "t_s = 1.0\nshift_m = [0.2, 0.0, 0.0]\n",
            "support_shift[0].shift_m",
            "at most 0.1 m",
        ),
        (
            "t_s = -1.0\nshift_m = [0.0, 0.0, 0.0]\n",
            "support_shift[0].t_s",
            "must be >= 0",
        ),
        (
            "t_s = 1.0\nshift_m = [0.0, 0.0, 0.0]\nduration_s = -0.5\n",
            "support_shift[0].duration_s",
            "must be >= 0",
        ),
        (
            "t_s = 1.0\nshift_m = [0.0, 0.0]\n",
            "support_shift[0].shift_m",
            "",
        ),
    ] {
        let e = refused(&format!("{MINIMAL}\n[[support_shift]]\n{body}"));
        assert_eq!(e.key(), Some(key), "{e}");
        assert!(e.to_string().contains(problem), "{e}");
    }
}
