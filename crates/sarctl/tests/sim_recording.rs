//! A `sard --sim` recording as a new user meets it (issue 16, section 3):
//! - it carries the daemon's configuration (`sar_config` metadata), so that
//!   `sarctl replay --input REC` needs no `--config`: a recording from the
//!   daemon's first cycle replays bit for bit with it (exit 0); one of the
//!   built-in configuration made with `sarctl record start|stop` names it;
//! - it records the simulator's truth on `/sar/sim/tip_wrench_truth` (one
//!   message per new sensor sample), so that `--compare` gives figures;
//! - a recording without a configuration is refused with what to give;
//! - `sarctl export --rosbag2 DIR` refuses a missing file, a directory that
//!   exists and is not empty, a scene companion and two files of one name.
//!   (`tests/strict_readers.rs` opens the directory with `rosbags`.)

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod support;
use support::{SARCTL, recordings, sard, text};

use sar_record::McapReader;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn sarctl(args: &[&str], paths: &[&Path]) -> Output {
    Command::new(SARCTL)
        .args(args)
        .args(paths)
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-simrec-{}", std::process::id()),
        )
        .output()
        .unwrap()
}

/// Messages on `topic` of `file`.
fn count(file: &Path, topic: &str) -> u64 {
    let bytes = std::fs::read(file).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut ids = Vec::new();
    for m in reader.by_ref() {
        ids.push(m.unwrap().channel_id);
    }
    let id = reader.channel_of(topic).unwrap().id;
    ids.iter().filter(|&&i| i == id).count() as u64
}

/// `sard --sim` for `cycles` recording into `dir/rec`: the recording's file.
fn sim_recording(dir: &Path, cycles: u64) -> PathBuf {
    let prefix = format!("sar-simrec-sard-{}", std::process::id());
    support::sim_recording(dir, cycles, &prefix)
}

