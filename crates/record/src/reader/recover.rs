//! [`recover`]: a recording cut short rewritten into a complete one
//! (summary, chunk and message indexes).

use super::McapReader;
use super::error::ReadError;
use super::info::{ChannelInfo, RawMessage};
use super::skipped::SkippedTally;
use crate::file::{CountingFile, FileOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

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
pub(super) struct Recovery<'p> {
    pub(super) reader: McapReader<'static>,
    pub(super) output: &'p Path,
    pub(super) options: mcap::WriteOptions,
    /// The output file, until its writer is made.
    pub(super) file: Option<CountingFile>,
    pub(super) writer: Option<mcap::Writer<CountingFile>>,
    /// The channels copied.
    pub(super) known: BTreeMap<u16, ()>,
    /// Metadata records already copied: those before the first message are
    /// copied at the start (where readers such as replay look for them).
    pub(super) metadata_copied: usize,
    pub(super) messages: u64,
    pub(super) skipped: SkippedTally,
    pub(super) stopped: Option<ReadError>,
    /// The output's file system's free space.
    pub(super) space: crate::output::SpaceWatch,
    /// Bytes written to the output so far.
    pub(super) position: Arc<std::sync::atomic::AtomicU64>,
}

/// The channel `c` (and its schema) under the same ids.
pub(super) fn copy_channel<W: std::io::Write + std::io::Seek>(
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
    pub(super) fn mcap_err(&self) -> impl Fn(mcap::McapError) -> RecoverError + use<> {
        let path = self.output.to_path_buf();
        move |source| RecoverError::Mcap {
            path: path.clone(),
            source,
        }
    }

    /// The input's next message: a corrupt chunk is passed over (the good
    /// ones after it are kept); `None` at its end or where it is cut short
    /// (noted in `stopped`).
    pub(super) fn next_message(&mut self) -> Option<RawMessage> {
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
    pub(super) fn make_writer(
        &mut self,
    ) -> Result<Option<mcap::Writer<CountingFile>>, RecoverError> {
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
    pub(super) fn copy_messages(&mut self) -> Result<(), RecoverError> {
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
    pub(super) fn finish(&mut self, input: &Path) -> Result<(), RecoverError> {
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
    pub(super) fn recover_metadata(&self, input: &Path) -> mcap::records::Metadata {
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
    pub(super) fn report(self) -> RecoverReport {
        RecoverReport {
            messages: self.messages,
            channels: self.reader.channels().len(),
            input_complete: self.reader.is_complete() && self.skipped.is_empty(),
            stopped: self.stopped,
            skipped: self.skipped,
        }
    }
}
