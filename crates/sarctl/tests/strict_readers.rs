//! The recordings as the ecosystem's tools read them (issue 16), with none of
//! this project's code: Python `rosbags` (the file opened by
//! `rosbags.rosbag2.Reader`, a type store built only from the schemas the
//! file embeds) and the parsers Foxglove and Lichtblick use (`@mcap/core`,
//! `@foxglove/rosmsg` `parse(.., {ros2: true})`,
//! `@foxglove/rosmsg2-serialization`), each decoding every schema and every
//! message with 0 failures, on
//! - every fixture under `tests/fixtures/`,
//! - a `sarctl replay` output,
//! - a fresh recording of `sard --sim`, and the rosbag2 directory that
//!   `sarctl export --rosbag2` makes of it (`rosbags.rosbag2.Reader(DIR)`
//!   reads its `metadata.yaml`, then every message of the file);
//!
//! and every message path of `deploy/foxglove-layout.json` on a recorded
//! topic found in the decoded messages of the replay output and of the
//! daemon's recording, the 3D panel's topics (`/sar/scene`, `/tf`,
//! `/tf_static`) included: each file opens alone with the scene. The
//! scene's schemas match ROS 2 Jazzy's types (rosbags' `Stores.ROS2_JAZZY`),
//! and one `MarkerArray` decoded by `rosbags` draws the rod from A's foot to
//! the recorded tip and F_tip |F_tip| x the scale long
//! (`scripts/test-readers/check_scene.py`). The readers are installed on first use by
//! `scripts/setup-test-readers.sh` (`common::readers`); `SAR_SKIP_PYTHON=1`
//! or `SAR_SKIP_NODE=1` at build time mark these tests ignored.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

#[path = "../../daemon/tests/common/mod.rs"]
mod common;
mod support;
use support::{Daemon, sard};

use common::readers;
use sar_record::McapReader;
use sar_record::replay::{ReplayOptions, replay_file};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The layout's paths on the recorded topics (the live-only
/// `/sar/view/status` is not in recordings; the fixtures predate the scene).
const RECORDED_PREFIXES: [&str; 2] = ["/sar/estimate/", "/sar/guard/"];

/// The 3D panel's topics, in every fresh recording and replay output.
const SCENE_PATHS: [&str; 3] = ["/sar/scene", "/tf", "/tf_static"];

/// Every path of the layout resolves on this one file, but the live view's
/// own status (`/sar/view/status`, JSON, never recorded).
fn assert_every_layout_path(file: &serde_json::Value) {
    let layout = file["layout"].as_object().unwrap();
    for p in SCENE_PATHS {
        assert_eq!(layout.get(p), Some(&"ok".into()), "{p} in {}", file["path"]);
    }
    for (p, status) in layout {
        if !p.starts_with("/sar/view/status") && !p.starts_with("/sar/guard/") {
            assert_eq!(status, "ok", "{p} in {}", file["path"]);
        }
    }
}

/// The scene of `file` as `rosbags` decodes it: Jazzy's types, the rod's
/// ends and the arrow against the recorded state of the same cycle.
fn check_scene_with_rosbags(file: &Path) {
    let out = sar_test_support::process::run_ok(
        readers::python()
            .arg(readers::repo_root().join("scripts/test-readers/check_scene.py"))
            .arg(file),
        "check_scene.py",
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["mismatches"], serde_json::json!([]), "{v}");
    // MarkerArray, Marker, Header, Time, Pose, Point, Quaternion, Vector3,
    // ColorRGBA, Duration, CompressedImage, UVCoordinate, MeshFile;
    // TFMessage, TransformStamped, Transform.
    assert_eq!(v["types"], 16, "{v}");
    assert_eq!(
        v["tf_static"],
        serde_json::json!([["world", "base"]]),
        "{v}"
    );
    let xyz =
        |x: &serde_json::Value| -> [f64; 3] { std::array::from_fn(|i| x[i].as_f64().unwrap()) };
    let (scene, state) = (&v["scene"], &v["state"]);
    assert_eq!(scene["frame_id"], "base");
    let (ujoint, tip, force) = (
        xyz(&state["ujoint_m"]),
        xyz(&state["tip_m"]),
        xyz(&state["tip_force_n"]),
    );
    let dist = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let cfg = sar_config::builtin().unwrap();
    let geometry = sar_scene::geometry::SceneGeometry::from_config(&cfg.estimator);
    // The rod: A's foot on the rod axis (|d| from A), then the tip D, L apart.
    let (foot, end) = (xyz(&scene["rod"][0]), xyz(&scene["rod"][1]));
    assert!(dist(end, tip) < 1e-9, "{v}");
    assert!(
        (dist(foot, ujoint) - geometry.offset_m.abs()).abs() < 1e-9,
        "{v}"
    );
    assert!((dist(foot, end) - geometry.length_m).abs() < 1e-9, "{v}");
    // The arrow: from D, |F_tip| x the scale long, along F_tip.
    let (tail, head) = (xyz(&scene["arrow"][0]), xyz(&scene["arrow"][1]));
    assert!(dist(tail, tip) < 1e-12, "{v}");
    let magnitude = dist(force, [0.0; 3]);
    assert!(magnitude > 0.0);
    assert!(
        (dist(head, tail) - magnitude * geometry.force_scale_m_per_n).abs() < 1e-12,
        "{v}"
    );
    let along: [f64; 3] =
        std::array::from_fn(|i| tail[i] + force[i] * geometry.force_scale_m_per_n);
    assert!(dist(head, along) < 1e-12, "{v}");
}

