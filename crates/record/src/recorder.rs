//! The recorder: the control loop pushes fixed-size messages into a bounded
//! wait-free queue and never waits; a writer thread drains it into rotating
//! MCAP files. When the queue is full the message is dropped and counted; the
//! count is readable by the loop (to publish it) and written into the files
//! (`/sar/recorder/drops` periodically and at each close, and metadata
//! `sar_recorder` at each close).
//!
//! The queue is `rtrb`'s single-producer single-consumer ring: a push is a
//! copy into a preallocated slot and two atomic operations, wait-free and
//! allocation-free (the loop is the only producer, the writer the only
//! consumer, so a multi-producer queue's compare-and-swap loops would buy
//! nothing).

use super::file::{FileOptions, RotatingWriter, WriteError};
use super::lean::{LeanScales, LeanWriter};
use sar_msgs::msgs::{Outgoing, RecorderDrops};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// The recorder's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderConfig {
    /// The files.
    pub files: FileOptions,
    /// Messages the queue holds (at 4 kHz and about six messages a cycle,
    /// 65536 is about 2.7 s of disk stall).
    pub queue_capacity: usize,
    /// Log-time interval of the `/sar/recorder/drops` messages and of the syncs
    /// to disk (chunk ended, fsync), ns.
    pub status_interval_ns: u64,
    /// How long the writer sleeps when the queue is empty (the loop never
    /// wakes it: it drains what came meanwhile in one batch; a stop wakes it).
    pub idle_wait: Duration,
    /// The lean mode (`[record] mode = "inputs"`, [`crate::lean`]) with
    /// the devices' scales; `None`: the full recording.
    pub lean: Option<LeanScales>,
}

impl RecorderConfig {
    /// A 65536-message queue, status and sync every second, 10 ms idle wait
    /// (about ten cycles' messages at 1 kHz, far below the smallest queue).
    pub fn new(files: FileOptions) -> Self {
        Self {
            files,
            queue_capacity: 65536,
            status_interval_ns: 1_000_000_000,
            idle_wait: Duration::from_millis(10),
            lean: None,
        }
    }
}

/// State shared by the loop's side and the writer thread.
#[derive(Debug, Default)]
struct Shared {
    dropped: AtomicU64,
    stop: AtomicBool,
    failed: AtomicBool,
    /// The OS error of the failure (0: none named), set before `failed`.
    errno: std::sync::atomic::AtomicU32,
    /// Woken when the writer fails (the thread that manages the recording).
    on_fail: std::sync::OnceLock<std::thread::Thread>,
}

/// Tells another thread than the loop's whether a recorder's writer has
/// failed ([`Recorder::failure_watch`]).
#[derive(Debug, Clone)]
pub struct FailureWatch(Arc<Shared>);

impl FailureWatch {
    /// Whether the writer has failed.
    pub fn failed(&self) -> bool {
        self.0.failed.load(Ordering::Acquire)
    }
}

/// What a finished recording wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingReport {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// Messages written (including the recorder's own status messages).
    pub written: u64,
    /// Messages dropped (queue full, or the writer failed).
    pub dropped: u64,
}

/// Why a recording ended badly.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    /// A setting is out of range.
    #[error("recorder setting {field} = {value}: {why}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: u64,
        /// What is wrong.
        why: &'static str,
    },
    /// Writing failed; the message that failed and every one after it were
    /// dropped (and counted: `dropped` is the final count).
    #[error("recording failed after {written} messages ({dropped} dropped): {source}")]
    Write {
        /// Messages written before.
        written: u64,
        /// Messages dropped in all.
        dropped: u64,
        /// The cause.
        source: WriteError,
    },
    /// The writer thread could not be started.
    #[error("the writer thread could not start: {0}")]
    Spawn(std::io::Error),
    /// The writer thread panicked.
    #[error("the writer thread panicked")]
    WriterPanicked,
}

impl RecorderError {
    /// The OS error behind a write error (e.g. ENOSPC, a full disk).
    pub fn os_error(&self) -> Option<i32> {
        match self {
            RecorderError::Write { source, .. } => source.os_error(),
            RecorderError::Spawn(e) => e.raw_os_error(),
            _ => None,
        }
    }
}

/// The loop's side: push messages, read the drop count.
///
/// Dropping it without [`Recorder::stop`] lets the writer thread drain the
/// queue and close the file on its own (the report is then lost).
pub struct Recorder {
    producer: rtrb::Producer<Outgoing>,
    shared: Arc<Shared>,
    writer: Option<JoinHandle<Result<RecordingReport, RecorderError>>>,
    pending: Option<PendingWriter>,
}

