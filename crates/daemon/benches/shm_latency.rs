//! The daemon's state publishing, against bare iceoryx2 in the same run.
//!
//! - `shm_latency/daemon`: from the loop's publish call (`DaemonShm::push_state`:
//!   queue + wake of the publishing thread, which sends through iceoryx2 and
//!   notifies the event) to a subscriber thread blocked on the event as
//!   `sarctl monitor` is (`StateSubscription::wait`) having the sample; the
//!   monotonic stamp travels in the payload (`StateMsg::now_ns`).
//! - `shm_latency/bare`: a bare iceoryx2 pair (publisher and notifier,
//!   subscriber and listener), same payload (`StateMsg`), the publisher on
//!   the calling thread: the floor.
//! - `shm_loop_side/*`: what a publish costs the loop thread, back to back:
//!   the push into the queue (no wake-up) against a direct iceoryx2 publish
//!   (loan, write, send, notify). The push with the wake-up of a sleeping
//!   publishing thread (the per-cycle case at 1 kHz) is the "publish call"
//!   printed by the latency run.
//!
//! One sample at a time (the next after the previous arrived), so both
//! threads sleep between samples as at 1 kHz. The publishing side (the
//! bench's thread, as the loop) runs at SCHED_FIFO 80 while measured when
//! permitted, as `sard`'s loop does; the daemon's publishing thread and the
//! subscribers run at normal priority, as in `sard` and `sarctl`. Prints p50/p99 of every
//! latency and of the publish call itself, and the ratios of the p50s and
//! p99s, after criterion's report.
//! `cargo bench -p sar-daemon --bench shm_latency`

#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use criterion::{Criterion, criterion_group};
use sar_loop::control::Operator;
use sar_msgs::wire::StateMsg;
use sar_shm::{Client, DaemonShm, node};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The calling thread at SCHED_FIFO 80 (`true`) or back to normal.
#[allow(unsafe_code)]
fn fifo(on: bool) {
    if on {
        FIFO.store(sar_loop::rt::set_fifo(80).is_ok(), Ordering::Relaxed);
    } else {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: `param` is valid; pid 0 is the calling thread.
        unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
    }
}

static FIFO: AtomicBool = AtomicBool::new(false);

fn mono() -> u64 {
    sar_loop::rt::monotonic_ns().unwrap()
}

/// Latencies (ns) and publish-call times (ns) per setup.
#[derive(Default)]
struct Record {
    latency_ns: Vec<u64>,
    call_ns: Vec<u64>,
}

static DAEMON: Mutex<Option<Record>> = Mutex::new(None);
static BARE: Mutex<Option<Record>> = Mutex::new(None);

fn stamped(seq: u64) -> StateMsg {
    StateMsg {
        cycle: seq,
        now_ns: mono(),
        ..StateMsg::default()
    }
}

/// Runs `iters` samples one at a time: `publish` returns the duration of the
/// publish call; the subscriber answers each sample's latency on `rx`.
fn ping(
    iters: u64,
    record: &Mutex<Option<Record>>,
    rx: &Receiver<u64>,
    mut publish: impl FnMut(u64) -> u64,
) -> Duration {
    let mut total = 0u64;
    let mut rec = record.lock().unwrap();
    let rec = rec.get_or_insert_with(Record::default);
    for i in 0..iters {
        let call = publish(i);
        let latency = rx.recv_timeout(Duration::from_secs(5)).expect("no sample");
        rec.latency_ns.push(latency);
        rec.call_ns.push(call);
        total += latency;
    }
    Duration::from_nanos(total)
}

fn daemon_subscriber(prefix: String, tx: Sender<u64>, stop: Arc<AtomicBool>) {
    let client = Client::new(&prefix).unwrap();
    let sub = client.subscribe().unwrap();
    while !stop.load(Ordering::Relaxed) {
        sub.wait(Duration::from_millis(20), |s| {
            let _ = tx.send(mono().saturating_sub(s.now_ns));
        });
    }
}

