//! Time as an input of the run loop: the clock it reads and sleeps on.
//!
//! [`RealTime`] is the host's `CLOCK_MONOTONIC` with absolute sleeps: the
//! robot's time. [`SimulatedTime`] is a simulated clock (shared with the
//! simulator's world) that the loop moves to each deadline itself, paced at
//! a multiple of real time or as fast as the machine allows: the same loop,
//! the same step, the same sinks, but a cycle takes no simulated time, so a
//! simulated run is the same run whatever the host's load (no late
//! wake-up, no overrun: the cycles' inputs depend on the scenario and the
//! operator's requests only).
//!
//! What is measured against the host itself stays on the host's clock in
//! both: the publishing thread's silence ([`LoopClock::host_ns`]), since
//! that thread runs in real time whatever the loop's clock.

use crate::rt;
use sar_hal::SimClock;

/// The clock the run loop reads and sleeps on.
pub trait LoopClock {
    /// Now, ns; `None` when the clock cannot be read (the step faults:
    /// `clock_failed`).
    fn now_ns(&self) -> Option<u64>;
    /// Returns once the clock reads `deadline_ns` (at once if past), or
    /// earlier when a stop is requested (the caller checks).
    fn sleep_until_ns(&self, deadline_ns: u64);
    /// The host's monotonic time, ns, for what runs in real time beside the
    /// loop (the publishing thread). In real time: `now`, read again.
    fn host_ns(&self) -> Option<u64> {
        rt::monotonic_ns()
    }
    /// Whether the clock is simulated: the loop then waits for its sinks'
    /// room instead of dropping (waiting costs no simulated time).
    fn simulated(&self) -> bool {
        false
    }
}

/// The host's monotonic clock: `clock_nanosleep` to absolute deadlines.
#[derive(Debug, Clone, Copy, Default)]
pub struct RealTime;

impl LoopClock for RealTime {
    fn now_ns(&self) -> Option<u64> {
        rt::monotonic_ns()
    }
    fn sleep_until_ns(&self, deadline_ns: u64) {
        rt::sleep_until_ns(deadline_ns);
    }
}

/// How fast simulated time runs against the host's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    /// Simulated seconds per real second (`0 < factor <= MAX_FACTOR`).
    Factor(f64),
    /// As fast as the machine allows (no real sleep at all).
    Max,
}

/// The largest paced factor (beyond it, `max`).
pub const MAX_FACTOR: f64 = 1000.0;

impl Speed {
    /// Parses `max` or a factor in (0, [`MAX_FACTOR`]]; the error is one
    /// line naming the value and the range.
    pub fn parse(text: &str) -> Result<Self, String> {
        if text.trim() == "max" {
            return Ok(Self::Max);
        }
        match text.trim().parse::<f64>() {
            Ok(f) if f.is_finite() && f > 0.0 && f <= MAX_FACTOR => Ok(Self::Factor(f)),
            _ => Err(format!(
                "speed {text:?}: expected `max` or a factor of real time above 0 and at most {MAX_FACTOR}"
            )),
        }
    }
}

/// A simulated clock the loop moves to each deadline, paced against the
/// host's clock by a [`Speed`]. Lives on the loop's thread (the simulator
/// shares its [`SimClock`]).
#[derive(Debug, Clone)]
pub struct SimulatedTime {
    clock: SimClock,
    speed: Speed,
    /// Simulated and host time at the start, ns: the pacing's origin.
    origin_sim_ns: u64,
    origin_host_ns: u64,
}

impl SimulatedTime {
    /// Simulated time on `clock` (read now as the origin), at `speed`.
    pub fn new(clock: SimClock, speed: Speed) -> Self {
        let origin_sim_ns = clock.now_ns();
        Self {
            clock,
            speed,
            origin_sim_ns,
            origin_host_ns: rt::monotonic_ns().unwrap_or(0),
        }
    }

    /// The host's time at which simulated time reaches `deadline_ns`.
    fn host_deadline_ns(&self, deadline_ns: u64, factor: f64) -> u64 {
        let sim_ns = deadline_ns.saturating_sub(self.origin_sim_ns) as f64;
        self.origin_host_ns
            .saturating_add((sim_ns / factor).min(u64::MAX as f64) as u64)
    }
}

impl LoopClock for SimulatedTime {
    fn now_ns(&self) -> Option<u64> {
        Some(self.clock.now_ns())
    }
    fn sleep_until_ns(&self, deadline_ns: u64) {
        if let Speed::Factor(f) = self.speed {
            rt::sleep_until_ns(self.host_deadline_ns(deadline_ns, f));
            if rt::stop_requested() {
                return;
            }
        }
        sar_hal::Clock::sleep_until_ns(&self.clock, deadline_ns);
    }
    fn simulated(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds_parse_and_bad_ones_are_named() {
        assert_eq!(Speed::parse("max"), Ok(Speed::Max));
        assert_eq!(Speed::parse("50"), Ok(Speed::Factor(50.0)));
        assert_eq!(Speed::parse("0.5"), Ok(Speed::Factor(0.5)));
        for bad in ["0", "-1", "NaN", "inf", "1001", "fast", ""] {
            let e = Speed::parse(bad).unwrap_err();
            assert!(e.contains("expected `max`"), "{bad}: {e}");
        }
    }

    #[test]
    fn simulated_time_moves_only_to_the_deadlines() {
        let clock = SimClock::new(5_000);
        let t = SimulatedTime::new(clock.clone(), Speed::Max);
        assert_eq!(t.now_ns(), Some(5_000));
        t.sleep_until_ns(1_005_000);
        assert_eq!(t.now_ns(), Some(1_005_000));
        assert_eq!(
            clock.now_ns(),
            1_005_000,
            "the simulator's clock is the loop's"
        );
        // Never backwards.
        t.sleep_until_ns(10);
        assert_eq!(t.now_ns(), Some(1_005_000));
        assert!(t.simulated() && !RealTime.simulated());
    }

    #[test]
    fn a_paced_clock_maps_simulated_deadlines_to_host_time() {
        let t = SimulatedTime::new(SimClock::new(1_000), Speed::Factor(4.0));
        let host = t.host_deadline_ns(1_000 + 8_000_000, 4.0);
        assert_eq!(host - t.origin_host_ns, 2_000_000);
        // A deadline before the origin is the origin.
        assert_eq!(t.host_deadline_ns(0, 4.0), t.origin_host_ns);
        // A paced sleep reaches the deadline in simulated time.
        t.sleep_until_ns(1_000 + 400_000);
        assert_eq!(t.now_ns(), Some(401_000));
        assert!(rt::monotonic_ns().unwrap() >= t.origin_host_ns + 100_000);
    }
}
