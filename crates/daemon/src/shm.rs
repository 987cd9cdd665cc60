//! iceoryx2 (0.10) shared memory between `sard` and its clients.
//!
//! Services, under a prefix (default [`DEFAULT_PREFIX`]; tests use unique
//! ones so that they run in parallel):
//! - `PREFIX/state`: publish-subscribe of [`StateMsg`], once per cycle. One
//!   publisher (the daemon), safe overflow (a slow or dead subscriber loses
//!   its oldest samples; the loop never waits), subscriber buffer
//!   [`STATE_BUFFER`], history [`STATE_HISTORY`].
//! - `PREFIX/state_event`: an event notified after each publish, so that a
//!   subscriber blocks on its listener instead of spinning.
//! - `PREFIX/command`: request-response of [`CommandMsg`] to [`ReplyMsg`]
//!   (reset, tare, move-tip, limits). The loop takes at most one command per
//!   cycle and replies from the cycle that judged it.
//!
//! At start the daemon removes the stale resources of dead nodes (a daemon
//! or client killed with SIGKILL) and then creates the services; when they
//! exist (a living daemon with the same prefix), it refuses to start.

use crate::control::{Envelope, Operator};
use crate::runloop::{Publish, Published};
use crate::wire::{CommandMsg, ReplyMsg, StateMsg, StateParts, command_kind, reply_code};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use std::time::Duration;

/// The default service prefix.
pub const DEFAULT_PREFIX: &str = "sar";
/// Samples a state subscriber buffers.
pub const STATE_BUFFER: usize = 64;
/// Samples a new subscriber may get from the history.
pub const STATE_HISTORY: usize = 1;
/// Subscribers of the state at most.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Command clients at most.
pub const MAX_CLIENTS: usize = 8;

/// The service names under `prefix`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Names {
    /// State publish-subscribe.
    pub state: String,
    /// State event.
    pub event: String,
    /// Commands.
    pub command: String,
}

impl Names {
    /// The names under `prefix`.
    pub fn new(prefix: &str) -> Self {
        Self {
            state: format!("{prefix}/state"),
            event: format!("{prefix}/state_event"),
            command: format!("{prefix}/command"),
        }
    }
}

fn msg(what: &str, e: impl std::fmt::Debug) -> String {
    format!("{what}: {e:?}")
}

fn service_name(name: &str) -> Result<ServiceName, String> {
    ServiceName::new(name).map_err(|e| msg(&format!("bad service name {name:?}"), e))
}

/// A node without iceoryx2's own signal handlers (the daemon has its own).
pub fn node() -> Result<Node<ipc::Service>, String> {
    NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| msg("cannot create the iceoryx2 node", e))
}

/// Removes the resources of dead nodes; returns how many were cleaned.
pub fn clean_dead_nodes() -> usize {
    let mut cleaned = 0;
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            cleaned += 1;
        }
        CallbackProgression::Continue
    });
    cleaned
}

type StatePublisher = Publisher<ipc::Service, StateMsg, ()>;
type CommandServer = Server<ipc::Service, CommandMsg, (), ReplyMsg, ()>;
type CommandRequest = ActiveRequest<ipc::Service, CommandMsg, (), ReplyMsg, ()>;

/// The daemon's side: publishes the state, serves commands.
pub struct DaemonShm {
    _node: Node<ipc::Service>,
    publisher: StatePublisher,
    notifier: Notifier<ipc::Service>,
    server: CommandServer,
    operator: Operator,
    /// The command handed to the loop, waiting for its reply.
    in_flight: Option<CommandRequest>,
    /// The guard's limits, N (warn, stop for total, axial, lateral).
    limits_n: [f64; 6],
    /// The simulator's truth of F_tip, when simulated.
    truth: Option<Box<dyn FnMut() -> Option<sar_estimator::Vec3>>>,
    publish_errors: u64,
    /// Where `record start|stop` go (`None`: refused as unknown).
    record_switch: Option<std::sync::Arc<crate::record::live::RecordSwitch>>,
}

impl DaemonShm {
    /// Takes `record start|stop` commands into `switch`.
    pub fn with_record_switch(
        mut self,
        switch: std::sync::Arc<crate::record::live::RecordSwitch>,
    ) -> Self {
        self.record_switch = Some(switch);
        self
    }

    /// Cleans dead nodes' resources, then creates the services under
    /// `prefix`; refuses when a living daemon has them.
    pub fn create(
        prefix: &str,
        operator: Operator,
        limits_n: [f64; 6],
        truth: Option<Box<dyn FnMut() -> Option<sar_estimator::Vec3>>>,
    ) -> Result<Self, String> {
        let cleaned = clean_dead_nodes();
        if cleaned > 0 {
            tracing::info!("removed the shared-memory resources of {cleaned} dead process(es)");
        }
        let names = Names::new(prefix);
        let node = node()?;
        let state = node
            .service_builder(&service_name(&names.state)?)
            .publish_subscribe::<StateMsg>()
            .max_publishers(1)
            .max_subscribers(MAX_SUBSCRIBERS)
            .subscriber_max_buffer_size(STATE_BUFFER)
            .history_size(STATE_HISTORY)
            .enable_safe_overflow(true)
            .create()
            .map_err(|e| {
                format!(
                    "cannot create the service {:?} ({e:?}): another sard runs with the prefix {prefix:?}",
                    names.state
                )
            })?;
        let publisher = state
            .publisher_builder()
            .create()
            .map_err(|e| msg("cannot create the state publisher", e))?;
        let event = node
            .service_builder(&service_name(&names.event)?)
            .event()
            .create()
            .map_err(|e| {
                format!(
                    "cannot create the service {:?} ({e:?}): another sard runs with the prefix {prefix:?}",
                    names.event
                )
            })?;
        let notifier = event
            .notifier_builder()
            .create()
            .map_err(|e| msg("cannot create the state notifier", e))?;
        let command = node
            .service_builder(&service_name(&names.command)?)
            .request_response::<CommandMsg, ReplyMsg>()
            .max_servers(1)
            .max_clients(MAX_CLIENTS)
            .max_active_requests_per_client(1)
            .max_response_buffer_size(1)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .create()
            .map_err(|e| {
                format!(
                    "cannot create the service {:?} ({e:?}): another sard runs with the prefix {prefix:?}",
                    names.command
                )
            })?;
        let server = command
            .server_builder()
            .create()
            .map_err(|e| msg("cannot create the command server", e))?;
        Ok(Self {
            _node: node,
            publisher,
            notifier,
            server,
            operator,
            in_flight: None,
            limits_n,
            truth,
            publish_errors: 0,
            record_switch: None,
        })
    }

