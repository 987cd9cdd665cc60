//! Runs a [`MotionScript`] on any [`ForceSensor`] and [`AxisDrives`] with any
//! [`Clock`]: enables the drives, commands each step's target, waits for
//! arrival (bounded by a timeout from the distance and the axes' limits),
//! holds, and all along polls the sensor and the positions every period,
//! keeping every new sample in memory.
//!
//! This is a tool for scenarios, tests and recording procedures, not the
//! real-time path: it allocates (`Vec`s grow with the run). Every wait is
//! bounded: the run ends at the end of the script, at `max_duration_ns`, or
//! shortly after a drive fault, and says which.

use crate::scenario::{MotionScript, MotionStep};
use sar_hal::motion::{SlideSign, SlideTracker, move_time_s};
use sar_hal::{
    AxisDrives, Clock, ClockError, DriveState, Error, ErrorKind, ForceSensor, JointPositions,
    WrenchSample,
};
use sar_kinematics::ActiveJoints;

/// Default polling period, ns (1 kHz: every sample of a 500 Hz sensor and of
/// 1 kHz positions).
pub const DEFAULT_PERIOD_NS: u64 = 1_000_000;
/// Default arrival tolerance on each axis, m (about 8 encoder counts of the
/// article's axes).
pub const DEFAULT_ARRIVAL_TOLERANCE_M: f64 = 1e-5;
/// Default time to keep recording after a drive fault, ns.
pub const DEFAULT_LINGER_AFTER_FAULT_NS: u64 = 200_000_000;
/// Margin added to every arrival timeout, ns.
pub const ARRIVAL_MARGIN_NS: u64 = 1_000_000_000;

/// How to run a script.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    /// Polling period, ns (> 0). Samples that arrive faster than this are lost
    /// (the sensor's `poll` returns only the newest).
    pub period_ns: u64,
    /// The run stops after this long whatever the script, ns.
    pub max_duration_ns: u64,
    /// A target is reached when every axis is within this, m (> 0).
    pub arrival_tolerance_m: f64,
    /// Time to keep recording after the drives fault, ns.
    pub linger_after_fault_ns: u64,
}

impl RunOptions {
    /// Options for `script`: polling every `period_ns`, at most twice the
    /// script's nominal duration plus 10 s, the default tolerance and linger.
    pub fn for_script(script: &MotionScript, period_ns: u64) -> Self {
        Self {
            period_ns,
            max_duration_ns: script
                .nominal_duration_ns()
                .saturating_mul(2)
                .saturating_add(10_000_000_000),
            arrival_tolerance_m: DEFAULT_ARRIVAL_TOLERANCE_M,
            linger_after_fault_ns: DEFAULT_LINGER_AFTER_FAULT_NS,
        }
    }
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    /// Every step was done.
    ScriptDone,
    /// `max_duration_ns` passed first.
    MaxDuration,
    /// The drives faulted (with their code); the run recorded
    /// `linger_after_fault_ns` more and stopped.
    DriveFault {
        /// The drives' fault code.
        code: u16,
    },
}

/// A hold: the axes at a step's target, not moving (a static pose).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldSegment {
    /// Index of the step in the script.
    pub step: usize,
    /// Start (arrival), host ns, inclusive.
    pub start_ns: u64,
    /// End, host ns, exclusive.
    pub end_ns: u64,
    /// Sign of the last slide of the rod in the support before the hold, from
    /// the measured positions: inserting when A last moved towards B (the rod
    /// slid along u), retracting away, unknown when it has not slid since the
    /// start (such a hold is left out of a friction fit, MODEL.md 5).
    pub slide_sign: SlideSign,
    /// Whether the axes reached the target (false: the arrival timed out and
    /// the hold is where they were).
    pub arrived: bool,
}

/// What happened to one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRecord {
    /// Index of the step in the script.
    pub step: usize,
    /// When the target was commanded, host ns.
    pub commanded_ns: u64,
    /// When the positions were first within tolerance, host ns (`None`: timed out).
    pub arrived_ns: Option<u64>,
}

/// Something that did not stop the run.
#[derive(Debug, Clone, PartialEq)]
pub enum RunEvent {
    /// The sensor's `poll` failed.
    SensorError {
        /// When, host ns.
        at_ns: u64,
        /// The error's kind.
        kind: ErrorKind,
        /// The error's message.
        message: String,
    },
    /// The drives' `positions` or `state` failed.
    DrivesError {
        /// When, host ns.
        at_ns: u64,
        /// The error's kind.
        kind: ErrorKind,
        /// The error's message.
        message: String,
    },
    /// A step's target was not reached in time; its hold went on where the axes were.
    ArrivalTimeout {
        /// When, host ns.
        at_ns: u64,
        /// Index of the step.
        step: usize,
    },
    /// The drives went to `Fault`.
    DriveFault {
        /// When it was seen, host ns.
        at_ns: u64,
        /// The drives' fault code.
        code: u16,
    },
}

