//! The lock-free handoff from the receive thread (the only writer) to the
//! control loop (the only reader), in safe Rust: every shared word is an
//! `AtomicU64` (an `f64` travels as its bits), so there is no data race to
//! reason about, only orderings.
//!
//! - [`Latest`]: a seqlock holding the newest sample. The writer never waits;
//!   the reader retries at most [`READ_TRIES`] times when it meets a write in
//!   progress (a few tens of ns), then reports nothing new for this call.
//! - [`Ring`]: a single-producer single-consumer queue of fixed capacity
//!   for the draining read. When it is full the writer drops the NEW sample
//!   and counts it (`overflows`): the reader only ever sees whole samples it
//!   has not seen, in order.
//!
//! Neither side takes a lock, allocates or makes a system call.

use sar_hal::{SensorStatus, Vec3, WrenchSample};
use std::sync::atomic::{AtomicU64, Ordering, fence};

/// Words of one packed sample: force (3), torque (3), counter and status,
/// received_ns.
const WORDS: usize = 8;

/// How often a reader retries a read that met a write in progress.
pub const READ_TRIES: u32 = 64;

type Slot = [AtomicU64; WORDS];

fn new_slot() -> Slot {
    std::array::from_fn(|_| AtomicU64::new(0))
}

fn pack(s: &WrenchSample) -> [u64; WORDS] {
    [
        s.force_n.x.to_bits(),
        s.force_n.y.to_bits(),
        s.force_n.z.to_bits(),
        s.torque_nm.x.to_bits(),
        s.torque_nm.y.to_bits(),
        s.torque_nm.z.to_bits(),
        (u64::from(s.counter) << 32) | u64::from(s.status.0),
        s.received_ns,
    ]
}

fn unpack(w: [u64; WORDS]) -> WrenchSample {
    let [fx, fy, fz, tx, ty, tz, counter_status, received_ns] = w;
    WrenchSample {
        force_n: Vec3::new(f64::from_bits(fx), f64::from_bits(fy), f64::from_bits(fz)),
        torque_nm: Vec3::new(f64::from_bits(tx), f64::from_bits(ty), f64::from_bits(tz)),
        // The shift and the mask make both halves fit their u32.
        counter: u32::try_from(counter_status >> 32).unwrap_or(u32::MAX),
        status: SensorStatus(u32::try_from(counter_status & 0xFFFF_FFFF).unwrap_or(u32::MAX)),
        received_ns,
    }
}

fn store(slot: &Slot, words: [u64; WORDS]) {
    for (atom, word) in slot.iter().zip(words) {
        atom.store(word, Ordering::Relaxed);
    }
}

fn load(slot: &Slot) -> [u64; WORDS] {
    let mut words = [0u64; WORDS];
    for (word, atom) in words.iter_mut().zip(slot) {
        *word = atom.load(Ordering::Relaxed);
    }
    words
}

/// The newest sample (a seqlock). One writer thread, one reader thread.
#[derive(Debug)]
pub struct Latest {
    /// Odd while a write is in progress; otherwise twice the number of
    /// samples published.
    seq: AtomicU64,
    words: Slot,
}

impl Default for Latest {
    fn default() -> Self {
        Self {
            seq: AtomicU64::new(0),
            words: new_slot(),
        }
    }
}

impl Latest {
    /// Publishes `sample` (writer only). Never waits.
    pub fn publish(&self, sample: &WrenchSample) {
        let seq = self.seq.load(Ordering::Relaxed);
        self.seq.store(seq.wrapping_add(1), Ordering::Relaxed);
        // Orders the odd mark before the data: a reader that sees any new
        // word also sees the mark (through its acquire fence).
        fence(Ordering::Release);
        store(&self.words, pack(sample));
        self.seq.store(seq.wrapping_add(2), Ordering::Release);
    }

    /// The newest sample with its publication number (even, > 0), `None`
    /// when none was published yet or every try met a write in progress.
    pub fn read(&self) -> Option<(u64, WrenchSample)> {
        for _ in 0..READ_TRIES {
            let before = self.seq.load(Ordering::Acquire);
            if before & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            if before == 0 {
                return None;
            }
            let words = load(&self.words);
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == before {
                return Some((before, unpack(words)));
            }
        }
        None
    }
}

/// A single-producer single-consumer queue of fixed capacity.
#[derive(Debug)]
pub struct Ring {
    slots: Box<[Slot]>,
    /// Samples ever pushed (written by the producer).
    head: AtomicU64,
    /// Samples ever popped (written by the consumer).
    tail: AtomicU64,
    /// Samples dropped because the ring was full.
    overflows: AtomicU64,
}

