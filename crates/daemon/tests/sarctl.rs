//! `sarctl` as a process: every command fails with a one-line reason when no
//! daemon runs; with `sard --sim` running, `monitor --format json` prints one
//! JSON object per line and `limits`, `status`, `tare`, `move-tip` answer.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const SARD: &str = env!("CARGO_BIN_EXE_sard");
const SARCTL: &str = env!("CARGO_BIN_EXE_sarctl");

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
        Command::new(SARD)
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
    assert_eq!(err.lines().count(), 1);
}
