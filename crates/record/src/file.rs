//! MCAP files of the recorded topics: profile `ros2`, `ros2msg` schemas, `cdr`
//! messages, zstd chunks written whole (a crash loses at most the chunk being
//! filled), rotation by size or duration with every file self-contained (all
//! schemas and channels at its start, summary and index at its end).
//! Every channel carries `offered_qos_profiles` metadata, the YAML text ROS 2's
//! recorder (Jazzy) writes there ([`OFFERED_QOS_PROFILES`]).
//!
//! With [`FileOptions::scene`], the 3D scene (`/sar/scene`, `/tf`,
//! `/tf_static`: [`crate::scene`]) is drawn from the recorded messages of a
//! cycle, decimated, on the writer's thread, into the file itself.

pub use crate::scene::SceneOptions;
use crate::scene::{SceneEncodeError, SceneState};
use sar_config::Rotation;
use sar_msgs::msgs::{Outgoing, RecorderDrops, RosMessage, SnapshotChunk, StateSnapshot, Topic};
use sar_msgs::viz::{MarkerArray, TfMessage};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Why a recording could not be written.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The file could not be created, written or synced (a full disk:
    /// "No space left on device").
    #[error("{path}: write error: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The MCAP writer refused.
    #[error("{path}: MCAP: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mcap::McapError,
    },
    /// A message could not be encoded (a stamp beyond 2^31 s).
    #[error("{topic}: {source}")]
    Encode {
        /// The topic.
        topic: &'static str,
        /// The cause.
        source: sar_msgs::cdr::CdrError,
    },
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
}

impl WriteError {
    /// The MCAP writer's error on `path`: its I/O errors as [`WriteError::Io`]
    /// (the mcap crate's own text does not name the cause, e.g. a full disk).
    pub fn mcap(path: PathBuf, source: mcap::McapError) -> Self {
        match source {
            mcap::McapError::Io(source) => WriteError::Io { path, source },
            source => WriteError::Mcap { path, source },
        }
    }
    /// The OS error behind it (ENOSPC for a full disk), if any.
    pub fn os_error(&self) -> Option<i32> {
        match self {
            WriteError::Io { source, .. } => source.raw_os_error(),
            _ => None,
        }
    }
}

/// The `offered_qos_profiles` metadata of every channel, in the form ROS 2's
/// recorder writes it (rosbag2, Jazzy: `rosbag2_storage::
/// serialize_rclcpp_qos_vector`, yaml-cpp's `Dump`, version 9 string
/// policies): one profile, a reliable, volatile, keep-last publisher with no
/// deadline, lifespan or lease (rmw's infinite duration). `ros2 bag play`
/// offers it again (with its default history); Python `rosbags` and the
/// viewers parse it. (A recorder that saw the publisher on DDS would write
/// `history: unknown`, `depth: 0`: discovery does not carry them.)
pub const OFFERED_QOS_PROFILES: &str = "- history: keep_last
  depth: 1000
  reliability: reliable
  durability: volatile
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false";

/// The metadata key of [`OFFERED_QOS_PROFILES`].
pub const QOS_METADATA_KEY: &str = "offered_qos_profiles";

/// The `offered_qos_profiles` of `/tf_static`: as [`OFFERED_QOS_PROFILES`]
/// but `transient_local` with a depth of 1 (a late subscriber gets the
/// fixed frames: what `ros2 bag play` offers again, and the viewers read).
pub const OFFERED_QOS_PROFILES_STATIC: &str = "- history: keep_last
  depth: 1
  reliability: reliable
  durability: transient_local
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false";

/// The scene's channels in one file.
#[derive(Debug, Clone, Copy)]
struct SceneChannels {
    scene: u16,
    tf: u16,
    tf_static: u16,
}

/// Adds the scene's schemas and channels to a file being opened.
fn add_scene_channels<W: Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
) -> Result<SceneChannels, mcap::McapError> {
    let qos = |text: &str| BTreeMap::from([(QOS_METADATA_KEY.to_owned(), text.to_owned())]);
    let markers = writer.add_schema(
        MarkerArray::TYPE_NAME,
        "ros2msg",
        MarkerArray::SCHEMA.as_bytes(),
    )?;
    let tf = writer.add_schema(
        TfMessage::TYPE_NAME,
        "ros2msg",
        TfMessage::SCHEMA.as_bytes(),
    )?;
    Ok(SceneChannels {
        scene: writer.add_channel(
            markers,
            sar_scene::SCENE_TOPIC,
            "cdr",
            &qos(OFFERED_QOS_PROFILES),
        )?,
        tf: writer.add_channel(tf, sar_scene::TF_TOPIC, "cdr", &qos(OFFERED_QOS_PROFILES))?,
        tf_static: writer.add_channel(
            tf,
            sar_scene::TF_STATIC_TOPIC,
            "cdr",
            &qos(OFFERED_QOS_PROFILES_STATIC),
        )?,
    })
}

