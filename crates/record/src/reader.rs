//! Reading a recording record by record, and recovering one cut short.
//!
//! [`McapReader`] walks the data section: each chunk is decompressed and
//! checked (CRC) whole before any of its messages is given out, so a file cut
//! short by a crash or a power loss yields every message of its complete
//! chunks, then one [`ReadError::Truncated`] saying where it stopped. It never
//! panics on a prefix of a valid file. [`recover`] rewrites such a file into a
//! complete one (summary, chunk and message indexes).

use super::file::{CountingFile, FileOptions};
use mcap::records::{Record, op};
use sar_msgs::cdr::CdrError;
use sar_msgs::msgs::{Outgoing, RosMessage, Topic};
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

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

/// A schema of the recording, shared by every channel that names it (one
/// copy, however many channels: a schema of 2 MiB named by 4000 channels
/// is 2 MiB, not 8 GB).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema name (the ROS 2 type).
    pub name: String,
    /// Schema encoding (`ros2msg`).
    pub encoding: String,
    /// Schema text.
    pub data: Vec<u8>,
}

/// A channel of the recording with its schema.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel id.
    pub id: u16,
    /// Topic.
    pub topic: String,
    /// Message encoding (`cdr`).
    pub message_encoding: String,
    /// Schema id (0: none).
    pub schema_id: u16,
    /// The schema (`None`: no schema, or one not defined before the
    /// channel), shared with the reader and the other channels.
    pub schema: Option<Arc<SchemaInfo>>,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
}

impl ChannelInfo {
    /// Schema name (the ROS 2 type), empty without schema.
    pub fn schema_name(&self) -> &str {
        self.schema.as_deref().map_or("", |s| s.name.as_str())
    }
    /// Schema encoding (`ros2msg`), empty without schema.
    pub fn schema_encoding(&self) -> &str {
        self.schema.as_deref().map_or("", |s| s.encoding.as_str())
    }
    /// Schema text, empty without schema.
    pub fn schema_data(&self) -> &[u8] {
        self.schema.as_deref().map_or(&[], |s| s.data.as_slice())
    }
}

/// One message as recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    /// Channel id.
    pub channel_id: u16,
    /// Sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The CDR bytes.
    pub data: Vec<u8>,
}

/// One message as recorded, borrowed from the reader's current chunk (see
/// [`McapReader::visit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageRef<'m> {
    /// Channel id.
    pub channel_id: u16,
    /// Sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The CDR bytes.
    pub data: &'m [u8],
}

impl MessageRef<'_> {
    /// An owned copy.
    pub fn to_owned_message(&self) -> RawMessage {
        RawMessage {
            channel_id: self.channel_id,
            sequence: self.sequence,
            log_time_ns: self.log_time_ns,
            publish_time_ns: self.publish_time_ns,
            data: self.data.to_vec(),
        }
    }
}

/// The callback of [`McapReader::visit`] as a trait object: the channels
/// known so far and one message. (`visit` takes any such closure; a concrete
/// one is inlined into the record loop, the hot path of a replay.)
pub type Visitor<'v, E> =
    dyn FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> + 'v;

/// The bound of the record loop's callback: any closure of the [`Visitor`]
/// shape, or a [`Visitor`] itself.
trait OnMessage<E>: FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> {}

impl<E, F> OnMessage<E> for F where
    F: FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> + ?Sized
{
}

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

/// A corrupt record passed over by [`McapReader::skip_bad_record`], or a
/// run of them one after the other ([`Skipped::absorb`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// Its offset in the file.
    pub offset: u64,
    /// Its length, prefix included (the bytes skipped).
    pub bytes: u64,
    /// The log times of its messages (a chunk's header, when readable), ns.
    pub log_time_ns: Option<(u64, u64)>,
    /// Why it was refused (the first of a run).
    pub why: String,
    /// The corrupt records in it: 1, or a run's length.
    pub records: u64,
}

