//! Criterion benchmarks of replay and of the live recorder.
//!
//! `replay/*` (throughput in cycles): a one-hour 1 kHz daemon recording
//! (3.6 M cycles of `/sar/cycle/input`, `/sar/sensor/wrench` at 500 Hz and
//! `/sar/joints`; zstd chunks; made once and kept under the target's tmp
//! dir), held in memory:
//! - `read` (the baseline): every message read (chunks decompressed and
//!   CRC-checked) and every `/sar/cycle/input` decoded, through the
//!   iterator (a copy of each message); `read_visit`: the same through
//!   `McapReader::visit` (no copy), which replay uses; `read_streamed`: the
//!   same streamed from the file record by record (`McapReader::open`,
//!   constant memory), which `sarctl replay` uses;
//! - `read_step`: that and the daemon's loop step (estimator, guard, drive
//!   decision) per cycle: what `sarctl replay` does without an output file
//!   and without comparing;
//! - `read_step_compare`: and the rebuilt `/sar/cycle/input` compared bit for
//!   bit with the recorded one;
//! - `read_step_write`: and every output topic written to a new MCAP file;
//! - `read_step_streamed`: `read_step` from the file (`replay_file`).
//!
//! `replay_lean/*` (issue 28): that recording and its lean file
//! (`[record] mode = "inputs"`) replayed in the same run, compared and
//! written ([`replay_lean_bench`]). Measured with 200 000 cycles (103.4
//! bytes a cycle full, 24.1 lean: this recording has no outputs): compared
//! as `sarctl replay` does, full 256 ms, lean 190 ms; written (`--output`),
//! full 1.13 s, lean 2.06 s (its output holds the sensor and joint
//! messages too, 1.5 a cycle more, which a full input's output leaves out).
//!
//! `SAR_BENCH_REPLAY_CYCLES` shortens the recording (default 3 600 000).
//!
//! `recorder_4khz/writer_cpu_per_s`: the recorder fed in real time at 4 kHz
//! with the daemon's messages of each cycle (about seven), for one second
//! per iteration; the time reported is the CPU time of the writer thread
//! (every thread of the process but the feeding one, from
//! `/proc/self/task/*/schedstat`) per second of recording. Drops are
//! checked to be zero.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

#[path = "../tests/common/mod.rs"]
mod common;
mod support;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sar_config as config;
use sar_daemon::sim;
use sar_hal::{DriveState, SimClock};
use sar_loop::control::{Operator, Request};
use sar_loop::logq;
use sar_loop::step::{LoopInput, LoopStep};
use sar_msgs::msgs::{CycleInput, Outgoing, RecorderDrops, RosMessage, Topic};
use sar_record::replay::{ReplayOptions, replay, replay_file};
use sar_record::{FileOptions, McapReader, Recorder, RecorderConfig, RotatingWriter};
use sar_record::{convert, lean};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const HOUR_CYCLES: u64 = 3_600_000;
const PERIOD_NS: u64 = 1_000_000;

/// Every `/sar/cycle/input` of `reader` decoded through
/// `McapReader::visit` (no copy), to the end: how many.
fn visit_cycle_inputs(reader: &mut McapReader<'_>) -> u64 {
    let mut id = None;
    let mut count = 0u64;
    let stopped = reader
        .visit::<()>(&mut |channels, m| {
            let input = *id.get_or_insert_with(|| {
                channels
                    .values()
                    .find(|c| c.topic == Topic::CycleInput.name())
                    .map(|c| c.id)
            });
            if Some(m.channel_id) == input {
                black_box(CycleInput::decode(m.data).unwrap());
                count += 1;
            }
            Ok(())
        })
        .unwrap();
    assert!(stopped.is_none());
    count
}

