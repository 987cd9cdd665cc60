//! Issue 35, findings 5 and 6: the readers' memory is bounded by the file's
//! size and a constant, whatever a crafted file holds.
//! - One schema named by many channels is held once (the reader used to
//!   clone its bytes into every channel: a 2 MiB schema named by 4000
//!   channels took 8 GB); channels, schemas and metadata beyond
//!   [`retained_limit`] of the file (a compressed chunk of big channel
//!   records) are refused with a typed error.
//! - Corrupt records are counted, the first few kept in detail (a list of
//!   every one took 2.98 GB in `replay`, 4.86 GB in `recover` for a 90 MB
//!   file of 9-byte records); the counts reach the final message.
//!
//! The files are small (kilobytes to a few MB): the bound is shown by how
//! the peak of the bytes in use (a counting allocator) scales with what
//! the file multiplies, not by a file of gigabytes.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_record::McapReader;
use sar_record::reader::{MAX_SKIPPED_SHOWN, ReadError, recover, retained_limit};
use sar_record::replay::{ReplayError, ReplayOptions, replay_file};
use sar_test_support::counting::{Counting, peak_bytes_in};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The peak figures are the process's: one measuring test at a time.
static SERIAL: Mutex<()> = Mutex::new(());

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

fn string(s: &[u8]) -> Vec<u8> {
    let mut v = (s.len() as u32).to_le_bytes().to_vec();
    v.extend_from_slice(s);
    v
}

fn record(op: u8, body: &[u8]) -> Vec<u8> {
    let mut v = vec![op];
    v.extend_from_slice(&(body.len() as u64).to_le_bytes());
    v.extend_from_slice(body);
    v
}

fn header() -> Vec<u8> {
    record(0x01, &[string(b"ros2"), string(b"craft")].concat())
}

fn schema(id: u16, data: &[u8]) -> Vec<u8> {
    let mut b = id.to_le_bytes().to_vec();
    b.extend(string(b"sar_msgs/msg/CycleInput"));
    b.extend(string(b"ros2msg"));
    b.extend(string(data));
    record(0x03, &b)
}

fn channel(id: u16, schema_id: u16, metadata: &[(&[u8], &[u8])]) -> Vec<u8> {
    let mut b = id.to_le_bytes().to_vec();
    b.extend(schema_id.to_le_bytes());
    b.extend(string(format!("/t{id}").as_bytes()));
    b.extend(string(b"cdr"));
    let map: Vec<u8> = metadata
        .iter()
        .flat_map(|(k, v)| [string(k), string(v)].concat())
        .collect();
    b.extend(string(&map));
    record(0x04, &b)
}

/// The end of a file: data end, an empty footer, the magic.
fn end() -> Vec<u8> {
    let mut v = record(0x0F, &0u32.to_le_bytes());
    v.extend(record(0x02, &[0u8; 20]));
    v.extend_from_slice(MAGIC);
    v
}

fn file(parts: &[Vec<u8>]) -> Vec<u8> {
    let mut v = MAGIC.to_vec();
    v.extend(header());
    for p in parts {
        v.extend_from_slice(p);
    }
    v.extend(end());
    v
}

