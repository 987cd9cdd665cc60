//! A push onto the recorder's queue does not allocate, accepted or dropped:
//! counted by a global allocator that counts each thread's allocations (the
//! writer thread allocates as it likes; the loop's thread must not).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_msgs::msgs::Outgoing;
use sar_record::{FileOptions, Recorder, RecorderConfig};
use sar_test_support::counting::{Counting, thread_allocations as allocations};

#[global_allocator]
static GLOBAL: Counting = Counting;

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
    let before = allocations();
    let mut accepted = 0u64;
    for m in &msgs[..1000] {
        accepted += u64::from(rec.push(*m));
    }
    let during = allocations() - before;
    let _ = rec.dropped();
    assert_eq!(
        during, 0,
        "{during} allocations in {accepted} accepted pushes"
    );
    assert!(accepted > 0);
    rec.stop().unwrap();

    // Writer stalled: most pushes dropped, counted, still no allocation.
    let mut rec = Recorder::new_paused(config).unwrap();
    let before = allocations();
    let mut dropped = 0u64;
    for m in &msgs {
        dropped += u64::from(!rec.push(*m));
    }
    let count = rec.dropped();
    let during = allocations() - before;
    assert_eq!(during, 0, "{during} allocations in {} pushes", msgs.len());
    assert_eq!(dropped, msgs.len() as u64 - 4096);
    assert_eq!(count, dropped);
    rec.stop().unwrap();

    // The counter counts: an allocation on this thread is seen.
    let before = allocations();
    let v = std::hint::black_box(vec![1u8; 10]);
    assert!(allocations() > before, "{v:?}");
}
