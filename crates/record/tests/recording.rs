//! Recordings written by the recorder and read back: bit for bit, cut short at
//! many byte offsets (read up to the last complete chunk, never a panic) and
//! recovered, rotated by size and by duration, and drops counted when the
//! writer is stalled.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

// The other recording tests, in this binary (one binary: less to link); the
// strict readers of the tests (shared with sar-daemon's and sar-tests' tests).
#[path = "recording/lean_recording.rs"]
mod lean_recording;
#[path = "recording/python_reader.rs"]
mod python_reader;
#[path = "../../daemon/tests/common/readers.rs"]
mod readers;
#[path = "recording/snapshot_recording.rs"]
mod snapshot_recording;

use sar_msgs::msgs::*;
use sar_record::output::OutputError;
use sar_record::reader::ReadError;
use sar_record::*;
use std::path::Path;

fn config(dir: &Path, chunk: u64) -> RecorderConfig {
    let mut files = FileOptions::new(dir, "rec");
    files.chunk_size_bytes = chunk;
    let mut c = RecorderConfig::new(files);
    c.queue_capacity = 1 << 16;
    c
}

/// Records cycles 0..n; the queue holds them all, so nothing may drop.
fn record(config: RecorderConfig, n: u64) -> (RecordingReport, Vec<Outgoing>) {
    let mut rec = Recorder::start(config).unwrap();
    let mut pushed = Vec::new();
    for k in 0..n {
        for m in sar_test_support::messages::cycle_messages(k) {
            assert!(rec.push(m));
            pushed.push(m);
        }
    }
    let report = rec.stop().unwrap();
    assert_eq!(report.dropped, 0);
    (report, pushed)
}

fn encoded(m: &Outgoing) -> Vec<u8> {
    let mut b = Vec::new();
    m.encode(&mut b).unwrap();
    b
}

/// All messages of a file (topic, raw) and how the read ended.
fn read_all(bytes: &[u8]) -> (Vec<(String, RawMessage)>, Option<ReadError>, McapReader<'_>) {
    let mut reader = McapReader::new(bytes).unwrap();
    let mut out = Vec::new();
    let mut end = None;
    for item in reader.by_ref() {
        match item {
            Ok(m) => out.push((String::new(), m)),
            Err(e) => end = Some(e),
        }
    }
    for (topic, m) in &mut out {
        *topic = reader.channels()[&m.channel_id].topic.clone();
    }
    (out, end, reader)
}

#[test]
fn recording_reads_back_bit_for_bit() {
    let dir = sar_test_support::scratch!("bit_for_bit");
    let (report, pushed) = record(config(&dir, 64 * 1024), 2000);
    assert_eq!(report.files.len(), 1);
    let bytes = read_file(&report.files[0]).unwrap();
    let (msgs, end, reader) = read_all(&bytes);
    assert!(end.is_none(), "{end:?}");
    assert!(reader.is_complete());
    assert_eq!(reader.profile(), Some("ros2"));
    // Every topic has its channel, with its schema, in every file (the
    // lean mode's batches only in a lean file).
    assert_eq!(reader.channels().len(), Topic::FULL.len());
    for t in Topic::FULL {
        let c = reader.channel_of(t.name()).unwrap();
        assert_eq!(c.message_encoding, "cdr");
        assert_eq!(c.schema_encoding(), "ros2msg");
        assert_eq!(c.schema_name(), t.type_name());
        assert_eq!(c.schema_data(), t.schema().as_bytes());
    }
    // The pushed messages, in order, byte for byte; then the final status.
    let (data, status) = msgs.split_at(pushed.len());
    for (m, (topic, raw)) in pushed.iter().zip(data) {
        assert_eq!(topic, m.topic().name());
        assert_eq!(raw.data, encoded(m));
        assert_eq!(raw.log_time_ns, m.stamp_ns());
        assert_eq!(raw.publish_time_ns, m.stamp_ns());
    }
    // Status messages: one a second of log time (2000 cycles = 0.5 s: none)
    // and one at close.
    assert_eq!(status.len(), 1);
    let drops = RecorderDrops::decode(&status[0].1.data).unwrap();
    assert_eq!(drops.dropped, 0);
    assert_eq!(drops.written, pushed.len() as u64 + 1);
    assert_eq!(drops.stamp_ns, sar_test_support::messages::now_ns(1999));
    let meta = reader
        .metadata()
        .iter()
        .find(|m| m.name == "sar_recorder")
        .unwrap();
    assert_eq!(meta.metadata["dropped"], "0");
    // Typed reading by topic.
    let inputs: Vec<_> = McapReader::new(&bytes)
        .unwrap()
        .typed::<CycleInput>(Topic::CycleInput.name())
        .map(|r| r.unwrap())
        .collect();
    assert_eq!(inputs.len(), 2000);
    for (k, (log, m)) in inputs.iter().enumerate() {
        assert_eq!(
            Outgoing::CycleInput(*m),
            sar_test_support::messages::cycle_messages(k as u64)[0]
        );
        assert_eq!(*log, m.now_ns);
    }
    // Every SAR topic decoded, in file order.
    let decoded: Vec<Outgoing> = McapReader::new(&bytes)
        .unwrap()
        .decoded()
        .map(|r| r.unwrap().2)
        .filter(|m| m.topic() != Topic::RecorderDrops)
        .collect();
    assert_eq!(decoded, pushed);
    // The wrong type for a topic is refused.
    let mut wrong = McapReader::new(&bytes)
        .unwrap()
        .typed::<WrenchStamped>(Topic::CycleInput.name());
    assert!(matches!(
        wrong.next(),
        Some(Err(ReadError::WrongType { .. }))
    ));
    // An independent reader (the mcap crate's summary) agrees.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(
        summary.stats.unwrap().message_count,
        pushed.len() as u64 + 1
    );
    assert!(summary.chunk_indexes.len() > 1);
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.compression == "zstd")
    );
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.compressed_size < c.uncompressed_size)
    );
}

