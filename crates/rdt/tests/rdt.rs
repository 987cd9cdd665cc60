//! The RDT driver over real loopback sockets (127.0.0.1 only) against the
//! device emulator: the sensor conformance suite, then loss, reordering,
//! duplicates, status faults, silence and restart, the commands and their
//! packing, and the draining read's bounds.
//!
//! No sleep decides a result: the emulator's manual pacing makes exactly the
//! packets a test wants, and the test waits for them with bounded waits
//! (`wait`, the emulator's condition variable) whose generous timeouts only
//! matter when something is broken.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_hal::conformance;

use conformance::{Capability, SensorHarness, TareCheck};
use sar_hal::{Clock, Error, ErrorKind, ForceSensor, MonotonicClock, Rail, WrenchSample};
use sar_rdt::codec::{CMD_BIAS, CMD_FILTER, CMD_RATE, Request, Response};
use sar_rdt::emulator::{
    Action, Emulator, EmulatorConfig, HEX_E_RANGE_COUNTS, Pacing, SensorFault, counts_for,
};
use sar_rdt::{Filter, Flavour, RdtConfig, RdtError, RdtSensor, SilenceCause};
use std::time::Duration;

/// Host time, ns: the one place this file reads the clock.
fn now_ns(clock: &MonotonicClock) -> u64 {
    clock.now_ns().unwrap()
}

const MS: u64 = 1_000_000;
/// The bound of every wait that only a broken driver reaches.
const PATIENCE: Duration = Duration::from_secs(10);
const PATIENCE_NS: u64 = 10_000_000_000;

fn config(emulator: &Emulator) -> RdtConfig {
    RdtConfig {
        // Generous: a loaded test machine must not look silent.
        silence_limit_ns: 2_000 * MS,
        restart_interval_ns: 50 * MS,
        ..RdtConfig::new(emulator.address(), 10_000.0, 100_000.0)
    }
}

/// A manual emulator with `script`, a driver connected to it, its stream started.
fn manual(script: Vec<(u64, Action)>) -> (Emulator, RdtSensor) {
    manual_with(
        EmulatorConfig {
            script,
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    )
}

fn manual_with(
    emulator: EmulatorConfig,
    make: impl Fn(&Emulator) -> RdtConfig,
) -> (Emulator, RdtSensor) {
    let emulator = Emulator::start(emulator).unwrap();
    let sensor = RdtSensor::connect(make(&emulator)).unwrap();
    assert!(emulator.wait_for_starts(1, PATIENCE), "no start request");
    (emulator, sensor)
}

fn filler() -> WrenchSample {
    WrenchSample {
        force_n: Default::default(),
        torque_nm: Default::default(),
        counter: 0,
        status: Default::default(),
        received_ns: 0,
    }
}

/// Waits (bounded) until the newest sample has counter `counter`, then
/// drains everything: the drained samples.
fn collect_until(sensor: &mut RdtSensor, counter: u32) -> Vec<WrenchSample> {
    let mut newest = None;
    while newest != Some(counter) {
        let s = sensor
            .wait(PATIENCE_NS)
            .unwrap_or_else(|e| panic!("waiting for counter {counter}: {e}"));
        newest = Some(s.counter);
    }
    let mut buf = [filler(); 256];
    let d = sensor.drain(&mut buf).unwrap();
    assert_eq!((d.lost, d.remaining), (0, 0), "{d:?}");
    buf[..d.count].to_vec()
}

fn counters(samples: &[WrenchSample]) -> Vec<u32> {
    samples.iter().map(|s| s.counter).collect()
}

// ---------------------------------------------------------------------------
// Conformance, against a periodic emulator at 1 kHz

struct RdtHarness {
    // Field order: the driver drops (and stops its stream) before the device.
    sensor: RdtSensor,
    _emulator: Emulator,
    clock: MonotonicClock,
}

impl RdtHarness {
    fn new() -> Self {
        let emulator =
            Emulator::start(EmulatorConfig::new(Pacing::Periodic { period_ns: MS })).unwrap();
        let sensor = RdtSensor::connect(RdtConfig {
            // The driver asks for 1 kHz: the emulator honours the rate command.
            rate_hz: Some(1000),
            ..config(&emulator)
        })
        .unwrap();
        assert!(emulator.wait_for_starts(1, PATIENCE));
        Self {
            sensor,
            _emulator: emulator,
            clock: MonotonicClock::new().unwrap(),
        }
    }
}

impl SensorHarness for RdtHarness {
    type Sensor = RdtSensor;
    fn sensor(&mut self) -> &mut RdtSensor {
        &mut self.sensor
    }
    fn let_time_pass(&mut self, ns: u64) {
        std::thread::sleep(Duration::from_nanos(ns));
    }
    fn now_ns(&self) -> u64 {
        now_ns(&self.clock)
    }
    fn period_ns(&self) -> u64 {
        MS
    }
    /// Real time on a shared 2-core machine: generous.
    fn arrival_bound_ns(&self) -> u64 {
        500 * MS
    }
    fn call_slack_ns(&self) -> u64 {
        100 * MS
    }
    /// The emulator's default reading (1.25, -2.5, 9.8 N; 0.01, -0.02, 0.03 N m)
    /// is noise-free and its OnRobot bias is exact in counts: a tare must read
    /// zero to the count, and a clear_tare give the reading back.
    fn tare_check(&self) -> Capability<TareCheck> {
        Capability::Ready(TareCheck {
            // The command crosses the socket before the next samples: a few
            // periods, generous for a loaded machine.
            takes_effect_ns: 50 * MS,
            samples: 5,
            tolerance_n: 1e-3,
            tolerance_nm: 1e-4,
        })
    }
}

macro_rules! conformance_tests {
    ($($check:ident),* $(,)?) => {
        mod sensor_conformance {
            use super::*;
            $(
                #[test]
                fn $check() {
                    conformance::sensor::$check(&mut RdtHarness::new());
                }
            )*
        }
    };
}

conformance_tests!(
    poll_does_not_block_and_returns_each_sample_once,
    polled_samples_are_in_order_and_not_from_the_future,
    poll_after_a_pause_returns_the_newest,
    wait_returns_a_newer_sample_within_the_bound,
    wait_times_out_within_its_timeout,
    poll_after_wait_does_not_repeat,
    tare_and_clear_tare_are_ok_or_unsupported,
    tare_takes_effect_and_clear_tare_undoes_it,
    samples_are_valid_and_finite_in_normal_operation,
    drain_hands_over_every_sample_once_in_order,
);

// ---------------------------------------------------------------------------
// Stream behaviour, with manual pacing

#[test]
fn counts_are_scaled_and_stamped_with_the_host_clock() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.set_counts([10_000, -25_000, 3, 100_000, -50_000, 7]);
    let clock = MonotonicClock::new().unwrap();
    let before = now_ns(&clock);
    assert_eq!(emulator.step(1), 1);
    let s = sensor.wait(PATIENCE_NS).unwrap();
    let after = now_ns(&clock);
    assert_eq!(s.force_n.as_slice(), &[1.0, -2.5, 3e-4]);
    assert_eq!(s.torque_nm.as_slice(), &[1.0, -0.5, 7e-5]);
    assert_eq!(s.counter, 1001);
    assert!(s.is_valid());
    assert!(
        (before..=after).contains(&s.received_ns),
        "{before} {s:?} {after}"
    );
    assert_eq!(sensor.poll().unwrap(), None, "the same sample twice");
}

