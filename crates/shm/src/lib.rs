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
//!
//! The modules: `error` ([`ShmError`]), `node` (a side's node, dead nodes
//! cleaned), `ports` (the daemon's services), `worker` (the publishing
//! thread), `daemon` (the loop's side), `client`, [`access`].

pub mod access;
mod client;
mod daemon;
mod error;
mod node;
mod ports;
mod service;
mod worker;

pub use access::{DEFAULT_RUNTIME_DIR, RUNTIME_DIR_ENV, Side, runtime_dir};
pub use client::{Client, ClientError, StateSubscription};
pub use daemon::DaemonShm;
pub use error::ShmError;
pub use node::{clean_dead_nodes, clean_dead_nodes_in, config, log_errors_only, node, node_in};
pub use service::Service as SarIpc;
pub use worker::{RecordCommands, ShmWorker};

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
/// How often the daemon's maintenance thread (`sard-reap`) reclaims the
/// ports and files of dead clients (killed with SIGKILL, crashed) and takes
/// other users' access away from the daemon's newest files.
pub const REAP_PERIOD: Duration = Duration::from_secs(1);
/// How long dropping the daemon's side waits for each of its threads (the
/// publishing thread, the maintenance thread) at most, then leaves it
/// behind (`sar_hal::join::left_behind` names it).
pub const JOIN_WAIT: Duration = Duration::from_millis(700);

/// How long a `record start|stop` waits for the recorder's answer (closing
/// a file syncs it to disk) before the reply says it did not come.
pub const RECORD_ANSWER_WAIT: Duration = Duration::from_secs(8);

/// How long a starting daemon waits for the clients of a daemon that is
/// gone to let go of its services (a client lets go at once when it finds
/// no living daemon's port in a service it opens; one that had it open
/// before lets go at its deadline, 2 s at most for a command or `status`:
/// then the start is refused, naming the cause, and systemd's next start
/// a second later succeeds). Well within [`START_TIMEOUT`].
pub const ORPHAN_WAIT: Duration = Duration::from_secs(1);
