//! iceoryx2 (0.10) shared memory between `sard` and its clients.
//!
//! Services, under a prefix (default [`DEFAULT_PREFIX`]; tests use unique
//! ones so that they run in parallel):
//! - `PREFIX/state`: publish-subscribe of [`StateMsg`], once per cycle. One
//!   publisher (the daemon), safe overflow and a discarding backpressure
//!   strategy (a slow or dead subscriber loses its oldest samples; nothing
//!   waits for it), subscriber buffer [`STATE_BUFFER`], borrowed samples
//!   [`STATE_BORROWED`], history [`STATE_HISTORY`].
//! - `PREFIX/state_event`: an event notified after each batch of states, so
//!   that a subscriber blocks on its listener instead of spinning.
//! - `PREFIX/wake`: an event the clients notify after they send a command or
//!   subscribe, so that the publishing thread sleeps until there is work
//!   (one listener: the daemon).
//! - `PREFIX/command`: request-response of [`CommandMsg`] to [`ReplyMsg`]
//!   (reset, tare, move-tip, limits). The loop takes at most one command per
//!   cycle and replies from the cycle that judged it.
//!
//! No iceoryx2 call runs on the loop thread (iceoryx2 allocates per sample
//! and per request): the loop hands each cycle's state to the publishing
//! thread through a bounded wait-free queue ([`DaemonShm`]); that thread owns
//! the ports ([`ShmWorker`]).
//!
//! At start the daemon removes the stale resources of dead nodes (a daemon
//! or client killed with SIGKILL) and then creates the services; when they
//! exist (a living daemon with the same prefix), it refuses to start.
//!
//! Every file lives in the runtime directory ([`access`]: `/run/sar` or
//! `SAR_RUNTIME_DIR`), never in `/dev/shm` or `/tmp` ([`SarIpc`]): the
//! daemon's user and its group (the operators) may enter it, nobody else.
//! The checks of [`access`] run before iceoryx2 is called, so a client
//! without the right fails at once with the user and the group named, and a
//! damaged management file is named instead of spun on.

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;

pub mod access;
mod service;
pub use access::{DEFAULT_RUNTIME_DIR, RUNTIME_DIR_ENV, Side, runtime_dir};
use sar_loop::control::{Envelope, Operator, Reply};
use sar_loop::publish::StateParts;
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_msgs::wire::{CommandMsg, ReplyMsg, StateMsg, reply_code};
pub use service::Service as SarIpc;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// The default service prefix.
pub const DEFAULT_PREFIX: &str = "sar";
/// Samples a state subscriber buffers.
pub const STATE_BUFFER: usize = 64;
/// Samples a new subscriber may get from the history.
pub const STATE_HISTORY: usize = 1;
/// Subscribers of the state at most (`status`, `monitor`, `view`,
/// `retreat`, `identify --live`, each one while it runs). An operator's
/// station runs a few; a suspended (Ctrl-Z) or hung one keeps its place
/// until it ends, so the limit is far above real use (16 `monitor`s used to
/// lock out `status`): 64, for 2.3 MB of the publisher's segment (36 KB a
/// subscriber) and a cost only for those connected.
pub const MAX_SUBSCRIBERS: usize = 64;
/// Command clients at most (each `sarctl` command while it waits for its
/// answer, at most 2 s; a suspended one keeps its place until it ends: 8
/// suspended commands used to lock out the reset after a Stop).
pub const MAX_CLIENTS: usize = 64;
/// Processes (iceoryx2 nodes) that may have one of the daemon's services
/// open at once: every client and subscriber, and the daemon (iceoryx2's
/// default, 20, made `status` say "no daemon runs" beside 20-30 suspended
/// clients).
pub const MAX_NODES: usize = MAX_CLIENTS + MAX_SUBSCRIBERS + 1;
/// Samples a state subscriber may hold at once (borrowed, not yet released).
pub const STATE_BORROWED: usize = 2;
/// States queued from the loop to the publishing thread at most (cycles of
/// slack: 256 ms at 1 kHz); beyond, the loop drops and counts.
pub const STATE_QUEUE: usize = 256;
/// The publishing thread's longest sleep when nobody subscribes and no
/// client wakes it (`PREFIX/wake`): its heartbeat's period then (the loop
/// faults after 500 ms of silence), and the states it sends in one batch
/// (far below [`STATE_QUEUE`]).
pub const WORKER_WAIT: Duration = Duration::from_millis(20);
/// The publishing thread's sleep while a subscriber is connected: the states
/// go out in batches of this period (the loop never wakes the thread), the
/// most a live view's state waits.
pub const BATCH_WAIT: Duration = Duration::from_millis(4);
/// The publishing thread's sleep while a command's reply (the loop answers
/// in its next cycle) or a recorder's answer is awaited.
pub const REPLY_WAIT: Duration = Duration::from_millis(1);