#[test]
fn duplicates_are_dropped() {
    let (emulator, mut sensor) = manual(vec![(1, Action::Duplicate), (3, Action::Duplicate)]);
    emulator.step(5);
    let got = collect_until(&mut sensor, 1005);
    assert_eq!(counters(&got), [1001, 1002, 1003, 1004, 1005]);
    let stats = sensor.stats();
    assert_eq!((stats.duplicates, stats.lost, stats.accepted), (2, 0, 5));
}

#[test]
fn a_reordered_packet_is_dropped_and_its_gap_counted() {
    // Packet 2 comes after packet 3: 1001, 1002, 1004, (1003 late), 1005.
    let (emulator, mut sensor) = manual(vec![(2, Action::SwapWithNext)]);
    emulator.step(5);
    let got = collect_until(&mut sensor, 1005);
    assert_eq!(counters(&got), [1001, 1002, 1004, 1005]);
    let stats = sensor.stats();
    assert_eq!((stats.reordered, stats.lost), (1, 1), "{stats:?}");
}

#[test]
fn losses_are_counted_and_show_as_counter_gaps() {
    let (emulator, mut sensor) = manual(vec![
        (1, Action::Drop),
        (4, Action::Drop),
        (5, Action::Drop),
    ]);
    emulator.step(8);
    let got = collect_until(&mut sensor, 1008);
    assert_eq!(counters(&got), [1001, 1003, 1004, 1007, 1008]);
    assert_eq!(sensor.stats().lost, 3);
}

#[test]
fn a_fault_status_makes_that_sample_invalid() {
    let (emulator, mut sensor) = manual(vec![(1, Action::Status(0x8000_0004))]);
    emulator.step(3);
    let got = collect_until(&mut sensor, 1003);
    assert_eq!(counters(&got), [1001, 1002, 1003]);
    assert!(got[0].is_valid());
    assert!(!got[1].is_valid());
    assert_eq!(got[1].status.0, 0x8000_0004);
    assert!(got[2].is_valid());
    assert_eq!(sensor.stats().faults, 1);
}

// ---------------------------------------------------------------------------
// Failures of the sensor itself

/// The HEX-E's noise at OnRobot's scale, counts.
const HEX_NOISE_COUNTS: [f64; 6] = [2000.0, 2000.0, 8000.0, 1000.0, 1000.0, 200.0];