#[test]
fn a_sim_recording_replays_without_a_configuration_and_compares_with_the_truth() {
    let dir = support::scratch("simrec_replay");
    // 5 s: the demo's contact rises from 2 s (2.7 N along the rod at 5 s).
    let rec = sim_recording(&dir, 5000);
    // The sensor's samples at 500 Hz, every one recorded; one truth per
    // cycle with a new sample (a late cycle drains two samples, one truth).
    let truths = count(&rec, "/sar/sim/tip_wrench_truth");
    let samples = count(&rec, "/sar/sensor/wrench");
    assert!(
        truths <= samples && samples - truths <= samples / 10,
        "{truths} truths, {samples} samples"
    );
    assert!(truths >= 2400, "{truths} truths in 5 s");
    let out = sarctl(
        &[
            "--format",
            "json",
            "replay",
            "--compare",
            "/sar/sim/tip_wrench_truth",
            "--input",
        ],
        &[&rec],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    assert_eq!(v["cycles"], 5000, "{v}");
    let c = &v["comparison"];
    assert!(c["pairs"].as_u64().unwrap() >= 2400, "{c}");
    // The estimate follows the truth along the rod (X0) within the noise.
    let rms_x = c["rms_n"][0].as_f64().unwrap();
    assert!(rms_x > 0.0 && rms_x < 0.5, "{c}");
    // The text says which configuration it ran.
    let out = sarctl(&["replay", "--input"], &[&rec]);
    assert!(out.status.success(), "{}", text(&out.stderr));
}

/// The lean mode (`[record] mode = "inputs"`, issue 28) on the real
/// `sard --sim`: the file replays without error (its guard events and
/// snapshots compared), `replay --output` makes a full file of it that
/// replays bit for bit itself, and it takes a fraction of a full
/// recording's bytes per cycle (the full one of the same length beside it).
#[test]
fn a_lean_sim_recording_replays_and_makes_the_full_one() {
    let dir = support::scratch("simrec_lean");
    let cycles = 3000u64;
    let prefix = format!("sar-simrec-lean-{}", std::process::id());
    for sub in ["lean", "full", "identify"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    let lean = support::sim_lean_recording(&dir.join("lean"), cycles, &prefix);
    let full = support::sim_recording(&dir.join("full"), cycles, &prefix);
    let size = |p: &Path| std::fs::metadata(p).unwrap().len() as f64 / cycles as f64;
    let (lean_b, full_b) = (size(&lean), size(&full));
    // (A short file: the start's snapshot, schemas and configuration weigh
    // in its bytes a cycle.)
    eprintln!("sard --sim, {cycles} cycles: lean {lean_b:.1} bytes a cycle, full {full_b:.1}");
    assert!(lean_b * 4.0 < full_b, "lean {lean_b}, full {full_b}");
    assert!(count(&lean, "/sar/cycle/batch") >= cycles / 100);
    assert_eq!(count(&lean, "/sar/estimate/state"), 0);
    let out = sarctl(&["--format", "json", "replay", "--input"], &[&lean]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    assert_eq!(v["cycles"], cycles, "{v}");
    let made = dir.join("made-full.mcap");
    let out = sarctl(
        &["replay", "--input"],
        &[&lean, Path::new("--output"), &made],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(count(&made, "/sar/estimate/state"), cycles);
    // The sensor's samples at 500 Hz, given back from the batches.
    assert!(count(&made, "/sar/sensor/wrench") >= cycles / 2 - 50);
    let out = sarctl(&["--format", "json", "replay", "--input"], &[&made]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    assert_eq!(v["cycles"], cycles, "{v}");
    // `sarctl identify` reads the joint and sensor messages of a lean file
    // from its batches: the same answer as from the full file made of it
    // (here: the demo at rest is one static pose, too few).
    let (config, _) = support::recording_config(&dir.join("identify"));
    let identify = |rec: &Path| {
        let out = sarctl(
            &["--format", "json", "--config"],
            &[
                &config,
                Path::new("identify"),
                Path::new("--dry-run"),
                Path::new("--input"),
                rec,
            ],
        );
        let said = text(&out.stderr).replace(&rec.display().to_string(), "REC");
        (out.status.code(), text(&out.stdout), said)
    };
    let (from_lean, from_full) = (identify(&lean), identify(&made));
    assert!(from_lean.2.contains("static pose"), "{from_lean:?}");
    assert_eq!(from_lean, from_full);
}

#[test]
fn a_record_start_of_the_builtin_configuration_names_it_when_replayed() {
    let dir = support::scratch("simrec_builtin");
    let prefix = format!("sar-simrec-b-{}", std::process::id());
    // Out of the box: no --config, recordings under the working directory.
    let mut daemon = sard(&prefix)
        .arg("--sim")
        .current_dir(&dir)
        .spawn()
        .unwrap();
    let ctl = |args: &[&str]| support::sarctl(&prefix, args);
    let start = Instant::now();
    while !ctl(&["record", "start"]).status.success() {
        assert!(start.elapsed() < Duration::from_secs(30), "no daemon");
        std::thread::sleep(Duration::from_millis(100));
    }
    // Until the recording holds a few hundred cycles.
    std::thread::sleep(Duration::from_millis(600));
    let stop = ctl(&["record", "stop"]);
    let _ = Command::new("kill")
        .args(["-TERM", &daemon.id().to_string()])
        .status();
    let _ = daemon.wait();
    assert!(stop.status.success(), "{}", text(&stop.stderr));
    let rec = recordings(&dir.join("recordings"));
    assert_eq!(rec.len(), 1, "{rec:?}");
    let source = sar_record::replay::recorded_config(&rec[0])
        .unwrap()
        .unwrap();
    assert_eq!(source.origin, "the built-in configuration");
    assert_eq!(source.toml, sar_config::DEFAULT_TOML);
    assert!(count(&rec[0], "/sar/sim/tip_wrench_truth") > 0);
    // Replayed with the recorded configuration: it started after the first
    // cycle, from the snapshot it begins with, bit for bit (exit 0).
    let out = sarctl(&["--format", "json", "replay", "--input"], &[&rec[0]]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["cycles"].as_u64().unwrap() > 100, "{v}");
    assert_eq!(v["from_first_cycle"], false, "{v}");
    assert!(v["from_snapshot"].as_u64().is_some(), "{v}");
    assert_eq!(v["identical"], true, "{v}");
}

#[test]
fn a_recording_without_a_configuration_needs_one() {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/replay/contact_inputs.mcap");
    let out = sarctl(&["replay", "--input"], &[&fixture]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains("carries no configuration"), "{err}");
    assert!(err.contains("--config FILE"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}

#[test]
fn export_refuses_bad_input_with_one_line() {
    let dir = support::scratch("simrec_export_errors");
    let rec = dir.join("rec.mcap");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/fixtures/replay/contact_daemon.mcap"),
        &rec,
    )
    .unwrap();
    let refused = |args: &[&str], paths: &[&Path], why: &str| {
        let out = sarctl(args, paths);
        assert!(!out.status.success(), "{args:?} {paths:?}");
        let err = text(&out.stderr);
        assert!(err.contains(why), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    };
    let bag = dir.join("bag");
    // A missing recording: nothing is created.
    refused(
        &["export", "--rosbag2"],
        &[&bag, &dir.join("missing.mcap")],
        "missing.mcap",
    );
    assert!(!bag.exists());
    // A directory that exists and holds something.
    let full = dir.join("full");
    std::fs::create_dir_all(&full).unwrap();
    std::fs::write(full.join("x"), "x").unwrap();
    refused(&["export", "--rosbag2"], &[&full, &rec], "not empty");
    // A file where the directory should be.
    refused(&["export", "--rosbag2"], &[&rec, &rec], "is a file");
    // Not a recording.
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, "not mcap").unwrap();
    refused(&["export", "--rosbag2"], &[&bag, &junk], "not an MCAP file");
    // A file of another profile (as the scene companions of older builds).
    let scene = dir.join("rec.scene.mcap");
    let mut w = mcap::WriteOptions::new()
        .profile("")
        .create(std::io::BufWriter::new(
            std::fs::File::create(&scene).unwrap(),
        ))
        .unwrap();
    w.finish().unwrap();
    drop(w);
    refused(&["export", "--rosbag2"], &[&bag, &scene], "not \"ros2\"");
    // A file cut short.
    let cut = dir.join("cut.mcap");
    let bytes = std::fs::read(&rec).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    refused(&["export", "--rosbag2"], &[&bag, &cut], "sarctl recover");
    // Two files of one name.
    let other = dir.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::copy(&rec, other.join("rec.mcap")).unwrap();
    refused(
        &["export", "--rosbag2"],
        &[&bag, &rec, &other.join("rec.mcap")],
        "two recordings are named rec.mcap",
    );
    assert!(!bag.exists());
    // An empty directory is taken.
    std::fs::create_dir_all(&bag).unwrap();
    let out = sarctl(&["--format", "json", "export", "--rosbag2"], &[&bag, &rec]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["messages"].as_u64().unwrap() > 1000, "{v}");
    assert!(bag.join("metadata.yaml").exists());
    assert!(bag.join("rec.mcap").exists());
}

/// Every message of `file`, by topic, in order.
fn messages(file: &Path) -> std::collections::BTreeMap<String, Vec<Vec<u8>>> {
    let bytes = std::fs::read(file).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut by_id: Vec<(u16, Vec<u8>)> = Vec::new();
    for m in reader.by_ref() {
        let m = m.unwrap();
        by_id.push((m.channel_id, m.data.to_vec()));
    }
    let mut out = std::collections::BTreeMap::<String, Vec<Vec<u8>>>::new();
    for (id, data) in by_id {
        let topic = reader.channels()[&id].topic.clone();
        out.entry(topic).or_default().push(data);
    }
    out
}

/// A cycle's recorded input with the one input measured on the host's own
/// clock (the publishing thread's silence, which runs in real time) set
/// aside.
fn input_without_host_time(data: &[u8]) -> sar_msgs::msgs::CycleInput {
    match sar_msgs::msgs::Outgoing::decode(sar_msgs::msgs::Topic::CycleInput, data).unwrap() {
        sar_msgs::msgs::Outgoing::CycleInput(mut m) => {
            m.publisher_idle_ns = 0;
            m
        }
        other => panic!("not a cycle input: {other:?}"),
    }
}

/// `sard --sim --speed SPEED --max-cycles CYCLES`, recording, into the
/// recording directory of `config` (run `run` of the test `tag`): the new
/// recording. The run must not wait for real time (no late cycle: the
/// wake-up and compute are 0) and drop nothing.
fn simulated_run(
    config: &Path,
    rec_dir: &Path,
    speed: &str,
    cycles: u64,
    tag: &str,
    seen: &[PathBuf],
) -> PathBuf {
    let out = Command::new(&*support::SARD)
        .args(["--sim", "--speed", speed, "--config"])
        .arg(config)
        .args(["--max-cycles", &cycles.to_string()])
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-simtime-{}-{tag}", std::process::id()),
        )
        .output()
        .unwrap();
    let log = text(&out.stderr);
    assert!(out.status.success(), "sard: {log}");
    assert!(
        log.contains("0 overruns (0 periods skipped)")
            && log.contains("wake-up latency p50 0 us p99 0 us max 0 us"),
        "{log}"
    );
    assert!(log.contains("0 messages dropped by the recorder"), "{log}");
    let now: Vec<PathBuf> = recordings(rec_dir)
        .into_iter()
        .filter(|f| !seen.contains(f))
        .collect();
    assert_eq!(now.len(), 1, "{now:?}");
    now[0].clone()
}

/// Two recordings are one run: the same topics, every message equal byte
/// for byte, but for the publishing thread's silence in the cycles' inputs
/// (measured on the host's clock by design). Returns the messages of `a`.
fn assert_one_run(
    a: &Path,
    b: &Path,
    cycles: usize,
) -> std::collections::BTreeMap<String, Vec<Vec<u8>>> {
    let (a, b) = (messages(a), messages(b));
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "the same topics"
    );
    for (topic, left) in &a {
        let right = &b[topic];
        assert_eq!(left.len(), right.len(), "{topic}: message counts");
        if topic == "/sar/cycle/input" {
            assert_eq!(left.len(), cycles);
            for (i, (l, r)) in left.iter().zip(right).enumerate() {
                assert_eq!(
                    input_without_host_time(l),
                    input_without_host_time(r),
                    "cycle {i}'s input differs"
                );
            }
        } else {
            let differ = left.iter().zip(right).filter(|(l, r)| l != r).count();
            assert_eq!(
                differ,
                0,
                "{topic}: {differ} of {} messages differ",
                left.len()
            );
        }
    }
    a
}

/// Time as an input (issue 36): `sard --sim --speed max` runs the same
/// loop, recorder and services in simulated time. Two runs of the demo are
/// one run ([`assert_one_run`]), and each replays bit for bit.
#[test]
fn two_runs_in_simulated_time_are_one_run_and_each_replays_bit_for_bit() {
    let dir = support::scratch("simtime");
    let (config, rec_dir) = support::recording_config(&dir);
    let mut files = Vec::new();
    for run in 0..2 {
        // 20 s of the demo: its contact rises into Warn at about 8.3 s.
        let file = simulated_run(&config, &rec_dir, "max", 20_000, &run.to_string(), &files);
        files.push(file);
    }
    let a = assert_one_run(&files[0], &files[1], 20_000);
    // The demo's Warn is in both, at the same cycle.
    assert_eq!(a["/sar/guard/events"].len(), 2, "reset accepted, then Warn");
    for file in &files {
        let out = sarctl(&["--format", "json", "replay", "--input"], &[file]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["identical"], true, "{v}");
        assert_eq!(v["cycles"], 20_000, "{v}");
    }
}

/// The pace is not an input: the demo paced at real time (`--speed 1`, a
/// cycle every millisecond of the wall clock, the publishing thread and the
/// recorder working beside it as in a real-time run) records the same run
/// as the demo at the machine's full speed (`--speed max`).
#[test]
fn the_demo_paced_at_real_time_records_the_run_made_at_full_speed() {
    let dir = support::scratch("simtime_paced");
    let (config, rec_dir) = support::recording_config(&dir);
    let fast = simulated_run(&config, &rec_dir, "max", 3_000, "max", &[]);
    let paced = simulated_run(
        &config,
        &rec_dir,
        "1",
        3_000,
        "paced",
        std::slice::from_ref(&fast),
    );
    assert_one_run(&fast, &paced, 3_000);
    let out = sarctl(&["--format", "json", "replay", "--input"], &[&paced]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
}
