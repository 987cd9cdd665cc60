//! The identification fixtures (`tests/fixtures/identify/*.mcap`): inputs-only
//! recordings of the simulator running the identification scenarios, written
//! with the project's recorder library (`record::file`): one
//! `/sar/sensor/wrench` message per sensor sample (stamp: its host receive
//! time) and one `/sar/joints` message per position sample (stamp: its
//! measurement time), log time = that stamp, in stamp order.
//!
//! The scenarios are the shipped ones (`scenarios/`), copied in memory with
//! these documented edits:
//! - the sensor's bias is zero: the procedure starts with the device tared
//!   with the rod detached (MODEL.md 5), so the readings carry no bias and
//!   `sarctl identify` runs with its default tare of zero;
//! - to keep the files small (about 0.2 MB each): the sensor runs at 100 Hz
//!   (50 samples per 0.5 s dwell window, five times the article's K = 10),
//!   the positions are reported at 100 Hz, and the torque has no noise (it
//!   is recorded, but identification does not use it; random mantissas do
//!   not compress);
//! - the cone set for manipulators 1, 3 and 4 is `identify_cone_manipulator_2`
//!   with that manipulator's `[manipulator]` table and its own seed.
//!
//! Regenerate: `cargo run -p sar-tests --example make_identify_fixtures`
//! (deterministic: the same files bit for bit).
//!
//! Test tooling, not product code: any failure stops it loudly.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config::scenario::{Scenario, parse};
use sar_hal::SimClock;
use sar_msgs::msgs::{ActiveJointState, RecorderDrops, WrenchStamped};
use sar_record::{FileOptions, Outgoing, RotatingWriter};
use sar_sim::Simulator;
use sar_sim::runner::{EndReason, RunOptions, run};
use std::path::{Path, PathBuf};

/// Host time at the start of every run, ns.
pub const HOST_START_NS: u64 = 1_000_000_000;
/// The runner's polling period, ns (1 kHz: every sample).
pub const PERIOD_NS: u64 = 1_000_000;

/// The article's Table 2 manipulators: (name, m kg, c m).
pub const TABLE2: [(&str, f64, f64); 4] = [
    ("manipulator-1", 1.611, 0.115),
    ("manipulator-2", 2.593, 0.103),
    ("manipulator-3", 3.198, 0.125),
    ("manipulator-4", 4.159, 0.1456),
];

/// One fixture: its file stem and the scenario text it records.
#[derive(Debug, Clone)]
pub struct Fixture {
    /// File stem (`identify_manipulator_1`, ...).
    pub name: String,
    /// The scenario as simulated.
    pub scenario: Scenario,
}

