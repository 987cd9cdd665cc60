//! ROS 2 on the wire, read by a DDS that is not ours: `sard --sim` records
//! while `sar-ros2` bridges it onto a DDS domain, and Eclipse Cyclone DDS
//! (the DDS of ROS 2's `rmw_cyclonedds_cpp`, from Python: `cyclonedds`,
//! installed pinned by `scripts/setup-test-readers.sh`) subscribes with IDL
//! types written from the `.msg` files (`tests/cyclone_reader.py`). It
//! discovers every topic with ROS 2's names, types and QoS, decodes every
//! message, and each equals the recording's message of the same stamp
//! (read by Python `mcap-ros2-support`), field by field, floats bit for
//! bit; readers that join after the run get `/tf_static` and the last
//! guard events (transient local).
//!
//! The whole run lives in a private network namespace (`unshare -n`: this
//! machine's `lo` has no multicast, and no packet may reach a real
//! interface): the test runs itself again inside it, brings its `lo` up
//! with multicast, and gives Cyclone DDS (`CYCLONEDDS_URI`) and the bridge
//! (`[ros2] interfaces`) the loopback only. The daemon and the bridge use a
//! runtime directory of their own (`SAR_RUNTIME_DIR`). Needs root (or
//! unprivileged user namespaces), `unshare` and `ip`; `SAR_SKIP_PYTHON=1`
//! at build time marks it ignored, as the other strict readers' tests.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::{readers, repo_root, target_dir};
use sar_ros2::names::{dds_topic, dds_type};
use sar_ros2::topics::{ALL, Published, Qos};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Set in the test's second run, inside the network namespace.
const IN_NETNS: &str = "SAR_ROS2_TEST_IN_NETNS";
/// The DDS domain of the test.
const DOMAIN: u16 = 37;
/// Cycles `sard` runs (4 s at 1 kHz; the scenario's sensor freezes at 2 s).
const CYCLES: u64 = 4000;
/// The test's name (the second run selects it).
const NAME: &str = "cyclone_dds_reads_every_topic_equal_to_the_recording";

/// `sard`, in the same target directory as this package's binary (`cargo
/// test --workspace` builds every binary first; alone: `cargo build -p
/// sar-daemon --bin sard`).
fn sard() -> PathBuf {
    let sard = Path::new(env!("CARGO_BIN_EXE_sar-ros2")).with_file_name("sard");
    assert!(
        sard.exists(),
        "{} is missing: run `cargo test --workspace`, or `cargo build -p sar-daemon --bin sard` first",
        sard.display()
    );
    sard
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1: no Python Cyclone DDS")]
fn cyclone_dds_reads_every_topic_equal_to_the_recording() {
    if std::env::var(IN_NETNS).is_ok_and(|v| v == "1") {
        in_netns();
        return;
    }
    readers();
    sard();
    // Again, alone, in a network namespace of its own (root: `unshare -n`;
    // another user: in a user namespace of its own too, `-r`).
    let root = is_root();
    let mut cmd = Command::new("unshare");
    if !root {
        cmd.arg("-r");
    }
    cmd.arg("-n")
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", NAME, "--nocapture", "--test-threads", "1"])
        .env(IN_NETNS, "1");
    let mut child = cmd.spawn().expect("unshare (util-linux)");
    let status = wait_for(
        &mut child,
        Duration::from_secs(240),
        "the test in its namespace",
    );
    assert!(
        status.success(),
        "the test in its network namespace failed: {status}"
    );
}

/// Whether this process runs as root (`id -u`: no `unsafe` for `geteuid`).
fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Waits for `child` at most `limit` (then kills it and fails).
fn wait_for(child: &mut Child, limit: Duration, what: &str) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what} did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A child that is ended (SIGTERM, then waited for) when dropped.
struct Proc(Child);

impl Proc {
    fn terminate(&self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        self.terminate();
        let _ = wait_for_quiet(&mut self.0, Duration::from_secs(5));
    }
}

