//! MCAP files of the recorded topics: profile `ros2`, `ros2msg` schemas, `cdr`
//! messages, zstd chunks written whole (a crash loses at most the chunk being
//! filled), rotation by size or duration with every file self-contained (all
//! schemas and channels at its start, summary and index at its end).
//! Every channel carries `offered_qos_profiles` metadata, the YAML text ROS 2's
//! recorder (Jazzy) writes there ([`OFFERED_QOS_PROFILES`]).
//!
//! With [`FileOptions::scene`], the live view's 3D scene is drawn from the
//! recorded messages of a cycle, decimated, on the writer's thread, and
//! written into the recording itself, CDR like every channel: `/sar/scene`
//! (`visualization_msgs/msg/MarkerArray`), `/sar/scene/status` (the guard's
//! figures, `sar_msgs/msg/SceneStatus`), `/tf` (the moving frames) and
//! `/tf_static` (`tf2_msgs/msg/TFMessage`, `world` -> `base`, written at the
//! start of every file with transient-local durability, so that each file
//! of a rotation opens alone with its 3D scene).

use sar_config::Rotation;
use sar_msgs::msgs::SceneStatus;
use sar_msgs::msgs::{
    EstimatorState, Outgoing, PassiveJointState, RecorderDrops, RosMessage, SnapshotChunk,
    StateSnapshot, Topic,
};
use sar_msgs::scene::{MarkerArray, TfMessage};
use sar_scene::draw as scene;
use sar_scene::geometry::SceneGeometry;
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

/// [`OFFERED_QOS_PROFILES`] with transient-local durability: `/tf_static`'s,
/// as ROS 2's static transform broadcaster offers it (a late subscriber
/// still gets the fixed frames).
pub const OFFERED_QOS_PROFILES_LATCHED: &str = "- history: keep_last
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

/// The metadata key of [`OFFERED_QOS_PROFILES`].
pub const QOS_METADATA_KEY: &str = "offered_qos_profiles";

/// The 3D scene written with the recorded topics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneOptions {
    /// The robot and manipulator as drawn (from the configuration).
    pub geometry: SceneGeometry,
    /// The force limits drawn until a cycle records others (warn, stop of
    /// total, axial, lateral), N.
    pub limits_n: [f64; 6],
    /// At most one scene per this much log time, ns (33 333 333: 30 Hz).
    pub period_ns: u64,
}

impl SceneOptions {
    /// The scene the configuration asks for (`[record] scene_hz`), drawn
    /// from its geometry and limits. `None` when it asks for none
    /// (`scene_hz = 0`).
    pub fn from_config(config: &sar_config::Config) -> Option<Self> {
        let period_ns = config.record.scene_period_ns?;
        Some(Self {
            geometry: SceneGeometry::from_config(&config.estimator),
            limits_n: config.estimator.guard.force_limits().to_array(),
            period_ns,
        })
    }
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
    /// The live view's 3D scene with the topics (`None`: not written).
    pub scene: Option<SceneOptions>,
    /// Rotation waits for a snapshot (`/sar/cycle/snapshot`), which then
    /// starts the new file, so that every file replays on its own; when no
    /// snapshot comes for this long (log time, ns) after the rotation fell
    /// due (all dropped), the file rotates at the next message anyway (that
    /// file then starts without one). `None`: rotate at any message.
    pub rotate_at_snapshots_grace_ns: Option<u64>,
    /// A lean file (`crate::lean`): the `/sar/cycle/batch` channel too
    /// (a full file has the channels of [`Topic::FULL`]).
    pub lean: bool,
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
            lean: false,
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

/// What the scene is drawn from: the messages of one cycle (all stamped with
/// the cycle's `now`), gathered until a message of a later cycle (or the
/// file's end) closes it, whatever their order.
struct SceneState {
    options: SceneOptions,
    rate: sar_scene::rate::Decimator,
    cycle: Option<SceneCycle>,
    /// The limits in use (the last `/sar/cycle/input`'s).
    limits_n: [f64; 6],
    /// The last joints (`/sar/cycle/input` or `/sar/joints`).
    q_m: [f64; 3],
    buf: Vec<u8>,
}

/// One cycle's messages as the scene needs them.
#[derive(Debug, Clone, Copy)]
struct SceneCycle {
    stamp_ns: u64,
    estimator: Option<EstimatorState>,
    passive: Option<PassiveJointState>,
    /// The simulator's true F_tip (`/sar/sim/tip_wrench_truth`), N.
    truth_n: Option<[f64; 3]>,
}

/// The scene's channels in one recording file.
struct SceneChannels {
    scene: u16,
    tf: u16,
    tf_static: u16,
    status: u16,
    /// The scenes written to this file (`/sar/scene`'s and `/tf`'s sequence).
    sequence: u32,
    /// `/tf_static` is written before the file's first scene.
    static_written: bool,
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

/// A topic without a channel in the file (`OpenFile::channel_ids`).
const NO_CHANNEL: u16 = u16::MAX;

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
            scene: options.scene.map(|o| SceneState {
                options: o,
                rate: sar_scene::rate::Decimator::new(o.period_ns),
                cycle: None,
                limits_n: o.limits_n,
                q_m: [0.0; 3],
                buf: Vec::with_capacity(4096),
            }),
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

