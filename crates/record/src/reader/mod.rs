//! Reading a recording record by record, and recovering one cut short.
//!
//! [`McapReader`] walks the data section: each chunk is decompressed and
//! checked (CRC) whole before any of its messages is given out, so a file cut
//! short by a crash or a power loss yields every message of its complete
//! chunks, then one [`ReadError::Truncated`] saying where it stopped. It never
//! panics on a prefix of a valid file. [`recover`] rewrites such a file into a
//! complete one (summary, chunk and message indexes).
//!
//! The modules: `error` ([`ReadError`]), `info` (channels, schemas,
//! messages), `skipped` (corrupt records passed over), `parse` (one
//! record's bytes, a chunk decompressed), `walk` (the data section, record
//! by record), `iter` (the reader as iterators), `files` (opening, reading
//! whole, the retained bound), `recover`.

mod error;
mod files;
mod info;
mod iter;
mod parse;
mod recover;
mod skipped;
mod walk;

pub use error::ReadError;
pub use files::{
    RETAINED_BASE_BYTES, RETAINED_PER_FILE_BYTE, open_regular, read_file, retained_limit,
};
pub use info::{ChannelInfo, MessageRef, RawMessage, SchemaInfo, Visitor};
pub use parse::{MAX_CHUNK_BYTES, MAX_RECORD_BYTES};
pub use recover::{RecoverError, RecoverReport, recover};
pub use skipped::{MAX_SKIPPED_SHOWN, Skipped, SkippedTally};

use mcap::records::op;
use parse::RECORD_PREFIX;
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where a reader's bytes come from: memory, or a file read record by
/// record into one reused buffer (memory bounded by the largest record,
/// whatever the file's length).
///
/// (Reading ahead on a thread of its own was tried: on these 2-core virtual
/// machines it made a streamed replay slower, 0.60 M against 0.97 M cycles/s,
/// so the file is read on the caller's thread.)
#[derive(Debug)]
enum Source<'a> {
    Bytes(&'a [u8]),
    File {
        file: std::fs::File,
        path: PathBuf,
        len: u64,
        /// The current record's bytes (prefix and body).
        buf: Vec<u8>,
    },
}

/// Iterates over the messages of an MCAP file, in file order: held in
/// memory ([`McapReader::new`]) or streamed from disk ([`McapReader::open`],
/// one record at a time: memory bounded by the largest chunk, not by the
/// file).
///
/// Ends with `None` after the data section (or the footer); a file cut short
/// ends with one `Err` (`Truncated`, `Unfinished` or `Corrupt`) after the last
/// message of its last complete chunk.
#[derive(Debug)]
pub struct McapReader<'a> {
    source: Source<'a>,
    pos: usize,
    schemas: BTreeMap<u16, Arc<SchemaInfo>>,
    channels: BTreeMap<u16, ChannelInfo>,
    /// The bytes the schemas, channels and metadata read so far hold
    /// (counted as [`McapReader::retained_bytes`] says), against
    /// [`retained_limit`].
    retained: u64,
    /// The ids of `channels`, one bit each (bit `id % 64` of word `id / 64`):
    /// the check that every message's channel is known, without a map
    /// lookup per message.
    known_channels: Vec<u64>,
    metadata: Vec<mcap::records::Metadata>,
    profile: Option<String>,
    pending: VecDeque<RawMessage>,
    done: bool,
    complete: bool,
    /// The current chunk's records, decompressed (reused: one allocation
    /// for the largest chunk).
    chunk: Vec<u8>,
    /// The zstd context, made at the first compressed chunk and reused.
    zstd: Option<ZstdContext>,
    /// The record being read: its offset and length (prefix included),
    /// once the file holds all of it (a corrupt one can be skipped).
    current: Option<(u64, u64)>,
}

/// A reused zstd decompression context.
struct ZstdContext(zstd::bulk::Decompressor<'static>);

impl std::fmt::Debug for ZstdContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ZstdContext")
    }
}

impl McapReader<'static> {
    /// Opens `path` for streaming (checks the magic): records are read one
    /// at a time, so memory does not grow with the file.
    pub fn open(path: &Path) -> Result<Self, ReadError> {
        use std::io::Read;
        let io = |source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut file = open_regular(path)?;
        let len = file.metadata().map_err(io)?.len();
        let mut magic = [0u8; 8];
        let got = (&mut file).take(8).read(&mut magic).map_err(io)?;
        if got < magic.len() || magic.as_slice() != mcap::MAGIC {
            return Err(ReadError::NotMcap {
                len: usize::try_from(len.min(8)).unwrap_or(8),
            });
        }
        Ok(Self::with_source(Source::File {
            file,
            path: path.to_path_buf(),
            len,
            buf: Vec::new(),
        }))
    }
}

