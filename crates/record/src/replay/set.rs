//! The reading of a set's files in turn ([`SetReplay`]): each file's
//! channels and records visited, the cycles handed to the replayer, the files
//! chained, the end of the range, the set finished.

use super::OUTPUT_TOPICS;
use super::compare::compare;
use super::inputs_only::{INPUT_WINDOW, InputItem, InputsOnly};
use super::options::{ReplayError, ReplayOptions};
use super::replayer::Replayer;
use super::report::ReplayReport;
use super::start::{Input, SetStart, display_name, probe, replay_metadata};
use crate::convert::{self};
use crate::lean;
use crate::reader::{ChannelInfo, McapReader, MessageRef, ReadError};
use sar_msgs::msgs::{
    ActiveJointState, CycleBatch, CycleInput as CycleInputMsg, Outgoing, RecorderDrops, RosMessage,
    StateSnapshot, Topic,
};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The replay of a set of files across them: the replayer, and what
/// reading the files in turn carries from one to the next.
pub(super) struct SetReplay<'o> {
    pub(super) r: Replayer,
    pub(super) options: &'o ReplayOptions,
    /// `--from` and `--to`, ns after the first cycle.
    pub(super) from_ns: Option<u64>,
    pub(super) to_ns: Option<u64>,
    /// The stamp of the recording's first cycle, ns.
    pub(super) first_stamp_ns: Option<u64>,
    /// Whether a `/sar/cycle/input` was read (a daemon recording).
    pub(super) saw_cycle_input: bool,
    /// The window of an inputs-only recording.
    pub(super) inputs_only: InputsOnly,
    /// Whether a file is a recovered one whose input was cut short.
    pub(super) recovered_from_cut: bool,
    /// Whether every file was read to its end.
    pub(super) complete: bool,
    /// The previous file's `file_index`.
    pub(super) previous_index: Option<u64>,
    /// Whether the replay reached `--to`.
    pub(super) reached_end_of_range: bool,
    /// Whether the recording is a lean one (`/sar/cycle/batch` read).
    pub(super) lean: bool,
}

/// One file's reading state (channel ids are the file's own).
pub(super) struct FileVisit {
    pub(super) path: Option<PathBuf>,
    /// Topic per channel id (the index), looked up once per channel:
    /// `None` for a channel not seen yet.
    pub(super) topics: Vec<Option<Option<Topic>>>,
    /// The channel of `--compare`'s reference topic.
    pub(super) reference_channel: Option<u16>,
    /// The cycle the file must start with (after the previous file's).
    pub(super) expect_cycle: Option<u64>,
}

impl FileVisit {
    /// How the file is named in errors and reports.
    pub(super) fn name(&self) -> String {
        display_name(self.path.as_ref())
    }

    /// The topic of channel `id` (looked up once per channel, which is
    /// also when the reference channel of `compare` is found).
    #[inline(always)]
    pub(super) fn topic(
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
    pub(super) fn check_start(&mut self, cycle: u64) -> Result<(), ReplayError> {
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
    pub(super) fn open(
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
    pub(super) fn chain(&mut self, input: &Input<'_>) -> Result<(), ReplayError> {
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
    pub(super) fn visit_file(
        &mut self,
        index: usize,
        input: &Input<'_>,
    ) -> Result<(), ReplayError> {
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
    pub(super) fn visit_records(
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
    pub(super) fn message(
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
                // Its cycles nest whole `CycleInput`s: only this version's
                // layout can be cut into cycles (an older one's would be
                // misread, its fields added since taken from the next
                // cycle's bytes). The file's schema says which it is.
                let schema = channels.get(&id).map(ChannelInfo::schema_data);
                if schema != Some(Topic::CycleBatch.schema().as_bytes()) {
                    return Err(ReplayError::OtherLeanLayout {
                        log_time_ns: msg.log_time_ns,
                    });
                }
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
    pub(super) fn start_cycle_inputs(&mut self, log_time_ns: u64) -> Result<(), ReplayError> {
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
    pub(super) fn cycle_input(
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
    pub(super) fn cycle_batch(
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
    pub(super) fn before_range(&mut self, stamp_ns: u64) -> Result<bool, ReplayError> {
        let t0 = *self.first_stamp_ns.get_or_insert(stamp_ns);
        let t = stamp_ns.saturating_sub(t0);
        if self.to_ns.is_some_and(|to| t > to) {
            return Err(ReplayError::EndOfRange);
        }
        Ok(self.from_ns.is_some_and(|from| t < from))
    }

    /// A file read (`result`: how reading ended): the first difference
    /// named by its file, a cut noted, whether it was complete.
    pub(super) fn end_file(
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
    pub(super) fn ended(&self) -> bool {
        self.r.report.stopped.is_some() || self.reached_end_of_range
    }

    /// Every file read: what is pending compared (a daemon recording) or
    /// the inputs-only window replayed; the comparison with the reference,
    /// the series; the output closed.
    pub(super) fn finish(mut self) -> Result<ReplayReport, ReplayError> {
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
            r.report.comparison = Some(compare(
                &mut r.references,
                &r.tally.estimates,
                r.tally.left_out,
                topic,
            )?);
        }
        if self.options.keep_series {
            r.report.series = r.series();
        }
        r.sink.finish()?;
        Ok(self.r.report)
    }
}
