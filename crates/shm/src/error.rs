//! Why shared memory failed ([`ShmError`]), and the one reading of
//! iceoryx2's errors into it (`open_error`: what a client that cannot open a
//! service is told).

use crate::MAX_NODES;
use iceoryx2::prelude::*;

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

pub(crate) fn port(what: &'static str, e: impl std::fmt::Debug) -> ShmError {
    ShmError::Port {
        what,
        detail: format!("{e:?}"),
    }
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, ShmError> {
    ServiceName::new(name).map_err(|e| ShmError::ServiceName {
        name: name.to_owned(),
        detail: format!("{e:?}"),
    })
}

/// Why a client could not open a service: "no daemon runs" only when it
/// does not exist (or is being removed); every place taken names the
/// limit; another message type names the likely cause (`sarctl` and `sard`
/// from different builds); anything else says what failed.
pub(crate) fn open_error(service: &str, e: impl std::fmt::Debug) -> ShmError {
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
