//! A client of the daemon ([`Client`]: commands and replies, the state) and
//! a subscription to the states ([`StateSubscription`]).

use crate::access::{RUNTIME_DIR_ENV, Side, runtime_dir};
use crate::error::{ShmError, open_error, port, service_name};
use crate::node::node_in;
use crate::{Names, STATE_BUFFER, SarIpc, access};
use iceoryx2::prelude::*;
use sar_msgs::wire::{CommandMsg, ReplyMsg, StateMsg};
use std::path::Path;
use std::time::Duration;

/// A client's side: subscribes to the state, sends commands.
#[derive(Debug)]
pub struct Client {
    pub(crate) dir: std::path::PathBuf,
    /// Made at the first call when the runtime directory did not exist yet.
    pub(crate) node: std::cell::OnceCell<Node<SarIpc>>,
    pub(crate) names: Names,
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
    pub(crate) fn node(&self, service: &str) -> Result<&Node<SarIpc>, ShmError> {
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
    pub(crate) fn gone(&self, service: &str) -> ShmError {
        ShmError::NoDaemon {
            service: service.to_owned(),
            detail: "no sard serves it: the one that made it is gone (a new sard replaces it at its start)".to_owned(),
        }
    }

    /// This client's own node files (for [`access::fence_own_files`]).
    pub(crate) fn own_paths(&self) -> (Vec<std::path::PathBuf>, Vec<std::path::PathBuf>) {
        match self.node.get() {
            Some(n) => {
                let (dir, files) = access::node_paths(&self.dir, n.id().value());
                (vec![dir], files)
            }
            None => (Vec::new(), Vec::new()),
        }
    }

    /// Takes other users' access away from this client's own files.
    pub(crate) fn fence(&self) {
        let (dirs, files) = self.own_paths();
        access::fence_own_files(&self.dir, &dirs, &files);
    }

    /// Wakes the daemon's publishing thread (`PREFIX/wake`) so that it
    /// takes a command or a new subscriber now, not at its next round; a
    /// daemon without the service (an older one) finds it at its next round.
    pub(crate) fn wake_daemon(&self) {
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
pub(crate) fn process_alive(id: &iceoryx2::identifiers::UniqueNodeId) -> bool {
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
    pub(crate) subscriber: iceoryx2::port::subscriber::Subscriber<SarIpc, StateMsg, ()>,
    pub(crate) listener: iceoryx2::port::listener::Listener<SarIpc>,
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
