//! Logging off the loop thread: the loop pushes small `Copy` events into a
//! bounded lock-free queue (no allocation, no lock, no I/O); a logging thread
//! pops them and writes them with `tracing`. A full queue drops the event and
//! counts it, never blocks the loop. The logging thread sleeps until a thread
//! that wakes anyway (`sard`'s publishing thread) finds events queued and
//! wakes it ([`LogWaker`]); the loop never wakes it (a system call).

use crate::reply::Reply;
use crossbeam_queue::ArrayQueue;
use sar_estimator::cycle::CommandEvent;
use sar_estimator::guard::Transition;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Capacity of the queue, events.
pub const CAPACITY: usize = 1024;
/// The logging thread's longest sleep when nothing wakes it (the warning of
/// dropped events, a logging thread nobody wakes).
pub const LOG_WAIT: Duration = Duration::from_secs(1);

/// What the loop reports.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum LogEvent {
    /// A guard transition.
    Transition(Transition),
    /// An estimator command and what became of it.
    Command(CommandEvent),
    /// A reply to an operator request.
    Reply(Reply),
    /// The drives were told to quick-stop in this cycle.
    QuickStop {
        /// The cycle.
        cycle: u64,
        /// Whether the drives accepted the command.
        ok: bool,
    },
    /// A drive or sensor call failed.
    DeviceError {
        /// The cycle.
        cycle: u64,
        /// Which call.
        what: &'static str,
    },
    /// The sensor's poll failed, with the driver's cause (empty: none given).
    SensorPollFailed {
        /// The cycle.
        cycle: u64,
        /// The cause ("sensor silent: only duplicate packets").
        cause: &'static str,
    },
    /// The drives' state changed (`None`: it could not be read).
    DriveState {
        /// The cycle.
        cycle: u64,
        /// The new state.
        state: Option<sar_hal::DriveState>,
    },
    /// A cycle ended after the next deadline.
    Overrun {
        /// The cycle.
        cycle: u64,
        /// How late, ns.
        late_ns: u64,
        /// Whole periods that passed meanwhile, skipped (a stall).
        skipped: u64,
    },
    /// A guarded move was braked: its force reached the limit.
    GuardedStop(crate::step::GuardedStop),
    /// The inertia watch named I_perp or the adapter's mass (issue 34).
    InertiaNamed {
        /// The cycle.
        cycle: u64,
        /// Its verdict.
        verdict: sar_estimator::inertia_watch::InertiaVerdict,
        /// The configured I_perp, kg m^2, and m_s, kg.
        configured: (f64, f64),
    },
    /// The support watch's status (the first reset, a verdict's change, a
    /// confirmation; issue 34).
    Support(crate::step::SupportNote),
    /// The drives do not follow the servo model (issue 34): named once
    /// until they are released.
    ServoMismatch {
        /// The cycle.
        cycle: u64,
        /// The encoders less the model's position, RMS per axis (q1, q2,
        /// q3) over the fit's window of motion, m.
        follow_rms_m: [f64; 3],
        /// The acceleration the observer adds to the model's, per axis,
        /// m/s^2.
        disturbance_mps2: [f64; 3],
        /// One encoder count, m.
        count_m: f64,
    },
}

/// The bounded queue of log events the loop fills ([`channel`]).
pub type LogQueue = Arc<ArrayQueue<LogEvent>>;

/// The loop's end of the queue.
#[derive(Debug, Clone)]
pub struct LogSender {
    queue: Arc<ArrayQueue<LogEvent>>,
    dropped: Arc<AtomicU64>,
}

