//! The RDT driver's reads on the loop's path allocate nothing: `drain` and
//! `poll` (each reading the socket: accepted packets, a duplicate, a late
//! one, malformed datagrams, a burst of several cycles' packets, a silence
//! with its restart requests), counted by a global allocator that counts
//! the allocations of this thread while inside [`counted`]. Real UDP on
//! loopback, against the device emulator (whose own thread is not counted).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_hal::{ForceSensor, WrenchSample};
use sar_rdt::codec::Response;
use sar_rdt::emulator::{Emulator, EmulatorConfig, Pacing};
use sar_rdt::{RdtConfig, RdtSensor};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::{Duration, Instant};

/// Forwards to the system allocator, counting this thread's allocations
/// while [`COUNTING`] is set.
struct Counting;

thread_local! {
    /// Inside [`counted`] (const thread-locals: reading them never allocates).
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        let _ = COUNT.try_with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: forwards every call to the system allocator, only counting.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f` counting this thread's allocations; its result and the count.
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    let out = f();
    COUNTING.with(|c| c.set(false));
    (out, COUNT.with(Cell::get))
}

const MS: u64 = 1_000_000;

const EMPTY: WrenchSample = WrenchSample {
    force_n: sar_hal::Vec3::new(0.0, 0.0, 0.0),
    torque_nm: sar_hal::Vec3::new(0.0, 0.0, 0.0),
    counter: 0,
    status: sar_hal::SensorStatus::OK,
    received_ns: 0,
};

/// One loop cycle's reads, counted: drain then poll. The samples drained,
/// whether poll failed, and the allocations.
fn cycle(sensor: &mut RdtSensor, buf: &mut [WrenchSample]) -> (usize, bool, u64) {
    let ((drained, failed), allocations) = counted(|| {
        let drained = sensor.drain(buf).map_or(0, |d| d.count);
        (drained, sensor.poll().is_err())
    });
    (drained, failed, allocations)
}

#[test]
fn the_loops_reads_allocate_nothing() {
    let emulator = Emulator::start(EmulatorConfig::new(Pacing::Manual)).unwrap();
    let mut sensor = RdtSensor::connect(RdtConfig {
        silence_limit_ns: 30 * MS,
        restart_interval_ns: 10 * MS,
        ..RdtConfig::new(emulator.address(), 10_000.0, 100_000.0)
    })
    .unwrap();
    assert!(emulator.wait_for_starts(1, Duration::from_secs(10)));
    let mut buf = [EMPTY; 64];
    let mut total = 0u64;
    let mut drained = 0;
    // Packets, one a cycle, then a burst of 40 (several cycles' worth);
    // a duplicate, a late packet, and malformed datagrams among them.
    for round in 0..60u64 {
        emulator.step(if round == 30 { 40 } else { 1 });
        if round == 10 {
            let again = Response {
                rdt_sequence: 11,
                sample_counter: 1011,
                ..Response::default()
            };
            assert!(emulator.send_raw(&again.encode()));
            assert!(emulator.send_raw(&[0x12; 20]));
        }
        if round == 20 {
            let late = Response {
                rdt_sequence: 15,
                sample_counter: 1015,
                ..Response::default()
            };
            assert!(emulator.send_raw(&late.encode()));
        }
        std::thread::sleep(Duration::from_millis(1));
        let (n, _, allocations) = cycle(&mut sensor, &mut buf);
        drained += n;
        total += allocations;
    }
    // Then silence: the reads declare it and send the restart requests.
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut failed = false;
    while !(failed && sensor.stats().restarts >= 2) {
        assert!(Instant::now() < deadline, "{:?}", sensor.stats());
        std::thread::sleep(Duration::from_millis(1));
        let (n, f, allocations) = cycle(&mut sensor, &mut buf);
        drained += n;
        failed |= f;
        total += allocations;
    }
    let stats = sensor.stats();
    // What the reads saw: the test reached every path it names.
    assert_eq!(drained as u64, stats.accepted);
    assert!(stats.accepted >= 90, "{stats:?}");
    assert!(stats.duplicates >= 1 && stats.reordered >= 1, "{stats:?}");
    assert!(stats.malformed >= 1 && stats.silences >= 1, "{stats:?}");
    assert_eq!(total, 0, "the driver's reads allocated {total} times");
}

/// The counter counts: an allocation inside `counted` is seen (the test
/// above cannot pass by counting nothing).
#[test]
fn the_counter_sees_an_allocation() {
    let (v, allocations) = counted(|| vec![1u8; 16]);
    assert_eq!(v.len(), 16);
    assert_eq!(allocations, 1);
}