#[test]
fn truncated_files_read_to_last_complete_chunk_and_recover() {
    let dir = sar_test_support::scratch!("truncated");
    let (report, pushed) = record(config(&dir, 16 * 1024), 1500);
    let full = read_file(&report.files[0]).unwrap();
    let summary = mcap::Summary::read(&full).unwrap().unwrap();
    // Message count of each chunk, from the mcap crate's own index reader.
    let chunks: Vec<(u64, usize)> = summary
        .chunk_indexes
        .iter()
        .map(|ci| {
            let n = summary.stream_chunk(&full, ci).unwrap().count();
            (ci.chunk_start_offset + ci.chunk_length, n)
        })
        .collect();
    assert!(chunks.len() > 10, "{} chunks", chunks.len());
    let all: Vec<Vec<u8>> = pushed.iter().map(encoded).collect();

    let mut cuts: Vec<usize> = (0..full.len()).step_by(full.len() / 150).collect();
    for &(end, _) in &chunks {
        let end = end as usize;
        cuts.extend([end - 1, end, end + 1, end + 9]);
    }
    cuts.extend([0, 1, 7, 8, 9, 20, full.len() - 1]);
    cuts.retain(|&c| c < full.len());
    let mut recovered_checked = 0;
    for (i, &cut) in cuts.iter().enumerate() {
        let bytes = &full[..cut];
        let Ok(reader) = McapReader::new(bytes) else {
            assert!(cut < 8, "cut {cut}: magic refused");
            let path = dir.join("cut-streamed.mcap");
            std::fs::write(&path, bytes).unwrap();
            assert!(McapReader::open(&path).is_err(), "cut {cut}");
            continue;
        };
        let mut got = Vec::new();
        let mut end = None;
        for item in reader {
            match item {
                Ok(m) => got.push(m),
                Err(e) => end = Some(e),
            }
        }
        // Exactly the messages of the chunks that end at or before the cut.
        let expected: usize = chunks
            .iter()
            .filter(|(e, _)| *e as usize <= cut)
            .map(|(_, n)| n)
            .sum();
        assert_eq!(got.len(), expected, "cut at {cut}");
        for (m, want) in got.iter().zip(&all) {
            assert_eq!(&m.data, want, "cut at {cut}");
        }
        // Streamed from a file record by record: the same messages and the
        // same end, error included.
        if i % 2 == 0 {
            let path = dir.join("cut-streamed.mcap");
            std::fs::write(&path, bytes).unwrap();
            let mut streamed = Vec::new();
            let mut streamed_end = None;
            for item in McapReader::open(&path).unwrap() {
                match item {
                    Ok(m) => streamed.push(m),
                    Err(e) => streamed_end = Some(e),
                }
            }
            assert_eq!(streamed, got, "cut at {cut}");
            assert_eq!(
                format!("{streamed_end:?}"),
                format!("{end:?}"),
                "cut at {cut}"
            );
        }
        match end {
            Some(ReadError::Truncated { offset, .. }) | Some(ReadError::Unfinished { offset }) => {
                assert!(offset as usize <= cut, "cut at {cut}: stopped at {offset}");
            }
            // A cut inside the summary: the data section is whole.
            None => assert_eq!(expected, all.len() + 1, "cut at {cut}: ended with None"),
            other => panic!("cut at {cut}: ended with {other:?}"),
        }
        // Recover some of them (every 8th cut, and all cuts at chunk ends).
        if i % 8 == 0 || chunks.iter().any(|(e, _)| *e as usize == cut) {
            let input = dir.join("cut.mcap");
            let output = dir.join("recovered.mcap");
            std::fs::write(&input, bytes).unwrap();
            let _ = std::fs::remove_file(&output);
            let r = recover(&input, &output).unwrap();
            assert_eq!(r.messages as usize, expected);
            assert_eq!(r.input_complete, r.stopped.is_none());
            if expected == 0 {
                // Nothing recovered: nothing written in the output's place.
                assert!(!output.exists(), "cut {cut}");
                continue;
            }
            let out = read_file(&output).unwrap();
            let (msgs, end, reader) = read_all(&out);
            assert!(end.is_none(), "recovered cut {cut}: {end:?}");
            assert_eq!(msgs.len(), expected);
            if expected > 0 {
                assert_eq!(reader.profile(), Some("ros2"));
            }
            for ((_, m), want) in msgs.iter().zip(&all) {
                assert_eq!(&m.data, want);
            }
            // Fully indexed: summary, statistics, chunk indexes.
            let s = mcap::Summary::read(&out).unwrap().unwrap();
            assert_eq!(s.stats.as_ref().unwrap().message_count as usize, expected);
            if expected > 0 {
                assert!(!s.chunk_indexes.is_empty());
                // Every message reachable through the index.
                let indexed: usize = s
                    .chunk_indexes
                    .iter()
                    .map(|ci| s.stream_chunk(&out, ci).unwrap().count())
                    .sum();
                assert_eq!(indexed, expected);
            }
            assert!(reader.metadata().iter().any(|m| m.name == "sar_recover"));
            recovered_checked += 1;
        }
    }
    assert!(recovered_checked > 20);
}

