//! The lean recording mode (`[record] mode = "inputs"`, issue 28): one run
//! of the simulated rig recorded twice, full and lean, from the same
//! cycles (two recordings fed by the loop side by side); `replay --output`
//! of the lean file is the full file message for message (every channel
//! that both carry, compared generically: bytes, log and publish times,
//! sequence numbers; the metadata written at a file's start), and the lean
//! file is much smaller.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config as config;
use sar_config::{RecordMode, RecordSettings, Rotation};
use sar_estimator::Vec3;
use sar_loop::control::{Envelope, Request};
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_loop::stats::LoopStats;
use sar_msgs::msgs::{RecorderDrops, RosMessage, Topic};
use sar_record::live::{LiveRecorder, RecordManager, RecordSwitch};
use sar_record::replay::{ReplayOptions, replay_file};
use sar_record::{McapReader, read_file};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A recording of `mode` into `dir`, from the first cycle on, with a
/// snapshot every 250 ms.
fn recording(
    dir: &Path,
    mode: RecordMode,
    m_per_count: f64,
    bias: sar_estimator::cycle::Bias,
) -> (RecordManager, LiveRecorder, Arc<RecordSwitch>) {
    let switch = Arc::new(RecordSwitch::default());
    let (manager, sink) = RecordManager::start(
        RecordSettings {
            enabled: true,
            directory: dir.to_path_buf(),
            rotation: Rotation::default(),
            queue_capacity: 1 << 20,
            scene_period_ns: None,
            snapshot_period_ns: 250_000_000,
            config_source: Some(Arc::new(config::ConfigSource {
                origin: "the built-in configuration".into(),
                toml: config::DEFAULT_TOML.into(),
            })),
            mode,
            scales: config::DeviceScales {
                joint_m_per_count: m_per_count,
                ..config::DeviceScales::default()
            },
        },
        None,
        bias,
        Arc::clone(&switch),
    )
    .unwrap();
    (manager, sink, switch)
}

/// Runs 4 s of the demo rig (a reset, a tare, a move, a 20 N push along the
/// rod that stops the guard, a reset, new limits) recorded full into
/// `dirs.0` and lean into `dirs.1`: the two files.
fn run_both(name: &str) -> (PathBuf, PathBuf) {
    let root = sar_test_support::scratch!(name);
    let (full_dir, lean_dir) = (root.join("full"), root.join("lean"));
    let SimRig {
        mut c,
        sim,
        clock,
        operator,
        queue,
        bias,
        cfg,
        ..
    } = RigBuilder::demo(rod_push_20n([
        2_000_000_000,
        2_300_000_000,
        2_600_000_000,
        2_900_000_000,
    ]))
    .build();
    let m_per_count = sim.encoder_m_per_count().unwrap();
    let (full_mgr, mut full, full_switch) =
        recording(&full_dir, RecordMode::Full, m_per_count, bias);
    let (lean_mgr, mut lean, lean_switch) =
        recording(&lean_dir, RecordMode::Inputs, m_per_count, bias);
    let stats = LoopStats::default();
    let configured = cfg.estimator.guard.force_limits();
    let lower = sar_estimator::guard::ForceLimits {
        warn_total_n: configured.warn_total_n - 0.5,
        ..configured
    };
    for cycle in 1..=4000u64 {
        clock.advance_ns(1_000_000);
        let request = match cycle {
            100 | 3200 => Some(Request::Reset),
            300 => Some(Request::Tare),
            500 => Some(Request::MoveTip {
                tip_m: Vec3::new(0.6, 0.2, 0.002),
            }),
            3500 => Some(Request::SetLimits(lower)),
            _ => None,
        };
        if let Some(request) = request {
            operator
                .requests
                .push(Envelope { id: cycle, request })
                .unwrap();
        }
        full.before_cycle();
        lean.before_cycle();
        c.step(cycle, || Some(clock.now_ns()));
        let truth = None;
        full.cycle(&Cycle::of(&c, &stats, truth), &mut SinkHealth::default());
        lean.cycle(&Cycle::of(&c, &stats, truth), &mut SinkHealth::default());
        while queue.pop().is_some() {}
        while operator.replies.pop().is_some() {}
    }
    assert_eq!((full_switch.dropped(), lean_switch.dropped()), (0, 0));
    full.release();
    lean.release();
    full_mgr.finish();
    lean_mgr.finish();
    let one = |dir: &Path| {
        let files = sar_test_support::files::recordings(dir);
        assert_eq!(files.len(), 1, "{files:?}");
        files[0].clone()
    };
    (one(&full_dir), one(&lean_dir))
}

