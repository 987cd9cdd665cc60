//! The body of one control cycle: gather the inputs (sensor poll, drive
//! positions and state, at most one pending operator request), run the pure
//! per-cycle step [`Estimator::cycle`], and carry out its decision on the
//! drives (quick stop on Stop or Fault in the same cycle; moves refused until
//! a reset is accepted; a move deeper along the tip force refused above the
//! warning limit). Everything is allocated in [`Controller::new`]; a cycle
//! allocates nothing (proved by `tests/no_alloc.rs`).

use crate::logq::{LogEvent, LogSender};
use crossbeam_queue::ArrayQueue;
use sar_drivers::{AxisDrives, DriveState, ForceSensor, WrenchSample};
use sar_estimator::cycle::{
    Command, CommandAccepted, CommandRefused, CycleInput, CycleOutput, Estimator, EstimatorConfig,
    JointSample, SensorSample, TipOutcome,
};
use sar_estimator::guard::{GuardState, Reason};
use sar_estimator::{SettingError, Vec3};
use sar_kinematics::{ActiveJoints, inverse};
use std::sync::Arc;

/// Capacity of the operator request queue and of the reply queue.
pub const QUEUE_CAPACITY: usize = 16;

/// An operator request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// Leave Stop or Fault (judged on the cycle's input).
    Reset,
    /// Model-based tare.
    Tare,
    /// Move the tip to this point, base frame, m (inverse kinematics, then
    /// a limited-speed move of the drives).
    MoveTip {
        /// The wanted tip, base frame, m.
        tip_m: Vec3,
    },
}

/// A request with the caller's id (echoed in the reply).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// The caller's id.
    pub id: u64,
    /// The request.
    pub request: Request,
}

/// What became of a request. The numbers are the wire codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ReplyStatus {
    /// Done.
    Accepted = 0,
    /// A reset while nothing was latched.
    NothingToReset = 1,
    /// A reset refused: its cause persists (the reason code says which).
    ResetRefused = 2,
    /// A tare outside `Ok`.
    NotOk = 3,
    /// A tare with a force above a warn limit.
    AboveWarn = 4,
    /// A tare without an estimate, or whose bias cannot be solved.
    NoEstimate = 5,
    /// A move while the drives are halted (Stop or Fault not yet reset).
    Halted = 6,
    /// A move the kinematics cannot reach, or outside the travel.
    Unreachable = 7,
    /// A move deeper along the tip force while it is above the warn limit.
    TowardForce = 8,
    /// The drives refused the command.
    DrivesRefused = 9,
    /// Refused for another reason.
    Refused = 10,
}

/// The reply to a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reply {
    /// The request's id.
    pub id: u64,
    /// The request.
    pub request: Request,
    /// The cycle that judged it.
    pub cycle: u64,
    /// What became of it.
    pub status: ReplyStatus,
    /// The guard's reason code ([`reason_code`]) behind a refusal, 0 otherwise.
    pub reason: u16,
}

/// The numeric code of a guard reason (stable: recordings and `sarctl` use it).
pub fn reason_code(reason: &Reason) -> u16 {
    match reason {
        Reason::NoInputYet => 1,
        Reason::CycleOutOfOrder { .. } => 2,
        Reason::ClockFailed => 3,
        Reason::ClockNotAdvancing { .. } => 4,
        Reason::SensorCounterGap { .. } => 5,
        Reason::SensorStatus { .. } => 6,
        Reason::JointJump { .. } => 7,
        Reason::JointsStampBackwards { .. } => 8,
        Reason::TorqueImplausible { .. } => 9,
        Reason::ResetNotCurrent { .. } => 10,
        Reason::SensorInvalid => 11,
        Reason::SensorStale { .. } => 12,
        Reason::JointsInvalid => 13,
        Reason::JointsStale { .. } => 14,
        Reason::PoseInvalid => 15,
        Reason::NonFinite { .. } => 16,
        Reason::NegativeStd { .. } => 17,
        Reason::RodDirNotUnit { .. } => 18,
        Reason::EstimatorNotObservable => 19,
        Reason::NotObservable { .. } => 20,
        Reason::AboveStop { .. } => 21,
        Reason::AboveWarn { .. } => 22,
        Reason::BelowWarn => 23,
        Reason::Reset => 24,
        _ => 0xffff,
    }
}

