//! Replay in constant memory (issue 17): `replay_files` streams each file
//! record by record, so the peak of heap memory during a replay does not
//! grow with the recording's length. Measured with a global allocator that
//! tracks the bytes in use and their peak, on two daemon recordings of the
//! same scenario, one ten times longer than the other; the in-memory path
//! (`replay` of the file's bytes) is measured beside it (it holds the whole
//! file). The figures are printed (`--nocapture`); the one-hour figure is
//! the ignored test (`cargo test --release -p sar-tests --test
//! replay_memory -- --ignored --nocapture`).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_daemon::record::read_file;
use sar_daemon::record::replay::{ReplayOptions, replay, replay_file};
use sar_tests::{fixture_gen, scenarios_dir};
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

struct Peak;
static LIVE: AtomicU64 = AtomicU64::new(0);
static PEAK: AtomicU64 = AtomicU64::new(0);

fn grow(n: usize) {
    let live = LIVE.fetch_add(n as u64, Ordering::SeqCst) + n as u64;
    PEAK.fetch_max(live, Ordering::SeqCst);
}
fn shrink(n: usize) {
    LIVE.fetch_sub(n as u64, Ordering::SeqCst);
}

// SAFETY: forwards to the system allocator, only counting bytes.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Peak {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        grow(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrink(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        grow(new_size);
        shrink(layout.size());
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Peak = Peak;

/// Peak heap bytes in use beyond those in use before, while `f` runs.
fn peak_of<T>(f: impl FnOnce() -> T) -> (u64, T) {
    let before = LIVE.load(Ordering::SeqCst);
    PEAK.store(before, Ordering::SeqCst);
    let out = f();
    (PEAK.load(Ordering::SeqCst) - before, out)
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A daemon recording of `cycles` 1 ms cycles of a random-contact scenario.
fn record(path: &Path, cycles: u64) -> u64 {
    fixture_gen::daemon_recording_at_level(
        &scenarios_dir().join("random_contact_manipulator_2.toml"),
        cycles,
        1_000_000,
        &fixture_gen::contact_requests(),
        path,
        0,
    )
    .unwrap();
    std::fs::metadata(path).unwrap().len()
}

/// Streamed and in-memory peaks for a recording of `cycles`.
fn measure(dir: &Path, cycles: u64) -> (u64, u64, u64) {
    let path = dir.join(format!("rec-{cycles}.mcap"));
    let len = record(&path, cycles);
    let cfg = sar_daemon::config::builtin().unwrap();
    let options = ReplayOptions::from_config(&cfg);
    let (streamed, r) = peak_of(|| replay_file(&path, &options).unwrap());
    assert_eq!(r.cycles, cycles);
    assert_eq!(r.first_difference, None);
    let (in_memory, r) = peak_of(|| {
        let bytes = read_file(&path).unwrap();
        replay(&bytes, &options).unwrap()
    });
    assert_eq!(r.cycles, cycles);
    println!(
        "{cycles} cycles ({:.1} MB file): peak heap {:.2} MB streamed, {:.2} MB in memory",
        len as f64 / 1e6,
        streamed as f64 / 1e6,
        in_memory as f64 / 1e6
    );
    (len, streamed, in_memory)
}

#[test]
fn the_peak_heap_of_a_replay_does_not_grow_with_the_recording() {
    let dir = scratch("replay_memory");
    let (_, short, _) = measure(&dir, 3_000);
    let (len, long, in_memory) = measure(&dir, 30_000);
    // The in-memory path holds the file: the measure can see it.
    assert!(in_memory >= len, "{in_memory} < {len}");
    // Streamed: no more than a chunk's worth more than the short one, and
    // well under the file.
    assert!(long <= short + 1_000_000, "{long} vs {short}");
    assert!(long < len / 2, "{long} vs a {len}-byte file");
}

#[test]
#[ignore = "figures: a one-minute and a one-hour recording (release build, minutes)"]
fn peak_heap_for_a_one_minute_and_a_one_hour_recording() {
    let dir = scratch("replay_memory_hour");
    measure(&dir, 60_000);
    measure(&dir, 3_600_000);
}
