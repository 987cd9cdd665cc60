//! The few system calls of the real-time loop: the monotonic clock, absolute
//! sleeps (`clock_nanosleep` with `TIMER_ABSTIME`), memory locking, SCHED_FIFO
//! and CPU pinning, and the stop flag that SIGTERM, SIGINT, SIGHUP and every
//! other terminating signal that can be caught set ([`STOP_SIGNALS`]), and
//! the guard against a shared-memory file truncated under the process
//! ([`install_bus_guard`]: its SIGBUS stops cleanly). Each call says why it
//! failed; none allocates.
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, AtomicUsize, Ordering};

/// `CLOCK_MONOTONIC` in ns, or `None` when it cannot be read (the drivers'
/// clock: one place reads it).
pub use sar_hal::clock::monotonic_ns;

/// Sleeps until the monotonic clock reads `deadline_ns` (absolute: a late
/// wake-up never shifts later deadlines). Interrupted sleeps are resumed; a
/// signal that asks to stop ends the sleep early (the caller checks).
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: libc::time_t::try_from(deadline_ns / 1_000_000_000).unwrap_or(libc::time_t::MAX),
        tv_nsec: libc::c_long::try_from(deadline_ns % 1_000_000_000).unwrap_or(0),
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remainder pointer may be null
        // with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR || stop_requested() {
            return;
        }
    }
}

/// Why a real-time setting was not applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RtError {
    /// `mlockall` failed.
    #[error(
        "cannot lock memory (mlockall): errno {errno} (needs CAP_IPC_LOCK or LimitMEMLOCK=infinity)"
    )]
    Mlock {
        /// The errno.
        errno: i32,
    },
    /// `sched_setscheduler(SCHED_FIFO)` failed.
    #[error(
        "cannot run at SCHED_FIFO priority {priority}: errno {errno} (needs CAP_SYS_NICE or LimitRTPRIO)"
    )]
    Fifo {
        /// The priority asked for.
        priority: i32,
        /// The errno.
        errno: i32,
    },
    /// The wake-up latency request (`/dev/cpu_dma_latency`) failed.
    #[error(
        "cannot hold the CPUs' wake-up latency (/dev/cpu_dma_latency): errno {errno} (needs root)"
    )]
    Latency {
        /// The errno.
        errno: i32,
    },
    /// `sched_setaffinity` failed.
    #[error("cannot pin the loop to CPU {cpu}: errno {errno}")]
    Pin {
        /// The CPU.
        cpu: usize,
        /// The errno.
        errno: i32,
    },
}

fn errno() -> i32 {
    std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
}

/// Locks present and future memory (no page fault in the loop).
pub fn lock_memory() -> Result<(), RtError> {
    // SAFETY: plain system call with flag arguments.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 {
        Ok(())
    } else {
        Err(RtError::Mlock { errno: errno() })
    }
}

/// Holds the CPUs' wake-up latency at `max_us` microseconds for as long as
/// the returned file stays open: the kernel's PM QoS request
/// (`/dev/cpu_dma_latency`), which keeps the CPUs out of the idle states that
/// are slow to leave, as `cyclictest` does by default. Without it, the loop's
/// wake-up waits for an idle CPU to come back (tens of microseconds).
pub fn hold_wakeup_latency(max_us: i32) -> Result<std::fs::File, RtError> {
    use std::io::Write;
    let latency = |e: std::io::Error| RtError::Latency {
        errno: e.raw_os_error().unwrap_or(0),
    };
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        .map_err(latency)?;
    file.write_all(&max_us.to_ne_bytes()).map_err(latency)?;
    Ok(file)
}

/// Runs the calling thread at SCHED_FIFO `priority`.
pub fn set_fifo(priority: i32) -> Result<(), RtError> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is valid; pid 0 is the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(RtError::Fifo {
            priority,
            errno: errno(),
        })
    }
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), RtError> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(RtError::Pin {
            cpu,
            errno: libc::EINVAL,
        });
    }
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET is in range
    // (checked above); pid 0 is the calling thread.
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(RtError::Pin {
            cpu,
            errno: errno(),
        })
    }
}

static STOP: AtomicBool = AtomicBool::new(false);
/// The signal that asked to stop (0: none yet, or [`request_stop`]).
static STOP_SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(sig: libc::c_int) {
    // The first signal is kept (a second one while stopping changes nothing).
    let _ = STOP_SIGNAL.compare_exchange(0, sig, Ordering::SeqCst, Ordering::SeqCst);
    STOP.store(true, Ordering::SeqCst);
}

