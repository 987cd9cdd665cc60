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
/// snapshot every 250 ms and the 3D scene at 30 Hz.
fn recording(
    dir: &Path,
    mode: RecordMode,
    scales: config::DeviceScales,
    bias: sar_estimator::cycle::Bias,
) -> (RecordManager, LiveRecorder, Arc<RecordSwitch>) {
    let switch = Arc::new(RecordSwitch::default());
    let (manager, sink) = RecordManager::start(
        RecordSettings {
            enabled: true,
            directory: dir.to_path_buf(),
            rotation: Rotation::default(),
            queue_capacity: 1 << 20,
            scene_period_ns: Some(33_333_333),
            snapshot_period_ns: 250_000_000,
            config_source: Some(Arc::new(config::ConfigSource {
                origin: "the built-in configuration".into(),
                toml: config::DEFAULT_TOML.into(),
            })),
            mode,
            scales,
        },
        // The 3D scene as `sard` writes it (the lean mode writes none; its
        // replay draws it into the full file).
        sar_record::SceneOptions::from_config(&config::builtin().unwrap()),
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
    // The devices' scales as `sard --sim` gives them: the demo reports
    // counts (its sensor the HEX-E's, its encoders the axes').
    let (force_counts_per_n, torque_counts_per_nm) = sim.sensor_counts().unwrap();
    assert!(force_counts_per_n > 0.0 && torque_counts_per_nm > 0.0);
    let scales = config::DeviceScales {
        force_counts_per_n,
        torque_counts_per_nm,
        joint_m_per_count: sim.encoder_m_per_count().unwrap(),
    };
    let (full_mgr, mut full, full_switch) = recording(&full_dir, RecordMode::Full, scales, bias);
    let (lean_mgr, mut lean, lean_switch) = recording(&lean_dir, RecordMode::Inputs, scales, bias);
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

/// splitmix64.
fn mix(x: &mut u64) -> u64 {
    *x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *x;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce5_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Cycles whose every input field is drawn (seeded) from what the devices
/// give (counts of the RDT's and the encoders' scales, repeats) and what
/// they should never give (any f64 bits: NaN, -0.0, infinities; stamps,
/// counters and idle times anywhere in their range, wrapping), with
/// commands, extra sensor messages and joint messages: the lean writer's
/// batches give every one back bit for bit (`unbatch`), in batches of at
/// most 100 cycles, with the guard events after their batch.
#[test]
fn batches_give_back_every_input_bit_for_bit() {
    use sar_msgs::msgs::{
        ClockStatusCode, CommandKindCode, CycleBatch, CycleInput, DriveStateCode, GuardEvent,
        Outgoing, WrenchStamped,
    };
    use sar_record::lean::{LeanScales, LeanWriter, unbatch};
    let dir = sar_test_support::scratch!("lean_batches");
    let scales = LeanScales {
        force_counts_per_n: 10_000.0,
        torque_counts_per_nm: 100_000.0,
        joint_m_per_count: 0.01 / 4096.0,
    };
    let mut seed = 28u64;
    let mut want: Vec<(CycleInput, Vec<WrenchStamped>, bool)> = Vec::new();
    let mut prev = CycleInput::default();
    for k in 0..2500u64 {
        let r = &mut seed;
        let any = |r: &mut u64| f64::from_bits(mix(r));
        let mut m = prev;
        m.cycle = if mix(r).is_multiple_of(50) {
            mix(r)
        } else {
            prev.cycle + 1
        };
        m.now_ns = prev.now_ns.wrapping_add(1_000_000 + mix(r) % 50_000);
        if mix(r).is_multiple_of(300) {
            // Anywhere a header stamp can say (< 2^31 s).
            m.now_ns = mix(r) % (i32::MAX as u64 * 1_000_000_000);
        }
        m.clock_status = [ClockStatusCode::Ok, ClockStatusCode::ReadFailed]
            [usize::from(mix(r).is_multiple_of(97))];
        m.publisher_idle_ns = match mix(r) % 10 {
            0 => 0,
            1 => mix(r),
            _ => prev
                .publisher_idle_ns
                .wrapping_add(m.now_ns.wrapping_sub(prev.now_ns)),
        };
        if mix(r).is_multiple_of(2) {
            m.sensor_counter = prev.sensor_counter.wrapping_add(1);
            m.sensor_stamp_ns = m.now_ns.wrapping_sub(mix(r) % 100_000);
            for (i, v) in m
                .sensor_force_n
                .iter_mut()
                .chain(m.sensor_torque_nm.iter_mut())
                .enumerate()
            {
                let per = if i < 3 { 10_000.0 } else { 100_000.0 };
                *v = match mix(r) % 40 {
                    0 => any(r),
                    1 => -0.0,
                    2 => f64::NAN,
                    _ => f64::from((mix(r) % 400_000) as i32 - 200_000) / per,
                };
            }
        }
        m.sensor_status = if mix(r).is_multiple_of(200) {
            mix(r) as u32
        } else {
            0
        };
        m.sensor_valid = !mix(r).is_multiple_of(100);
        if mix(r).is_multiple_of(3) {
            m.joints_stamp_ns = m.now_ns;
            for q in &mut m.joints_q_m {
                *q = match mix(r) % 30 {
                    0 => any(r),
                    _ => f64::from((mix(r) % 100_000) as i32) * (0.01 / 4096.0),
                };
            }
        }
        m.joints_valid = !mix(r).is_multiple_of(100);
        m.drive_state = DriveStateCode::from_code((mix(r) % 5) as u8).unwrap();
        m.drive_fault_axis = (mix(r) % 4) as i8 - 1;
        m.drive_fault_code = (mix(r) % 3) as u16;
        m.command_kind = CommandKindCode::None;
        m.command_values = [0.0; 6];
        m.move_tip_m = [0.0; 3];
        m.back_out_m = 0.0;
        if mix(r).is_multiple_of(40) {
            m.command_kind = CommandKindCode::MoveTip;
            m.move_tip_m = [any(r), 0.2, -0.0];
            m.back_out_m = any(r);
        }
        m.stamp_ns =
            sar_record::convert::cycle_stamp_ns(&sar_record::convert::loop_input(&m).cycle_input());
        // The sensor's messages: extras before the cycle's own sample.
        let mut sensors = Vec::new();
        for _ in 0..mix(r) % 3 {
            sensors.push(WrenchStamped::sensor(
                mix(r),
                [any(r), 1.0, 2.0],
                [3.0, any(r), 4.0],
            ));
        }
        if mix(r).is_multiple_of(2) {
            sensors.push(WrenchStamped::sensor(
                m.sensor_stamp_ns,
                m.sensor_force_n,
                m.sensor_torque_nm,
            ));
        }
        let joints = mix(r).is_multiple_of(2);
        want.push((m, sensors, joints));
        prev = m;
        let _ = k;
    }
    let path = dir.join("batches.mcap");
    let mut options = sar_record::FileOptions::single(&path);
    // Small chunks: a cut file keeps most of them.
    options.chunk_size_bytes = 8 * 1024;
    options.lean = true;
    let mut files = sar_record::RotatingWriter::new(options).unwrap();
    let mut writer = LeanWriter::new(scales);
    let status = RecorderDrops::default();
    for (k, (m, sensors, joints)) in want.iter().enumerate() {
        writer
            .write(&mut files, &Outgoing::CycleInput(*m), &status)
            .unwrap();
        for w in sensors {
            writer
                .write(&mut files, &Outgoing::SensorWrench(*w), &status)
                .unwrap();
        }
        if *joints {
            let j = sar_record::lean::joints_msg_of(m);
            writer
                .write(&mut files, &Outgoing::Joints(j), &status)
                .unwrap();
        }
        if k.is_multiple_of(700) {
            let e = GuardEvent {
                stamp_ns: m.stamp_ns,
                cycle: m.cycle,
                ..GuardEvent::default()
            };
            writer
                .write(&mut files, &Outgoing::GuardEvent(e), &status)
                .unwrap();
        }
    }
    // A cycle whose stamp the format cannot say is refused (the recorder
    // drops and counts it), not the batch it would have gone into.
    let mut late = want[0].0;
    late.now_ns = u64::MAX - 5;
    late.stamp_ns = late.now_ns;
    assert!(
        writer
            .write(&mut files, &Outgoing::CycleInput(late), &status)
            .is_err()
    );
    writer.flush(&mut files, &status).unwrap();
    files.close(&status).unwrap();
    let bytes = read_file(&path).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut got = Vec::new();
    let mut order = Vec::new();
    while let Some(msg) = reader.next() {
        let msg = msg.unwrap();
        let topic = reader.channels()[&msg.channel_id].topic.clone();
        order.push(topic.clone());
        if topic == Topic::CycleBatch.name() {
            let b = CycleBatch::decode(&msg.data).unwrap();
            assert!(b.flags.len() <= 100);
            got.extend(unbatch(&b).unwrap());
        }
    }
    assert_eq!(got.len(), want.len());
    for (k, (g, (m, sensors, joints))) in got.iter().zip(&want).enumerate() {
        // Every input field (the decision's are the replay's): the message
        // rebuilt by `convert::loop_input` must be the same.
        let (a, b) = (
            sar_record::convert::loop_input(&g.input),
            sar_record::convert::loop_input(m),
        );
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "cycle {k}");
        for (x, y) in g
            .input
            .sensor_force_n
            .iter()
            .chain(&g.input.sensor_torque_nm)
            .zip(m.sensor_force_n.iter().chain(&m.sensor_torque_nm))
        {
            assert_eq!(x.to_bits(), y.to_bits(), "cycle {k}");
        }
        for (x, y) in g.input.joints_q_m.iter().zip(&m.joints_q_m) {
            assert_eq!(x.to_bits(), y.to_bits(), "cycle {k}");
        }
        assert_eq!(g.input.stamp_ns, m.stamp_ns, "cycle {k}");
        assert_eq!(g.sensors.len(), sensors.len(), "cycle {k}");
        for (x, y) in g.sensors.iter().zip(sensors) {
            assert_eq!(x.stamp_ns, y.stamp_ns);
            for (a, b) in x
                .force_n
                .iter()
                .chain(&x.torque_nm)
                .zip(y.force_n.iter().chain(&y.torque_nm))
            {
                assert_eq!(a.to_bits(), b.to_bits(), "cycle {k}");
            }
        }
        assert_eq!(g.joints_message, *joints, "cycle {k}");
    }
    // Each guard event after the batch of its cycle.
    let first_event = order
        .iter()
        .position(|t| t == Topic::GuardEvents.name())
        .unwrap();
    assert_eq!(order[first_event - 1], Topic::CycleBatch.name());
    // A file cut short recovers (`sarctl recover`) to every whole batch
    // of its whole chunks: the cycles up to one of them, all of them.
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 5]).unwrap();
    let recovered = dir.join("recovered.mcap");
    let report = sar_record::recover(&cut, &recovered).unwrap();
    assert!(!report.input_complete);
    let bytes = read_file(&recovered).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut cycles = Vec::new();
    while let Some(msg) = reader.next() {
        let msg = msg.unwrap();
        if reader.channels()[&msg.channel_id].topic == Topic::CycleBatch.name() {
            let b = CycleBatch::decode(&msg.data).unwrap();
            cycles.extend(unbatch(&b).unwrap());
        }
    }
    assert!(
        cycles.len() > want.len() / 3 && cycles.len() < want.len(),
        "{} of {} cycles",
        cycles.len(),
        want.len()
    );
    // (Debug: NaN != NaN; their bits were compared above.)
    assert_eq!(
        format!("{:?}", &cycles[..]),
        format!("{:?}", &got[..cycles.len()])
    );
}

