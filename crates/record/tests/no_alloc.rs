//! Recording on: the loop's side of the recorder (`record::live::LiveRecorder`,
//! the conversion of a cycle into its messages and the queue push) allocates
//! nothing on the loop's thread, through a Warn, a Stop with its quick stop
//! and operator requests; the writer thread (which may allocate) is not
//! counted. The file it writes replays bit for bit, guard transitions
//! included. A push onto the recorder's queue does not allocate, accepted or
//! dropped (counted on the pushing thread alone: the writer thread allocates
//! as it likes; the loop's thread must not).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config::{RecordSettings, Rotation};
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_loop::control::{Controller, Envelope, Request};
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_loop::stats::LoopStats;
use sar_msgs::msgs::Outgoing;
use sar_record::live::{RecordManager, RecordSwitch};
use sar_record::replay::{Mode, ReplayOptions, replay_file};
use sar_record::{FileOptions, McapReader, Recorder, RecorderConfig, read_file};
use sar_test_support::counting::{Counting, allocations, counted, thread_allocations};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};
use std::sync::Arc;

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn recording_allocates_nothing_on_the_loop_and_replays_bit_for_bit() {
    let dir = sar_test_support::scratch!("no_alloc_record");
    // 20 N along the rod from 1.5 s to 3 s: Warn, then Stop.
    let SimRig {
        mut c,
        clock,
        operator,
        queue,
        bias,
        cfg,
        ..
    } = RigBuilder::demo(rod_push_20n([
        500_000_000,
        2_500_000_000,
        3_000_000_000,
        3_500_000_000,
    ]))
    .build();
    let switch = Arc::new(RecordSwitch::default());
    let (manager, mut publisher) = RecordManager::start(
        RecordSettings {
            enabled: true,
            directory: dir.clone(),
            rotation: Rotation::default(),
            // 4500 cycles of at most 8 messages: never full, whatever the
            // writer's speed.
            queue_capacity: 65536,
            scene_period_ns: None,
            // A snapshot every 100 ms: the loop takes and pushes 45.
            snapshot_period_ns: 100_000_000,
            config_source: None,
        },
        None,
        bias,
        Arc::clone(&switch),
    )
    .unwrap();
    let stats = LoopStats::default();
    let mut cycle = 0u64;
    let mut seen = (false, false);
    // The loop's one health, kept across cycles as `runloop::run` keeps it.
    let mut health = SinkHealth {
        recorder_drops: u64::MAX,
        ..SinkHealth::default()
    };
    let mut step = |c: &mut Controller<_, _>, p: &mut dyn Sink| {
        cycle += 1;
        clock.advance_ns(1_000_000);
        if cycle % 1000 == 10 {
            let request = match (cycle / 1000) % 3 {
                0 => Request::Reset,
                1 => Request::Tare,
                _ => Request::MoveTip {
                    tip_m: Vec3::new(0.6, 0.2, 0.001),
                },
            };
            operator
                .requests
                .push(Envelope { id: cycle, request })
                .unwrap();
        }
        p.before_cycle();
        let out = *c.step(cycle, || Some(clock.now_ns()));
        p.cycle(&Cycle::of(c, &stats, None), &mut health);
        while queue.pop().is_some() {}
        while operator.replies.pop().is_some() {}
        seen.0 |= out.guard_state == GuardState::Warn;
        seen.1 |= out.guard_state == GuardState::Stop;
    };
    for _ in 0..500 {
        step(&mut c, &mut publisher);
    }
    assert!(switch.recording());
    let before = allocations();
    counted(|| {
        for _ in 0..4000 {
            step(&mut c, &mut publisher);
        }
    });
    let allocations = allocations() - before;
    assert!(seen.0 && seen.1, "warn and stop: {seen:?}");
    assert_eq!(
        allocations, 0,
        "the recorded cycles allocated {allocations} times"
    );
    assert_eq!(switch.dropped(), 0);
    // The recording sink keeps its counters in the loop's health, where the
    // publisher after it reads them.
    assert_eq!(health.recording, sar_msgs::wire::recording_code::ON);
    assert_eq!(health.recorder_drops, 0);
    publisher.release();
    manager.finish();

    // One file, every cycle in it, replayed bit for bit.
    let files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let r = replay_file(&files[0], &ReplayOptions::from_config(&cfg)).unwrap();
    assert_eq!(r.mode, Mode::CycleInput);
    assert_eq!(r.cycles, 4500);
    assert_eq!(r.first_difference, None);
    // The snapshots taken on the loop (one at the start, one every 100 ms)
    // were written and equal the replayed step's state.
    assert!(r.snapshots_compared >= 44, "{}", r.snapshots_compared);
    assert_eq!(r.compared, r.outputs + r.snapshots_compared);
    let bytes = read_file(&files[0]).unwrap();
    let events = McapReader::new(&bytes)
        .unwrap()
        .decoded()
        .filter(|m| matches!(m, Ok((_, _, Outgoing::GuardEvent(_)))))
        .count();
    assert!(events >= 3, "{events} guard events");
}

#[test]
fn push_does_not_allocate() {
    let dir = sar_test_support::scratch!("no_alloc");
    let mut config = RecorderConfig::new(FileOptions::new(&dir, "rec"));
    config.queue_capacity = 4096;
    // Prepared before counting: the messages of 2000 cycles.
    let msgs: Vec<Outgoing> = (0..2000)
        .flat_map(sar_test_support::messages::cycle_messages)
        .collect();

    // Writer running: pushes accepted.
    let mut rec = Recorder::start(config.clone()).unwrap();
    let before = thread_allocations();
    let mut accepted = 0u64;
    for m in &msgs[..1000] {
        accepted += u64::from(rec.push(*m));
    }
    let during = thread_allocations() - before;
    let _ = rec.dropped();
    assert_eq!(
        during, 0,
        "{during} allocations in {accepted} accepted pushes"
    );
    assert!(accepted > 0);
    rec.stop().unwrap();

    // Writer stalled: most pushes dropped, counted, still no allocation.
    let mut rec = Recorder::new_paused(config).unwrap();
    let before = thread_allocations();
    let mut dropped = 0u64;
    for m in &msgs {
        dropped += u64::from(!rec.push(*m));
    }
    let count = rec.dropped();
    let during = thread_allocations() - before;
    assert_eq!(during, 0, "{during} allocations in {} pushes", msgs.len());
    assert_eq!(dropped, msgs.len() as u64 - 4096);
    assert_eq!(count, dropped);
    rec.stop().unwrap();

    // The counter counts: an allocation on this thread is seen.
    let before = thread_allocations();
    let v = std::hint::black_box(vec![1u8; 10]);
    assert!(thread_allocations() > before, "{v:?}");
}
