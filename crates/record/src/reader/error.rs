//! Why a recording cannot be read ([`ReadError`]).

use sar_msgs::cdr::CdrError;
use std::path::PathBuf;

/// Why reading stopped or a message could not be decoded.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be opened or read (a read error: the disk, the
    /// permissions).
    #[error("{path}: read error: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The path is not a regular file (a FIFO, a device, a directory,
    /// a socket): refused before it is opened (a FIFO would block).
    #[error("{path}: not a regular file ({kind}): give a recording's file")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The file does not start with the MCAP magic.
    #[error("not an MCAP file (the first {len} bytes are not the MCAP magic)")]
    NotMcap {
        /// Bytes in the file (up to 8 looked at).
        len: usize,
    },
    /// The file ends inside a record: everything before `offset` was read.
    #[error(
        "truncated at byte {offset}: the file ends inside a record (opcode {opcode:?}, {needed} bytes needed, {available} available): read up to there"
    )]
    Truncated {
        /// Offset of the incomplete record: the end of the last complete one.
        offset: u64,
        /// Its opcode, when the file holds it.
        opcode: Option<u8>,
        /// Bytes the record needs (opcode, length and body).
        needed: u64,
        /// Bytes left in the file.
        available: u64,
    },
    /// The file ends after a complete record but before the data section's end
    /// (no data-end record, no footer): all of it was read.
    #[error(
        "truncated at byte {offset}: the file ends there without a data-end record or footer: read up to there"
    )]
    Unfinished {
        /// The file's length.
        offset: u64,
    },
    /// A complete record could not be parsed (bad CRC, bad compression, ...).
    #[error("record at byte {offset} (opcode {opcode:#04x}) is corrupt: {source}")]
    Corrupt {
        /// Its offset.
        offset: u64,
        /// Its opcode.
        opcode: u8,
        /// The cause.
        source: mcap::McapError,
    },
    /// A chunk claims more uncompressed bytes than [`MAX_CHUNK_BYTES`].
    #[error(
        "chunk at byte {offset} claims {uncompressed_size} uncompressed bytes (limit {limit}): corrupt"
    )]
    ChunkTooLarge {
        /// Its offset.
        offset: u64,
        /// The size it claims.
        uncompressed_size: u64,
        /// The limit.
        limit: u64,
    },
    /// A record read from a file claims a length beyond any chunk's.
    #[error("record at byte {offset} claims {len} bytes (limit {limit}): corrupt")]
    RecordTooLarge {
        /// Its offset.
        offset: u64,
        /// The length it claims.
        len: u64,
        /// The limit.
        limit: u64,
    },
    /// The schemas, channels and metadata read would hold more than a file
    /// of this length can honestly need ([`retained_limit`]).
    #[error(
        "the schemas, channels and metadata read up to byte {offset} would hold {retained} bytes, more than {limit} for a file of {file_bytes} bytes: corrupt or crafted"
    )]
    TooMuchMetadata {
        /// The record (or its chunk) that would exceed the limit.
        offset: u64,
        /// What the reader would hold with it, bytes.
        retained: u64,
        /// The limit, bytes.
        limit: u64,
        /// The file's length.
        file_bytes: u64,
    },
    /// A chunk's content is not what its header says.
    #[error("chunk at byte {offset}: {why} (at byte {at} of its content)")]
    BadChunkContent {
        /// The chunk's offset.
        offset: u64,
        /// Offset within the uncompressed content.
        at: u64,
        /// What is wrong.
        why: &'static str,
    },
    /// A message names a channel not defined before it.
    #[error("message at byte {offset} names unknown channel {channel_id}")]
    UnknownChannel {
        /// Offset of the record (or its chunk).
        offset: u64,
        /// The channel.
        channel_id: u16,
    },
    /// A topic's schema is not the type asked for.
    #[error("topic {topic} has type {found}, not {expected}")]
    WrongType {
        /// The topic.
        topic: String,
        /// The type asked for.
        expected: &'static str,
        /// The schema's name.
        found: String,
    },
    /// A message could not be decoded.
    #[error("{topic} message at log time {log_time_ns} ns: {source}")]
    Decode {
        /// The topic.
        topic: String,
        /// Its log time.
        log_time_ns: u64,
        /// The cause.
        source: CdrError,
    },
}
