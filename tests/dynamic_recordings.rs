//! Recordings of the simulator with the plant in motion (issue 26: the rod's
//! inertia, servos of 30 Hz / 0.7) driven through the excitation of
//! `sarctl identify --dynamic` ([`sarctl::identify::excitation`]) with the
//! tip free: the excitation's set points are streamed to the simulated
//! drives every 1 ms (CSP, as the daemon's loop streams them), and every new
//! sensor sample (stamp: its host receive time) and position sample (stamp:
//! its measurement time) is written with the project's recorder library,
//! as the identification fixtures are (`identify_fixtures`).
//!
//! Test tooling, not product code: any failure stops it loudly.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config::scenario::parse;
use sar_hal::{AxisDrives, ForceSensor, SimClock};
use sar_kinematics::ActiveJoints;
use sar_msgs::msgs::{ActiveJointState, RecorderDrops, WrenchStamped};
use sar_record::{FileOptions, Outgoing, RotatingWriter};
use sar_sim::Simulator;
use sarctl::identify::excitation::Excitation;
use std::path::{Path, PathBuf};

/// The stream's period, ns.
pub const PERIOD_NS: u64 = 1_000_000;
/// The simulated sensor's latency, s (the scenario's `latency_s`).
pub const SENSOR_LATENCY_S: f64 = 0.001;
/// Manipulator 2 (the truth): m, kg; c, m; L, m.
pub const ROD: (f64, f64, f64) = (2.593, 0.103, 0.35);
/// The excitation's centre, joints (q1, q2, q3), m: A = (0.25, 0.2, 0),
/// the nominal pose of MODEL.md 10.
pub const CENTRE_M: [f64; 3] = [0.0, 0.28, 0.25];

/// The scenario: manipulator 2 with `I_perp = inertia_perp_kgm2`, the
/// support's friction 0.3 N, HEX-6 noise, the sensor tared (no bias),
/// servos on, starting at [`CENTRE_M`] (one motion step: stay there), and
/// `adapter_mass_kg` between the sensor and the U-joint.
pub fn scenario_text(inertia_perp_kgm2: f64, adapter_mass_kg: f64, seed: u64) -> String {
    format!(
        r#"name = "excitation-manipulator-2"
seed = {seed}

[robot]
gravity = [0.0, -9.80665, 0.0]
support = [0.45, 0.20, 0.0]
p_home = [0.0, 0.0, 0.0]
ujoint_offset = [0.0, -0.08, 0.0]
sensor_offset = [0.0, -0.03, 0.0]
sensor_rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

[manipulator]
name = "manipulator-2"
length_m = 0.35
offset_m = 0.0
mass_kg = 2.593
com_m = 0.103
inertia_perp_kgm2 = {inertia_perp_kgm2}

[support]
friction_n = 0.3

[axes]
start = [{}, {}, {}]
servo_bandwidth_hz = 30.0
servo_damping = 0.7
servo_max_accel_mps2 = 5.0

[sensor]
rate_hz = 500.0
latency_s = {SENSOR_LATENCY_S}
noise_n = [0.2, 0.2, 0.8]
noise_nm = [0.01, 0.01, 0.002]
adapter_mass_kg = {adapter_mass_kg}

[[motion]]
joints = [{}, {}, {}]
hold_s = 0.1
"#,
        CENTRE_M[0], CENTRE_M[1], CENTRE_M[2], CENTRE_M[0], CENTRE_M[1], CENTRE_M[2]
    )
}

/// Simulates `excitation` on the scenario `text` and writes the inputs
/// into `dir/{name}.mcap`; returns the path.
pub fn write(text: &str, excitation: &Excitation, dir: &Path, name: &str) -> PathBuf {
    let scenario = parse(text, name).unwrap_or_else(|e| panic!("{e}"));
    let clock = SimClock::new(crate::identify_fixtures::HOST_START_NS);
    let sim =
        Simulator::new(scenario.spec.clone(), clock.clone()).unwrap_or_else(|e| panic!("{e}"));
    let mut sensor = sim.sensor();
    let mut drives = sim.drives();
    drives.enable().unwrap();
    let mut msgs: Vec<Outgoing> = Vec::new();
    let mut last_joints = None;
    let steps = (excitation.spec.duration_s * 1e9 / PERIOD_NS as f64).ceil() as u64 + 300;
    for k in 0..steps {
        let t_s = (k + 1) as f64 * PERIOD_NS as f64 * 1e-9;
        let (q, _, _) = excitation.at(t_s);
        let target = ActiveJoints {
            q1_m: q[0],
            q2_m: q[1],
            q3_m: q[2],
        };
        drives
            .stream(target, PERIOD_NS)
            .unwrap_or_else(|e| panic!("{t_s} s: {e}"));
        clock.advance_ns(PERIOD_NS);
        if let Some(w) = sensor.poll().unwrap() {
            msgs.push(Outgoing::SensorWrench(WrenchStamped::sensor(
                w.received_ns,
                w.force_n.into(),
                w.torque_nm.into(),
            )));
        }
        let p = drives.positions().unwrap();
        if p.valid && last_joints != Some(p.stamp_ns) {
            last_joints = Some(p.stamp_ns);
            msgs.push(Outgoing::Joints(ActiveJointState {
                stamp_ns: p.stamp_ns,
                q_m: [p.joints.q1_m, p.joints.q2_m, p.joints.q3_m],
            }));
        }
    }
    msgs.sort_by_key(Outgoing::stamp_ns);
    let tmp = dir.join(format!(".{name}-tmp"));
    let mut writer = RotatingWriter::new(FileOptions::new(&tmp, name)).unwrap();
    for m in &msgs {
        writer.write(m, &RecorderDrops::default()).unwrap();
    }
    let last = msgs.last().map_or(0, Outgoing::stamp_ns);
    writer
        .close(&RecorderDrops {
            stamp_ns: last,
            ..RecorderDrops::default()
        })
        .unwrap();
    let files = writer.files().to_vec();
    assert_eq!(files.len(), 1, "{name}: one file");
    let out = dir.join(format!("{name}.mcap"));
    std::fs::rename(&files[0], &out).unwrap();
    std::fs::remove_dir(&tmp).unwrap();
    out
}