/// Everything a run recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// Host time at the start, ns.
    pub start_ns: u64,
    /// Host time at the end, ns.
    pub end_ns: u64,
    /// Why the run ended.
    pub end: EndReason,
    /// Every new sensor sample, in order of arrival.
    pub sensor_samples: Vec<WrenchSample>,
    /// Every new set of positions (a new stamp), in order.
    pub positions: Vec<JointPositions>,
    /// The completed holds (steps with a hold time > 0), in order.
    pub holds: Vec<HoldSegment>,
    /// One record per commanded step.
    pub steps: Vec<StepRecord>,
    /// Every change of the direction in which the rod slides in the support,
    /// from the valid positions (see [`SlideTracker`]).
    pub slides: Vec<SlideChange>,
    /// What went wrong without stopping the run.
    pub events: Vec<RunEvent>,
}

impl Run {
    /// The sensor samples received in `[start_ns, end_ns)`.
    pub fn sensor_samples_in(&self, start_ns: u64, end_ns: u64) -> &[WrenchSample] {
        let lo = self
            .sensor_samples
            .partition_point(|s| s.received_ns < start_ns);
        let hi = self
            .sensor_samples
            .partition_point(|s| s.received_ns < end_ns);
        self.sensor_samples.get(lo..hi.max(lo)).unwrap_or(&[])
    }

    /// The positions stamped in `[start_ns, end_ns)`.
    pub fn positions_in(&self, start_ns: u64, end_ns: u64) -> &[JointPositions] {
        let lo = self.positions.partition_point(|p| p.stamp_ns < start_ns);
        let hi = self.positions.partition_point(|p| p.stamp_ns < end_ns);
        self.positions.get(lo..hi.max(lo)).unwrap_or(&[])
    }

    /// The sign of the last slide as of `t_ns` (unknown before any).
    pub fn slide_sign_at(&self, t_ns: u64) -> SlideSign {
        let n = self.slides.partition_point(|s| s.at_ns <= t_ns);
        n.checked_sub(1)
            .and_then(|i| self.slides.get(i))
            .map_or(SlideSign::Unknown, |s| s.sign)
    }

    /// The latest positions stamped at or before `t_ns`.
    pub fn positions_at(&self, t_ns: u64) -> Option<&JointPositions> {
        let n = self.positions.partition_point(|p| p.stamp_ns <= t_ns);
        n.checked_sub(1).and_then(|i| self.positions.get(i))
    }
}

/// Why a run could not go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// An option is out of range.
    #[error("run option {field} is not allowed: {why}")]
    InvalidOptions {
        /// Which option.
        field: &'static str,
        /// What it must be.
        why: &'static str,
    },
    /// The clock could not be read: the run stops (no made-up time).
    #[error("the clock could not be read: {0}")]
    Clock(#[from] ClockError),
    /// The drives could not be enabled at the start.
    #[error("the drives could not be enabled ({kind}): {message}")]
    Enable {
        /// The error's kind.
        kind: ErrorKind,
        /// What the drives said.
        message: String,
    },
    /// The drives refused a step's target (and are not in fault).
    #[error("the drives refused the target of step {step} ({key}) ({kind}): {message}")]
    Target {
        /// Index of the step.
        step: usize,
        /// The step's key in the scenario file.
        key: String,
        /// The error's kind.
        kind: ErrorKind,
        /// What the drives said.
        message: String,
    },
}

/// A change of the slide direction seen in the positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlideChange {
    /// Stamp of the positions that showed it, host ns.
    pub at_ns: u64,
    /// The new sign (see [`SlideTracker`]; never unknown once it has changed).
    pub sign: SlideSign,
}

fn valid_options(options: &RunOptions) -> Result<(), RunError> {
    if options.period_ns == 0 {
        return Err(RunError::InvalidOptions {
            field: "period_ns",
            why: "must be > 0",
        });
    }
    if !(options.arrival_tolerance_m.is_finite() && options.arrival_tolerance_m > 0.0) {
        return Err(RunError::InvalidOptions {
            field: "arrival_tolerance_m",
            why: "must be finite and > 0",
        });
    }
    Ok(())
}

/// The state of one run.
struct Runner<'a, S, D, C> {
    script: &'a MotionScript,
    sensor: &'a mut S,
    drives: &'a mut D,
    clock: &'a C,
    options: RunOptions,
    deadline_ns: u64,
    next_tick_ns: u64,
    latest: Option<JointPositions>,
    tracker: SlideTracker,
    fault: Option<u16>,
    run: Run,
}

/// How a wait ended.
enum Wait {
    Done,
    Deadline,
    Fault(u16),
}