impl Skipped {
    /// Takes `next` into this one when it starts where this one ends (a
    /// run of corrupt records is one part passed over); false otherwise.
    pub fn absorb(&mut self, next: &Skipped) -> bool {
        if self.bytes == 0
            || next.bytes == 0
            || self.offset.saturating_add(self.bytes) != next.offset
        {
            return false;
        }
        self.bytes = self.bytes.saturating_add(next.bytes);
        self.records = self.records.saturating_add(next.records);
        self.log_time_ns = match (self.log_time_ns, next.log_time_ns) {
            (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
            (a, b) => a.or(b),
        };
        true
    }

    /// "N bytes at byte X (why)", with the records of a run.
    pub fn describe(&self) -> String {
        format!(
            "{} bytes at byte {}{} ({})",
            self.bytes,
            self.offset,
            if self.records > 1 {
                format!(", {} corrupt records in a row", self.records)
            } else {
                String::new()
            },
            self.why
        )
    }
}

/// The most corrupt parts kept in detail ([`SkippedTally`]); the rest are
/// counted.
pub const MAX_SKIPPED_SHOWN: usize = 16;

/// The corrupt records a reading passed over, in bounded memory: the first
/// [`MAX_SKIPPED_SHOWN`] parts in detail (a run of records one after the
/// other is one part), and the count and bytes of every one.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SkippedTally {
    /// The first parts, in file order.
    pub shown: Vec<Skipped>,
    /// Every corrupt record passed over.
    pub records: u64,
    /// Their bytes.
    pub bytes: u64,
    /// The parts (runs) in all, shown or not.
    pub parts: u64,
}

impl SkippedTally {
    /// Counts `s`; kept in detail if it continues the last part or there
    /// is room.
    pub fn add(&mut self, s: Skipped) {
        self.records = self.records.saturating_add(s.records);
        self.bytes = self.bytes.saturating_add(s.bytes);
        if let Some(last) = self.shown.last_mut()
            && last.absorb(&s)
        {
            return;
        }
        self.parts = self.parts.saturating_add(1);
        if self.shown.len() < MAX_SKIPPED_SHOWN {
            self.shown.push(s);
        }
    }

    /// Whether nothing was passed over.
    pub fn is_empty(&self) -> bool {
        self.records == 0
    }

    /// One line: how many records and bytes in how many parts, the first
    /// ones named.
    pub fn summary(&self) -> String {
        let shown: Vec<String> = self.shown.iter().map(Skipped::describe).collect();
        format!(
            "{} corrupt records ({} bytes) in {} part(s) passed over{}: {}",
            self.records,
            self.bytes,
            self.parts,
            if self.parts > self.shown.len() as u64 {
                format!(", the first {} named", self.shown.len())
            } else {
                String::new()
            },
            shown.join("; ")
        )
    }
}

/// A reused zstd decompression context.
struct ZstdContext(zstd::bulk::Decompressor<'static>);

impl std::fmt::Debug for ZstdContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ZstdContext")
    }
}

const RECORD_PREFIX: usize = 9;
/// A message record's header: channel id, sequence, log and publish time.
const MESSAGE_HEADER: usize = 2 + 4 + 8 + 8;