/// The writer side before its thread starts (a test can fill the queue first).
pub struct PendingWriter {
    consumer: rtrb::Consumer<Outgoing>,
    shared: Arc<Shared>,
    config: RecorderConfig,
    files: RotatingWriter,
    /// The lean mode's batching (`None`: every message written as it is).
    lean: Option<LeanWriter>,
}

impl Recorder {
    /// Creates the recorder and its writer thread.
    pub fn start(config: RecorderConfig) -> Result<Self, RecorderError> {
        let mut recorder = Self::new_paused(config)?;
        recorder.resume()?;
        Ok(recorder)
    }

    /// Creates the recorder with its writer not started: pushes fill the queue,
    /// then drop. [`Recorder::resume`] starts the writer.
    pub fn new_paused(config: RecorderConfig) -> Result<Self, RecorderError> {
        if config.queue_capacity == 0 {
            return Err(RecorderError::Setting {
                field: "queue_capacity",
                value: 0,
                why: "must be positive",
            });
        }
        if config.status_interval_ns == 0 {
            return Err(RecorderError::Setting {
                field: "status_interval_ns",
                value: 0,
                why: "must be positive",
            });
        }
        let files =
            RotatingWriter::new(config.files.clone()).map_err(|source| RecorderError::Write {
                written: 0,
                dropped: 0,
                source,
            })?;
        let (producer, consumer) = rtrb::RingBuffer::new(config.queue_capacity);
        let shared = Arc::new(Shared::default());
        Ok(Self {
            producer,
            shared: Arc::clone(&shared),
            writer: None,
            pending: Some(PendingWriter {
                consumer,
                shared,
                lean: config.lean.map(LeanWriter::new),
                config,
                files,
            }),
        })
    }

    /// Starts the writer thread (no effect once started).
    pub fn resume(&mut self) -> Result<(), RecorderError> {
        if let Some(pending) = self.pending.take() {
            let handle = std::thread::Builder::new()
                .name("sar-recorder".into())
                .spawn(move || pending.run())
                .map_err(RecorderError::Spawn)?;
            self.writer = Some(handle);
        }
        Ok(())
    }

