//! The [`ForceSensor`] conformance checks. Each takes a fresh harness.

use super::{SensorHarness, TareCheck};
use crate::{Error, ErrorKind, ForceSensor, Vec3, WrenchSample};

/// `next` comes after `prev`: its counter moved forward (by less than half the
/// counter's range, allowing the wrap) and it was not received earlier.
pub fn is_newer(prev: &WrenchSample, next: &WrenchSample) -> bool {
    let advance = next.counter.wrapping_sub(prev.counter);
    (1..=u32::MAX / 2).contains(&advance) && next.received_ns >= prev.received_ns
}

fn wait_ok<H: SensorHarness>(h: &mut H) -> WrenchSample {
    let bound = h.arrival_bound_ns();
    match h.sensor().wait(bound) {
        Ok(s) => s,
        Err(e) => panic!(
            "no sample within the arrival bound {bound} ns: {e} ({:?})",
            e.kind()
        ),
    }
}

/// Two polls in a row take no time, and do not return the same sample twice.
pub fn poll_does_not_block_and_returns_each_sample_once<H: SensorHarness>(h: &mut H) {
    h.let_time_pass(h.arrival_bound_ns());
    let before = h.now_ns();
    let first = h.sensor().poll().unwrap();
    let second = h.sensor().poll().unwrap();
    let took = h.now_ns() - before;
    assert!(took <= 2 * h.call_slack_ns(), "two polls took {took} ns");
    let first = first.expect("a sample arrived within the arrival bound");
    if let Some(second) = second {
        assert!(is_newer(&first, &second), "{first:?} then {second:?}");
    }
}

/// Polling faster than the sample rate: every returned sample is newer than
/// the one before (counter forward, received_ns not backwards) and was
/// received no later than the poll returned.
pub fn polled_samples_are_in_order_and_not_from_the_future<H: SensorHarness>(h: &mut H) {
    let step = (h.period_ns() / 3).max(1);
    let mut last: Option<WrenchSample> = None;
    let mut count = 0;
    for _ in 0..90 {
        h.let_time_pass(step);
        let sample = h.sensor().poll().unwrap();
        let now = h.now_ns();
        if let Some(s) = sample {
            assert!(
                s.received_ns <= now,
                "received at {} after now {now}",
                s.received_ns
            );
            if let Some(prev) = &last {
                assert!(is_newer(prev, &s), "{prev:?} then {s:?}");
            }
            last = Some(s);
            count += 1;
        }
    }
    assert!(count >= 10, "only {count} samples in 30 periods");
}

/// After a pause of many periods, one poll gives the newest sample: recent,
/// and with a counter gap for the samples it dropped.
pub fn poll_after_a_pause_returns_the_newest<H: SensorHarness>(h: &mut H) {
    let first = wait_ok(h);
    h.let_time_pass(10 * h.period_ns());
    let s = h
        .sensor()
        .poll()
        .unwrap()
        .expect("samples arrived during the pause");
    let age = h.now_ns() - s.received_ns;
    assert!(
        age <= h.arrival_bound_ns() + h.call_slack_ns(),
        "newest sample {age} ns old"
    );
    assert!(is_newer(&first, &s));
    assert!(
        s.counter.wrapping_sub(first.counter) >= 2,
        "no gap for the dropped samples: {} then {}",
        first.counter,
        s.counter
    );
}

/// `wait` returns a sample newer than the last one returned, within its bound.
pub fn wait_returns_a_newer_sample_within_the_bound<H: SensorHarness>(h: &mut H) {
    let mut last = wait_ok(h);
    for _ in 0..10 {
        let before = h.now_ns();
        let s = wait_ok(h);
        let after = h.now_ns();
        assert!(is_newer(&last, &s), "{last:?} then {s:?}");
        assert!(s.received_ns <= after);
        assert!(after - before <= h.arrival_bound_ns() + h.call_slack_ns());
        last = s;
    }
}

/// `wait` with a short timeout returns a newer sample or a `Timeout`-kind
/// error, and never takes longer than its timeout.
pub fn wait_times_out_within_its_timeout<H: SensorHarness>(h: &mut H) {
    let mut last = wait_ok(h);
    for timeout_ns in [0, 1, h.period_ns() / 4, h.period_ns() / 2] {
        let before = h.now_ns();
        let result = h.sensor().wait(timeout_ns);
        let took = h.now_ns() - before;
        assert!(
            took <= timeout_ns + h.call_slack_ns(),
            "wait({timeout_ns}) took {took} ns"
        );
        match result {
            Ok(s) => {
                assert!(is_newer(&last, &s));
                last = s;
            }
            Err(e) => assert_eq!(e.kind(), ErrorKind::Timeout, "{e}"),
        }
    }
}

/// `poll` after `wait` does not give the waited sample again.
pub fn poll_after_wait_does_not_repeat<H: SensorHarness>(h: &mut H) {
    let s = wait_ok(h);
    if let Some(p) = h.sensor().poll().unwrap() {
        assert!(is_newer(&s, &p));
    }
}