/// The largest uncompressed chunk read (the recorder writes 256 KiB chunks;
/// other writers rarely exceed a few MiB). A larger size is taken as corrupt.
pub const MAX_CHUNK_BYTES: u64 = 256 * 1024 * 1024;

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

    /// Notes a schema, channel or metadata record read at `offset` (a
    /// record of the data section, or of the chunk there); refused when
    /// what the reader holds would exceed [`retained_limit`] (a crafted
    /// file: small records in a compressed chunk, or many of them).
    fn apply(&mut self, record: Record<'_>, offset: u64) -> Result<(), ReadError> {
        let Some(cost) = self.cost_of(&record) else {
            // Written again (some writers repeat them per chunk).
            return Ok(());
        };
        let retained = self.retained.saturating_add(cost);
        let limit = retained_limit(self.total_bytes());
        if retained > limit {
            return Err(ReadError::TooMuchMetadata {
                offset,
                retained,
                limit,
                file_bytes: self.total_bytes(),
            });
        }
        self.retained = retained;
        match record {
            Record::Header(h) => self.profile = Some(h.profile),
            Record::Schema { header, data } => {
                self.schemas.insert(
                    header.id,
                    Arc::new(SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    }),
                );
            }
            Record::Channel(c) => {
                let info = ChannelInfo {
                    id: c.id,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                    schema_id: c.schema_id,
                    schema: self.schemas.get(&c.schema_id).cloned(),
                    metadata: c.metadata,
                };
                let (word, bit) = (usize::from(c.id / 64), c.id % 64);
                if self.known_channels.len() <= word {
                    self.known_channels.resize(word + 1, 0);
                }
                if let Some(w) = self.known_channels.get_mut(word) {
                    *w |= 1 << bit;
                }
                self.channels.insert(c.id, info);
            }
            Record::Metadata(m) => self.metadata.push(m),
            _ => {}
        }
        Ok(())
    }

    /// What a schema, channel or metadata record would add to what the
    /// reader holds ([`McapReader::retained_bytes`]); `None` for one that
    /// says again what it holds.
    fn cost_of(&self, record: &Record<'_>) -> Option<u64> {
        Some(match record {
            Record::Schema { header, data } => {
                let same = self.schemas.get(&header.id).is_some_and(|s| {
                    s.name == header.name && s.encoding == header.encoding && *s.data == **data
                });
                if same {
                    return None;
                }
                entry_cost([header.name.len(), header.encoding.len(), data.len()])
            }
            Record::Channel(c) => {
                if self.channels.get(&c.id).is_some_and(|k| same_channel(k, c)) {
                    return None;
                }
                entry_cost([
                    c.topic.len(),
                    c.message_encoding.len(),
                    map_bytes(&c.metadata),
                ])
            }
            Record::Metadata(m) => entry_cost([m.name.len(), map_bytes(&m.metadata), 0]),
            _ => 0,
        })
    }

    /// Whether a channel record with this id has been read.
    fn is_known(&self, channel_id: u16) -> bool {
        self.known_channels
            .get(usize::from(channel_id / 64))
            .is_some_and(|w| w & (1 << (channel_id % 64)) != 0)
    }

    /// Hands one message record's body to `on_msg` (its channel must be
    /// known).
    fn message<E, F: OnMessage<E> + ?Sized>(
        &self,
        body: &[u8],
        offset: u64,
        opcode: u8,
        on_msg: &mut F,
    ) -> Result<Result<(), E>, ReadError> {
        // The message header by hand (channel u16, sequence u32, log and
        // publish times u64, little-endian; MCAP spec): the hot path of a
        // replay. A body too short for it goes to the mcap crate's parser
        // for its error.
        let Some((&header, data)) = body.split_first_chunk::<MESSAGE_HEADER>() else {
            let source = match mcap::parse_record(opcode, body) {
                Err(source) => source,
                Ok(_) => mcap::McapError::UnexpectedEof,
            };
            return Err(ReadError::Corrupt {
                offset,
                opcode,
                source,
            });
        };
        let [
            c0,
            c1,
            s0,
            s1,
            s2,
            s3,
            l0,
            l1,
            l2,
            l3,
            l4,
            l5,
            l6,
            l7,
            p @ ..,
        ] = header;
        let channel_id = u16::from_le_bytes([c0, c1]);
        if !self.is_known(channel_id) {
            return Err(ReadError::UnknownChannel { offset, channel_id });
        }
        Ok(on_msg(
            &self.channels,
            MessageRef {
                channel_id,
                sequence: u32::from_le_bytes([s0, s1, s2, s3]),
                log_time_ns: u64::from_le_bytes([l0, l1, l2, l3, l4, l5, l6, l7]),
                publish_time_ns: u64::from_le_bytes(p),
                data,
            },
        ))
    }

    /// Reads the next record for the iterator (its messages queued).
    fn step(&mut self) -> Result<bool, ReadError> {
        let mut queued = std::mem::take(&mut self.pending);
        let mut queue = |_: &BTreeMap<u16, ChannelInfo>, m: MessageRef<'_>| {
            queued.push_back(m.to_owned_message());
            Ok::<(), std::convert::Infallible>(())
        };
        let result = self.step_with(&mut queue);
        self.pending = queued;
        match result {
            Ok(r) => r,
            Err(never) => match never {},
        }
    }

    /// Every message, in file order, handed to `f` without a copy (the
    /// iterator's way with no allocation per message). Returns `Ok(None)` at
    /// the end of the data section, `Ok(Some(e))` where a file cut short or
    /// corrupt stops (after the messages of its last complete chunk;
    /// [`McapReader::is_complete`] tells), and `Err` when `f` fails.
    pub fn visit<E>(
        &mut self,
        f: &mut (impl FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> + ?Sized),
    ) -> Result<Option<ReadError>, E> {
        // Queued by an earlier iteration first.
        while let Some(m) = self.pending.pop_front() {
            f(
                &self.channels,
                MessageRef {
                    channel_id: m.channel_id,
                    sequence: m.sequence,
                    log_time_ns: m.log_time_ns,
                    publish_time_ns: m.publish_time_ns,
                    data: &m.data,
                },
            )?;
        }
        while !self.done {
            let stepped = self.step_with(f)?;
            if let Some(e) = self.after_step(stepped) {
                return Ok(Some(e));
            }
        }
        Ok(None)
    }

    /// How a record's step ended, noted: the end of the data section (the
    /// file complete), or where the file stops (`Some`: cut or corrupt).
    #[inline]
    fn after_step(&mut self, stepped: Result<bool, ReadError>) -> Option<ReadError> {
        match stepped {
            Ok(true) => None,
            Ok(false) => {
                self.done = true;
                self.complete = true;
                None
            }
            Err(e) => {
                self.done = true;
                Some(e)
            }
        }
    }

    /// Reads the next record, handing its messages to `on_msg`; Ok(Ok(false))
    /// at the end of the data section.
    fn step_with<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        on_msg: &mut F,
    ) -> Result<Result<bool, ReadError>, E> {
        match self.step_inner(on_msg) {
            Ok(Ok(more)) => Ok(Ok(more)),
            Ok(Err(e)) => Err(e),
            Err(e) => Ok(Err(e)),
        }
    }

    fn step_inner<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        on_msg: &mut F,
    ) -> Result<Result<bool, E>, ReadError> {
        match &mut self.source {
            Source::Bytes(bytes) => {
                let bytes: &'a [u8] = bytes;
                let rest = bytes.get(self.pos..).unwrap_or(&[]);
                self.step_on(rest, rest.len() as u64, on_msg)
            }
            Source::File {
                file,
                path,
                len,
                buf,
            } => {
                let available = len.saturating_sub(self.pos as u64);
                let mut record = std::mem::take(buf);
                let filled = fill_record(file, path, self.pos as u64, available, &mut record);
                let result = filled.and_then(|()| self.step_on(&record, available, on_msg));
                if let Source::File { buf, .. } = &mut self.source {
                    *buf = record;
                }
                result
            }
        }
    }

    /// One record from `rest` (the bytes from `self.pos`: all of them in
    /// memory, or the record alone from a file), with `available` bytes
    /// left in the file.
    fn step_on<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        rest: &[u8],
        available: u64,
        on_msg: &mut F,
    ) -> Result<Result<bool, E>, ReadError> {
        let offset = self.pos as u64;
        self.current = None;
        let (op_byte, body, needed) = record_parts(rest, offset, available)?;
        // Whole in the file: a corrupt one can be passed over.
        self.current = Some((offset, needed));
        match op_byte {
            op::FOOTER | op::DATA_END => {
                self.pos += RECORD_PREFIX + body.len();
                return Ok(Ok(false));
            }
            op::CHUNK => return self.chunk(body, offset, on_msg),
            op::MESSAGE => {
                let sent = self.message(body, offset, op_byte, on_msg)?;
                self.pos += RECORD_PREFIX + body.len();
                return Ok(sent.map(|()| true));
            }
            op::HEADER | op::SCHEMA | op::CHANNEL | op::METADATA => {
                let record = mcap::parse_record(op_byte, body).map_err(corrupt(offset, op_byte))?;
                self.apply(record, offset)?;
            }
            _ => {}
        }
        self.pos += RECORD_PREFIX + body.len();
        Ok(Ok(true))
    }

    /// A chunk record's `body` at `offset`: the whole chunk decompressed
    /// and checked before any of its messages is given out, then its
    /// records.
    fn chunk<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        body: &[u8],
        offset: u64,
        on_msg: &mut F,
    ) -> Result<Result<bool, E>, ReadError> {
        let Record::Chunk { header, data } =
            mcap::parse_record(op::CHUNK, body).map_err(corrupt(offset, op::CHUNK))?
        else {
            // Not a chunk after all: skip the record (never read the
            // same one again).
            self.pos += RECORD_PREFIX + body.len();
            return Ok(Ok(true));
        };
        // A corrupt size must not make us allocate it.
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return Err(ReadError::ChunkTooLarge {
                offset,
                uncompressed_size: header.uncompressed_size,
                limit: MAX_CHUNK_BYTES,
            });
        }
        let mut content = std::mem::take(&mut self.chunk);
        decompress(&mut self.zstd, &header, &data, offset, &mut content)?;
        let result = self.chunk_records(&content, offset, body.len(), on_msg);
        self.chunk = content;
        result
    }

    /// The records of a chunk (`content`, decompressed and checked) of
    /// `chunk_len` bytes at `offset`: messages to `on_msg`, schemas and
    /// channels noted.
    fn chunk_records<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        content: &[u8],
        offset: u64,
        chunk_len: usize,
        on_msg: &mut F,
    ) -> Result<Result<bool, E>, ReadError> {
        let mut at = 0usize;
        while at < content.len() {
            let inner = content.get(at..).unwrap_or(&[]);
            let bad = |why: &'static str| ReadError::BadChunkContent {
                offset,
                at: at as u64,
                why,
            };
            let (prefix, after) = inner
                .split_first_chunk::<RECORD_PREFIX>()
                .ok_or_else(|| bad("a record prefix is cut"))?;
            let [inner_op, len_bytes @ ..] = *prefix;
            let body = usize::try_from(u64::from_le_bytes(len_bytes))
                .ok()
                .and_then(|n| after.get(..n))
                .ok_or_else(|| bad("a record is longer than the chunk"))?;
            if inner_op == op::MESSAGE {
                if let Err(e) = self.message(body, offset, inner_op, on_msg)? {
                    // The callback failed: stop after this record.
                    self.pos += RECORD_PREFIX + chunk_len;
                    return Ok(Err(e));
                }
            } else if matches!(inner_op, op::SCHEMA | op::CHANNEL) {
                let record =
                    mcap::parse_record(inner_op, body).map_err(corrupt(offset, op::CHUNK))?;
                self.apply(record, offset)?;
            }
            at += RECORD_PREFIX + body.len();
        }
        self.pos += RECORD_PREFIX + chunk_len;
        Ok(Ok(true))
    }

    /// Every message of the SAR topics ([`Topic`]) decoded, with its topic and
    /// log time; other topics are skipped, and so are the snapshots
    /// (`/sar/cycle/snapshot`, variable length: decode the raw message with
    /// [`sar_msgs::msgs::StateSnapshot`]).
    pub fn decoded(self) -> impl Iterator<Item = Result<(Topic, u64, Outgoing), ReadError>> + 'a {
        self.picked(|channel, msg| {
            let Some(topic) = Topic::from_name(&channel.topic) else {
                return Pick::Skip;
            };
            if matches!(topic, Topic::StateSnapshot | Topic::CycleBatch) {
                return Pick::Skip;
            }
            if channel.schema_name() != topic.type_name() {
                return Pick::Fail(ReadError::WrongType {
                    topic: channel.topic.clone(),
                    expected: topic.type_name(),
                    found: channel.schema_name().to_owned(),
                });
            }
            Pick::Give(
                Outgoing::decode(topic, &msg.data)
                    .map(|m| (topic, msg.log_time_ns, m))
                    .map_err(|source| ReadError::Decode {
                        topic: channel.topic.clone(),
                        log_time_ns: msg.log_time_ns,
                        source,
                    }),
            )
        })
    }

    /// The messages of `topic` decoded as `M` (the topic's schema must be
    /// `M::TYPE_NAME`), with their log times. Other topics are skipped.
    pub fn typed<M: RosMessage + 'a>(
        self,
        topic: &'a str,
    ) -> impl Iterator<Item = Result<(u64, M), ReadError>> + 'a {
        let mut checked: Option<u16> = None;
        self.picked(move |channel, msg| {
            if channel.topic != topic {
                return Pick::Skip;
            }
            if checked != Some(msg.channel_id) {
                if channel.schema_name() != M::TYPE_NAME {
                    return Pick::Fail(ReadError::WrongType {
                        topic: topic.to_owned(),
                        expected: M::TYPE_NAME,
                        found: channel.schema_name().to_owned(),
                    });
                }
                checked = Some(msg.channel_id);
            }
            Pick::Give(
                M::decode(&msg.data)
                    .map(|m| (msg.log_time_ns, m))
                    .map_err(|source| ReadError::Decode {
                        topic: topic.to_owned(),
                        log_time_ns: msg.log_time_ns,
                        source,
                    }),
            )
        })
    }

    /// Every message with its channel handed to `pick`, which skips it,
    /// gives an item, or fails; a failure, as a read error, is the last
    /// item.
    fn picked<T: 'a>(
        self,
        mut pick: impl FnMut(&ChannelInfo, &RawMessage) -> Pick<T> + 'a,
    ) -> impl Iterator<Item = Result<T, ReadError>> + 'a {
        let mut reader = self;
        let mut failed = false;
        std::iter::from_fn(move || {
            if failed {
                return None;
            }
            loop {
                let msg = match reader.next()? {
                    Ok(m) => m,
                    Err(e) => {
                        failed = true;
                        return Some(Err(e));
                    }
                };
                let channel = reader.channels.get(&msg.channel_id)?;
                match pick(channel, &msg) {
                    Pick::Skip => {}
                    Pick::Give(item) => return Some(item),
                    Pick::Fail(e) => {
                        failed = true;
                        return Some(Err(e));
                    }
                }
            }
        })
    }
}

