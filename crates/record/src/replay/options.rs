//! How to replay ([`ReplayOptions`], [`Mode`]), and why a replay stops
//! ([`ReplayError`]).

use crate::file::WriteError;
use crate::lean;
use crate::output::OutputError;
use crate::reader::ReadError;
use sar_estimator::cycle::EstimatorConfig;
use sar_loop::step::StepConfig;
use std::path::PathBuf;

/// How to replay.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// The estimator's configuration.
    pub config: EstimatorConfig,
    /// The loop step's (daemon recordings).
    pub step: StepConfig,
    /// Where to write the outputs (`None`: not written).
    pub output: Option<PathBuf>,
    /// The reference topic of the error figures.
    pub compare: Option<String>,
    /// Keep the tip force series (time, estimate, reference) for a plot.
    pub keep_series: bool,
    /// Compare with the recorded outputs (daemon recordings; on by default).
    pub check_recorded: bool,
    /// Replay only the cycles from this time on, s after the recording's
    /// first cycle (daemon recordings): the step starts from the snapshot
    /// before it and runs up to it without writing or comparing.
    pub from_s: Option<f64>,
    /// Stop after the cycles up to this time, s after the first cycle.
    pub to_s: Option<f64>,
    /// The 3D scene in the output: at most one per this much log time, ns
    /// (the configuration's `[record] scene_hz`, as the daemon's recorder
    /// writes it; `None`: no scene).
    pub scene_period_ns: Option<u64>,
}

impl ReplayOptions {
    /// The options of a daemon configuration: nothing written, no
    /// comparison, no series.
    pub fn from_config(config: &sar_config::Config) -> Self {
        Self {
            config: config.estimator,
            step: config.step_config(),
            output: None,
            compare: None,
            keep_series: false,
            check_recorded: true,
            from_s: None,
            to_s: None,
            scene_period_ns: config.record.scene_period_ns,
        }
    }
}

/// How the recording was replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// From `/sar/cycle/input`.
    CycleInput,
    /// From `/sar/sensor/wrench` and `/sar/joints`.
    InputsOnly,
}

impl Mode {
    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::CycleInput => "cycle_input",
            Mode::InputsOnly => "inputs_only",
        }
    }
}

/// Why a replay could not run.
#[non_exhaustive]
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The input is not an MCAP file, or a message cannot be decoded.
    #[error("{0}")]
    Read(#[from] ReadError),
    /// The output could not be written.
    #[error("{0}")]
    Write(#[from] WriteError),
    /// The estimator refused the configuration.
    #[error("the configuration: {0}")]
    Setting(String),
    /// A lean recording's batch does not hold what it says.
    #[error("{0}")]
    Lean(#[from] lean::BatchError),
    /// Neither `/sar/cycle/input` nor `/sar/sensor/wrench` messages.
    #[error("no inputs: the recording has no /sar/cycle/input and no /sar/sensor/wrench messages")]
    NoInputs,
    /// No input read, and corrupt records passed over: they may have held
    /// the inputs.
    #[error(
        "no inputs read: no /sar/cycle/input and no /sar/sensor/wrench messages outside {records} corrupt records ({bytes} bytes in {parts} part(s) passed over; the first: {first})"
    )]
    NoInputsAmidCorrupt {
        /// Corrupt records passed over.
        records: u64,
        /// Their bytes.
        bytes: u64,
        /// The gaps.
        parts: u64,
        /// The first, described.
        first: String,
    },
    /// The comparison's reference topic has no usable message.
    #[error("--compare {topic}: {why}")]
    Compare {
        /// The topic.
        topic: String,
        /// What is wrong.
        why: &'static str,
    },
    /// The output would overwrite an input (the same file by any name),
    /// or too little space is free for it.
    #[error("{0}")]
    Output(#[from] OutputError),
    /// `--from`/`--to` out of order or not finite and >= 0.
    #[error("the time range: {0}")]
    Range(String),
    /// Internal: the replay reached `to_s` (never returned to the caller).
    #[error("the end of the time range")]
    EndOfRange,
    /// An inputs-only recording's messages are further out of log-time
    /// order than the window that orders them in bounded memory.
    #[error(
        "a message at log time {log_time_ns} ns comes after later ones by more than {window} messages: the inputs cannot be put in time order in bounded memory"
    )]
    Order {
        /// The message's log time.
        log_time_ns: u64,
        /// [`INPUT_WINDOW`].
        window: usize,
    },
    /// A lean recording whose cycles are laid out by another version of
    /// `sard` (its `/sar/cycle/batch` schema is not this version's): its
    /// nested cycle inputs cannot be cut apart without misreading them.
    #[error(
        "/sar/cycle/batch at log time {log_time_ns} ns: a lean recording of another version of sard (its cycle layout differs from this sarctl's: the fields each version added); replay it with the sarctl of the sard that recorded it"
    )]
    OtherLeanLayout {
        /// The batch's log time.
        log_time_ns: u64,
    },
    /// `/sar/cycle/input` appears after the inputs-only replay had started
    /// (more than the window of sensor and joint messages before it).
    #[error(
        "/sar/cycle/input first appears at log time {log_time_ns} ns, after more than {window} sensor and joint messages had been replayed as an inputs-only recording"
    )]
    LateCycleInput {
        /// The cycle input's log time.
        log_time_ns: u64,
        /// [`INPUT_WINDOW`].
        window: usize,
    },
    /// The files of a set do not chain.
    #[error("{file} does not follow the previous file: {why}")]
    Chain {
        /// The file.
        file: String,
        /// How.
        why: String,
    },
    /// A recorded snapshot cannot be restored (corrupted, another format,
    /// or taken under another configuration): never trusted.
    #[error("the snapshot after cycle {after_cycle} cannot be restored: {source}")]
    Snapshot {
        /// The cycle it was taken after.
        after_cycle: u64,
        /// Why.
        source: sar_snapshot::SnapshotError,
    },
}

/// `--from`/`--to`: times >= 0, in order.
pub(super) fn check_range(options: &ReplayOptions) -> Result<(), ReplayError> {
    for v in [options.from_s, options.to_s].into_iter().flatten() {
        if !(v.is_finite() && v >= 0.0) {
            return Err(ReplayError::Range(format!("{v} s is not a time >= 0")));
        }
    }
    if let (Some(a), Some(b)) = (options.from_s, options.to_s)
        && a > b
    {
        return Err(ReplayError::Range(format!(
            "--from {a} s is after --to {b} s"
        )));
    }
    Ok(())
}