    /// Before a cycle: takes at most one command and hands it to the loop
    /// (answers LIMITS and unknown kinds at once).
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
        };
        match command.request() {
            Some(request) => {
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
            None if command.kind == command_kind::LIMITS => {
                let _ = active.send_copy(immediate(0));
            }
            None if matches!(
                command.kind,
                command_kind::RECORD_START | command_kind::RECORD_STOP
            ) && self.record_switch.is_some() =>
            {
                if let Some(s) = &self.record_switch {
                    if command.kind == command_kind::RECORD_START {
                        s.request_start();
                    } else {
                        s.request_stop();
                    }
                }
                let _ = active.send_copy(immediate(0));
            }
            None => {
                let _ = active.send_copy(immediate(reply_code::UNKNOWN_COMMAND));
            }
        }
    }

    /// Publish errors so far.
    pub fn publish_errors(&self) -> u64 {
        self.publish_errors
    }
}

impl Publish for DaemonShm {
    fn before_cycle(&mut self) {
        self.take_command();
    }

    fn publish(&mut self, c: &Published<'_>) {
        // The limits in use (an operator may have changed them this cycle).
        self.limits_n = c.decision.limits.to_array();
        // The reply of the command judged in this cycle.
        while let Some(reply) = self.operator.replies.pop() {
            if let Some(active) = self.in_flight.take() {
                let _ = active.send_copy(ReplyMsg::from_reply(&reply, self.limits_n));
            }
        }
        let truth_tip_force_n = self.truth.as_mut().and_then(|f| f());
        let state = StateMsg::from_parts(&StateParts {
            input: c.input,
            output: c.output,
            stats: c.stats,
            limits_n: self.limits_n,
            drive_state: c.drive_state,
            halted: c.halted,
            quick_stops: c.quick_stops,
            recorder_drops: c.recorder_drops,
            recording: c.recording,
            truth_tip_force_n,
        });
        let sent = self
            .publisher
            .loan_uninit()
            .map(|s| s.write_payload(state))
            .map_err(|_| ())
            .and_then(|s| s.send().map_err(|_| ()));
        if sent.is_err() {
            self.publish_errors += 1;
        }
        let _ = self.notifier.notify();
    }
}

/// A client's side: subscribes to the state, sends commands.
#[derive(Debug)]
pub struct Client {
    node: Node<ipc::Service>,
    names: Names,
}

/// Why a client call failed.
pub type ClientError = String;

impl Client {
    /// A client for the daemon with `prefix`.
    pub fn new(prefix: &str) -> Result<Self, ClientError> {
        Ok(Self {
            node: node()?,
            names: Names::new(prefix),
        })
    }

    fn no_daemon(&self, service: &str, e: impl std::fmt::Debug) -> String {
        format!("no daemon runs (cannot open the service {service:?}: {e:?})")
    }

    /// Subscribes to the state; `Err` when no daemon runs.
    pub fn subscribe(&self) -> Result<StateSubscription, ClientError> {
        let state = self
            .node
            .service_builder(&service_name(&self.names.state)?)
            .publish_subscribe::<StateMsg>()
            .open()
            .map_err(|e| self.no_daemon(&self.names.state, e))?;
        let subscriber = state
            .subscriber_builder()
            .buffer_size(STATE_BUFFER)
            .create()
            .map_err(|e| msg("cannot subscribe to the state", e))?;
        let event = self
            .node
            .service_builder(&service_name(&self.names.event)?)
            .event()
            .open()
            .map_err(|e| self.no_daemon(&self.names.event, e))?;
        let listener = event
            .listener_builder()
            .create()
            .map_err(|e| msg("cannot listen to the state event", e))?;
        Ok(StateSubscription {
            subscriber,
            listener,
        })
    }

    /// Sends a command and waits up to `timeout` for its reply.
    pub fn command(&self, command: CommandMsg, timeout: Duration) -> Result<ReplyMsg, ClientError> {
        let service = self
            .node
            .service_builder(&service_name(&self.names.command)?)
            .request_response::<CommandMsg, ReplyMsg>()
            .open()
            .map_err(|e| self.no_daemon(&self.names.command, e))?;
        let client = service
            .client_builder()
            .create()
            .map_err(|e| msg("cannot create the command client", e))?;
        let pending = client
            .send_copy(command)
            .map_err(|e| msg("cannot send the command", e))?;
        let start = std::time::Instant::now();
        while start.elapsed() < timeout {
            if let Ok(Some(reply)) = pending.receive() {
                return Ok(*reply.payload());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        Err(format!(
            "no reply from the daemon within {} ms",
            timeout.as_millis()
        ))
    }
}

/// A subscription to the state.
#[derive(Debug)]
pub struct StateSubscription {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, StateMsg, ()>,
    listener: iceoryx2::port::listener::Listener<ipc::Service>,
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
