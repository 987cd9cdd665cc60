//! `sarctl` as a process: every command fails with a one-line reason when no
//! daemon runs; with `sard --sim` running, `monitor --format json` prints one
//! JSON object per line and `limits`, `status`, `tare`, `move-tip` answer;
//! `record start|stop` print the recording's absolute path.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use support::{SARCTL, SARD};

fn sarctl(prefix: &str, args: &[&str]) -> Output {
    Command::new(SARCTL)
        .args(args)
        .env("SAR_SERVICE_PREFIX", prefix)
        .output()
        .unwrap()
}

#[test]
fn every_command_fails_in_one_line_without_a_daemon() {
    let prefix = format!("sar-none-{}", std::process::id());
    for args in [
        &["status"][..],
        &["monitor"],
        &["reset"],
        &["tare"],
        &["move-tip", "0.6", "0.2", "-0.01"],
        &["limits"],
        &["status", "--format", "json"],
    ] {
        let out = sarctl(&prefix, args);
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("sarctl: no daemon runs"), "{args:?}: {err}");
    }
}

struct Daemon(std::process::Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

#[test]
fn monitor_json_limits_status_and_commands_with_a_daemon() {
    let prefix = format!("sar-ctl-{}", std::process::id());
    let _daemon = Daemon(
        Command::new(&*SARD)
            .arg("--sim")
            .env("SAR_SERVICE_PREFIX", &prefix)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let start = Instant::now();
    while !sarctl(&prefix, &["status"]).status.success() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "sard did not come up"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = sarctl(&prefix, &["monitor", "--format", "json", "--count", "5"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 5, "{text}");
    let cycles: Vec<u64> = lines.iter().map(|v| v["cycle"].as_u64().unwrap()).collect();
    assert!(cycles.windows(2).all(|w| w[0] < w[1]), "{cycles:?}");
    assert!(lines[0]["guard"].is_string());

    let out = sarctl(&prefix, &["limits", "--format", "json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["stop_total_n"], 15.0);
    assert_eq!(v["warn_axial_n"], 8.0);

    // Lowering a limit is accepted and shows at once; raising one above its
    // ceiling (by default the configured limit) is refused in one line and
    // changes nothing.
    let out = sarctl(
        &prefix,
        &["limits", "--stop-axial", "11.5", "--format", "json"],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["stop_axial_n"], 11.5);
    assert_eq!(v["warn_axial_n"], 8.0);
    let out = sarctl(&prefix, &["limits", "--stop-axial", "30"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("ceiling"), "{err}");
    let out = sarctl(&prefix, &["limits", "--format", "json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["stop_axial_n"], 11.5);

    let out = sarctl(&prefix, &["status", "--format", "json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["tip_m"][0], 0.6);
    assert_eq!(v["limits_n"][3], 11.5);
    // Named fields beside the bare ones.
    assert_eq!(v["limits"]["stop_axial_n"], 11.5);
    assert_eq!(v["limits"]["stop_total_n"], v["limits_n"][1]);
    assert_eq!(v["limits"]["warn_lateral_n"], v["limits_n"][4]);
    let names = ["unknown", "ready", "enabled", "quick_stop", "fault"];
    let code = usize::try_from(v["drive_state"].as_u64().unwrap()).unwrap();
    assert_eq!(v["drive_state_name"], names[code], "{v}");

    // The reachable region: the built-in travel, and from the present pose
    // the tip's range along base x/y/z moving one axis at a time.
    let out = sarctl(&prefix, &["workspace", "--format", "json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let w: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(w["travel_m"]["q1"], serde_json::json!([-0.3, 0.3]), "{w}");
    assert_eq!(w["travel_m"]["q3"], serde_json::json!([0.0, 0.6]), "{w}");
    let tip = w["present_tip_m"].as_array().unwrap();
    let sweeps = w["one_axis_at_a_time"].as_array().unwrap();
    assert_eq!(sweeps.len(), 3, "{w}");
    for s in sweeps {
        // Each range holds the present tip (the sweep passes through it).
        for (c, key) in ["tip_x_m", "tip_y_m", "tip_z_m"].iter().enumerate() {
            let r = s[key].as_array().unwrap();
            let (lo, hi) = (r[0].as_f64().unwrap(), r[1].as_f64().unwrap());
            let t = tip[c].as_f64().unwrap();
            assert!(lo <= t + 1e-3 && t - 1e-3 <= hi, "{s} {key} vs {t}");
        }
    }
    let out = sarctl(&prefix, &["workspace"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("axis travel ([axes] travel_m): q1 -0.3000..0.3000 m"),
        "{text}"
    );
    assert!(text.contains("q2: x "), "{text}");

    // A small move along +Z (the force is along +X): accepted in Ok, which
    // the demo's automatic reset reaches once the mean at rest is complete.
    let start = Instant::now();
    loop {
        let out = sarctl(&prefix, &["status", "--format", "json"]);
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        if v["guard"] == "ok" {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "never Ok: {v}");
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = sarctl(
        &prefix,
        &["move-tip", "0.6", "0.2", "0.002", "--format", "json"],
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["command"], "move-tip");
    assert!(out.status.success(), "{v}");
    // A target the rod cannot reach is refused, in one line.
    let out = sarctl(&prefix, &["move-tip", "5.0", "0.2", "0.0"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot be reached"), "{err}");
    assert!(err.contains("sarctl workspace"), "{err}");
    assert_eq!(err.lines().count(), 1);
    // A target beyond q3's travel: the axis, its range and by how much.
    let out = sarctl(&prefix, &["move-tip", "0.3", "0.2", "0.0"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("q3 would be 0.6500 m, outside its travel 0.0000..0.6000 m"),
        "{err}"
    );
    assert!(
        err.contains("[axes] travel_m) by 0.0500 m above its upper end"),
        "{err}"
    );
    assert!(err.contains("sarctl workspace"), "{err}");
}

#[test]
fn completions_name_the_subcommands() {
    let prefix = format!("sar-none-{}", std::process::id());
    for shell in ["bash", "zsh", "fish"] {
        let out = sarctl(&prefix, &["completions", shell]);
        assert!(out.status.success(), "{shell}");
        let text = String::from_utf8(out.stdout).unwrap();
        for word in [
            "sarctl",
            "status",
            "monitor",
            "move-tip",
            "workspace",
            "record",
            "completions",
        ] {
            assert!(text.contains(word), "{shell}: no {word}");
        }
    }
    let out = sarctl(&prefix, &["completions", "tcsh"]);
    assert!(!out.status.success());
}

#[test]
fn the_log_has_no_rust_debug_text() {
    let prefix = format!("sar-log-{}", std::process::id());
    let dir = scratch("log_words");
    let out = Command::new(&*SARD)
        .args(["--sim", "--max-cycles", "2000"])
        .current_dir(&dir)
        .env("SAR_SERVICE_PREFIX", &prefix)
        .output()
        .unwrap();
    assert!(out.status.success());
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(log.contains("drives: "), "{log}");
    for bad in ["Some(", "None", "(("] {
        assert!(!log.contains(bad), "{bad} in the log:\n{log}");
    }
}

/// Starts `sard --sim` under `prefix` in `dir` (its log to `log`) and waits
/// until `sarctl status` answers (deadline 30 s).
fn start_daemon(prefix: &str, dir: &std::path::Path, extra: &[&str]) -> Daemon {
    let log = std::fs::File::create(dir.join("sard.log")).unwrap();
    let daemon = Daemon(
        Command::new(&*SARD)
            .arg("--sim")
            .args(extra)
            .current_dir(dir)
            .env("SAR_SERVICE_PREFIX", prefix)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    let start = Instant::now();
    while !sarctl(prefix, &["status"]).status.success() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "sard did not come up"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    daemon
}

/// A fresh scratch directory under the target's tmp dir.
fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("sar-daemon-sarctl")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn record_start_and_stop_print_the_absolute_path() {
    let prefix = format!("sar-rec-{}", std::process::id());
    let dir = scratch("record_path");
    let daemon = start_daemon(&prefix, &dir, &[]);
    let expected_dir = dir.canonicalize().unwrap().join("recordings");

    let out = sarctl(&prefix, &["record", "start"]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let file_of = |text: &str, key: &str| -> std::path::PathBuf {
        let line = text
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .unwrap_or_else(|| panic!("no {key:?} line: {text}"));
        std::path::PathBuf::from(line.split(" (after a rotation").next().unwrap().trim())
    };
    let started = file_of(&text, "file:");
    assert!(started.is_absolute(), "{text}");
    assert_eq!(
        started.parent().unwrap().canonicalize().unwrap(),
        expected_dir,
        "{text}"
    );
    assert!(started.to_string_lossy().ends_with("-0000.mcap"), "{text}");

    let out = sarctl(&prefix, &["record", "stop", "--format", "json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["recording"], false);
    assert_eq!(v["file"].as_str().unwrap(), started.to_str().unwrap());

    // The file is there once the writer has closed it (its summary written).
    let deadline = Instant::now() + Duration::from_secs(20);
    while !std::fs::metadata(&started).is_ok_and(|m| m.len() > 0) {
        assert!(
            Instant::now() < deadline,
            "{} never written",
            started.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(daemon);
    let log = std::fs::read_to_string(dir.join("sard.log")).unwrap();
    assert!(
        log.contains(&format!("recordings go to {}", expected_dir.display())),
        "{log}"
    );
}

/// Issue 25, finding 7: `sarctl status | head -0` and every other output
/// into a pipe whose reader has gone end quietly: no panic ("failed
/// printing to stdout"), no exit 101, nothing on stderr. The reader is
/// closed before `sarctl` starts, so that its first write meets the closed
/// pipe whatever the timing. `sarctl` ends as the Unix filters do, by
/// SIGPIPE (a shell says 141).
#[test]
fn a_closed_pipe_ends_every_output_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let prefix = format!("sar-pipe-{}", std::process::id());
    let dir = scratch("closed_pipe");
    let _daemon = start_daemon(&prefix, &dir, &[]);
    for args in [
        &["status"][..],
        &["status", "--format", "json"],
        &["workspace"],
        &["workspace", "--format", "json"],
        &["limits"],
        &["monitor", "--count", "3"],
        &["monitor", "--format", "json", "--count", "3"],
        &["completions", "bash"],
        &["--help"],
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(SARCTL)
            .args(args)
            .env("SAR_SERVICE_PREFIX", &prefix)
            .stdout(writer)
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.is_empty(), "{args:?}: {err}");
        assert!(
            out.status.success() || out.status.signal() == Some(13),
            "{args:?}: {:?}",
            out.status
        );
    }
}
