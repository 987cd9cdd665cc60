//! Recordings that start mid-run and rotate (issue 17): a recording started
//! after the daemon has tared, had its limits changed, stopped on a contact
//! and been reset, rotated into several files, replays bit for bit from the
//! snapshot each file starts with: every file alone, and the set as one
//! (whose files must chain). A corrupted snapshot is refused with a clear
//! error, never trusted.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config as config;
use sar_config::{RecordSettings, Rotation};
use sar_estimator::Vec3;
use sar_estimator::guard::{ForceLimits, GuardState};
use sar_loop::control::{Controller, Envelope, Request};
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_loop::stats::LoopStats;
use sar_msgs::msgs::{RosMessage, StateSnapshot, Topic};
use sar_record::live::{RecordManager, RecordSwitch};
use sar_record::replay::{ReplayError, ReplayOptions, replay_file, replay_files};
use sar_record::{McapReader, read_file};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Records a session on the simulator: 4.5 s before the recording starts
/// (first reset, tare, lower limits, a contact that stops the guard, a
/// reset), then about 3.6 s recorded with 1 s files and a snapshot every
/// 250 ms (moves, a push). Returns the files in order.
fn session(name: &str) -> Vec<PathBuf> {
    let dir = sar_test_support::scratch!(name);
    // 20 N along the rod from 2 s (rising), held 2.7-3.2 s, off at 3.5 s.
    let SimRig {
        mut c,
        clock,
        operator,
        queue,
        bias,
        cfg,
        ..
    } = RigBuilder::demo(rod_push_20n([
        2_000_000_000,
        2_700_000_000,
        3_200_000_000,
        3_500_000_000,
    ]))
    .build();
    let switch = Arc::new(RecordSwitch::default());
    let (manager, mut publisher) = RecordManager::start(
        RecordSettings {
            enabled: false,
            directory: dir.clone(),
            rotation: Rotation {
                max_bytes: None,
                max_duration_ns: Some(1_000_000_000),
            },
            queue_capacity: 65536,
            scene_period_ns: None,
            snapshot_period_ns: 250_000_000,
            config_source: None,
            mode: sar_config::RecordMode::Full,
            scales: sar_config::DeviceScales::default(),
        },
        None,
        bias,
        Arc::clone(&switch),
    )
    .unwrap();
    let stats = LoopStats::default();
    let mut cycle = 0u64;
    let mut states = Vec::new();
    let mut step = |c: &mut Controller<_, _>, p: &mut dyn Sink, request: Option<Request>| {
        cycle += 1;
        clock.advance_ns(1_000_000);
        if let Some(request) = request {
            let env = Envelope { id: cycle, request };
            operator.requests.push(env).unwrap();
        }
        p.before_cycle();
        let out = *c.step(cycle, || Some(clock.now_ns()));
        p.cycle(&Cycle::of(c, &stats, None), &mut SinkHealth::default());
        while queue.pop().is_some() {}
        while operator.replies.pop().is_some() {}
        out.guard_state
    };
    let configured = cfg.estimator.guard.force_limits();
    let lower = ForceLimits {
        warn_total_n: configured.warn_total_n - 0.5,
        stop_total_n: configured.stop_total_n - 0.5,
        warn_lateral_n: configured.warn_lateral_n - 0.2,
        ..configured
    };
    for k in 1..=4500u64 {
        let request = match k {
            1100 | 4000 => Some(Request::Reset),
            1300 => Some(Request::Tare),
            1500 => Some(Request::SetLimits(lower)),
            _ => None,
        };
        states.push(step(&mut c, &mut publisher, request));
    }
    assert!(
        states.contains(&GuardState::Stop),
        "the contact never stopped"
    );
    assert!(
        states.last().is_some_and(|s| !s.is_halting()),
        "not reset after the Stop: {:?}",
        states.last()
    );
    // Start recording; the manager thread opens it (bounded wait).
    switch.request_start();
    let mut waited = 0;
    while !switch.recording() {
        step(&mut c, &mut publisher, None);
        std::thread::sleep(std::time::Duration::from_millis(1));
        waited += 1;
        assert!(waited < 10_000, "the recording never started");
    }
    for k in 0..3600u64 {
        let request = match k {
            200 => Some(Request::MoveTip {
                tip_m: Vec3::new(0.6, 0.2, 0.002),
            }),
            1400 => Some(Request::Push { axial_n: 1.0 }),
            2600 => Some(Request::Position),
            3000 => Some(Request::Tare),
            _ => None,
        };
        step(&mut c, &mut publisher, request);
    }
    switch.request_stop();
    step(&mut c, &mut publisher, None);
    assert!(!switch.recording());
    assert_eq!(switch.dropped(), 0);
    publisher.release();
    manager.finish();
    sar_test_support::files::recordings(&dir)
}

