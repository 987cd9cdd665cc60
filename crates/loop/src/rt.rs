//! The few system calls of the real-time loop: the monotonic clock, absolute
//! sleeps (`clock_nanosleep` with `TIMER_ABSTIME`), memory locking, SCHED_FIFO
//! and CPU pinning, and the SIGTERM/SIGINT flag. Each call says why it failed;
//! none allocates.
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicBool, Ordering};

/// `CLOCK_MONOTONIC` in ns, or `None` when it cannot be read (the drivers'
/// clock: one place reads it).
pub use sar_drivers::clock::monotonic_ns;

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

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Installs the SIGTERM and SIGINT handler that asks the loop to stop.
pub fn install_stop_handler() -> std::io::Result<()> {
    for sig in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: a zeroed sigaction is valid; the handler only stores an
        // atomic (async-signal-safe); no SA_RESTART, so sleeps are interrupted.
        let rc = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(sig, &action, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    Ok(())
}

/// Whether SIGTERM or SIGINT arrived (or [`request_stop`] was called).
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// Asks the loop to stop (as a signal would).
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}