fn cycles() -> u64 {
    std::env::var("SAR_BENCH_REPLAY_CYCLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(HOUR_CYCLES)
}

/// splitmix64 in [-1, 1).
fn noise(seed: u64) -> f64 {
    (common::mix(seed) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// The recording: the sensor reading and pose of the simulated robot at
/// rest (from the real controller over the simulator), then `n` cycles of
/// that reading with 0.2 N / 0.002 N m of noise, a new sample every second
/// cycle, the drives enabled, decided by the loop step.
fn make_recording(path: &Path, n: u64) {
    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let clock = SimClock::new(1_000_000_000);
    let (log, _t, _q) = logq::channel(false);
    let (_sim, mut c, bias) =
        support::sim_controller(&cfg, &scenario, clock.clone(), Operator::new(), log);
    for k in 1..=100 {
        clock.advance_ns(PERIOD_NS);
        c.step(k, || Some(clock.now_ns()));
    }
    let template = *c.loop_input();
    let mut step = LoopStep::new(&cfg.estimator, bias, cfg.step_config()).unwrap();
    let mut o = FileOptions::single(path);
    o.metadata = vec![convert::replay_metadata(&bias, true)];
    let mut w = RotatingWriter::new(o).unwrap();
    let status = RecorderDrops::default();
    let t0 = 10_000_000_000u64;
    let mut last_joints = None;
    for k in 1..=n {
        let now = t0 + k * PERIOD_NS;
        let mut input: LoopInput = template;
        input.cycle = k;
        input.now_ns = Some(now);
        let sample = k / 2;
        input.sensor.counter = sample as u32;
        input.sensor.stamp_ns = t0 + sample * 2 * PERIOD_NS;
        for i in 0..3 {
            input.sensor.force_n[i] += 0.2 * noise(sample * 8 + i as u64);
            input.sensor.torque_nm[i] += 0.002 * noise(sample * 8 + 4 + i as u64);
        }
        input.joints.stamp_ns = now;
        input.drive_state = Some(if k == 1 {
            DriveState::Ready
        } else {
            DriveState::Enabled
        });
        input.request = (k == 1).then_some(Request::Reset);
        let decision = *step.step(&input);
        let mut write = |m: Outgoing| w.write(&m, &status).unwrap();
        write(Outgoing::CycleInput(convert::cycle_input_msg(
            &input, &decision,
        )));
        if decision.estimate.new_sample {
            write(Outgoing::SensorWrench(convert::sensor_wrench(
                &input.sensor,
            )));
        }
        if last_joints != Some(input.joints.stamp_ns) {
            last_joints = Some(input.joints.stamp_ns);
            write(Outgoing::Joints(convert::joints_msg(&input.joints)));
        }
    }
    w.close(&status).unwrap();
}

fn recording() -> (PathBuf, Vec<u8>, u64) {
    let n = cycles();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("sar-bench-replay");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("hour-v1-{n}.mcap"));
    if !path.exists() {
        let start = Instant::now();
        let tmp = dir.join("making.mcap");
        make_recording(&tmp, n);
        std::fs::rename(&tmp, &path).unwrap();
        eprintln!(
            "made {} ({} cycles) in {:.1} s",
            path.display(),
            n,
            start.elapsed().as_secs_f64()
        );
    }
    let bytes = std::fs::read(&path).unwrap();
    eprintln!("{}: {} MB", path.display(), bytes.len() / 1_000_000);
    (dir, bytes, n)
}

fn replay_bench(c: &mut Criterion) {
    let (dir, bytes, n) = recording();
    let cfg = config::builtin().unwrap();
    let base = ReplayOptions::from_config(&cfg);
    let mut g = c.benchmark_group("replay");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(30));
    g.throughput(Throughput::Elements(n));
    g.bench_function("read", |b| {
        b.iter(|| {
            let mut reader = McapReader::new(&bytes).unwrap();
            let mut id = None;
            let mut count = 0u64;
            while let Some(m) = reader.next() {
                let m = m.unwrap();
                let input = *id.get_or_insert_with(|| {
                    reader.channel_of(Topic::CycleInput.name()).map(|c| c.id)
                });
                if Some(m.channel_id) == input {
                    black_box(CycleInput::decode(&m.data).unwrap());
                    count += 1;
                }
            }
            assert_eq!(count, n);
        })
    });
    // Streamed from the file, record by record (constant memory: what
    // `sarctl replay` does), beside the in-memory reads above.
    let path = dir.join(format!("hour-v1-{n}.mcap"));
    g.bench_function("read_streamed", |b| {
        b.iter(|| {
            let mut reader = McapReader::open(&path).unwrap();
            assert_eq!(visit_cycle_inputs(&mut reader), n);
        })
    });
    g.bench_function("read_step_streamed", |b| {
        let o = ReplayOptions {
            check_recorded: false,
            ..base.clone()
        };
        b.iter(|| {
            let r = replay_file(&path, &o).unwrap();
            assert_eq!(r.cycles, n);
            black_box(r);
        })
    });
    g.bench_function("read_visit", |b| {
        b.iter(|| {
            let mut reader = McapReader::new(&bytes).unwrap();
            assert_eq!(visit_cycle_inputs(&mut reader), n);
        })
    });
    let run = |o: &ReplayOptions| {
        let r = replay(&bytes, o).unwrap();
        assert_eq!(r.cycles, n);
        assert_eq!(r.differences, 0);
        black_box(r);
    };
    g.bench_function("read_step", |b| {
        let o = ReplayOptions {
            check_recorded: false,
            ..base.clone()
        };
        b.iter(|| run(&o))
    });
    g.bench_function("read_step_compare", |b| {
        // The outputs are not in this recording: only /sar/cycle/input is
        // compared (the others stop being compared after MAX_PENDING).
        let o = base.clone();
        b.iter(|| {
            let r = replay(&bytes, &o).unwrap();
            assert_eq!(r.cycles, n);
            assert!(
                r.first_difference
                    .as_ref()
                    .is_none_or(|d| d.topic != "/sar/cycle/input")
            );
            black_box(r);
        })
    });
    g.bench_function("read_step_write", |b| {
        let o = ReplayOptions {
            check_recorded: false,
            output: Some(dir.join("out.mcap")),
            ..base.clone()
        };
        b.iter(|| run(&o))
    });
    g.finish();
    let _ = std::fs::remove_file(dir.join("out.mcap"));
}

/// The lean file of the same cycles (`[record] mode = "inputs"`): the
/// hour recording's messages through the lean mode's writer, as the
/// recorder's thread writes them (its metadata, marked lean).
fn lean_of(full: &[u8], path: &Path) {
    let mut probe = McapReader::new(full).unwrap();
    let _ = probe.next();
    let mut o = FileOptions::single(path);
    o.metadata = probe
        .metadata()
        .iter()
        .map(|m| {
            let mut kv = m.metadata.clone();
            kv.insert(lean::RECORD_MODE_KEY.to_owned(), "inputs".to_owned());
            (m.name.clone(), kv)
        })
        .collect();
    o.lean = true;
    let mut w = RotatingWriter::new(o).unwrap();
    let mut writer = lean::LeanWriter::new(lean::LeanScales::default());
    let status = RecorderDrops::default();
    for item in McapReader::new(full).unwrap().decoded() {
        let (_, _, m) = item.unwrap();
        writer.write(&mut w, &m, &status).unwrap();
    }
    writer.flush(&mut w, &status).unwrap();
    w.close(&status).unwrap();
}

/// `replay_lean/*` (issue 28): the same cycles replayed from the full
/// recording and from its lean file, in the same run: `*_compare` as
/// `sarctl replay` (the recorded outputs compared: the cycle inputs of the
/// full file, the guard events and snapshots of the lean one), `*_write`
/// with an output file (the lean one's output is the full file: sensor
/// and joint messages too).
fn replay_lean_bench(c: &mut Criterion) {
    let (dir, full, n) = recording();
    let lean_path = dir.join(format!("hour-v1-{n}.lean.mcap"));
    if !lean_path.exists() {
        lean_of(&full, &dir.join("making-lean.mcap"));
        std::fs::rename(dir.join("making-lean.mcap"), &lean_path).unwrap();
    }
    let lean_bytes = std::fs::read(&lean_path).unwrap();
    eprintln!(
        "{n} cycles: full {:.1} bytes a cycle, lean {:.1}",
        full.len() as f64 / n as f64,
        lean_bytes.len() as f64 / n as f64
    );
    let cfg = config::builtin().unwrap();
    let base = ReplayOptions::from_config(&cfg);
    let mut g = c.benchmark_group("replay_lean");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(30));
    g.throughput(Throughput::Elements(n));
    for (name, bytes) in [("full", &full), ("lean", &lean_bytes)] {
        g.bench_function(format!("{name}_compare"), |b| {
            b.iter(|| {
                let r = replay(bytes, &base).unwrap();
                assert_eq!(r.cycles, n);
                black_box(r);
            })
        });
        let o = ReplayOptions {
            output: Some(dir.join("out-lean.mcap")),
            ..base.clone()
        };
        g.bench_function(format!("{name}_write"), |b| {
            b.iter(|| {
                let r = replay(bytes, &o).unwrap();
                assert_eq!(r.cycles, n);
                black_box(r);
            })
        });
    }
    g.finish();
    let _ = std::fs::remove_file(dir.join("out-lean.mcap"));
}

