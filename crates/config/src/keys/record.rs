//! `[record]`: recording from the daemon's start (`sarctl record
//! start|stop` at any time), where, how files rotate, the queue, the scene
//! and the snapshots in each file, and what a recording holds.

use crate::decl::{choice, int, num, switch, text};
use crate::keys::ns;
use crate::toml_file::Ctx;
use crate::{ConfigError, DeviceScales, RecordMode, RecordSettings, Rotation};

crate::section! {
    /// The recording (sarctl record start|stop at any time).
    section "record";
    /// record from the start (sarctl record start|stop any time)
    enabled: bool = value(false), switch() => [RecordSettings.enabled];
    /// relative: to the working directory sard starts in (made absolute at start, logged)
    directory: String = value("recordings"), text("a path, not empty") => [RecordSettings.directory];
    /// a new file after this many MB (0: no size limit)
    max_file_mb: f64 = value(1024.0), num(0.0, 1e6, "MB") => [RecordSettings.rotation];
    /// a new file after this long (0: no time limit)
    max_file_s: f64 = value(600.0), num(0.0, 86_400.0, "s") => [RecordSettings.rotation];
    /// messages; a full queue drops and counts
    queue_capacity: i64 = value(65536), int(1024, 1 << 24, "messages") => [RecordSettings.queue_capacity];
    /// the 3D scene in each recording (0: none)
    scene_hz: f64 = value(30.0), num(0.0, 1000.0, "Hz") => [RecordSettings.scene_period_ns];
    /// the loop's decision state every this often (and at each file's start): replay from any file
    snapshot_s: f64 = value(10.0), num(0.01, 3600.0, "s") => [RecordSettings.snapshot_period_ns];
    /// "full": every topic; "inputs": what replay needs (~0.1 of the size), `sarctl replay --output` makes the full file
    mode: String = value(RecordMode::Full.name()),
        choice(&[RecordMode::Full.name(), RecordMode::Inputs.name()]) => [RecordSettings.mode];
}

/// The recording's settings (the devices' scales are the drivers').
pub(crate) fn build(ctx: &Ctx<'_>, r: &Section) -> Result<RecordSettings, ConfigError> {
    if r.directory.is_empty() {
        return Err(ctx.err(KEY.directory.key, "must not be empty"));
    }
    let mode = RecordMode::from_name(&r.mode)
        .ok_or_else(|| ctx.err(KEY.mode.key, format!("unknown mode {:?}", r.mode)))?;
    Ok(RecordSettings {
        mode,
        scales: DeviceScales::default(),
        enabled: r.enabled,
        directory: std::path::PathBuf::from(&r.directory),
        rotation: Rotation {
            max_bytes: (r.max_file_mb > 0.0).then(|| (r.max_file_mb * 1e6).round() as u64),
            max_duration_ns: (r.max_file_s > 0.0).then(|| ns(r.max_file_s)),
        },
        queue_capacity: usize::try_from(r.queue_capacity).unwrap_or(65536),
        scene_period_ns: (r.scene_hz > 0.0).then(|| (1e9 / r.scene_hz).round() as u64),
        snapshot_period_ns: ns(r.snapshot_s),
        config_source: None,
    })
}