/// A zstd chunk holding `records`.
fn chunk(records: &[u8]) -> Vec<u8> {
    let compressed = zstd::bulk::compress(records, 3).unwrap();
    let mut b = Vec::new();
    b.extend(0u64.to_le_bytes()); // message start time
    b.extend(0u64.to_le_bytes()); // message end time
    b.extend((records.len() as u64).to_le_bytes());
    b.extend(crc32fast::hash(records).to_le_bytes());
    b.extend(string(b"zstd"));
    b.extend((compressed.len() as u64).to_le_bytes());
    b.extend(compressed);
    record(0x06, &b)
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("reader_memory");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Reads every record of `path` through the streaming reader: the peak
/// of the bytes in use, and how it ended.
fn read_peak(path: &Path) -> (Option<String>, u64) {
    let (end, peak) = peak_bytes_in(|| {
        let mut reader = McapReader::open(path).unwrap();
        let mut end = None;
        for m in reader.by_ref() {
            if let Err(e) = m {
                end = Some(e.to_string());
            }
        }
        end
    });
    (end, peak)
}

/// One schema of 256 KiB named by 100 and by 800 channels: the reader
/// holds it once, so its peak does not grow with the channels beyond
/// their own small records (before: 800 x 256 KiB = 200 MiB).
#[test]
fn a_schema_named_by_many_channels_is_held_once() {
    let _serial = SERIAL.lock().unwrap();
    let big = vec![b'#'; 256 * 1024];
    let mut peaks = Vec::new();
    for channels in [100u16, 800] {
        let mut parts = vec![schema(1, &big)];
        parts.extend((1..=channels).map(|id| channel(id, 1, &[])));
        let bytes = file(&parts);
        let path = scratch(&format!("schema_x{channels}.mcap"));
        std::fs::write(&path, &bytes).unwrap();
        let (end, peak) = read_peak(&path);
        assert_eq!(end, None, "{channels} channels");
        // Every channel has the schema, the same one.
        let mut reader = McapReader::open(&path).unwrap();
        reader.by_ref().for_each(drop);
        assert_eq!(reader.channels().len(), usize::from(channels));
        let first = reader.channels()[&1].schema.clone().unwrap();
        for c in reader.channels().values() {
            assert!(std::sync::Arc::ptr_eq(c.schema.as_ref().unwrap(), &first));
            assert_eq!(c.schema_data().len(), big.len());
        }
        println!(
            "{channels} channels naming one 256 KiB schema: file {} bytes, peak {peak} bytes",
            bytes.len()
        );
        assert!(
            peak < 4 * bytes.len() as u64 + (1 << 20),
            "{channels} channels: peak {peak} bytes for a file of {}",
            bytes.len()
        );
        peaks.push(peak);
    }
    // 700 more channels: their records (about 200 bytes held each), not
    // 700 more copies of the schema (179 MB).
    assert!(
        peaks[1] - peaks[0].min(peaks[1]) < 700 * 1024,
        "peaks {peaks:?}"
    );
}

/// Channels whose metadata is 1 MiB each, 40 of them in one zstd chunk of
/// a few kilobytes: what they would hold (40 MiB) is beyond the bound for
/// the file's size, and refused with a typed error naming it; the peak
/// stays within the chunk's buffer and the bound.
#[test]
fn channels_beyond_the_files_bound_are_refused() {
    let _serial = SERIAL.lock().unwrap();
    let value = vec![b'a'; 1 << 20];
    let records: Vec<u8> = (1..=40u16)
        .flat_map(|id| channel(id, 0, &[(b"k", &value)]))
        .collect();
    let bytes = file(&[chunk(&records)]);
    assert!(bytes.len() < 64 * 1024, "{} bytes", bytes.len());
    let path = scratch("metadata_bomb.mcap");
    std::fs::write(&path, &bytes).unwrap();
    let limit = retained_limit(bytes.len() as u64);
    let (end, peak) = read_peak(&path);
    let end = end.expect("refused");
    assert!(end.contains("corrupt or crafted"), "{end}");
    assert!(end.contains(&format!("more than {limit}")), "{end}");
    let mut reader = McapReader::open(&path).unwrap();
    let err = reader.find_map(Result::err).unwrap();
    assert!(
        matches!(err, ReadError::TooMuchMetadata { retained, limit: l, .. } if retained > l && l == limit),
        "{err}"
    );
    // The decompressed chunk (40 MiB) and what the reader kept below the
    // bound: nothing near the 40 channels' 40 MiB on top.
    println!(
        "40 x 1 MiB channels in a {} byte file: refused; peak {peak} bytes",
        bytes.len()
    );
    assert!(
        peak < records.len() as u64 + limit + (4 << 20),
        "peak {peak} bytes"
    );
}

/// `n` corrupt 9-byte records (chunks with an empty body) in a row, or
/// each followed by a harmless record of an unknown opcode (so that no two
/// are adjacent).
fn bad_records(n: usize, interleaved: bool) -> Vec<u8> {
    let bad = record(0x06, &[]);
    let other = record(0x80, &[]);
    let mut parts = Vec::with_capacity(n);
    for _ in 0..n {
        let mut p = bad.clone();
        if interleaved {
            p.extend_from_slice(&other);
        }
        parts.push(p);
    }
    file(&parts)
}

/// `recover` and `replay` of files of corrupt records: counted, the first
/// few in detail, the counts in the report and the final message; the
/// peak of the bytes in use does not grow with their number (before: a
/// list of every one, about 300 bytes each in `recover`).
#[test]
fn corrupt_records_are_counted_in_bounded_memory_and_reported() {
    let _serial = SERIAL.lock().unwrap();
    for interleaved in [false, true] {
        let mut peaks = Vec::new();
        for n in [2_000usize, 20_000] {
            let bytes = bad_records(n, interleaved);
            let input = scratch(&format!("bad_{n}_{interleaved}.mcap"));
            std::fs::write(&input, &bytes).unwrap();
            let output = scratch(&format!("bad_{n}_{interleaved}.recovered.mcap"));
            let (report, peak) = peak_bytes_in(|| recover(&input, &output).unwrap());
            let s = &report.skipped;
            assert_eq!(s.records, n as u64, "interleaved {interleaved}");
            assert_eq!(s.bytes, 9 * n as u64);
            assert_eq!(s.parts, if interleaved { n as u64 } else { 1 });
            assert!(s.shown.len() <= MAX_SKIPPED_SHOWN);
            assert!(s.summary().starts_with(&format!("{n} corrupt records")));
            assert_eq!(report.messages, 0);
            // replay: the corrupt records named in the error that ends it.
            let cfg = sar_config::builtin().unwrap();
            let (replayed, replay_peak) =
                peak_bytes_in(|| replay_file(&input, &ReplayOptions::from_config(&cfg)));
            match replayed {
                Err(e @ ReplayError::NoInputsAmidCorrupt { records, .. }) => {
                    assert_eq!(records, n as u64, "{e}");
                    assert!(
                        e.to_string().contains(&format!("{n} corrupt records")),
                        "{e}"
                    );
                }
                other => panic!("{other:?}"),
            }
            println!(
                "{n} corrupt records (interleaved {interleaved}): recover peak {peak} bytes, replay peak {replay_peak} bytes"
            );
            peaks.push((peak, replay_peak));
        }
        // 18,000 more records: not 18,000 more entries (about 5 MB before).
        let (a, b) = (peaks[0], peaks[1]);
        assert!(b.0 < a.0 + 256 * 1024, "recover peaks {peaks:?}");
        assert!(b.1 < a.1 + 256 * 1024, "replay peaks {peaks:?}");
    }
}