fn fixtures() -> Vec<PathBuf> {
    let root = readers::repo_root().join("tests/fixtures");
    let mut files = Vec::new();
    for sub in ["replay", "identify"] {
        for e in std::fs::read_dir(root.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "mcap") {
                files.push(p);
            }
        }
    }
    files.sort();
    files
}

/// Messages per topic by this project's reader.
fn our_counts(file: &Path) -> BTreeMap<String, u64> {
    let bytes = std::fs::read(file).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut ids = Vec::new();
    for m in reader.by_ref() {
        ids.push(m.unwrap().channel_id);
    }
    let mut counts = BTreeMap::new();
    for id in ids {
        *counts
            .entry(reader.channels()[&id].topic.clone())
            .or_default() += 1;
    }
    counts
}

/// Both readers over `files`: 0 failures, every message of every file (as
/// our reader counts them per topic) decoded by each. Returns the Foxglove
/// check's files (with the layout's paths).
fn check_strictly(files: &[PathBuf], what: &str) -> Vec<serde_json::Value> {
    let py = readers::rosbags(files);
    let js = readers::foxglove(files);
    let py_files = readers::assert_clean(&py, "rosbags");
    let js_files = readers::assert_clean(&js, "foxglove");
    for ((file, p), j) in files.iter().zip(&py_files).zip(&js_files) {
        let ours = our_counts(file);
        let as_map = |v: &serde_json::Value| -> BTreeMap<String, u64> {
            v["topics"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(k, n)| (k.clone(), n.as_u64().unwrap()))
                .collect()
        };
        assert_eq!(as_map(p), ours, "rosbags vs ours: {}", file.display());
        assert_eq!(as_map(j), ours, "foxglove vs ours: {}", file.display());
        assert_eq!(j["profile"], "ros2", "{}", file.display());
    }
    let (n, schemas, messages, failures) = readers::totals(&py);
    eprintln!(
        "{what}: rosbags decoded {messages} messages, {schemas} schemas in {n} files, {failures} failures"
    );
    let (n, schemas, messages, failures) = readers::totals(&js);
    eprintln!(
        "{what}: Foxglove parsers decoded {messages} messages, {schemas} schemas in {n} files, {failures} failures"
    );
    js_files
}

