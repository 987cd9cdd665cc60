//! Clocks: the host's monotonic clock, and a simulated clock that tests and
//! scenario runs advance by hand, so that a simulation is deterministic.

use std::cell::Cell;
use std::rc::Rc;

/// A monotonic clock in nanoseconds.
pub trait Clock {
    /// Now, ns, or why the clock could not be read (never a made-up time).
    fn now_ns(&self) -> Result<u64, ClockError>;
    /// Returns once `now_ns() >= deadline_ns` (at once if already past).
    fn sleep_until_ns(&self, deadline_ns: u64);
}

/// The host's `CLOCK_MONOTONIC`, the time base of every stamp and recording.
///
/// Made by [`MonotonicClock::new`], which reads the clock once: a host without
/// a readable monotonic clock is refused at start, not discovered mid-run.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    _readable: (),
}

/// The host's monotonic clock cannot be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("CLOCK_MONOTONIC cannot be read on this host")]
pub struct ClockError;

impl crate::Error for ClockError {
    fn kind(&self) -> crate::ErrorKind {
        crate::ErrorKind::Unsupported
    }
}

impl MonotonicClock {
    /// The monotonic clock, after one successful read.
    pub fn new() -> Result<Self, ClockError> {
        Self::read_ns()
            .map(|_| Self { _readable: () })
            .ok_or(ClockError)
    }

    /// `CLOCK_MONOTONIC` in ns, or `None` when the clock cannot be read.
    fn read_ns() -> Option<u64> {
        monotonic_ns()
    }
}

/// `CLOCK_MONOTONIC` in ns, or `None` when the clock cannot be read: the one
/// place the workspace reads it (the loop's `rt::monotonic_ns` is this).
pub fn monotonic_ns() -> Option<u64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC exists on Linux.
    #[allow(unsafe_code)]
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        return None;
    }
    Some(
        u64::try_from(ts.tv_sec)
            .ok()?
            .saturating_mul(1_000_000_000)
            .saturating_add(u64::try_from(ts.tv_nsec).ok()?),
    )
}

impl Clock for MonotonicClock {
    /// Now, ns.
    ///
    /// Once [`MonotonicClock::new`] has read the clock, `clock_gettime` cannot
    /// fail (its errors are a bad clock id or a bad pointer, both excluded
    /// here). Should it fail all the same, this is [`ClockError`], never a
    /// sentinel time: the loop passes "no time" to the estimator's cycle
    /// (`CycleInput::now_ns = None`), which is a Fault of its own
    /// (`Reason::ClockFailed`).
    fn now_ns(&self) -> Result<u64, ClockError> {
        Self::read_ns().ok_or(ClockError)
    }

    fn sleep_until_ns(&self, deadline_ns: u64) {
        // Bounded: each sleep is at most the remaining time, and the loop ends
        // as soon as the clock passes the deadline. A clock that cannot be
        // read ends the sleep at once (rather than sleeping `deadline_ns` from
        // a reading of 0, i.e. for about the machine's uptime).
        while let Some(now) = Self::read_ns() {
            if now >= deadline_ns {
                return;
            }
            std::thread::sleep(std::time::Duration::from_nanos(deadline_ns - now));
        }
    }
}

/// A simulated clock: time moves only when told. Clones share the same time.
#[derive(Debug, Clone, Default)]
pub struct SimClock {
    now_ns: Rc<Cell<u64>>,
}

impl SimClock {
    /// A clock at `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        Self {
            now_ns: Rc::new(Cell::new(start_ns)),
        }
    }

    /// Moves time forward by `dt_ns` (saturating).
    pub fn advance_ns(&self, dt_ns: u64) {
        self.now_ns.set(self.now_ns.get().saturating_add(dt_ns));
    }

    /// Now, ns: a simulated clock is always readable (the [`Clock`] trait's
    /// `now_ns` gives the same time as `Ok`).
    pub fn now_ns(&self) -> u64 {
        self.now_ns.get()
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> Result<u64, ClockError> {
        Ok(self.now_ns.get())
    }

    /// Simulated sleep: jumps to the deadline (never backwards).
    fn sleep_until_ns(&self, deadline_ns: u64) {
        if deadline_ns > self.now_ns.get() {
            self.now_ns.set(deadline_ns);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_reads_never_go_back_and_sleep_reaches_the_deadline() {
        let clock = MonotonicClock::new().unwrap();
        let first = clock.now_ns().unwrap();
        assert!(first > 0, "CLOCK_MONOTONIC read as 0");
        let deadline = first + 2_000_000;
        clock.sleep_until_ns(deadline);
        let after = clock.now_ns().unwrap();
        assert!(after >= deadline, "woke at {after}, before {deadline}");
        // A deadline in the past returns without sleeping into the future.
        clock.sleep_until_ns(first);
        assert!(clock.now_ns().unwrap() >= after);
    }

    #[test]
    fn sim_clock_clones_share_time_and_never_go_back() {
        let a = SimClock::new(100);
        let b = a.clone();
        a.advance_ns(50);
        assert_eq!(b.now_ns(), 150);
        b.sleep_until_ns(120);
        assert_eq!(a.now_ns(), 150);
        b.sleep_until_ns(400);
        assert_eq!(a.now_ns(), 400);
        a.advance_ns(u64::MAX);
        assert_eq!(b.now_ns(), u64::MAX);
        assert_eq!(Clock::now_ns(&b), Ok(u64::MAX));
    }
}