#[test]
fn recover_refuses_to_overwrite_its_input_and_non_mcap() {
    let dir = sar_test_support::scratch!("recover_refuses");
    let p = dir.join("x.mcap");
    std::fs::write(&p, b"not an mcap file").unwrap();
    let same = |r: Result<RecoverReport, RecoverError>| {
        matches!(r, Err(RecoverError::Output(OutputError::IsInput { .. })))
    };
    assert!(same(recover(&p, &p)));
    // The same file spelt another way, or by a hard or a symbolic link, is
    // refused too (compared by device and inode), and left as it was.
    let other_spelling = dir.join(".").join("x.mcap");
    assert!(same(recover(&p, &other_spelling)));
    let hard = dir.join("hard.mcap");
    let _ = std::fs::remove_file(&hard);
    std::fs::hard_link(&p, &hard).unwrap();
    assert!(same(recover(&p, &hard)));
    let soft = dir.join("soft.mcap");
    let _ = std::fs::remove_file(&soft);
    std::os::unix::fs::symlink(&p, &soft).unwrap();
    assert!(same(recover(&p, &soft)));
    assert_eq!(std::fs::read(&p).unwrap(), b"not an mcap file");
    assert!(matches!(
        recover(&p, &dir.join("y.mcap")),
        Err(RecoverError::Read(ReadError::NotMcap { .. }))
    ));
}

/// All messages of the files in order, each file complete and self-contained.
fn read_files(files: &[std::path::PathBuf]) -> Vec<(String, RawMessage)> {
    let mut all = Vec::new();
    for f in files {
        let bytes = read_file(f).unwrap();
        let (msgs, end, reader) = read_all(&bytes);
        assert!(end.is_none(), "{}: {end:?}", f.display());
        assert_eq!(
            reader.channels().len(),
            Topic::FULL.len(),
            "{}",
            f.display()
        );
        assert!(mcap::Summary::read(&bytes).unwrap().is_some());
        all.extend(msgs);
    }
    all
}