/// The signals whose default action ends the process and that can be
/// caught, by name: each asks the loop to stop cleanly, as SIGTERM does
/// (drives halted, recording closed, the stop line logged, exit 0). The
/// real-time signals (SIGRTMIN..=SIGRTMAX, default: terminate) are caught
/// too ([`install_stop_handler`]).
///
/// Not among them: SIGKILL and SIGSTOP (cannot be caught); SIGSEGV, SIGBUS,
/// SIGFPE, SIGILL, SIGSYS, SIGTRAP, SIGABRT (a fault of the process itself
/// or a debugger's: the process cannot be trusted to go on, the drives'
/// heartbeat consumer stops them, SAFETY.md D4), except the one SIGBUS that
/// is no fault of the process, a read or write beyond the end of a mapped
/// file that someone else truncated ([`install_bus_guard`]); SIGPIPE and SIGXFSZ
/// (ignored instead: they come from a write to a closed pipe or socket, or
/// beyond the file-size limit, and that write then fails with EPIPE or
/// EFBIG, which its writer reports; a closed log pipe or a recording at
/// its size limit must not stop the robot).
pub const STOP_SIGNALS: [(libc::c_int, &str); 13] = [
    (libc::SIGTERM, "SIGTERM"),
    (libc::SIGINT, "SIGINT"),
    (libc::SIGHUP, "SIGHUP"),
    (libc::SIGQUIT, "SIGQUIT"),
    (libc::SIGUSR1, "SIGUSR1"),
    (libc::SIGUSR2, "SIGUSR2"),
    (libc::SIGALRM, "SIGALRM"),
    (libc::SIGVTALRM, "SIGVTALRM"),
    (libc::SIGPROF, "SIGPROF"),
    (libc::SIGXCPU, "SIGXCPU"),
    (libc::SIGIO, "SIGIO"),
    (libc::SIGPWR, "SIGPWR"),
    (libc::SIGSTKFLT, "SIGSTKFLT"),
];

/// The signals that are ignored rather than caught (see [`STOP_SIGNALS`]).
pub const IGNORED_SIGNALS: [libc::c_int; 2] = [libc::SIGPIPE, libc::SIGXFSZ];

/// Sets `sig`'s disposition to `handler` (a function or `SIG_IGN`).
fn set_disposition(sig: libc::c_int, handler: libc::sighandler_t) -> std::io::Result<()> {
    // SAFETY: a zeroed sigaction is valid; the handler only stores atomics
    // (async-signal-safe). SA_RESTART: the other threads' interrupted
    // system calls resume; the loop's sleep is never restarted whatever the
    // flag (clock_nanosleep returns EINTR, signal(7)) and checks the flag.
    let rc = unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler;
        action.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut action.sa_mask);
        libc::sigaction(sig, &action, std::ptr::null_mut())
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Installs the handler that asks the loop to stop for every signal of
/// [`STOP_SIGNALS`] and every real-time signal, and ignores
/// [`IGNORED_SIGNALS`].
pub fn install_stop_handler() -> std::io::Result<()> {
    let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
    for (sig, _) in STOP_SIGNALS {
        set_disposition(sig, handler)?;
    }
    for sig in libc::SIGRTMIN()..=libc::SIGRTMAX() {
        set_disposition(sig, handler)?;
    }
    for sig in IGNORED_SIGNALS {
        set_disposition(sig, libc::SIG_IGN)?;
    }
    Ok(())
}

/// Gives SIGPIPE back its default action (end the process), which Rust's
/// runtime sets to "ignore" before `main`: for a command-line tool whose
/// output goes into a pipe (`sarctl status | head -1`), a reader that has
/// gone ends it quietly, as it ends `cat` or `grep`, instead of every write
/// failing with EPIPE and `println!` panicking. Not for a daemon or a
/// server ([`install_stop_handler`] ignores it again).
pub fn default_sigpipe() -> std::io::Result<()> {
    set_disposition(libc::SIGPIPE, libc::SIG_DFL)
}

/// Whether a stop signal arrived (or [`request_stop`] was called).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// The signal that asked to stop, if one did.
pub fn stop_signal() -> Option<libc::c_int> {
    match STOP_SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        sig => Some(sig),
    }
}

/// A signal's name: `SIGHUP`, `SIGRTMIN+3`, or `signal 99`.
pub fn signal_name(sig: libc::c_int) -> String {
    if let Some((_, name)) = STOP_SIGNALS.iter().find(|(s, _)| *s == sig) {
        return (*name).to_owned();
    }
    if sig == libc::SIGBUS {
        return "SIGBUS".to_owned();
    }
    if (libc::SIGRTMIN()..=libc::SIGRTMAX()).contains(&sig) {
        return format!("SIGRTMIN+{}", sig - libc::SIGRTMIN());
    }
    format!("signal {sig}")
}

/// Asks the loop to stop (as a signal would).
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}

