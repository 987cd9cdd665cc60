//! The RDT driver's latency: from the emulator sending a packet on loopback
//! to the sample returned by the loop's `poll` (which reads the socket on
//! the caller's thread), p50/p99, beside two baselines in the same run: a
//! bare UDP send and recv on one thread, and a UDP send received by a
//! thread blocked in `recv` that hands a flag to the spinning sender (the
//! least any receive-thread design, the driver's former one, can cost).
//! Then the cost of one cycle's reads with nothing new (`drain` then `poll`:
//! one `recvmmsg` that finds the socket empty) beside a bare non-blocking
//! `recv` on an empty UDP socket.
//!
//! Each figure is a distribution measured here (5000 rounds, printed), then
//! criterion's own estimate of the mean of the same round.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use criterion::{Criterion, criterion_group, criterion_main};
use sar_hal::{Clock, ForceSensor, MonotonicClock};
use sar_rdt::emulator::{Emulator, EmulatorConfig, Pacing};
use sar_rdt::{RdtConfig, RdtSensor};
use std::hint::black_box;
use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Host time, ns: the one place this file reads the clock.
fn now_ns(clock: &MonotonicClock) -> u64 {
    clock.now_ns().expect("the monotonic clock cannot be read")
}

const ROUNDS: usize = 5000;

const EMPTY: sar_hal::WrenchSample = sar_hal::WrenchSample {
    force_n: sar_hal::Vec3::new(0.0, 0.0, 0.0),
    torque_nm: sar_hal::Vec3::new(0.0, 0.0, 0.0),
    counter: 0,
    status: sar_hal::SensorStatus::OK,
    received_ns: 0,
};

/// Spins until `done`, at most 1 s (a lost packet must not hang the bench).
fn spin_until(clock: &MonotonicClock, mut done: impl FnMut() -> bool) -> bool {
    let deadline = now_ns(clock) + 1_000_000_000;
    while !done() {
        if now_ns(clock) > deadline {
            return false;
        }
        std::hint::spin_loop();
    }
    true
}

struct Rig {
    clock: MonotonicClock,
    emulator: Emulator,
    sensor: RdtSensor,
}

impl Rig {
    fn new() -> Self {
        let emulator = Emulator::start(EmulatorConfig::new(Pacing::Manual)).unwrap();
        let sensor = RdtSensor::connect(RdtConfig {
            silence_limit_ns: 3_600_000_000_000,
            ..RdtConfig::new(emulator.address(), 10_000.0, 100_000.0)
        })
        .unwrap();
        assert!(emulator.wait_for_starts(1, Duration::from_secs(10)));
        Self {
            clock: MonotonicClock::new().unwrap(),
            emulator,
            sensor,
        }
    }

    /// One packet: emulator send to `poll` returning it, ns.
    fn round(&mut self) -> Option<u64> {
        let t0 = now_ns(&self.clock);
        self.emulator.step(1);
        let sensor = &mut self.sensor;
        let got = spin_until(&self.clock, || matches!(sensor.poll(), Ok(Some(_))));
        got.then(|| now_ns(&self.clock) - t0)
    }
}

struct Bare {
    clock: MonotonicClock,
    tx: UdpSocket,
    rx: UdpSocket,
}

impl Bare {
    fn new() -> Self {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        tx.connect(rx.local_addr().unwrap()).unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
        Self {
            clock: MonotonicClock::new().unwrap(),
            tx,
            rx,
        }
    }

    fn round(&mut self) -> Option<u64> {
        let mut buf = [0u8; 64];
        let t0 = now_ns(&self.clock);
        self.tx.send(&[0u8; 36]).unwrap();
        self.rx.recv(&mut buf).ok()?;
        Some(now_ns(&self.clock) - t0)
    }
}

struct Threaded {
    clock: MonotonicClock,
    tx: UdpSocket,
    received: Arc<AtomicU64>,
    seen: u64,
}

impl Threaded {
    fn new() -> Self {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        tx.connect(rx.local_addr().unwrap()).unwrap();
        let received = Arc::new(AtomicU64::new(0));
        {
            let received = Arc::clone(&received);
            std::thread::spawn(move || {
                let mut buf = [0u8; 64];
                // Ends with the process (the bench's lifetime).
                while rx.recv(&mut buf).is_ok() {
                    received.fetch_add(1, Ordering::Release);
                }
            });
        }
        Self {
            clock: MonotonicClock::new().unwrap(),
            tx,
            received,
            seen: 0,
        }
    }

    fn round(&mut self) -> Option<u64> {
        let t0 = now_ns(&self.clock);
        self.tx.send(&[0u8; 36]).unwrap();
        let target = self.seen + 1;
        let received = &self.received;
        let got = spin_until(&self.clock, || received.load(Ordering::Acquire) >= target);
        self.seen = received.load(Ordering::Acquire);
        got.then(|| now_ns(&self.clock) - t0)
    }
}

/// Runs `round` ROUNDS times and prints p50, p99 and max, us.
fn distribution(name: &str, mut round: impl FnMut() -> Option<u64>) {
    let mut ns: Vec<u64> = Vec::with_capacity(ROUNDS);
    let mut lost = 0;
    for _ in 0..ROUNDS {
        match round() {
            Some(t) => ns.push(t),
            None => lost += 1,
        }
    }
    ns.sort_unstable();
    let at = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize] as f64 / 1e3;
    println!(
        "{name:<48} p50 {:>7.1} us  p99 {:>7.1} us  max {:>8.1} us  ({} rounds, {lost} lost)",
        at(0.5),
        at(0.99),
        at(1.0),
        ns.len()
    );
}

fn latency(c: &mut Criterion) {
    let mut rig = Rig::new();
    let mut bare = Bare::new();
    let mut threaded = Threaded::new();
    println!("\npacket-to-poll latency distributions (loopback, {ROUNDS} rounds each):");
    distribution("baseline: UDP send + recv, one thread", || bare.round());
    distribution("baseline: UDP send -> recv thread -> atomic", || {
        threaded.round()
    });
    distribution("rdt: emulator packet -> poll", || rig.round());
    println!();

    let mut group = c.benchmark_group("rdt");
    group
        .sample_size(30)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    group.bench_function("baseline udp send+recv (one thread)", |b| {
        b.iter(|| black_box(bare.round()))
    });
    group.bench_function("baseline udp send -> recv thread -> atomic", |b| {
        b.iter(|| black_box(threaded.round()))
    });
    group.bench_function("emulator packet -> poll", |b| {
        b.iter(|| black_box(rig.round()))
    });
    group.bench_function("poll with nothing new", |b| {
        b.iter(|| black_box(rig.sensor.poll()))
    });
    let mut out = [rig.sensor.wait(0).unwrap_or(EMPTY); 8];
    group.bench_function("one cycle's reads with nothing new (drain, poll)", |b| {
        b.iter(|| {
            black_box(rig.sensor.drain(&mut out).ok());
            black_box(rig.sensor.poll().ok())
        })
    });
    let empty = UdpSocket::bind("127.0.0.1:0").unwrap();
    empty.set_nonblocking(true).unwrap();
    group.bench_function("baseline: recv on an empty socket (non-blocking)", |b| {
        let mut buf = [0u8; 64];
        b.iter(|| black_box(empty.recv(&mut buf).is_err()))
    });
    group.finish();
}

criterion_group!(benches, latency);
criterion_main!(benches);