fn bare_subscriber(name: String, tx: Sender<u64>, stop: Arc<AtomicBool>, ready: Sender<()>) {
    let node = node().unwrap();
    let state = node
        .service_builder(&format!("{name}/state").as_str().try_into().unwrap())
        .publish_subscribe::<StateMsg>()
        .open()
        .unwrap();
    let sub = state.subscriber_builder().create().unwrap();
    let event = node
        .service_builder(&format!("{name}/event").as_str().try_into().unwrap())
        .event()
        .open()
        .unwrap();
    let listener = event.listener_builder().create().unwrap();
    ready.send(()).unwrap();
    while !stop.load(Ordering::Relaxed) {
        let _ = listener.timed_wait(|_| {}, Duration::from_millis(20));
        while let Ok(Some(s)) = sub.receive() {
            let _ = tx.send(mono().saturating_sub(s.payload().now_ns));
        }
    }
}

fn latency(c: &mut Criterion) {
    let mut g = c.benchmark_group("shm_latency");
    g.sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));

    // The daemon's path.
    {
        let prefix = format!("sar-bench-{}", std::process::id());
        let mut shm = DaemonShm::create(&prefix, Operator::new(), [1.0; 6]).unwrap();
        let (tx, rx) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let sub = {
            let (prefix, stop) = (prefix.clone(), stop.clone());
            std::thread::spawn(move || daemon_subscriber(prefix, tx, stop))
        };
        // Until the subscriber is connected: one sample through.
        let mut seq = 0;
        loop {
            seq += 1;
            shm.push_state(stamped(seq));
            if rx.recv_timeout(Duration::from_millis(50)).is_ok() {
                break;
            }
        }
        while rx.try_recv().is_ok() {}
        fifo(true);
        g.bench_function("daemon", |b| {
            b.iter_custom(|iters| {
                ping(iters, &DAEMON, &rx, |i| {
                    let state = stamped(i);
                    let t0 = mono();
                    shm.push_state(state);
                    mono() - t0
                })
            })
        });
        fifo(false);
        stop.store(true, Ordering::Relaxed);
        sub.join().unwrap();
        println!(
            "daemon path: {} published, {} dropped, {} publish errors",
            shm.published(),
            shm.publish_queue_drops(),
            shm.publish_errors()
        );
    }

    // Bare iceoryx2, same payload, publisher on this thread.
    {
        let name = format!("sar-bench-bare-{}", std::process::id());
        let node = node().unwrap();
        let state = node
            .service_builder(&format!("{name}/state").as_str().try_into().unwrap())
            .publish_subscribe::<StateMsg>()
            .create()
            .unwrap();
        let publisher = state.publisher_builder().create().unwrap();
        let event = node
            .service_builder(&format!("{name}/event").as_str().try_into().unwrap())
            .event()
            .create()
            .unwrap();
        let notifier = event.notifier_builder().create().unwrap();
        let (tx, rx) = channel();
        let (ready_tx, ready_rx) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let sub = {
            let stop = stop.clone();
            std::thread::spawn(move || bare_subscriber(name, tx, stop, ready_tx))
        };
        ready_rx.recv().unwrap();
        fifo(true);
        g.bench_function("bare", |b| {
            b.iter_custom(|iters| {
                ping(iters, &BARE, &rx, |i| {
                    let state = stamped(i);
                    let t0 = mono();
                    publisher
                        .loan_uninit()
                        .unwrap()
                        .write_payload(state)
                        .send()
                        .unwrap();
                    notifier.notify().unwrap();
                    mono() - t0
                })
            })
        });
        fifo(false);
        stop.store(true, Ordering::Relaxed);
        sub.join().unwrap();
    }
    g.finish();
}