/// SIGBUS faults the guard took (see [`install_bus_guard`]).
static BUS_FAULTS: AtomicU64 = AtomicU64::new(0);
/// The first address such a fault touched.
static BUS_ADDRESS: AtomicUsize = AtomicUsize::new(0);

/// The SIGBUS handler: a fault beyond the end of a mapped file
/// (`BUS_ADRERR`: the file was truncated under the mapping, e.g. an iceoryx2
/// file of the runtime directory by a member of its group) asks the loop to
/// stop, as SIGTERM does (remembering the signal and the address), and
/// parks the faulting thread for good: it never returns into the code that
/// read a file that is gone (iceoryx2, given zeros there, panics in a
/// destructor and aborts the process). The loop, which maps no file, halts
/// the drives at its next cycle and `sard` ends; the parked thread (the
/// publishing or the maintenance thread) is left behind, named, and ends
/// with the process. Every other thread that touches the file parks the
/// same way. Any other SIGBUS (a misaligned access, a hardware memory
/// error) gets the default action back and faults again: the process ends
/// by SIGBUS as before.
extern "C" fn on_sigbus(sig: libc::c_int, info: *mut libc::siginfo_t, _ctx: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo_t to an SA_SIGINFO handler.
    let (code, addr) = unsafe { ((*info).si_code, (*info).si_addr() as usize) };
    if code == libc::BUS_ADRERR {
        let _ = BUS_ADDRESS.compare_exchange(0, addr, Ordering::SeqCst, Ordering::SeqCst);
        BUS_FAULTS.fetch_add(1, Ordering::SeqCst);
        let _ = STOP_SIGNAL.compare_exchange(0, sig, Ordering::SeqCst, Ordering::SeqCst);
        STOP.store(true, Ordering::SeqCst);
        loop {
            // SAFETY: async-signal-safe; returns after each caught signal.
            unsafe { libc::pause() };
        }
    }
    // SAFETY: restores the default action (async-signal-safe); the access
    // faults again when the handler returns and the process ends by SIGBUS.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = libc::SIG_DFL;
        libc::sigemptyset(&mut action.sa_mask);
        libc::sigaction(libc::SIGBUS, &action, std::ptr::null_mut());
    }
}

/// Installs the SIGBUS guard of the daemon's shared memory: a member of the
/// operators' group may write (so truncate) the iceoryx2 files the daemon
/// maps read-write (a service's dynamic configuration, a connection); a
/// truncated one used to kill `sard` at its next access (SIGBUS, exit 135,
/// no log line, no halt). With the guard, the thread that touched it parks
/// for good and the loop stops cleanly at its next cycle (drives halted,
/// recording closed); [`bus_faults`] says what happened.
pub fn install_bus_guard() -> std::io::Result<()> {
    // SAFETY: a zeroed sigaction is valid; the handler stores atomics and
    // then only calls pause (async-signal-safe).
    let rc = unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = on_sigbus
            as extern "C" fn(libc::c_int, *mut libc::siginfo_t, *mut libc::c_void)
            as libc::sighandler_t;
        action.sa_flags = libc::SA_SIGINFO | libc::SA_RESTART;
        libc::sigemptyset(&mut action.sa_mask);
        libc::sigaction(libc::SIGBUS, &action, std::ptr::null_mut())
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// The SIGBUS faults [`install_bus_guard`] took so far, and the first
/// address (`None`: none).
pub fn bus_faults() -> Option<(u64, usize)> {
    match BUS_FAULTS.load(Ordering::SeqCst) {
        0 => None,
        n => Some((n, BUS_ADDRESS.load(Ordering::SeqCst))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispositions after [`install_stop_handler`]: every stop signal
    /// caught, the ignored ones ignored. (Nothing is raised: the flag is
    /// process-wide and other tests of this binary read it.)
    #[test]
    fn every_terminating_signal_is_caught_and_pipe_and_xfsz_are_ignored() {
        assert!(install_stop_handler().is_ok());
        let disposition = |sig| {
            // SAFETY: reading the current action into a zeroed struct.
            unsafe {
                let mut old: libc::sigaction = std::mem::zeroed();
                assert_eq!(libc::sigaction(sig, std::ptr::null(), &mut old), 0);
                old.sa_sigaction
            }
        };
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        for (sig, name) in STOP_SIGNALS {
            assert_eq!(disposition(sig), handler, "{name}");
            assert_eq!(signal_name(sig), name);
        }
        for sig in libc::SIGRTMIN()..=libc::SIGRTMAX() {
            assert_eq!(disposition(sig), handler, "{}", signal_name(sig));
        }
        for sig in IGNORED_SIGNALS {
            assert_eq!(disposition(sig), libc::SIG_IGN, "{sig}");
        }
    }
}