/// How files are written.
#[derive(Debug, Clone, PartialEq)]
pub struct FileOptions {
    /// The directory of the files.
    pub directory: PathBuf,
    /// File names are `{prefix}-{index:04}.mcap`.
    pub prefix: String,
    /// Uncompressed bytes per chunk (a crash loses at most one chunk).
    pub chunk_size_bytes: u64,
    /// zstd level (0: zstd's default, 3).
    pub zstd_level: u32,
    /// Compress chunks with zstd (false: uncompressed chunks, for comparison).
    pub compress: bool,
    /// When to rotate.
    pub rotation: Rotation,
    /// Metadata records written at the start of every file (name, key-value
    /// pairs): e.g. `sar_replay`, what replay needs beyond the messages.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// The exact path of the first file (instead of `{prefix}-0000.mcap`;
    /// later files of a rotation keep the numbered names).
    pub first_path: Option<PathBuf>,
    /// The 3D scene in the file (`None`: not written).
    pub scene: Option<SceneOptions>,
    /// Rotation waits for a snapshot (`/sar/cycle/snapshot`), which then
    /// starts the new file, so that every file replays on its own; when no
    /// snapshot comes for this long (log time, ns) after the rotation fell
    /// due (all dropped), the file rotates at the next message anyway (that
    /// file then starts without one). `None`: rotate at any message.
    pub rotate_at_snapshots_grace_ns: Option<u64>,
}

impl FileOptions {
    /// zstd chunks of 256 KiB, no rotation.
    pub fn new(directory: impl Into<PathBuf>, prefix: impl Into<String>) -> Self {
        Self {
            directory: directory.into(),
            prefix: prefix.into(),
            chunk_size_bytes: 256 * 1024,
            zstd_level: 0,
            compress: true,
            rotation: Rotation::default(),
            metadata: Vec::new(),
            first_path: None,
            scene: None,
            rotate_at_snapshots_grace_ns: None,
        }
    }

    /// One file at `path` (no rotation).
    pub fn single(path: &Path) -> Self {
        let directory = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut options = Self::new(directory, "replay");
        options.first_path = Some(path.to_path_buf());
        options
    }

    /// The path of file number `index`.
    pub fn path(&self, index: u32) -> PathBuf {
        if index == 0
            && let Some(p) = &self.first_path
        {
            return p.clone();
        }
        self.directory
            .join(format!("{}-{index:04}.mcap", self.prefix))
    }

    pub(crate) fn mcap_options(&self) -> mcap::WriteOptions {
        mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("sar-daemon/", env!("CARGO_PKG_VERSION")))
            .compression(if self.compress {
                Some(mcap::Compression::Zstd)
            } else {
                None
            })
            .compression_level(self.zstd_level)
            // Compress in the writer thread itself: no extra threads on a
            // two-core controller.
            .compression_threads(0)
            .chunk_size(Some(self.chunk_size_bytes))
            // Chunks are built in memory and written whole: a file cut short
            // ends with complete chunks and at most one partial record.
            .disable_seeking(true)
    }
}

/// A file that counts the bytes written to it (its position), shared with the
/// rotation check.
pub(crate) struct CountingFile {
    inner: BufWriter<File>,
    pos: u64,
    shared_pos: Arc<AtomicU64>,
}

impl CountingFile {
    /// The file, a handle to sync it and its shared position.
    pub(crate) fn create(path: &Path) -> std::io::Result<(Self, File, Arc<AtomicU64>)> {
        let file = File::create(path)?;
        let handle = file.try_clone()?;
        let shared_pos = Arc::new(AtomicU64::new(0));
        Ok((
            Self {
                inner: BufWriter::with_capacity(1 << 20, file),
                pos: 0,
                shared_pos: Arc::clone(&shared_pos),
            },
            handle,
            shared_pos,
        ))
    }
}