/// The service names under `prefix`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Names {
    /// State publish-subscribe.
    pub state: String,
    /// State event.
    pub event: String,
    /// Commands.
    pub command: String,
    /// The clients' wake-up of the publishing thread.
    pub wake: String,
}

impl Names {
    /// The names under `prefix`.
    pub fn new(prefix: &str) -> Self {
        Self {
            state: format!("{prefix}/state"),
            event: format!("{prefix}/state_event"),
            command: format!("{prefix}/command"),
            wake: format!("{prefix}/wake"),
        }
    }
}

/// Why the transport failed (every error a caller of this crate sees).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShmError {
    /// The prefix makes a name iceoryx2 refuses.
    #[error("bad service name {name:?}: {detail}")]
    ServiceName {
        /// The name.
        name: String,
        /// iceoryx2's reason.
        detail: String,
    },
    /// An iceoryx2 port or node could not be made, or a command not sent.
    #[error("{what}: {detail}")]
    Port {
        /// What was being done.
        what: &'static str,
        /// iceoryx2's reason.
        detail: String,
    },
    /// The daemon's service exists: another daemon runs with the prefix.
    #[error(
        "cannot create the service {service:?} ({detail}): another sard runs with the prefix {prefix:?}"
    )]
    DaemonRuns {
        /// The prefix.
        prefix: String,
        /// The service that exists.
        service: String,
        /// iceoryx2's reason.
        detail: String,
    },
    /// A client found no daemon's service.
    #[error("no daemon runs (cannot open the service {service:?}: {detail})")]
    NoDaemon {
        /// The service that is missing.
        service: String,
        /// iceoryx2's reason.
        detail: String,
    },
    /// The daemon did not reply in time.
    #[error("no reply from the daemon within {timeout_ms} ms")]
    NoReply {
        /// How long the client waited, ms.
        timeout_ms: u128,
    },
    /// Every place of a service is taken (by clients that run, are
    /// suspended or hang: each keeps its place until it ends).
    #[error(
        "{count} {what} are connected to the daemon; the limit is {limit} (a suspended or hung sarctl keeps its place until it ends: end it, `jobs` and `kill %N` in its shell)"
    )]
    Full {
        /// What is counted: "clients", "subscribers", "processes", ...
        what: &'static str,
        /// How many are connected.
        count: usize,
        /// The limit.
        limit: usize,
    },
    /// `SAR_RUNTIME_DIR` is set to something unusable.
    #[error("{detail}")]
    RuntimeDirEnv {
        /// What is wrong with it.
        detail: String,
    },
    /// A client found no runtime directory: no daemon runs there.
    #[error(
        "no daemon runs: the runtime directory {dir} does not exist (sard creates it; SAR_RUNTIME_DIR names another)"
    )]
    NoRuntimeDir {
        /// The directory.
        dir: String,
    },
    /// The runtime directory cannot be used (missing parent, not a
    /// directory, another user's).
    #[error("the runtime directory {dir}: {detail}")]
    RuntimeDir {
        /// The directory.
        dir: String,
        /// Why.
        detail: String,
    },
    /// This process may not use the runtime directory.
    #[error("permission denied: {detail}")]
    PermissionDenied {
        /// Who, and what is missing.
        detail: String,
    },
    /// A management file of iceoryx2 is damaged.
    #[error(
        "the shared-memory management file {path} is damaged ({detail}): stop every sard and sarctl of it and remove it"
    )]
    Damaged {
        /// The file.
        path: String,
        /// What is wrong.
        detail: String,
    },
    /// iceoryx2 did not finish creating the daemon's node and services in
    /// time (a damaged file it spins on).
    #[error(
        "iceoryx2 did not create the services within {timeout_ms} ms (a damaged file in the runtime directory {dir}?)"
    )]
    Stuck {
        /// The runtime directory.
        dir: String,
        /// How long sard waited, ms.
        timeout_ms: u128,
    },
    /// The daemon was asked to stop while it was starting.
    #[error("stopped while creating the services")]
    Stopped,
    /// The publishing thread could not be started, or ended at start.
    #[error("the publishing thread: {detail}")]
    Thread {
        /// Why.
        detail: String,
    },
}

fn port(what: &'static str, e: impl std::fmt::Debug) -> ShmError {
    ShmError::Port {
        what,
        detail: format!("{e:?}"),
    }
}

fn service_name(name: &str) -> Result<ServiceName, ShmError> {
    ServiceName::new(name).map_err(|e| ShmError::ServiceName {
        name: name.to_owned(),
        detail: format!("{e:?}"),
    })
}