impl LogSender {
    /// Queues an event; a full queue drops it and counts it.
    pub fn send(&self, event: LogEvent) {
        if self.queue.push(event).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Events dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// The logging thread.
#[derive(Debug)]
pub struct LogThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    waker: Option<LogWaker>,
}

/// Wakes the logging thread when events are queued: for a thread that wakes
/// anyway (never the loop: a wake-up is a system call).
#[derive(Debug, Clone)]
pub struct LogWaker {
    queue: LogQueue,
    thread: std::thread::Thread,
}

impl LogWaker {
    /// Wakes the logging thread when the queue holds events (a drop comes
    /// with a full queue); two loads when there are none.
    pub fn wake_if_pending(&self) {
        if !self.queue.is_empty() {
            self.thread.unpark();
        }
    }
}

/// How long [`LogThread::finish`] waits for the logging thread at most.
pub const LOG_JOIN_WAIT: std::time::Duration = std::time::Duration::from_millis(500);

/// Makes the queue (allocated here, once) and, when `spawn`, the thread
/// that writes its events with `tracing`.
pub fn channel(spawn: bool) -> (LogSender, Option<LogThread>, LogQueue) {
    let queue = Arc::new(ArrayQueue::new(CAPACITY));
    let sender = LogSender {
        queue: Arc::clone(&queue),
        dropped: Arc::new(AtomicU64::new(0)),
    };
    let thread = spawn.then(|| {
        let stop = Arc::new(AtomicBool::new(false));
        let q = Arc::clone(&queue);
        let s = Arc::clone(&stop);
        let dropped = Arc::clone(&sender.dropped);
        let handle = std::thread::Builder::new()
            .name("sard-log".to_owned())
            .spawn(move || log_loop(&q, &s, &dropped))
            .ok();
        let waker = handle.as_ref().map(|h| LogWaker {
            queue: Arc::clone(&queue),
            thread: h.thread().clone(),
        });
        LogThread {
            stop,
            handle,
            waker,
        }
    });
    (sender, thread, queue)
}

impl LogThread {
    /// The thread's waker (`None`: the thread did not start).
    pub fn waker(&self) -> Option<LogWaker> {
        self.waker.clone()
    }