/// Every message of a file by channel topic: (sequence, log time, publish
/// time, bytes); and the metadata records written at its start.
type Messages = BTreeMap<String, Vec<(u32, u64, u64, Vec<u8>)>>;

fn messages(path: &Path) -> (Messages, BTreeMap<String, BTreeMap<String, String>>) {
    let bytes = read_file(path).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut out = Messages::new();
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        let topic = reader.channels()[&m.channel_id].topic.clone();
        out.entry(topic)
            .or_default()
            .push((m.sequence, m.log_time_ns, m.publish_time_ns, m.data));
    }
    let metadata = reader
        .metadata()
        .iter()
        .map(|m| (m.name.clone(), m.metadata.clone()))
        .collect();
    (out, metadata)
}

#[test]
fn a_lean_recording_replays_to_the_full_one_message_for_message() {
    let (full, lean) = run_both("lean_recording");
    let (full_size, lean_size) = (
        std::fs::metadata(&full).unwrap().len(),
        std::fs::metadata(&lean).unwrap().len(),
    );
    println!(
        "4000 cycles: full {full_size} bytes ({:.1} per cycle), lean {lean_size} bytes ({:.1} per cycle)",
        full_size as f64 / 4000.0,
        lean_size as f64 / 4000.0
    );
    let cfg = config::builtin().unwrap();
    // The lean file replays directly (its guard events and snapshots
    // compared) ...
    let r = replay_file(&lean, &ReplayOptions::from_config(&cfg)).unwrap();
    assert_eq!(r.first_difference, None);
    assert_eq!(r.cycles, 4000);
    assert!(r.snapshots_compared >= 15, "{}", r.snapshots_compared);
    // ... and its replay's output is the full file.
    let out = lean.with_file_name("made-full.mcap");
    let mut options = ReplayOptions::from_config(&cfg);
    options.output = Some(out.clone());
    let r = replay_file(&lean, &options).unwrap();
    assert_eq!(r.first_difference, None);
    let (want, want_meta) = messages(&full);
    let (got, got_meta) = messages(&out);
    let (lean_msgs, _) = messages(&lean);
    assert!(lean_msgs.contains_key(Topic::CycleBatch.name()));
    assert!(
        want[Topic::GuardEvents.name()].len() >= 2,
        "the run has guard events"
    );
    // Every channel, generically: the recorder's own account differs in
    // its `written` count (the lean recorder wrote fewer messages), and
    // is compared on what it says of the drops.
    let drops = Topic::RecorderDrops.name();
    let topics: Vec<&String> = want.keys().chain(got.keys()).collect();
    for topic in topics {
        if topic == drops {
            continue;
        }
        let (w, g) = (want.get(topic), got.get(topic));
        let (w, g) = (
            w.map_or(&[][..], Vec::as_slice),
            g.map_or(&[][..], Vec::as_slice),
        );
        assert_eq!(w.len(), g.len(), "{topic}: message count");
        for (i, (a, b)) in w.iter().zip(g).enumerate() {
            assert!(a == b, "{topic}: message {i} differs");
        }
    }
    let dropped = |m: &Messages| {
        m[drops]
            .iter()
            .map(|(_, _, _, d)| RecorderDrops::decode(d).unwrap().dropped)
            .max()
    };
    assert_eq!(dropped(&got), dropped(&want));
    for name in [
        sar_record::convert::REPLAY_METADATA,
        sar_record::convert::CONFIG_METADATA,
    ] {
        assert_eq!(got_meta.get(name), want_meta.get(name), "{name}");
    }
    assert!(
        lean_size * 4 < full_size,
        "lean {lean_size} bytes, full {full_size}"
    );
}