/// How long a daemon's iceoryx2 call waits for a resource another process
/// is still initialising (a new subscriber's connection, a client's request
/// segment), at most: the publishing thread must never wait long for a
/// client (its stall faults the loop after 500 ms; finding 1). A resource
/// not ready in time is not connected (that client gets nothing).
pub const DAEMON_CREATION_TIMEOUT: Duration = Duration::from_millis(100);
/// The same for a client.
pub const CLIENT_CREATION_TIMEOUT: Duration = Duration::from_millis(500);
/// How long `sard` waits for iceoryx2 to create its node and services (a
/// few milliseconds when healthy; a margin for a loaded machine).
pub const START_TIMEOUT: Duration = Duration::from_secs(2);
/// The same for [`DaemonShm::create`] (tests and benchmarks, many at once on
/// a loaded machine).
const LIBRARY_START_TIMEOUT: Duration = Duration::from_secs(30);

/// iceoryx2's configuration for the runtime directory `dir` (never a file
/// iceoryx2 would look for: the defaults, with the root path in `dir`).
pub fn config(dir: &Path, side: Side) -> Result<Config, ShmError> {
    let mut config = Config::default();
    let root = iceoryx2::prelude::Path::new(dir.as_os_str().as_encoded_bytes()).map_err(|e| {
        ShmError::RuntimeDir {
            dir: dir.display().to_string(),
            detail: format!("iceoryx2 refuses the path: {e:?}"),
        }
    })?;
    config.global.set_root_path(&root);
    config.global.creation_timeout = match side {
        Side::Daemon => DAEMON_CREATION_TIMEOUT,
        Side::Client => CLIENT_CREATION_TIMEOUT,
    };
    if side == Side::Client {
        // Only the daemon removes dead nodes' resources (at its start and
        // every [`REAP_PERIOD`] while it runs): a client never lists every
        // node (one damaged, e.g. a details file that is a FIFO, would
        // block it) and never cleans a dead node, not even the dead owners
        // of a service it opens (iceoryx2's default). A client killed in
        // the middle of cleaning left the dead node it cleaned half done
        // for good (its ports kept their places: after about 12,500 kills
        // of `sarctl monitor`, no subscriber could connect), and a member
        // may not remove the daemon's files (the directory is sticky).
        config.global.node.cleanup_dead_nodes_on_creation = false;
        config.global.node.cleanup_dead_nodes_on_destruction = false;
        config.global.service.cleanup_dead_nodes_on_open = false;
    }
    Ok(config)
}

/// iceoryx2's own log (e.g. "no config file was loaded") only for errors:
/// what a command-line tool sets before it talks to the daemon.
pub fn log_errors_only() {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
}

/// A node in the runtime directory `dir` (checked first, [`access`]),
/// without iceoryx2's own signal handlers (the daemon has its own).
pub fn node_in(dir: &Path, side: Side) -> Result<Node<SarIpc>, ShmError> {
    access::prepare(dir, side)?;
    let config = config(dir, side)?;
    NodeBuilder::new()
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<SarIpc>()
        .map_err(|e| {
            // The management file may have been damaged since it was
            // checked (a member swapped a FIFO in): named, not guessed.
            if let Err(damaged @ ShmError::Damaged { .. }) = access::check_mgmt(dir) {
                return damaged;
            }
            ShmError::Port {
                what: "cannot create the iceoryx2 node",
                detail: format!(
                    "{e:?} (a damaged file in the runtime directory {}? its management file is {})",
                    dir.display(),
                    dir.join(access::GLOBAL_MGMT_FILE).display()
                ),
            }
        })
}

/// A client's node in the runtime directory [`runtime_dir`].
pub fn node() -> Result<Node<SarIpc>, ShmError> {
    node_in(&runtime_dir()?, Side::Client)
}

/// Removes the resources of dead nodes in the runtime directory `dir`;
/// returns how many were cleaned.
pub fn clean_dead_nodes_in(dir: &Path) -> usize {
    let Ok(config) = config(dir, Side::Daemon) else {
        return 0;
    };
    let mut cleaned = 0;
    let _ = Node::<SarIpc>::list(&config, |state| {
        if let NodeState::Dead(view) = state {
            use iceoryx2::node::NodeView;
            let done = match view.details() {
                Some(_) => view.try_remove_stale_resources(),
                // A node whose details file is gone (its process died while
                // making it, or a cleaning was cut after removing it):
                // iceoryx2 would clean it in its default directory
                // (`/tmp/iceoryx2`), never here; it is cleaned with this
                // directory's configuration (iceoryx2 0.10's hidden entry
                // for that, pinned with the crate).
                None => {
                    iceoryx2::node::DeadNodeView::<SarIpc>::__internal_try_remove_stale_resources(
                        *view.id(),
                        iceoryx2::node::NodeDetails::__internal_new(&None, &config),
                    )
                }
            };
            if done.is_ok() {
                cleaned += 1;
            }
        }
        CallbackProgression::Continue
    });
    cleaned
}

/// [`clean_dead_nodes_in`] the runtime directory [`runtime_dir`] (0 when
/// it cannot be named).
pub fn clean_dead_nodes() -> usize {
    runtime_dir().map_or(0, |d| clean_dead_nodes_in(&d))
}