/// The shipped scenario's text.
fn shipped(file: &str) -> String {
    let path = crate::scenarios_dir().join(file);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The text with `from` replaced by `to` exactly once.
fn edit(text: &str, from: &str, to: &str, what: &str) -> String {
    assert_eq!(
        text.matches(from).count(),
        1,
        "{what}: `{from}` not found once"
    );
    text.replacen(from, to, 1)
}

/// The edits every fixture's scenario gets (see the module's doc).
fn tared(text: &str, what: &str) -> String {
    let text = edit(
        text,
        "bias_n = [1.5, -2.0, 0.7]",
        "bias_n = [0.0, 0.0, 0.0]",
        what,
    );
    let text = edit(&text, "rate_hz = 500.0", "rate_hz = 100.0", what);
    let text = edit(
        &text,
        "noise_nm = [0.01, 0.01, 0.002]",
        "noise_nm = [0.0, 0.0, 0.0]",
        what,
    );
    edit(
        &text,
        "[axes]\n",
        "[axes]\nposition_rate_hz = 100.0\n",
        what,
    )
}

fn fixture(name: &str, text: &str) -> Fixture {
    let scenario = parse(text, name).unwrap_or_else(|e| panic!("{e}"));
    Fixture {
        name: name.to_owned(),
        scenario,
    }
}

/// Every fixture: the article protocol and the cone set for the four Table 2
/// manipulators, and the three Table 3 masses.
pub fn all() -> Vec<Fixture> {
    let mut out = Vec::new();
    for k in 1..=4 {
        let file = format!("identify_manipulator_{k}");
        out.push(fixture(
            &file,
            &tared(&shipped(&format!("{file}.toml")), &file),
        ));
    }
    let cone2 = shipped("identify_cone_manipulator_2.toml");
    let (_, m2, c2) = TABLE2[1];
    for (k, (name, m, c)) in TABLE2.iter().enumerate() {
        let file = format!("identify_cone_manipulator_{}", k + 1);
        let mut text = tared(&cone2, &file);
        if k != 1 {
            text = edit(
                &text,
                "seed = 202",
                &format!("seed = {}", 200 + k + 1),
                &file,
            );
            text = edit(
                &text,
                "name = \"manipulator-2\"",
                &format!("name = \"{name}\""),
                &file,
            );
            text = edit(
                &text,
                &format!("mass_kg = {m2}"),
                &format!("mass_kg = {m}"),
                &file,
            );
            text = edit(
                &text,
                &format!("com_m = {c2}"),
                &format!("com_m = {c}"),
                &file,
            );
        }
        out.push(fixture(&file, &text));
    }
    for file in [
        "table3_mass_0_51kg",
        "table3_mass_1_03kg",
        "table3_mass_2_04kg",
    ] {
        out.push(fixture(
            file,
            &tared(&shipped(&format!("{file}.toml")), file),
        ));
    }
    out
}

/// The folder of the identification fixtures.
pub fn dir() -> PathBuf {
    crate::fixtures_dir().join("identify")
}

/// Simulates `f` and writes its inputs into `dir/{name}.mcap`; returns the path.
pub fn write(f: &Fixture, dir: &Path) -> PathBuf {
    let s = &f.scenario;
    let clock = SimClock::new(HOST_START_NS);
    let sim = Simulator::new(s.spec.clone(), clock.clone()).unwrap_or_else(|e| panic!("{e}"));
    let options = RunOptions::for_script(&s.script, PERIOD_NS);
    let mut sensor = sim.sensor();
    let mut drives = sim.drives();
    let r = run(&s.script, &mut sensor, &mut drives, &clock, &options)
        .unwrap_or_else(|e| panic!("{}: {e}", f.name));
    assert_eq!(r.end, EndReason::ScriptDone, "{}", f.name);
    let mut msgs: Vec<Outgoing> = r
        .sensor_samples
        .iter()
        .map(|w| {
            Outgoing::SensorWrench(WrenchStamped::sensor(
                w.received_ns,
                w.force_n.into(),
                w.torque_nm.into(),
            ))
        })
        .chain(r.positions.iter().filter(|p| p.valid).map(|p| {
            Outgoing::Joints(ActiveJointState {
                stamp_ns: p.stamp_ns,
                q_m: [p.joints.q1_m, p.joints.q2_m, p.joints.q3_m],
            })
        }))
        .collect();
    // Stable: a sensor sample before a joint sample of the same stamp.
    msgs.sort_by_key(Outgoing::stamp_ns);
    let tmp = dir.join(format!(".{}-tmp", f.name));
    let mut writer = RotatingWriter::new(FileOptions::new(&tmp, &f.name)).unwrap();
    for m in &msgs {
        writer
            .write(m, &RecorderDrops::default())
            .unwrap_or_else(|e| panic!("{}: {e}", f.name));
    }
    let last = msgs.last().map_or(0, Outgoing::stamp_ns);
    writer
        .close(&RecorderDrops {
            stamp_ns: last,
            ..RecorderDrops::default()
        })
        .unwrap();
    let files = writer.files().to_vec();
    assert_eq!(files.len(), 1, "{}: one file", f.name);
    let out = dir.join(format!("{}.mcap", f.name));
    std::fs::rename(&files[0], &out).unwrap();
    std::fs::remove_dir(&tmp).unwrap();
    out
}