/// A live (noisy) manual emulator with `faults`, a driver connected to it.
fn live(faults: Vec<SensorFault>, seed: u64) -> (Emulator, RdtSensor) {
    manual_with(
        EmulatorConfig {
            noise_counts: HEX_NOISE_COUNTS,
            seed,
            faults,
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    )
}

fn bits(s: &WrenchSample) -> Vec<u64> {
    s.force_n
        .iter()
        .chain(s.torque_nm.iter())
        .map(|x| x.to_bits())
        .collect()
}

/// Packets `0..n` of a device, as samples (counters 1001..=1000 + n).
fn packets(emulator: &Emulator, sensor: &mut RdtSensor, n: u64) -> Vec<WrenchSample> {
    assert_eq!(emulator.step(n), n);
    let got = collect_until(sensor, 1000 + u32::try_from(n).unwrap());
    assert_eq!(got.len() as u64, n, "{:?}", counters(&got));
    got
}

#[test]
fn a_live_device_is_noisy_and_its_noise_is_seeded() {
    let (emulator, mut sensor) = live(vec![], 7);
    let a = packets(&emulator, &mut sensor, 50);
    for w in a.windows(2) {
        assert_ne!(
            bits(&w[0]),
            bits(&w[1]),
            "a live sensor never repeats itself"
        );
    }
    let std_fz = {
        let mean = a.iter().map(|s| s.force_n.z).sum::<f64>() / 50.0;
        (a.iter().map(|s| (s.force_n.z - mean).powi(2)).sum::<f64>() / 49.0).sqrt()
    };
    assert!(
        (0.4..1.6).contains(&std_fz),
        "Fz noise {std_fz} N (0.8 N specified)"
    );
    let (emulator, mut sensor) = live(vec![], 7);
    let b = packets(&emulator, &mut sensor, 50);
    let (emulator, mut sensor) = live(vec![], 8);
    let c = packets(&emulator, &mut sensor, 50);
    for ((x, y), z) in a.iter().zip(&b).zip(&c) {
        assert_eq!(bits(x), bits(y), "same seed, same counts");
        assert_ne!(bits(x), bits(z), "another seed, other counts");
    }
}

#[test]
fn a_frozen_device_repeats_its_counts_while_its_sequence_and_counter_run() {
    let (emulator, mut sensor) = live(
        vec![SensorFault::Frozen {
            from: 5,
            until: Some(15),
        }],
        1,
    );
    let got = packets(&emulator, &mut sensor, 20);
    assert_eq!(counters(&got), (1001..=1020).collect::<Vec<_>>());
    // The RDT sequence ran on too: nothing was lost or dropped as a duplicate.
    let stats = sensor.stats();
    assert_eq!((stats.lost, stats.duplicates, stats.accepted), (0, 0, 20));
    for s in &got[5..15] {
        assert_eq!(bits(s), bits(&got[4]), "packet {}", s.counter - 1001);
        assert!(s.is_valid(), "a frozen sensor says all is well");
    }
    for w in got[..5].windows(2).chain(got[15..].windows(2)) {
        assert_ne!(bits(&w[0]), bits(&w[1]));
    }
    assert_ne!(bits(&got[15]), bits(&got[4]));
}

#[test]
fn the_range_clips_and_a_saturated_channel_reads_the_end_of_it() {
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            faults: vec![SensorFault::Saturated {
                from: 2,
                until: Some(4),
                channels: [false, false, false, true, false, true],
                rail: Some(Rail::Negative),
            }],
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    );
    // 250 N on Fz: beyond the HEX-E's 200 N.
    emulator.set_counts([12_500, -25_000, 2_500_000, 1_000, -2_000, 3_000]);
    let got = packets(&emulator, &mut sensor, 6);
    assert_eq!(HEX_E_RANGE_COUNTS[2], 2_000_000);
    for (i, s) in got.iter().enumerate() {
        assert_eq!(s.force_n.z, 200.0, "clipped at the range");
        assert_eq!((s.force_n.x, s.force_n.y), (1.25, -2.5));
        if (2..4).contains(&i) {
            assert_eq!(
                (s.torque_nm.x, s.torque_nm.z),
                (-10.0, -13.0),
                "at the rail"
            );
        } else {
            assert_eq!((s.torque_nm.x, s.torque_nm.z), (0.01, 0.03));
        }
        assert_eq!(s.torque_nm.y, -0.02);
    }
}

#[test]
fn a_spike_is_in_exactly_its_packets() {
    let (emulator, mut sensor) = manual(vec![]);
    // Added at run time, keyed on the packets produced so far.
    emulator.add_fault(SensorFault::Spike {
        at: emulator.produced() + 3,
        counts: [0, 0, 300_000, 0, 5_000, 0],
        packets: 2,
    });
    let got = packets(&emulator, &mut sensor, 7);
    let spiked: Vec<u32> = got
        .iter()
        .filter(|s| s.force_n.z != 9.8066)
        .map(|s| s.counter)
        .collect();
    assert_eq!(spiked, [1004, 1005]);
    for s in &got[3..5] {
        assert!((s.force_n.z - 39.8066).abs() < 1e-9);
        assert!((s.torque_nm.y - 0.03).abs() < 1e-12);
    }
}