    /// Writes what is left and ends the thread, waiting for it at most
    /// [`LOG_JOIN_WAIT`] (a log pipe whose reader stalls holds it): false
    /// when it was left behind (`sar_hal::join::left_behind` names it).
    pub fn finish(mut self) -> bool {
        self.stop.store(true, Ordering::SeqCst);
        match self.handle.take() {
            Some(h) => {
                h.thread().unpark();
                sar_hal::join::join_within(h, LOG_JOIN_WAIT).is_some()
            }
            None => true,
        }
    }
}

/// The logging thread's body: writes the queued events and says how many
/// were dropped, then sleeps until woken ([`LogWaker`], [`LogThread::finish`])
/// or for at most [`LOG_WAIT`].
fn log_loop(queue: &ArrayQueue<LogEvent>, stop: &AtomicBool, dropped: &AtomicU64) {
    let mut reported_dropped = 0;
    loop {
        let stopping = stop.load(Ordering::SeqCst);
        while let Some(event) = queue.pop() {
            write(&event);
        }
        let d = dropped.load(Ordering::Relaxed);
        if d > reported_dropped {
            tracing::warn!("{} log events dropped (queue full)", d - reported_dropped);
            reported_dropped = d;
        }
        if stopping {
            return;
        }
        std::thread::park_timeout(LOG_WAIT);
    }
}

/// Writes one event.
pub fn write(event: &LogEvent) {
    match event {
        LogEvent::Transition(t) => write_transition(t),
        LogEvent::Command(c) => match &c.result {
            Ok(a) => tracing::info!("command {}: {}", command_text(&c.command), accepted_text(a)),
            Err(e) => tracing::warn!("command {} refused: {}", command_text(&c.command), e),
        },
        LogEvent::Reply(r) => tracing::info!(
            id = r.id,
            cycle = r.cycle,
            "request {}: {}",
            r.request,
            sar_msgs::wire::status_name(r.status as u32)
        ),
        LogEvent::QuickStop { cycle, ok } => {
            if *ok {
                tracing::error!(cycle, "drives told to quick-stop");
            } else {
                tracing::error!(cycle, "drives REFUSED the quick stop");
            }
        }
        LogEvent::DeviceError { cycle, what } => tracing::error!(cycle, "{what} failed"),
        LogEvent::SensorPollFailed { cycle, cause: "" } => {
            tracing::error!(cycle, "sensor poll failed")
        }
        LogEvent::SensorPollFailed { cycle, cause } => {
            tracing::error!(cycle, "sensor poll failed: {cause}")
        }
        LogEvent::DriveState { cycle, state } => {
            tracing::info!(cycle, "drives: {}", drive_state_text(*state))
        }
        LogEvent::Overrun {
            cycle,
            late_ns,
            skipped,
        } => tracing::warn!(
            cycle,
            "cycle overran its period by {late_ns} ns: {skipped} periods skipped"
        ),
        LogEvent::InertiaNamed { .. } => write_inertia(event),
        LogEvent::GuardedStop(g) => tracing::info!(
            cycle = g.cycle,
            "guarded move braked at tip ({:.4}, {:.4}, {:.4}) m: |F_tip| {:.2} N reached its {} N",
            g.tip_m.x,
            g.tip_m.y,
            g.tip_m.z,
            g.force_n.norm(),
            g.max_force_n
        ),
        LogEvent::Support(n) => write_support(n),
        LogEvent::ServoMismatch { .. } => write_servo_mismatch(event),
    }
}

/// A guard transition: an error when it halts, else a warning.
fn write_transition(t: &Transition) {
    if t.to.is_halting() {
        tracing::error!(
            cycle = t.cycle,
            "guard {} -> {}: {}",
            t.from,
            t.to,
            t.reason
        );
    } else {
        tracing::warn!(
            cycle = t.cycle,
            "guard {} -> {}: {}",
            t.from,
            t.to,
            t.reason
        );
    }
}

/// The servo mismatch, a warning.
fn write_servo_mismatch(event: &LogEvent) {
    if let LogEvent::ServoMismatch {
        cycle,
        follow_rms_m,
        disturbance_mps2,
        count_m,
    } = event
    {
        let text = servo_mismatch_text(follow_rms_m, disturbance_mps2, *count_m);
        tracing::warn!(cycle, "{text}");
    }
}

/// The servo mismatch in words: how far the axes follow the model, what
/// the observer absorbs, the advice.
pub fn servo_mismatch_text(
    follow_rms_m: &[f64; 3],
    disturbance_mps2: &[f64; 3],
    count_m: f64,
) -> String {
    let [a, b, c] = follow_rms_m.map(|m| m * 1e3);
    let [d1, d2, d3] = *disturbance_mps2;
    format!(
        "the drives do not follow the servo model ([axes] servo_*): encoders less the model, RMS over the last {} s of motion q1 {a:.3} mm, q2 {b:.3} mm, q3 {c:.3} mm (named beyond {:.4} mm); the servo observer absorbs it (model acceleration corrected by [{d1:.3} {d2:.3} {d3:.3}] m/s^2, its standard deviation in the guard's margin); run `sarctl identify --servo`",
        crate::observer::FIT_WINDOW_S,
        crate::observer::FIT_NAME_COUNTS * count_m * 1e3
    )
}

/// Writes [`LogEvent::InertiaNamed`] (a warning).
fn write_inertia(event: &LogEvent) {
    if let LogEvent::InertiaNamed {
        cycle,
        verdict,
        configured,
    } = event
    {
        tracing::warn!(cycle, "{}", inertia_text(verdict, *configured));
    }
}

/// The inertia watch's finding, one line: what reads off, by how much, the
/// implied value, and what to do.
pub fn inertia_text(
    v: &sar_estimator::inertia_watch::InertiaVerdict,
    (inertia_kgm2, adapter_kg): (f64, f64),
) -> String {
    let mut parts = Vec::new();
    if v.named.inertia_perp {
        parts.push(format!(
            "I_perp reads {:.2}x the configured ({:.5} +- {:.5} kg m^2 where {:.5} is configured)",
            v.inertia_perp_ratio, v.inertia_perp_kgm2, v.inertia_perp_std_kgm2, inertia_kgm2
        ));
    }
    if v.named.adapter {
        parts.push(format!(
            "the adapter's mass reads {:.3} +- {:.3} kg where {adapter_kg} kg is configured",
            v.adapter_mass_kg, v.adapter_mass_std_kg
        ));
    }
    format!(
        "inertia watch: in free motion the tip force follows the carriage's acceleration: {}: run `sarctl identify --dynamic` (it writes [manipulator] inertia_perp_kgm2 and [sensor] adapter_mass_kg)",
        parts.join("; ")
    )
}

/// A support note: an error when a shift is named, else information.
fn write_support(n: &crate::step::SupportNote) {
    let text = support_text(n);
    if n.status.verdict == sar_estimator::support::SupportVerdict::Shifted {
        tracing::error!(cycle = n.cycle, "{text}");
    } else {
        tracing::info!(cycle = n.cycle, "{text}");
    }
}

/// A support note in words: why, the verdict, the shift per axis with its
/// standard error (or "not determined").
pub fn support_text(n: &crate::step::SupportNote) -> String {
    use crate::step::SupportWhy;
    let s = &n.status;
    let why = match n.why {
        SupportWhy::FirstReset => "support at the first reset (the mean at rest)",
        SupportWhy::Verdict => "support check",
        SupportWhy::Confirmed => "support confirmed by the operator",
    };
    let axes: Vec<String> = ["X0", "Y0", "Z0"]
        .iter()
        .zip(s.shift_m.iter().zip(s.std_m.iter()))
        .map(|(name, (v, sd))| {
            if *sd <= n.max_std_m {
                format!("{name} {:+.2} +- {:.2} mm", v * 1e3, sd * 1e3)
            } else {
                format!("{name} not determined")
            }
        })
        .collect();
    let mut text = format!(
        "{why}: {}; shift {} (limit {:.1} mm; a constant tip force {} N; chi2/dof {:.2}, {:.0} free samples)",
        s.verdict.words(),
        axes.join(", "),
        n.max_shift_m * 1e3,
        v3_text(&s.contact_n, 2),
        s.chi2_dof,
        s.samples
    );
    if s.verdict == sar_estimator::support::SupportVerdict::Shifted {
        text.push_str(
            "; force control refused until re-calibrated (sarctl identify) or confirmed (sarctl support confirm)",
        );
    }
    text
}

/// A vector as `[x y z]` with `digits` decimals.
fn v3_text(v: &sar_kinematics::Vec3, digits: usize) -> String {
    format!("[{:.digits$} {:.digits$} {:.digits$}]", v.x, v.y, v.z)
}

/// Force limits as the log prints them (their `Display`).
fn limits_text(l: &sar_estimator::guard::ForceLimits) -> String {
    l.to_string()
}

/// A bias as the log prints it.
fn bias_text(b: &sar_estimator::cycle::Bias) -> String {
    format!(
        "force {} N, torque {} N m",
        v3_text(&b.force_n, 3),
        v3_text(&b.torque_nm, 4)
    )
}

/// An estimator command in words.
fn command_text(c: &sar_estimator::cycle::Command) -> String {
    use sar_estimator::cycle::Command;
    match c {
        Command::Reset => "reset".to_owned(),
        Command::Tare => "tare".to_owned(),
        Command::SetBias(b) => format!("set bias ({})", bias_text(b)),
        Command::SetLimits(l) => format!("set limits ({})", limits_text(l)),
    }
}

/// What an accepted estimator command did, in words.
fn accepted_text(a: &sar_estimator::cycle::CommandAccepted) -> String {
    use sar_estimator::cycle::CommandAccepted;
    match a {
        CommandAccepted::Reset => "accepted, the guard is reset".to_owned(),
        CommandAccepted::NothingToReset => "accepted, nothing to reset".to_owned(),
        CommandAccepted::BiasSet { previous, bias } => format!(
            "accepted, bias now {} (was {})",
            bias_text(bias),
            bias_text(previous)
        ),
        CommandAccepted::LimitsSet { previous, limits } => format!(
            "accepted, limits now {} (were {})",
            limits_text(limits),
            limits_text(previous)
        ),
    }
}

/// The drives' state in words (`None`: it could not be read).
fn drive_state_text(state: Option<sar_hal::DriveState>) -> String {
    use sar_hal::DriveState;
    match state {
        None => "state unreadable".to_owned(),
        Some(DriveState::Ready) => "ready".to_owned(),
        Some(DriveState::Enabled) => "enabled".to_owned(),
        Some(DriveState::QuickStop) => "quick stop".to_owned(),
        Some(DriveState::Fault {
            axis: Some(axis),
            code,
        }) => format!("fault on q{} (code 0x{code:04x})", u16::from(axis) + 1),
        Some(DriveState::Fault { axis: None, code }) => {
            format!("fault (code 0x{code:04x}, axis not known)")
        }
    }
}
