//! `sarctl replay`, `recover` and `record` as processes:
//! - `sard --sim` with `[record] enabled`: `sarctl record stop` closes the
//!   recording, `record start` opens another; the first (from the daemon's
//!   first cycle) replays bit for bit with `sarctl replay` (exit 0), the
//!   status shows the recorder's drops;
//! - a replay that differs (another configuration) exits non-zero with one
//!   line naming the first cycle, topic and field;
//! - `--compare`, `--format json` and `--plot` on the contact fixture;
//! - `recover` refuses to overwrite its input.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod support;
use support::{Daemon, SARCTL, sarctl, sard, text};

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/replay")
}

fn status_json(prefix: &str) -> serde_json::Value {
    let out = sarctl(prefix, &["status", "--format", "json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn sard_records_on_start_and_on_request_and_the_file_replays_bit_for_bit() {
    let dir = support::scratch("replay_cli_e2e");
    let (config, rec_dir) = support::recording_config(&dir);
    let prefix = format!("sar-rec-{}", std::process::id());
    let daemon = Daemon::start(
        sard(&prefix).args(["--sim", "--config"]).arg(&config),
        &prefix,
    );
    let s = status_json(&prefix);
    assert_eq!(s["recording"], true, "{s}");
    assert!(s["recorder_drops"].is_u64(), "{s}");
    std::thread::sleep(Duration::from_millis(500));
    let out = sarctl(&prefix, &["record", "stop", "--format", "json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["recording"], false, "{v}");
    assert_eq!(status_json(&prefix)["recording"], false);
    let out = sarctl(&prefix, &["record", "start"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("recording"),
        "{}",
        text(&out.stdout)
    );
    std::thread::sleep(Duration::from_millis(300));
    let out = sarctl(&prefix, &["record", "stop"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    daemon.stop();

    let mut files: Vec<_> = std::fs::read_dir(&rec_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    // Two recordings and nothing beside them: each carries its 3D scene
    // (the fixed frames and at least one scene) in itself.
    assert_eq!(files.len(), 2, "{files:?}");
    for f in &files {
        let bytes = std::fs::read(f).unwrap();
        let mut topics = std::collections::BTreeSet::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            topics.insert(m.unwrap().channel.topic.clone());
        }
        for t in ["/sar/scene", "/tf", "/tf_static", "/sar/scene/status"] {
            assert!(topics.contains(t), "{f:?}: no {t} in {topics:?}");
        }
    }
    // The recording from the first cycle replays bit for bit.
    let out_file = dir.join("replayed.mcap");
    let out = Command::new(SARCTL)
        .args(["replay", "--format", "json", "--config"])
        .arg(&config)
        .arg("--input")
        .arg(&files[0])
        .arg("--output")
        .arg(&out_file)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    assert_eq!(v["from_first_cycle"], true, "{v}");
    assert_eq!(v["mode"], "cycle_input", "{v}");
    assert_eq!(v["recorder_dropped"], 0, "{v}");
    assert!(v["cycles"].as_u64().unwrap() > 100, "{v}");
    // Every output, and the snapshot at the recording's start (compared
    // with the replayed state, not restored).
    assert_eq!(v["from_snapshot"], serde_json::Value::Null, "{v}");
    assert_eq!(v["snapshots_compared"], 1, "{v}");
    assert_eq!(
        v["compared"].as_u64(),
        v["outputs"].as_u64().map(|o| o + 1),
        "{v}"
    );
    assert!(out_file.exists());
    // The one started on request is a complete, readable recording too; it
    // says that it starts after the daemon's first cycle, and replays bit
    // for bit from the snapshot it starts with (issue 17).
    let cfg = sar_config::load(&config).unwrap();
    let r = sar_record::replay::replay_file(
        &files[1],
        &sar_record::replay::ReplayOptions::from_config(&cfg),
    )
    .unwrap();
    assert_eq!(r.from_first_cycle, Some(false));
    assert!(r.cycles > 10, "{}", r.cycles);
    assert_eq!(r.first_difference, None);
    assert!(
        r.from_snapshot.is_some_and(|c| c > 100),
        "{:?}",
        r.from_snapshot
    );
    assert_eq!(r.compared, r.outputs);
    let bytes = sar_record::read_file(&files[1]).unwrap();
    let mut reader = sar_record::McapReader::new(&bytes).unwrap();
    assert!(reader.by_ref().all(|m| m.is_ok()));
    assert!(reader.is_complete());
}

#[test]
fn a_replay_that_differs_exits_non_zero_naming_the_first_cycle_and_field() {
    let dir = support::scratch("replay_cli_differs");
    // Another sensor noise: the deviation differs from the first estimate on.
    let config = dir.join("other.toml");
    let toml = std::fs::read_to_string(fixtures().join("config.toml"))
        .unwrap()
        .replace("noise_n = [0.2, 0.2, 0.8]", "noise_n = [0.3, 0.2, 0.8]");
    std::fs::write(&config, toml).unwrap();
    let out = Command::new(SARCTL)
        .args(["replay", "--config"])
        .arg(&config)
        .arg("--input")
        .arg(fixtures().join("fault_daemon.mcap"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("first at cycle"), "{err}");
    assert!(err.contains("tip_force_std_n"), "{err}");
    // The fixture's own configuration: identical, exit 0.
    let out = Command::new(SARCTL)
        .args(["replay", "--config"])
        .arg(fixtures().join("config.toml"))
        .arg("--input")
        .arg(fixtures().join("fault_daemon.mcap"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("0 differ"),
        "{}",
        text(&out.stdout)
    );
}

#[test]
fn compare_json_and_plot_on_the_contact_fixture() {
    let dir = support::scratch("replay_cli_compare");
    let svg = dir.join("fig9.svg");
    let out = Command::new(SARCTL)
        .args([
            "replay",
            "--format",
            "json",
            "--compare",
            "/sar/sim/tip_wrench_truth",
            "--config",
        ])
        .arg(fixtures().join("config.toml"))
        .arg("--input")
        .arg(fixtures().join("contact_inputs.mcap"))
        .arg("--output")
        .arg(dir.join("out.mcap"))
        .arg("--plot")
        .arg(&svg)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["mode"], "inputs_only", "{v}");
    let c = &v["comparison"];
    assert_eq!(c["topic"], "/sar/sim/tip_wrench_truth");
    for key in ["e_ra", "rms_n", "max_n"] {
        assert_eq!(c[key].as_array().unwrap().len(), 3, "{c}");
    }
    let plot = std::fs::read_to_string(&svg).unwrap();
    assert!(plot.starts_with("<svg"), "{}", &plot[..plot.len().min(80)]);
    assert!(
        plot.matches("<polyline").count() >= 6,
        "estimate and truth, 3 axes"
    );
}

#[test]
fn recover_refuses_to_overwrite_its_input() {
    let dir = support::scratch("replay_cli_recover");
    let cut = dir.join("cut.mcap");
    let bytes = std::fs::read(fixtures().join("fault_daemon.mcap")).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = Command::new(SARCTL)
        .arg("recover")
        .arg(&cut)
        .arg("--output")
        .arg(&cut)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("refusing to write over the input"),
        "{}",
        text(&out.stderr)
    );
    let out = Command::new(SARCTL)
        .args(["recover", "--format", "json"])
        .arg(&cut)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["input_complete"], false, "{v}");
    assert!(dir.join("cut.recovered.mcap").exists());
}

/// A tmpfs mounted at `dir` (made if missing) with `options`, unmounted on
/// drop. Needs root (CI runs as root): a test that cannot mount says so.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, options: &str) -> Self {
        std::fs::create_dir_all(dir).unwrap();
        sar_test_support::process::run_ok(
            Command::new("mount")
                .args(["-t", "tmpfs", "-o", options, "tmpfs"])
                .arg(dir),
            "this test needs a tmpfs (mount, as root): mount -t tmpfs -o  failed",
        );
        Self(dir.to_path_buf())
    }
    fn remount(&self, options: &str) {
        let out = Command::new("mount")
            .args(["-o", &format!("remount,{options}")])
            .arg(&self.0)
            .output()
            .unwrap();
        assert!(out.status.success(), "remount: {}", text(&out.stderr));
    }
    /// Bytes in use.
    fn used(&self) -> u64 {
        let out = Command::new("df")
            .args(["-B1", "--output=used"])
            .arg(&self.0)
            .output()
            .unwrap();
        text(&out.stdout)
            .lines()
            .nth(1)
            .unwrap()
            .trim()
            .parse()
            .unwrap()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

/// Issue 25, finding 5: a recording on a file system that is read-only or
/// too small is refused at `record start` (saying why, with the space a
/// minute needs and the space free); one that fills up stops at the write
/// error, which the status and the daemon's log name at once ("No space
/// left on device"); `record stop` then says the file is incomplete and
/// exits non-zero, never "written to"; the guard and the loop go on
/// unaffected (recording is not a safety function); the cut file is
/// recovered and replays.
#[test]
fn a_recording_on_a_full_disk_is_refused_or_stops_at_once_and_stop_says_incomplete() {
    let dir = support::scratch("replay_cli_full_disk");
    let rec_dir = dir.join("rec");
    let config = dir.join("sim.toml");
    let toml = sar_config::DEFAULT_TOML.replace(
        "directory = \"recordings\"",
        &format!("directory = {:?}", rec_dir.display().to_string()),
    );
    std::fs::write(&config, toml).unwrap();
    let fs = Tmpfs::mount(&rec_dir, "ro,size=256m");
    let log = dir.join("sard.log");
    let prefix = format!("sar-full-{}", std::process::id());
    let daemon = Daemon::start(
        sard(&prefix)
            .args(["--sim", "--config"])
            .arg(&config)
            .stderr(std::fs::File::create(&log).unwrap()),
        &prefix,
    );
    // Read-only: refused, saying so.
    let out = sarctl(&prefix, &["record", "start"]);
    assert!(!out.status.success(), "{}", text(&out.stdout));
    assert!(
        text(&out.stderr).contains("read-only file system"),
        "{}",
        text(&out.stderr)
    );
    // Too small for a minute of recording: refused with both figures.
    drop(fs);
    let fs = Tmpfs::mount(&rec_dir, "size=2m");
    let out = sarctl(&prefix, &["record", "start"]);
    assert!(!out.status.success(), "{}", text(&out.stdout));
    let e = text(&out.stderr);
    assert!(
        e.contains("too little space")
            && e.contains("MB free")
            && e.contains("a minute of recording needs"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
    // Room enough at the start, then the disk fills.
    drop(fs);
    let fs = Tmpfs::mount(&rec_dir, "size=256m");
    let out = sarctl(&prefix, &["record", "start"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // The simulator's automatic first reset: the guard is Ok from then on.
    let start = Instant::now();
    while status_json(&prefix)["guard"] != "ok" {
        assert!(start.elapsed() < Duration::from_secs(20), "never ok");
        std::thread::sleep(Duration::from_millis(50));
    }
    let file = text(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("file: "))
        .and_then(|l| l.split(' ').next())
        .map(PathBuf::from)
        .unwrap();
    let before = status_json(&prefix);
    assert_eq!(before["recording"], true, "{before}");
    fs.remount(&format!("size={}", fs.used() + 64 * 1024));
    let start = Instant::now();
    let failed = loop {
        let s = status_json(&prefix);
        if s["recording"] == false {
            break s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "still recording: {s}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    println!(
        "the recording failed {:?} after the disk was filled",
        start.elapsed()
    );
    let why = failed["recording_failed"]
        .as_str()
        .unwrap_or_default()
        .to_owned();
    assert!(why.contains("No space left on device"), "{failed}");
    // In the log, before any stop: the manager closes the failed recording
    // as soon as the loop hands it back (its writer wakes it), a few
    // milliseconds after the state says failed; waited for, not raced.
    let said = |text: &str| text.contains("No space left on device") && text.contains("incomplete");
    let logged_by = Instant::now() + Duration::from_secs(5);
    let mut logged = std::fs::read_to_string(&log).unwrap();
    while !said(&logged) && Instant::now() < logged_by {
        std::thread::sleep(Duration::from_millis(5));
        logged = std::fs::read_to_string(&log).unwrap();
    }
    assert!(said(&logged), "{logged}");
    let out = sarctl(&prefix, &["status"]);
    assert!(
        text(&out.stdout).contains("recording FAILED"),
        "{}",
        text(&out.stdout)
    );
    // Not a safety function: the guard and the loop went on as before.
    assert_eq!(failed["guard"], before["guard"], "{failed}");
    assert_eq!(failed["quick_stops"], before["quick_stops"], "{failed}");
    assert!(failed["cycle"].as_u64() > before["cycle"].as_u64());
    let later = status_json(&prefix);
    assert!(later["cycle"].as_u64() > failed["cycle"].as_u64());
    assert_eq!(later["guard"], before["guard"]);
    // Stop: the file is incomplete, never "written to".
    let out = sarctl(&prefix, &["record", "stop"]);
    assert!(!out.status.success(), "{}", text(&out.stdout));
    let e = text(&out.stderr);
    assert!(
        e.contains("incomplete") && e.contains("No space left on device"),
        "{e}"
    );
    assert!(
        !text(&out.stdout).contains("written to"),
        "{}",
        text(&out.stdout)
    );
    // A second stop, with nothing recording: "no recording ran", exit 0
    // (not the failed recording's answer again).
    let out = sarctl(&prefix, &["record", "stop"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("no recording ran"),
        "{}",
        text(&out.stdout)
    );
    daemon.stop();
    // The cut file: recovered, then replayed (exit 0).
    let recovered = dir.join("recovered.mcap");
    let out = Command::new(SARCTL)
        .arg("recover")
        .arg(&file)
        .arg("--output")
        .arg(&recovered)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    drop(fs);
    sar_test_support::process::run_ok(
        Command::new(SARCTL)
            .arg("replay")
            .arg("--input")
            .arg(&recovered),
        "the command",
    );
}

/// The chunks of an MCAP file (offset, record length with its prefix), by
/// walking its records.
fn chunks(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        match bytes[pos] {
            0x06 => out.push((pos, len + 9)),
            0x0F => break,
            _ => {}
        }
        pos += 9 + len;
    }
    out
}

/// Runs `sarctl args`, killed after 10 s (a tool blocked on a FIFO).
fn sarctl_bounded(args: &[&std::ffi::OsStr]) -> (Output, Duration) {
    let start = Instant::now();
    let mut child = Command::new(SARCTL)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    (child.wait_with_output().unwrap(), start.elapsed())
}

/// Issue 25, finding 6: every tool exits non-zero when it did not do all it
/// was asked. A corrupt chunk in the middle: `replay` passes over it, reads
/// the rest and names the gap (where, how many bytes, the cycles lost),
/// exit non-zero; `recover` keeps the good chunks after it. Cut files:
/// "truncated at byte N" (not "carries no configuration"), exit non-zero;
/// `recover` of a file with no complete chunk exits non-zero; `export
/// --rosbag2` refuses a file cut inside its summary. A FIFO or a device is
/// refused at once by every tool that reads a file; a read error is named.
#[test]
fn bad_files_exit_non_zero_and_say_what_was_not_done() {
    let dir = support::scratch("replay_cli_bad_files");
    let bytes = std::fs::read(fixtures().join("fault_daemon.mcap")).unwrap();
    let all = chunks(&bytes);
    assert!(all.len() > 10, "{} chunks", all.len());
    // One corrupt chunk in the middle (its compressed data).
    let (at, len) = all[all.len() / 2];
    let mut corrupt = bytes.clone();
    for b in &mut corrupt[at + len / 2..at + len / 2 + 16] {
        *b ^= 0x5a;
    }
    let corrupt_path = dir.join("corrupt.mcap");
    std::fs::write(&corrupt_path, &corrupt).unwrap();
    let config = fixtures().join("config.toml");
    let out = sarctl(
        "unused",
        &[
            "replay",
            "--config",
            config.to_str().unwrap(),
            "--format",
            "json",
            "--input",
            corrupt_path.to_str().unwrap(),
        ],
    );
    assert!(!out.status.success(), "{}", text(&out.stdout));
    assert!(
        text(&out.stderr).contains(&format!("at byte {at}")),
        "{}",
        text(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let gap = &v["gaps"][0];
    assert_eq!(gap["offset"], at as u64, "{v}");
    assert_eq!(gap["bytes"], len as u64, "{v}");
    let lost = gap["cycles_lost"].as_u64().unwrap();
    let not_replayed = gap["cycles_not_replayed"].as_u64().unwrap();
    assert!(lost > 0 && not_replayed > 0, "{v}");
    // Every cycle of the file is accounted for: the chunks after the gap
    // were read.
    assert_eq!(
        v["cycles"].as_u64().unwrap() + lost + not_replayed,
        3000,
        "{v}"
    );
    // Recover keeps the good chunks after it.
    let cut_at_gap = dir.join("cut_at_gap.mcap");
    std::fs::write(&cut_at_gap, &bytes[..at]).unwrap();
    let recover_json = |input: &Path, output: &Path| {
        let (out, _) = sarctl_bounded(&[
            "recover".as_ref(),
            "--format".as_ref(),
            "json".as_ref(),
            input.as_os_str(),
            "--output".as_ref(),
            output.as_os_str(),
        ]);
        (
            out.status.success(),
            text(&out.stderr),
            serde_json::from_slice::<serde_json::Value>(&out.stdout).ok(),
        )
    };
    let (ok, e, before_gap) = recover_json(&cut_at_gap, &dir.join("r1.mcap"));
    assert!(ok, "{e}");
    let (ok, e, past_gap) = recover_json(&corrupt_path, &dir.join("r2.mcap"));
    assert!(ok, "{e}");
    let (before_gap, past_gap) = (before_gap.unwrap(), past_gap.unwrap());
    assert!(
        past_gap["messages"].as_u64().unwrap() > before_gap["messages"].as_u64().unwrap() * 3 / 2,
        "{before_gap} {past_gap}"
    );
    assert!(
        past_gap["skipped"][0]
            .as_str()
            .unwrap()
            .contains(&format!("at byte {at}")),
        "{past_gap}"
    );
    // The recovered file replays to the same end: the cycles missing are
    // named, never "differs".
    let out = sarctl(
        "unused",
        &[
            "replay",
            "--config",
            config.to_str().unwrap(),
            "--input",
            dir.join("r2.mcap").to_str().unwrap(),
        ],
    );
    assert!(!out.status.success());
    let e = text(&out.stderr);
    assert!(
        e.contains("are missing from the recording") && !e.contains("differs"),
        "{e}"
    );
    // Cut files: truncated, at which byte; never "no configuration".
    let (first_chunk, _) = all[0];
    for cut in [8, first_chunk / 2, first_chunk + 100, at + len / 2] {
        let path = dir.join(format!("cut{cut}.mcap"));
        std::fs::write(&path, &bytes[..cut]).unwrap();
        // (The fixture carries no configuration: the last cut, whose
        // start is whole, is given one.)
        let mut args: Vec<&std::ffi::OsStr> =
            vec!["replay".as_ref(), "--input".as_ref(), path.as_os_str()];
        if cut > first_chunk + 100 {
            args.extend(["--config".as_ref(), config.as_os_str()]);
        }
        let (out, _) = sarctl_bounded(&args);
        let e = text(&out.stderr);
        assert!(!out.status.success(), "cut {cut}: {}", text(&out.stdout));
        assert!(e.contains("truncated at byte"), "cut {cut}: {e}");
        assert!(!e.contains("carries no configuration"), "cut {cut}: {e}");
        // Nothing to recover before the first complete chunk.
        if cut < first_chunk + 100 {
            let output = dir.join(format!("cut{cut}.recovered.mcap"));
            let (ok, e, _) = recover_json(&path, &output);
            assert!(!ok && e.contains("recovered nothing"), "cut {cut}: {e}");
            assert!(!output.exists(), "cut {cut}");
        }
    }
    // Cut inside the summary (the data section whole): export refuses it.
    let (summary_cut, _) = (bytes.len() - 100, ());
    let path = dir.join("summary_cut.mcap");
    std::fs::write(&path, &bytes[..summary_cut]).unwrap();
    let (out, _) = sarctl_bounded(&[
        "export".as_ref(),
        "--rosbag2".as_ref(),
        dir.join("bag").as_os_str(),
        path.as_os_str(),
    ]);
    assert!(!out.status.success(), "{}", text(&out.stdout));
    assert!(
        text(&out.stderr).contains("sarctl recover"),
        "{}",
        text(&out.stderr)
    );
    // A FIFO and a device: refused at once by every tool that reads a file.
    let fifo = dir.join("fifo.mcap");
    support::mkfifo(&fifo);
    let bag2 = dir.join("bag2");
    let runs: [Vec<&std::ffi::OsStr>; 5] = [
        vec!["replay".as_ref(), "--input".as_ref(), fifo.as_os_str()],
        vec![
            "replay".as_ref(),
            "--config".as_ref(),
            config.as_os_str(),
            "--input".as_ref(),
            fifo.as_os_str(),
        ],
        vec!["recover".as_ref(), fifo.as_os_str()],
        vec![
            "export".as_ref(),
            "--rosbag2".as_ref(),
            bag2.as_os_str(),
            fifo.as_os_str(),
        ],
        vec![
            "identify".as_ref(),
            "--config".as_ref(),
            config.as_os_str(),
            "--input".as_ref(),
            fifo.as_os_str(),
        ],
    ];
    for args in &runs {
        let (out, took) = sarctl_bounded(args);
        println!("{args:?}: refused in {took:?}");
        assert!(took < Duration::from_secs(5), "{args:?} took {took:?}");
        assert!(!out.status.success(), "{args:?}");
        assert!(
            text(&out.stderr).contains("not a regular file (a FIFO)"),
            "{args:?}: {}",
            text(&out.stderr)
        );
    }
    let (out, _) = sarctl_bounded(&[
        "recover".as_ref(),
        "/dev/zero".as_ref(),
        "--output".as_ref(),
        dir.join("z.mcap").as_os_str(),
    ]);
    assert!(
        text(&out.stderr).contains("a character device"),
        "{}",
        text(&out.stderr)
    );
    // A read error is named as such (reading /proc/self/mem at 0: EIO).
    let (out, _) = sarctl_bounded(&[
        "replay".as_ref(),
        "--input".as_ref(),
        "/proc/self/mem".as_ref(),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("read error: Input/output error"),
        "{}",
        text(&out.stderr)
    );
}

/// Runs `sarctl args` (no daemon): (success, stdout, stderr).
fn run_sarctl(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let out = Command::new(SARCTL).args(args).output().unwrap();
    (out.status.success(), text(&out.stdout), text(&out.stderr))
}

/// Issue 35, finding 2: an output is never one of the inputs, by any
/// name. "The output is the input" compared paths, not files: `recover
/// cut.mcap --output cut_hard.mcap` through a hard link cut the recording
/// (474,946 bytes to 463); after `export --rosbag2 bag rec.mcap` (which
/// hard-links), `replay --input rec.mcap --output bag/rec.mcap` cut the
/// original; `replay --plot rec.mcap` and `identify ... --plot REC`
/// replaced the recording with an SVG, exit 0. Now every file written is
/// compared by (device, inode) with every file read (the configuration
/// too) and with the other outputs, and refused in one line; the input is
/// left byte for byte; an output that replaces an older file (not an
/// input) is written beside it and renamed, leaving no temporary file.
#[test]
fn an_output_is_never_an_input_by_any_name() {
    let dir = support::scratch("replay_cli_output_is_input");
    let bytes = std::fs::read(fixtures().join("fault_daemon.mcap")).unwrap();
    let os = |p: &Path| p.as_os_str().to_owned();
    let refused = |args: &[std::ffi::OsString], kept: &Path, expected: &[u8]| {
        let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
        let (ok, _, err) = run_sarctl(&args);
        assert!(!ok, "{args:?} was not refused");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.contains("refusing to write over the input") || err.contains("same file"),
            "{args:?}: {err}"
        );
        assert!(
            std::fs::read(kept).unwrap() == expected,
            "{args:?}: {} changed",
            kept.display()
        );
    };
    // recover through a hard link of the crash-cut recording.
    let cut = dir.join("cut.mcap");
    let cut_bytes = &bytes[..bytes.len() * 2 / 3];
    std::fs::write(&cut, cut_bytes).unwrap();
    let cut_hard = dir.join("cut_hard.mcap");
    std::fs::hard_link(&cut, &cut_hard).unwrap();
    refused(
        &["recover".into(), os(&cut), "--output".into(), os(&cut_hard)],
        &cut,
        cut_bytes,
    );
    // replay into the rosbag2 directory export made of the same file.
    let rec = dir.join("rec.mcap");
    std::fs::write(&rec, &bytes).unwrap();
    let bag = dir.join("bag");
    let (ok, _, err) = run_sarctl(&[
        "export".as_ref(),
        "--rosbag2".as_ref(),
        bag.as_os_str(),
        rec.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let config = dir.join("config.toml");
    std::fs::copy(fixtures().join("config.toml"), &config).unwrap();
    let config_bytes = std::fs::read(&config).unwrap();
    let replay = |more: &[std::ffi::OsString]| {
        let mut a: Vec<std::ffi::OsString> = vec![
            "replay".into(),
            "--config".into(),
            os(&config),
            "--input".into(),
            os(&rec),
        ];
        a.extend_from_slice(more);
        a
    };
    refused(
        &replay(&["--output".into(), os(&bag.join("rec.mcap"))]),
        &rec,
        &bytes,
    );
    // A symbolic link, and the plot over the recording or the configuration.
    let soft = dir.join("soft.mcap");
    std::os::unix::fs::symlink(&rec, &soft).unwrap();
    refused(&replay(&["--output".into(), os(&soft)]), &rec, &bytes);
    refused(&replay(&["--plot".into(), os(&rec)]), &rec, &bytes);
    refused(
        &replay(&["--plot".into(), os(&config)]),
        &config,
        &config_bytes,
    );
    // --output and --plot the same file (one of them not there yet).
    let (ok, _, err) = run_sarctl(
        &replay(&[
            "--output".into(),
            os(&dir.join("o.mcap")),
            "--plot".into(),
            os(&dir.join(".").join("o.mcap")),
        ])
        .iter()
        .map(|a| a.as_os_str())
        .collect::<Vec<_>>(),
    );
    assert!(!ok && err.contains("are the same file"), "{err}");
    assert!(!dir.join("o.mcap").exists());
    // identify's plot over its recording or its configuration.
    let id_rec = dir.join("identify.mcap");
    std::fs::copy(
        fixtures().join("../identify/identify_manipulator_1.mcap"),
        &id_rec,
    )
    .unwrap();
    let id_bytes = std::fs::read(&id_rec).unwrap();
    let identify = |plot: &Path| -> Vec<std::ffi::OsString> {
        vec![
            "--config".into(),
            os(&config),
            "identify".into(),
            "--dry-run".into(),
            "--input".into(),
            os(&id_rec),
            "--plot".into(),
            os(plot),
        ]
    };
    refused(&identify(&id_rec), &id_rec, &id_bytes);
    refused(&identify(&config), &config, &config_bytes);
    // An older output (not an input) is replaced whole, through a
    // temporary file renamed over it: none is left beside it.
    let older = dir.join("older.mcap");
    std::fs::write(&older, b"an older output").unwrap();
    let (ok, _, err) = run_sarctl(
        &replay(&["--output".into(), os(&older)])
            .iter()
            .map(|a| a.as_os_str())
            .collect::<Vec<_>>(),
    );
    assert!(ok, "{err}");
    assert_eq!(&std::fs::read(&older).unwrap()[..8], b"\x89MCAP0\r\n");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    assert_eq!(std::fs::read(&rec).unwrap(), bytes);
    assert_eq!(std::fs::read(&cut).unwrap(), cut_bytes);
}

/// Issue 35, finding 10: `replay --output` writes what its input expands
/// to (a crafted lean file expanded 1,500 times, 242 KB to 379 MB) with no
/// look at the disk. Now the output's file system must have the inputs'
/// length free beyond a reserve (a twentieth of it, at most 256 MiB)
/// before anything is written, and the free space is checked while
/// writing: an output that would eat into the reserve stops with a clear
/// message, and nothing is left in its place (an older file there is kept
/// as it was, the temporary file removed). Shown on a small tmpfs with an
/// input whose replay (2.4 MB) is larger than the file system (2.35 MB).
#[test]
fn a_replay_stops_before_its_output_fills_the_disk_and_leaves_nothing_in_its_place() {
    let dir = support::scratch("replay_cli_expansion");
    let small = dir.join("small");
    let fs = Tmpfs::mount(&small, "size=2300k");
    let out = small.join("out.mcap");
    std::fs::write(&out, b"an older output").unwrap();
    let input = fixtures().join("contact_inputs.mcap");
    let config = fixtures().join("config.toml");
    let replay = |out: &Path| {
        run_sarctl(&[
            "replay".as_ref(),
            "--config".as_ref(),
            config.as_os_str(),
            "--input".as_ref(),
            input.as_os_str(),
            "--output".as_ref(),
            out.as_os_str(),
        ])
    };
    let (ok, _, err) = replay(&out);
    println!("{err}");
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("stopped while writing") && err.contains("must stay free"),
        "{err}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), b"an older output");
    let files: Vec<_> = std::fs::read_dir(&small)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(files, ["out.mcap"], "nothing beside the older output");
    assert!(fs.used() < 64 * 1024, "{} bytes used", fs.used());
    // Less free than the input's length and the reserve: refused before
    // anything is written.
    fs.remount("size=1200k");
    let (ok, _, err) = replay(&small.join("other.mcap"));
    assert!(!ok);
    assert!(err.contains("refused before writing"), "{err}");
    assert!(!small.join("other.mcap").exists());
}
