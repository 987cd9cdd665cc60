//! The loop's side ([`DaemonShm`]): a [`Sink`] that hands each cycle's state
//! to the publishing thread through a bounded wait-free queue (no iceoryx2
//! call on the loop's thread), started and stopped with that thread.

use crate::access::runtime_dir;
use crate::error::ShmError;
use crate::node::LIBRARY_START_TIMEOUT;
use crate::worker::{RecordCommands, Shared, ShmWorker, maintain};
use crate::{JOIN_WAIT, START_TIMEOUT, STATE_QUEUE, access};
use sar_loop::control::Operator;
use sar_loop::publish::StateParts;
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_msgs::wire::StateMsg;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// The daemon's loop side: a [`Sink`] of the loop.
///
/// iceoryx2 0.10 allocates on the heap for every sample it loans (an `Rc` of
/// the sample's shared state in `Publisher::loan_uninit`, also behind
/// `send_copy`), for every request a server receives and for every response
/// it sends (and more when a new client connects): none of that may run on
/// the loop thread. So the loop only copies its [`StateMsg`] into a bounded
/// wait-free single-producer single-consumer ring ([`STATE_QUEUE`] entries,
/// allocated here, once); it never wakes the publishing thread (a wake-up
/// is a system call on the loop's path). A full ring drops the state and
/// counts it ([`StateMsg::publish_queue_drops`]). The publishing thread (`sard-shm`,
/// see [`ShmWorker`]) owns every iceoryx2 port and sleeps until it has
/// work ([`ShmWorker::sleep`]): it sends the states in batches, notifies the
/// event, takes operator commands into the controller's bounded request
/// queue and sends the replies the loop leaves in its reply queue. The loop
/// never waits for it.
pub struct DaemonShm {
    pub(crate) states: rtrb::Producer<StateMsg>,
    /// The publishing thread, woken at the end (`None` with a worker driven
    /// by hand).
    pub(crate) wake: Option<std::thread::Thread>,
    pub(crate) thread: Option<std::thread::JoinHandle<()>>,
    /// The maintenance thread (`None` with a worker driven by hand).
    pub(crate) maintenance: Option<std::thread::JoinHandle<()>>,
    pub(crate) shared: Arc<Shared>,
    pub(crate) queue_drops: u64,
    /// The cycle time of the guard's newest transition (`StateMsg::guard_changed_ns`).
    pub(crate) guard_changed_ns: u64,
}

impl std::fmt::Debug for DaemonShm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DaemonShm")
            .field("queue_drops", &self.queue_drops)
            .field("shared", &self.shared)
            .finish_non_exhaustive()
    }
}

/// Waits for the publishing thread's start (`ready`: the node id, or why
/// not) at most `timeout`, returning early when `stop` says so.
pub(crate) fn wait_ready(
    ready: &std::sync::mpsc::Receiver<Result<u128, ShmError>>,
    dir: &Path,
    stop: &dyn Fn() -> bool,
    timeout: Duration,
) -> Result<Result<u128, ShmError>, ShmError> {
    let start = std::time::Instant::now();
    loop {
        match ready.recv_timeout(Duration::from_millis(20)) {
            Ok(r) => return Ok(r),
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Ok(Err(ShmError::Thread {
                    detail: "it ended at start".to_owned(),
                }));
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
        }
        if stop() {
            return Err(ShmError::Stopped);
        }
        if start.elapsed() >= timeout {
            return Err(ShmError::Stuck {
                dir: dir.display().to_string(),
                timeout_ms: timeout.as_millis(),
            });
        }
    }
}

