//! systemd's notify protocol (`Type=notify`), written by hand: one datagram
//! per message to the unix socket named by `NOTIFY_SOCKET` (a path, or an
//! abstract name starting with `@`). The messages are fixed strings (no
//! formatting, no allocation on the loop); the socket is non-blocking, so a
//! full or missing receiver never slows the loop.

use sar_estimator::guard::{GuardState, Reason};
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};

/// A connection to the service manager.
#[derive(Debug)]
pub struct Notifier {
    socket: UnixDatagram,
    sent: u64,
    failed: u64,
}

impl Notifier {
    /// From `NOTIFY_SOCKET`; `None` when it is not set (not run by systemd)
    /// or cannot be used.
    pub fn from_env() -> Option<Self> {
        let path = std::env::var_os("NOTIFY_SOCKET")?;
        Self::connect(path.to_str()?).ok()
    }

    /// Connects to `name` (a path, or `@abstract`).
    pub fn connect(name: &str) -> std::io::Result<Self> {
        let socket = UnixDatagram::unbound()?;
        let addr = match name.strip_prefix('@') {
            Some(abstract_name) => SocketAddr::from_abstract_name(abstract_name.as_bytes())?,
            None => SocketAddr::from_pathname(name)?,
        };
        socket.connect_addr(&addr)?;
        socket.set_nonblocking(true)?;
        Ok(Self {
            socket,
            sent: 0,
            failed: 0,
        })
    }

    /// Sends one message (e.g. `READY=1`); a failure is counted.
    pub fn send(&mut self, message: &str) {
        match self.socket.send(message.as_bytes()) {
            Ok(_) => self.sent += 1,
            Err(_) => self.failed += 1,
        }
    }

    /// Messages sent and failed.
    pub fn counts(&self) -> (u64, u64) {
        (self.sent, self.failed)
    }
}

/// The `STATUS=` line for a guard state.
pub fn status_message(state: GuardState) -> &'static str {
    match state {
        GuardState::Ok => "STATUS=guard ok",
        GuardState::Warn => "STATUS=guard WARN: tip force near a stop limit",
        GuardState::Stop => "STATUS=guard STOP: drives quick-stopped, reset needed",
        GuardState::Fault => "STATUS=guard FAULT: drives quick-stopped, reset needed",
        GuardState::Retreat => {
            "STATUS=guard RETREAT: only motions that reduce the tip force are accepted"
        }
    }
}

/// Whether the loop keeps feeding systemd's watchdog. Not while the guard
/// holds a Fault for a stalled publishing thread: the guard has already
/// stopped the drives, but that thread carries every operator command and
/// the published state, so the operator can neither see nor command the
/// robot; without pings systemd restarts `sard` after `WatchdogSec` (the
/// new daemon starts in Fault, waiting for its first reset).
pub fn watchdog_fed(reason: &Reason) -> bool {
    !matches!(reason, Reason::PublisherStalled { .. })
}

/// What the loop tells systemd, decided from its health.
#[derive(Debug)]
pub struct Watchdog {
    notifier: Option<Notifier>,
    ready: bool,
    last_state: Option<GuardState>,
    every_cycles: u64,
}

impl Watchdog {
    /// Pings every `every_cycles` healthy cycles.
    pub fn new(notifier: Option<Notifier>, every_cycles: u64) -> Self {
        Self {
            notifier,
            ready: false,
            last_state: None,
            every_cycles: every_cycles.max(1),
        }
    }

    /// After each cycle, from the loop thread itself (so a stuck loop stops
    /// the pings): READY=1 after the first good cycle (`good`: it gave a
    /// tip-force estimate), then WATCHDOG=1 every `every_cycles` cycles
    /// while [`watchdog_fed`] says so, STATUS= on every guard state change.
    pub fn after_cycle(&mut self, cycle: u64, state: GuardState, reason: &Reason, good: bool) {
        let Some(n) = self.notifier.as_mut() else {
            return;
        };
        if self.last_state != Some(state) {
            n.send(status_message(state));
            self.last_state = Some(state);
        }
        if good && !self.ready {
            n.send("READY=1");
            self.ready = true;
        }
        if self.ready && cycle.is_multiple_of(self.every_cycles) && watchdog_fed(reason) {
            n.send("WATCHDOG=1");
        }
    }

    /// At shutdown.
    pub fn stopping(&mut self) {
        if let Some(n) = self.notifier.as_mut() {
            n.send("STOPPING=1");
        }
    }
}