/// The `/sar/cycle/snapshot` messages of a file (after_cycle), and the cycle
/// of its first `/sar/cycle/input`.
fn snapshots(path: &Path) -> (Vec<u64>, Option<u64>) {
    let bytes = read_file(path).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut out = Vec::new();
    let mut first_cycle = None;
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        let topic = reader.channels()[&m.channel_id].topic.clone();
        if topic == Topic::StateSnapshot.name() {
            out.push(StateSnapshot::decode(&m.data).unwrap().after_cycle);
        } else if topic == Topic::CycleInput.name() && first_cycle.is_none() {
            let c = sar_msgs::msgs::CycleInput::decode(&m.data).unwrap();
            first_cycle = Some(c.cycle);
        }
    }
    (out, first_cycle)
}

#[test]
fn a_rotated_recording_started_mid_run_replays_bit_for_bit_file_by_file_and_as_a_set() {
    let files = session("snapshot_recording");
    assert!(files.len() >= 3, "{files:?}");
    let cfg = config::builtin().unwrap();
    let options = ReplayOptions::from_config(&cfg);
    let mut total = 0;
    for (i, f) in files.iter().enumerate() {
        let (snaps, first_cycle) = snapshots(f);
        // Every rotated file starts with a snapshot (the first file starts
        // with the cycle the recording began in, then its snapshot).
        assert!(!snaps.is_empty(), "{f:?}");
        if i > 0 {
            assert_eq!(Some(snaps[0] + 1), first_cycle, "{f:?}");
        }
        let r = replay_file(f, &options).unwrap();
        println!(
            "{}: {} cycles from the snapshot after cycle {:?} ({} skipped), {} outputs and {} snapshots compared",
            f.display(),
            r.cycles,
            r.from_snapshot,
            r.skipped_cycles,
            r.outputs,
            r.snapshots_compared
        );
        assert_eq!(r.first_difference, None, "{f:?}");
        assert_eq!(r.from_first_cycle, Some(false), "{f:?}");
        assert_eq!(r.from_snapshot, Some(snaps[0]), "{f:?}");
        assert_eq!(r.skipped_cycles, u64::from(i == 0), "{f:?}");
        assert!(r.cycles > 200, "{f:?}: {}", r.cycles);
        assert_eq!(r.snapshots_compared, snaps.len() as u64 - 1, "{f:?}");
        assert_eq!(r.compared, r.outputs + r.snapshots_compared, "{f:?}");
        total += r.cycles;
    }
    // The set as one: the state carried across files, each file's first
    // snapshot compared with it.
    let r = replay_files(&files, &options).unwrap();
    assert_eq!(r.first_difference, None);
    assert_eq!(r.cycles, total);
    assert_eq!(
        r.snapshots_compared as usize,
        files.iter().map(|f| snapshots(f).0.len()).sum::<usize>() - 1
    );
    // A time range across a rotation: from the snapshot before it, only
    // the cycles in it compared.
    let range = ReplayOptions {
        from_s: Some(1.6),
        to_s: Some(2.4),
        ..options.clone()
    };
    let r = replay_files(&files, &range).unwrap();
    assert_eq!(r.first_difference, None);
    assert_eq!(r.cycles, 801);
    assert!(r.compared >= 801 * 5, "{}", r.compared);
    let backwards = ReplayOptions {
        from_s: Some(2.0),
        to_s: Some(1.0),
        ..options.clone()
    };
    assert!(matches!(
        replay_files(&files, &backwards).unwrap_err(),
        ReplayError::Range(_)
    ));
    // Files that do not chain are refused, naming the file.
    let gap = [files[0].clone(), files[2].clone()];
    let e = replay_files(&gap, &options).unwrap_err();
    assert!(matches!(e, ReplayError::Chain { .. }), "{e}");
    assert!(e.to_string().contains(&*files[2].to_string_lossy()), "{e}");
    let backwards = [files[1].clone(), files[0].clone()];
    assert!(matches!(
        replay_files(&backwards, &options).unwrap_err(),
        ReplayError::Chain { .. }
    ));
    // A corrupt chunk in a file (issue 25): passed over and reported, the
    // replay goes on from the next snapshot, bit for bit; every cycle of
    // the file is replayed, lost in the chunk, or waiting for the snapshot.
    let whole = replay_file(&files[1], &options).unwrap();
    let mut bytes = read_file(&files[1]).unwrap();
    let (mut pos, mut chunks) = (8usize, Vec::new());
    while pos + 9 <= bytes.len() && bytes[pos] != 0x0F {
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        if bytes[pos] == 0x06 {
            chunks.push((pos, len + 9));
        }
        pos += 9 + len;
    }
    assert!(chunks.len() >= 3, "{chunks:?}");
    // A chunk in the first half: a snapshot follows it in the file.
    let (at, len) = chunks[chunks.len() / 3];
    for b in &mut bytes[at + len / 2..at + len / 2 + 8] {
        *b ^= 0xa5;
    }
    let corrupt = files[1].with_extension("corrupt.mcap");
    std::fs::write(&corrupt, &bytes).unwrap();
    let r = replay_file(&corrupt, &options).unwrap();
    assert_eq!(r.first_difference, None);
    assert_eq!(r.gaps.len(), 1, "{:?}", r.gaps);
    let g = &r.gaps[0];
    assert_eq!((g.skipped.offset, g.skipped.bytes), (at as u64, len as u64));
    assert!(g.resumed_after_cycle.is_some(), "{g:?}");
    assert!(
        g.cycles_lost().is_some_and(|n| n > 0) && g.cycles_not_replayed > 0,
        "{g:?}"
    );
    assert_eq!(
        r.cycles + g.cycles_lost().unwrap() + g.cycles_not_replayed,
        whole.cycles,
        "{g:?}"
    );
    assert!(r.snapshots_compared >= 1);
    // Recovered (the chunks after it kept), it replays the same: the cycles
    // missing are a gap, replay goes on from the next snapshot.
    let recovered = files[1].with_extension("recovered.mcap");
    let rec = sar_record::recover(&corrupt, &recovered).unwrap();
    assert_eq!(
        (rec.skipped.parts, rec.skipped.shown.len()),
        (1, 1),
        "{rec:?}"
    );
    let r2 = replay_file(&recovered, &options).unwrap();
    assert_eq!(r2.first_difference, None);
    assert_eq!(r2.gaps.len(), 1, "{:?}", r2.gaps);
    assert_eq!(r2.gaps[0].resumed_after_cycle, g.resumed_after_cycle);
    assert_eq!(r2.gaps[0].cycles_lost(), g.cycles_lost());
    assert_eq!(r2.cycles, r.cycles);
}