    /// Queues a message; never blocks, never allocates. Returns false when
    /// the queue was full and the message was dropped (and counted).
    #[inline]
    pub fn push(&mut self, msg: Outgoing) -> bool {
        match self.producer.push(msg) {
            Ok(()) => true,
            Err(_) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Messages dropped so far.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Whether the writer has failed (from then on every message is dropped).
    pub fn failed(&self) -> bool {
        self.shared.failed.load(Ordering::Acquire)
    }

    /// Marks the writer failed, as its own failure would (tests of what
    /// the recorder's users do then).
    #[cfg(test)]
    pub(crate) fn fail_for_test(&self) {
        self.shared.failed.store(true, Ordering::Release);
    }

    /// A watch of this recorder's failure for `waker`, the thread that
    /// closes it, which the writer wakes when it fails: so the failure is
    /// closed and said at once, and nobody polls for it (the loop only
    /// hands the recorder back).
    pub fn failure_watch(&self, waker: std::thread::Thread) -> FailureWatch {
        let _ = self.shared.on_fail.set(waker);
        FailureWatch(Arc::clone(&self.shared))
    }

    /// The OS error the writer failed with (ENOSPC: a full disk); 0 when
    /// it has not failed or the failure named none.
    pub fn os_error(&self) -> u32 {
        self.shared.errno.load(Ordering::Relaxed)
    }

    /// Free slots in the queue now.
    pub fn free_slots(&self) -> usize {
        self.producer.slots()
    }

    /// The queue's capacity (`queue_capacity`), messages.
    pub fn capacity(&self) -> usize {
        self.producer.buffer().capacity()
    }

    /// Stops: the writer drains the queue, writes the final status and closes
    /// the last file. A paused writer is started first, so nothing queued is
    /// lost.
    pub fn stop(mut self) -> Result<RecordingReport, RecorderError> {
        self.shared.stop.store(true, Ordering::Release);
        self.resume()?;
        match self.writer.take() {
            Some(handle) => {
                handle.thread().unpark();
                handle.join().map_err(|_| RecorderError::WriterPanicked)?
            }
            None => Err(RecorderError::WriterPanicked),
        }
    }
}

impl PendingWriter {
    fn status(&self, stamp_ns: u64) -> RecorderDrops {
        RecorderDrops {
            stamp_ns,
            dropped: self.shared.dropped.load(Ordering::Relaxed),
            written: self.files.written(),
            queue_capacity: self.config.queue_capacity as u64,
        }
    }

    fn fail(&mut self, source: WriteError) -> RecorderError {
        let errno = source.os_error().map_or(0, i32::unsigned_abs);
        self.shared.errno.store(errno, Ordering::Relaxed);
        self.shared.failed.store(true, Ordering::Release);
        if let Some(t) = self.shared.on_fail.get() {
            t.unpark();
        }
        RecorderError::Write {
            written: self.files.written(),
            dropped: self.shared.dropped.load(Ordering::Relaxed),
            source,
        }
    }

    fn run(mut self) -> Result<RecordingReport, RecorderError> {
        let mut progress = Progress::default();
        loop {
            // Read the flag before draining: whatever was pushed before stop()
            // is drained in this pass. A recorder dropped without stop() ends
            // the same way (its producer is gone).
            let stopping = self.shared.stop.load(Ordering::Acquire) || self.consumer.is_abandoned();
            let drained = self.drain(&mut progress);
            if stopping {
                break;
            }
            if drained == 0 {
                std::thread::park_timeout(self.config.idle_wait);
            }
        }
        self.finish(progress)
    }

    /// Writes what is queued; returns how many messages it took (after a
    /// failure each is dropped and counted).
    fn drain(&mut self, progress: &mut Progress) -> usize {
        let mut drained = 0usize;
        while let Ok(msg) = self.consumer.pop() {
            drained += 1;
            if progress.error.is_some() {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            self.write(&msg, progress);
        }
        drained
    }

    /// One message written, then the status and a sync to disk when due.
    fn write(&mut self, msg: &Outgoing, progress: &mut Progress) {
        // The status of the file a rotation closes: up to the last
        // message written, not this one.
        let status = self.status(progress.last_ns);
        let result = match &mut self.lean {
            Some(lean) => lean.write(&mut self.files, msg, &status),
            None => self.files.write(msg, &status),
        };
        if let Err(e) = result {
            self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            // One message that cannot be encoded (a stamp beyond the
            // format's range) is dropped and counted; the recording
            // goes on. A failing file ends it.
            if !matches!(e, WriteError::Encode { .. }) {
                progress.error = Some(self.fail(e));
            }
            return;
        }
        progress.last_ns = progress.last_ns.max(msg.stamp_ns());
        let interval_ns = self.config.status_interval_ns;
        let due = *progress
            .next_status_ns
            .get_or_insert(progress.last_ns + interval_ns);
        if progress.last_ns >= due {
            progress.next_status_ns = Some(progress.last_ns + interval_ns);
            let status = self.status(progress.last_ns);
            let result = self
                .files
                .write(&Outgoing::RecorderDrops(status), &status)
                .and_then(|()| self.files.sync());
            if let Err(e) = result {
                progress.error = Some(self.fail(e));
            }
        }
    }

    /// The last file closed with the final status (unless writing failed):
    /// the report, or the failure with the drop count at the end.
    fn finish(mut self, progress: Progress) -> Result<RecordingReport, RecorderError> {
        let mut error = progress.error;
        if error.is_none() {
            let status = self.status(progress.last_ns);
            let flushed = match &mut self.lean {
                Some(lean) => lean.flush(&mut self.files, &status),
                None => Ok(()),
            };
            if let Err(e) = flushed.and_then(|()| self.files.close(&status)) {
                error = Some(self.fail(e));
            }
        }
        match error {
            // The count at the end, not at the failure.
            Some(RecorderError::Write {
                written, source, ..
            }) => Err(RecorderError::Write {
                written,
                dropped: self.shared.dropped.load(Ordering::Relaxed),
                source,
            }),
            Some(e) => Err(e),
            None => Ok(RecordingReport {
                files: self.files.files().to_vec(),
                written: self.files.written(),
                dropped: self.shared.dropped.load(Ordering::Relaxed),
            }),
        }
    }
}

/// What the writer thread has done so far.
#[derive(Default)]
struct Progress {
    /// The newest stamp written, ns.
    last_ns: u64,
    /// When the next status and sync are due (log time, ns).
    next_status_ns: Option<u64>,
    /// The failure that ended writing (every later message is dropped).
    error: Option<RecorderError>,
}
