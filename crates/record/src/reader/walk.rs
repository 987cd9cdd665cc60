//! The walk over the data section, record by record: schemas, channels and
//! metadata kept, each chunk checked whole before its messages are given to
//! a visitor.

use super::error::ReadError;
use super::files::retained_limit;
use super::info::{ChannelInfo, SchemaInfo};
use super::info::{MessageRef, OnMessage};
use super::parse::{
    MAX_CHUNK_BYTES, MESSAGE_HEADER, RECORD_PREFIX, corrupt, decompress, entry_cost, fill_record,
    map_bytes, record_parts, same_channel,
};
use super::{McapReader, Source};
use mcap::records::{Record, op};
use std::collections::BTreeMap;
use std::sync::Arc;

impl<'a> McapReader<'a> {
    /// Notes a schema, channel or metadata record read at `offset` (a
    /// record of the data section, or of the chunk there); refused when
    /// what the reader holds would exceed [`retained_limit`] (a crafted
    /// file: small records in a compressed chunk, or many of them).
    pub(super) fn apply(&mut self, record: Record<'_>, offset: u64) -> Result<(), ReadError> {
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
    pub(super) fn cost_of(&self, record: &Record<'_>) -> Option<u64> {
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
    pub(super) fn is_known(&self, channel_id: u16) -> bool {
        self.known_channels
            .get(usize::from(channel_id / 64))
            .is_some_and(|w| w & (1 << (channel_id % 64)) != 0)
    }

    /// Hands one message record's body to `on_msg` (its channel must be
    /// known).
    pub(super) fn message<E, F: OnMessage<E> + ?Sized>(
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
    pub(super) fn step(&mut self) -> Result<bool, ReadError> {
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
    pub(super) fn after_step(&mut self, stepped: Result<bool, ReadError>) -> Option<ReadError> {
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
    pub(super) fn step_with<E, F: OnMessage<E> + ?Sized>(
        &mut self,
        on_msg: &mut F,
    ) -> Result<Result<bool, ReadError>, E> {
        match self.step_inner(on_msg) {
            Ok(Ok(more)) => Ok(Ok(more)),
            Ok(Err(e)) => Err(e),
            Err(e) => Ok(Err(e)),
        }
    }

    pub(super) fn step_inner<E, F: OnMessage<E> + ?Sized>(
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
    pub(super) fn step_on<E, F: OnMessage<E> + ?Sized>(
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
    pub(super) fn chunk<E, F: OnMessage<E> + ?Sized>(
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
    pub(super) fn chunk_records<E, F: OnMessage<E> + ?Sized>(
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
}
