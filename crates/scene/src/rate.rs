//! Decimation by the cycles' stamps: at most one message per period, the
//! first at once, then the first at or after each multiple of the period of
//! the monotonic clock (30 Hz on a 1 ms loop is 30 Hz, not one message
//! every 34 ms; after a gap, the first message after it). Aligned to the
//! clock, not to the first message, so that two streams of the same cycles
//! (a recording and the ROS 2 bridge, which joins later) pick the same
//! cycles. The recorder's scene (`[record] scene_hz`) and `sar-ros2`'s
//! per-topic rates use it.

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
        (hz.is_finite() && hz > 0.0).then(|| (1e9 / hz).round() as u64)
    }

    /// Whether a message stamped `stamp_ns` is due; if so, the next one is
    /// due at the next multiple of the period after it.
    pub fn due(&mut self, stamp_ns: u64) -> bool {
        if self.next_ns.is_some_and(|next| stamp_ns < next) {
            return false;
        }
        let period = self.period_ns.max(1);
        self.next_ns = Some((stamp_ns / period).saturating_add(1).saturating_mul(period));
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
    fn the_first_at_once_then_one_per_multiple_of_the_period() {
        let period = Decimator::period_of_hz(30.0).unwrap_or(0);
        assert_eq!(period, 33_333_333);
        let mut d = Decimator::new(period);
        let stamps: Vec<u64> = (0..200u64).map(|k| 1_000 + k * 1_000_000).collect();
        let due: Vec<u64> = stamps.iter().copied().filter(|t| d.due(*t)).collect();
        // The first, then the first stamp at or after each multiple.
        let mut expected = vec![1_000];
        for m in 1..=5u64 {
            expected.push(*stamps.iter().find(|t| **t >= m * period).unwrap_or(&0));
        }
        assert_eq!(due, expected);
        assert_eq!(due[1], 34_001_000);
        // Another stream of the same stamps that starts later picks the
        // same ones from its second message on.
        let mut late = Decimator::new(period);
        let picked: Vec<u64> = stamps[50..]
            .iter()
            .copied()
            .filter(|t| late.due(*t))
            .collect();
        assert_eq!(picked[0], stamps[50]);
        assert_eq!(&picked[1..], &due[2..]);
        // After a gap of ten periods: the first message after it, then the
        // next multiple.
        assert!(d.due(10 * period + 500));
        assert!(!d.due(10 * period + 600));
        assert!(!d.due(11 * period - 1));
        assert!(d.due(11 * period));
        d.reset();
        assert!(d.due(11 * period + 1));
        // Period 0: every message.
        let mut all = Decimator::new(0);
        assert!((0..10).all(|t| all.due(t)));
        assert_eq!(Decimator::period_of_hz(0.0), None);
        assert_eq!(Decimator::period_of_hz(f64::NAN), None);
    }
}