/// Every layout path on a recorded topic is found in the file's messages.
fn assert_layout_paths(file: &serde_json::Value) {
    let layout = file["layout"].as_object().unwrap();
    let recorded: Vec<_> = layout
        .iter()
        .filter(|(p, _)| RECORDED_PREFIXES.iter().any(|pre| p.starts_with(pre)))
        .collect();
    // The per-axis F_tip plots, the axial/lateral plots, the guard events.
    assert!(recorded.len() >= 6, "{layout:?}");
    for (p, status) in recorded {
        assert_eq!(status, "ok", "{p} in {}", file["path"]);
    }
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
#[cfg_attr(sar_skip_node, ignore = "SAR_SKIP_NODE=1")]
fn every_fixture_decodes_with_the_strict_readers() {
    let files = fixtures();
    assert!(files.len() >= 10, "{files:?}");
    for f in check_strictly(&files, "fixtures") {
        // Fixtures with outputs (the daemon's) carry every layout path.
        let layout = f["layout"].as_object().unwrap();
        if layout.get("/sar/estimate/state.axial_n") != Some(&"no-channel".into())
            && f["topics"].get("/sar/estimate/state").is_some()
        {
            assert_layout_paths(&f);
        }
    }
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
#[cfg_attr(sar_skip_node, ignore = "SAR_SKIP_NODE=1")]
fn a_replay_output_decodes_with_the_strict_readers() {
    let root = readers::repo_root();
    let cfg = sar_config::load(&root.join("tests/fixtures/replay/config.toml")).unwrap();
    let dir = common::scratch("strict_replay");
    let out = dir.join("out.mcap");
    let mut options = ReplayOptions::from_config(&cfg);
    options.output = Some(out.clone());
    let report = replay_file(
        &root.join("tests/fixtures/replay/contact_daemon.mcap"),
        &options,
    )
    .unwrap();
    assert!(report.first_difference.is_none(), "{report:?}");
    let files = check_strictly(std::slice::from_ref(&out), "replay output");
    assert_layout_paths(&files[0]);
    assert_every_layout_path(&files[0]);
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
#[cfg_attr(sar_skip_node, ignore = "SAR_SKIP_NODE=1")]
fn a_sard_recording_decodes_with_the_strict_readers() {
    let dir = common::scratch("strict_sard");
    // 3 s of the demo on the simulator, then sard ends and closes the file;
    // the one recording of it.
    let prefix = format!("sar-strict-{}", std::process::id());
    let files = vec![support::sim_recording(&dir, 3000, &prefix)];
    let checked = check_strictly(&files, "sard --sim recording");
    assert_layout_paths(&checked[0]);
    assert_every_layout_path(&checked[0]);
    check_scene_with_rosbags(&files[0]);
    let topics = checked[0]["topics"].as_object().unwrap();
    for t in [
        "/sar/sensor/wrench",
        "/sar/joints",
        "/sar/estimate/tip_wrench",
        "/sar/estimate/state",
        "/sar/cycle/input",
    ] {
        // 3000 cycles at 1 kHz; the sensor's samples at its own rate.
        assert!(topics[t].as_u64().unwrap() >= 1000, "{t}: {topics:?}");
    }
    // The rosbag2 directory of it, as ROS 2's tools open one.
    let bag = dir.join("bag");
    sar_test_support::process::run_ok(
        Command::new(support::SARCTL)
            .args(["export", "--rosbag2"])
            .arg(&bag)
            .arg(&files[0]),
        "sarctl export",
    );
    let py = readers::rosbags(std::slice::from_ref(&bag));
    let py_files = readers::assert_clean(&py, "rosbags (rosbag2 directory)");
    let ours = our_counts(&files[0]);
    let theirs: BTreeMap<String, u64> = py_files[0]["topics"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, n)| (k.clone(), n.as_u64().unwrap()))
        .collect();
    assert_eq!(theirs, ours, "rosbag2 directory vs ours");
    // Every channel in metadata.yaml, the empty ones too, and the scene's.
    assert_eq!(
        py_files[0]["channels"].as_u64().unwrap(),
        sar_record::Topic::ALL.len() as u64 + SCENE_PATHS.len() as u64
    );
    for t in SCENE_PATHS {
        assert!(theirs.get(t).is_some_and(|n| *n >= 1), "{t}: {theirs:?}");
    }
    let (_, schemas, messages, failures) = readers::totals(&py);
    eprintln!(
        "rosbag2 directory: rosbags decoded {messages} messages, {schemas} schemas, {failures} failures"
    );
}

/// The live view with `@foxglove/ws-protocol`'s client (its default
/// subprotocol `foxglove.websocket.v1`): every advertised `ros2msg` schema
/// parses, every CDR message received decodes, and every path of the layout
/// (the live-only status panel's too) is in the decoded messages.
#[test]
#[cfg_attr(sar_skip_node, ignore = "SAR_SKIP_NODE=1")]
fn the_live_view_decodes_with_the_foxglove_client() {
    use std::io::{BufRead, BufReader};
    let prefix = format!("sar-strict-live-{}", std::process::id());
    // Install first: the daemon should not wait for npm.
    let _ = readers::ensure(readers::Part::Node);
    let _daemon = Daemon::spawn(sard(&prefix).arg("--sim"));
    support::wait_for_state(&prefix, "sard did not come up", |_| true);
    let mut view = Command::new(support::SARCTL)
        .args(["--prefix", &prefix, "view", "--bind", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(view.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let _view = Daemon(view);
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("ws://"))
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_owned();
    let out = sar_test_support::process::run_ok(
        readers::node()
            .arg(readers::repo_root().join("scripts/test-readers/check_live.mjs"))
            .arg("--layout")
            .arg(readers::repo_root().join("deploy/foxglove-layout.json"))
            .arg(&url),
        "check_live.mjs",
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!(
        "live view: the Foxglove client decoded {} messages, {} schemas, {} failures",
        v["messages"], v["schemas"], v["failures"]
    );
    assert_eq!(v["failures"], 0, "{}", v["errors"]);
    assert_eq!(v["subprotocol"], "foxglove.websocket.v1");
    assert!(v["schemas"].as_u64().unwrap() >= 4, "{v}");
    let layout = v["layout"].as_object().unwrap();
    assert!(layout.len() >= 15, "{layout:?}");
    for (p, status) in layout {
        // The guard's events come only at transitions; the rest is there.
        if p != "/sar/guard/events" {
            assert_eq!(status, "ok", "{p}: {v}");
        }
    }
}
