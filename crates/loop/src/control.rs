//! The body of one control cycle: gather the inputs (sensor poll, drive
//! positions and state, at most one pending operator request) into a
//! [`LoopInput`], run the pure step [`LoopStep::step`], and carry out its
//! decision on the drives ([`DriveAction`]: a quick stop, a release after an
//! accepted reset, the setpoint of a planned move) and the reply. Nothing is
//! decided here: what the drives are told is a function of the recorded
//! input. Everything is allocated in [`Controller::new`]; a cycle allocates
//! nothing (proved by `tests/no_alloc.rs`).

use crate::logq::{LogEvent, LogSender};
pub use crate::reply::{Envelope, Reply};
use crate::step::{
    DriveAction, LoopInput, LoopOutput, LoopStep, Release, StepConfig, StepConfigError,
};
pub use crate::step::{ReplyStatus, Request, reason_code, recorded_reason_code};
use crossbeam_queue::ArrayQueue;
use sar_estimator::Vec3;
use sar_estimator::cycle::{
    CommandAccepted, CycleInput, CycleOutput, DrainedSamples, EstimatorConfig, JointSample,
    SensorSample, SpikeLimits,
};
use sar_hal::{AxisDrives, DriveState, ForceSensor, WrenchSample};
use sar_kinematics::ActiveJoints;
use std::sync::Arc;

/// Capacity of the operator request queue and of the reply queue.
pub const QUEUE_CAPACITY: usize = 16;

/// The operator's ends of the request and reply queues.
#[derive(Debug, Clone)]
pub struct Operator {
    /// Requests in (bounded; a full queue refuses the push).
    pub requests: Arc<ArrayQueue<Envelope>>,
    /// Replies out (bounded; the oldest is dropped when full).
    pub replies: Arc<ArrayQueue<Reply>>,
    /// The publishing thread's heartbeat (it carries the commands and the
    /// state; its silence is a Fault: `Reason::PublisherStalled`).
    pub publisher: Arc<Heartbeat>,
}

impl Operator {
    /// New empty queues.
    pub fn new() -> Self {
        Self {
            requests: Arc::new(ArrayQueue::new(QUEUE_CAPACITY)),
            replies: Arc::new(ArrayQueue::new(QUEUE_CAPACITY)),
            publisher: Arc::new(Heartbeat::default()),
        }
    }
}

/// A thread's sign of life, read by the loop (wait-free): the publishing
/// thread beats once per wake-up (it is woken every cycle).
#[derive(Debug, Default)]
pub struct Heartbeat {
    beats: std::sync::atomic::AtomicU64,
    monitored: std::sync::atomic::AtomicBool,
}

impl Heartbeat {
    /// Marks the thread as watched (from its start on, its silence counts).
    pub fn watch(&self) {
        self.monitored
            .store(true, std::sync::atomic::Ordering::Release);
    }

    /// One sign of life.
    pub fn beat(&self) {
        self.beats
            .fetch_add(1, std::sync::atomic::Ordering::Release);
    }

    /// The beats so far, or `None` when nobody beats (no such thread).
    pub fn read(&self) -> Option<u64> {
        self.monitored
            .load(std::sync::atomic::Ordering::Acquire)
            .then(|| self.beats.load(std::sync::atomic::Ordering::Acquire))
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
    /// Sensor samples the driver dropped before the loop drained them (its
    /// store of undrained samples was full): missing from the recording.
    pub sensor_samples_lost: u64,
}

/// A cycle's time, read once after its inputs are gathered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleTime {
    /// The loop's clock (the cycle's `now`; simulated on a simulated
    /// clock), ns; `None`: it could not be read.
    pub now_ns: Option<u64>,
    /// The host's monotonic clock, ns, against which the publishing
    /// thread's silence is measured (it runs in real time whatever the
    /// loop's clock).
    pub host_ns: Option<u64>,
}

/// One reading for both (real time: the loop's clock is the host's).
impl From<Option<u64>> for CycleTime {
    fn from(now_ns: Option<u64>) -> Self {
        Self {
            now_ns,
            host_ns: now_ns,
        }
    }
}