#[test]
fn a_drift_grows_linearly_from_its_packet() {
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            faults: vec![SensorFault::Drift {
                from: 2,
                counts_per_packet: [100.0, 0.0, -50.0, 0.0, 0.0, 10.0],
            }],
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    );
    let got = packets(&emulator, &mut sensor, 10);
    for (i, s) in got.iter().enumerate() {
        let packets = i.saturating_sub(2) as f64;
        assert!((s.force_n.x - (1.25 + 0.01 * packets)).abs() < 1e-9, "{i}");
        assert!(
            (s.force_n.z - (9.8066 - 0.005 * packets)).abs() < 1e-9,
            "{i}"
        );
        assert!(
            (s.torque_nm.z - (0.03 + 1e-4 * packets)).abs() < 1e-12,
            "{i}"
        );
    }
}

#[test]
fn a_gain_error_and_a_wrong_counts_per_newton_scale_the_reading() {
    let wrench = ([3.0, -4.0, 12.0], [0.2, -0.1, 0.05]);
    // A device with 10 % more counts per newton than the host's 10 000.
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            counts: counts_for(wrench.0, wrench.1, 11_000.0, 110_000.0),
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    );
    let s = &packets(&emulator, &mut sensor, 1)[0];
    assert!((s.force_n - nalgebra::Vector3::from(wrench.0) * 1.1).amax() < 1e-9);
    assert!((s.torque_nm - nalgebra::Vector3::from(wrench.1) * 1.1).amax() < 1e-9);
    // A gain error from packet 2 on.
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            counts: counts_for(wrench.0, wrench.1, 10_000.0, 100_000.0),
            faults: vec![SensorFault::Scale {
                from: 2,
                factor: 0.9,
            }],
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    );
    let got = packets(&emulator, &mut sensor, 4);
    for (i, s) in got.iter().enumerate() {
        let gain = if i < 2 { 1.0 } else { 0.9 };
        assert!(
            (s.force_n - nalgebra::Vector3::from(wrench.0) * gain).amax() < 1e-9,
            "{i}: {s:?}"
        );
    }
}

#[test]
fn malformed_datagrams_are_counted_and_skipped() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.step(1);
    collect_until(&mut sensor, 1001);
    assert!(emulator.send_raw(&[0u8; 35]));
    assert!(emulator.send_raw(&[0u8; 37]));
    assert!(emulator.send_raw(&[]));
    emulator.step(1);
    let got = collect_until(&mut sensor, 1002);
    assert_eq!(counters(&got), [1002]);
    assert_eq!(sensor.stats().malformed, 3);
}

/// The device goes mute (its stream ends): past the silence limit, `poll`
/// fails with kind Disconnected, the driver sends start again, and once the
/// device streams again the samples are valid and `poll` succeeds.
#[test]
fn silence_fails_poll_and_the_stream_is_restarted() {
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            script: vec![(2, Action::Mute)],
            ..EmulatorConfig::new(Pacing::Manual)
        },
        |e| RdtConfig {
            silence_limit_ns: 30 * MS,
            restart_interval_ns: 30 * MS,
            ..config(e)
        },
    );
    emulator.step(3);
    assert_eq!(counters(&collect_until(&mut sensor, 1002)), [1001, 1002]);
    assert!(!emulator.is_streaming());
    // Bounded: polls until the driver declares the silence.
    let clock = MonotonicClock::new().unwrap();
    let deadline = now_ns(&clock) + PATIENCE_NS;
    let error = loop {
        match sensor.poll() {
            Ok(None) => {}
            Ok(Some(s)) => panic!("a sample from a mute device: {s:?}"),
            Err(e) => break e,
        }
        assert!(now_ns(&clock) < deadline, "silence never declared");
        std::thread::sleep(Duration::from_millis(1));
    };
    assert_eq!(error.kind(), ErrorKind::Disconnected, "{error}");
    assert!(sensor.is_silent());
    assert_eq!(sensor.wait(0).unwrap_err().kind(), ErrorKind::Disconnected);
    // The driver restarts the stream; the device answers.
    assert!(emulator.wait_for_starts(2, PATIENCE), "no restart");
    assert!(emulator.is_streaming());
    emulator.step(2);
    // Packet 2 was the mute one: the new stream carries 1004 and 1005.
    let got = collect_until(&mut sensor, 1005);
    assert_eq!(counters(&got), [1004, 1005]);
    assert!(got.iter().all(WrenchSample::is_valid));
    assert_eq!(sensor.poll().unwrap(), None);
    assert!(!sensor.is_silent());
    let stats = sensor.stats();
    assert!(stats.restarts >= 1 && stats.silences >= 1, "{stats:?}");
    // The new stream's RDT sequence restarted at 1: not taken as late.
    assert_eq!(
        (stats.reordered, stats.duplicates, stats.resyncs),
        (0, 0, 0)
    );
}

/// The device restarts its stream on its own (sequence back to 1, counter
/// going on): the jump back beyond the reorder window is a resync, not a
/// flood of late packets. (A restart within the first `REORDER_WINDOW`
/// packets of a stream would drop that many: the driver cannot tell it
/// from reordering.)
#[test]
fn a_stream_restarted_by_the_device_is_followed() {
    let (emulator, mut sensor) = manual(vec![(100, Action::RestartStream)]);
    emulator.step(103);
    let got = collect_until(&mut sensor, 1103);
    assert_eq!(counters(&got), (1001..=1103).collect::<Vec<_>>());
    let stats = sensor.stats();
    assert_eq!(
        (stats.resyncs, stats.reordered, stats.lost),
        (1, 0, 0),
        "{stats:?}"
    );
}