impl Write for CountingFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.pos += n as u64;
        self.shared_pos.store(self.pos, Ordering::Relaxed);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl Seek for CountingFile {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        // The writer only asks where it is (disable_seeking): answer without
        // flushing the buffer.
        if to == SeekFrom::Current(0) {
            return Ok(self.pos);
        }
        self.pos = self.inner.seek(to)?;
        self.shared_pos.store(self.pos, Ordering::Relaxed);
        Ok(self.pos)
    }
}

/// Writes the recorded topics into rotating MCAP files.
pub struct RotatingWriter {
    options: FileOptions,
    current: Option<OpenFile>,
    next_index: u32,
    files: Vec<PathBuf>,
    sequence: [u32; Topic::ALL.len()],
    buf: Vec<u8>,
    written: u64,
    scene: Option<SceneState>,
    /// The snapshot being joined from its chunks: its `after_cycle` and the
    /// next chunk expected.
    joining: Option<(u64, u8)>,
    /// The joined snapshot's bytes.
    snapshot: StateSnapshot,
    /// When the current file's rotation fell due (log time, ns).
    rotation_due_ns: Option<u64>,
}

struct OpenFile {
    path: PathBuf,
    writer: mcap::Writer<CountingFile>,
    handle: File,
    position: Arc<AtomicU64>,
    channel_ids: [u16; Topic::ALL.len()],
    scene: Option<SceneChannels>,
    first_log_ns: Option<u64>,
}

fn scene_encode_error((topic, source): SceneEncodeError) -> WriteError {
    WriteError::Encode { topic, source }
}

fn topic_index(topic: Topic) -> usize {
    Topic::ALL.iter().position(|t| *t == topic).unwrap_or(0)
}

impl RotatingWriter {
    /// Checks the options; no file is created before the first message.
    pub fn new(options: FileOptions) -> Result<Self, WriteError> {
        if options.chunk_size_bytes == 0 {
            return Err(WriteError::Setting {
                field: "chunk_size_bytes",
                value: 0,
                why: "must be positive",
            });
        }
        if options.rotation.max_duration_ns == Some(0) {
            return Err(WriteError::Setting {
                field: "max_duration_ns",
                value: 0,
                why: "must be positive",
            });
        }
        std::fs::create_dir_all(&options.directory).map_err(|source| WriteError::Io {
            path: options.directory.clone(),
            source,
        })?;
        Ok(Self {
            current: None,
            next_index: 0,
            files: Vec::new(),
            sequence: [0; Topic::ALL.len()],
            buf: Vec::with_capacity(1024),
            written: 0,
            scene: options.scene.map(SceneState::new),
            options,
            joining: None,
            snapshot: StateSnapshot {
                stamp_ns: 0,
                after_cycle: 0,
                format_version: sar_snapshot::VERSION,
                data: Vec::with_capacity(sar_snapshot::CAPACITY),
            },
            rotation_due_ns: None,
        })
    }

    /// The files started so far (the last one may be open).
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Messages written so far.
    pub fn written(&self) -> u64 {
        self.written
    }