/// [`reason_code`] in a recording's `uint8` field (`sar_msgs` `REASON_*`: the
/// same numbers; one unknown to the table is `REASON_OTHER`).
pub fn recorded_reason_code(reason: &Reason) -> u8 {
    u8::try_from(reason_code(reason)).unwrap_or(crate::record::msgs::reason::OTHER)
}

/// The operator's ends of the request and reply queues.
#[derive(Debug, Clone)]
pub struct Operator {
    /// Requests in (bounded; a full queue refuses the push).
    pub requests: Arc<ArrayQueue<Envelope>>,
    /// Replies out (bounded; the oldest is dropped when full).
    pub replies: Arc<ArrayQueue<Reply>>,
}

impl Operator {
    /// New empty queues.
    pub fn new() -> Self {
        Self {
            requests: Arc::new(ArrayQueue::new(QUEUE_CAPACITY)),
            replies: Arc::new(ArrayQueue::new(QUEUE_CAPACITY)),
        }
    }
}

impl Default for Operator {
    fn default() -> Self {
        Self::new()
    }
}

/// Counters of what the controller did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ActionCounts {
    /// Quick stops sent.
    pub quick_stops: u64,
    /// Cycles whose sensor poll failed.
    pub sensor_errors: u64,
    /// Cycles whose drive reading failed.
    pub drive_errors: u64,
    /// Cycles in which the drives were quick-stopped in the same cycle as the
    /// guard entered Stop or Fault (equal to the entries while all is well).
    pub stops_in_same_cycle: u64,
    /// Guard entries into Stop or Fault.
    pub halting_transitions: u64,
    /// Quick stops repeated because the drives were still enabled.
    pub quick_stop_retries: u64,
}

/// The per-cycle controller.
#[derive(Debug)]
pub struct Controller<S: ForceSensor, D: AxisDrives> {
    estimator: Estimator,
    calibration: sar_kinematics::Calibration,
    profile: sar_kinematics::Profile,
    sensor: S,
    drives: D,
    operator: Operator,
    log: LogSender,
    travel_m: [(f64, f64); 3],
    sensor_sample: SensorSample,
    joints: JointSample,
    drive_state: Option<DriveState>,
    last_input: CycleInput,
    output: CycleOutput,
    /// The drives were quick-stopped and no reset has been accepted since.
    halted: bool,
    /// Reset automatically (the demo only) until the first accepted reset.
    auto_reset: bool,
    counts: ActionCounts,
    /// Called once per cycle, in the gather phase, before the positions are
    /// read (the CANopen drives' SYNC / PDO exchange); `None` for drives that
    /// need nothing (the simulator).
    drives_cycle: Option<DrivesCycle<D>>,
}

/// The per-cycle hook of drives that must be driven by the loop (see
/// [`Controller::with_drives_cycle`]): `Err` names what failed, for the log.
pub type DrivesCycle<D> = fn(&mut D) -> Result<(), &'static str>;

fn sensor_sample(s: &WrenchSample) -> SensorSample {
    SensorSample {
        force_n: s.force_n,
        torque_nm: s.torque_nm,
        counter: s.counter,
        status: s.status.0,
        stamp_ns: s.received_ns,
        valid: s.is_valid(),
    }
}

