//! Where a set of files starts: its inputs (bytes or files), and what the
//! first file's metadata says of the whole set ([`SetStart`]: the bias, the
//! daemon's first cycle, snapshots, a lean recording), and the output file
//! made from it ([`output_writer`]).

use super::options::{ReplayError, ReplayOptions};
use crate::convert::{self, REPLAY_METADATA, bias_from_metadata};
use crate::file::{FileOptions, RotatingWriter, WriteError};
use crate::lean;
use crate::output::PendingFile;
use crate::reader::{McapReader, ReadError};
use sar_estimator::Vec3;
use sar_estimator::cycle::Bias;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The `sar_replay` bias of a recording (zero when absent).
pub(super) fn start_bias(reader: &McapReader<'_>) -> Bias {
    replay_metadata(reader)
        .and_then(bias_from_metadata)
        .unwrap_or(Bias::force_only(Vec3::zeros()))
}

/// One recording to replay: bytes in memory, or a file streamed record by
/// record (memory independent of its length).
#[derive(Debug, Clone, Copy)]
pub(super) enum Input<'b> {
    Bytes(&'b [u8]),
    File(&'b Path),
}

impl<'b> Input<'b> {
    pub(super) fn open(&self) -> Result<McapReader<'b>, ReadError> {
        match self {
            Input::Bytes(b) => McapReader::new(b),
            Input::File(p) => McapReader::open(p),
        }
    }
    pub(super) fn path(&self) -> Option<PathBuf> {
        match self {
            Input::Bytes(_) => None,
            Input::File(p) => Some(p.to_path_buf()),
        }
    }
    /// Its length, bytes (0 when it cannot be read: the reader says why).
    pub(super) fn len(&self) -> u64 {
        match self {
            Input::Bytes(b) => b.len() as u64,
            Input::File(p) => std::fs::metadata(p).map_or(0, |m| m.len()),
        }
    }
}

/// A file opened and read up to its first message: the metadata written
/// at a file's start (`sar_replay`, `sar_config`) is then known.
pub(super) fn probe<'b>(input: &Input<'b>) -> Result<McapReader<'b>, ReadError> {
    let mut probe = input.open()?;
    let _ = probe.next();
    Ok(probe)
}

/// The `sar_replay` metadata a reader has seen.
pub(super) fn replay_metadata<'r>(
    reader: &'r McapReader<'_>,
) -> Option<&'r BTreeMap<String, String>> {
    reader
        .metadata()
        .iter()
        .find(|m| m.name == REPLAY_METADATA)
        .map(|m| &m.metadata)
}

/// How a file is named in errors and reports.
pub(super) fn display_name(path: Option<&PathBuf>) -> String {
    path.map_or_else(|| "the input".to_owned(), |p| p.display().to_string())
}

/// What the first file says of the whole set (its `sar_replay` metadata,
/// written at its start).
pub(super) struct SetStart {
    /// The estimator's bias at the start (zero without the metadata).
    pub(super) bias: Bias,
    /// The metadata itself (copied into the output).
    pub(super) metadata: Option<BTreeMap<String, String>>,
    /// Whether the set holds the daemon's first cycle
    /// ([`ReplayReport::from_first_cycle`]).
    pub(super) from_first_cycle: Option<bool>,
    /// Whether its files start with snapshots.
    pub(super) with_snapshots: bool,
    /// Whether it is a lean recording (`record_mode = "inputs"`).
    pub(super) lean: bool,
    /// Its `sar_config` metadata (copied into the full file made of a
    /// lean one).
    pub(super) config: Option<BTreeMap<String, String>>,
}

impl SetStart {
    /// Read from the first file, up to its first message.
    pub(super) fn read(first: &Input<'_>) -> Result<Self, ReplayError> {
        let probe = probe(first)?;
        let metadata = replay_metadata(&probe).cloned();
        let from_first_cycle = metadata.as_ref().map(|m| {
            m.get("from_first_cycle").is_some_and(|v| v == "true")
                && m.get("file_index").is_none_or(|i| i == "0")
        });
        let with_snapshots = metadata
            .as_ref()
            .is_some_and(|m| m.contains_key(convert::SNAPSHOT_FORMAT_KEY));
        let lean = metadata
            .as_ref()
            .is_some_and(|m| m.contains_key(lean::RECORD_MODE_KEY));
        let config = probe
            .metadata()
            .iter()
            .find(|m| m.name == convert::CONFIG_METADATA)
            .map(|m| m.metadata.clone());
        Ok(Self {
            bias: start_bias(&probe),
            metadata,
            from_first_cycle,
            with_snapshots,
            lean,
            config,
        })
    }
}

/// The output file of a replay (`options.output`; `None`: not written),
/// written into `pending`'s temporary file.
pub(super) fn output_writer(
    options: &ReplayOptions,
    start: &SetStart,
    pending: Option<&PendingFile>,
) -> Result<Option<RotatingWriter>, WriteError> {
    let Some(pending) = pending else {
        return Ok(None);
    };
    let mut o = FileOptions::single(pending.tmp_path());
    // The replayed file holds every cycle of its input.
    o.metadata = start
        .metadata
        .as_ref()
        .map(|m| (REPLAY_METADATA.to_owned(), m.clone()))
        .into_iter()
        .collect();
    if start.lean {
        // The full file of a lean one: its metadata as the full mode
        // writes it (the configuration too).
        for (_, m) in &mut o.metadata {
            m.remove(lean::RECORD_MODE_KEY);
        }
        if let Some(c) = &start.config {
            o.metadata
                .push((convert::CONFIG_METADATA.to_owned(), c.clone()));
        }
    }
    // The 3D scene, as the daemon's recorder writes it.
    o.scene = options
        .scene_period_ns
        .map(|period_ns| crate::SceneOptions {
            geometry: sar_scene::geometry::SceneGeometry::from_config(&options.config),
            limits_n: options.config.guard.force_limits().to_array(),
            period_ns,
        });
    Ok(Some(RotatingWriter::new(o)?))
}