/// Issue 35, finding 12: a lean batch whose cycle number goes back (a
/// difference below cycle 0: 1, then 1 - 2 wrapping to 2^64 - 1) is named
/// as a cycle that goes back; it used to read "cycles 2..=
/// 18446744073709551614 are missing". A cycle that goes back is a gap (the
/// state after it is unknown until a snapshot), never stepped.
#[test]
fn a_lean_cycle_that_goes_back_is_named_as_such() {
    use sar_msgs::msgs::{CycleBatch, batch_flags};
    let dir = sar_test_support::scratch!("lean_cycle_back");
    let raw = batch_flags::SENSOR_RAW | batch_flags::JOINTS_RAW | batch_flags::SENSOR_VALID;
    let batch = CycleBatch {
        stamp_ns: 1_001_000_000,
        flags: vec![raw | batch_flags::JOINTS_VALID; 2],
        cycle: vec![1, -2],
        now_ns: vec![1_001_000_000, 1_000_000],
        clock_status: vec![0, 0],
        publisher_idle_ns: vec![0, 0],
        sensor_counter: vec![1, 1],
        sensor_status: vec![0, 0],
        sensor_stamp_ns: vec![1_000_900_000, 1_000_000],
        sensor_counts: vec![0; 12],
        sensor_raw: [0.1, 0.2, -20.0, 0.01, 0.02, 0.0].repeat(2),
        joints_stamp_ns: vec![1_000_950_000, 1_000_000],
        joint_counts: vec![0; 6],
        joints_raw: [0.0, 0.28, 0.25].repeat(2),
        drive_state: vec![0, 0],
        drive_fault_axis: vec![-1, -1],
        drive_fault_code: vec![0, 0],
        ..CycleBatch::default()
    };
    let cycles = sar_record::lean::unbatch(&batch).unwrap();
    assert_eq!(
        cycles.iter().map(|c| c.input.cycle).collect::<Vec<_>>(),
        [1, u64::MAX]
    );
    let path = dir.join("back.mcap");
    let mut o = sar_record::FileOptions::single(&path);
    o.lean = true;
    let (name, mut metadata) = sar_record::convert::replay_metadata(
        &sar_estimator::cycle::Bias::force_only(Vec3::zeros()),
        true,
    );
    metadata.insert(
        sar_record::lean::RECORD_MODE_KEY.to_owned(),
        "inputs".to_owned(),
    );
    o.metadata = vec![(name, metadata)];
    let mut w = sar_record::RotatingWriter::new(o).unwrap();
    w.write_batch(&batch, &RecorderDrops::default()).unwrap();
    w.close(&RecorderDrops::default()).unwrap();
    let cfg = config::builtin().unwrap();
    let r = replay_file(&path, &ReplayOptions::from_config(&cfg)).unwrap();
    assert_eq!(r.cycles, 1, "the cycle that goes back is not stepped");
    let why = &r.gaps.first().expect("a gap").skipped.why;
    assert!(
        why.contains("cycle 18446744073709551615 follows cycle 1")
            && why.contains("go back by 2 below cycle 0")
            && !why.contains("missing"),
        "{why}"
    );
}