    /// Bytes written so far into the file open now (0 when none is).
    pub fn open_file_bytes(&self) -> u64 {
        self.current.as_ref().map_or(0, OpenFile::writer_position)
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
        // (NO_CHANNEL: a topic this file has no channel of.)
        let mut channel_ids = [NO_CHANNEL; Topic::ALL.len()];
        let qos = BTreeMap::from([(QOS_METADATA_KEY.to_owned(), OFFERED_QOS_PROFILES.to_owned())]);
        for (id, topic) in channel_ids.iter_mut().zip(Topic::ALL) {
            if topic == Topic::CycleBatch && !self.options.lean {
                continue;
            }
            let schema = writer
                .add_schema(topic.type_name(), "ros2msg", topic.schema().as_bytes())
                .map_err(mcap_err(&path))?;
            *id = writer
                .add_channel(schema, topic.name(), "cdr", &qos)
                .map_err(mcap_err(&path))?;
        }
        let scene = match &self.scene {
            Some(_) => Some(scene_channels(&mut writer, &path)?),
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
        self.rotate_if_due(msg.stamp_ns(), status)?;
        self.write_raw(msg)
    }

    /// Closes the current file before a message logged at `log_ns` when
    /// it is full (waiting for a snapshot up to the grace).
    fn rotate_if_due(&mut self, log_ns: u64, status: &RecorderDrops) -> Result<(), WriteError> {
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
        Ok(())
    }

    /// Writes one `/sar/cycle/batch` (the lean mode's, `crate::lean`),
    /// logged at its stamp, rotating first as [`RotatingWriter::write`].
    pub fn write_batch(
        &mut self,
        batch: &sar_msgs::msgs::CycleBatch,
        status: &RecorderDrops,
    ) -> Result<(), WriteError> {
        self.rotate_if_due(batch.stamp_ns, status)?;
        batch
            .encode(&mut self.buf)
            .map_err(|source| WriteError::Encode {
                topic: Topic::CycleBatch.name(),
                source,
            })?;
        self.write_encoded(Topic::CycleBatch, batch.stamp_ns)
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
        }
        let Some(file) = self.current.as_mut() else {
            return Ok(());
        };
        let channel_id = file.channel_ids.get(i).copied().unwrap_or(NO_CHANNEL);
        if channel_id == NO_CHANNEL {
            return Err(WriteError::Setting {
                field: "lean",
                value: 0,
                why: "/sar/cycle/batch is written only into a lean file",
            });
        }
        file.first_log_ns.get_or_insert(log_ns);
        let header = mcap::records::MessageHeader {
            channel_id,
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
        let Some(state) = self.scene.as_mut() else {
            return Ok(());
        };
        let stamp_ns = msg.stamp_ns();
        if state.cycle.is_some_and(|c| c.stamp_ns != stamp_ns) {
            self.flush_scene()?;
        }
        let Some(state) = self.scene.as_mut() else {
            return Ok(());
        };
        let cycle = state.cycle.get_or_insert(SceneCycle {
            stamp_ns,
            estimator: None,
            passive: None,
            truth_n: None,
        });
        match msg {
            Outgoing::EstimatorState(e) => cycle.estimator = Some(*e),
            Outgoing::PassiveJoints(p) => cycle.passive = Some(*p),
            Outgoing::SimTruth(t) => cycle.truth_n = Some(t.force_n),
            Outgoing::CycleInput(c) => {
                if sar_scene::topics::valid_limits(&c.limits_in_use_n) {
                    state.limits_n = c.limits_in_use_n;
                }
                state.q_m = c.joints_q_m;
            }
            Outgoing::Joints(j) => state.q_m = j.q_m,
            _ => {}
        }
        Ok(())
    }

    /// Closes the cycle gathered: writes its scene when one is due (at most
    /// one per period of log time, keeping the phase), after the file's
    /// `/tf_static` when it is the file's first.
    fn flush_scene(&mut self) -> Result<(), WriteError> {
        let (Some(state), Some(file)) = (self.scene.as_mut(), self.current.as_mut()) else {
            return Ok(());
        };
        let Some(SceneCycle {
            stamp_ns: log_ns,
            estimator: Some(estimator),
            passive,
            truth_n,
        }) = state.cycle.take()
        else {
            return Ok(());
        };
        if !state.rate.due(log_ns) {
            return Ok(());
        }
        let Some(channels) = file.scene.as_mut() else {
            return Ok(());
        };
        let published = sar_scene::topics::scene_state(&sar_scene::topics::SceneInput {
            estimator,
            passive,
            q_m: state.q_m,
            limits_n: state.limits_n,
            truth_n,
        });
        let geometry = &state.options.geometry;
        let mut out = SceneOut {
            writer: &mut file.writer,
            path: &file.path,
            buf: &mut state.buf,
            log_ns,
        };
        if !channels.static_written {
            let frames = scene::static_frames(log_ns);
            out.put((channels.tf_static, 0), sar_scene::TF_STATIC_TOPIC, |b| {
                frames.encode(b)
            })?;
            channels.static_written = true;
        }
        let at = |channel| (channel, channels.sequence);
        let markers = scene::scene(&published, geometry);
        out.put(at(channels.scene), sar_scene::SCENE_TOPIC, |b| {
            markers.encode(b)
        })?;
        let frames = scene::moving_frames(&published, geometry);
        out.put(at(channels.tf), sar_scene::TF_TOPIC, |b| frames.encode(b))?;
        let status = sar_scene::topics::scene_status(&published);
        out.put(at(channels.status), sar_scene::SCENE_STATUS_TOPIC, |b| {
            status.encode(b)
        })?;
        channels.sequence = channels.sequence.wrapping_add(1);
        Ok(())
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

/// Adds the scene's schemas and channels to a new recording file.
fn scene_channels(
    writer: &mut mcap::Writer<CountingFile>,
    path: &Path,
) -> Result<SceneChannels, WriteError> {
    let mcap_err = |source| WriteError::mcap(path.to_path_buf(), source);
    let qos = |profiles: &str| BTreeMap::from([(QOS_METADATA_KEY.to_owned(), profiles.to_owned())]);
    let markers = writer
        .add_schema(
            MarkerArray::TYPE_NAME,
            "ros2msg",
            MarkerArray::SCHEMA.as_bytes(),
        )
        .map_err(mcap_err)?;
    let tf = writer
        .add_schema(
            TfMessage::TYPE_NAME,
            "ros2msg",
            TfMessage::SCHEMA.as_bytes(),
        )
        .map_err(mcap_err)?;
    let status = writer
        .add_schema(
            SceneStatus::TYPE_NAME,
            "ros2msg",
            SceneStatus::SCHEMA.as_bytes(),
        )
        .map_err(mcap_err)?;
    Ok(SceneChannels {
        scene: writer
            .add_channel(
                markers,
                sar_scene::SCENE_TOPIC,
                "cdr",
                &qos(OFFERED_QOS_PROFILES),
            )
            .map_err(mcap_err)?,
        tf: writer
            .add_channel(tf, sar_scene::TF_TOPIC, "cdr", &qos(OFFERED_QOS_PROFILES))
            .map_err(mcap_err)?,
        tf_static: writer
            .add_channel(
                tf,
                sar_scene::TF_STATIC_TOPIC,
                "cdr",
                &qos(OFFERED_QOS_PROFILES_LATCHED),
            )
            .map_err(mcap_err)?,
        status: writer
            .add_channel(
                status,
                sar_scene::SCENE_STATUS_TOPIC,
                "cdr",
                &qos(OFFERED_QOS_PROFILES),
            )
            .map_err(mcap_err)?,
        sequence: 0,
        static_written: false,
    })
}

/// Where one scene's messages go: the open file, at the cycle's log time.
struct SceneOut<'a> {
    writer: &'a mut mcap::Writer<CountingFile>,
    path: &'a Path,
    buf: &'a mut Vec<u8>,
    log_ns: u64,
}

impl SceneOut<'_> {
    /// Encodes one message of `topic` (by `encode`, into the reused buffer)
    /// and writes it on `channel_id`.
    fn put(
        &mut self,
        (channel_id, sequence): (u16, u32),
        topic: &'static str,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), sar_msgs::cdr::CdrError>,
    ) -> Result<(), WriteError> {
        encode(self.buf).map_err(|source| WriteError::Encode { topic, source })?;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: self.log_ns,
            publish_time: self.log_ns,
        };
        self.writer
            .write_to_known_channel(&header, self.buf)
            .map_err(|source| WriteError::mcap(self.path.to_path_buf(), source))
    }
}

impl OpenFile {
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
