//! `sarctl export --rosbag2 DIR REC.mcap...`: a rosbag2 directory of
//! recordings, as ROS 2's recorder leaves one: the MCAP files themselves
//! (hard-linked, or copied when a link cannot be made) beside a
//! `metadata.yaml` (rosbag2 version 9, storage `mcap`, no compression of
//! the files; every channel with its message count, its `ros2msg` type and
//! the `offered_qos_profiles` the file carries), so that `ros2 bag
//! info|play DIR` and Python `rosbags.rosbag2.Reader(DIR)` open it.
//!
//! The files of one recording (a rotation's `-0000.mcap`, `-0001.mcap`,
//! ...) go into one directory in the order given. Only complete `ros2`
//! files are taken: a file cut short, even inside its summary (the data
//! section whole), is refused (`sarctl recover` first). The 3D scene is in
//! the files themselves, CDR like every channel.

use super::reader::{McapReader, ReadError};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The rosbag2 metadata version written (ROS 2 Jazzy's).
pub const METADATA_VERSION: u32 = 9;

/// Why a directory could not be written.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// No recording was given.
    #[error("no recording given")]
    NoInput,
    /// A recording could not be read.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: ReadError,
    },
    /// A recording is not a complete `ros2` MCAP file.
    #[error("{path}: {why}")]
    NotRos2 {
        /// The file.
        path: PathBuf,
        /// What it is instead.
        why: String,
    },
    /// The directory exists and holds something.
    #[error(
        "{0} exists and is not empty: give a new directory (ros2 bag record refuses an existing one too)"
    )]
    NotEmpty(PathBuf),
    /// The directory's path is a file.
    #[error("{0} is a file, not a directory")]
    NotADirectory(PathBuf),
    /// Two recordings have the same file name.
    #[error("two recordings are named {0}: a rosbag2 directory holds each file by its name")]
    SameName(String),
    /// The directory or a file in it could not be written.
    #[error("{path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// One channel of the directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicCount {
    /// The topic.
    pub topic: String,
    /// Its ROS 2 type (`geometry_msgs/msg/WrenchStamped`).
    pub type_name: String,
    /// Its `offered_qos_profiles` metadata ("" when the file has none).
    pub offered_qos_profiles: String,
    /// Messages in every file.
    pub messages: u64,
}

/// One file of the directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileCount {
    /// Its name in the directory.
    pub name: String,
    /// The first message's log time, ns (0 when it has none).
    pub start_ns: u64,
    /// From the first message's log time to the last's, ns.
    pub duration_ns: u64,
    /// Messages in it.
    pub messages: u64,
}

/// What [`export`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportReport {
    /// The directory.
    pub directory: PathBuf,
    /// Its files, in order.
    pub files: Vec<FileCount>,
    /// Its channels, in the order of their first appearance.
    pub topics: Vec<TopicCount>,
    /// Files copied because a hard link could not be made (another file system).
    pub copied: usize,
}

impl ExportReport {
    /// Messages in every file.
    pub fn messages(&self) -> u64 {
        self.files.iter().map(|f| f.messages).sum()
    }
    /// The first message's log time over every file, ns.
    pub fn start_ns(&self) -> u64 {
        self.files
            .iter()
            .filter(|f| f.messages > 0)
            .map(|f| f.start_ns)
            .min()
            .unwrap_or(0)
    }
    /// From the first message's log time to the last's, over every file, ns.
    pub fn duration_ns(&self) -> u64 {
        let end = self
            .files
            .iter()
            .filter(|f| f.messages > 0)
            .map(|f| f.start_ns.saturating_add(f.duration_ns))
            .max()
            .unwrap_or(0);
        end.saturating_sub(self.start_ns())
    }
}

