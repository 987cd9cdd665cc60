//! The publishing thread's side ([`ShmWorker`]): it owns the ports, publishes
//! the states the loop queued, takes the operators' commands to the loop and
//! answers them; the maintenance thread reaps dead clients.

use crate::access::Side;
use crate::error::ShmError;
use crate::node::{clean_dead_nodes_in, node_in};
use crate::ports::{
    CommandRequest, CommandServer, StatePublisher, StateService, fence_at_start, services,
};
use crate::{
    BATCH_WAIT, Names, REAP_PERIOD, RECORD_ANSWER_WAIT, REPLY_WAIT, SarIpc, WORKER_WAIT, access,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use sar_loop::control::{Envelope, Operator, Reply};
use sar_msgs::command::{DaemonCommand, WireCommand};
use sar_msgs::wire::{ReplyMsg, StateMsg, reply_code};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// What the loop side and the publishing thread share.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    /// Set when the daemon side is dropped: the thread publishes what is
    /// queued and ends.
    pub(crate) stop: AtomicBool,
    /// States the thread failed to send (no free sample: should not happen
    /// with the sizes above; counted, never waited for).
    pub(crate) publish_errors: AtomicU64,
    /// States the thread sent.
    pub(crate) published: AtomicU64,
    /// Where `record start|stop` go (unset: refused as unknown).
    pub(crate) record_switch: std::sync::OnceLock<Arc<dyn RecordCommands>>,
    /// The logging thread, woken at each round when the loop queued events.
    pub(crate) log: std::sync::OnceLock<sar_loop::logq::LogWaker>,
    /// Dead processes whose resources the maintenance thread reclaimed.
    pub(crate) reclaimed: AtomicU64,
}

/// The maintenance thread's body: every [`REAP_PERIOD`] until the daemon
/// side is dropped, the resources of the dead processes in `dir` are
/// removed (their ports leave the services: the places they held are free
/// again) and the daemon's own files are fenced
/// ([`access::fence_own_files`]). It is not the publishing thread: a
/// listing that blocks on a member's damaged file (a FIFO for a node's
/// details) stops the reclaiming, never the states or the commands.
pub(crate) fn maintain(
    dir: &Path,
    own_dirs: &[std::path::PathBuf],
    own_files: &[std::path::PathBuf],
    shared: &Shared,
) {
    loop {
        std::thread::park_timeout(REAP_PERIOD);
        if shared.stop.load(Ordering::Acquire) {
            return;
        }
        let cleaned = clean_dead_nodes_in(dir) + access::sweep_half_made_nodes(dir);
        if cleaned > 0 {
            let total = shared
                .reclaimed
                .fetch_add(cleaned as u64, Ordering::Relaxed)
                + cleaned as u64;
            tracing::info!(
                "reclaimed the shared-memory ports and files of {cleaned} dead client process(es) ({total} since the start)"
            );
        }
        access::fence_own_files(dir, own_dirs, own_files);
    }
}

/// Where the commands `record start|stop` go: the recording's switch, wired
/// in by `sard` (the transport knows no recorder). Called on the publishing
/// thread; must not block: the recording's own thread does the file
/// system's work (the checks of a start, the closing of a stop), and the
/// publishing thread asks for its answer at each round and replies once
/// it has one (other commands go on meanwhile).
pub trait RecordCommands: Send + Sync + std::fmt::Debug {
    /// Asks for a recording to start: a ticket for
    /// [`RecordCommands::answer`].
    fn start(&self) -> u64;
    /// Asks for the recording to stop: a ticket for
    /// [`RecordCommands::answer`].
    fn stop(&self) -> u64;
    /// The answer to request `ticket`, once the recorder has acted: the
    /// recording's first file, or why the start was refused or the
    /// recording failed (its file is incomplete).
    fn answer(&self, ticket: u64) -> Option<Result<String, String>>;
}

/// The publishing thread's side: every iceoryx2 port of the daemon. Made and
/// used on one thread (iceoryx2's `ipc` ports are not `Send`): the
/// `sard-shm` thread that [`DaemonShm::create`] starts, or a test's own
/// thread with [`DaemonShm::create_manual`], which then calls
/// [`ShmWorker::pump`] when it likes (deterministic tests).
pub struct ShmWorker {
    pub(crate) node: Node<SarIpc>,
    /// The state's service (how many subscribe).
    pub(crate) state: StateService,
    pub(crate) publisher: StatePublisher,
    pub(crate) notifier: Notifier<SarIpc>,
    /// Notified by the clients (`PREFIX/wake`): a command, a subscriber.
    pub(crate) wake: Listener<SarIpc>,
    pub(crate) server: CommandServer,
    pub(crate) operator: Operator,
    pub(crate) states: rtrb::Consumer<StateMsg>,
    pub(crate) shared: Arc<Shared>,
    /// The command handed to the loop, waiting for its reply.
    pub(crate) in_flight: Option<CommandRequest>,
    /// A `record start|stop` waiting for the recorder's answer: the
    /// request, its ticket and until when it waits.
    pub(crate) record_pending: Option<(CommandRequest, u64, std::time::Instant)>,
    /// The loop's reply, waiting for the state of its cycle.
    pub(crate) waiting: Option<Reply>,
    /// The newest state's cycle.
    pub(crate) last_cycle: u64,
    /// The newest state's limits (the loop may change them), N.
    pub(crate) limits_n: [f64; 6],
}