/// The per-cycle controller.
#[derive(Debug)]
pub struct Controller<S: ForceSensor, D: AxisDrives> {
    step: LoopStep,
    sensor: S,
    drives: D,
    operator: Operator,
    log: LogSender,
    /// The last cycle's input; its sensor and joint samples are kept until
    /// the devices report newer ones.
    last_input: LoopInput,
    /// Reset automatically (the demo only) until the first accepted reset:
    /// the reset is a request of the cycle's input like an operator's.
    auto_reset: bool,
    counts: ActionCounts,
    /// Called once per cycle, in the gather phase, before the positions are
    /// read (the CANopen drives' SYNC / PDO exchange); `None` for drives that
    /// need nothing (the simulator).
    drives_cycle: Option<DrivesCycle<D>>,
    /// The publishing thread's last beat count and when it changed (ns of
    /// the cycle clock).
    publisher_beat: Option<(u64, u64)>,
    /// Every sensor sample received since the previous cycle (the
    /// recorder's `/sar/sensor/wrench`), `drained_count` of them in use;
    /// fixed at construction.
    drained: [WrenchSample; DRAIN_CAPACITY],
    drained_count: usize,
    /// The spike check's limits and the sensor's noise: every drained
    /// sample's step from the one before it is judged with them
    /// ([`DrainedSamples`], recorded with the cycle's input).
    spikes: Option<SpikeLimits>,
    noise_n: Vec3,
    /// The force of the last finite sample drained (the chain of jumps goes
    /// on from it across cycles).
    last_drained_force_n: Option<Vec3>,
    /// This cycle's count of what was drained.
    drained_samples: DrainedSamples,
}

/// Sensor samples handed to the recorder per cycle at most (16 kHz at a
/// 1 kHz loop); more wait for the next cycle (the driver keeps them).
pub const DRAIN_CAPACITY: usize = 16;

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
        // Set by `gather` for every cycle's input.
        drained: DrainedSamples::default(),
    }
}

