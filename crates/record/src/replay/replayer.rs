//! The replayer of one set: the step and the estimator run over the
//! recorded inputs, their outputs written (`super::start::output_writer`) and matched
//! with the recorded ones topic by topic, snapshots compared, gaps counted.

use super::compare::reference_at;
use super::options::{Mode, ReplayError, ReplayOptions};
use super::report::{
    Difference, Gap, MAX_FORWARD, MAX_GAPS_SHOWN, ReplayReport, SeriesPoint, describe,
};
use super::start::{SetStart, output_writer};
use super::{MAX_PENDING, OUTPUT_TOPICS};
use crate::convert;
use crate::file::RotatingWriter;
use crate::output::{PendingFile, SpaceWatch};
use sar_estimator::Vec3;
use sar_estimator::cycle::{CycleContext, CycleInput, CycleOutput, Estimator, TipOutcome};
use sar_loop::step::{LoopInput, LoopStep};
use sar_msgs::msgs::{Outgoing, RecorderDrops, SnapshotChunk, StateSnapshot, Topic};
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;

pub(super) struct Sink {
    pub(super) writer: Option<RotatingWriter>,
    pub(super) status: RecorderDrops,
    /// The output's temporary file, renamed over the output once the
    /// replay has written all of it; removed if it stops before.
    pub(super) pending: Option<PendingFile>,
    /// The output's file system's free space.
    pub(super) space: Option<SpaceWatch>,
}

impl Sink {
    pub(super) fn write(&mut self, m: &Outgoing) -> Result<(), ReplayError> {
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
    pub(super) fn finish(&mut self) -> Result<(), ReplayError> {
        if let Some(w) = &mut self.writer {
            w.close(&self.status)?;
        }
        if let Some(p) = self.pending.take() {
            p.commit()?;
        }
        Ok(())
    }
}

pub(super) struct Replayer {
    pub(super) scratch: Vec<Outgoing>,
    pub(super) estimator: Estimator,
    pub(super) step: LoopStep,
    pub(super) sink: Sink,
    pub(super) report: ReplayReport,
    /// Per output topic: the replayed messages (cycle, message, bytes) not
    /// yet matched, and the recorded ones (bytes) not yet matched.
    pub(super) replayed: BTreeMap<Topic, VecDeque<(u64, Outgoing, Vec<u8>)>>,
    pub(super) recorded: BTreeMap<Topic, VecDeque<Vec<u8>>>,
    pub(super) comparing: bool,
    /// Topics whose recorded outputs are missing (no longer compared).
    pub(super) lacking: Vec<Topic>,
    /// What the cycles add up to beyond the report's counts.
    pub(super) tally: Tally,
    /// The latest gap beyond [`MAX_GAPS_SHOWN`] (counted, not in the
    /// report).
    pub(super) unshown_gap: Option<Gap>,
    pub(super) references: Vec<(u64, [f64; 3])>,
    pub(super) last_cycle: u64,
    /// Whether the step's state is known (from the first cycle, or restored
    /// from a snapshot): cycles before are skipped with their outputs.
    pub(super) anchored: bool,
    /// The snapshot taken of the replayed step (compared, written).
    pub(super) snapshot: Box<sar_snapshot::Snapshot>,
    /// Before `from_s`: cycles are stepped, nothing is written or compared.
    pub(super) quiet: bool,
    /// Whether a cycle was stepped since the state became known (the next
    /// one must follow it).
    pub(super) stepped: bool,
}

pub(super) fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// What every replayed cycle adds up to, whether its messages are made or
/// not (beside the report's counts): the first cycle's stamp and the
/// estimates kept for `--compare` and `--plot`.
pub(super) struct Tally {
    /// The stamp of the first cycle replayed, ns.
    pub(super) first_ns: Option<u64>,
    /// The observable estimates of new samples (stamp, tip force N), with
    /// `keep_estimates`.
    pub(super) estimates: Vec<(u64, [f64; 3])>,
    /// New samples without an observable estimate, with `keep_estimates`.
    pub(super) left_out: usize,
    pub(super) keep_estimates: bool,
}

impl Tally {
    /// Nothing counted yet; the estimates kept with `keep_estimates`.
    pub(super) fn new(keep_estimates: bool) -> Self {
        Self {
            first_ns: None,
            estimates: Vec::new(),
            left_out: 0,
            keep_estimates,
        }
    }