impl std::fmt::Debug for ShmWorker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmWorker")
            .field("in_flight", &self.in_flight.is_some())
            .field("shared", &self.shared)
            .finish_non_exhaustive()
    }
}

impl ShmWorker {
    /// Cleans dead nodes' resources, then creates the services under
    /// `prefix`; refuses when a living daemon has them.
    pub(crate) fn create(
        dir: &Path,
        prefix: &str,
        operator: Operator,
        limits_n: [f64; 6],
        states: rtrb::Consumer<StateMsg>,
        shared: Arc<Shared>,
    ) -> Result<Self, ShmError> {
        access::prepare(dir, Side::Daemon)?;
        if !access::on_tmpfs(dir) {
            tracing::warn!(
                "{}: not a tmpfs; the shared memory's pages are written back to its disk (systemd's /run is a tmpfs)",
                dir.display()
            );
        }
        let cleaned = clean_dead_nodes_in(dir);
        if cleaned > 0 {
            tracing::info!("removed the shared-memory resources of {cleaned} dead process(es)");
        }
        let names = Names::new(prefix);
        let node = node_in(dir, Side::Daemon)?;
        let (server, (state, publisher), (notifier, wake)) = services(&node, &names, prefix)?;
        fence_at_start(dir, &node);
        Ok(Self {
            node,
            state,
            publisher,
            notifier,
            wake,
            server,
            operator,
            states,
            shared,
            in_flight: None,
            record_pending: None,
            waiting: None,
            last_cycle: 0,
            limits_n,
        })
    }

    /// One round: sends every queued state (then notifies the event once),
    /// sends the replies the loop left, takes at most one command. Never
    /// waits. Returns the states sent.
    pub fn pump(&mut self) -> usize {
        let mut sent = 0;
        while let Ok(mut state) = self.states.pop() {
            // The limits of the newest cycle, for the replies.
            self.limits_n = state.limits_n;
            self.last_cycle = state.cycle;
            state.publish_errors = self.shared.publish_errors.load(Ordering::Relaxed);
            let ok = self
                .publisher
                .loan_uninit()
                .map_err(|_| ())
                .and_then(|s| s.write_payload(state).send().map_err(|_| ()));
            if ok.is_ok() {
                sent += 1;
            } else {
                self.shared.publish_errors.fetch_add(1, Ordering::Relaxed);
            }
        }
        if sent > 0 {
            self.shared
                .published
                .fetch_add(sent as u64, Ordering::Relaxed);
            let _ = self.notifier.notify();
        }
        self.send_replies(false);
        self.answer_record();
        self.take_command();
        sent
    }

    /// Replies to a waiting `record start|stop` once the recorder answered
    /// (or when it did not within [`RECORD_ANSWER_WAIT`]).
    pub(crate) fn answer_record(&mut self) {
        let Some((active, ticket, until)) = self.record_pending.take() else {
            return;
        };
        let answer = self
            .shared
            .record_switch
            .get()
            .and_then(|s| s.answer(ticket));
        let answer = match answer {
            Some(a) => a,
            None if std::time::Instant::now() < until => {
                self.record_pending = Some((active, ticket, until));
                return;
            }
            // Not a refusal: the request may still take effect (the
            // recorder's thread acts on it when it wakes).
            None => Err(format!(
                "the recorder did not answer within {} s: the request may still take effect (see `sarctl status` and the daemon's log)",
                RECORD_ANSWER_WAIT.as_secs()
            )),
        };
        let command = *active.payload();
        let mut reply = ReplyMsg {
            id: command.id,
            cycle: self.last_cycle,
            status: 0,
            reason: 0,
            limits_n: self.limits_n,
            ..ReplyMsg::default()
        };
        match answer {
            Ok(path) => reply.set_detail(&path),
            Err(why) => {
                reply.status = reply_code::RECORD_FAILED;
                reply.set_detail(&why);
            }
        }
        let _ = active.send_copy(reply);
    }