impl<S: ForceSensor, D: AxisDrives> Controller<S, D> {
    /// Builds the controller. The drives are not enabled here: the guard
    /// starts in Fault (no input yet), and only an accepted reset releases
    /// them; drives that come up enabled get a quick stop in the first
    /// cycle. `auto_reset` (the demo) requests a reset in every cycle without
    /// an operator request until one is accepted, as an operator would at
    /// the start.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        config: &EstimatorConfig,
        bias: sar_estimator::cycle::Bias,
        step: StepConfig,
        sensor: S,
        drives: D,
        operator: Operator,
        log: LogSender,
        auto_reset: bool,
    ) -> Result<Self, StepConfigError> {
        let step = LoopStep::new(config, bias, step)?;
        let sensor_sample = SensorSample {
            force_n: Vec3::zeros(),
            torque_nm: Vec3::zeros(),
            counter: 0,
            status: 0,
            stamp_ns: 0,
            valid: false,
            drained: DrainedSamples::default(),
        };
        let joints = JointSample {
            joints: ActiveJoints::default(),
            stamp_ns: 0,
            valid: false,
        };
        let last_input = LoopInput {
            cycle: 0,
            now_ns: None,
            sensor: sensor_sample,
            joints,
            drive_state: None,
            request: None,
            publisher_idle_ns: 0,
        };
        Ok(Self {
            step,
            sensor,
            drives,
            operator,
            log,
            last_input,
            auto_reset,
            counts: ActionCounts::default(),
            drives_cycle: None,
            publisher_beat: None,
            // Never read beyond `drained_count`.
            drained: [WrenchSample {
                force_n: Vec3::zeros(),
                torque_nm: Vec3::zeros(),
                counter: 0,
                status: sar_hal::SensorStatus(u32::MAX),
                received_ns: 0,
            }; DRAIN_CAPACITY],
            drained_count: 0,
            spikes: config.plausibility.limits().spikes,
            noise_n: config.noise.std_n(),
            last_drained_force_n: None,
            drained_samples: DrainedSamples::default(),
        })
    }

    /// Every sensor sample received since the previous cycle, oldest first
    /// (the one the step used among them, or in an earlier cycle's: its
    /// counter and stamp are in the cycle's input).
    pub fn sensor_samples(&self) -> &[WrenchSample] {
        self.drained.get(..self.drained_count).unwrap_or(&[])
    }

    /// Calls `hook` on the drives once per cycle, in the gather phase before
    /// their positions are read (e.g. `sar_daemon::devices::canopen_cycle`: a
    /// CANopen host that stops cycling makes its drives quick-stop). A
    /// failing hook counts as a drive error and is logged; the positions it
    /// could not refresh go stale and the guard acts on that.
    pub fn with_drives_cycle(mut self, hook: DrivesCycle<D>) -> Self {
        self.drives_cycle = Some(hook);
        self
    }

    /// The estimator's output of the last cycle.
    pub fn output(&self) -> &CycleOutput {
        &self.step.last().estimate
    }

    /// The whole decision of the last cycle.
    pub fn decision(&self) -> &LoopOutput {
        self.step.last()
    }

    /// The estimator's input of the last cycle.
    pub fn input(&self) -> CycleInput {
        self.last_input.cycle_input()
    }

    /// The whole input of the last cycle (what a recording holds).
    pub fn loop_input(&self) -> &LoopInput {
        &self.last_input
    }

    /// The pure step (its configuration, the estimator's bias and limits).
    pub fn loop_step(&self) -> &LoopStep {
        &self.step
    }

    /// The drives' state as read in the last cycle.
    pub fn drive_state(&self) -> Option<DriveState> {
        self.last_input.drive_state
    }

    /// Whether the drives are halted: the guard is in Stop or Fault (they
    /// were quick-stopped, or never released), so moves are refused until a
    /// reset is accepted.
    pub fn halted(&self) -> bool {
        self.step.last().estimate.guard_state.is_halting()
    }

    /// What the controller did so far.
    pub fn counts(&self) -> ActionCounts {
        self.counts
    }

    /// The drives (for the shutdown's halt, and tests).
    pub fn drives_mut(&mut self) -> &mut D {
        &mut self.drives
    }

    /// How long the publishing thread's heartbeat has not changed, ns (0
    /// when nobody beats, or the clock failed).
    fn publisher_idle_ns(&mut self, beats: Option<u64>, now_ns: Option<u64>) -> u64 {
        let (Some(beats), Some(now_ns)) = (beats, now_ns) else {
            return 0;
        };
        match self.publisher_beat {
            Some((last, since_ns)) if last == beats => now_ns.saturating_sub(since_ns),
            _ => {
                self.publisher_beat = Some((beats, now_ns));
                0
            }
        }
    }

    /// Halts the drives (shutdown): quick stop, then disable.
    pub fn shutdown(&mut self) {
        let _ = self.drives.quick_stop();
        let _ = self.drives.disable();
    }

    /// Runs one cycle. `now` reads the clocks (`None`: one could not be
    /// read); it is called once, after the inputs are gathered, so that no
    /// input is stamped after the cycle's time.
    pub fn step<T: Into<CycleTime>>(
        &mut self,
        cycle: u64,
        now: impl FnOnce() -> T,
    ) -> &CycleOutput {
        // Gather: the cycle's input (and the request's envelope, for the
        // reply).
        let envelope = self.gather(cycle, now);
        // Decide: the pure step.
        self.step.step(&self.last_input);
        // Act: a halting state stops the drives in this very cycle.
        self.report(cycle);
        self.carry_out(cycle);
        self.answer(cycle, envelope);
        &self.step.last().estimate
    }

    /// Gathers the cycle's input into `last_input`: every sensor sample for
    /// the recorder and the newest for the step, the drives' positions and
    /// state, the operator's request, the publishing thread's silence, and
    /// last the clock. Returns the request's envelope.
    fn gather<T: Into<CycleTime>>(
        &mut self,
        cycle: u64,
        now: impl FnOnce() -> T,
    ) -> Option<Envelope> {
        self.drain_sensor();
        self.poll_sensor(cycle);
        self.read_joints(cycle);
        let drive_state = self.read_drive_state(cycle);
        let envelope = self.operator.requests.pop();
        let request = match envelope {
            Some(e) => Some(e.request),
            None => self.auto_reset.then_some(Request::Reset),
        };
        let beats = self.operator.publisher.read();
        let CycleTime { now_ns, host_ns } = now().into();
        let publisher_idle_ns = self.publisher_idle_ns(beats, host_ns);
        let mut sensor = self.last_input.sensor;
        sensor.drained = self.drained_samples;
        self.last_input = LoopInput {
            cycle,
            now_ns,
            sensor,
            joints: self.last_input.joints,
            drive_state,
            request,
            publisher_idle_ns,
        };
        envelope
    }

    /// Every sensor sample received since the previous cycle, for the
    /// recorder ([`Controller::sensor_samples`]), counting those the driver
    /// lost.
    fn drain_sensor(&mut self) {
        let drained = self.sensor.drain(&mut self.drained);
        self.drained_count = match drained {
            Ok(d) => {
                if d.lost > 0 {
                    self.counts.sensor_samples_lost += d.lost;
                }
                d.count.min(DRAIN_CAPACITY)
            }
            Err(_) => 0,
        };
        self.drained_samples = DrainedSamples {
            counted: drained.is_ok(),
            samples: u16::try_from(self.drained_count).unwrap_or(u16::MAX),
            jumps: self.count_jumps(),
        };
    }

    /// The jumps beyond the spike threshold among the samples drained this
    /// cycle, each from the finite sample received before it (across
    /// cycles); a non-finite one breaks the chain, as it restarts the
    /// estimator's own check. Never allocates.
    fn count_jumps(&mut self) -> u16 {
        let mut jumps = 0u16;
        let count = self.drained_count;
        for s in self.drained.iter().take(count) {
            let finite = s
                .force_n
                .iter()
                .chain(s.torque_nm.iter())
                .all(|v| v.is_finite());
            if !finite {
                self.last_drained_force_n = None;
                continue;
            }
            if let (Some(limits), Some(previous)) = (self.spikes, self.last_drained_force_n)
                && limits.is_jump(&self.noise_n, &previous, &s.force_n)
            {
                jumps = jumps.saturating_add(1);
            }
            self.last_drained_force_n = Some(s.force_n);
        }
        jumps
    }

    /// The newest sensor sample into the input (kept when there is none; a
    /// failed poll marks it invalid and is logged with its cause).
    fn poll_sensor(&mut self, cycle: u64) {
        match self.sensor.poll() {
            Ok(Some(s)) => self.last_input.sensor = sensor_sample(&s),
            Ok(None) => {}
            Err(e) => {
                self.last_input.sensor.valid = false;
                self.counts.sensor_errors += 1;
                // Its cause, a static text: no allocation here.
                self.log.send(LogEvent::SensorPollFailed {
                    cycle,
                    cause: sar_hal::Error::cause(&e),
                });
            }
        }
    }

    /// The drives' per-cycle hook, then their positions into the input (a
    /// failed reading marks them invalid).
    fn read_joints(&mut self, cycle: u64) {
        if let Some(hook) = self.drives_cycle
            && let Err(what) = hook(&mut self.drives)
        {
            self.drive_error(cycle, what);
        }
        match self.drives.positions() {
            Ok(p) => {
                self.last_input.joints = JointSample {
                    joints: p.joints,
                    stamp_ns: p.stamp_ns,
                    valid: p.valid,
                }
            }
            Err(_) => {
                self.last_input.joints.valid = false;
                self.drive_error(cycle, "drive positions");
            }
        }
    }

    /// The drives' state (`None`: unreadable), logged when it changed since
    /// the last cycle.
    fn read_drive_state(&mut self, cycle: u64) -> Option<DriveState> {
        let drive_state = self.drives.state().ok();
        if drive_state != self.last_input.drive_state {
            self.log.send(LogEvent::DriveState {
                cycle,
                state: drive_state,
            });
        }
        drive_state
    }

    /// Logs what the guard did this cycle: a guarded move's stop, a
    /// transition (counting the entries into Stop or Fault).
    fn report(&mut self, cycle: u64) {
        let decision = self.step.last();
        if let Some(g) = decision.guarded_stop
            && g.cycle == cycle
        {
            self.log.send(LogEvent::GuardedStop(g));
        }
        if decision.inertia.newly_named {
            let rod = self.step.estimator().tip_estimator().inertia();
            self.log.send(LogEvent::InertiaNamed {
                cycle,
                verdict: decision.inertia,
                configured: (rod.inertia_perp_kgm2, rod.adapter_mass_kg),
            });
        }
        if let Some(n) = decision.support_note {
            self.log.send(LogEvent::Support(n));
        }
        if decision.servo_named_now {
            let fit = &decision.servo_fit;
            self.log.send(LogEvent::ServoMismatch {
                cycle,
                follow_rms_m: fit.follow_rms_per_axis_m(),
                disturbance_mps2: fit.disturbance_mps2,
                count_m: decision.encoder_count_m,
            });
        }
        if let Some(t) = decision.estimate.transition {
            self.log.send(LogEvent::Transition(t));
            if t.to.is_halting() {
                self.counts.halting_transitions += 1;
            }
        }
    }

    /// Tells the drives the step's [`DriveAction`]; a failure is counted
    /// and logged.
    fn carry_out(&mut self, cycle: u64) {
        let decision = self.step.last();
        let entered_halt = decision
            .estimate
            .transition
            .is_some_and(|t| t.to.is_halting());
        let action = decision.action;
        match action {
            DriveAction::None => {}
            DriveAction::QuickStop => self.quick_stop(cycle, entered_halt),
            DriveAction::Release(how) => {
                if !self.release(how) {
                    self.drive_error(cycle, "drive release");
                }
            }
            DriveAction::Setpoint(q) => {
                if self.drives.set_targets(q).is_err() {
                    self.drive_error(cycle, "drive setpoint");
                }
            }
            DriveAction::FaultReset => {
                if self.drives.fault_reset().is_err() {
                    self.drive_error(cycle, "drive fault reset");
                }
            }
            DriveAction::Stream(q) => {
                let period_ns = self.step.config().period_ns;
                if self.drives.stream(q, period_ns).is_err() {
                    self.drive_error(cycle, "drive stream set point");
                }
            }
        }
    }

    /// A quick stop: the one of the cycle that entered Stop or Fault, or a
    /// repeat while the drives still report Enabled (refused, lost, or they
    /// came up enabled), repeated every cycle until they stop.
    fn quick_stop(&mut self, cycle: u64, entered_halt: bool) {
        let ok = self.drives.quick_stop().is_ok();
        if entered_halt {
            self.counts.quick_stops += 1;
            self.counts.stops_in_same_cycle += 1;
            self.log.send(LogEvent::QuickStop { cycle, ok });
        } else {
            self.counts.quick_stop_retries += 1;
            if !ok {
                self.log.send(LogEvent::QuickStop { cycle, ok });
            }
        }
    }

    /// Brings the drives back after an accepted reset; `false` when a call
    /// failed.
    fn release(&mut self, how: Release) -> bool {
        match how {
            Release::Enable => self.drives.enable().is_ok(),
            Release::DisableEnable => self.drives.disable().is_ok() && self.drives.enable().is_ok(),
            Release::FaultResetEnable => {
                self.drives.fault_reset().is_ok() && self.drives.enable().is_ok()
            }
        }
    }

    /// A failed drive call: counted and logged.
    fn drive_error(&mut self, cycle: u64, what: &'static str) {
        self.counts.drive_errors += 1;
        self.log.send(LogEvent::DeviceError { cycle, what });
    }

    /// The operator's side: an operator's estimator command logged, the
    /// demo's automatic reset ended by an accepted reset, and the reply to
    /// the request queued (a full queue loses its oldest reply, never
    /// blocks the loop) and logged.
    fn answer(&mut self, cycle: u64, envelope: Option<Envelope>) {
        let decision = self.step.last();
        if let Some(ev) = decision.estimate.command {
            if envelope.is_some() {
                self.log.send(LogEvent::Command(ev));
            }
            if matches!(ev.result, Ok(CommandAccepted::Reset)) {
                self.auto_reset = false;
            }
        }
        if let (Some(env), Some((status, reason))) = (envelope, decision.reply) {
            let reply = Reply {
                id: env.id,
                request: env.request,
                cycle,
                status,
                reason,
                detail: decision.reply_detail,
            };
            let _ = self.operator.replies.force_push(reply);
            self.log.send(LogEvent::Reply(reply));
        }
    }
}