/// Issue 36: a lean file nests whole cycle inputs, so one of another
/// layout (an older `sard`'s, before the fields it lacks were added) cannot
/// be cut into cycles without misreading them. The replay refuses it by
/// name, from the file's own schema, instead of misreading it; the same
/// file with this version's schema replays.
#[test]
fn a_lean_recording_of_another_layout_is_refused_by_name() {
    let (_, lean) = run_both("lean_other_layout");
    let cfg = config::builtin().unwrap();
    let older = lean.with_file_name("older-layout.mcap");
    let bytes = read_file(&lean).unwrap();
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(&older).unwrap(),
    ))
    .unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let _ = reader.next();
    for meta in reader.metadata() {
        w.write_metadata(&mcap::records::Metadata {
            name: meta.name.clone(),
            metadata: meta.metadata.clone(),
        })
        .unwrap();
    }
    // The batch's schema as an older sard wrote it: without issue 36's
    // fields.
    let mut batch_channel = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let channel = if m.channel.topic == Topic::CycleBatch.name() {
            batch_channel
                .get_or_insert_with(|| {
                    let mut c = (*m.channel).clone();
                    let mut s = (**c.schema.as_ref().unwrap()).clone();
                    let text = String::from_utf8(s.data.to_vec()).unwrap();
                    assert!(text.contains("command_layout"), "{text}");
                    let kept: Vec<&str> = text
                        .lines()
                        .filter(|l| !l.contains("command_layout") && !l.contains("excite_"))
                        .collect();
                    s.data = std::borrow::Cow::Owned(kept.join("\n").into_bytes());
                    c.schema = Some(std::sync::Arc::new(s));
                    std::sync::Arc::new(c)
                })
                .clone()
        } else {
            m.channel.clone()
        };
        w.write(&mcap::Message { channel, ..m }).unwrap();
    }
    w.finish().unwrap();
    let e = replay_file(&older, &ReplayOptions::from_config(&cfg)).unwrap_err();
    assert!(
        matches!(e, sar_record::replay::ReplayError::OtherLeanLayout { .. }),
        "{e}"
    );
    assert!(e.to_string().contains("another version of sard"), "{e}");
    let r = replay_file(&lean, &ReplayOptions::from_config(&cfg)).unwrap();
    assert_eq!(r.first_difference, None);
}
