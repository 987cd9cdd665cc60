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

use super::convert::{self, REPLAY_METADATA, bias_from_metadata};
use super::file::{FileOptions, RotatingWriter, WriteError};
use super::lean;
use super::output::{OutputError, PendingFile, SpaceWatch, check_outputs};
use super::reader::{ChannelInfo, McapReader, MessageRef, ReadError};
use sar_estimator::Vec3;
use sar_estimator::cycle::{
    Bias, Command, CommandAccepted, CycleContext, CycleInput, CycleOutput, Estimator,
    EstimatorConfig, JointSample, SensorSample, TipOutcome,
};
use sar_kinematics::ActiveJoints;
use sar_loop::step::{LoopInput, LoopStep, StepConfig};
use sar_msgs::msgs::{
    ActiveJointState, CycleBatch, CycleInput as CycleInputMsg, Outgoing, RecorderDrops, RosMessage,
    SnapshotChunk, StateSnapshot, Topic,
};
use std::collections::{BTreeMap, VecDeque};
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

/// The first replayed output that differs from the recorded one.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    /// The cycle.
    pub cycle: u64,
    /// The topic.
    pub topic: &'static str,
    /// The first field that differs (`message` when the messages cannot be
    /// told apart field by field, e.g. one is missing).
    pub field: String,
    /// The recorded value.
    pub recorded: String,
    /// The replayed value.
    pub replayed: String,
    /// The file it is in (replays of files; `None` for bytes in memory).
    pub file: Option<PathBuf>,
}

impl Difference {
    /// A replayed message `m` of `topic` at `cycle` without its recorded
    /// counterpart.
    fn not_recorded(topic: Topic, cycle: u64, m: &Outgoing) -> Self {
        Self {
            file: None,
            cycle,
            topic: topic.name(),
            field: "message".into(),
            recorded: "(none)".into(),
            replayed: format!("{m:?}"),
        }
    }
}

/// Error figures of one axis (MODEL.md 6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisError {
    /// Absolute relative error e_ra (a fraction).
    pub e_ra: f64,
    /// RMS of estimate - reference, N.
    pub rms_n: f64,
    /// Largest |estimate - reference|, N.
    pub max_n: f64,
}

/// The estimate against a reference channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The reference topic.
    pub topic: String,
    /// Pairs compared.
    pub pairs: usize,
    /// Estimates left out: not observable, or no reference at or before them.
    pub left_out: usize,
    /// X, Y, Z.
    pub axes: [AxisError; 3],
}

/// One point of the tip-force series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeriesPoint {
    /// Time from the first cycle, s.
    pub t_s: f64,
    /// The unfiltered estimate, N.
    pub estimate_n: [f64; 3],
    /// The reference, N.
    pub reference_n: Option<[f64; 3]>,
}

/// What a replay found.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayReport {
    /// How the inputs were read.
    pub mode: Mode,
    /// Cycles run.
    pub cycles: u64,
    /// Output messages produced.
    pub outputs: u64,
    /// Output messages compared with recorded ones (daemon recordings).
    pub compared: u64,
    /// Output messages that differ (or are missing on one side).
    pub differences: u64,
    /// The first difference.
    pub first_difference: Option<Difference>,
    /// Messages the recorder reported dropped (`/sar/recorder/drops`).
    pub recorder_dropped: u64,
    /// Whether the input was read to its end (false: cut short, replayed up
    /// to its last complete chunk).
    pub input_complete: bool,
    /// Why reading stopped early.
    pub stopped: Option<String>,
    /// The error figures, with `compare`.
    pub comparison: Option<Comparison>,
    /// The tip-force series, with `keep_series`.
    pub series: Vec<SeriesPoint>,
    /// The output file, when written.
    pub output: Option<PathBuf>,
    /// Whether the recording holds the daemon's first cycle (its `sar_replay`
    /// metadata: recorded from the start, first file of a rotation); `None`
    /// without that metadata. A recording that does not lacks the
    /// estimator's earlier state (guard, filter, bias after tares): its
    /// replay may differ.
    pub from_first_cycle: Option<bool>,
    /// The snapshot replay started from (`/sar/cycle/snapshot`): the cycle
    /// it was taken after. `None`: replay started at the recording's first
    /// cycle (a recording from the daemon's start, or one without
    /// snapshots).
    pub from_snapshot: Option<u64>,
    /// Cycles of the recording before the snapshot replay started from (not
    /// replayed: their state is unknown).
    pub skipped_cycles: u64,
    /// Recorded snapshots compared with the replayed step's state (byte for
    /// byte; a difference is reported on `/sar/cycle/snapshot`).
    pub snapshots_compared: u64,
    /// Corrupt parts passed over (a chunk whose data, CRC or content is
    /// bad; a run of corrupt records one after the other is one part), and
    /// cycles found missing: reading went on after each; the cycles after
    /// one are replayed again from the next snapshot (their state is
    /// unknown before it). The first [`MAX_GAPS_SHOWN`] only (memory
    /// bounded whatever the file holds): `gaps_total` counts them all.
    pub gaps: Vec<Gap>,
    /// Every gap, shown in `gaps` or not.
    pub gaps_total: u64,
    /// Every corrupt record passed over.
    pub corrupt_records: u64,
    /// Their bytes.
    pub corrupt_bytes: u64,
}

/// The most gaps a [`ReplayReport`] holds in detail.
pub const MAX_GAPS_SHOWN: usize = 16;

/// The largest step forward of a cycle number taken as cycles missing; a
/// larger one is a step back below cycle 0 (a lean batch's difference
/// wraps).
const MAX_FORWARD: u64 = i64::MAX as u64;

impl ReplayReport {
    /// The report before the first cycle.
    fn start(output: Option<PathBuf>, from_first_cycle: Option<bool>) -> Self {
        Self {
            mode: Mode::CycleInput,
            cycles: 0,
            outputs: 0,
            compared: 0,
            differences: 0,
            first_difference: None,
            recorder_dropped: 0,
            input_complete: false,
            stopped: None,
            comparison: None,
            series: Vec::new(),
            output,
            from_first_cycle,
            from_snapshot: None,
            skipped_cycles: 0,
            snapshots_compared: 0,
            gaps: Vec::new(),
            gaps_total: 0,
            corrupt_records: 0,
            corrupt_bytes: 0,
        }
    }
}

/// A corrupt part of a recording that replay passed over.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Gap {
    /// The file (replays of files).
    pub file: Option<PathBuf>,
    /// Where, and how many bytes (the record passed over).
    pub skipped: super::reader::Skipped,
    /// The last cycle read before it.
    pub last_cycle_before: Option<u64>,
    /// The first cycle read after it (`None`: none followed).
    pub first_cycle_after: Option<u64>,
    /// Cycles read after it but not replayed (no snapshot yet to restore
    /// the state from).
    pub cycles_not_replayed: u64,
    /// The snapshot replay went on from after it (`None`: none came).
    pub resumed_after_cycle: Option<u64>,
}

