//! The draining read's store: a fixed ring of samples, filled and emptied on
//! the loop's thread (the driver has no thread of its own), allocated once
//! at connect. When it is full the NEW sample is dropped and counted
//! (`overflows`): the reader only ever sees whole samples it has not seen,
//! in order. No lock, no allocation, no system call.

use sar_hal::{SensorStatus, Vec3, WrenchSample};

/// A slot's content before any sample was written there.
const EMPTY: WrenchSample = WrenchSample {
    force_n: Vec3::new(0.0, 0.0, 0.0),
    torque_nm: Vec3::new(0.0, 0.0, 0.0),
    counter: 0,
    status: SensorStatus::OK,
    received_ns: 0,
};

/// A first-in first-out ring of a fixed number of samples.
#[derive(Debug)]
pub struct Ring {
    slots: Vec<WrenchSample>,
    /// Index of the oldest sample.
    head: usize,
    /// Samples held.
    len: usize,
    /// Samples dropped because the ring was full.
    overflows: u64,
}

impl Ring {
    /// A ring of `capacity` samples (at least 1), allocated here once.
    pub fn new(capacity: usize) -> Self {
        Self {
            slots: vec![EMPTY; capacity.max(1)],
            head: 0,
            len: 0,
            overflows: 0,
        }
    }

    /// Appends `sample`; false, and counted, when full.
    pub fn push(&mut self, sample: &WrenchSample) -> bool {
        let capacity = self.slots.len();
        if self.len >= capacity {
            self.overflows += 1;
            return false;
        }
        let index = (self.head + self.len) % capacity;
        match self.slots.get_mut(index) {
            Some(slot) => {
                *slot = *sample;
                self.len += 1;
                true
            }
            None => {
                self.overflows += 1;
                false
            }
        }
    }

    /// Moves the oldest samples into `out`: how many, and how many remain.
    pub fn pop_into(&mut self, out: &mut [WrenchSample]) -> (usize, usize) {
        let capacity = self.slots.len();
        let mut count = 0;
        for place in out.iter_mut().take(self.len) {
            let Some(slot) = self.slots.get((self.head + count) % capacity) else {
                break;
            };
            *place = *slot;
            count += 1;
        }
        self.head = (self.head + count) % capacity;
        self.len -= count;
        (count, self.len)
    }

    /// Samples dropped so far because the ring was full.
    pub fn overflows(&self) -> u64 {
        self.overflows
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn sample(k: u32) -> WrenchSample {
        let x = f64::from(k);
        WrenchSample {
            force_n: Vec3::new(x, -x, 0.5 * x),
            torque_nm: Vec3::new(x * 1e-3, f64::NAN, -0.0),
            counter: k,
            status: SensorStatus(k ^ 0xDEAD_BEEF),
            received_ns: u64::from(k) * 1000 + 7,
        }
    }

    #[test]
    fn ring_keeps_order_counts_overflow_and_hands_out_in_parts() {
        let mut ring = Ring::new(4);
        for k in 0..6 {
            assert_eq!(ring.push(&sample(k)), k < 4);
        }
        assert_eq!(ring.overflows(), 2);
        let mut out = [sample(99); 3];
        assert_eq!(ring.pop_into(&mut out), (3, 1));
        assert_eq!(out.map(|s| s.counter), [0, 1, 2]);
        assert!(ring.push(&sample(6)));
        assert_eq!(ring.pop_into(&mut out), (2, 0));
        assert_eq!([out[0].counter, out[1].counter], [3, 6]);
        assert_eq!(ring.pop_into(&mut out), (0, 0));
    }

    /// Many rounds around the ring: what comes out is whole (every bit of
    /// the sample pushed), in order, and what is missing is exactly what was
    /// counted as overflow.
    #[test]
    fn ring_wraps_around_and_loses_nothing_uncounted() {
        let mut ring = Ring::new(5);
        let mut out = [sample(0); 3];
        let (mut pushed, mut got) = (0u32, 0u64);
        let mut last: Option<u32> = None;
        for round in 0..1000u32 {
            for _ in 0..(round % 7) {
                ring.push(&sample(pushed));
                pushed += 1;
            }
            let (n, remaining) = ring.pop_into(&mut out);
            assert!(n + remaining <= 5);
            for s in &out[..n] {
                let want = sample(s.counter);
                assert_eq!(s.force_n, want.force_n);
                assert_eq!(s.torque_nm.x.to_bits(), want.torque_nm.x.to_bits());
                assert_eq!((s.status, s.received_ns), (want.status, want.received_ns));
                assert!(last.is_none_or(|l| s.counter > l));
                last = Some(s.counter);
            }
            got += n as u64;
        }
        let mut rest = [sample(0); 8];
        got += ring.pop_into(&mut rest).0 as u64;
        assert!(ring.overflows() > 0);
        assert_eq!(got + ring.overflows(), u64::from(pushed));
    }
}
