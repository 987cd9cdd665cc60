//! What a replay reports ([`ReplayReport`]): the first difference with the
//! recorded outputs (described field by field), the comparison with a
//! reference, the series, the gaps of a recovered recording.

use super::options::Mode;
use sar_msgs::msgs::{Outgoing, Topic};
use std::path::PathBuf;

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
    pub(super) fn not_recorded(topic: Topic, cycle: u64, m: &Outgoing) -> Self {
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
pub(super) const MAX_FORWARD: u64 = i64::MAX as u64;

impl ReplayReport {
    /// The report before the first cycle.
    pub(super) fn start(output: Option<PathBuf>, from_first_cycle: Option<bool>) -> Self {
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
    pub skipped: crate::reader::Skipped,
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
    pub(super) fn new(
        file: Option<PathBuf>,
        skipped: crate::reader::Skipped,
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

/// The first field in which two messages differ, from their `Debug` forms
/// (`Name { a: 1, b: [1.0, 2.0], .. }`): top-level fields are split at the
/// commas outside brackets.
pub(super) fn fields(debug: &str) -> Vec<(String, String)> {
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

pub(super) fn describe(
    topic: Topic,
    cycle: u64,
    replayed: &Outgoing,
    recorded: &[u8],
) -> Difference {
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
