//! Decimation by the cycles' stamps: at most one message per period, keeping
//! the phase (30 Hz on a 1 ms loop is 30 Hz, not one message every 34 ms),
//! starting again after a gap. The recorder's scene (`[record] scene_hz`)
//! and `sar-ros2`'s per-topic rates use it.

/// One decimated stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decimator {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl Decimator {
    /// At most one message every `period_ns` (0: every message).
    pub fn new(period_ns: u64) -> Self {
        Self {
            period_ns,
            next_ns: None,
        }
    }

    /// The period of a rate in Hz (`None` for a rate that is not a positive
    /// number).
    pub fn period_of_hz(hz: f64) -> Option<u64> {
        (hz.is_finite() && hz > 0.0).then(|| (1e9 / hz) as u64)
    }

    /// Whether a message stamped `stamp_ns` is due; if so, the next one is
    /// due a period after the last period boundary at or before it.
    pub fn due(&mut self, stamp_ns: u64) -> bool {
        if self.next_ns.is_some_and(|next| stamp_ns < next) {
            return false;
        }
        let period = self.period_ns.max(1);
        self.next_ns = Some(match self.next_ns {
            Some(next) => next + (stamp_ns - next) / period * period + period,
            None => stamp_ns.saturating_add(period),
        });
        true
    }

    /// Forgets the phase: the next message is due (a restarted source).
    pub fn reset(&mut self) {
        self.next_ns = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_phase_and_restarts_after_a_gap() {
        let mut d = Decimator::new(Decimator::period_of_hz(30.0).unwrap_or(0));
        let period = 33_333_333;
        let due: Vec<u64> = (0..200u64)
            .map(|k| 1_000 + k * 1_000_000)
            .filter(|t| d.due(*t))
            .collect();
        // Every message at or after 1000 + k * period: 0, 34, 67, 100, ... ms.
        let expected: Vec<u64> = (0..6u64)
            .map(|k| 1_000 + (k * period).div_ceil(1_000_000) * 1_000_000)
            .collect();
        assert_eq!(due, expected);
        // A gap of 10 periods: the first message after it is due, and the
        // phase is kept from the last boundary before it.
        assert!(d.due(1_000 + 10 * period + 500));
        assert!(!d.due(1_000 + 10 * period + 600));
        assert!(d.due(1_000 + 11 * period));
        d.reset();
        assert!(d.due(1_000 + 11 * period + 1));
        // Period 0: every message.
        let mut all = Decimator::new(0);
        assert!((0..10).all(|t| all.due(t)));
        assert_eq!(Decimator::period_of_hz(0.0), None);
        assert_eq!(Decimator::period_of_hz(f64::NAN), None);
    }
}