/// The loop thread's cost of one publish, back to back.
fn loop_side(c: &mut Criterion) {
    let mut g = c.benchmark_group("shm_loop_side");
    g.sample_size(30)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    let state = StateMsg::default();

    // Push only (the worker pumped by hand, outside the timing, every 64).
    {
        let prefix = format!("sar-bench-push-{}", std::process::id());
        let (mut shm, mut worker) =
            DaemonShm::create_manual(&prefix, Operator::new(), [1.0; 6]).unwrap();
        g.bench_function("queue_push", |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut left = iters;
                while left > 0 {
                    let n = left.min(64);
                    let t = std::time::Instant::now();
                    for _ in 0..n {
                        shm.push_state(std::hint::black_box(state));
                    }
                    total += t.elapsed();
                    worker.pump();
                    left -= n;
                }
                total
            })
        });
    }
    // Direct iceoryx2 publish with a subscriber and a listener connected.
    {
        let name = format!("sar-bench-direct-{}", std::process::id());
        let node = node().unwrap();
        let service = node
            .service_builder(&format!("{name}/state").as_str().try_into().unwrap())
            .publish_subscribe::<StateMsg>()
            .enable_safe_overflow(true)
            .create()
            .unwrap();
        let publisher = service.publisher_builder().create().unwrap();
        let _sub = service.subscriber_builder().create().unwrap();
        let event = node
            .service_builder(&format!("{name}/event").as_str().try_into().unwrap())
            .event()
            .create()
            .unwrap();
        let notifier = event.notifier_builder().create().unwrap();
        let _listener = event.listener_builder().create().unwrap();
        g.bench_function("iceoryx2_direct", |b| {
            b.iter(|| {
                publisher
                    .loan_uninit()
                    .unwrap()
                    .write_payload(std::hint::black_box(state))
                    .send()
                    .unwrap();
                notifier.notify().unwrap();
            })
        });
    }
    g.finish();
}

fn quantile(v: &mut [u64], q: f64) -> u64 {
    if v.is_empty() {
        return 0;
    }
    v.sort_unstable();
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    v[i]
}

fn report() {
    let take = |m: &Mutex<Option<Record>>| m.lock().unwrap().take().unwrap_or_default();
    let (mut d, mut b) = (take(&DAEMON), take(&BARE));
    if d.latency_ns.is_empty() || b.latency_ns.is_empty() {
        return;
    }
    let row = |name: &str, v: &mut Vec<u64>| {
        let (p50, p99) = (quantile(v, 0.5), quantile(v, 0.99));
        println!(
            "{name:>34}: p50 {p50:>7} ns  p99 {p99:>8} ns  ({} samples)",
            v.len()
        );
        (p50, p99)
    };
    println!(
        "\nthe publishing side at SCHED_FIFO 80: {}",
        FIFO.load(Ordering::Relaxed)
    );
    println!("publish -> receive latency (subscriber blocked on the event):");
    let (d50, d99) = row("daemon (queue + thread + iceoryx2)", &mut d.latency_ns);
    let (b50, b99) = row("bare iceoryx2 pair", &mut b.latency_ns);
    println!(
        "{:>34}: p50 {:.2}x  p99 {:.2}x",
        "ratio daemon / bare",
        d50 as f64 / b50.max(1) as f64,
        d99 as f64 / b99.max(1) as f64
    );
    println!("the publish call on the loop's thread (next sample after the previous arrived):");
    let (c50, c99) = row("daemon: queue push + wake", &mut d.call_ns);
    let (i50, i99) = row("bare: loan, send, notify", &mut b.call_ns);
    println!(
        "{:>34}: p50 {:.2}x  p99 {:.2}x",
        "ratio daemon / bare",
        c50 as f64 / i50.max(1) as f64,
        c99 as f64 / i99.max(1) as f64
    );
}

criterion_group!(benches, latency, loop_side);

fn main() {
    benches();
    report();
    Criterion::default().configure_from_args().final_summary();
}
