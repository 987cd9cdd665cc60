//! Criterion benchmarks of the recording: the cost of a push on the loop's
//! side (accepted, and dropped on a full queue), and the writer's throughput
//! on a 4 kHz daemon recording (CycleInput and the outputs of each cycle,
//! about seven messages a cycle) with zstd chunks, beside two baselines:
//! encoding alone, and writing uncompressed chunks; and with zstd and the 3D
//! scene at 30 Hz (`/sar/scene`, `/tf`, `/tf_static` drawn on the writer's
//! thread), the cost of the scene beside the zstd run.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use sar_msgs::msgs::{Outgoing, RecorderDrops};
use sar_record::{FileOptions, Recorder, RecorderConfig, RotatingWriter};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// One second of a 4 kHz recording.
const CYCLES: u64 = 4000;

fn messages() -> Vec<Outgoing> {
    (0..CYCLES).flat_map(common::cycle_messages).collect()
}

fn push(c: &mut Criterion) {
    let dir = common::scratch("bench_push");
    let msgs = messages();
    let mut g = c.benchmark_group("push");
    g.throughput(Throughput::Elements(1));
    // Accepted: bursts of 4096 pushes into a running recorder's warm queue
    // (65536 slots), timed; between bursts, untimed, the writer drains it.
    let mut config = RecorderConfig::new(FileOptions::new(&dir, "push"));
    config.queue_capacity = 1 << 16;
    let capacity = config.queue_capacity;
    let mut rec = Recorder::start(config).unwrap();
    let mut i = 0usize;
    g.bench_function("accepted", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            let mut left = iters;
            while left > 0 {
                let n = left.min(4096);
                let start = Instant::now();
                for _ in 0..n {
                    i = (i + 1) % msgs.len();
                    black_box(rec.push(msgs[i]));
                }
                total += start.elapsed();
                while rec.free_slots() < capacity {
                    std::thread::yield_now();
                }
                left -= n;
            }
            total
        })
    });
    assert_eq!(rec.dropped(), 0);
    drop(rec.stop().unwrap());
    // Dropped: the queue full.
    let mut config = RecorderConfig::new(FileOptions::new(&dir, "drop"));
    config.queue_capacity = 16;
    let mut rec = Recorder::new_paused(config).unwrap();
    for m in &msgs[..16] {
        rec.push(*m);
    }
    let mut i = 0usize;
    g.bench_function("dropped", |b| {
        b.iter(|| {
            i = (i + 1) % msgs.len();
            black_box(rec.push(msgs[i]))
        })
    });
    g.finish();
    drop(rec.stop().unwrap());
}

fn writer(c: &mut Criterion) {
    let dir = common::scratch("bench_writer");
    let msgs = messages();
    let status = RecorderDrops::default();
    let mut g = c.benchmark_group("writer_1s_of_4kHz");
    g.throughput(Throughput::Elements(msgs.len() as u64));
    g.sample_size(10);
    g.bench_function("encode_only", |b| {
        let mut buf = Vec::with_capacity(1024);
        b.iter(|| {
            for m in &msgs {
                m.encode(&mut buf).unwrap();
                black_box(&buf);
            }
        })
    });
    let cfg = sar_config::builtin().unwrap();
    let scene = sar_record::SceneOptions::from_config(&cfg);
    assert!(
        scene.is_some(),
        "the built-in configuration draws the scene"
    );
    for (name, compress, scene) in [
        ("uncompressed", false, None),
        ("zstd", true, None),
        ("zstd_scene_30Hz", true, scene),
    ] {
        g.bench_function(name, |b| {
            b.iter_batched(
                || {
                    let mut o = FileOptions::new(&dir, name);
                    o.compress = compress;
                    o.scene = scene;
                    RotatingWriter::new(o).unwrap()
                },
                |mut w| {
                    for m in &msgs {
                        w.write(m, &status).unwrap();
                    }
                    w.close(&status).unwrap();
                    w
                },
                BatchSize::PerIteration,
            )
        });
    }
    g.finish();
    for name in ["uncompressed", "zstd", "zstd_scene_30Hz"] {
        let path = FileOptions::new(&dir, name).path(0);
        let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        println!(
            "{name}: {len} bytes for 1 s of 4 kHz ({} messages): {:.1} MB/h",
            msgs.len(),
            len as f64 * 3600.0 / 1e6
        );
    }
}

criterion_group!(benches, push, writer);
criterion_main!(benches);