/// Copies `input` to `output` with `change` applied to every snapshot's
/// bytes (the other messages as they are).
fn rewrite_snapshots(input: &Path, output: &Path, mut change: impl FnMut(&mut Vec<u8>)) {
    let bytes = read_file(input).unwrap();
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(output).unwrap(),
    ))
    .unwrap();
    // The metadata replay needs, first (as the recorder writes it).
    let mut reader = McapReader::new(&bytes).unwrap();
    let _ = reader.next();
    for meta in reader.metadata() {
        w.write_metadata(&mcap::records::Metadata {
            name: meta.name.clone(),
            metadata: meta.metadata.clone(),
        })
        .unwrap();
    }
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let mut data = m.data.to_vec();
        if m.channel.topic == Topic::StateSnapshot.name() {
            let mut s = StateSnapshot::decode(&data).unwrap();
            change(&mut s.data);
            s.encode(&mut data).unwrap();
        }
        w.write(&mcap::Message {
            data: std::borrow::Cow::Owned(data),
            ..m
        })
        .unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_corrupted_snapshot_is_refused_with_a_clear_error() {
    let files = session("snapshot_corrupted");
    let cfg = config::builtin().unwrap();
    let options = ReplayOptions::from_config(&cfg);
    let bad = files[1].with_extension("bad.mcap");
    // One bit of the first snapshot's state flipped (its CRC then fails).
    let mut first = true;
    rewrite_snapshots(&files[1], &bad, |data| {
        if std::mem::take(&mut first) {
            data[40] ^= 0x10;
        }
    });
    let e = replay_file(&bad, &options).unwrap_err();
    let text = e.to_string();
    println!("{text}");
    assert!(matches!(e, ReplayError::Snapshot { .. }), "{text}");
    assert!(
        text.contains("checksum") && text.contains("after cycle"),
        "{text}"
    );
    // The same file untouched (rewritten without change) replays.
    let good = files[1].with_extension("good.mcap");
    rewrite_snapshots(&files[1], &good, |_| {});
    assert_eq!(replay_file(&good, &options).unwrap().first_difference, None);
    // Under another configuration the snapshot is refused too.
    let mut other = cfg.clone();
    other.axes.following_tolerance_m *= 2.0;
    let e = replay_file(&good, &ReplayOptions::from_config(&other)).unwrap_err();
    assert!(e.to_string().contains("another configuration"), "{e}");
}