#[test]
fn counters_wrap_without_a_gap_or_a_drop() {
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            first_counter: u32::MAX - 2,
            ..EmulatorConfig::new(Pacing::Manual)
        },
        config,
    );
    emulator.step(5);
    let got = collect_until(&mut sensor, 2);
    assert_eq!(counters(&got), [u32::MAX - 1, u32::MAX, 0, 1, 2]);
    let stats = sensor.stats();
    assert_eq!(
        (stats.accepted, stats.lost, stats.reordered, stats.resyncs),
        (5, 0, 0, 0)
    );
}

/// The socket is connected to the sensor: a well-formed packet from any
/// other address never becomes a sample.
#[test]
fn packets_from_another_address_are_ignored() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.step(1);
    collect_until(&mut sensor, 1001);
    let stranger = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let forged = Response {
        rdt_sequence: 2,
        sample_counter: 1002,
        status: 0,
        counts: [1_000_000; 6],
    };
    stranger
        .send_to(&forged.encode(), sensor.local_address().unwrap())
        .unwrap();
    emulator.step(2);
    let got = collect_until(&mut sensor, 1003);
    assert_eq!(counters(&got), [1002, 1003]);
    assert!(got.iter().all(|s| s.force_n.x == 1.25), "{got:?}");
    let stats = sensor.stats();
    assert_eq!(
        (stats.accepted, stats.duplicates, stats.malformed),
        (3, 0, 0)
    );
}

#[test]
fn a_sample_count_stops_the_stream() {
    let (emulator, _sensor) = manual(vec![]);
    let client = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    client.connect(emulator.address()).unwrap();
    client.send(&Request::start(3).encode()).unwrap();
    assert!(emulator.wait_for_starts(2, PATIENCE));
    assert_eq!(emulator.step(5), 3);
    assert!(!emulator.is_streaming());
}

// ---------------------------------------------------------------------------
// Commands

/// The requests the emulator received after the start-up ones.
fn requests_after_startup(emulator: &Emulator, startup: usize, expect: usize) -> Vec<Request> {
    assert!(emulator.wait_for_datagrams(startup + expect, PATIENCE));
    emulator.requests()[startup..].to_vec()
}

#[test]
fn start_up_sends_rate_filter_and_start_packed_as_big_endian_u32() {
    let (emulator, sensor) = manual_with(EmulatorConfig::new(Pacing::Manual), |e| RdtConfig {
        filter: Some(Filter::Hz15),
        rate_hz: Some(1),
        ..config(e)
    });
    let datagrams = emulator.datagrams();
    assert_eq!(
        datagrams,
        [
            vec![0x12, 0x34, 0x00, 0x81, 0, 0, 0, 4],
            // 1 Hz: data 1000 = 0x03E8 in the low bytes (not 03 E8 03 E8).
            vec![0x12, 0x34, 0x00, 0x82, 0, 0, 0x03, 0xE8],
            vec![0x12, 0x34, 0x00, 0x02, 0, 0, 0, 0],
        ]
    );
    assert_eq!(emulator.filter_code(), Some(4));
    drop(sensor);
    // Dropping the driver stops the stream.
    assert!(emulator.wait_for_datagrams(4, PATIENCE));
    assert_eq!(emulator.requests()[3], Request::stop());
    assert!(!emulator.is_streaming());
}

#[test]
fn onrobot_bias_filter_and_rate_commands() {
    let (emulator, mut sensor) = manual(vec![]);
    let startup = emulator.datagrams().len();
    sensor.tare().unwrap();
    sensor.clear_tare().unwrap();
    sensor.set_filter(Filter::Hz1_5).unwrap();
    sensor.set_rate_hz(250).unwrap();
    assert_eq!(
        sensor.set_rate_hz(1001).unwrap_err().kind(),
        ErrorKind::InvalidArgument
    );
    let got = requests_after_startup(&emulator, startup, 4);
    assert_eq!(
        got,
        [
            Request {
                command: CMD_BIAS,
                data: 0xFF
            },
            Request {
                command: CMD_BIAS,
                data: 0x00
            },
            Request {
                command: CMD_FILTER,
                data: 6
            },
            Request {
                command: CMD_RATE,
                data: 4
            },
        ]
    );
    assert_eq!(sensor.config().rate_hz, Some(250));
}

#[test]
fn onrobot_tare_zeroes_the_reading_and_clear_tare_restores_it() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.step(1);
    let raw = sensor.wait(PATIENCE_NS).unwrap();
    assert!(raw.force_n.norm() > 1.0);
    let sent = emulator.datagrams().len();
    sensor.tare().unwrap();
    assert!(emulator.wait_for_datagrams(sent + 1, PATIENCE));
    emulator.step(1);
    let tared = sensor.wait(PATIENCE_NS).unwrap();
    assert_eq!(tared.force_n.norm() + tared.torque_nm.norm(), 0.0);
    sensor.clear_tare().unwrap();
    assert!(emulator.wait_for_datagrams(sent + 2, PATIENCE));
    emulator.step(1);
    let back = sensor.wait(PATIENCE_NS).unwrap();
    assert_eq!((back.force_n, back.torque_nm), (raw.force_n, raw.torque_nm));
}