    /// One cycle stamped `stamp_ns` ([`convert::cycle_stamp_ns`]): counted in
    /// `report`, its stamp noted, its estimate kept (`--compare`, `--plot`).
    pub(super) fn cycle(&mut self, report: &mut ReplayReport, stamp_ns: u64, out: &CycleOutput) {
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
    pub(super) fn new(
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
    pub(super) fn lean_comparison(&mut self) {
        for topic in OUTPUT_TOPICS {
            if topic != Topic::GuardEvents && !self.lacking.contains(&topic) {
                self.lacking.push(topic);
                self.replayed.remove(&topic);
                self.recorded.remove(&topic);
            }
        }
    }

    /// The recording is an inputs-only one: nothing to compare.
    pub(super) fn inputs_only_mode(&mut self) {
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
    pub(super) fn follows(&mut self, file: Option<PathBuf>, cycle: u64) {
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
        let skipped = crate::reader::Skipped {
            offset: 0,
            bytes: 0,
            log_time_ns: None,
            records: 0,
            why,
        };
        self.gap(Gap::new(file, skipped, Some(last)), false);
    }

    /// A corrupt record of `file` passed over.
    pub(super) fn corrupt_part(&mut self, file: Option<PathBuf>, skipped: crate::reader::Skipped) {
        let last_cycle_before =
            (self.anchored || self.report.cycles > 0).then_some(self.last_cycle);
        self.gap(Gap::new(file, skipped, last_cycle_before), true);
    }

    /// Whether a recorded cycle is replayed: not while the state is
    /// unknown (before the first snapshot, or after a gap before the next
    /// one), counted then as skipped or not replayed.
    pub(super) fn replayable(&mut self, cycle: u64) -> bool {
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
    pub(super) fn series(&self) -> Vec<SeriesPoint> {
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
    pub(super) fn loop_cycle(
        &mut self,
        input: &LoopInput,
        between: &[Outgoing],
    ) -> Result<(), ReplayError> {
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
    pub(super) fn estimator_cycle(&mut self, input: &CycleInput) -> Result<(), ReplayError> {
        let out = *self.estimator.cycle(input, &CycleContext::AT_REST);
        self.emit_outputs(input, &out)
    }

    pub(super) fn emit(&mut self, cycle: u64, m: Outgoing) -> Result<(), ReplayError> {
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

    pub(super) fn emit_outputs(
        &mut self,
        input: &CycleInput,
        out: &CycleOutput,
    ) -> Result<(), ReplayError> {
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
    pub(super) fn needs_messages(&self) -> bool {
        self.comparing || self.sink.writer.is_some()
    }

    pub(super) fn differ(&mut self, d: Difference) {
        // (leftovers at the end)
        self.report.differences += 1;
        if self.report.first_difference.is_none() {
            self.report.first_difference = Some(d);
        }
    }

    pub(super) fn match_pending(&mut self) {
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
    pub(super) fn snapshot(&mut self, m: &StateSnapshot) -> Result<(), ReplayError> {
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
    pub(super) fn write_snapshot(&mut self, m: &StateSnapshot) -> Result<(), ReplayError> {
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

    pub(super) fn recorded_output(&mut self, topic: Topic, data: &[u8]) {
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
    pub(super) fn gap(&mut self, gap: Gap, match_first: bool) {
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
    pub(super) fn last_gap(&mut self) -> Option<&mut Gap> {
        match &mut self.unshown_gap {
            Some(g) => Some(g),
            None => self.report.gaps.last_mut(),
        }
    }

    /// `complete`: the recording was not cut short (a recovered file says
    /// in its `sar_recover` metadata whether its input was).
    pub(super) fn finish_comparison(&mut self, complete: bool) {
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
