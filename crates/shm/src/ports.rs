//! The daemon's services and ports: the command server, the state publisher,
//! the events, created at start after orphaned services are released and the
//! runtime directory fenced.

use crate::error::{ShmError, port, service_name};
use crate::{
    MAX_CLIENTS, MAX_NODES, MAX_SUBSCRIBERS, Names, ORPHAN_WAIT, STATE_BORROWED, STATE_BUFFER,
    STATE_HISTORY, SarIpc, access,
};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use sar_msgs::wire::{CommandMsg, ReplyMsg, StateMsg};
use std::path::Path;
use std::time::Duration;

pub(crate) type StatePublisher = Publisher<SarIpc, StateMsg, ()>;
pub(crate) type StateService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<SarIpc, StateMsg, ()>;
pub(crate) type CommandServer = Server<SarIpc, CommandMsg, (), ReplyMsg, ()>;
pub(crate) type CommandRequest = ActiveRequest<SarIpc, CommandMsg, (), ReplyMsg, ()>;

pub(crate) fn exists(prefix: &str, service: &str, e: impl std::fmt::Debug) -> ShmError {
    ShmError::DaemonRuns {
        prefix: prefix.to_owned(),
        service: service.to_owned(),
        detail: format!("{e:?}"),
    }
}

/// The command service (request-response) and its one server.
pub(crate) fn command_server(
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
pub(crate) fn state_publisher(
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
pub(crate) fn events(
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

/// The services under `names` that exist with no daemon's port (no
/// publisher, server, notifier or wake-up listener): a killed daemon's,
/// kept by the clients that still have them open (its dead ports were
/// cleaned; a service goes once no process has it open). Each is opened
/// and let go of: the last process to let go removes it (iceoryx2 removes
/// a service nobody has open), so once its clients are gone it is gone.
/// Returns how many there were.
pub(crate) fn release_orphaned_services(node: &Node<SarIpc>, names: &Names) -> usize {
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
pub(crate) type DaemonPorts = (
    CommandServer,
    (StateService, StatePublisher),
    (Notifier<SarIpc>, Listener<SarIpc>),
);

pub(crate) fn services(
    node: &Node<SarIpc>,
    names: &Names,
    prefix: &str,
) -> Result<DaemonPorts, ShmError> {
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
pub(crate) fn fence_at_start(dir: &Path, node: &Node<SarIpc>) {
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