impl Gap {
    /// A gap in `file` after `last_cycle_before` (what follows it is noted
    /// as reading goes on).
    fn new(
        file: Option<PathBuf>,
        skipped: super::reader::Skipped,
        last_cycle_before: Option<u64>,
    ) -> Self {
        Self {
            file,
            skipped,
            last_cycle_before,
            first_cycle_after: None,
            cycles_not_replayed: 0,
            resumed_after_cycle: None,
        }
    }

    /// Cycles lost in it (by their numbers on either side).
    pub fn cycles_lost(&self) -> Option<u64> {
        Some(
            self.first_cycle_after?
                .saturating_sub(self.last_cycle_before?)
                .saturating_sub(1),
        )
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

struct Sink {
    writer: Option<RotatingWriter>,
    status: RecorderDrops,
    /// The output's temporary file, renamed over the output once the
    /// replay has written all of it; removed if it stops before.
    pending: Option<PendingFile>,
    /// The output's file system's free space.
    space: Option<SpaceWatch>,
}

impl Sink {
    fn write(&mut self, m: &Outgoing) -> Result<(), ReplayError> {
        if let Some(w) = &mut self.writer {
            self.status.stamp_ns = self.status.stamp_ns.max(m.stamp_ns());
            w.write(m, &self.status)?;
            if let Some(space) = &mut self.space {
                space.written(w.open_file_bytes())?;
            }
        }
        Ok(())
    }

    /// The output closed and renamed over its path.
    fn finish(&mut self) -> Result<(), ReplayError> {
        if let Some(w) = &mut self.writer {
            w.close(&self.status)?;
        }
        if let Some(p) = self.pending.take() {
            p.commit()?;
        }
        Ok(())
    }
}

struct Replayer {
    scratch: Vec<Outgoing>,
    estimator: Estimator,
    step: LoopStep,
    sink: Sink,
    report: ReplayReport,
    /// Per output topic: the replayed messages (cycle, message, bytes) not
    /// yet matched, and the recorded ones (bytes) not yet matched.
    replayed: BTreeMap<Topic, VecDeque<(u64, Outgoing, Vec<u8>)>>,
    recorded: BTreeMap<Topic, VecDeque<Vec<u8>>>,
    comparing: bool,
    /// Topics whose recorded outputs are missing (no longer compared).
    lacking: Vec<Topic>,
    /// What the cycles add up to beyond the report's counts.
    tally: Tally,
    /// The latest gap beyond [`MAX_GAPS_SHOWN`] (counted, not in the
    /// report).
    unshown_gap: Option<Gap>,
    references: Vec<(u64, [f64; 3])>,
    last_cycle: u64,
    /// Whether the step's state is known (from the first cycle, or restored
    /// from a snapshot): cycles before are skipped with their outputs.
    anchored: bool,
    /// The snapshot taken of the replayed step (compared, written).
    snapshot: Box<sar_snapshot::Snapshot>,
    /// Before `from_s`: cycles are stepped, nothing is written or compared.
    quiet: bool,
    /// Whether a cycle was stepped since the state became known (the next
    /// one must follow it).
    stepped: bool,
}

fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// What every replayed cycle adds up to, whether its messages are made or
/// not (beside the report's counts): the first cycle's stamp and the
/// estimates kept for `--compare` and `--plot`.
struct Tally {
    /// The stamp of the first cycle replayed, ns.
    first_ns: Option<u64>,
    /// The observable estimates of new samples (stamp, tip force N), with
    /// `keep_estimates`.
    estimates: Vec<(u64, [f64; 3])>,
    /// New samples without an observable estimate, with `keep_estimates`.
    left_out: usize,
    keep_estimates: bool,
}

impl Tally {
    /// Nothing counted yet; the estimates kept with `keep_estimates`.
    fn new(keep_estimates: bool) -> Self {
        Self {
            first_ns: None,
            estimates: Vec::new(),
            left_out: 0,
            keep_estimates,
        }
    }

    /// One cycle stamped `stamp_ns` ([`convert::cycle_stamp_ns`]): counted in
    /// `report`, its stamp noted, its estimate kept (`--compare`, `--plot`).
    fn cycle(&mut self, report: &mut ReplayReport, stamp_ns: u64, out: &CycleOutput) {
        report.cycles += 1;
        self.first_ns.get_or_insert(stamp_ns);
        if self.keep_estimates && out.new_sample {
            match out.tip {
                TipOutcome::Estimate(e) if e.observable => {
                    self.estimates.push((stamp_ns, arr(&e.force_n)));
                }
                _ => self.left_out += 1,
            }
        }
    }
}

impl Replayer {
    /// A replayer at the start of a set: the estimator and the step from
    /// the configuration and the set's start bias, the output opened.
    /// `input_bytes`: the inputs' length (the output of a full recording
    /// is about as long; a lean one's is longer).
    fn new(
        options: &ReplayOptions,
        start: &SetStart,
        input_bytes: u64,
    ) -> Result<Self, ReplayError> {
        let estimator = Estimator::with_bias(&options.config, start.bias)
            .map_err(|e| ReplayError::Setting(e.to_string()))?;
        let step = LoopStep::new(&options.config, start.bias, options.step)
            .map_err(|e| ReplayError::Setting(e.to_string()))?;
        let (pending, space) = match &options.output {
            Some(out) => {
                let pending = PendingFile::new(out)?;
                let space = SpaceWatch::before(out, pending.tmp_path(), input_bytes)?;
                (Some(pending), Some(space))
            }
            None => (None, None),
        };
        let writer = output_writer(options, start, pending.as_ref())?;
        Ok(Self {
            scratch: Vec::with_capacity(8),
            estimator,
            step,
            sink: Sink {
                writer,
                status: RecorderDrops::default(),
                pending,
                space,
            },
            report: ReplayReport::start(options.output.clone(), start.from_first_cycle),
            replayed: BTreeMap::new(),
            recorded: BTreeMap::new(),
            comparing: options.check_recorded,
            lacking: Vec::new(),
            tally: Tally::new(options.compare.is_some() || options.keep_series),
            unshown_gap: None,
            references: Vec::new(),
            last_cycle: 0,
            // A recording whose files start with snapshots waits for one,
            // unless it holds the daemon's first cycle; one without steps
            // from its first cycle (as before snapshots; it may differ if
            // it started mid-run, and says so).
            anchored: start.from_first_cycle == Some(true) || !start.with_snapshots,
            snapshot: Box::new(sar_snapshot::Snapshot::new()),
            quiet: false,
            stepped: false,
        })
    }

    /// The recording is a lean one: of the outputs, only the guard
    /// events are in it to compare (and the snapshots).
    fn lean_comparison(&mut self) {
        for topic in OUTPUT_TOPICS {
            if topic != Topic::GuardEvents && !self.lacking.contains(&topic) {
                self.lacking.push(topic);
                self.replayed.remove(&topic);
                self.recorded.remove(&topic);
            }
        }
    }

    /// The recording is an inputs-only one: nothing to compare.
    fn inputs_only_mode(&mut self) {
        self.report.mode = Mode::InputsOnly;
        self.comparing = false;
        self.replayed.clear();
        self.recorded.clear();
    }

    /// Before a recorded `cycle` of `file`, while stepping: cycles missing
    /// before it (dropped by its recorder, or a corrupt chunk `sarctl
    /// recover` passed over), or a cycle number that goes back (repeated,
    /// earlier, or below 0 by a lean batch's difference), make a gap, as a
    /// corrupt chunk does; each named as what it is.
    fn follows(&mut self, file: Option<PathBuf>, cycle: u64) {
        if !(self.anchored && self.stepped) {
            return;
        }
        let last = self.last_cycle;
        let step = cycle.wrapping_sub(last);
        let why = match step {
            1 => return,
            2..=MAX_FORWARD => format!(
                "cycles {}..={} are missing from the recording (dropped by its recorder, or a corrupt chunk passed over by `sarctl recover`)",
                last + 1,
                cycle - 1
            ),
            0 => format!(
                "cycle {cycle} is recorded twice: the recording's cycle numbers go back (corrupt or crafted)"
            ),
            _ if cycle < last => format!(
                "cycle {cycle} follows cycle {last}: the recording's cycle numbers go back by {} (corrupt or crafted)",
                last - cycle
            ),
            _ => format!(
                "cycle {cycle} follows cycle {last}: the recording's cycle numbers go back by {} below cycle 0 (corrupt or crafted)",
                last.wrapping_sub(cycle)
            ),
        };
        let skipped = super::reader::Skipped {
            offset: 0,
            bytes: 0,
            log_time_ns: None,
            records: 0,
            why,
        };
        self.gap(Gap::new(file, skipped, Some(last)), false);
    }

    /// A corrupt record of `file` passed over.
    fn corrupt_part(&mut self, file: Option<PathBuf>, skipped: super::reader::Skipped) {
        let last_cycle_before =
            (self.anchored || self.report.cycles > 0).then_some(self.last_cycle);
        self.gap(Gap::new(file, skipped, last_cycle_before), true);
    }

    /// Whether a recorded cycle is replayed: not while the state is
    /// unknown (before the first snapshot, or after a gap before the next
    /// one), counted then as skipped or not replayed.
    fn replayable(&mut self, cycle: u64) -> bool {
        let anchored = self.anchored;
        if let Some(gap) = self.last_gap() {
            gap.first_cycle_after.get_or_insert(cycle);
            if !anchored {
                // After a corrupt part, before a snapshot.
                gap.cycles_not_replayed += 1;
                return false;
            }
        }
        if !self.anchored {
            // Before the first snapshot: the state is unknown.
            self.report.skipped_cycles += 1;
            return false;
        }
        true
    }

    /// The tip-force series (`--plot`): each kept estimate with the
    /// reference at or before it.
    fn series(&self) -> Vec<SeriesPoint> {
        let t0 = self.tally.first_ns.unwrap_or(0);
        self.tally
            .estimates
            .iter()
            .map(|(t, e)| SeriesPoint {
                t_s: t.saturating_sub(t0) as f64 * 1e-9,
                estimate_n: *e,
                reference_n: reference_at(&self.references, *t),
            })
            .collect()
    }

    /// One cycle of a daemon recording: the loop step. `between`: the
    /// cycle's input messages a lean recording gives back
    /// (`/sar/sensor/wrench`, `/sar/joints`), written after its
    /// `/sar/cycle/input` (not compared).
    fn loop_cycle(&mut self, input: &LoopInput, between: &[Outgoing]) -> Result<(), ReplayError> {
        let needs_messages = self.needs_messages();
        let out = self.step.step(input);
        self.last_cycle = input.cycle;
        self.stepped = true;
        if self.quiet {
            // Before the range: only the state matters.
            return Ok(());
        }
        if !needs_messages {
            // Nothing written or compared (no output file, no comparison
            // with the recorded outputs): the decision is counted where it
            // lies, not copied (the copies of the step's output were about
            // a twentieth of a replayed cycle): `/sar/cycle/input` and the
            // messages `convert::outputs` would give are counted.
            self.report.outputs += 1 + convert::output_count(&out.estimate);
            let stamp_ns = convert::loop_stamp_ns(input);
            self.tally.cycle(&mut self.report, stamp_ns, &out.estimate);
            return Ok(());
        }
        let out = *out;
        let m = Outgoing::CycleInput(convert::cycle_input_msg(input, &out));
        self.emit(input.cycle, m)?;
        for m in between {
            self.sink.write(m)?;
        }
        self.emit_outputs(&input.cycle_input(), &out.estimate)
    }

    /// One cycle of an inputs-only recording: the estimator alone.
    fn estimator_cycle(&mut self, input: &CycleInput) -> Result<(), ReplayError> {
        let out = *self.estimator.cycle(input, &CycleContext::AT_REST);
        self.emit_outputs(input, &out)
    }

    fn emit(&mut self, cycle: u64, m: Outgoing) -> Result<(), ReplayError> {
        self.report.outputs += 1;
        self.sink.write(&m)?;
        if self.comparing && !self.lacking.contains(&m.topic()) {
            let mut bytes = Vec::with_capacity(256);
            if m.encode(&mut bytes).is_ok() {
                self.replayed
                    .entry(m.topic())
                    .or_default()
                    .push_back((cycle, m, bytes));
            }
        }
        Ok(())
    }

    fn emit_outputs(&mut self, input: &CycleInput, out: &CycleOutput) -> Result<(), ReplayError> {
        let out = *out;
        self.last_cycle = input.cycle;
        let stamp_ns = convert::cycle_stamp_ns(input);
        self.tally.cycle(&mut self.report, stamp_ns, &out);
        let cycle = input.cycle;
        if !self.needs_messages() {
            // Nothing written or compared: only counted (the messages'
            // text and encoding are most of a cycle's cost).
            self.report.outputs += convert::output_count(&out);
            return Ok(());
        }
        let mut msgs = std::mem::take(&mut self.scratch);
        msgs.clear();
        convert::outputs(input, &out, |m| msgs.push(m));
        let mut result = Ok(());
        for m in msgs.drain(..) {
            if result.is_ok() {
                result = self.emit(cycle, m);
            }
        }
        self.scratch = msgs;
        result?;
        if self.comparing {
            self.match_pending();
        }
        Ok(())
    }

    /// Whether the output messages are written or compared.
    fn needs_messages(&self) -> bool {
        self.comparing || self.sink.writer.is_some()
    }

    fn differ(&mut self, d: Difference) {
        // (leftovers at the end)
        self.report.differences += 1;
        if self.report.first_difference.is_none() {
            self.report.first_difference = Some(d);
        }
    }

    fn match_pending(&mut self) {
        for topic in OUTPUT_TOPICS {
            if self.lacking.contains(&topic) {
                continue;
            }
            let rep = self.replayed.entry(topic).or_default();
            let rec = self.recorded.entry(topic).or_default();
            while !rep.is_empty() && !rec.is_empty() {
                let (Some((cycle, m, bytes)), Some(recorded)) = (rep.pop_front(), rec.pop_front())
                else {
                    break;
                };
                self.report.compared += 1;
                if bytes != recorded {
                    self.report.differences += 1;
                    if self.report.first_difference.is_none() {
                        self.report.first_difference = Some(describe(topic, cycle, &m, &recorded));
                    }
                }
            }
            if rep.len() > MAX_PENDING {
                // The recording lacks these outputs: one difference, then
                // this topic is no longer compared.
                if let Some((cycle, m, _)) = rep.pop_front() {
                    self.report.differences += 1;
                    self.report
                        .first_difference
                        .get_or_insert_with(|| Difference::not_recorded(topic, cycle, &m));
                }
                rep.clear();
                self.lacking.push(topic);
            }
        }
    }

    /// A recorded `/sar/cycle/snapshot`: restores the step from it when the
    /// state is not known yet; else compares it with the replayed step's
    /// state, byte for byte. Written to the output either way (the replayed
    /// step's own).
    fn snapshot(&mut self, m: &StateSnapshot) -> Result<(), ReplayError> {
        let failed = |source| ReplayError::Snapshot {
            after_cycle: m.after_cycle,
            source,
        };
        if !self.anchored {
            self.step.restore(&m.data).map_err(failed)?;
            self.anchored = true;
            self.stepped = true;
            if let Some(gap) = self.last_gap() {
                // Replay goes on after a corrupt part.
                gap.resumed_after_cycle = Some(m.after_cycle);
                self.last_cycle = m.after_cycle;
                return self.write_snapshot(m);
            }
            self.report.from_snapshot = Some(m.after_cycle);
            self.last_cycle = m.after_cycle;
            // Outputs of the skipped cycles recorded after the last one
            // stepped: none are pending (they were never kept).
        } else if self.comparing {
            // The step's state after the same cycle.
            self.match_pending();
            self.step.snapshot(&mut self.snapshot).map_err(failed)?;
            self.report.compared += 1;
            self.report.snapshots_compared += 1;
            let replayed = self.snapshot.as_bytes();
            if replayed != m.data.as_slice() || self.last_cycle != m.after_cycle {
                let at = replayed
                    .iter()
                    .zip(&m.data)
                    .position(|(a, b)| a != b)
                    .unwrap_or(replayed.len().min(m.data.len()));
                self.differ(Difference {
                    file: None,
                    cycle: m.after_cycle,
                    topic: Topic::StateSnapshot.name(),
                    field: format!("state (byte {at})"),
                    recorded: format!("{} bytes after cycle {}", m.data.len(), m.after_cycle),
                    replayed: format!("{} bytes after cycle {}", replayed.len(), self.last_cycle),
                });
            }
        }
        self.write_snapshot(m)
    }

    /// The replayed step's snapshot into the output, with `m`'s stamp.
    fn write_snapshot(&mut self, m: &StateSnapshot) -> Result<(), ReplayError> {
        let failed = |source| ReplayError::Snapshot {
            after_cycle: m.after_cycle,
            source,
        };
        if self.sink.writer.is_some() && !self.quiet {
            self.step.snapshot(&mut self.snapshot).map_err(failed)?;
            let snapshot = std::mem::take(&mut self.snapshot);
            let mut result = Ok(());
            SnapshotChunk::split(m.stamp_ns, self.last_cycle, snapshot.as_bytes(), |c| {
                result = self.sink.write(&c);
                result.is_ok()
            });
            self.snapshot = snapshot;
            result?;
        }
        Ok(())
    }

    fn recorded_output(&mut self, topic: Topic, data: &[u8]) {
        if !self.anchored || self.quiet {
            return;
        }
        if self.comparing && !self.lacking.contains(&topic) {
            self.recorded
                .entry(topic)
                .or_default()
                .push_back(data.to_vec());
        }
    }

    /// A corrupt part passed over: what is pending on either side of it is
    /// not compared (its counterpart was in it), and the state is unknown
    /// until the next snapshot. `match_first`: what was read before it is
    /// matched first (a corrupt chunk, found before any message after it
    /// was read; not for cycles found missing, whose recorded outputs read
    /// may already be the later cycles').
    fn gap(&mut self, gap: Gap, match_first: bool) {
        if self.comparing && match_first {
            self.match_pending();
        }
        self.replayed.clear();
        self.recorded.clear();
        self.anchored = false;
        self.stepped = false;
        self.report.corrupt_records = self
            .report
            .corrupt_records
            .saturating_add(gap.skipped.records);
        self.report.corrupt_bytes = self.report.corrupt_bytes.saturating_add(gap.skipped.bytes);
        // A corrupt record right after the last one, nothing read between
        // them: one part (a run of them is never a list of its records).
        if let Some(last) = self.last_gap()
            && last.first_cycle_after.is_none()
            && last.file == gap.file
            && last.skipped.absorb(&gap.skipped)
        {
            return;
        }
        self.report.gaps_total = self.report.gaps_total.saturating_add(1);
        if self.report.gaps.len() < MAX_GAPS_SHOWN {
            self.report.gaps.push(gap);
        } else {
            // Counted, not kept: the latest stands for the state's
            // bookkeeping (memory bounded whatever the file holds).
            self.unshown_gap = Some(gap);
        }
    }

    /// The latest gap (kept in the report, or the latest beyond
    /// [`MAX_GAPS_SHOWN`]).
    fn last_gap(&mut self) -> Option<&mut Gap> {
        match &mut self.unshown_gap {
            Some(g) => Some(g),
            None => self.report.gaps.last_mut(),
        }
    }

    /// `complete`: the recording was not cut short (a recovered file says
    /// in its `sar_recover` metadata whether its input was).
    fn finish_comparison(&mut self, complete: bool) {
        if !self.comparing {
            return;
        }
        self.match_pending();
        let last_cycle = self.last_cycle;
        let mut leftovers = Vec::new();
        for topic in OUTPUT_TOPICS {
            if let Some(rep) = self.replayed.get(&topic) {
                for (cycle, m, _) in rep {
                    // A file cut short may lack its last cycle's outputs.
                    if complete || *cycle < last_cycle {
                        leftovers.push(Difference::not_recorded(topic, *cycle, m));
                    }
                }
            }
            if let Some(rec) = self.recorded.get(&topic) {
                for bytes in rec {
                    leftovers.push(Difference {
                        file: None,
                        cycle: last_cycle,
                        topic: topic.name(),
                        field: "message".into(),
                        recorded: format!("{:?}", Outgoing::decode(topic, bytes)),
                        replayed: "(none)".into(),
                    });
                }
            }
        }
        leftovers.sort_by_key(|d| d.cycle);
        for d in leftovers {
            self.differ(d);
        }
    }
}

/// The first field in which two messages differ, from their `Debug` forms
/// (`Name { a: 1, b: [1.0, 2.0], .. }`): top-level fields are split at the
/// commas outside brackets.
fn fields(debug: &str) -> Vec<(String, String)> {
    let inner = debug
        .find('{')
        .and_then(|i| debug.get(i + 1..debug.len().saturating_sub(1)))
        .unwrap_or(debug);
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut start = 0usize;
    let push = |s: &str, out: &mut Vec<(String, String)>| {
        let s = s.trim();
        if s.is_empty() {
            return;
        }
        match s.split_once(':') {
            Some((k, v)) => out.push((k.trim().to_owned(), v.trim().to_owned())),
            None => out.push((String::new(), s.to_owned())),
        }
    };
    for (i, c) in inner.char_indices() {
        match c {
            '[' | '{' | '(' => depth += 1,
            ']' | '}' | ')' => depth -= 1,
            ',' if depth == 0 => {
                push(inner.get(start..i).unwrap_or(""), &mut out);
                start = i + 1;
            }
            _ => {}
        }
    }
    push(inner.get(start..).unwrap_or(""), &mut out);
    out
}

fn describe(topic: Topic, cycle: u64, replayed: &Outgoing, recorded: &[u8]) -> Difference {
    let rec = Outgoing::decode(topic, recorded);
    let (field, rec_v, rep_v) = match &rec {
        Ok(r) => {
            let a = fields(&format!("{r:?}"));
            let b = fields(&format!("{replayed:?}"));
            a.iter()
                .zip(b.iter())
                .find(|(x, y)| x != y)
                .map(|((k, v), (_, w))| (k.clone(), v.clone(), w.clone()))
                // Same Debug text, different bits (e.g. -0.0 and 0.0 print
                // alike; NaN payloads).
                .unwrap_or_else(|| ("bits".into(), format!("{r:?}"), format!("{replayed:?}")))
        }
        Err(e) => (
            "message".into(),
            format!("undecodable: {e}"),
            format!("{replayed:?}"),
        ),
    };
    Difference {
        file: None,
        cycle,
        topic: topic.name(),
        field,
        recorded: rec_v,
        replayed: rep_v,
    }
}

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

/// The `sar_replay` bias of a recording (zero when absent).
fn start_bias(reader: &McapReader<'_>) -> Bias {
    replay_metadata(reader)
        .and_then(bias_from_metadata)
        .unwrap_or(Bias::force_only(Vec3::zeros()))
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

/// One recording to replay: bytes in memory, or a file streamed record by
/// record (memory independent of its length).
#[derive(Debug, Clone, Copy)]
enum Input<'b> {
    Bytes(&'b [u8]),
    File(&'b Path),
}

impl<'b> Input<'b> {
    fn open(&self) -> Result<McapReader<'b>, ReadError> {
        match self {
            Input::Bytes(b) => McapReader::new(b),
            Input::File(p) => McapReader::open(p),
        }
    }
    fn path(&self) -> Option<PathBuf> {
        match self {
            Input::Bytes(_) => None,
            Input::File(p) => Some(p.to_path_buf()),
        }
    }
    /// Its length, bytes (0 when it cannot be read: the reader says why).
    fn len(&self) -> u64 {
        match self {
            Input::Bytes(b) => b.len() as u64,
            Input::File(p) => std::fs::metadata(p).map_or(0, |m| m.len()),
        }
    }
}

/// A file opened and read up to its first message: the metadata written
/// at a file's start (`sar_replay`, `sar_config`) is then known.
fn probe<'b>(input: &Input<'b>) -> Result<McapReader<'b>, ReadError> {
    let mut probe = input.open()?;
    let _ = probe.next();
    Ok(probe)
}

/// The `sar_replay` metadata a reader has seen.
fn replay_metadata<'r>(reader: &'r McapReader<'_>) -> Option<&'r BTreeMap<String, String>> {
    reader
        .metadata()
        .iter()
        .find(|m| m.name == REPLAY_METADATA)
        .map(|m| &m.metadata)
}

/// How a file is named in errors and reports.
fn display_name(path: Option<&PathBuf>) -> String {
    path.map_or_else(|| "the input".to_owned(), |p| p.display().to_string())
}

/// `--from`/`--to`: times >= 0, in order.
fn check_range(options: &ReplayOptions) -> Result<(), ReplayError> {
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

/// What the first file says of the whole set (its `sar_replay` metadata,
/// written at its start).
struct SetStart {
    /// The estimator's bias at the start (zero without the metadata).
    bias: Bias,
    /// The metadata itself (copied into the output).
    metadata: Option<BTreeMap<String, String>>,
    /// Whether the set holds the daemon's first cycle
    /// ([`ReplayReport::from_first_cycle`]).
    from_first_cycle: Option<bool>,
    /// Whether its files start with snapshots.
    with_snapshots: bool,
    /// Whether it is a lean recording (`record_mode = "inputs"`).
    lean: bool,
    /// Its `sar_config` metadata (copied into the full file made of a
    /// lean one).
    config: Option<BTreeMap<String, String>>,
}

impl SetStart {
    /// Read from the first file, up to its first message.
    fn read(first: &Input<'_>) -> Result<Self, ReplayError> {
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
fn output_writer(
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
        .map(|period_ns| super::SceneOptions {
            geometry: sar_scene::geometry::SceneGeometry::from_config(&options.config),
            limits_n: options.config.guard.force_limits().to_array(),
            period_ns,
        });
    Ok(Some(RotatingWriter::new(o)?))
}

/// The replay of a set of files across them: the replayer, and what
/// reading the files in turn carries from one to the next.
struct SetReplay<'o> {
    r: Replayer,
    options: &'o ReplayOptions,
    /// `--from` and `--to`, ns after the first cycle.
    from_ns: Option<u64>,
    to_ns: Option<u64>,
    /// The stamp of the recording's first cycle, ns.
    first_stamp_ns: Option<u64>,
    /// Whether a `/sar/cycle/input` was read (a daemon recording).
    saw_cycle_input: bool,
    /// The window of an inputs-only recording.
    inputs_only: InputsOnly,
    /// Whether a file is a recovered one whose input was cut short.
    recovered_from_cut: bool,
    /// Whether every file was read to its end.
    complete: bool,
    /// The previous file's `file_index`.
    previous_index: Option<u64>,
    /// Whether the replay reached `--to`.
    reached_end_of_range: bool,
    /// Whether the recording is a lean one (`/sar/cycle/batch` read).
    lean: bool,
}

/// One file's reading state (channel ids are the file's own).
struct FileVisit {
    path: Option<PathBuf>,
    /// Topic per channel id (the index), looked up once per channel:
    /// `None` for a channel not seen yet.
    topics: Vec<Option<Option<Topic>>>,
    /// The channel of `--compare`'s reference topic.
    reference_channel: Option<u16>,
    /// The cycle the file must start with (after the previous file's).
    expect_cycle: Option<u64>,
}

impl FileVisit {
    /// How the file is named in errors and reports.
    fn name(&self) -> String {
        display_name(self.path.as_ref())
    }

    /// The topic of channel `id` (looked up once per channel, which is
    /// also when the reference channel of `compare` is found).
    #[inline(always)]
    fn topic(
        &mut self,
        channels: &BTreeMap<u16, ChannelInfo>,
        id: u16,
        compare: Option<&String>,
    ) -> Option<Topic> {
        if let Some(Some(t)) = self.topics.get(usize::from(id)) {
            return *t;
        }
        let channel = channels.get(&id);
        let topic = channel.and_then(|c| Topic::from_name(&c.topic));
        if let (Some(c), Some(reference)) = (channel, compare)
            && &c.topic == reference
        {
            self.reference_channel = Some(id);
        }
        let at = usize::from(id);
        if self.topics.len() <= at {
            self.topics.resize(at + 1, None);
        }
        if let Some(slot) = self.topics.get_mut(at) {
            *slot = Some(topic);
        }
        topic
    }

    /// The file's first cycle must be the one after the previous file's
    /// last.
    fn check_start(&mut self, cycle: u64) -> Result<(), ReplayError> {
        if let Some(want) = self.expect_cycle.take()
            && cycle != want
        {
            return Err(ReplayError::Chain {
                file: self.name(),
                why: format!(
                    "it starts at cycle {}, the previous file ends at cycle {}",
                    cycle,
                    want.saturating_sub(1)
                ),
            });
        }
        Ok(())
    }
}

impl<'o> SetReplay<'o> {
    /// Opens the set: the first file's metadata read, the estimator, the
    /// step and the output made.
    fn open(
        first: &Input<'_>,
        options: &'o ReplayOptions,
        input_bytes: u64,
    ) -> Result<Self, ReplayError> {
        let start = SetStart::read(first)?;
        let range_ns = |s: Option<f64>| s.map(|v| (v * 1e9).round() as u64);
        Ok(Self {
            r: Replayer::new(options, &start, input_bytes)?,
            options,
            from_ns: range_ns(options.from_s),
            to_ns: range_ns(options.to_s),
            first_stamp_ns: None,
            saw_cycle_input: false,
            inputs_only: InputsOnly::new(),
            recovered_from_cut: false,
            complete: true,
            previous_index: None,
            reached_end_of_range: false,
            lean: start.lean,
        })
    }

    /// A file of a set of several must follow the previous one: one
    /// rotation, in order (its `file_index` the next).
    fn chain(&mut self, input: &Input<'_>) -> Result<(), ReplayError> {
        let probe = probe(input)?;
        let index = replay_metadata(&probe)
            .and_then(|m| m.get("file_index").and_then(|v| v.parse::<u64>().ok()));
        if let (Some(prev), Some(index)) = (self.previous_index, index)
            && index != prev + 1
        {
            return Err(ReplayError::Chain {
                file: display_name(input.path().as_ref()),
                why: if index == 0 {
                    "it starts another recording (file_index 0): give the files of one recording (NAME-0000.mcap, NAME-0001.mcap, ...)".to_owned()
                } else {
                    format!("its file_index is {index}, the previous file's {prev}")
                },
            });
        }
        self.previous_index = index;
        Ok(())
    }

    /// The `index`th file of the set: its messages replayed in order, a
    /// corrupt part passed over (reading goes on after it; the state is
    /// unknown until the next snapshot), how it ended noted.
    fn visit_file(&mut self, index: usize, input: &Input<'_>) -> Result<(), ReplayError> {
        let mut reader = input.open()?;
        let mut file = FileVisit {
            path: input.path(),
            topics: Vec::new(),
            reference_channel: None,
            expect_cycle: (index > 0 && self.r.anchored)
                .then_some(self.r.last_cycle.saturating_add(1)),
        };
        let result = loop {
            let result = self.visit_records(&mut reader, &mut file);
            if let Ok(Some(e)) = &result
                && let Some(skipped) = reader.skip_bad_record(e)
            {
                self.r.corrupt_part(file.path.clone(), skipped);
                continue;
            }
            break result;
        };
        self.end_file(&reader, &file, result)
    }

    /// The file's records up to its end, a cut or a corrupt part
    /// (`Ok(Some)`), or `--to` (noted, `Ok(None)`).
    fn visit_records(
        &mut self,
        reader: &mut McapReader<'_>,
        file: &mut FileVisit,
    ) -> Result<Option<ReadError>, ReplayError> {
        let mut visitor = |channels: &BTreeMap<u16, ChannelInfo>,
                           msg: MessageRef<'_>|
         -> Result<(), ReplayError> { self.message(file, channels, msg) };
        match reader.visit(&mut visitor) {
            Err(ReplayError::EndOfRange) => {
                self.reached_end_of_range = true;
                Ok(None)
            }
            other => other,
        }
    }

    /// One message: the reference of `--compare`, a cycle input, a
    /// snapshot, an inputs-only message, the recorder's drops, or a
    /// recorded output (to compare).
    #[inline(always)]
    fn message(
        &mut self,
        file: &mut FileVisit,
        channels: &BTreeMap<u16, ChannelInfo>,
        msg: MessageRef<'_>,
    ) -> Result<(), ReplayError> {
        let id = msg.channel_id;
        let topic = file.topic(channels, id, self.options.compare.as_ref());
        let decode_err = |source| ReadError::Decode {
            topic: topic.map_or("?", |t| t.name()).to_owned(),
            log_time_ns: msg.log_time_ns,
            source,
        };
        if file.reference_channel == Some(id) {
            let w = sar_msgs::msgs::WrenchStamped::decode(msg.data).map_err(decode_err)?;
            self.r.references.push((w.stamp_ns, w.force_n));
            return Ok(());
        }
        match topic {
            Some(Topic::CycleInput) => {
                self.start_cycle_inputs(msg.log_time_ns)?;
                let m = CycleInputMsg::decode(msg.data).map_err(decode_err)?;
                self.cycle_input(file, &m, msg.data)?;
            }
            Some(Topic::StateSnapshot) => {
                let m = StateSnapshot::decode(msg.data).map_err(decode_err)?;
                self.r.snapshot(&m)?;
            }
            Some(Topic::CycleBatch) => {
                self.start_cycle_inputs(msg.log_time_ns)?;
                self.cycle_batch(file, &msg)?;
            }
            Some(Topic::SensorWrench) if !self.saw_cycle_input => {
                let w = sar_msgs::msgs::WrenchStamped::decode(msg.data).map_err(decode_err)?;
                let item = InputItem::Sensor(w);
                self.inputs_only.push(&mut self.r, msg.log_time_ns, item)?;
            }
            Some(Topic::Joints) if !self.saw_cycle_input => {
                let j = ActiveJointState::decode(msg.data).map_err(decode_err)?;
                let item = InputItem::Joints(j);
                self.inputs_only.push(&mut self.r, msg.log_time_ns, item)?;
            }
            Some(Topic::RecorderDrops) => {
                let d = RecorderDrops::decode(msg.data).map_err(decode_err)?;
                self.r.report.recorder_dropped = self.r.report.recorder_dropped.max(d.dropped);
                if self.lean {
                    // The full file made of a lean one says its drops.
                    let s = &mut self.r.sink.status;
                    s.dropped = s.dropped.max(d.dropped);
                    s.queue_capacity = d.queue_capacity;
                }
            }
            Some(t) if OUTPUT_TOPICS.contains(&t) => self.r.recorded_output(t, msg.data),
            _ => {}
        }
        Ok(())
    }

    /// The first `/sar/cycle/input` makes the recording a daemon one: the
    /// inputs-only window is forgotten (refused once its cycles have run).
    fn start_cycle_inputs(&mut self, log_time_ns: u64) -> Result<(), ReplayError> {
        if !self.saw_cycle_input {
            if self.inputs_only.started {
                return Err(ReplayError::LateCycleInput {
                    log_time_ns,
                    window: INPUT_WINDOW,
                });
            }
            self.saw_cycle_input = true;
            self.inputs_only.discard();
        }
        Ok(())
    }

    /// One cycle of a daemon recording (`data`: its recorded bytes): its
    /// place in the file and the time range checked, cycles missing before
    /// it made a gap, skipped while the state is unknown, else stepped and
    /// the recorded message compared with the one rebuilt from its input
    /// and the replayed decision.
    #[inline(always)]
    fn cycle_input(
        &mut self,
        file: &mut FileVisit,
        m: &CycleInputMsg,
        data: &[u8],
    ) -> Result<(), ReplayError> {
        file.check_start(m.cycle)?;
        self.r.quiet = self.before_range(m.stamp_ns)?;
        let r = &mut self.r;
        r.follows(file.path.clone(), m.cycle);
        if !r.replayable(m.cycle) {
            return Ok(());
        }
        // A message of an older recording (without the fields added since,
        // a command in the older layout) compares as `sard` records it now
        // (`command::upgraded`, the fields added since at their default):
        // the same input and decision, in today's layout.
        let mut now = Vec::with_capacity(data.len() + 64);
        match sar_msgs::msgs::RosMessage::encode(&sar_msgs::command::upgraded(m), &mut now) {
            Ok(()) => r.recorded_output(Topic::CycleInput, &now),
            Err(_) => r.recorded_output(Topic::CycleInput, data),
        }
        r.loop_cycle(&convert::loop_input(m), &[])
    }

    /// A lean recording's `/sar/cycle/batch`: its cycles, each as a
    /// recorded `/sar/cycle/input` is, with its sensor and joint messages
    /// written after it. Only the guard events and the snapshots are
    /// compared (the other outputs are not in a lean file).
    fn cycle_batch(
        &mut self,
        file: &mut FileVisit,
        msg: &MessageRef<'_>,
    ) -> Result<(), ReplayError> {
        let batch = CycleBatch::decode(msg.data).map_err(|source| ReadError::Decode {
            topic: Topic::CycleBatch.name().to_owned(),
            log_time_ns: msg.log_time_ns,
            source,
        })?;
        let cycles = lean::unbatch(&batch)?;
        self.lean = true;
        if !self.r.lacking.contains(&Topic::CycleInput) {
            self.r.lean_comparison();
        }
        let mut between = Vec::with_capacity(4);
        for c in &cycles {
            let m = &c.input;
            file.check_start(m.cycle)?;
            self.r.quiet = self.before_range(m.stamp_ns)?;
            let r = &mut self.r;
            r.follows(file.path.clone(), m.cycle);
            if !r.replayable(m.cycle) {
                continue;
            }
            between.clear();
            between.extend(c.sensors.iter().map(|w| Outgoing::SensorWrench(*w)));
            if c.joints_message {
                between.push(Outgoing::Joints(lean::joints_msg_of(m)));
            }
            r.loop_cycle(&convert::loop_input(m), &between)?;
        }
        Ok(())
    }

    /// Whether a cycle stamped `stamp_ns` comes before `--from` (stepped
    /// quietly); [`ReplayError::EndOfRange`] after `--to`.
    fn before_range(&mut self, stamp_ns: u64) -> Result<bool, ReplayError> {
        let t0 = *self.first_stamp_ns.get_or_insert(stamp_ns);
        let t = stamp_ns.saturating_sub(t0);
        if self.to_ns.is_some_and(|to| t > to) {
            return Err(ReplayError::EndOfRange);
        }
        Ok(self.from_ns.is_some_and(|from| t < from))
    }

    /// A file read (`result`: how reading ended): the first difference
    /// named by its file, a cut noted, whether it was complete.
    fn end_file(
        &mut self,
        reader: &McapReader<'_>,
        file: &FileVisit,
        result: Result<Option<ReadError>, ReplayError>,
    ) -> Result<(), ReplayError> {
        if let Some(d) = &mut self.r.report.first_difference
            && d.file.is_none()
        {
            d.file = file.path.clone();
        }
        if let Some(e) = result? {
            self.r.report.stopped = Some(format!("{}: {e}", file.name()));
        }
        self.complete &= reader.is_complete();
        self.recovered_from_cut |= reader
            .metadata()
            .iter()
            .any(|m| m.name == "sar_recover" && m.metadata.contains_key("stopped"));
        Ok(())
    }

    /// Whether the set ends here: a file cut short (what follows cannot
    /// chain), or `--to` reached.
    fn ended(&self) -> bool {
        self.r.report.stopped.is_some() || self.reached_end_of_range
    }

    /// Every file read: what is pending compared (a daemon recording) or
    /// the inputs-only window replayed; the comparison with the reference,
    /// the series; the output closed.
    fn finish(mut self) -> Result<ReplayReport, ReplayError> {
        let r = &mut self.r;
        r.report.input_complete = self.complete;
        if self.saw_cycle_input {
            r.finish_comparison(
                self.complete && !self.recovered_from_cut && !self.reached_end_of_range,
            );
        } else {
            if self.inputs_only.sensors_seen == 0 {
                let rep = &r.report;
                return Err(match rep.gaps.first() {
                    Some(g) if rep.corrupt_records > 0 => ReplayError::NoInputsAmidCorrupt {
                        records: rep.corrupt_records,
                        bytes: rep.corrupt_bytes,
                        parts: rep.gaps_total,
                        first: g.skipped.describe(),
                    },
                    _ => ReplayError::NoInputs,
                });
            }
            r.inputs_only_mode();
            self.inputs_only.finish(r)?;
        }
        if let Some(topic) = &self.options.compare {
            r.report.comparison = Some(compare(r, topic)?);
        }
        if self.options.keep_series {
            r.report.series = r.series();
        }
        r.sink.finish()?;
        Ok(self.r.report)
    }
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

/// The most inputs-only messages (`/sar/sensor/wrench`, `/sar/joints`) held
/// to put them in log-time order: a recording whose messages are further out
/// of order than this is refused ([`ReplayError::Order`]), never paired
/// wrongly. 4096 messages are about 2 s of a 1 kHz sensor and joints.
pub const INPUT_WINDOW: usize = 4096;

/// One inputs-only message waiting in the window.
#[derive(Debug)]
enum InputItem {
    Joints(ActiveJointState),
    Sensor(sar_msgs::msgs::WrenchStamped),
}

/// Its place in the replay's order: log time, then joints before a sensor
/// sample at the same time (the joint at or before a sample pairs with it),
/// then the order in the file.
#[derive(Debug)]
struct Pending {
    key: (u64, u8, u64),
    item: InputItem,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key.cmp(&other.key)
    }
}

/// The replay of an inputs-only recording, streamed: messages enter a
/// window of at most [`INPUT_WINDOW`] ordered by [`Pending::key`]; the
/// earliest leaves when the window is full, and its cycle runs. The result
/// is the one of sorting the whole recording (as the replay did when it held
/// it in memory) whenever no message is more than the window out of order;
/// otherwise the replay stops with [`ReplayError::Order`].
struct InputsOnly {
    window: std::collections::BinaryHeap<std::cmp::Reverse<Pending>>,
    /// Messages pushed, for the order in the file.
    sequence: u64,
    /// Sensor messages seen (in any order).
    sensors_seen: u64,
    /// The key of the last message out of the window.
    last_key: Option<(u64, u8, u64)>,
    /// Whether a message has left the window (a cycle may have run).
    started: bool,
    /// The newest joint message out of the window.
    latest: Option<ActiveJointState>,
    /// Sensor messages out of the window (the counter given to the cycle).
    sensor_index: u64,
    cycle: u64,
    reset_pending: bool,
}

impl InputsOnly {
    fn new() -> Self {
        Self {
            window: std::collections::BinaryHeap::with_capacity(INPUT_WINDOW),
            sequence: 0,
            sensors_seen: 0,
            last_key: None,
            started: false,
            latest: None,
            sensor_index: 0,
            cycle: 0,
            reset_pending: true,
        }
    }

    /// Forget the window: the recording turned out to hold cycle inputs.
    fn discard(&mut self) {
        debug_assert!(!self.started, "inputs-only cycles ran before a cycle input");
        self.window.clear();
    }

    /// One message, at its log time; cycles run for those that leave.
    fn push(
        &mut self,
        r: &mut Replayer,
        log_time_ns: u64,
        item: InputItem,
    ) -> Result<(), ReplayError> {
        let kind = match item {
            InputItem::Joints(_) => 0,
            InputItem::Sensor(_) => {
                self.sensors_seen += 1;
                1
            }
        };
        let key = (log_time_ns, kind, self.sequence);
        self.sequence += 1;
        if let Some(last) = self.last_key
            && key < last
        {
            return Err(ReplayError::Order {
                log_time_ns,
                window: INPUT_WINDOW,
            });
        }
        if self.window.len() >= INPUT_WINDOW
            && let Some(std::cmp::Reverse(first)) = self.window.pop()
        {
            if !self.started {
                self.started = true;
                r.inputs_only_mode();
            }
            self.run(r, first)?;
        }
        debug_assert!(self.window.len() < INPUT_WINDOW);
        self.window.push(std::cmp::Reverse(Pending { key, item }));
        Ok(())
    }

    /// The messages left in the window, in order.
    fn finish(&mut self, r: &mut Replayer) -> Result<(), ReplayError> {
        while let Some(std::cmp::Reverse(first)) = self.window.pop() {
            self.run(r, first)?;
        }
        Ok(())
    }

    /// A message leaves the window: a joint message becomes the newest, a
    /// sensor message runs a cycle with it.
    fn run(&mut self, r: &mut Replayer, p: Pending) -> Result<(), ReplayError> {
        debug_assert!(self.last_key.is_none_or(|last| last < p.key));
        self.last_key = Some(p.key);
        let t = p.key.0;
        let w = match p.item {
            InputItem::Joints(j) => {
                self.latest = Some(j);
                return Ok(());
            }
            InputItem::Sensor(w) => w,
        };
        let index = self.sensor_index;
        self.sensor_index += 1;
        let Some(js) = &self.latest else {
            return Ok(());
        };
        self.cycle += 1;
        let finite = w.force_n.iter().chain(&w.torque_nm).all(|v| v.is_finite());
        let [fx, fy, fz] = w.force_n;
        let [tx, ty, tz] = w.torque_nm;
        let [q1_m, q2_m, q3_m] = js.q_m;
        let input = CycleInput {
            cycle: self.cycle,
            now_ns: Some(t),
            sensor: SensorSample {
                force_n: Vec3::new(fx, fy, fz),
                torque_nm: Vec3::new(tx, ty, tz),
                // The index: every message a new sample, no gap.
                counter: (index as u32).wrapping_add(1),
                status: 0,
                stamp_ns: w.stamp_ns,
                valid: finite,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: JointSample {
                joints: ActiveJoints { q1_m, q2_m, q3_m },
                stamp_ns: js.stamp_ns,
                valid: js.q_m.iter().all(|v| v.is_finite()),
            },
            command: self.reset_pending.then_some(Command::Reset),
        };
        r.estimator_cycle(&input)?;
        if let Some(ev) = r.estimator.last().command
            && matches!(ev.result, Ok(CommandAccepted::Reset))
        {
            self.reset_pending = false;
        }
        Ok(())
    }
}

fn reference_at(refs: &[(u64, [f64; 3])], t: u64) -> Option<[f64; 3]> {
    let i = refs.partition_point(|(s, _)| *s <= t);
    refs.get(i.checked_sub(1)?).map(|(_, f)| *f)
}

fn compare(r: &mut Replayer, topic: &str) -> Result<Comparison, ReplayError> {
    if r.references.is_empty() {
        return Err(ReplayError::Compare {
            topic: topic.to_owned(),
            why: "no message on this topic (it must be a geometry_msgs/msg/WrenchStamped)",
        });
    }
    r.references.sort_by_key(|(t, _)| *t);
    let mut est: [Vec<f64>; 3] = Default::default();
    let mut refv: [Vec<f64>; 3] = Default::default();
    let mut left_out = r.tally.left_out;
    for (t, e) in &r.tally.estimates {
        let Some(f) = reference_at(&r.references, *t) else {
            left_out += 1;
            continue;
        };
        for k in 0..3 {
            if let (Some(a), Some(b), Some(x), Some(y)) =
                (est.get_mut(k), refv.get_mut(k), e.get(k), f.get(k))
            {
                a.push(*x);
                b.push(*y);
            }
        }
    }
    let pairs = est.first().map_or(0, Vec::len);
    if pairs == 0 {
        return Err(ReplayError::Compare {
            topic: topic.to_owned(),
            why: "no observable estimate has a reference at or before it",
        });
    }
    let axis = |x: &[f64], y: &[f64]| {
        let e_ra = sar_estimator::error_measure::absolute_relative_error(x, y).unwrap_or(f64::NAN);
        let (mut sq, mut max) = (0.0f64, 0.0f64);
        for (a, b) in x.iter().zip(y) {
            let d = a - b;
            sq += d * d;
            max = max.max(d.abs());
        }
        AxisError {
            e_ra,
            rms_n: (sq / x.len() as f64).sqrt(),
            max_n: max,
        }
    };
    let [ex, ey, ez] = &est;
    let [rx, ry, rz] = &refv;
    Ok(Comparison {
        topic: topic.to_owned(),
        pairs,
        left_out,
        axes: [axis(ex, rx), axis(ey, ry), axis(ez, rz)],
    })
}

/// Replays the file at `input` (refuses an `output` that is the input).
pub fn replay_file(input: &Path, options: &ReplayOptions) -> Result<ReplayReport, ReplayError> {
    replay_files(std::slice::from_ref(&input.to_path_buf()), options)
}