impl<S: ForceSensor, D: AxisDrives, C: Clock> Runner<'_, S, D, C> {
    /// Reads whatever is new from the sensor and the drives.
    fn poll(&mut self) -> Result<(), ClockError> {
        let now = self.clock.now_ns()?;
        match self.sensor.poll() {
            Ok(Some(sample)) => self.run.sensor_samples.push(sample),
            Ok(None) => {}
            Err(e) => self.run.events.push(RunEvent::SensorError {
                at_ns: now,
                kind: e.kind(),
                message: e.to_string(),
            }),
        }
        match self.drives.positions() {
            Ok(p) => {
                if self.latest.is_none_or(|l| l.stamp_ns != p.stamp_ns) {
                    self.run.positions.push(p);
                    if p.valid && self.tracker.update(&p.joints) {
                        self.run.slides.push(SlideChange {
                            at_ns: p.stamp_ns,
                            sign: self.tracker.sign(),
                        });
                    }
                }
                self.latest = Some(p);
            }
            Err(e) => self.run.events.push(RunEvent::DrivesError {
                at_ns: now,
                kind: e.kind(),
                message: e.to_string(),
            }),
        }
        match self.drives.state() {
            Ok(DriveState::Fault { code, .. }) => {
                if self.fault.is_none() {
                    self.fault = Some(code);
                    self.run
                        .events
                        .push(RunEvent::DriveFault { at_ns: now, code });
                }
            }
            Ok(_) => {}
            Err(e) => self.run.events.push(RunEvent::DrivesError {
                at_ns: now,
                kind: e.kind(),
                message: e.to_string(),
            }),
        }
        Ok(())
    }

    /// One period: sleep to the next tick, then poll.
    fn tick(&mut self) -> Result<(), ClockError> {
        self.next_tick_ns = self.next_tick_ns.saturating_add(self.options.period_ns);
        self.clock.sleep_until_ns(self.next_tick_ns);
        self.poll()
    }

    fn arrived(&self, target: &ActiveJoints) -> bool {
        let tol = self.options.arrival_tolerance_m;
        self.latest.is_some_and(|p| {
            p.valid
                && (p.joints.q1_m - target.q1_m).abs() <= tol
                && (p.joints.q2_m - target.q2_m).abs() <= tol
                && (p.joints.q3_m - target.q3_m).abs() <= tol
        })
    }

    /// Ticks until `done` holds, `until_ns` passes, the deadline passes or the
    /// drives fault. Returns `Done` for both `done` and `until_ns`.
    fn wait(&mut self, until_ns: u64, done: impl Fn(&Self) -> bool) -> Result<Wait, ClockError> {
        loop {
            if let Some(code) = self.fault {
                return Ok(Wait::Fault(code));
            }
            let now = self.clock.now_ns()?;
            if done(self) || now >= until_ns {
                return Ok(Wait::Done);
            }
            if now >= self.deadline_ns {
                return Ok(Wait::Deadline);
            }
            self.tick()?;
        }
    }

    /// Records `linger_after_fault_ns` more (bounded by the deadline) and ends.
    fn end_after_fault(mut self, code: u16) -> Result<Run, ClockError> {
        let until = self
            .clock
            .now_ns()?
            .saturating_add(self.options.linger_after_fault_ns)
            .min(self.deadline_ns);
        while self.clock.now_ns()? < until {
            self.tick()?;
        }
        self.finish(EndReason::DriveFault { code })
    }

    fn finish(mut self, end: EndReason) -> Result<Run, ClockError> {
        self.run.end = end;
        self.run.end_ns = self.clock.now_ns()?;
        Ok(self.run)
    }

    /// The script's steps in turn (each commanded, arrived at, held), until
    /// it ends, a drive faults or the deadline comes.
    fn execute(mut self) -> Result<Run, RunError> {
        self.poll()?;
        let steps = self.script.steps.iter().enumerate();
        for (index, step) in steps {
            if let Some(code) = self.fault {
                return Ok(self.end_after_fault(code)?);
            }
            let ended = match self.command(index, step)? {
                Some(code) => Wait::Fault(code),
                None => match self.arrive(index, step)? {
                    Ok((arrived, now)) => self.hold(index, step, now, arrived)?,
                    Err(ended) => ended,
                },
            };
            match ended {
                Wait::Done => {}
                Wait::Deadline => return Ok(self.finish(EndReason::MaxDuration)?),
                Wait::Fault(code) => return Ok(self.end_after_fault(code)?),
            }
        }
        Ok(self.finish(EndReason::ScriptDone)?)
    }

    /// Commands the step's target. A refused target ends the run with an
    /// error, unless the drives report a fault only now: then it ends as a
    /// drive fault (`Some` with its code), not as a refused target.
    fn command(&mut self, index: usize, step: &MotionStep) -> Result<Option<u16>, RunError> {
        let Err(e) = self.drives.set_targets(step.target) else {
            return Ok(None);
        };
        if let Ok(DriveState::Fault { code, .. }) = self.drives.state() {
            if self.fault.is_none() {
                self.fault = Some(code);
                let at_ns = self.clock.now_ns()?;
                self.run.events.push(RunEvent::DriveFault { at_ns, code });
            }
            return Ok(Some(code));
        }
        Err(RunError::Target {
            step: index,
            key: step.key.clone(),
            kind: e.kind(),
            message: e.to_string(),
        })
    }

    /// Waits until every axis is at the step's target (at most 1.5 times the
    /// move's nominal time plus a margin) and records the step. `Err` with
    /// how the wait ended if that ends the run; else whether the target was
    /// reached (a time-out is an event, and the hold goes on) and when.
    fn arrive(
        &mut self,
        index: usize,
        step: &MotionStep,
    ) -> Result<Result<(bool, u64), Wait>, ClockError> {
        let commanded_ns = self.clock.now_ns()?;
        let from = self.latest.map_or(self.script.start, |p| p.joints);
        let move_s = move_time_s(
            &from,
            &step.target,
            self.script.max_speed_mps,
            self.script.max_accel_mps2,
        );
        let timeout_ns = ((1.5 * move_s * 1e9) as u64).saturating_add(ARRIVAL_MARGIN_NS);
        let target = step.target;
        let arrival = self.wait(commanded_ns.saturating_add(timeout_ns), |r| {
            r.arrived(&target)
        })?;
        let arrived = self.arrived(&target);
        let now = self.clock.now_ns()?;
        self.run.steps.push(StepRecord {
            step: index,
            commanded_ns,
            arrived_ns: arrived.then_some(now),
        });
        if !matches!(arrival, Wait::Done) {
            return Ok(Err(arrival));
        }
        if !arrived {
            self.run.events.push(RunEvent::ArrivalTimeout {
                at_ns: now,
                step: index,
            });
        }
        Ok(Ok((arrived, now)))
    }

    /// Holds the step's hold time from `start_ns`, and records the hold
    /// (with the slide's sign at its start) if it has one.
    fn hold(
        &mut self,
        index: usize,
        step: &MotionStep,
        start_ns: u64,
        arrived: bool,
    ) -> Result<Wait, ClockError> {
        let end_ns = start_ns.saturating_add(step.hold_ns);
        let slide_sign = self.tracker.sign();
        let held = self.wait(end_ns, |_| false)?;
        if !matches!(held, Wait::Done) {
            return Ok(held);
        }
        if step.hold_ns > 0 {
            self.run.holds.push(HoldSegment {
                step: index,
                start_ns,
                end_ns: self.clock.now_ns()?,
                slide_sign,
                arrived,
            });
        }
        Ok(Wait::Done)
    }
}

