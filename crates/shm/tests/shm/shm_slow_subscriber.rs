//! A slow or dead subscriber never slows the loop, and a full queue to the
//! publishing thread drops and counts instead of waiting. Deterministic: the
//! publishing thread's work is done by hand ([`DaemonShm::create_manual`],
//! [`ShmWorker::pump`]), cycle by cycle, on the test's thread; nothing is
//! timed.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_loop::control::Operator;
use sar_msgs::wire::StateMsg;
use sar_shm::{Client, DaemonShm, Names, STATE_BORROWED, STATE_BUFFER, STATE_QUEUE, ShmWorker};

fn daemon(name: &str) -> (String, DaemonShm, ShmWorker) {
    let prefix = format!("sar-slow-{name}-{}", std::process::id());
    let (shm, worker) = DaemonShm::create_manual(&prefix, Operator::new(), [1.0; 6]).unwrap();
    (prefix, shm, worker)
}

fn state(cycle: u64) -> StateMsg {
    StateMsg {
        cycle,
        now_ns: 1_000 + cycle,
        ..StateMsg::default()
    }
}

#[test]
fn subscribers_that_never_read_or_hold_samples_never_slow_the_loop() {
    let (prefix, mut shm, mut worker) = daemon("hold");
    let client = Client::new(&prefix).unwrap();
    // A subscriber that never reads.
    let idle = client.subscribe().unwrap();
    // A subscriber that took as many samples as it may and holds them for
    // ever (what a process stopped in a debugger, or killed and not yet
    // cleaned, looks like to the publisher).
    let node = sar_shm::node().unwrap();
    let names = Names::new(&prefix);
    let service = node
        .service_builder(&names.state.as_str().try_into().unwrap())
        .publish_subscribe::<StateMsg>()
        .open()
        .unwrap();
    let holder = service
        .subscriber_builder()
        .buffer_size(STATE_BUFFER)
        .create()
        .unwrap();
    let mut cycle = 0;
    for _ in 0..STATE_BORROWED {
        cycle += 1;
        shm.push_state(state(cycle));
        assert_eq!(worker.pump(), 1);
    }
    let held: Vec<_> = (0..STATE_BORROWED)
        .map(|_| holder.receive().unwrap().unwrap())
        .collect();
    assert_eq!(held.len(), STATE_BORROWED);

    // The loop goes on for many times the buffers: every state is queued
    // and sent, none dropped, no send fails.
    for _ in 0..20 * STATE_BUFFER {
        cycle += 1;
        shm.push_state(state(cycle));
        assert_eq!(worker.pump(), 1, "cycle {cycle} not sent");
    }
    assert_eq!(shm.publish_queue_drops(), 0);
    assert_eq!(shm.publish_errors(), 0);
    assert_eq!(shm.published(), cycle);

    // The idle reader resumes: it finds the newest STATE_BUFFER states, in
    // order, the last one the newest (its oldest were overwritten).
    let mut got = Vec::new();
    idle.drain(|s| got.push(s.cycle));
    assert_eq!(got.len(), STATE_BUFFER);
    assert_eq!(*got.last().unwrap(), cycle);
    assert!(got.windows(2).all(|w| w[1] == w[0] + 1), "{got:?}");
    // The holder may take no more while it holds its samples; once it
    // releases them it finds the newest too.
    assert!(holder.receive().is_err());
    drop(held);
    let mut newest = 0;
    while let Ok(Some(s)) = holder.receive() {
        newest = s.payload().cycle;
    }
    assert_eq!(newest, cycle);
}

#[test]
fn a_full_queue_to_the_publishing_thread_drops_and_counts_without_waiting() {
    let (prefix, mut shm, mut worker) = daemon("full");
    let client = Client::new(&prefix).unwrap();
    let sub = client.subscribe().unwrap();
    // The publishing thread is stuck (not pumped): the loop goes on.
    let extra = 10;
    for cycle in 1..=(STATE_QUEUE + extra) as u64 {
        shm.push_state(state(cycle));
    }
    assert_eq!(shm.publish_queue_drops(), extra as u64);
    // When it runs again it sends the queued states (the oldest ones: the
    // newest were dropped), then the next cycle's, which carries the count.
    assert_eq!(worker.pump(), STATE_QUEUE);
    let next = (STATE_QUEUE + extra + 1) as u64;
    let mut next_state = state(next);
    next_state.publish_queue_drops = shm.publish_queue_drops();
    shm.push_state(next_state);
    assert_eq!(worker.pump(), 1);
    let mut last = StateMsg::default();
    let n = sub.drain(|s| last = *s);
    assert_eq!(n, STATE_BUFFER);
    assert_eq!(last.cycle, next);
    assert_eq!(last.publish_queue_drops, extra as u64);
    assert_eq!(last.publish_errors, 0);
}