type StatePublisher = Publisher<SarIpc, StateMsg, ()>;
type StateService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<SarIpc, StateMsg, ()>;
type CommandServer = Server<SarIpc, CommandMsg, (), ReplyMsg, ()>;
type CommandRequest = ActiveRequest<SarIpc, CommandMsg, (), ReplyMsg, ()>;

/// What the loop side and the publishing thread share.
#[derive(Debug, Default)]
struct Shared {
    /// Set when the daemon side is dropped: the thread publishes what is
    /// queued and ends.
    stop: AtomicBool,
    /// States the thread failed to send (no free sample: should not happen
    /// with the sizes above; counted, never waited for).
    publish_errors: AtomicU64,
    /// States the thread sent.
    published: AtomicU64,
    /// Where `record start|stop` go (unset: refused as unknown).
    record_switch: std::sync::OnceLock<Arc<dyn RecordCommands>>,
    /// The logging thread, woken at each round when the loop queued events.
    log: std::sync::OnceLock<sar_loop::logq::LogWaker>,
    /// Dead processes whose resources the maintenance thread reclaimed.
    reclaimed: AtomicU64,
}

/// How often the daemon's maintenance thread (`sard-reap`) reclaims the
/// ports and files of dead clients (killed with SIGKILL, crashed) and takes
/// other users' access away from the daemon's newest files.
pub const REAP_PERIOD: Duration = Duration::from_secs(1);
/// How long dropping the daemon's side waits for each of its threads (the
/// publishing thread, the maintenance thread) at most, then leaves it
/// behind (`sar_hal::join::left_behind` names it).
pub const JOIN_WAIT: Duration = Duration::from_millis(700);

/// The maintenance thread's body: every [`REAP_PERIOD`] until the daemon
/// side is dropped, the resources of the dead processes in `dir` are
/// removed (their ports leave the services: the places they held are free
/// again) and the daemon's own files are fenced
/// ([`access::fence_own_files`]). It is not the publishing thread: a
/// listing that blocks on a member's damaged file (a FIFO for a node's
/// details) stops the reclaiming, never the states or the commands.
fn maintain(
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

/// How long a `record start|stop` waits for the recorder's answer (closing
/// a file syncs it to disk) before the reply says it did not come.
pub const RECORD_ANSWER_WAIT: Duration = Duration::from_secs(8);

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
    states: rtrb::Producer<StateMsg>,
    /// The publishing thread, woken at the end (`None` with a worker driven
    /// by hand).
    wake: Option<std::thread::Thread>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// The maintenance thread (`None` with a worker driven by hand).
    maintenance: Option<std::thread::JoinHandle<()>>,
    shared: Arc<Shared>,
    queue_drops: u64,
    /// The cycle time of the guard's newest transition (`StateMsg::guard_changed_ns`).
    guard_changed_ns: u64,
}

impl std::fmt::Debug for DaemonShm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DaemonShm")
            .field("queue_drops", &self.queue_drops)
            .field("shared", &self.shared)
            .finish_non_exhaustive()
    }
}

/// The publishing thread's side: every iceoryx2 port of the daemon. Made and
/// used on one thread (iceoryx2's `ipc` ports are not `Send`): the
/// `sard-shm` thread that [`DaemonShm::create`] starts, or a test's own
/// thread with [`DaemonShm::create_manual`], which then calls
/// [`ShmWorker::pump`] when it likes (deterministic tests).
pub struct ShmWorker {
    node: Node<SarIpc>,
    /// The state's service (how many subscribe).
    state: StateService,
    publisher: StatePublisher,
    notifier: Notifier<SarIpc>,
    /// Notified by the clients (`PREFIX/wake`): a command, a subscriber.
    wake: Listener<SarIpc>,
    server: CommandServer,
    operator: Operator,
    states: rtrb::Consumer<StateMsg>,
    shared: Arc<Shared>,
    /// The command handed to the loop, waiting for its reply.
    in_flight: Option<CommandRequest>,
    /// A `record start|stop` waiting for the recorder's answer: the
    /// request, its ticket and until when it waits.
    record_pending: Option<(CommandRequest, u64, std::time::Instant)>,
    /// The loop's reply, waiting for the state of its cycle.
    waiting: Option<Reply>,
    /// The newest state's cycle.
    last_cycle: u64,
    /// The newest state's limits (the loop may change them), N.
    limits_n: [f64; 6],
}

impl std::fmt::Debug for ShmWorker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ShmWorker")
            .field("in_flight", &self.in_flight.is_some())
            .field("shared", &self.shared)
            .finish_non_exhaustive()
    }
}

fn exists(prefix: &str, service: &str, e: impl std::fmt::Debug) -> ShmError {
    ShmError::DaemonRuns {
        prefix: prefix.to_owned(),
        service: service.to_owned(),
        detail: format!("{e:?}"),
    }
}