/// Counts the messages of one complete `ros2` file, per topic, into `topics`.
fn count(path: &Path, topics: &mut Vec<TopicCount>) -> Result<FileCount, ExportError> {
    let read = |source| ExportError::Read {
        path: path.to_path_buf(),
        source,
    };
    let not_ros2 = |why| ExportError::NotRos2 {
        path: path.to_path_buf(),
        why,
    };
    let bytes = super::reader::read_file(path).map_err(read)?;
    let mut reader = McapReader::new(&bytes).map_err(read)?;
    let data = DataCount::read(&mut reader).map_err(|source| {
        not_ros2(format!(
            "{source}; `sarctl recover` rewrites a file cut short"
        ))
    })?;
    check_summary(&bytes).map_err(not_ros2)?;
    check_ros2(&reader).map_err(not_ros2)?;
    add_topics(&reader, &data.per_channel, topics);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let messages = data.messages;
    Ok(FileCount {
        name,
        start_ns: if messages > 0 { data.first_ns } else { 0 },
        duration_ns: if messages > 0 {
            data.last_ns - data.first_ns
        } else {
            0
        },
        messages,
    })
}

/// The messages of a file's data section: per channel, in all, and the
/// first and last log times.
struct DataCount {
    per_channel: BTreeMap<u16, u64>,
    first_ns: u64,
    last_ns: u64,
    messages: u64,
}

impl DataCount {
    /// Every message of the data section, which must be whole.
    fn read(reader: &mut McapReader<'_>) -> Result<Self, ReadError> {
        let mut c = Self {
            per_channel: BTreeMap::new(),
            first_ns: u64::MAX,
            last_ns: 0,
            messages: 0,
        };
        for m in reader.by_ref() {
            let m = m?;
            *c.per_channel.entry(m.channel_id).or_default() += 1;
            c.first_ns = c.first_ns.min(m.log_time_ns);
            c.last_ns = c.last_ns.max(m.log_time_ns);
            c.messages += 1;
        }
        Ok(c)
    }
}

/// The data section is whole; the summary and the footer must be too:
/// ROS 2's and Python's readers start there (a file cut inside its
/// summary is refused by them).
fn check_summary(bytes: &[u8]) -> Result<(), String> {
    match mcap::Summary::read(bytes) {
        Ok(Some(_)) => Ok(()),
        Ok(None) => {
            Err("the file has no summary section: `sarctl recover` rewrites it with one".to_owned())
        }
        Err(e) => Err(format!(
            "truncated or corrupt after its data section (it ends at byte {} inside its summary or footer: {e}): `sarctl recover` rewrites it",
            bytes.len()
        )),
    }
}

/// The file's profile is `ros2` and every channel `cdr`/`ros2msg`.
fn check_ros2(reader: &McapReader<'_>) -> Result<(), String> {
    let profile = reader.profile().unwrap_or_default();
    if profile != "ros2" {
        return Err(format!(
            "MCAP profile {profile:?}, not \"ros2\" (ROS 2 tools refuse it; an older build's scene companion NAME.scene.mcap is not part of a rosbag2 directory)"
        ));
    }
    for c in reader.channels().values() {
        if c.message_encoding != "cdr" || c.schema_encoding() != "ros2msg" {
            return Err(format!(
                "channel {} is {}/{}, not cdr/ros2msg",
                c.topic,
                c.message_encoding,
                c.schema_encoding()
            ));
        }
    }
    Ok(())
}

/// Each channel's messages added to its topic's count (a topic of another
/// file with the same type adds up), with the channel's offered QoS.
fn add_topics(
    reader: &McapReader<'_>,
    per_channel: &BTreeMap<u16, u64>,
    topics: &mut Vec<TopicCount>,
) {
    for c in reader.channels().values() {
        let n = per_channel.get(&c.id).copied().unwrap_or(0);
        let qos = c
            .metadata
            .get(super::QOS_METADATA_KEY)
            .cloned()
            .unwrap_or_default();
        match topics
            .iter_mut()
            .find(|t| t.topic == c.topic && t.type_name == c.schema_name())
        {
            Some(t) => t.messages += n,
            None => topics.push(TopicCount {
                topic: c.topic.clone(),
                type_name: c.schema_name().to_owned(),
                offered_qos_profiles: qos,
                messages: n,
            }),
        }
    }
}