    /// Sends the replies of the commands the loop judged, each after the
    /// state of its cycle (so that it carries the limits that cycle left in
    /// force, and a client that has its reply finds that state published);
    /// `all`: without waiting for the state (at the end).
    pub(crate) fn send_replies(&mut self, all: bool) {
        loop {
            let Some(reply) = self.waiting.take().or_else(|| self.operator.replies.pop()) else {
                return;
            };
            if !all && reply.cycle > self.last_cycle {
                self.waiting = Some(reply);
                return;
            }
            if let Some(active) = self.in_flight.take() {
                let _ = active.send_copy(sar_loop::publish::reply_msg(&reply, self.limits_n));
            }
        }
    }

    /// Takes at most one command and hands it to the loop (answers LIMITS
    /// and unknown kinds at once).
    pub(crate) fn take_command(&mut self) {
        if self.in_flight.is_some() {
            return;
        }
        let Ok(Some(active)) = self.server.receive() else {
            return;
        };
        let command = *active.payload();
        let immediate = |status: u32| ReplyMsg {
            id: command.id,
            cycle: 0,
            status,
            reason: 0,
            limits_n: self.limits_n,
            ..ReplyMsg::default()
        };
        match sar_msgs::command::decode(&command) {
            Ok(WireCommand::Loop(request)) => {
                let env = Envelope {
                    id: command.id,
                    request,
                };
                if self.operator.requests.push(env).is_ok() {
                    self.in_flight = Some(active);
                } else {
                    let _ = active.send_copy(immediate(reply_code::BUSY));
                }
            }
            Ok(WireCommand::Daemon(DaemonCommand::Limits)) => {
                let _ = active.send_copy(immediate(0));
            }
            Ok(WireCommand::Daemon(
                record @ (DaemonCommand::RecordStart | DaemonCommand::RecordStop),
            )) if self.shared.record_switch.get().is_some() => {
                // One at a time; the reply waits for the recorder's answer
                // (the first file, or why not), other commands go on.
                if self.record_pending.is_some() {
                    let _ = active.send_copy(immediate(reply_code::BUSY));
                    return;
                }
                let ticket = self.shared.record_switch.get().map_or(0, |s| {
                    if record == DaemonCommand::RecordStart {
                        s.start()
                    } else {
                        s.stop()
                    }
                });
                self.record_pending = Some((
                    active,
                    ticket,
                    std::time::Instant::now() + RECORD_ANSWER_WAIT,
                ));
            }
            // Recording asked of a daemon without a recorder, or a kind of
            // no command of this build.
            Ok(WireCommand::Daemon(DaemonCommand::RecordStart | DaemonCommand::RecordStop))
            | Err(_) => {
                let _ = active.send_copy(immediate(reply_code::UNKNOWN_COMMAND));
            }
        }
    }

    /// Sleeps until there is work, never woken by the loop (its wake-up
    /// would be a system call on the loop's path):
    /// - a command's reply or a recorder's answer awaited: [`REPLY_WAIT`]
    ///   (the loop answers in its next cycle);
    /// - a subscriber connected: [`BATCH_WAIT`], then the states queued
    ///   meanwhile go out in one batch; a client's wake-up is taken along;
    /// - else until a client notifies `PREFIX/wake` (a command, a new
    ///   subscriber), for at most [`WORKER_WAIT`] (the heartbeat, the states
    ///   queued meanwhile, the fence).
    pub fn sleep(&self) {
        if self.in_flight.is_some() || self.waiting.is_some() || self.record_pending.is_some() {
            std::thread::park_timeout(REPLY_WAIT);
        } else if self.state.dynamic_config().number_of_subscribers() > 0 {
            std::thread::park_timeout(BATCH_WAIT);
            let _ = self.wake.try_wait(|_| {});
        } else {
            let _ = self.wake.timed_wait(|_| {}, WORKER_WAIT);
        }
    }

    /// The thread's body: pumps, then sleeps until there is work
    /// ([`ShmWorker::sleep`]; a stalled loop still gets its LIMITS queries
    /// answered). Ends when the daemon side is dropped, after sending what
    /// is queued.
    pub(crate) fn run(mut self) {
        self.operator.publisher.watch();
        loop {
            // A sign of life per wake-up (at least every WORKER_WAIT): the
            // loop faults when it stops (`Reason::PublisherStalled`).
            self.operator.publisher.beat();
            self.pump();
            if let Some(log) = self.shared.log.get() {
                log.wake_if_pending();
            }
            if self.shared.stop.load(Ordering::Acquire) {
                self.pump();
                self.send_replies(true);
                return;
            }
            self.sleep();
        }
    }
}
