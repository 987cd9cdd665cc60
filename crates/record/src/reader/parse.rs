//! One record's bytes: its prefix and body checked against what the file
//! holds, read whole from a file, a chunk decompressed (sizes bounded before
//! anything is allocated), the retained bytes' costs.

use super::ZstdContext;
use super::error::ReadError;
use super::info::ChannelInfo;
use std::collections::BTreeMap;
use std::path::Path;

pub(super) const RECORD_PREFIX: usize = 9;
/// A message record's header: channel id, sequence, log and publish time.
pub(super) const MESSAGE_HEADER: usize = 2 + 4 + 8 + 8;

/// The largest uncompressed chunk read (the recorder writes 256 KiB chunks;
/// other writers rarely exceed a few MiB). A larger size is taken as corrupt.
pub const MAX_CHUNK_BYTES: u64 = 256 * 1024 * 1024;

/// The error of a record (`opcode`, at `offset`) the mcap crate's parser
/// refused.
pub(super) fn corrupt(offset: u64, opcode: u8) -> impl Fn(mcap::McapError) -> ReadError {
    move |source| ReadError::Corrupt {
        offset,
        opcode,
        source,
    }
}

/// The record at the start of `rest` (at `offset`, with `available` bytes
/// left in the file): its opcode, its body and its length with the prefix,
/// or why it is not whole.
pub(super) fn record_parts(
    rest: &[u8],
    offset: u64,
    available: u64,
) -> Result<(u8, &[u8], u64), ReadError> {
    if rest.is_empty() {
        return Err(ReadError::Unfinished { offset });
    }
    let opcode = rest.first().copied();
    let Some((prefix, after)) = rest.split_first_chunk::<RECORD_PREFIX>() else {
        return Err(ReadError::Truncated {
            offset,
            opcode,
            needed: RECORD_PREFIX as u64,
            available,
        });
    };
    let [op_byte, len_bytes @ ..] = *prefix;
    let len = u64::from_le_bytes(len_bytes);
    let needed = len.saturating_add(RECORD_PREFIX as u64);
    let body = usize::try_from(len)
        .ok()
        .and_then(|n| after.get(..n))
        .ok_or_else(|| ReadError::Truncated {
            offset,
            opcode,
            needed,
            available,
        })?;
    Ok((op_byte, body, needed))
}

/// The allowance of one map entry (its node and its allocations), bytes.
pub(super) const ENTRY_OVERHEAD: u64 = 128;

/// What an entry of strings of these lengths holds, bytes.
pub(super) fn entry_cost(lens: [usize; 3]) -> u64 {
    lens.iter()
        .fold(ENTRY_OVERHEAD, |a, n| a.saturating_add(*n as u64))
}

/// The bytes of a string map's keys and values, with an allowance per entry.
pub(super) fn map_bytes(m: &BTreeMap<String, String>) -> usize {
    m.iter()
        .map(|(k, v)| k.len() + v.len() + 64)
        .fold(0usize, usize::saturating_add)
}

/// Whether a channel record says again what `known` holds.
pub(super) fn same_channel(known: &ChannelInfo, c: &mcap::records::Channel) -> bool {
    known.topic == c.topic
        && known.message_encoding == c.message_encoding
        && known.schema_id == c.schema_id
        && known.metadata == c.metadata
}

/// The largest record read from a file (a chunk's compressed bytes and its
/// header): a larger length is taken as corrupt, so that a bad length never
/// makes the reader allocate it.
pub const MAX_RECORD_BYTES: u64 = MAX_CHUNK_BYTES + 1024 * 1024;

/// Reads the record at `pos` of `file` into `buf`: its prefix, then its body
/// when the file holds all of it (else the prefix alone, which the caller
/// reports as cut short).
pub(super) fn fill_record(
    file: &mut std::fs::File,
    path: &Path,
    pos: u64,
    available: u64,
    buf: &mut Vec<u8>,
) -> Result<(), ReadError> {
    use std::io::{Read, Seek, SeekFrom};
    let io = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut read = |buf: &mut Vec<u8>, n: u64| -> Result<(), ReadError> {
        buf.clear();
        // Exactly the record: a reused buffer grows to the largest once.
        buf.reserve_exact(usize::try_from(n).unwrap_or(0));
        file.seek(SeekFrom::Start(pos)).map_err(io)?;
        (&mut *file).take(n).read_to_end(buf).map_err(io)?;
        Ok(())
    };
    let head = available.min(RECORD_PREFIX as u64);
    read(buf, head)?;
    let Some((prefix, _)) = buf.split_first_chunk::<RECORD_PREFIX>() else {
        return Ok(());
    };
    let [_, len_bytes @ ..] = *prefix;
    let len = u64::from_le_bytes(len_bytes);
    let needed = len.saturating_add(RECORD_PREFIX as u64);
    if needed > available {
        return Ok(());
    }
    if len > MAX_RECORD_BYTES {
        return Err(ReadError::RecordTooLarge {
            offset: pos,
            len,
            limit: MAX_RECORD_BYTES,
        });
    }
    read(buf, needed)
}

/// The chunk's records, decompressed into `content` (its allocation reused)
/// and checked against its CRC, or why not.
pub(super) fn decompress(
    zstd: &mut Option<ZstdContext>,
    header: &mcap::records::ChunkHeader,
    data: &[u8],
    offset: u64,
    content: &mut Vec<u8>,
) -> Result<(), ReadError> {
    let size = usize::try_from(header.uncompressed_size).unwrap_or(usize::MAX);
    let bad = |why: &'static str| ReadError::BadChunkContent { offset, at: 0, why };
    content.clear();
    match header.compression.as_str() {
        "" => content.extend_from_slice(data),
        "zstd" => {
            // The header's size is bounded (MAX_CHUNK_BYTES) by the caller.
            content.reserve_exact(size);
            let context = match zstd {
                Some(c) => c,
                None => zstd.insert(ZstdContext(
                    zstd::bulk::Decompressor::new()
                        .map_err(|_| bad("zstd could not make its context"))?,
                )),
            };
            // Writes at most the capacity: a frame larger than the header
            // says is refused, not grown into.
            context
                .0
                .decompress_to_buffer(data, &mut *content)
                .map_err(|_| bad("zstd refused the data"))?;
        }
        _ => return Err(bad("compression other than zstd or none")),
    }
    if content.len() != size {
        return Err(bad("the size differs from the chunk header's"));
    }
    if header.uncompressed_crc != 0 && crc32fast::hash(content) != header.uncompressed_crc {
        return Err(bad("the CRC differs from the chunk header's"));
    }
    Ok(())
}