#[test]
fn ati_has_a_one_shot_bias_and_no_filter_rate_or_clear_tare() {
    let (emulator, mut sensor) = manual_with(
        EmulatorConfig {
            flavour: Flavour::Ati,
            ..EmulatorConfig::new(Pacing::Manual)
        },
        |e| RdtConfig::ati(e.address(), 1_000_000.0, 1_000_000.0),
    );
    // ATI start-up: the start request alone.
    assert_eq!(emulator.requests(), [Request::start(0)]);
    sensor.tare().unwrap();
    for e in [
        sensor.clear_tare().unwrap_err(),
        sensor.set_filter(Filter::Hz50).unwrap_err(),
        sensor.set_rate_hz(100).unwrap_err(),
    ] {
        assert_eq!(e.kind(), ErrorKind::Unsupported, "{e}");
    }
    let got = requests_after_startup(&emulator, 1, 1);
    assert_eq!(
        got,
        [Request {
            command: CMD_BIAS,
            data: 0
        }]
    );
    assert!(emulator.bias().is_some());
    // An ATI configuration with OnRobot settings is refused.
    let bad = RdtConfig {
        filter: Some(Filter::Hz5),
        ..RdtConfig::ati(emulator.address(), 1e6, 1e6)
    };
    assert_eq!(
        RdtSensor::connect(bad).unwrap_err().kind(),
        ErrorKind::Unsupported
    );
}

#[test]
fn invalid_configurations_are_refused_with_the_value() {
    let address = "127.0.0.1:9".parse().unwrap();
    let base = RdtConfig::new(address, 10_000.0, 100_000.0);
    for bad in [
        RdtConfig {
            counts_per_n: 0.0,
            ..base
        },
        RdtConfig {
            counts_per_nm: f64::NAN,
            ..base
        },
        RdtConfig {
            silence_limit_ns: 0,
            ..base
        },
        RdtConfig {
            ring_capacity: 0,
            ..base
        },
        RdtConfig {
            rate_hz: Some(0),
            ..base
        },
        RdtConfig {
            rate_hz: Some(2000),
            ..base
        },
    ] {
        let e = bad.validate().unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidArgument, "{e}");
    }
    assert!(base.validate().is_ok());
}

// ---------------------------------------------------------------------------
// The draining read

#[test]
fn drain_in_parts_loses_nothing() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.step(10);
    // Wait for the newest through `wait` (its own cursor).
    while sensor.wait(PATIENCE_NS).unwrap().counter != 1010 {}
    let mut buf = [filler(); 4];
    let mut got = Vec::new();
    for expect_remaining in [6, 2, 0] {
        let d = sensor.drain(&mut buf).unwrap();
        assert_eq!((d.lost, d.remaining), (0, expect_remaining), "{d:?}");
        got.extend_from_slice(&buf[..d.count]);
    }
    assert_eq!(counters(&got), (1001..=1010).collect::<Vec<_>>());
    assert_eq!(sensor.drain(&mut buf).unwrap().count, 0);
}

#[test]
fn a_full_ring_drops_the_newest_and_says_how_many() {
    let (emulator, mut sensor) = manual_with(EmulatorConfig::new(Pacing::Manual), |e| RdtConfig {
        ring_capacity: 8,
        ..config(e)
    });
    emulator.step(20);
    while sensor.wait(PATIENCE_NS).unwrap().counter != 1020 {}
    let mut buf = [filler(); 32];
    let d = sensor.drain(&mut buf).unwrap();
    assert_eq!((d.count, d.lost, d.remaining), (8, 12, 0));
    assert_eq!(counters(&buf[..8]), (1001..=1008).collect::<Vec<_>>());
    assert_eq!(sensor.stats().ring_overflows, 12);
    // Counted once: the next drain starts afresh.
    emulator.step(1);
    while sensor.wait(PATIENCE_NS).unwrap().counter != 1021 {}
    let d = sensor.drain(&mut buf).unwrap();
    assert_eq!((d.count, d.lost, buf[0].counter), (1, 0, 1021));
}