/// A YAML double-quoted scalar (JSON's string syntax is a subset of it).
fn quoted(s: &str) -> String {
    serde_json::Value::String(s.to_owned()).to_string()
}

/// The `metadata.yaml` of a report, as rosbag2 writes it.
pub fn metadata_yaml(r: &ExportReport) -> String {
    let mut y = String::new();
    let _ = writeln!(y, "rosbag2_bagfile_information:");
    let _ = writeln!(y, "  version: {METADATA_VERSION}");
    let _ = writeln!(y, "  storage_identifier: mcap");
    let _ = writeln!(y, "  duration:\n    nanoseconds: {}", r.duration_ns());
    let _ = writeln!(
        y,
        "  starting_time:\n    nanoseconds_since_epoch: {}",
        r.start_ns()
    );
    let _ = writeln!(y, "  message_count: {}", r.messages());
    let _ = writeln!(y, "  topics_with_message_count:");
    for t in &r.topics {
        let _ = writeln!(y, "    - topic_metadata:");
        let _ = writeln!(y, "        name: {}", quoted(&t.topic));
        let _ = writeln!(y, "        type: {}", quoted(&t.type_name));
        let _ = writeln!(y, "        serialization_format: cdr");
        let _ = writeln!(
            y,
            "        offered_qos_profiles: {}",
            quoted(&t.offered_qos_profiles)
        );
        let _ = writeln!(y, "        type_description_hash: \"\"");
        let _ = writeln!(y, "      message_count: {}", t.messages);
    }
    let _ = writeln!(y, "  compression_format: \"\"");
    let _ = writeln!(y, "  compression_mode: \"\"");
    let _ = writeln!(y, "  relative_file_paths:");
    for f in &r.files {
        let _ = writeln!(y, "    - {}", quoted(&f.name));
    }
    let _ = writeln!(y, "  files:");
    for f in &r.files {
        let _ = writeln!(y, "    - path: {}", quoted(&f.name));
        let _ = writeln!(
            y,
            "      starting_time:\n        nanoseconds_since_epoch: {}",
            f.start_ns
        );
        let _ = writeln!(y, "      duration:\n        nanoseconds: {}", f.duration_ns);
        let _ = writeln!(y, "      message_count: {}", f.messages);
    }
    let _ = writeln!(y, "  custom_data: ~");
    let _ = writeln!(y, "  ros_distro: \"\"");
    y
}

/// Writes the rosbag2 directory `dir` of `recordings` (see the module's
/// documentation). `dir` must not exist, or be empty.
pub fn export(dir: &Path, recordings: &[PathBuf]) -> Result<ExportReport, ExportError> {
    if recordings.is_empty() {
        return Err(ExportError::NoInput);
    }
    let write = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ExportError::Write { path, source }
    };
    if dir.exists() {
        if !dir.is_dir() {
            return Err(ExportError::NotADirectory(dir.to_path_buf()));
        }
        if std::fs::read_dir(dir).map_err(write(dir))?.next().is_some() {
            return Err(ExportError::NotEmpty(dir.to_path_buf()));
        }
    }
    // Everything is read and checked before anything is written.
    let mut topics = Vec::new();
    let mut files: Vec<FileCount> = Vec::new();
    for path in recordings {
        let f = count(path, &mut topics)?;
        if files.iter().any(|g| g.name == f.name) {
            return Err(ExportError::SameName(f.name));
        }
        files.push(f);
    }
    std::fs::create_dir_all(dir).map_err(write(dir))?;
    let mut copied = 0;
    for (path, f) in recordings.iter().zip(&files) {
        let to = dir.join(&f.name);
        if std::fs::hard_link(path, &to).is_err() {
            std::fs::copy(path, &to).map_err(write(&to))?;
            copied += 1;
        }
    }
    let report = ExportReport {
        directory: dir.to_path_buf(),
        files,
        topics,
        copied,
    };
    let yaml = dir.join("metadata.yaml");
    std::fs::write(&yaml, metadata_yaml(&report)).map_err(write(&yaml))?;
    Ok(report)
}