fn pushed_in(all: &[(String, RawMessage)]) -> Vec<Vec<u8>> {
    all.iter()
        .filter(|(t, _)| t != Topic::RecorderDrops.name())
        .map(|(_, m)| m.data.clone())
        .collect()
}

#[test]
fn rotation_by_size() {
    let dir = sar_test_support::scratch!("rotation_size");
    let mut c = config(&dir, 8 * 1024);
    c.files.rotation.max_bytes = Some(24 * 1024);
    let (report, pushed) = record(c, 3000);
    assert!(report.files.len() >= 3, "{:?}", report.files);
    for f in &report.files[..report.files.len() - 1] {
        let len = std::fs::metadata(f).unwrap().len();
        // Closed before the chunk that passed the limit, plus the summary;
        // and the channels' QoS text, at the start and in the summary.
        let qos = 2 * Topic::FULL.len() as u64 * sar_record::OFFERED_QOS_PROFILES.len() as u64;
        assert!(len < 24 * 1024 + 16 * 1024 + qos, "{}: {len}", f.display());
    }
    let all = read_files(&report.files);
    let want: Vec<_> = pushed.iter().map(encoded).collect();
    assert_eq!(pushed_in(&all), want);
    // Each closed file ends with its status message.
    let statuses = all
        .iter()
        .filter(|(t, _)| t == Topic::RecorderDrops.name())
        .count();
    assert!(statuses >= report.files.len());
}

#[test]
fn rotation_by_duration() {
    let dir = sar_test_support::scratch!("rotation_duration");
    let mut c = config(&dir, 64 * 1024);
    c.files.rotation.max_duration_ns = Some(100_000_000);
    // 2000 cycles at 4 kHz: 0.5 s, five files of 0.1 s.
    let (report, pushed) = record(c, 2000);
    assert_eq!(report.files.len(), 5, "{:?}", report.files);
    for (i, f) in report.files.iter().enumerate() {
        let bytes = read_file(f).unwrap();
        let (msgs, _, _) = read_all(&bytes);
        let first = msgs.first().unwrap().1.log_time_ns;
        let min = msgs.iter().map(|m| m.1.log_time_ns).min().unwrap();
        let max = msgs.iter().map(|m| m.1.log_time_ns).max().unwrap();
        assert!(max - min < 100_000_000, "{}: {min}..{max}", f.display());
        // A file starts with the cycle that reached the limit.
        assert_eq!(first, sar_test_support::messages::now_ns(400 * i as u64));
    }
    let all = read_files(&report.files);
    let want: Vec<_> = pushed.iter().map(encoded).collect();
    assert_eq!(pushed_in(&all), want);
}

#[test]
fn drops_are_counted_when_the_writer_is_stalled() {
    let dir = sar_test_support::scratch!("drops");
    let mut c = config(&dir, 64 * 1024);
    c.queue_capacity = 100;
    // The writer not started: a stalled disk, deterministically.
    let mut rec = Recorder::new_paused(c).unwrap();
    let msgs: Vec<Outgoing> = (0..30)
        .flat_map(sar_test_support::messages::cycle_messages)
        .collect();
    assert!(msgs.len() > 150);
    let accepted = msgs.iter().filter(|m| rec.push(**m)).count();
    assert_eq!(accepted, 100);
    assert_eq!(rec.dropped(), msgs.len() as u64 - 100);
    assert_eq!(rec.free_slots(), 0);
    let report = rec.stop().unwrap();
    assert_eq!(report.dropped, msgs.len() as u64 - 100);
    let bytes = read_file(&report.files[0]).unwrap();
    let (all, end, reader) = read_all(&bytes);
    assert!(end.is_none());
    // The first 100 messages were written, then the final status.
    let want: Vec<_> = msgs[..100].iter().map(encoded).collect();
    assert_eq!(pushed_in(&all), want);
    let (_, last) = all.last().unwrap();
    let status = RecorderDrops::decode(&last.data).unwrap();
    assert_eq!(status.dropped, msgs.len() as u64 - 100);
    assert_eq!(status.queue_capacity, 100);
    let meta = reader
        .metadata()
        .iter()
        .find(|m| m.name == "sar_recorder")
        .unwrap();
    assert_eq!(meta.metadata["dropped"], (msgs.len() - 100).to_string());
}