impl<'a> McapReader<'a> {
    /// Checks the magic.
    pub fn new(bytes: &'a [u8]) -> Result<Self, ReadError> {
        if bytes.get(..mcap::MAGIC.len()) != Some(mcap::MAGIC) {
            return Err(ReadError::NotMcap {
                len: bytes.len().min(8),
            });
        }
        Ok(Self::with_source(Source::Bytes(bytes)))
    }

    fn with_source(source: Source<'a>) -> Self {
        Self {
            source,
            pos: mcap::MAGIC.len(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            retained: 0,
            known_channels: Vec::new(),
            metadata: Vec::new(),
            profile: None,
            pending: VecDeque::new(),
            done: false,
            complete: false,
            chunk: Vec::new(),
            zstd: None,
            current: None,
        }
    }

    /// After an error at a complete but corrupt record (a chunk whose
    /// compressed data, CRC or content is bad; a record that does not
    /// parse), passes over it so that the iteration goes on with the
    /// records after it; `why` is the error's text. `None` when there is
    /// nothing to pass over: the iteration did not stop at such a record
    /// (a file cut short ends there: what follows is not in it).
    pub fn skip_bad_record(&mut self, why: &dyn std::fmt::Display) -> Option<Skipped> {
        if !self.done || self.complete {
            return None;
        }
        let (offset, bytes) = self.current.take()?;
        let end = usize::try_from(offset.saturating_add(bytes)).ok()?;
        if end <= self.pos {
            return None;
        }
        // The chunk header's message times, when they parse.
        let log_time_ns = self.chunk_times(offset, bytes);
        self.pos = end;
        self.done = false;
        Some(Skipped {
            offset,
            bytes,
            log_time_ns,
            why: why.to_string(),
            records: 1,
        })
    }

    /// The message times of the chunk at `offset` (from its header), if
    /// it is one and they can be read.
    fn chunk_times(&mut self, offset: u64, bytes: u64) -> Option<(u64, u64)> {
        const TIMES: usize = RECORD_PREFIX + 16;
        let head: Vec<u8> = match &mut self.source {
            Source::Bytes(b) => {
                let at = usize::try_from(offset).ok()?;
                b.get(at..at.checked_add(TIMES)?)?.to_vec()
            }
            Source::File { file, .. } => {
                use std::io::{Read, Seek, SeekFrom};
                let mut head = vec![0u8; TIMES];
                file.seek(SeekFrom::Start(offset)).ok()?;
                file.read_exact(&mut head).ok()?;
                head
            }
        };
        if head.first() != Some(&op::CHUNK) || bytes < TIMES as u64 {
            return None;
        }
        let word = |at: usize| {
            head.get(at..at + 8)
                .and_then(|w| <[u8; 8]>::try_from(w).ok())
                .map(u64::from_le_bytes)
        };
        Some((word(RECORD_PREFIX)?, word(RECORD_PREFIX + 8)?))
    }

    /// The channels seen so far (all of them once the iteration has ended).
    pub fn channels(&self) -> &BTreeMap<u16, ChannelInfo> {
        &self.channels
    }

    /// The channel of a topic, if seen.
    pub fn channel_of(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.values().find(|c| c.topic == topic)
    }

    /// The metadata records seen so far.
    pub fn metadata(&self) -> &[mcap::records::Metadata] {
        &self.metadata
    }

    /// The header's profile.
    pub fn profile(&self) -> Option<&str> {
        self.profile.as_deref()
    }

    /// Whether the data section was read to its end (false for a file cut
    /// short, or before the iteration ended).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// The file's (or the bytes') length.
    pub fn total_bytes(&self) -> u64 {
        match &self.source {
            Source::Bytes(b) => b.len() as u64,
            Source::File { len, .. } => *len,
        }
    }

    /// The offset up to which the file has been read (the end of the last
    /// complete record).
    pub fn offset(&self) -> u64 {
        self.pos as u64
    }

    /// The bytes the schemas, channels and metadata read so far hold: each
    /// distinct schema once (every channel shares it), each channel and
    /// metadata record with its strings, plus a fixed allowance per entry
    /// for the maps. At most [`retained_limit`] of the file's length.
    pub fn retained_bytes(&self) -> u64 {
        self.retained
    }
}