impl<S: ForceSensor, D: AxisDrives> Controller<S, D> {
    /// Builds the controller; enables the drives when they are `Ready`.
    /// `auto_reset` (the demo) sends a reset every cycle until one is
    /// accepted, as an operator would at the start.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        config: &EstimatorConfig,
        bias: sar_estimator::cycle::Bias,
        travel_m: [(f64, f64); 3],
        sensor: S,
        drives: D,
        operator: Operator,
        log: LogSender,
        auto_reset: bool,
    ) -> Result<Self, SettingError> {
        // The drives are not enabled here: the guard starts in Fault (no
        // input yet), so the controller starts halted, and only an accepted
        // reset enables them (`release_drives`). Drives that come up enabled
        // get a quick stop in the first cycle.
        let estimator = Estimator::with_bias(config, bias)?;
        let sensor_sample = SensorSample {
            force_n: Vec3::zeros(),
            torque_nm: Vec3::zeros(),
            counter: 0,
            status: 0,
            stamp_ns: 0,
            valid: false,
        };
        let joints = JointSample {
            joints: ActiveJoints::default(),
            stamp_ns: 0,
            valid: false,
        };
        let last_input = CycleInput {
            cycle: 0,
            now_ns: None,
            sensor: sensor_sample,
            joints,
            command: None,
        };
        let output = *estimator.last();
        Ok(Self {
            estimator,
            calibration: config.calibration,
            profile: config.profile,
            sensor,
            drives,
            operator,
            log,
            travel_m,
            sensor_sample,
            joints,
            drive_state: None,
            last_input,
            output,
            halted: true,
            auto_reset,
            counts: ActionCounts::default(),
            drives_cycle: None,
        })
    }

    /// Calls `hook` on the drives once per cycle, in the gather phase before
    /// their positions are read (e.g. [`crate::devices::canopen_cycle`]: a
    /// CANopen host that stops cycling makes its drives quick-stop). A
    /// failing hook counts as a drive error and is logged; the positions it
    /// could not refresh go stale and the guard acts on that.
    pub fn with_drives_cycle(mut self, hook: DrivesCycle<D>) -> Self {
        self.drives_cycle = Some(hook);
        self
    }

    /// The output of the last cycle.
    pub fn output(&self) -> &CycleOutput {
        &self.output
    }

    /// The input of the last cycle.
    pub fn input(&self) -> &CycleInput {
        &self.last_input
    }

    /// The drives' state as read in the last cycle.
    pub fn drive_state(&self) -> Option<DriveState> {
        self.drive_state
    }

    /// Whether the drives are halted (quick stop sent, no reset since).
    pub fn halted(&self) -> bool {
        self.halted
    }

    /// What the controller did so far.
    pub fn counts(&self) -> ActionCounts {
        self.counts
    }

    /// The drives (for the shutdown's halt, and tests).
    pub fn drives_mut(&mut self) -> &mut D {
        &mut self.drives
    }

    /// Halts the drives (shutdown): quick stop, then disable.
    pub fn shutdown(&mut self) {
        let _ = self.drives.quick_stop();
        let _ = self.drives.disable();
        self.halted = true;
    }

    fn reply(&mut self, env: Envelope, status: ReplyStatus, reason: u16) {
        let reply = Reply {
            id: env.id,
            request: env.request,
            cycle: self.output.cycle,
            status,
            reason,
        };
        // A full reply queue loses its oldest reply, never blocks the loop.
        let _ = self.operator.replies.force_push(reply);
        self.log.send(LogEvent::Reply(reply));
    }

    /// Runs one cycle. `now` reads the clock (`None`: it could not be read);
    /// it is called once, after the inputs are gathered, so that no input is
    /// stamped after the cycle's time.
    pub fn step(&mut self, cycle: u64, now: impl FnOnce() -> Option<u64>) -> &CycleOutput {
        // Gather.
        match self.sensor.poll() {
            Ok(Some(s)) => self.sensor_sample = sensor_sample(&s),
            Ok(None) => {}
            Err(_) => {
                self.sensor_sample.valid = false;
                self.counts.sensor_errors += 1;
                self.log.send(LogEvent::DeviceError {
                    cycle,
                    what: "sensor poll",
                });
            }
        }
        if let Some(hook) = self.drives_cycle
            && let Err(what) = hook(&mut self.drives)
        {
            self.counts.drive_errors += 1;
            self.log.send(LogEvent::DeviceError { cycle, what });
        }
        match self.drives.positions() {
            Ok(p) => {
                self.joints = JointSample {
                    joints: p.joints,
                    stamp_ns: p.stamp_ns,
                    valid: p.valid,
                }
            }
            Err(_) => {
                self.joints.valid = false;
                self.counts.drive_errors += 1;
                self.log.send(LogEvent::DeviceError {
                    cycle,
                    what: "drive positions",
                });
            }
        }
        let drive_state = self.drives.state().ok();
        if drive_state != self.drive_state {
            self.log.send(LogEvent::DriveState {
                cycle,
                state: drive_state,
            });
        }
        self.drive_state = drive_state;
        let request = self.operator.requests.pop();
        let command = match request.map(|e| e.request) {
            Some(Request::Reset) => Some(Command::Reset),
            Some(Request::Tare) => Some(Command::Tare),
            Some(Request::MoveTip { .. }) | None => {
                (self.auto_reset && request.is_none()).then_some(Command::Reset)
            }
        };
        let input = CycleInput {
            cycle,
            now_ns: now(),
            sensor: self.sensor_sample,
            joints: self.joints,
            command,
        };
        self.last_input = input;

        // Decide.
        let out = *self.estimator.cycle(&input);
        self.output = out;

        // Act: a halting state stops the drives in this very cycle.
        let halting = matches!(out.guard_state, GuardState::Stop | GuardState::Fault);
        if let Some(t) = out.transition {
            self.log.send(LogEvent::Transition(t));
            if matches!(t.to, GuardState::Stop | GuardState::Fault) {
                self.counts.halting_transitions += 1;
            }
        }
        if halting && !self.halted {
            let ok = self.drives.quick_stop().is_ok();
            self.halted = true;
            self.counts.quick_stops += 1;
            if out.transition.is_some() {
                self.counts.stops_in_same_cycle += 1;
            }
            self.log.send(LogEvent::QuickStop { cycle, ok });
        } else if self.halted && matches!(self.drive_state, Some(DriveState::Enabled)) {
            // The drives still follow targets after a quick stop (refused, or
            // lost): repeat it every cycle until they stop.
            let ok = self.drives.quick_stop().is_ok();
            self.counts.quick_stop_retries += 1;
            if !ok {
                self.log.send(LogEvent::QuickStop { cycle, ok });
            }
        }
        if let Some(ev) = out.command {
            if request.is_some() {
                self.log.send(LogEvent::Command(ev));
            }
            if matches!(ev.result, Ok(CommandAccepted::Reset)) {
                self.auto_reset = false;
                self.release_drives();
            }
            if let Some(env) = request {
                let (status, reason) = match ev.result {
                    Ok(CommandAccepted::NothingToReset) => (ReplyStatus::NothingToReset, 0),
                    Ok(_) => (ReplyStatus::Accepted, 0),
                    Err(CommandRefused::Reset { reason }) => {
                        (ReplyStatus::ResetRefused, reason_code(&reason))
                    }
                    Err(CommandRefused::NotOk { reason, .. }) => {
                        (ReplyStatus::NotOk, reason_code(&reason))
                    }
                    Err(CommandRefused::AboveWarn { reason }) => {
                        (ReplyStatus::AboveWarn, reason_code(&reason))
                    }
                    Err(CommandRefused::NoEstimate | CommandRefused::Unsolvable) => {
                        (ReplyStatus::NoEstimate, 0)
                    }
                    Err(_) => (ReplyStatus::Refused, 0),
                };
                self.reply(env, status, reason);
            }
        }
        if let Some(
            env @ Envelope {
                request: Request::MoveTip { tip_m },
                ..
            },
        ) = request
        {
            let (status, reason) = self.move_tip(&out, &tip_m);
            self.reply(env, status, reason);
        }
        &self.output
    }

    /// After an accepted reset: bring the drives back to `Enabled`, deciding
    /// on the drive state gathered (and published) in this cycle.
    fn release_drives(&mut self) {
        match self.drive_state {
            Some(DriveState::QuickStop) => {
                let _ = self.drives.disable();
                let _ = self.drives.enable();
            }
            Some(DriveState::Fault { .. }) => {
                let _ = self.drives.fault_reset();
                let _ = self.drives.enable();
            }
            Some(DriveState::Ready) => {
                let _ = self.drives.enable();
            }
            _ => {}
        }
        self.halted = false;
    }

    fn move_tip(&mut self, out: &CycleOutput, tip_m: &Vec3) -> (ReplyStatus, u16) {
        if self.halted || matches!(out.guard_state, GuardState::Stop | GuardState::Fault) {
            return (ReplyStatus::Halted, reason_code(&out.guard_reason));
        }
        let Ok(target) = inverse(&self.calibration, &self.profile, tip_m) else {
            return (ReplyStatus::Unreachable, 0);
        };
        let q = [target.q1_m, target.q2_m, target.q3_m];
        if q.iter()
            .zip(self.travel_m.iter())
            .any(|(v, (lo, hi))| !(v >= lo && v <= hi))
        {
            return (ReplyStatus::Unreachable, 0);
        }
        // Above the warn limit, only moves that do not push the tip further
        // along its force are allowed.
        if out.guard_state == GuardState::Warn {
            let (TipOutcome::Estimate(e), Some(pose)) = (out.tip, out.pose) else {
                return (ReplyStatus::TowardForce, reason_code(&out.guard_reason));
            };
            if (tip_m - pose.tip_m).dot(&e.force_n) > 0.0 {
                return (ReplyStatus::TowardForce, reason_code(&out.guard_reason));
            }
        }
        match self.drives.set_targets(target) {
            Ok(()) => (ReplyStatus::Accepted, 0),
            Err(_) => (ReplyStatus::DrivesRefused, 0),
        }
    }
}
