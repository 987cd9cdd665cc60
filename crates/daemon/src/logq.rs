//! Logging off the loop thread: the loop pushes small `Copy` events into a
//! bounded lock-free queue (no allocation, no lock, no I/O); a logging thread
//! pops them and writes them with `tracing`. A full queue drops the event and
//! counts it, never blocks the loop.

use crate::control::Reply;
use crossbeam_queue::ArrayQueue;
use sar_estimator::cycle::CommandEvent;
use sar_estimator::guard::Transition;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Capacity of the queue, events.
pub const CAPACITY: usize = 1024;

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
    /// The drives' state changed (`None`: it could not be read).
    DriveState {
        /// The cycle.
        cycle: u64,
        /// The new state.
        state: Option<sar_drivers::DriveState>,
    },
    /// A cycle ended after the next deadline.
    Overrun {
        /// The cycle.
        cycle: u64,
        /// How late, ns.
        late_ns: u64,
    },
    /// A guarded move was braked: its force reached the limit.
    GuardedStop(crate::step::GuardedStop),
}

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
}

/// Makes the queue (allocated here, once) and, when `spawn`, the thread
/// that writes its events with `tracing`.
pub fn channel(spawn: bool) -> (LogSender, Option<LogThread>, Arc<ArrayQueue<LogEvent>>) {
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
        LogThread { stop, handle }
    });
    (sender, thread, queue)
}

impl LogThread {
    /// Writes what is left and ends the thread.
    pub fn finish(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

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
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Writes one event.
pub fn write(event: &LogEvent) {
    match event {
        LogEvent::Transition(t) => {
            if matches!(
                t.to,
                sar_estimator::guard::GuardState::Stop | sar_estimator::guard::GuardState::Fault
            ) {
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
        LogEvent::Command(c) => match &c.result {
            Ok(a) => tracing::info!("command {:?} accepted: {:?}", c.command, a),
            Err(e) => tracing::warn!("command {:?} refused: {}", c.command, e),
        },
        LogEvent::Reply(r) => tracing::info!(
            id = r.id,
            cycle = r.cycle,
            "request {:?}: {:?}",
            r.request,
            r.status
        ),
        LogEvent::QuickStop { cycle, ok } => {
            if *ok {
                tracing::error!(cycle, "drives told to quick-stop");
            } else {
                tracing::error!(cycle, "drives REFUSED the quick stop");
            }
        }
        LogEvent::DeviceError { cycle, what } => tracing::error!(cycle, "{what} failed"),
        LogEvent::DriveState { cycle, state } => tracing::info!(cycle, "drives: {state:?}"),
        LogEvent::Overrun { cycle, late_ns } => {
            tracing::warn!(cycle, "cycle overran its period by {late_ns} ns")
        }
        LogEvent::GuardedStop(g) => tracing::info!(
            cycle = g.cycle,
            "guarded move braked at tip ({:.4}, {:.4}, {:.4}) m: |F_tip| {:.2} N reached its {} N",
            g.tip_m.x,
            g.tip_m.y,
            g.tip_m.z,
            g.force_n.norm(),
            g.max_force_n
        ),
    }
}
