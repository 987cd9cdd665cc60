//! The iceoryx2 node of a side (daemon or client) in the runtime directory,
//! and the cleaning of dead nodes' resources.

use crate::access::{Side, runtime_dir};
use crate::error::ShmError;
use crate::{CLIENT_CREATION_TIMEOUT, DAEMON_CREATION_TIMEOUT, SarIpc, access};
use iceoryx2::prelude::*;
use std::path::Path;
use std::time::Duration;

/// The same for [`DaemonShm::create`] (tests and benchmarks, many at once on
/// a loaded machine).
pub(crate) const LIBRARY_START_TIMEOUT: Duration = Duration::from_secs(30);

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