/// `tare` and `clear_tare` succeed when the harness declares a tare, and are
/// `Unsupported` when it declares the tare not applicable; samples keep coming.
pub fn tare_and_clear_tare_are_ok_or_unsupported<H: SensorHarness>(h: &mut H) {
    let _ = wait_ok(h);
    let has_tare = h.tare_check().is_ready();
    for (name, result) in [
        ("tare", h.sensor().tare()),
        ("clear_tare", h.sensor().clear_tare()),
    ] {
        match result {
            Ok(()) => assert!(
                has_tare,
                "{name} succeeded on a device declared without a tare"
            ),
            Err(e) => {
                assert_eq!(e.kind(), ErrorKind::Unsupported, "{name}: {e}");
                assert!(!has_tare, "{name}: {e}, but the harness declares a tare");
            }
        }
    }
    let s = wait_ok(h);
    assert!(s.is_valid());
}

/// The mean force and torque of `n` samples received from now on (the
/// pending one dropped, and `skip_ns` let pass first).
fn mean_reading<H: SensorHarness>(h: &mut H, skip_ns: u64, n: usize) -> (Vec3, Vec3) {
    h.let_time_pass(skip_ns);
    let _ = h.sensor().poll().unwrap();
    let (mut f, mut t) = (Vec3::zeros(), Vec3::zeros());
    for _ in 0..n {
        let s = wait_ok(h);
        assert!(s.is_valid(), "{s:?}");
        f += s.force_n;
        t += s.torque_nm;
    }
    (f / n as f64, t / n as f64)
}

fn assert_near(what: &str, got: &Vec3, want: &Vec3, tolerance: f64) {
    let off = (got - want).amax();
    assert!(
        off <= tolerance,
        "{what}: {got:?}, wanted {want:?} within {tolerance} (off by {off})"
    );
}

/// A tare takes effect: under a steady load, the readings after `tare` are
/// zero (force and torque, within the harness's tolerance), and after
/// `clear_tare` they are back to what they were. The load must read farther
/// from zero than the tolerance, or the check could not tell a tare from none.
pub fn tare_takes_effect_and_clear_tare_undoes_it<H: SensorHarness>(h: &mut H) {
    let Some(TareCheck {
        takes_effect_ns,
        samples,
        tolerance_n,
        tolerance_nm,
    }) = h
        .tare_check()
        .require("tare_takes_effect_and_clear_tare_undoes_it")
    else {
        return;
    };
    assert!(samples > 0 && tolerance_n > 0.0 && tolerance_nm > 0.0);
    let (before_n, before_nm) = mean_reading(h, 0, samples);
    assert!(
        before_n.amax() > 2.0 * tolerance_n,
        "the load reads {before_n:?} N: too close to zero to see a tare (tolerance {tolerance_n} N)"
    );
    h.sensor().tare().unwrap();
    let (tared_n, tared_nm) = mean_reading(h, takes_effect_ns, samples);
    assert_near("force after tare", &tared_n, &Vec3::zeros(), tolerance_n);
    assert_near("torque after tare", &tared_nm, &Vec3::zeros(), tolerance_nm);
    h.sensor().clear_tare().unwrap();
    let (cleared_n, cleared_nm) = mean_reading(h, takes_effect_ns, samples);
    assert_near("force after clear_tare", &cleared_n, &before_n, tolerance_n);
    assert_near(
        "torque after clear_tare",
        &cleared_nm,
        &before_nm,
        tolerance_nm,
    );
}

/// In normal operation samples are valid, and valid means finite.
pub fn samples_are_valid_and_finite_in_normal_operation<H: SensorHarness>(h: &mut H) {
    for _ in 0..20 {
        let s = wait_ok(h);
        assert!(s.is_valid(), "{s:?}");
        assert!(
            s.force_n
                .iter()
                .chain(s.torque_nm.iter())
                .all(|x| x.is_finite())
        );
    }
}

/// `drain` hands over every sample received, once, oldest first, whatever
/// the buffer's size (the rest waits for the next call), and includes every
/// sample `wait` returned meanwhile; nothing is lost in normal operation.
pub fn drain_hands_over_every_sample_once_in_order<H: SensorHarness>(h: &mut H) {
    let filler = wait_ok(h);
    let mut drained = Vec::new();
    // A buffer of 2: most calls leave samples for the next one.
    let mut buf = [filler; 2];
    let mut drain_all = |h: &mut H, drained: &mut Vec<WrenchSample>| {
        for _ in 0..10_000 {
            let d = h.sensor().drain(&mut buf).unwrap();
            assert!(d.count <= buf.len(), "{d:?}");
            assert_eq!(d.lost, 0, "samples lost in normal operation: {d:?}");
            drained.extend_from_slice(&buf[..d.count]);
            if d.remaining == 0 {
                return;
            }
        }
        panic!("drain never emptied");
    };
    drain_all(h, &mut drained);
    let mut waited = Vec::new();
    for _ in 0..6 {
        waited.push(wait_ok(h));
        drain_all(h, &mut drained);
    }
    for pair in drained.windows(2) {
        assert!(
            is_newer(&pair[0], &pair[1]),
            "{:?} then {:?}",
            pair[0],
            pair[1]
        );
    }
    for w in &waited {
        assert!(
            drained.iter().any(|d| d == w),
            "waited sample {} not drained",
            w.counter
        );
    }
    assert!(drained.len() >= waited.len());
    // Nothing more without time passing beyond one arrival.
    let d = h.sensor().drain(&mut buf).unwrap();
    if d.count > 0 {
        assert!(is_newer(drained.last().unwrap(), &buf[0]));
    }
}