/// Starts the maintenance thread `sard-reap` of the daemon whose node is
/// `node_id` in the runtime directory `dir` ([`maintain`]).
pub(crate) fn spawn_maintenance(
    dir: &Path,
    node_id: u128,
    shared: &Arc<Shared>,
) -> Result<std::thread::JoinHandle<()>, ShmError> {
    let (node_dir, node_files) = access::node_paths(dir, node_id);
    let own_dirs = vec![node_dir, dir.join(access::SERVICES_DIR)];
    let (dir, shared) = (dir.to_owned(), shared.clone());
    std::thread::Builder::new()
        .name("sard-reap".into())
        .spawn(move || maintain(&dir, &own_dirs, &node_files, &shared))
        .map_err(|e| ShmError::Thread {
            detail: format!("cannot start the maintenance thread: {e}"),
        })
}

impl DaemonShm {
    /// Starts the publishing thread `sard-shm`, which cleans dead nodes'
    /// resources and then creates the services under `prefix`; refuses
    /// when a living daemon has them.
    ///
    /// The thread takes the scheduling policy and CPU set of the caller at
    /// this moment: `sard` calls this before the loop thread switches to
    /// SCHED_FIFO and pins itself, so the publishing thread runs at normal
    /// priority and never competes with the loop.
    pub fn create(prefix: &str, operator: Operator, limits_n: [f64; 6]) -> Result<Self, ShmError> {
        Self::start(
            &runtime_dir()?,
            prefix,
            operator,
            limits_n,
            &|| false,
            LIBRARY_START_TIMEOUT,
        )
    }

    /// [`DaemonShm::create`] in the runtime directory `dir`. Waits at most
    /// [`START_TIMEOUT`] for iceoryx2 and returns early when `stop` says so
    /// (a SIGTERM during the start): a thread stuck in iceoryx2 is left
    /// behind, and ends with the process.
    pub fn create_in(
        dir: &Path,
        prefix: &str,
        operator: Operator,
        limits_n: [f64; 6],
        stop: &dyn Fn() -> bool,
    ) -> Result<Self, ShmError> {
        Self::start(dir, prefix, operator, limits_n, stop, START_TIMEOUT)
    }

    pub(crate) fn start(
        dir: &Path,
        prefix: &str,
        operator: Operator,
        limits_n: [f64; 6],
        stop: &dyn Fn() -> bool,
        timeout: Duration,
    ) -> Result<Self, ShmError> {
        let (producer, consumer) = rtrb::RingBuffer::new(STATE_QUEUE);
        let shared = Arc::new(Shared::default());
        // The worker's node id once it is made (for the maintenance thread).
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<u128, ShmError>>(1);
        let thread = {
            let (dir, prefix, shared) = (dir.to_owned(), prefix.to_owned(), shared.clone());
            std::thread::Builder::new()
                .name("sard-shm".into())
                .spawn(move || {
                    match ShmWorker::create(&dir, &prefix, operator, limits_n, consumer, shared) {
                        Ok(worker) => {
                            if ready_tx.send(Ok(worker.node.id().value())).is_ok() {
                                worker.run();
                            }
                        }
                        Err(e) => {
                            let _ = ready_tx.send(Err(e));
                        }
                    }
                })
                .map_err(|e| ShmError::Thread {
                    detail: format!("cannot start it: {e}"),
                })?
        };
        // On a timeout or a stop, the thread (stuck in iceoryx2) is left
        // behind: it ends with the process.
        let started = wait_ready(&ready_rx, dir, stop, timeout)?;
        let node_id = match started {
            Ok(id) => id,
            Err(e) => {
                let _ = sar_hal::join::join_within(thread, JOIN_WAIT);
                return Err(e);
            }
        };
        let maintenance = spawn_maintenance(dir, node_id, &shared);
        let maintenance = match maintenance {
            Ok(t) => t,
            Err(e) => {
                shared.stop.store(true, Ordering::Release);
                thread.thread().unpark();
                let _ = sar_hal::join::join_within(thread, JOIN_WAIT);
                return Err(e);
            }
        };
        Ok(Self {
            states: producer,
            wake: Some(thread.thread().clone()),
            thread: Some(thread),
            maintenance: Some(maintenance),
            shared,
            queue_drops: 0,
            guard_changed_ns: 0,
        })
    }