impl Ring {
    /// A ring of `capacity` samples (at least 1), allocated here once.
    pub fn new(capacity: usize) -> Self {
        Self {
            slots: (0..capacity.max(1)).map(|_| new_slot()).collect(),
            head: AtomicU64::new(0),
            tail: AtomicU64::new(0),
            overflows: AtomicU64::new(0),
        }
    }

    fn slot(&self, index: u64) -> Option<&Slot> {
        let len = u64::try_from(self.slots.len()).ok()?;
        self.slots.get(usize::try_from(index % len).ok()?)
    }

    fn capacity(&self) -> u64 {
        u64::try_from(self.slots.len()).unwrap_or(u64::MAX)
    }

    /// Appends `sample` (producer only); false, and counted, when full.
    pub fn push(&self, sample: &WrenchSample) -> bool {
        let head = self.head.load(Ordering::Relaxed);
        // Acquire: the consumer's reads of a slot happen before we reuse it.
        let tail = self.tail.load(Ordering::Acquire);
        match self.slot(head) {
            Some(slot) if head.wrapping_sub(tail) < self.capacity() => {
                store(slot, pack(sample));
                self.head.store(head.wrapping_add(1), Ordering::Release);
                true
            }
            _ => {
                self.overflows.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Moves the oldest samples into `out` (consumer only): how many, and
    /// how many remain.
    pub fn pop_into(&self, out: &mut [WrenchSample]) -> (usize, usize) {
        let tail = self.tail.load(Ordering::Relaxed);
        let head = self.head.load(Ordering::Acquire);
        let available = head.wrapping_sub(tail);
        let mut count: u64 = 0;
        for (place, index) in out.iter_mut().zip(tail..head) {
            let Some(slot) = self.slot(index) else { break };
            *place = unpack(load(slot));
            count += 1;
        }
        self.tail.store(tail.wrapping_add(count), Ordering::Release);
        (
            usize::try_from(count).unwrap_or(usize::MAX),
            usize::try_from(available - count).unwrap_or(usize::MAX),
        )
    }

    /// Samples dropped so far because the ring was full.
    pub fn overflows(&self) -> u64 {
        self.overflows.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use std::sync::Arc;

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
    fn packing_keeps_every_bit() {
        for k in [0, 1, 77, u32::MAX] {
            let s = sample(k);
            let back = unpack(pack(&s));
            assert_eq!(pack(&back), pack(&s));
            assert_eq!(back.counter, k);
            assert_eq!(back.status, s.status);
        }
    }

    #[test]
    fn ring_keeps_order_counts_overflow_and_hands_out_in_parts() {
        let ring = Ring::new(4);
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

    /// A writer thread publishing while the reader reads: every read is a
    /// whole sample (all its words from the same publication), and
    /// publication numbers never go back.
    #[test]
    fn seqlock_reads_are_never_torn() {
        let latest = Arc::new(Latest::default());
        let writer = {
            let latest = Arc::clone(&latest);
            std::thread::spawn(move || {
                for k in 1..=200_000u32 {
                    latest.publish(&sample(k));
                }
            })
        };
        let mut last_seq = 0;
        let mut reads = 0u64;
        while !writer.is_finished() || reads == 0 {
            if let Some((seq, s)) = latest.read() {
                assert!(seq >= last_seq);
                last_seq = seq;
                assert_eq!(pack(&s), pack(&sample(s.counter)), "torn read");
                reads += 1;
            }
        }
        writer.join().unwrap();
        assert_eq!(latest.read().unwrap().1.counter, 200_000);
    }

    /// The same for the ring: a producer pushing 0, 1, 2, ... while the
    /// consumer drains: what comes out is in order, whole, and what is
    /// missing is exactly what was counted as overflow.
    #[test]
    fn ring_under_concurrency_loses_nothing_uncounted() {
        let ring = Arc::new(Ring::new(16));
        let total = 100_000u32;
        let producer = {
            let ring = Arc::clone(&ring);
            std::thread::spawn(move || {
                for k in 0..total {
                    ring.push(&sample(k));
                }
            })
        };
        let mut out = [sample(0); 5];
        let mut got = 0u64;
        let mut last: Option<u32> = None;
        loop {
            let done = producer.is_finished();
            let (n, _) = ring.pop_into(&mut out);
            for s in &out[..n] {
                assert_eq!(pack(s), pack(&sample(s.counter)), "torn slot");
                assert!(last.is_none_or(|l| s.counter > l));
                last = Some(s.counter);
            }
            got += n as u64;
            if done && n == 0 {
                break;
            }
        }
        producer.join().unwrap();
        assert_eq!(got + ring.overflows(), u64::from(total));
    }
}