    fn open(&mut self) -> Result<&mut OpenFile, WriteError> {
        let path = self.options.path(self.next_index);
        self.next_index += 1;
        let mcap_err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| WriteError::mcap(path, source)
        };
        let (file, handle, position) =
            CountingFile::create(&path).map_err(|source| WriteError::Io {
                path: path.clone(),
                source,
            })?;
        let mut writer = mcap::Writer::with_options(file, self.options.mcap_options())
            .map_err(mcap_err(&path))?;
        let mut channel_ids = [0u16; Topic::ALL.len()];
        let qos = BTreeMap::from([(QOS_METADATA_KEY.to_owned(), OFFERED_QOS_PROFILES.to_owned())]);
        for (id, topic) in channel_ids.iter_mut().zip(Topic::ALL) {
            let schema = writer
                .add_schema(topic.type_name(), "ros2msg", topic.schema().as_bytes())
                .map_err(mcap_err(&path))?;
            *id = writer
                .add_channel(schema, topic.name(), "cdr", &qos)
                .map_err(mcap_err(&path))?;
        }
        let scene = match &self.scene {
            Some(_) => Some(add_scene_channels(&mut writer).map_err(mcap_err(&path))?),
            None => None,
        };
        // Each file says which of the rotation it is (`file_index`, 0 for
        // the first): a reader can tell a file that starts mid-recording.
        let index = self.next_index.saturating_sub(1);
        for (name, metadata) in &self.options.metadata {
            let mut metadata = metadata.clone();
            metadata.insert("file_index".to_owned(), index.to_string());
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: name.clone(),
                    metadata,
                })
                .map_err(mcap_err(&path))?;
        }
        self.files.push(path.clone());
        Ok(self.current.insert(OpenFile {
            path,
            writer,
            handle,
            position,
            channel_ids,
            scene,
            first_log_ns: None,
        }))
    }

    fn must_rotate(&self, file: &OpenFile, log_ns: u64) -> bool {
        let r = self.options.rotation;
        let by_size = r.max_bytes.is_some_and(|max| file.writer_position() >= max);
        let by_time = match (r.max_duration_ns, file.first_log_ns) {
            (Some(max), Some(first)) => log_ns.saturating_sub(first) >= max,
            _ => false,
        };
        by_size || by_time
    }

    /// Writes one message (log and publish time = its stamp), rotating first
    /// if the current file is full; `status` is written into the file closed.
    /// Snapshot chunks are joined, and the snapshot written once complete
    /// (with [`FileOptions::rotate_at_snapshots_grace_ns`], rotating there).
    pub fn write(&mut self, msg: &Outgoing, status: &RecorderDrops) -> Result<(), WriteError> {
        if let Outgoing::SnapshotChunk(chunk) = msg {
            return self.write_chunk(chunk, status);
        }
        let log_ns = msg.stamp_ns();
        if let Some(file) = &self.current
            && self.must_rotate(file, log_ns)
        {
            let overdue = match self.options.rotate_at_snapshots_grace_ns {
                None => true,
                Some(grace) => {
                    let due = *self.rotation_due_ns.get_or_insert(log_ns);
                    log_ns.saturating_sub(due) >= grace
                }
            };
            if overdue {
                self.close(status)?;
            }
        }
        self.write_raw(msg)
    }

    /// Joins a snapshot's chunks; writes it when complete. A chunk out of
    /// order (one was dropped: the queue's drop count has it) abandons the
    /// snapshot it belongs to.
    fn write_chunk(
        &mut self,
        chunk: &SnapshotChunk,
        status: &RecorderDrops,
    ) -> Result<(), WriteError> {
        if chunk.index == 0 {
            self.snapshot.data.clear();
        } else if self.joining != Some((chunk.after_cycle, chunk.index)) {
            self.joining = None;
            return Ok(());
        }
        self.snapshot.data.extend_from_slice(chunk.data());
        if chunk.index.saturating_add(1) < chunk.count {
            self.joining = Some((chunk.after_cycle, chunk.index + 1));
            return Ok(());
        }
        self.joining = None;
        if let Some(file) = &self.current
            && self.must_rotate(file, chunk.stamp_ns)
        {
            self.close(status)?;
        }
        self.snapshot.stamp_ns = chunk.stamp_ns;
        self.snapshot.after_cycle = chunk.after_cycle;
        self.snapshot
            .encode(&mut self.buf)
            .map_err(|source| WriteError::Encode {
                topic: Topic::StateSnapshot.name(),
                source,
            })?;
        self.write_encoded(Topic::StateSnapshot, chunk.stamp_ns)
    }

    fn write_raw(&mut self, msg: &Outgoing) -> Result<(), WriteError> {
        let topic = msg.topic();
        let log_ns = msg.stamp_ns();
        msg.encode(&mut self.buf)
            .map_err(|source| WriteError::Encode {
                topic: topic.name(),
                source,
            })?;
        self.write_encoded(topic, log_ns)?;
        self.write_scene(msg)
    }

    /// Writes the message encoded in `self.buf` on `topic`'s channel.
    fn write_encoded(&mut self, topic: Topic, log_ns: u64) -> Result<(), WriteError> {
        let i = topic_index(topic);
        let sequence = self.sequence.get(i).copied().unwrap_or(0);
        if self.current.is_none() {
            self.open()?;
            self.write_scene_static(log_ns)?;
        }
        let Some(file) = self.current.as_mut() else {
            return Ok(());
        };
        file.first_log_ns.get_or_insert(log_ns);
        let header = mcap::records::MessageHeader {
            channel_id: file.channel_ids.get(i).copied().unwrap_or(0),
            sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        file.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|source| WriteError::mcap(file.path.clone(), source))?;
        if let Some(s) = self.sequence.get_mut(i) {
            *s = s.wrapping_add(1);
        }
        self.written += 1;
        Ok(())
    }

    /// Follows the cycles' messages: a message of a later cycle closes the
    /// one gathered, whose scene is then written if one is due.
    fn write_scene(&mut self, msg: &Outgoing) -> Result<(), WriteError> {
        let Some(state) = self.scene.as_ref() else {
            return Ok(());
        };
        if state.closes(msg.stamp_ns()) {
            self.flush_scene()?;
        }
        if let Some(state) = self.scene.as_mut() {
            state.follow(msg);
        }
        Ok(())
    }

    /// `/tf_static` at the start of the file just opened.
    fn write_scene_static(&mut self, log_ns: u64) -> Result<(), WriteError> {
        let (Some(state), Some(file)) = (self.scene.as_mut(), self.current.as_mut()) else {
            return Ok(());
        };
        let Some(channels) = file.scene else {
            return Ok(());
        };
        let bytes = state.static_message(log_ns).map_err(scene_encode_error)?;
        file.write_other(channels.tf_static, log_ns, 0, bytes)
    }

    /// Closes the cycle gathered: writes its scene when one is due.
    fn flush_scene(&mut self) -> Result<(), WriteError> {
        let (Some(state), Some(file)) = (self.scene.as_mut(), self.current.as_mut()) else {
            return Ok(());
        };
        let Some(channels) = file.scene else {
            return Ok(());
        };
        let Some(d) = state.flush().map_err(scene_encode_error)? else {
            return Ok(());
        };
        file.write_other(channels.scene, d.log_ns, d.sequence, d.markers)?;
        file.write_other(channels.tf, d.log_ns, d.sequence, d.tf)
    }

    /// Ends the current chunk and hands the bytes to the disk (fsync): what was
    /// written so far survives a power loss.
    pub fn sync(&mut self) -> Result<(), WriteError> {
        if let Some(file) = &mut self.current {
            file.writer
                .flush()
                .map_err(|source| WriteError::mcap(file.path.clone(), source))?;
            file.sync()?;
        }
        Ok(())
    }

    /// Closes the current file (if any): writes `status` as a
    /// `/sar/recorder/drops` message and as metadata `sar_recorder`, then the
    /// summary and index, and syncs it to disk.
    pub fn close(&mut self, status: &RecorderDrops) -> Result<(), WriteError> {
        if self.current.is_none() {
            return Ok(());
        }
        self.flush_scene()?;
        let mut status = *status;
        status.written = self.written + 1;
        self.write_raw(&Outgoing::RecorderDrops(status))?;
        let Some(mut file) = self.current.take() else {
            return Ok(());
        };
        self.rotation_due_ns = None;
        let path = file.path.clone();
        let mcap_err = |source| WriteError::mcap(path.clone(), source);
        let metadata = mcap::records::Metadata {
            name: "sar_recorder".into(),
            metadata: BTreeMap::from([
                ("dropped".into(), status.dropped.to_string()),
                ("written".into(), status.written.to_string()),
                ("queue_capacity".into(), status.queue_capacity.to_string()),
                ("last_log_time_ns".into(), status.stamp_ns.to_string()),
            ]),
        };
        file.writer.write_metadata(&metadata).map_err(mcap_err)?;
        file.writer.finish().map_err(mcap_err)?;
        // The buffer's last bytes: an error here (a full disk) is the
        // file's, never dropped unseen.
        file.writer
            .into_inner()
            .flush()
            .map_err(|source| WriteError::Io {
                path: path.clone(),
                source,
            })?;
        file.handle.sync_all().map_err(|source| WriteError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(())
    }
}

impl OpenFile {
    /// Writes `bytes` on a channel beside the recorded topics (the scene's).
    fn write_other(
        &mut self,
        channel_id: u16,
        log_ns: u64,
        sequence: u32,
        bytes: &[u8],
    ) -> Result<(), WriteError> {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.writer
            .write_to_known_channel(&header, bytes)
            .map_err(|source| WriteError::mcap(self.path.clone(), source))
    }

    fn writer_position(&self) -> u64 {
        self.position.load(Ordering::Relaxed)
    }
    fn sync(&mut self) -> Result<(), WriteError> {
        self.handle.sync_data().map_err(|source| WriteError::Io {
            path: self.path.clone(),
            source,
        })
    }
}