/// CPU time of every thread of the process but the calling one, ns.
fn other_threads_cpu_ns() -> u64 {
    let me = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap();
    let mine: u64 = me.split_whitespace().next().unwrap().parse().unwrap();
    let mut all = 0u64;
    for task in std::fs::read_dir("/proc/self/task").unwrap() {
        let p = task.unwrap().path().join("schedstat");
        if let Ok(s) = std::fs::read_to_string(p) {
            all += s
                .split_whitespace()
                .next()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
        }
    }
    all.saturating_sub(mine)
}

fn recorder_4khz(c: &mut Criterion) {
    let dir = common::scratch("bench_recorder_4khz");
    // One second of a 4 kHz daemon recording, stamps made consecutive.
    let per_cycle: Vec<Vec<Outgoing>> = (0..4000).map(common::cycle_messages).collect();
    let mut g = c.benchmark_group("recorder_4khz");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(12));
    g.bench_function("writer_cpu_per_s", |b| {
        b.iter_custom(|iters| {
            let mut cpu = Duration::ZERO;
            for _ in 0..iters {
                let mut rec =
                    Recorder::start(RecorderConfig::new(FileOptions::new(&dir, "rt4k"))).unwrap();
                let before = other_threads_cpu_ns();
                let start = Instant::now();
                for (k, msgs) in per_cycle.iter().enumerate() {
                    // The cycle's deadline: k * 250 us.
                    let due = Duration::from_micros(250 * k as u64);
                    if let Some(wait) = due.checked_sub(start.elapsed()) {
                        std::thread::sleep(wait);
                    }
                    for m in msgs {
                        rec.push(*m);
                    }
                }
                let after = other_threads_cpu_ns();
                assert_eq!(rec.dropped(), 0, "the recorder dropped at 4 kHz");
                let report = rec.stop().unwrap();
                assert_eq!(report.dropped, 0);
                cpu += Duration::from_nanos(after - before);
            }
            cpu
        })
    });
    g.finish();
}

criterion_group!(benches, replay_bench, replay_lean_bench, recorder_4khz);
criterion_main!(benches);