fn wait_for_quiet(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if let Ok(Some(s)) = child.try_wait() {
            return Some(s);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().ok()
}

fn sh(cmd: &str) {
    let out = Command::new("sh").arg("-c").arg(cmd).output().unwrap();
    assert!(
        out.status.success(),
        "{cmd}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The lines of `stdout`, one by one, on a channel.
fn lines(stdout: std::process::ChildStdout) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// The Cyclone DDS QoS names of a topic's offered QoS (reliability,
/// durability) as the reader's summary spells them.
fn offered(qos: Qos) -> (&'static str, &'static str) {
    (
        if qos.reliable() {
            "Reliability.Reliable"
        } else {
            "Reliability.BestEffort"
        },
        if qos.transient_local() {
            "Durability.TransientLocal"
        } else {
            "Durability.Volatile"
        },
    )
}

/// The second run, inside the network namespace.
fn in_netns() {
    // Only the loopback, with multicast; nothing else exists here.
    sh("ip link set lo up multicast on");
    sh("ip route add 224.0.0.0/4 dev lo 2>/dev/null || true");
    let links = Command::new("ip").args(["-o", "link"]).output().unwrap();
    let links = String::from_utf8_lossy(&links.stdout).to_string();
    assert_eq!(links.lines().count(), 1, "not a private namespace: {links}");

    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("sar-ros2/cyclone");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (config, rec_dir) = sar_test_support::files::recording_config(&dir);
    // The built-in configuration's `[ros2]` (its keys commented out) with
    // the domain and the loopback.
    let toml = std::fs::read_to_string(&config).unwrap();
    let ros2 = format!("\n[ros2]\ndomain_id = {DOMAIN}\ninterfaces = [\"127.0.0.1\"]\n");
    let with_ros2 = toml.replacen("\n[ros2]\n", &ros2, 1);
    assert_ne!(with_ros2, toml, "no [ros2] in the built-in configuration");
    std::fs::write(&config, with_ros2).unwrap();
    let cyclone_xml = dir.join("cyclonedds.xml");
    std::fs::write(
        &cyclone_xml,
        r#"<?xml version="1.0" encoding="UTF-8" ?>
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces><NetworkInterface name="lo" multicast="true"/></Interfaces>
      <AllowMulticast>true</AllowMulticast>
    </General>
  </Domain>
</CycloneDDS>
"#,
    )
    .unwrap();
    let runtime = dir.join("run");
    let prefix = format!("ros2-cyclone-{}", std::process::id());
    let tr = target_dir().join("test-readers");

    // The reader first: it waits for the writers.
    let mut reader = Command::new("python3")
        .arg(repo_root().join("crates/ros2/tests/cyclone_reader.py"))
        .arg("--msg-dir")
        .arg(repo_root().join("crates/msgs/msg"))
        .args(["--domain", &DOMAIN.to_string()])
        .env(
            "PYTHONPATH",
            format!("{}:{}", tr.join("dds").display(), tr.join("py").display()),
        )
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("PYTHONNOUSERSITE", "1")
        .env(
            "CYCLONEDDS_URI",
            format!("file://{}", cyclone_xml.display()),
        )
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut to_reader = reader.stdin.take().unwrap();
    let from_reader = lines(reader.stdout.take().unwrap());
    let reader = Proc(reader);
    let ready = from_reader
        .recv_timeout(Duration::from_secs(60))
        .expect("the reader did not start");
    assert!(ready.contains("\"ready\": true"), "{ready}");

    // The bridge: it waits for the daemon.
    let bridge_log = dir.join("bridge.log");
    let bridge = Proc(
        Command::new(env!("CARGO_BIN_EXE_sar-ros2"))
            .arg("--config")
            .arg(&config)
            .env("SAR_SERVICE_PREFIX", &prefix)
            .env("SAR_RUNTIME_DIR", &runtime)
            .env_remove("ROS_DOMAIN_ID")
            .stderr(std::fs::File::create(&bridge_log).unwrap())
            .spawn()
            .unwrap(),
    );

    // The daemon, recording from its first cycle, with a sensor that
    // freezes at 2 s (a guard event while the bridge runs).
    let sard_log = dir.join("sard.log");
    let mut daemon = Command::new(sard())
        .arg("--sim")
        .arg("--scenario")
        .arg(repo_root().join("scenarios/fault_sensor_frozen.toml"))
        .arg("--config")
        .arg(&config)
        .args(["--max-cycles", &CYCLES.to_string()])
        .env("SAR_SERVICE_PREFIX", &prefix)
        .env("SAR_RUNTIME_DIR", &runtime)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&sard_log).unwrap())
        .spawn()
        .unwrap();
    let status = wait_for(&mut daemon, Duration::from_secs(90), "sard");
    assert!(
        status.success(),
        "sard: {status}: {}",
        std::fs::read_to_string(&sard_log).unwrap_or_default()
    );
    let files = sar_test_support::files::recordings(&rec_dir);
    assert_eq!(files.len(), 1, "{files:?}");

    // Readers that join now (the bridge still runs), then the comparison.
    writeln!(to_reader, "late").unwrap();
    std::thread::sleep(Duration::from_millis(500));
    writeln!(to_reader, "stop {}", files[0].display()).unwrap();
    let summary = from_reader
        .recv_timeout(Duration::from_secs(120))
        .expect("the reader gave no summary");
    bridge.terminate();
    let summary: serde_json::Value = serde_json::from_str(&summary).unwrap();
    drop(reader);
    drop(bridge);
    let bridge_said = std::fs::read_to_string(&bridge_log).unwrap();
    println!("sar-ros2's log:\n{bridge_said}");
    check(&summary, &bridge_said);
}

/// What the reader found.
fn check(summary: &serde_json::Value, bridge_said: &str) {
    // Every topic discovered with ROS 2's name, type and the QoS offered.
    let discovered = &summary["discovered"];
    for topic in ALL {
        let name = dds_topic(topic.name()).unwrap();
        let d = &discovered[&name];
        assert_eq!(
            d["type"].as_str(),
            Some(dds_type(topic.type_name()).unwrap().as_str()),
            "{name}: {d}"
        );
        let (reliability, durability) = offered(topic.qos());
        assert_eq!(d["reliability"].as_str(), Some(reliability), "{name}: {d}");
        assert_eq!(d["durability"].as_str(), Some(durability), "{name}: {d}");
    }
    // Every message decoded, equal to the recording's of the same stamp.
    // (`/tf_static` is compared without its stamp: the reader's
    // `STAMPLESS`.)
    let scene = [Published::Scene, Published::SceneStatus, Published::Tf];
    for topic in ALL {
        let t = &summary["topics"][topic.name()];
        let n = |k: &str| t[k].as_u64().unwrap();
        println!(
            "{:36} received {:5} recorded {:5} matched {:5} latency p50/p99/max {} ns",
            topic.name(),
            n("received"),
            n("recorded"),
            n("matched"),
            t["latency_ns"]
        );
        assert!(n("received") > 0, "{}: nothing received: {t}", topic.name());
        assert_eq!(n("mismatched"), 0, "{}: {t}", topic.name());
        if scene.contains(&topic) {
            // The bridge's first scene is drawn when it joins, which the
            // recording's need not be; after it the two pick the same
            // cycles (`sar_scene::rate`).
            assert!(n("unrecorded") <= 1, "{}: {t}", topic.name());
            if n("unrecorded") == 1 {
                assert_eq!(t["unrecorded_stamps"][0], t["first_stamp"], "{t}");
            }
        } else {
            assert_eq!(n("unrecorded"), 0, "{}: {t}", topic.name());
        }
        assert_eq!(n("matched") + n("unrecorded"), n("received"));
    }
    let count = |p: Published| summary["topics"][p.name()]["matched"].as_u64().unwrap();
    let estimate = Published::Record(sar_msgs::msgs::Topic::EstimatorState);
    assert!(count(estimate) >= 1000, "{}", count(estimate));
    assert!(count(Published::Scene) >= 30, "{}", count(Published::Scene));
    // The transient local topics reach a reader that joins later.
    let late = &summary["late"];
    let tf_static = &late[sar_scene::TF_STATIC_TOPIC];
    assert_eq!(tf_static["received"], 1, "{late}");
    assert_eq!(tf_static["all_recorded"], true, "{late}");
    let events = &late[sar_msgs::msgs::Topic::GuardEvents.name()];
    assert!(events["received"].as_u64().unwrap() >= 1, "{late}");
    assert_eq!(events["all_recorded"], true, "{late}");
    assert_eq!(events["last_is_recorded_last"], true, "{late}");
    // The bridge said what it did, and DDS refused nothing.
    let stopped = bridge_said
        .lines()
        .find(|l| l.starts_with("sar-ros2: stopped:"))
        .expect("the bridge's summary line");
    let refused: u64 = stopped
        .split('(')
        .skip(1)
        .filter_map(|s| s.split(')').next()?.parse::<u64>().ok())
        .sum();
    assert_eq!(refused, 0, "{stopped}");
}