/// The loop's pattern after the start-up's `wait`: each cycle `drain`, then
/// `poll`. The samples a cycle drains and the newest it polls come from the
/// same read of the socket: the polled sample is the last drained one (or
/// neither, when nothing came), never one a cycle ahead of the drained ones
/// (a spike seen in the drained samples belongs to the cycle's new sample).
#[test]
fn a_cycles_drain_and_poll_see_the_same_read() {
    let (emulator, mut sensor) = manual(vec![]);
    emulator.step(3);
    let mut newest = 1003;
    while sensor.wait(PATIENCE_NS).unwrap().counter != newest {}
    let mut buf = [filler(); 64];
    let mut drained_total = 0;
    for cycle in 0..200u64 {
        // Packets now and then, several at once sometimes.
        emulator.step([0, 1, 1, 2, 0, 3][(cycle % 6) as usize]);
        let d = sensor.drain(&mut buf).unwrap();
        let polled = sensor.poll().unwrap();
        let last_drained = buf[..d.count].last().map(|s| s.counter);
        if cycle == 0 {
            // The start-up's samples (1001 to 1003, the newest returned by
            // `wait`) come first.
            assert_eq!(buf[0].counter, 1001, "{d:?}");
        }
        if let Some(p) = polled {
            assert_eq!(Some(p.counter), last_drained, "cycle {cycle}: {d:?}");
            newest = p.counter;
        }
        if let Some(l) = last_drained {
            assert!(l <= newest, "cycle {cycle}: drained {l} ahead of {newest}");
        }
        drained_total += d.count;
    }
    assert!(newest > 1100, "{newest}");
    assert_eq!(drained_total as u64, sensor.stats().accepted);
}

/// A sensor faster than the loop: the emulator streams at 1 kHz while the
/// "loop" polls every 5 ms; the drained samples are complete (consecutive
/// counters, since the emulator loses none) although `poll` saw few.
#[test]
fn a_sensor_faster_than_the_loop_loses_nothing_for_the_recorder() {
    let emulator =
        Emulator::start(EmulatorConfig::new(Pacing::Periodic { period_ns: MS })).unwrap();
    let mut sensor = RdtSensor::connect(RdtConfig {
        rate_hz: Some(1000),
        ..config(&emulator)
    })
    .unwrap();
    let mut buf = [filler(); 64];
    let mut drained = Vec::new();
    let mut polled = 0;
    while drained.len() < 200 {
        std::thread::sleep(Duration::from_millis(5));
        polled += usize::from(sensor.poll().unwrap().is_some());
        let d = sensor.drain(&mut buf).unwrap();
        assert_eq!(d.lost, 0);
        drained.extend_from_slice(&buf[..d.count]);
    }
    assert!(polled > 0);
    for pair in drained.windows(2) {
        assert_eq!(pair[1].counter, pair[0].counter + 1, "a gap");
    }
    assert_eq!(sensor.stats().lost, 0);
}

// ---------------------------------------------------------------------------
// The sensor's network (SAFETY.md H4x): every poll failure names its cause;
// a spoofed packet is accepted (RDT has no authentication).

/// A manual emulator and a driver with a 30 ms silence limit, its stream
/// started.
fn quick_silence() -> (Emulator, RdtSensor) {
    manual_with(EmulatorConfig::new(Pacing::Manual), |e| RdtConfig {
        silence_limit_ns: 30 * MS,
        restart_interval_ns: 30 * MS,
        ..config(e)
    })
}