/// What [`McapReader::picked`]'s choice makes of a message.
enum Pick<T> {
    /// Not wanted: the next one.
    Skip,
    /// An item (one that cannot be decoded is an error item, and the
    /// iteration goes on).
    Give(Result<T, ReadError>),
    /// An error that ends the iteration.
    Fail(ReadError),
}

impl Iterator for McapReader<'_> {
    type Item = Result<RawMessage, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if self.done {
                return None;
            }
            let stepped = self.step();
            if let Some(e) = self.after_step(stepped) {
                return Some(Err(e));
            }
        }
    }
}

/// The error of a record (`opcode`, at `offset`) the mcap crate's parser
/// refused.
fn corrupt(offset: u64, opcode: u8) -> impl Fn(mcap::McapError) -> ReadError {
    move |source| ReadError::Corrupt {
        offset,
        opcode,
        source,
    }
}

/// The record at the start of `rest` (at `offset`, with `available` bytes
/// left in the file): its opcode, its body and its length with the prefix,
/// or why it is not whole.
fn record_parts(rest: &[u8], offset: u64, available: u64) -> Result<(u8, &[u8], u64), ReadError> {
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

/// What a reader may hold of schemas, channels and metadata for a file
/// (or bytes) of `file_bytes`: [`RETAINED_PER_FILE_BYTE`] times its length
/// plus [`RETAINED_BASE_BYTES`]. With one chunk's buffer (at most
/// [`MAX_CHUNK_BYTES`]) and its messages, this bounds a reader's memory by
/// the file's size and a constant.
pub fn retained_limit(file_bytes: u64) -> u64 {
    file_bytes
        .saturating_mul(RETAINED_PER_FILE_BYTE)
        .saturating_add(RETAINED_BASE_BYTES)
}

/// Bytes a reader may hold per byte of its file ([`retained_limit`]): a
/// record's strings cost their length and a fixed allowance, a compressed
/// chunk may hold a few times its length of them.
pub const RETAINED_PER_FILE_BYTE: u64 = 8;

/// Bytes a reader may hold whatever its file's length ([`retained_limit`]).
pub const RETAINED_BASE_BYTES: u64 = 16 * 1024 * 1024;

/// The allowance of one map entry (its node and its allocations), bytes.
const ENTRY_OVERHEAD: u64 = 128;

/// What an entry of strings of these lengths holds, bytes.
fn entry_cost(lens: [usize; 3]) -> u64 {
    lens.iter()
        .fold(ENTRY_OVERHEAD, |a, n| a.saturating_add(*n as u64))
}

/// The bytes of a string map's keys and values, with an allowance per entry.
fn map_bytes(m: &BTreeMap<String, String>) -> usize {
    m.iter()
        .map(|(k, v)| k.len() + v.len() + 64)
        .fold(0usize, usize::saturating_add)
}

/// Whether a channel record says again what `known` holds.
fn same_channel(known: &ChannelInfo, c: &mcap::records::Channel) -> bool {
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
fn fill_record(
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
fn decompress(
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

/// Opens `path` for reading if it is a regular file; anything else (a
/// FIFO, which would block until a writer comes; a device; a directory) is
/// refused at once, before it is opened.
pub fn open_regular(path: &Path) -> Result<std::fs::File, ReadError> {
    use std::os::unix::fs::FileTypeExt;
    let io = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let kind = std::fs::metadata(path).map_err(io)?.file_type();
    let not = |kind| {
        Err(ReadError::NotRegular {
            path: path.to_path_buf(),
            kind,
        })
    };
    if kind.is_fifo() {
        return not("a FIFO");
    }
    if kind.is_char_device() {
        return not("a character device");
    }
    if kind.is_block_device() {
        return not("a block device");
    }
    if kind.is_socket() {
        return not("a socket");
    }
    if kind.is_dir() {
        return not("a directory");
    }
    if !kind.is_file() {
        return not("not a file");
    }
    std::fs::File::open(path).map_err(io)
}

/// Reads a whole file into memory (a regular file only: [`open_regular`]).
pub fn read_file(path: &Path) -> Result<Vec<u8>, ReadError> {
    use std::io::Read;
    let mut bytes = Vec::new();
    open_regular(path)?
        .read_to_end(&mut bytes)
        .map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(bytes)
}

/// What [`recover`] did.
#[derive(Debug)]
pub struct RecoverReport {
    /// Messages copied.
    pub messages: u64,
    /// Channels copied.
    pub channels: usize,
    /// Whether the input was complete already.
    pub input_complete: bool,
    /// Where and why the input stopped, when it was cut short.
    pub stopped: Option<ReadError>,
    /// The corrupt records passed over (the chunks after them are kept):
    /// counted, the first ones in detail.
    pub skipped: SkippedTally,
}

/// Why [`recover`] failed.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// The input could not be read at all.
    #[error("reading: {0}")]
    Read(#[from] ReadError),
    /// The output could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The output.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP writer refused.
    #[error("{path}: MCAP: {source}")]
    Mcap {
        /// The output.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// The output is the input (the same file, by any name), or too
    /// little space is free for it.
    #[error("{0}")]
    Output(#[from] crate::output::OutputError),
}

/// Rewrites `input` (complete or cut short) into `output`, a complete file
/// with summary and indexes: every message of the input's complete chunks,
/// with its channel, sequence and times, its metadata, and metadata
/// `sar_recover` saying where and why the input stopped.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverReport, RecoverError> {
    use crate::output::{PendingFile, SpaceWatch, check_outputs};
    // The same file by any name (./x.mcap, a hard or symbolic link) is
    // refused; and the output is written beside itself and renamed at the
    // end, so that nothing in its place is ever cut.
    check_outputs(&[output], &[input])?;
    let reader = McapReader::open(input)?;
    let pending = PendingFile::new(output)?;
    // The output holds at most the input's messages, with its summary.
    let space = SpaceWatch::before(output, pending.tmp_path(), reader.total_bytes())?;
    let io = |source| RecoverError::Io {
        path: output.to_path_buf(),
        source,
    };
    let (file, handle, position) = CountingFile::create(pending.tmp_path()).map_err(io)?;
    let mut recovery = Recovery {
        reader,
        output,
        options: FileOptions::new(".", "recovered").mcap_options(),
        file: Some(file),
        writer: None,
        known: BTreeMap::new(),
        metadata_copied: 0,
        messages: 0,
        skipped: SkippedTally::default(),
        stopped: None,
        space,
        position,
    };
    recovery.copy_messages()?;
    recovery.finish(input)?;
    handle.sync_all().map_err(io)?;
    if recovery.messages > 0 {
        pending.commit()?;
    }
    // (Nothing recovered: the temporary file is removed, nothing renamed.)
    Ok(recovery.report())
}

/// A [`recover`] under way: the input's reader, the output (its writer made
/// at the input's first message, when the input's profile and the metadata
/// before it are known), and what was copied and passed over.
struct Recovery<'p> {
    reader: McapReader<'static>,
    output: &'p Path,
    options: mcap::WriteOptions,
    /// The output file, until its writer is made.
    file: Option<CountingFile>,
    writer: Option<mcap::Writer<CountingFile>>,
    /// The channels copied.
    known: BTreeMap<u16, ()>,
    /// Metadata records already copied: those before the first message are
    /// copied at the start (where readers such as replay look for them).
    metadata_copied: usize,
    messages: u64,
    skipped: SkippedTally,
    stopped: Option<ReadError>,
    /// The output's file system's free space.
    space: crate::output::SpaceWatch,
    /// Bytes written to the output so far.
    position: Arc<std::sync::atomic::AtomicU64>,
}

/// The channel `c` (and its schema) under the same ids.
fn copy_channel<W: std::io::Write + std::io::Seek>(
    w: &mut mcap::Writer<W>,
    c: &ChannelInfo,
) -> Result<(), mcap::McapError> {
    if c.schema_id != 0 {
        w.add_schema_with_id(
            c.schema_id,
            c.schema_name(),
            c.schema_encoding(),
            c.schema_data(),
        )?;
    }
    w.add_channel_with_id(
        c.id,
        c.schema_id,
        &c.topic,
        &c.message_encoding,
        &c.metadata,
    )?;
    Ok(())
}

impl Recovery<'_> {
    /// The MCAP writer's error, on the output.
    fn mcap_err(&self) -> impl Fn(mcap::McapError) -> RecoverError + use<> {
        let path = self.output.to_path_buf();
        move |source| RecoverError::Mcap {
            path: path.clone(),
            source,
        }
    }

    /// The input's next message: a corrupt chunk is passed over (the good
    /// ones after it are kept); `None` at its end or where it is cut short
    /// (noted in `stopped`).
    fn next_message(&mut self) -> Option<RawMessage> {
        loop {
            match self.reader.next()? {
                Ok(m) => return Some(m),
                Err(e) => match self.reader.skip_bad_record(&e) {
                    Some(s) => self.skipped.add(s),
                    None => {
                        self.stopped = Some(e);
                        return None;
                    }
                },
            }
        }
    }

    /// The output's writer, with the input's profile (`None` once made).
    fn make_writer(&mut self) -> Result<Option<mcap::Writer<CountingFile>>, RecoverError> {
        let Some(f) = self.file.take() else {
            return Ok(None);
        };
        let profile = self.reader.profile().unwrap_or("").to_owned();
        mcap::Writer::with_options(f, self.options.clone().profile(profile))
            .map(Some)
            .map_err(self.mcap_err())
    }

    /// Every message of the input's complete chunks, with its channel,
    /// sequence and times (the writer made at the first, with the metadata
    /// read so far).
    fn copy_messages(&mut self) -> Result<(), RecoverError> {
        let mcap_err = self.mcap_err();
        while let Some(msg) = self.next_message() {
            if self.writer.is_none() {
                let Some(mut w) = self.make_writer()? else {
                    break;
                };
                for m in self.reader.metadata() {
                    w.write_metadata(m).map_err(&mcap_err)?;
                }
                self.metadata_copied = self.reader.metadata().len();
                self.writer = Some(w);
            }
            let Some(w) = self.writer.as_mut() else {
                break;
            };
            if let std::collections::btree_map::Entry::Vacant(slot) =
                self.known.entry(msg.channel_id)
                && let Some(c) = self.reader.channels().get(&msg.channel_id)
            {
                copy_channel(w, c).map_err(&mcap_err)?;
                slot.insert(());
            }
            let header = mcap::records::MessageHeader {
                channel_id: msg.channel_id,
                sequence: msg.sequence,
                log_time: msg.log_time_ns,
                publish_time: msg.publish_time_ns,
            };
            w.write_to_known_channel(&header, &msg.data)
                .map_err(&mcap_err)?;
            self.messages += 1;
            self.space
                .written(self.position.load(std::sync::atomic::Ordering::Relaxed))?;
        }
        Ok(())
    }

    /// The output completed: the channels without messages (kept too), the
    /// metadata not copied yet, `sar_recover`, the summary and indexes.
    fn finish(&mut self, input: &Path) -> Result<(), RecoverError> {
        let mcap_err = self.mcap_err();
        let mut w = match self.writer.take() {
            Some(w) => w,
            None => self.make_writer()?.ok_or_else(|| RecoverError::Io {
                path: self.output.to_path_buf(),
                source: std::io::Error::other("the output's writer was made twice"),
            })?,
        };
        for c in self.reader.channels().values() {
            if !self.known.contains_key(&c.id) {
                copy_channel(&mut w, c).map_err(&mcap_err)?;
            }
        }
        for m in self.reader.metadata().iter().skip(self.metadata_copied) {
            w.write_metadata(m).map_err(&mcap_err)?;
        }
        w.write_metadata(&self.recover_metadata(input))
            .map_err(&mcap_err)?;
        w.finish().map_err(&mcap_err)?;
        Ok(())
    }

    /// `sar_recover`: the source, what was copied and read, where and why
    /// the input stopped, the corrupt records passed over.
    fn recover_metadata(&self, input: &Path) -> mcap::records::Metadata {
        let mut info = BTreeMap::from([
            ("source".to_owned(), input.display().to_string()),
            ("messages".to_owned(), self.messages.to_string()),
            (
                "read_up_to_byte".to_owned(),
                self.reader.offset().to_string(),
            ),
            (
                "input_bytes".to_owned(),
                self.reader.total_bytes().to_string(),
            ),
        ]);
        if let Some(e) = &self.stopped {
            info.insert("stopped".to_owned(), e.to_string());
        }
        if !self.skipped.is_empty() {
            info.insert("skipped".to_owned(), self.skipped.summary());
        }
        mcap::records::Metadata {
            name: "sar_recover".into(),
            metadata: info,
        }
    }

    /// What was done.
    fn report(self) -> RecoverReport {
        RecoverReport {
            messages: self.messages,
            channels: self.reader.channels().len(),
            input_complete: self.reader.is_complete() && self.skipped.is_empty(),
            stopped: self.stopped,
            skipped: self.skipped,
        }
    }
}
