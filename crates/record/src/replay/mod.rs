//! Replay (`sarctl replay`): the per-cycle step run over a recording's
//! inputs as fast as the machine allows, its outputs written and compared.
//!
//! - A daemon recording (one `/sar/cycle/input` per cycle) replays cycle by
//!   cycle; every output message is compared, as CDR bytes, with the one the
//!   daemon recorded on the same topic in the same order: the first that
//!   differs is reported with its cycle, topic and field.
//! - A recording of the inputs alone (`/sar/sensor/wrench` and `/sar/joints`,
//!   another program's or a simulated one) replays one cycle per sensor
//!   message with the newest joint message at or before it (by log time);
//!   the sensor counter is the message's index, `now` its log time, and a
//!   reset is given every cycle until one is accepted (as an operator would).
//!   The messages are put in log-time order in a window of
//!   [`INPUT_WINDOW`] messages, so memory stays bounded; a recording further
//!   out of order than that is refused.
//! - `compare`: the unfiltered tip force of every cycle with a new sample and
//!   an observable estimate against a reference channel (e.g.
//!   `/sar/sim/tip_wrench_truth`), paired by stamp (the newest reference at or
//!   before the estimate's): the absolute relative error of MODEL.md 6, RMS
//!   and maximum error per axis.
//!
//! The estimator starts with the bias of the recording's `sar_replay`
//! metadata (zero when absent).
//!
//! The modules: `options` (how, and why it stops), `report` (what it
//! says), `start` (the inputs and the set's start), `replayer` (the step
//! over the inputs, outputs matched), `set` (the files read in turn),
//! `inputs_only` (recordings of the inputs alone), `compare`
//! (`--compare`).

mod compare;
mod inputs_only;
mod options;
mod replayer;
mod report;
mod set;
mod start;

pub use inputs_only::INPUT_WINDOW;
use options::check_range;
pub use options::{Mode, ReplayError, ReplayOptions};
pub use report::{
    AxisError, Comparison, Difference, Gap, MAX_GAPS_SHOWN, ReplayReport, SeriesPoint,
};
use set::SetReplay;
use start::Input;

use crate::convert::{self};
use crate::output::check_outputs;
use crate::reader::{McapReader, ReadError};
use sar_msgs::msgs::Topic;
use std::path::{Path, PathBuf};

/// The output topics compared and written (`/sar/cycle/input` of a daemon
/// recording is recomputed from its input and the step's decision, so that
/// the reference, the drive action and the reply are compared too).
pub const OUTPUT_TOPICS: [Topic; 6] = [
    Topic::CycleInput,
    Topic::EstimatorState,
    Topic::TipWrench,
    Topic::TipWrenchFiltered,
    Topic::PassiveJoints,
    Topic::GuardEvents,
];

/// The most replayed messages of one topic waiting for their recorded
/// counterpart; beyond it the recording is taken to lack that topic's
/// outputs (a difference).
pub const MAX_PENDING: usize = 4096;

/// The configuration a recording carries (`sar_config` metadata, written by
/// `sard` since it records its configuration), `None` when it has none.
/// A file that ends (or is corrupt) before its first message and holds no
/// configuration is that error (truncated at which byte), not "none".
pub fn recorded_config(path: &Path) -> Result<Option<sar_config::ConfigSource>, ReadError> {
    // The metadata is written at the start of a file: read up to the first
    // message to find it (streamed: the file is not read whole).
    let mut probe = McapReader::open(path)?;
    let first = probe.next();
    let config = probe
        .metadata()
        .iter()
        .find(|m| m.name == convert::CONFIG_METADATA)
        .and_then(|m| convert::config_from_metadata(&m.metadata));
    match (config, first) {
        (None, Some(Err(e))) => Err(e),
        (config, _) => Ok(config),
    }
}

/// Replays the recording held in `bytes` (see the module documentation).
pub fn replay(bytes: &[u8], options: &ReplayOptions) -> Result<ReplayReport, ReplayError> {
    replay_with(&[Input::Bytes(bytes)], options)
}

/// Replays the files of a rotated recording in order, as one: the step
/// carries on from file to file, each file's first snapshot is compared
/// with the carried state, and the files must chain (their `file_index`
/// one after the other, and each file's first cycle the one after the
/// previous file's last). A difference names its file.
pub fn replay_files(
    inputs: &[PathBuf],
    options: &ReplayOptions,
) -> Result<ReplayReport, ReplayError> {
    if inputs.is_empty() {
        return Err(ReplayError::NoInputs);
    }
    if let Some(out) = &options.output {
        let paths: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
        check_outputs(&[out], &paths)?;
    }
    let inputs: Vec<Input<'_>> = inputs.iter().map(|p| Input::File(p)).collect();
    replay_with(&inputs, options)
}

/// The replay of `inputs`, in order, as one: the set opened from its first
/// file, each file chained to the previous one and visited, then finished.
fn replay_with(inputs: &[Input<'_>], options: &ReplayOptions) -> Result<ReplayReport, ReplayError> {
    check_range(options)?;
    let first = inputs.first().ok_or(ReplayError::NoInputs)?;
    let input_bytes = inputs
        .iter()
        .map(Input::len)
        .fold(0u64, u64::saturating_add);
    let mut set = SetReplay::open(first, options, input_bytes)?;
    for (index, input) in inputs.iter().enumerate() {
        if inputs.len() > 1 {
            set.chain(input)?;
        }
        set.visit_file(index, input)?;
        if set.ended() {
            break;
        }
    }
    set.finish()
}

/// Replays the file at `input` (refuses an `output` that is the input).
pub fn replay_file(input: &Path, options: &ReplayOptions) -> Result<ReplayReport, ReplayError> {
    replay_files(std::slice::from_ref(&input.to_path_buf()), options)
}
