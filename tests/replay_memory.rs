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

use sar_record::read_file;
use sar_record::replay::{ReplayOptions, replay, replay_file};
use sar_tests::scenarios_dir;

// The fixtures' generator (see replay.rs).
#[allow(dead_code)]
mod fixture_gen;
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

/// The counters are the process's: the tests measure one at a time.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

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

/// The process's resident memory before `f` runs and its peak (VmHWM) while
/// it runs, bytes: the peak is reset first (`/proc/self/clear_refs` 5, since
/// Linux 4.0) to what is resident now. `None` where /proc cannot do it. Counts
/// the whole process (binary, pages the allocator kept from earlier work),
/// unlike [`peak_of`]: the growth over "before" is the replay's.
fn peak_rss_of<T>(f: impl FnOnce() -> T) -> (Option<(u64, u64)>, T) {
    let read = |key: &str| -> Option<u64> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with(key))?;
        let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kb * 1024)
    };
    let reset = std::fs::write("/proc/self/clear_refs", "5").is_ok();
    let before = read("VmRSS:");
    let out = f();
    let peak = read("VmHWM:");
    (if reset { before.zip(peak) } else { None }, out)
}

/// "peak (+ growth over what was resident before)", MB.
fn mb(rss: Option<(u64, u64)>) -> String {
    rss.map_or_else(
        || "?".to_owned(),
        |(before, peak)| {
            format!(
                "{:.1} (+{:.1})",
                peak as f64 / 1e6,
                peak.saturating_sub(before) as f64 / 1e6
            )
        },
    )
}

/// Streamed and in-memory peaks for a recording of `cycles`.
fn measure(dir: &Path, cycles: u64) -> (u64, u64, u64) {
    let path = dir.join(format!("rec-{cycles}.mcap"));
    let len = record(&path, cycles);
    let cfg = sar_config::builtin().unwrap();
    let options = ReplayOptions::from_config(&cfg);
    let (rss_streamed, (streamed, r)) =
        peak_rss_of(|| peak_of(|| replay_file(&path, &options).unwrap()));
    assert_eq!(r.cycles, cycles);
    assert_eq!(r.first_difference, None);
    let (rss_in_memory, (in_memory, r)) = peak_rss_of(|| {
        peak_of(|| {
            let bytes = read_file(&path).unwrap();
            replay(&bytes, &options).unwrap()
        })
    });
    assert_eq!(r.cycles, cycles);
    println!(
        "{cycles} cycles ({:.1} MB file): peak heap {:.2} MB streamed, {:.2} MB in memory; peak RSS of the process {} MB streamed, {} MB in memory",
        len as f64 / 1e6,
        streamed as f64 / 1e6,
        in_memory as f64 / 1e6,
        mb(rss_streamed),
        mb(rss_in_memory),
    );
    (len, streamed, in_memory)
}

#[test]
fn the_peak_heap_of_a_replay_does_not_grow_with_the_recording() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
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

/// The sensor and joint messages of the daemon recording `daemon`: a
/// recording of the inputs alone (another program's, to the replay).
/// Returns the file's length and its sensor messages.
fn inputs_only(daemon: &Path, path: &Path) -> (u64, u64) {
    use sar_msgs::msgs::{Outgoing, RecorderDrops};
    use sar_record::{FileOptions, McapReader, RotatingWriter};
    let mut o = FileOptions::single(path);
    // Small chunks: the reader's buffers are warm (each grown to the largest
    // chunk) within the short recording too.
    o.chunk_size_bytes = 16 * 1024;
    let mut w = RotatingWriter::new(o).unwrap();
    let status = RecorderDrops::default();
    let mut sensors = 0;
    for m in McapReader::open(daemon).unwrap().decoded() {
        let (_, _, m) = m.unwrap();
        sensors += u64::from(matches!(m, Outgoing::SensorWrench(_)));
        if matches!(m, Outgoing::SensorWrench(_) | Outgoing::Joints(_)) {
            w.write(&m, &status).unwrap();
        }
    }
    w.close(&status).unwrap();
    (std::fs::metadata(path).unwrap().len(), sensors)
}

/// Issue 17: an inputs-only recording is paired in a bounded window, not
/// held whole: its replay's peak does not grow with its length either.
#[test]
fn the_peak_heap_of_an_inputs_only_replay_does_not_grow_with_the_recording() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = scratch("replay_memory_inputs");
    let cfg = sar_config::builtin().unwrap();
    let options = ReplayOptions::from_config(&cfg);
    let mut peaks = Vec::new();
    for cycles in [3_000, 30_000] {
        let daemon = dir.join(format!("daemon-{cycles}.mcap"));
        record(&daemon, cycles);
        let path = dir.join(format!("inputs-{cycles}.mcap"));
        let (len, sensors) = inputs_only(&daemon, &path);
        let (streamed, r) = peak_of(|| replay_file(&path, &options).unwrap());
        assert_eq!(r.mode, sar_record::replay::Mode::InputsOnly);
        // One cycle per sensor message (after the first joint message).
        assert!(
            r.cycles <= sensors && r.cycles + 2 >= sensors,
            "{} of {sensors}",
            r.cycles
        );
        println!(
            "inputs only, {cycles} cycles ({:.1} MB file): peak heap {:.2} MB streamed",
            len as f64 / 1e6,
            streamed as f64 / 1e6
        );
        peaks.push((len, streamed));
    }
    let [(short_len, short), (len, long)] = peaks[..] else {
        unreachable!()
    };
    // Ten times the messages, the same peak: nothing held per message.
    assert!(len > 5 * short_len, "{len} vs {short_len}");
    assert!(long <= short + 64_000, "{long} vs {short}");
}

#[test]
#[ignore = "figures: a one-minute and a one-hour recording (release build, minutes)"]
fn peak_heap_for_a_one_minute_and_a_one_hour_recording() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = scratch("replay_memory_hour");
    for cycles in [60_000, 3_600_000] {
        measure(&dir, cycles);
        // Its inputs alone, as another program would have recorded them.
        let daemon = dir.join(format!("rec-{cycles}.mcap"));
        let path = dir.join(format!("inputs-{cycles}.mcap"));
        let (len, _) = inputs_only(&daemon, &path);
        std::fs::remove_file(&daemon).unwrap();
        let cfg = sar_config::builtin().unwrap();
        let options = ReplayOptions::from_config(&cfg);
        let (rss, (streamed, r)) =
            peak_rss_of(|| peak_of(|| replay_file(&path, &options).unwrap()));
        assert_eq!(r.mode, sar_record::replay::Mode::InputsOnly);
        println!(
            "inputs only, {cycles} cycles ({:.1} MB file): peak heap {:.2} MB streamed; peak RSS of the process {} MB",
            len as f64 / 1e6,
            streamed as f64 / 1e6,
            mb(rss)
        );
        std::fs::remove_file(&path).unwrap();
    }
}