/// Runs `script` on `sensor` and `drives`, polling both every
/// `options.period_ns` on `clock` (advanced with `sleep_until_ns`).
///
/// Enables the drives (from `Ready`; nothing to do when already `Enabled`),
/// then for each step: commands the target, waits until every axis is within
/// `arrival_tolerance_m` (at most 1.5 times the move's nominal time plus 1 s;
/// on timeout the hold goes on and [`RunEvent::ArrivalTimeout`] says so), then
/// holds for the step's hold time. Errors of the sensor and of the position
/// reads are recorded as events; a drive fault ends the run
/// `linger_after_fault_ns` later. Errors: options out of range, drives that
/// cannot be enabled, a target refused by drives that are not in fault, a
/// clock that cannot be read.
pub fn run<S: ForceSensor, D: AxisDrives, C: Clock>(
    script: &MotionScript,
    sensor: &mut S,
    drives: &mut D,
    clock: &C,
    options: &RunOptions,
) -> Result<Run, RunError> {
    valid_options(options)?;
    let start_ns = clock.now_ns()?;
    match drives.state() {
        Ok(DriveState::Enabled) => {}
        _ => drives.enable().map_err(|e| RunError::Enable {
            kind: e.kind(),
            message: e.to_string(),
        })?,
    }
    let runner = Runner {
        script,
        sensor,
        drives,
        clock,
        options: *options,
        deadline_ns: start_ns.saturating_add(options.max_duration_ns),
        next_tick_ns: start_ns,
        latest: None,
        tracker: SlideTracker::new(&script.calibration),
        fault: None,
        run: Run {
            start_ns,
            end_ns: start_ns,
            end: EndReason::ScriptDone,
            sensor_samples: Vec::new(),
            positions: Vec::new(),
            holds: Vec::new(),
            steps: Vec::new(),
            slides: Vec::new(),
            events: Vec::new(),
        },
    };
    runner.execute()
}