#[test]
fn status_messages_every_interval() {
    let dir = sar_test_support::scratch!("status");
    let mut c = config(&dir, 64 * 1024);
    c.status_interval_ns = 50_000_000;
    let (report, _) = record(c, 2000);
    let all = read_files(&report.files);
    let stamps: Vec<u64> = all
        .iter()
        .filter(|(t, _)| t == Topic::RecorderDrops.name())
        .map(|(_, m)| m.log_time_ns)
        .collect();
    // 0.5 s of log time at one per 50 ms (the first due 50 ms after the first
    // message), plus the one at close.
    assert_eq!(stamps.len(), 10, "{stamps:?}");
    assert!(stamps.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn a_dropped_recorder_still_closes_its_file() {
    let dir = sar_test_support::scratch!("dropped_recorder");
    let mut rec = Recorder::start(config(&dir, 64 * 1024)).unwrap();
    for m in sar_test_support::messages::cycle_messages(0) {
        assert!(rec.push(m));
    }
    drop(rec);
    // The writer thread finishes on its own; wait for the file's footer
    // (bounded: 10 s).
    let path = FileOptions::new(&dir, "rec").path(0);
    for _ in 0..1000 {
        if let Ok(bytes) = std::fs::read(&path)
            && mcap::Summary::read(&bytes).is_ok_and(|s| s.is_some())
        {
            let (msgs, end, _) = read_all(&bytes);
            assert!(end.is_none());
            assert_eq!(
                msgs.len(),
                sar_test_support::messages::cycle_messages(0).len() + 1
            );
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    panic!("the file was not closed within 10 s");
}

#[test]
fn a_failed_writer_drops_and_counts_and_stop_reports_it() {
    let dir = sar_test_support::scratch!("failed_writer");
    let sub = dir.join("gone");
    let mut rec = Recorder::new_paused(config(&sub, 64 * 1024)).unwrap();
    // The disk goes away before the first file is created.
    std::fs::remove_dir_all(&sub).unwrap();
    let msgs = sar_test_support::messages::cycle_messages(0);
    for m in &msgs {
        assert!(rec.push(*m));
    }
    match rec.stop() {
        Err(RecorderError::Write {
            written, dropped, ..
        }) => {
            assert_eq!(written, 0);
            assert_eq!(dropped, msgs.len() as u64);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn bad_settings_are_refused() {
    let dir = sar_test_support::scratch!("settings");
    let mut c = config(&dir, 64 * 1024);
    c.queue_capacity = 0;
    assert!(matches!(
        Recorder::start(c),
        Err(RecorderError::Setting {
            field: "queue_capacity",
            ..
        })
    ));
    let mut c = config(&dir, 0);
    c.queue_capacity = 10;
    assert!(Recorder::start(c).is_err());
}

mod corrupted {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    fn small_recording() -> Vec<u8> {
        static FILE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        FILE.get_or_init(|| {
            let dir = sar_test_support::scratch!("corrupted");
            let (report, _) = record(config(&dir, 2 * 1024), 60);
            read_file(&report.files[0]).unwrap()
        })
        .clone()
    }

    proptest! {
        #![proptest_config(Config {
            cases: 256,
            rng_seed: RngSeed::Fixed(0xc0_44),
            failure_persistence: None,
            ..Config::default()
        })]

        /// Bytes changed anywhere (bit rot, a torn write): reading and
        /// recovering end with messages and/or a typed error, never a panic.
        #[test]
        fn corrupted_files_never_panic(
            edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = small_recording();
            for (at, value) in edits {
                let i = at.index(bytes.len());
                bytes[i] = value;
            }
            bytes.truncate(cut.index(bytes.len()) + 1);
            let in_memory: Option<Vec<String>> = McapReader::new(&bytes)
                .ok()
                .map(|r| r.decoded().map(|item| format!("{item:?}")).collect());
            // Streamed from a file: the same items, never a panic.
            let path = std::env::temp_dir().join(format!(
                "sar-corrupted-{}.mcap",
                std::process::id()
            ));
            std::fs::write(&path, &bytes).unwrap();
            let streamed: Option<Vec<String>> = McapReader::open(&path)
                .ok()
                .map(|r| r.decoded().map(|item| format!("{item:?}")).collect());
            let _ = std::fs::remove_file(&path);
            prop_assert_eq!(streamed, in_memory);
        }
    }
}

/// One message that cannot be encoded (a stamp beyond CDR's 2^31 s) is
/// dropped and counted; the recording goes on with the next ones.
#[test]
fn an_unencodable_message_is_dropped_and_the_recording_goes_on() {
    let dir = sar_test_support::scratch!("unencodable");
    let mut rec = Recorder::start(config(&dir, 64 * 1024)).unwrap();
    let good = sar_test_support::messages::cycle_messages(1);
    let bad = Outgoing::SensorWrench(WrenchStamped::sensor(
        u64::MAX,
        [1.0, 2.0, 3.0],
        [0.1, 0.2, 0.3],
    ));
    assert!(rec.push(bad));
    for m in &good {
        assert!(rec.push(*m));
    }
    let report = rec.stop().unwrap();
    assert_eq!(report.dropped, 1);
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let bytes = std::fs::read(file).unwrap();
    let (messages, end, _) = read_all(&bytes);
    assert!(end.is_none(), "{end:?}");
    let written: Vec<Vec<u8>> = messages.iter().map(|(_, m)| m.data.to_vec()).collect();
    for m in &good {
        assert!(written.contains(&encoded(m)), "{m:?} missing");
    }
}

/// Snapshot chunks are joined by the writer into one `/sar/cycle/snapshot`;
/// a snapshot with a chunk missing (dropped from a full queue) is not
/// written, and the next complete one is, whole.
#[test]
fn snapshot_chunks_are_joined_and_an_incomplete_snapshot_is_left_out() {
    let dir = sar_test_support::scratch!("snapshot_chunks");
    let mut w = RotatingWriter::new(FileOptions::new(&dir, "chunks")).unwrap();
    let status = RecorderDrops::default();
    let a: Vec<u8> = (0..1000u32).map(|i| (i % 251) as u8).collect();
    let b: Vec<u8> = (0..900u32).map(|i| (i * 3 % 241) as u8).collect();
    let mut chunks = Vec::new();
    SnapshotChunk::split(10, 7, &a, |c| {
        chunks.push(c);
        true
    });
    assert_eq!(chunks.len(), 3);
    // The middle chunk of the first snapshot is lost.
    chunks.remove(1);
    SnapshotChunk::split(20, 9, &b, |c| {
        chunks.push(c);
        true
    });
    for c in &chunks {
        w.write(c, &status).unwrap();
    }
    w.close(&status).unwrap();
    let bytes = read_file(&w.files()[0]).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut got = Vec::new();
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        if reader.channels()[&m.channel_id].topic == Topic::StateSnapshot.name() {
            got.push(StateSnapshot::decode(&m.data).unwrap());
        }
    }
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!((got[0].stamp_ns, got[0].after_cycle), (20, 9));
    assert_eq!(got[0].data, b);
}

/// Issue 25, finding 5: a file system too small for the recording (a tmpfs
/// of 12 KiB: the messages fit in the writer's buffer, the disk does not)
/// ends in a write error naming ENOSPC ("No space left on device", the OS
/// error kept; the mcap crate's own text, "I/O error from writing, or
/// reading a compression stream", named nothing), at the latest when the
/// last bytes are flushed at the close; never a report of a file written.
#[test]
fn a_full_file_system_is_a_write_error_naming_enospc_never_a_file_written() {
    let dir = sar_test_support::scratch!("full_file_system");
    let mount = dir.join("tiny");
    std::fs::create_dir_all(&mount).unwrap();
    sar_test_support::process::run_ok(
        std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=12k", "tmpfs"])
            .arg(&mount),
        "this test needs a tmpfs (mount, as root)",
    );
    struct Unmount(std::path::PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = std::process::Command::new("umount").arg(&self.0).status();
        }
    }
    let _unmount = Unmount(mount.clone());
    let mut rec = Recorder::start(config(&mount, 16 * 1024)).unwrap();
    for k in 0..300 {
        for m in sar_test_support::messages::cycle_messages(k) {
            rec.push(m);
        }
    }
    match rec.stop() {
        Err(e @ RecorderError::Write { .. }) => {
            assert_eq!(e.os_error(), Some(28), "{e}");
            assert!(e.to_string().contains("No space left on device"), "{e}");
        }
        other => panic!("a full file system, yet {other:?}"),
    }
}
