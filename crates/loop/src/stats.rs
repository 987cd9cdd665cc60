//! Fixed-size histograms of the loop's timing: one bucket per microsecond up
//! to [`BUCKETS`] µs, the rest in the last bucket; the exact maximum kept.
//! Recording is O(1) and never allocates.

/// Buckets per histogram (1 µs each; the last one holds everything beyond).
pub const BUCKETS: usize = 2048;

/// A histogram of durations, ns in, µs buckets.
#[derive(Debug, Clone)]
pub struct Histogram {
    counts: [u32; BUCKETS],
    total: u64,
    max_ns: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            counts: [0; BUCKETS],
            total: 0,
            max_ns: 0,
        }
    }
}

impl Histogram {
    /// Counts one duration.
    pub fn record(&mut self, ns: u64) {
        let bucket = usize::try_from(ns / 1000)
            .unwrap_or(usize::MAX)
            .min(BUCKETS - 1);
        if let Some(c) = self.counts.get_mut(bucket) {
            *c = c.saturating_add(1);
        }
        self.total = self.total.saturating_add(1);
        self.max_ns = self.max_ns.max(ns);
    }

    /// How many durations were counted.
    pub fn count(&self) -> u64 {
        self.total
    }

    /// The largest duration, ns.
    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// The upper edge of the bucket holding quantile `q` (0..=1), ns; the
    /// maximum for the last bucket; 0 when empty.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.total == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += u64::from(c);
            if seen >= rank {
                return if i == BUCKETS - 1 {
                    self.max_ns
                } else {
                    ((i as u64 + 1) * 1000).min(self.max_ns)
                };
            }
        }
        self.max_ns
    }
}

/// The loop's measurements.
#[derive(Debug, Clone, Default)]
pub struct LoopStats {
    /// Wake-up latency: actual wake-up minus the deadline, ns.
    pub wakeup: Histogram,
    /// Compute time of the cycle body, ns.
    pub compute: Histogram,
    /// Cycles that ended after the next deadline (counted; the whole
    /// periods that passed meanwhile are skipped: `skipped_periods`).
    pub overruns: u64,
    /// Whole periods skipped after overruns (a stall): never run.
    pub skipped_periods: u64,
    /// Cycles run.
    pub cycles: u64,
    /// The cycle of the last overrun.
    pub last_overrun_cycle: Option<u64>,
}

/// An overrun within this many cycles makes the loop unhealthy for the
/// watchdog.
pub const RECENT_CYCLES: u64 = 1000;

impl LoopStats {
    /// Notes an overrun in `cycle`.
    pub fn note_overrun(&mut self, cycle: u64) {
        self.last_overrun_cycle = Some(cycle);
    }

    /// 1 when an overrun happened in the last [`RECENT_CYCLES`] cycles.
    pub fn overruns_recent(&self) -> u64 {
        match self.last_overrun_cycle {
            Some(c) if self.cycles.saturating_sub(c) < RECENT_CYCLES => 1,
            _ => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_come_from_the_buckets_and_the_max_is_exact() {
        let mut h = Histogram::default();
        assert_eq!(h.quantile_ns(0.5), 0);
        for ns in [500, 1_500, 2_500, 3_500] {
            h.record(ns);
        }
        h.record(10_000_000);
        assert_eq!(h.count(), 5);
        assert_eq!(h.quantile_ns(0.5), 3_000);
        assert_eq!(h.quantile_ns(0.2), 1_000);
        assert_eq!(h.quantile_ns(1.0), 10_000_000);
        assert_eq!(h.max_ns(), 10_000_000);
    }
}