/// The command service (request-response) and its one server.
fn command_server(
    node: &Node<SarIpc>,
    names: &Names,
    prefix: &str,
) -> Result<CommandServer, ShmError> {
    node.service_builder(&service_name(&names.command)?)
        .request_response::<CommandMsg, ReplyMsg>()
        .max_servers(1)
        .max_clients(MAX_CLIENTS)
        .max_nodes(MAX_NODES)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1)
        .enable_safe_overflow_for_requests(true)
        .enable_safe_overflow_for_responses(true)
        .create()
        .map_err(|e| exists(prefix, &names.command, e))?
        .server_builder()
        .create()
        .map_err(|e| port("cannot create the command server", e))
}

/// The state's service (publish-subscribe) and its one publisher.
fn state_publisher(
    node: &Node<SarIpc>,
    names: &Names,
    prefix: &str,
) -> Result<(StateService, StatePublisher), ShmError> {
    let state = node
        .service_builder(&service_name(&names.state)?)
        .publish_subscribe::<StateMsg>()
        .max_publishers(1)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .subscriber_max_buffer_size(STATE_BUFFER)
        .subscriber_max_borrowed_samples(STATE_BORROWED)
        .history_size(STATE_HISTORY)
        .enable_safe_overflow(true)
        .create()
        .map_err(|e| exists(prefix, &names.state, e))?;
    let publisher = state
        .publisher_builder()
        .max_loaned_samples(1)
        // Never retry towards a full subscriber (with safe overflow its
        // oldest sample is replaced anyway).
        .backpressure_strategy(BackpressureStrategy::DiscardData)
        .create()
        .map_err(|e| port("cannot create the state publisher", e))?;
    Ok((state, publisher))
}