    /// As [`DaemonShm::create`] but without a thread: the caller drives the
    /// returned worker on its own thread ([`ShmWorker::pump`]). For
    /// deterministic tests and benchmarks.
    pub fn create_manual(
        prefix: &str,
        operator: Operator,
        limits_n: [f64; 6],
    ) -> Result<(Self, ShmWorker), ShmError> {
        let (producer, consumer) = rtrb::RingBuffer::new(STATE_QUEUE);
        let shared = Arc::new(Shared::default());
        let worker = ShmWorker::create(
            &runtime_dir()?,
            prefix,
            operator,
            limits_n,
            consumer,
            shared.clone(),
        )?;
        Ok((
            Self {
                states: producer,
                wake: None,
                thread: None,
                maintenance: None,
                shared,
                queue_drops: 0,
                guard_changed_ns: 0,
            },
            worker,
        ))
    }

    /// Takes `record start|stop` commands into `switch` (on the publishing
    /// thread; the loop and the recording's manager thread act on it).
    pub fn with_record_commands(self, switch: Arc<dyn RecordCommands>) -> Self {
        let _ = self.shared.record_switch.set(switch);
        self
    }

    /// Wakes the logging thread of `log` at each round that finds events in
    /// its queue (the logging thread then sleeps until there are some).
    pub fn wake_log(&self, log: sar_loop::logq::LogWaker) {
        let _ = self.shared.log.set(log);
    }

    /// States the publishing thread failed to send so far.
    pub fn publish_errors(&self) -> u64 {
        self.shared.publish_errors.load(Ordering::Relaxed)
    }

    /// States the publishing thread sent so far.
    pub fn published(&self) -> u64 {
        self.shared.published.load(Ordering::Relaxed)
    }

    /// States dropped so far because the publishing thread's queue was full.
    pub fn publish_queue_drops(&self) -> u64 {
        self.queue_drops
    }

    /// Queues one state for the publishing thread (which takes it at its
    /// next wake-up: [`ShmWorker::sleep`]); a full queue drops the state and
    /// counts it. Wait-free, allocation-free, no system call.
    pub fn push_state(&mut self, state: StateMsg) {
        if self.states.push(state).is_err() {
            self.queue_drops = self.queue_drops.saturating_add(1);
        }
    }
}

impl Drop for DaemonShm {
    /// Stops the publishing thread (it sends what is queued first) and the
    /// maintenance thread, waiting for each at most [`JOIN_WAIT`]: a thread
    /// stuck in iceoryx2 (a damaged file, a page of a truncated file) is
    /// left behind and named (`sar_hal::join::left_behind`), never
    /// waited for without bound.
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = &self.wake {
            t.unpark();
        }
        if let Some(t) = self.thread.take() {
            let _ = sar_hal::join::join_within(t, JOIN_WAIT);
        }
        if let Some(t) = self.maintenance.take() {
            t.thread().unpark();
            let _ = sar_hal::join::join_within(t, JOIN_WAIT);
        }
    }
}

impl Sink for DaemonShm {
    fn cycle(&mut self, c: &Cycle<'_>, health: &mut SinkHealth) {
        // The limits in use (an operator may have changed them this cycle)
        // travel in the state to the publishing thread, for its replies.
        let mut state = sar_loop::publish::state_msg(&StateParts {
            input: c.loop_input,
            decision: c.decision,
            stats: c.stats,
            quick_stops: c.quick_stops,
            recorder_drops: health.recorder_drops,
            recording: health.recording,
            truth: c.truth,
            sensor_samples: c.sensor_samples,
        });
        state.publish_queue_drops = self.queue_drops;
        if state.flags & sar_msgs::wire::flags::TRANSITION != 0 {
            self.guard_changed_ns = state.now_ns;
        }
        state.guard_changed_ns = self.guard_changed_ns;
        self.push_state(state);
        health.publish_queue_drops = self.queue_drops;
    }
}
