//! The RDT codec over arbitrary bytes (proptest, fixed seed): it never
//! panics, accepts exactly the well-formed datagrams, and round-trips; and
//! the driver's acceptance of arbitrary datagrams never panics either (a
//! fuzz of the whole receive path over a loopback socket).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config as ProptestConfig, RngSeed, TestRunner};
use sar_hal::ForceSensor;
use sar_rdt::codec::{CodecError, HEADER, REQUEST_LEN, RESPONSE_LEN, Request, Response};
use sar_rdt::emulator::{Emulator, EmulatorConfig, Pacing};
use sar_rdt::{RdtConfig, RdtSensor};
use std::time::Duration;

fn run<S: Strategy>(cases: u32, seed: u64, strategy: S, test: impl Fn(S::Value))
where
    S::Value: core::fmt::Debug,
{
    let mut runner = TestRunner::new(ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    if let Err(e) = runner.run(&strategy, |v| {
        test(v);
        Ok(())
    }) {
        panic!("{e}");
    }
}

/// Arbitrary lengths, weighted towards the interesting ones.
fn datagram() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        prop::collection::vec(any::<u8>(), 0..80),
        prop::collection::vec(any::<u8>(), REQUEST_LEN..=REQUEST_LEN),
        prop::collection::vec(any::<u8>(), RESPONSE_LEN..=RESPONSE_LEN),
        // Requests with the right header.
        prop::collection::vec(any::<u8>(), 6..=6).prop_map(|mut v| {
            let mut b = HEADER.to_be_bytes().to_vec();
            b.append(&mut v);
            b
        }),
    ]
}

#[test]
fn decoding_arbitrary_bytes_never_panics_and_is_exact() {
    run(20_000, 0x5EED_0001, datagram(), |bytes| {
        match Response::decode(&bytes) {
            Ok(r) => {
                assert_eq!(bytes.len(), RESPONSE_LEN);
                assert_eq!(r.encode().as_slice(), bytes.as_slice());
            }
            Err(e) => {
                assert_ne!(bytes.len(), RESPONSE_LEN);
                assert_eq!(
                    e,
                    CodecError::WrongLength {
                        expected: RESPONSE_LEN,
                        got: bytes.len()
                    }
                );
            }
        }
        match Request::decode(&bytes) {
            Ok(r) => {
                assert_eq!(r.encode().as_slice(), bytes.as_slice());
            }
            Err(CodecError::BadHeader { header }) => {
                assert_eq!(bytes.len(), REQUEST_LEN);
                assert_ne!(header, HEADER);
            }
            Err(e) => assert_ne!(bytes.len(), REQUEST_LEN, "{e}"),
        }
    });
}

#[test]
fn encode_then_decode_is_the_identity() {
    let response = (any::<u32>(), any::<u32>(), any::<u32>(), any::<[i32; 6]>());
    run(
        5_000,
        0x5EED_0002,
        response,
        |(seq, counter, status, counts)| {
            let r = Response {
                rdt_sequence: seq,
                sample_counter: counter,
                status,
                counts,
            };
            assert_eq!(Response::decode(&r.encode()), Ok(r));
        },
    );
    run(
        5_000,
        0x5EED_0003,
        (any::<u16>(), any::<u32>()),
        |(command, data)| {
            let r = Request { command, data };
            let bytes = r.encode();
            // The data field is the big-endian u32, all four bytes of it.
            assert_eq!(bytes[4..], data.to_be_bytes());
            assert_eq!(Request::decode(&bytes), Ok(r));
        },
    );
}

/// Arbitrary datagrams from the sensor's address into the running driver:
/// it neither panics nor stops, and every datagram is accounted for.
#[test]
fn the_driver_survives_arbitrary_datagrams() {
    let emulator = Emulator::start(EmulatorConfig::new(Pacing::Manual)).unwrap();
    let mut sensor = RdtSensor::connect(RdtConfig {
        silence_limit_ns: 60_000_000_000,
        ..RdtConfig::new(emulator.address(), 10_000.0, 100_000.0)
    })
    .unwrap();
    assert!(emulator.wait_for_starts(1, Duration::from_secs(10)));
    let datagrams: Vec<Vec<u8>> = {
        let mut runner = TestRunner::new(ProptestConfig {
            rng_seed: RngSeed::Fixed(0x5EED_0004),
            ..ProptestConfig::default()
        });
        let strategy = prop::collection::vec(datagram(), 300..=300);
        strategy.new_tree(&mut runner).unwrap().current()
    };
    let malformed = datagrams.iter().filter(|d| d.len() != RESPONSE_LEN).count() as u64;
    // Each datagram ends in exactly one counter: accepted (new samples and
    // resyncs), duplicate, late or malformed. Sent in batches of 50, each
    // waited for (bounded): a burst larger than the socket's receive buffer
    // would be dropped by the kernel, uncounted.
    let handled = |s: &sar_rdt::RdtStats| s.accepted + s.duplicates + s.reordered + s.malformed;
    let mut stats = sensor.stats();
    for (i, batch) in datagrams.chunks(50).enumerate() {
        for d in batch {
            assert!(emulator.send_raw(d));
        }
        let expected = (i * 50 + batch.len()) as u64;
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        loop {
            // The driver has no thread: each poll reads the socket.
            sensor.poll().unwrap();
            stats = sensor.stats();
            if handled(&stats) >= expected {
                break;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "unaccounted: {stats:?}"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        assert_eq!(handled(&stats), expected, "{stats:?}");
    }
    assert_eq!(stats.malformed, malformed);
    assert!(stats.accepted > 0, "{stats:?}");
    // Still running: poll answers.
    assert!(sensor.poll().is_ok());
}