/// The state event's notifier (the daemon tells the subscribers) and the
/// wake-up's listener (the clients tell the daemon).
fn events(
    node: &Node<SarIpc>,
    names: &Names,
    prefix: &str,
) -> Result<(Notifier<SarIpc>, Listener<SarIpc>), ShmError> {
    let notifier = node
        .service_builder(&service_name(&names.event)?)
        .event()
        .max_notifiers(1)
        .max_listeners(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .create()
        .map_err(|e| exists(prefix, &names.event, e))?
        .notifier_builder()
        .create()
        .map_err(|e| port("cannot create the state notifier", e))?;
    let wake = node
        .service_builder(&service_name(&names.wake)?)
        .event()
        .max_notifiers(MAX_CLIENTS + MAX_SUBSCRIBERS)
        .max_listeners(1)
        .max_nodes(MAX_NODES)
        .create()
        .map_err(|e| exists(prefix, &names.wake, e))?
        .listener_builder()
        .create()
        .map_err(|e| port("cannot create the wake-up listener", e))?;
    Ok((notifier, wake))
}

/// How long a starting daemon waits for the clients of a daemon that is
/// gone to let go of its services (a client lets go at once when it finds
/// no living daemon's port in a service it opens; one that had it open
/// before lets go at its deadline, 2 s at most for a command or `status`:
/// then the start is refused, naming the cause, and systemd's next start
/// a second later succeeds). Well within [`START_TIMEOUT`].
pub const ORPHAN_WAIT: Duration = Duration::from_secs(1);

/// The services under `names` that exist with no daemon's port (no
/// publisher, server, notifier or wake-up listener): a killed daemon's,
/// kept by the clients that still have them open (its dead ports were
/// cleaned; a service goes once no process has it open). Each is opened
/// and let go of: the last process to let go removes it (iceoryx2 removes
/// a service nobody has open), so once its clients are gone it is gone.
/// Returns how many there were.
fn release_orphaned_services(node: &Node<SarIpc>, names: &Names) -> usize {
    let orphaned = |name: &str, pattern: MessagingPattern| -> bool {
        let Ok(service) = service_name(name) else {
            return false;
        };
        let builder = node.service_builder(&service);
        let opened = |e: &dyn std::fmt::Debug| {
            let e = format!("{e:?}");
            if e == "IsMarkedForDestruction" || e == "ServiceInCorruptedState" {
                // Its last client let go but could not remove the daemon's
                // files (a member may not: the directory is sticky): the
                // daemon, their owner, removes them.
                // SAFETY (iceoryx2's contract: no other process uses it):
                // a service marked for destruction has no owner left.
                #[allow(unsafe_code)]
                let removed = unsafe { node.force_remove_service(&service, pattern) };
                if removed.is_ok_and(|r| r) {
                    tracing::info!("removed the service {name:?} of a sard that is gone");
                    return Ok(0);
                }
            }
            Err(())
        };
        let daemon_ports = match pattern {
            MessagingPattern::PublishSubscribe => {
                builder.publish_subscribe::<StateMsg>().open().map_or_else(
                    |e| opened(&e),
                    |s| Ok(s.dynamic_config().number_of_publishers()),
                )
            }
            MessagingPattern::RequestResponse => builder
                .request_response::<CommandMsg, ReplyMsg>()
                .open()
                .map_or_else(
                    |e| opened(&e),
                    |s| Ok(s.dynamic_config().number_of_servers()),
                ),
            _ if name == names.wake => builder.event().open().map_or_else(
                |e| opened(&e),
                |s| Ok(s.dynamic_config().number_of_listeners()),
            ),
            _ => builder.event().open().map_or_else(
                |e| opened(&e),
                |s| Ok(s.dynamic_config().number_of_notifiers()),
            ),
        };
        daemon_ports == Ok(0)
    };
    [
        (&names.command, MessagingPattern::RequestResponse),
        (&names.state, MessagingPattern::PublishSubscribe),
        (&names.event, MessagingPattern::Event),
        (&names.wake, MessagingPattern::Event),
    ]
    .into_iter()
    .filter(|(name, pattern)| orphaned(name, *pattern))
    .count()
}

/// Every port of the daemon's services under `names`: the command server
/// first (a client that finds the state finds the command server too), the
/// state's publisher, the events. The services of a daemon that is gone,
/// which its clients still have open, go as they let go: waited for up to
/// [`ORPHAN_WAIT`], then "another sard runs" with the cause.
type DaemonPorts = (
    CommandServer,
    (StateService, StatePublisher),
    (Notifier<SarIpc>, Listener<SarIpc>),
);

fn services(node: &Node<SarIpc>, names: &Names, prefix: &str) -> Result<DaemonPorts, ShmError> {
    let start = std::time::Instant::now();
    loop {
        let made = command_server(node, names, prefix).and_then(|server| {
            let state = state_publisher(node, names, prefix)?;
            Ok((server, state, events(node, names, prefix)?))
        });
        match made {
            Err(ShmError::DaemonRuns { .. }) if start.elapsed() < ORPHAN_WAIT => {
                if release_orphaned_services(node, names) == 0 {
                    // A living daemon's: refused at once.
                    return made;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(ShmError::DaemonRuns {
                prefix,
                service,
                detail,
            }) if release_orphaned_services(node, names) > 0 => {
                return Err(ShmError::DaemonRuns {
                    prefix,
                    service,
                    detail: format!(
                        "{detail}; no sard serves it: a client of a sard that is gone still has it open after {} ms (end it)",
                        ORPHAN_WAIT.as_millis()
                    ),
                });
            }
            made => return made,
        }
    }
}

/// The daemon's files once its services are made: its node directory the
/// group's to read only (its tags are made; nobody else adds or removes
/// one), and every file fenced ([`access::fence_own_files`]: as every later
/// one, from the maintenance thread).
fn fence_at_start(dir: &Path, node: &Node<SarIpc>) {
    let (node_dir, node_files) = access::node_paths(dir, node.id().value());
    if let Err(e) = std::fs::set_permissions(
        &node_dir,
        std::os::unix::fs::PermissionsExt::from_mode(access::OWN_NODE_DIR_MODE),
    ) {
        tracing::warn!("{}: cannot set its mode: {e}", node_dir.display());
    }
    access::fence_own_files(
        dir,
        &[node_dir, dir.join(access::SERVICES_DIR)],
        &node_files,
    );
}

impl ShmWorker {
    /// Cleans dead nodes' resources, then creates the services under
    /// `prefix`; refuses when a living daemon has them.
    fn create(
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
    fn answer_record(&mut self) {
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
    fn send_replies(&mut self, all: bool) {
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
    fn take_command(&mut self) {
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
        use sar_msgs::command::{DaemonCommand, WireCommand};
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
    fn run(mut self) {
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

/// Waits for the publishing thread's start (`ready`: the node id, or why
/// not) at most `timeout`, returning early when `stop` says so.
fn wait_ready(
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
fn spawn_maintenance(
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

    fn start(
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

/// Why a client could not open a service: "no daemon runs" only when it
/// does not exist (or is being removed); every place taken names the
/// limit; another message type names the likely cause (`sarctl` and `sard`
/// from different builds); anything else says what failed.
fn open_error(service: &str, e: impl std::fmt::Debug) -> ShmError {
    let name = format!("{e:?}");
    match name.as_str() {
        "DoesNotExist" | "IsMarkedForDestruction" => ShmError::NoDaemon {
            service: service.to_owned(),
            detail: name,
        },
        // Every place taken: the open itself failed, so the places are
        // all taken (the count is the limit).
        "ExceedsMaxNumberOfNodes" => ShmError::Full {
            what: "processes",
            count: MAX_NODES,
            limit: MAX_NODES,
        },
        n if n.starts_with("Incompatible") => ShmError::Port {
            what: "the daemon's service carries another message type: sarctl and sard are from different builds (install both from one build)",
            detail: format!("{service}: {name}"),
        },
        _ => ShmError::Port {
            what: "cannot open the daemon's service",
            detail: format!("{service}: {name}"),
        },
    }
}

/// A client's side: subscribes to the state, sends commands.
#[derive(Debug)]
pub struct Client {
    dir: std::path::PathBuf,
    /// Made at the first call when the runtime directory did not exist yet.
    node: std::cell::OnceCell<Node<SarIpc>>,
    names: Names,
}

/// Why a client call failed.
pub type ClientError = ShmError;

impl Client {
    /// A client for the daemon with `prefix` in the runtime directory
    /// [`runtime_dir`].
    pub fn new(prefix: &str) -> Result<Self, ClientError> {
        Self::in_dir(&runtime_dir()?, prefix)
    }

    /// A client for the daemon with `prefix` in the runtime directory `dir`:
    /// refused at once, naming the user and the group, when this process
    /// may not use the directory; never creates it.
    pub fn in_dir(dir: &Path, prefix: &str) -> Result<Self, ClientError> {
        let node = std::cell::OnceCell::new();
        match node_in(dir, Side::Client) {
            Ok(n) => {
                let _ = node.set(n);
            }
            // No daemon yet: the first call tries again.
            Err(ShmError::NoRuntimeDir { .. }) => {}
            Err(e) => return Err(e),
        }
        Ok(Self {
            dir: dir.to_owned(),
            node,
            names: Names::new(prefix),
        })
    }

    /// The client's node (made now when the runtime directory appeared
    /// since); a missing directory reads "no daemon runs" for `service`.
    fn node(&self, service: &str) -> Result<&Node<SarIpc>, ShmError> {
        if let Some(n) = self.node.get() {
            return Ok(n);
        }
        let n = node_in(&self.dir, Side::Client).map_err(|e| match e {
            ShmError::NoRuntimeDir { dir } => ShmError::NoDaemon {
                service: service.to_owned(),
                detail: format!(
                    "the runtime directory {dir} does not exist: sard creates it; {RUNTIME_DIR_ENV} names another"
                ),
            },
            e => e,
        })?;
        Ok(self.node.get_or_init(|| n))
    }

    /// A service that no daemon serves (a killed daemon's, not yet cleaned
    /// by the next one; or one starting): let go of at once, so that the
    /// next daemon can clean it and make its own.
    fn gone(&self, service: &str) -> ShmError {
        ShmError::NoDaemon {
            service: service.to_owned(),
            detail: "no sard serves it: the one that made it is gone (a new sard replaces it at its start)".to_owned(),
        }
    }

    /// This client's own node files (for [`access::fence_own_files`]).
    fn own_paths(&self) -> (Vec<std::path::PathBuf>, Vec<std::path::PathBuf>) {
        match self.node.get() {
            Some(n) => {
                let (dir, files) = access::node_paths(&self.dir, n.id().value());
                (vec![dir], files)
            }
            None => (Vec::new(), Vec::new()),
        }
    }

    /// Takes other users' access away from this client's own files.
    fn fence(&self) {
        let (dirs, files) = self.own_paths();
        access::fence_own_files(&self.dir, &dirs, &files);
    }

    /// Wakes the daemon's publishing thread (`PREFIX/wake`) so that it
    /// takes a command or a new subscriber now, not at its next round; a
    /// daemon without the service (an older one) finds it at its next round.
    fn wake_daemon(&self) {
        let Ok(node) = self.node(&self.names.wake) else {
            return;
        };
        let notifier = service_name(&self.names.wake).ok().and_then(|name| {
            node.service_builder(&name)
                .event()
                .open()
                .ok()?
                .notifier_builder()
                .create()
                .ok()
        });
        if let Some(n) = notifier {
            let _ = n.notify();
        }
    }

    /// Subscribes to the state; `Err` when no daemon runs, or when every
    /// place is taken (the limit named).
    pub fn subscribe(&self) -> Result<StateSubscription, ClientError> {
        let state = self
            .node(&self.names.state)?
            .service_builder(&service_name(&self.names.state)?)
            .publish_subscribe::<StateMsg>()
            .open()
            .map_err(|e| open_error(&self.names.state, e))?;
        let mut alive = false;
        state.dynamic_config().list_publishers(|p| {
            alive |= process_alive(&p.node_id);
            CallbackProgression::Continue
        });
        if !alive {
            return Err(self.gone(&self.names.state));
        }
        let subscriber = state
            .subscriber_builder()
            .buffer_size(STATE_BUFFER)
            .create()
            .map_err(|e| match format!("{e:?}").as_str() {
                "ExceedsMaxSupportedSubscribers" => ShmError::Full {
                    what: "subscribers of the state",
                    count: state.dynamic_config().number_of_subscribers(),
                    limit: state.static_config().max_subscribers(),
                },
                _ => port("cannot subscribe to the state", e),
            })?;
        let event = self
            .node(&self.names.event)?
            .service_builder(&service_name(&self.names.event)?)
            .event()
            .open()
            .map_err(|e| open_error(&self.names.event, e))?;
        let listener =
            event
                .listener_builder()
                .create()
                .map_err(|e| match format!("{e:?}").as_str() {
                    "ExceedsMaxSupportedListeners" => ShmError::Full {
                        what: "listeners of the state's event",
                        count: event.dynamic_config().number_of_listeners(),
                        limit: event.static_config().max_listeners(),
                    },
                    _ => port("cannot listen to the state event", e),
                })?;
        self.fence();
        self.wake_daemon();
        Ok(StateSubscription {
            subscriber,
            listener,
        })
    }

    /// Sends a command and waits up to `timeout` for its reply; its port is
    /// given up when the answer came or the time is up (a suspended client
    /// keeps it until it runs again: then it gives it up at once).
    pub fn command(&self, command: CommandMsg, timeout: Duration) -> Result<ReplyMsg, ClientError> {
        let service = self
            .node(&self.names.command)?
            .service_builder(&service_name(&self.names.command)?)
            .request_response::<CommandMsg, ReplyMsg>()
            .open()
            .map_err(|e| open_error(&self.names.command, e))?;
        let mut alive = false;
        service.dynamic_config().list_servers(|p| {
            alive |= process_alive(&p.node_id);
            CallbackProgression::Continue
        });
        if !alive {
            return Err(self.gone(&self.names.command));
        }
        let client =
            service
                .client_builder()
                .create()
                .map_err(|e| match format!("{e:?}").as_str() {
                    "ExceedsMaxSupportedClients" => ShmError::Full {
                        what: "command clients",
                        count: service.dynamic_config().number_of_clients(),
                        limit: service.static_config().max_clients(),
                    },
                    _ => port("cannot create the command client", e),
                })?;
        let pending = client
            .send_copy(command)
            .map_err(|e| port("cannot send the command", e))?;
        self.wake_daemon();
        let start = std::time::Instant::now();
        let mut fenced = false;
        while start.elapsed() < timeout {
            if !fenced {
                self.fence();
                fenced = true;
            }
            if let Ok(Some(reply)) = pending.receive() {
                return Ok(*reply.payload());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        Err(ShmError::NoReply {
            timeout_ms: timeout.as_millis(),
        })
    }
}

/// Whether the process that made the node `id` lives (its process id, from
/// the id: a signal 0 to it is delivered or refused for want of
/// permission). No file of the node is read (a member could make one
/// block the reader).
fn process_alive(id: &iceoryx2::identifiers::UniqueNodeId) -> bool {
    let Ok(pid) = id.pid::<SarIpc>() else {
        return true;
    };
    // SAFETY: a plain query; signal 0 is never delivered.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::kill(pid.value(), 0) };
    rc == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// A subscription to the state.
#[derive(Debug)]
pub struct StateSubscription {
    subscriber: iceoryx2::port::subscriber::Subscriber<SarIpc, StateMsg, ()>,
    listener: iceoryx2::port::listener::Listener<SarIpc>,
}

impl StateSubscription {
    /// Every sample waiting, oldest first, into `f`.
    pub fn drain(&self, mut f: impl FnMut(&StateMsg)) -> usize {
        let mut n = 0;
        while let Ok(Some(sample)) = self.subscriber.receive() {
            f(sample.payload());
            n += 1;
        }
        n
    }

    /// Blocks on the event for at most `timeout`, then drains.
    pub fn wait(&self, timeout: Duration, f: impl FnMut(&StateMsg)) -> usize {
        let _ = self.listener.timed_wait(|_| {}, timeout);
        self.drain(f)
    }

    /// The newest sample within `timeout`.
    pub fn latest(&self, timeout: Duration) -> Option<StateMsg> {
        let start = std::time::Instant::now();
        let mut last = None;
        while last.is_none() && start.elapsed() < timeout {
            self.wait(Duration::from_millis(50), |s| last = Some(*s));
        }
        last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// iceoryx2's open errors by their names (as `open_error` reads them).
    #[derive(Debug)]
    enum Open {
        DoesNotExist,
        IncompatibleTypes,
        ExceedsMaxNumberOfNodes,
        InternalFailure,
    }

    #[test]
    fn an_open_error_says_what_it_means() {
        let said = |e: Open| open_error("sar/state", e).to_string();
        assert!(said(Open::DoesNotExist).starts_with("no daemon runs"));
        let types = said(Open::IncompatibleTypes);
        assert!(
            types.contains("sarctl and sard are from different builds")
                && types.contains("sar/state: IncompatibleTypes")
                && !types.contains("no daemon runs"),
            "{types}"
        );
        assert!(said(Open::ExceedsMaxNumberOfNodes).contains("the limit is"));
        assert!(said(Open::InternalFailure).starts_with("cannot open the daemon's service"));
    }
}