/// Polls (bounded) until `poll` fails with a silence whose cause `want`
/// accepts; the error.
fn poll_failure(sensor: &mut RdtSensor, want: impl Fn(&SilenceCause) -> bool) -> RdtError {
    let clock = MonotonicClock::new().unwrap();
    let deadline = now_ns(&clock) + PATIENCE_NS;
    let mut last = None;
    loop {
        if let Err(e) = sensor.poll() {
            if let RdtError::Silent { cause, .. } = e
                && want(&cause)
            {
                return e;
            }
            last = Some(e);
        }
        assert!(now_ns(&clock) < deadline, "not the cause wanted: {last:?}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn every_poll_failure_names_its_cause() {
    // Nothing at all from the sensor's address.
    let (_emulator, mut sensor) = quick_silence();
    let e = poll_failure(&mut sensor, |c| *c == SilenceCause::NothingReceived);
    assert_eq!(e.kind(), ErrorKind::Disconnected);
    assert!(
        e.to_string().contains("nothing received from 127.0.0.1:"),
        "{e}"
    );
    assert!(e.cause().contains("nothing received"), "{}", e.cause());
    // Only datagrams of the wrong length (a short packet).
    let (emulator, mut sensor) = quick_silence();
    emulator.step(1);
    collect_until(&mut sensor, 1001);
    assert!(emulator.send_raw(&[0x12; 20]));
    let e = poll_failure(&mut sensor, |c| *c == SilenceCause::WrongLength { got: 20 });
    assert!(e.to_string().contains("20 bytes, not 36"), "{e}");
    assert!(e.cause().contains("wrong length"), "{}", e.cause());
    // Only repeats of the last sample (its sequence and counter).
    let (emulator, mut sensor) = quick_silence();
    emulator.step(1);
    collect_until(&mut sensor, 1001);
    let again = Response {
        rdt_sequence: 1,
        sample_counter: 1001,
        ..Response::default()
    };
    assert!(emulator.send_raw(&again.encode()));
    let e = poll_failure(&mut sensor, |c| *c == SilenceCause::Duplicates);
    assert!(e.cause().contains("duplicate"), "{}", e.cause());
    // Only late packets (behind the last accepted one).
    let (emulator, mut sensor) = quick_silence();
    emulator.step(3);
    collect_until(&mut sensor, 1003);
    let late = Response {
        rdt_sequence: 2,
        sample_counter: 1002,
        ..Response::default()
    };
    assert!(emulator.send_raw(&late.encode()));
    let e = poll_failure(&mut sensor, |c| *c == SilenceCause::Late);
    assert!(e.cause().contains("late"), "{}", e.cause());
    // The sensor's port closed (the device gone): the restart requests come
    // back as ICMP port unreachable, a socket error.
    let (emulator, mut sensor) = quick_silence();
    drop(emulator);
    let e = poll_failure(&mut sensor, |c| matches!(c, SilenceCause::Socket { .. }));
    let RdtError::Silent {
        cause: SilenceCause::Socket { kind },
        ..
    } = e
    else {
        unreachable!()
    };
    assert_eq!(kind, std::io::ErrorKind::ConnectionRefused);
    assert!(e.to_string().contains("socket error"), "{e}");
    assert!(e.cause().contains("socket error"), "{}", e.cause());
    // A receive buffer the kernel granted too small says so.
    let small = RdtError::ReceiveBuffer {
        granted_bytes: 4096,
        needed_bytes: sar_rdt::MIN_RECEIVE_BUFFER_BYTES,
    };
    assert!(
        small.cause().contains("receive buffer"),
        "{}",
        small.cause()
    );
}

/// Sends `payload` as a UDP datagram from `from` to `to` through a raw socket
/// (the source port written by hand: what anyone on the sensor's network can
/// do). Needs CAP_NET_RAW (CI runs as root).
#[allow(unsafe_code)]
fn spoof(from: std::net::SocketAddrV4, to: std::net::SocketAddrV4, payload: &[u8]) {
    // SAFETY: plain socket calls on a descriptor owned here; the buffers
    // outlive the calls.
    unsafe {
        let fd = libc::socket(libc::AF_INET, libc::SOCK_RAW, libc::IPPROTO_UDP);
        assert!(
            fd >= 0,
            "a raw socket needs CAP_NET_RAW (run as root): {}",
            std::io::Error::last_os_error()
        );
        let len = 8 + payload.len();
        let mut datagram = Vec::with_capacity(len);
        datagram.extend_from_slice(&from.port().to_be_bytes());
        datagram.extend_from_slice(&to.port().to_be_bytes());
        datagram.extend_from_slice(&u16::try_from(len).unwrap().to_be_bytes());
        // Checksum 0: none (allowed over IPv4).
        datagram.extend_from_slice(&[0, 0]);
        datagram.extend_from_slice(payload);
        let dest = libc::sockaddr_in {
            sin_family: libc::AF_INET as libc::sa_family_t,
            sin_port: 0,
            sin_addr: libc::in_addr {
                s_addr: u32::from_ne_bytes(to.ip().octets()),
            },
            sin_zero: [0; 8],
        };
        let sent = libc::sendto(
            fd,
            datagram.as_ptr().cast(),
            datagram.len(),
            0,
            std::ptr::from_ref(&dest).cast(),
            std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t,
        );
        let error = std::io::Error::last_os_error();
        libc::close(fd);
        assert_eq!(sent, datagram.len() as isize, "{error}");
    }
}

/// RDT has no authentication: a packet from the sensor's address (the
/// source address and port are only what the packet says) with the next
/// sequence number is taken as the sensor's sample, and the sensor's own
/// packet after it is dropped as a duplicate. The driver cannot tell; only
/// the network can (SAFETY.md: a dedicated link, no routing).
#[test]
fn a_spoofed_packet_with_the_next_sequence_from_the_sensors_address_is_accepted() {
    let (emulator, mut sensor) = manual(Vec::new());
    emulator.step(1);
    let first = collect_until(&mut sensor, 1001);
    assert_eq!(first.len(), 1);
    let std::net::SocketAddr::V4(device) = emulator.address() else {
        panic!("the emulator is on IPv4 loopback")
    };
    let std::net::SocketAddr::V4(driver) = sensor.local_address().unwrap() else {
        panic!("the driver is on IPv4 loopback")
    };
    // 50 N along z, the next sequence and counter, from the device's address.
    let forged = Response {
        rdt_sequence: 2,
        sample_counter: 1002,
        status: 0,
        counts: [0, 0, 500_000, 0, 0, 0],
    };
    spoof(device, driver, &forged.encode());
    let got = sensor.wait(PATIENCE_NS).unwrap();
    assert_eq!(got.counter, 1002);
    assert!(got.is_valid());
    assert_eq!(got.force_n.z, 50.0);
    // The device's own packet 2 now looks like a repeat and is dropped.
    emulator.step(1);
    let clock = MonotonicClock::new().unwrap();
    let deadline = now_ns(&clock) + PATIENCE_NS;
    // The driver has no thread: each poll reads the socket.
    while sensor.stats().duplicates == 0 {
        assert!(now_ns(&clock) < deadline, "the device's packet never came");
        assert_eq!(sensor.poll().unwrap(), None, "a repeat became a sample");
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(sensor.stats().accepted, 2);
    assert_eq!(sensor.poll().unwrap(), None);
}
