//! Snapshot encoding of the guard's reasons and the guard (issue 17): every
//! reason, with arbitrary values (NaN payloads, -0.0, infinities included),
//! reads back bit for bit, and its tag is its code in `REASONS` (so a
//! snapshot and a recording name a reason alike).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use proptest::prelude::*;
use sar_estimator::guard::{
    Axis, ForcePart, REASONS, Reason, RestResidual, SensorChannel, TipField,
};
use sar_snapshot::{Reader, Snap, Writer};

fn reason(code: u16, a: u64, b: u32, x: f64, y: f64, z: f64, k: u8) -> Reason {
    let axis = Axis::ALL[usize::from(k % 3)];
    let part = ForcePart::ALL[usize::from(k % 3)];
    let field = [TipField::Force, TipField::Std, TipField::RodDir][usize::from(k % 3)];
    let channel = SensorChannel::ALL[usize::from(k % 6)];
    let residual = [
        RestResidual::Axial,
        RestResidual::Lateral,
        RestResidual::Torque(axis),
    ][usize::from(k % 3)];
    match code {
        1 => Reason::NoInputYet,
        2 => Reason::CycleOutOfOrder {
            previous: a,
            got: a ^ 1,
        },
        3 => Reason::ClockFailed,
        4 => Reason::ClockNotAdvancing {
            previous_ns: a,
            now_ns: !a,
        },
        5 => Reason::SensorCounterGap {
            previous: b,
            got: !b,
            max_gap: b / 2,
        },
        6 => Reason::SensorStatus { status: b },
        7 => Reason::JointJump {
            axis: k,
            moved_m: x,
            allowed_m: y,
        },
        8 => Reason::JointsStampBackwards {
            previous_ns: a,
            got_ns: a / 3,
        },
        9 => Reason::TorqueImplausible {
            axis,
            residual_nm: x,
            std_nm: y,
            max_sigma: z,
        },
        10 => Reason::ResetNotCurrent {
            last: a,
            got: a / 5,
        },
        11 => Reason::SensorInvalid,
        12 => Reason::SensorStale {
            age_ns: a,
            max_age_ns: a / 7,
        },
        13 => Reason::JointsInvalid,
        14 => Reason::JointsStale {
            age_ns: a / 11,
            max_age_ns: a,
        },
        15 => Reason::PoseInvalid,
        16 => Reason::NonFinite { field, axis },
        17 => Reason::NegativeStd { axis, std_n: x },
        18 => Reason::RodDirNotUnit { norm: y },
        19 => Reason::EstimatorNotObservable,
        20 => Reason::NotObservable {
            std_max_n: x,
            max_std_n: z,
        },
        21 => Reason::AboveStop {
            part,
            force_n: x,
            limit_n: y,
        },
        22 => Reason::AboveWarn {
            part,
            force_n: y,
            limit_n: z,
        },
        23 => Reason::BelowWarn,
        24 => Reason::Reset,
        25 => Reason::FollowingError {
            axis: k,
            error_m: x,
            tolerance_m: z,
        },
        26 => Reason::AwaitingFirstReset,
        27 => Reason::SensorFrozen { repeats: b },
        28 => Reason::SensorSaturated {
            channel,
            value: x,
            range: y,
        },
        29 => Reason::SensorSpikes {
            spikes: b,
            window: b / 3,
        },
        30 => Reason::TareDue {
            age_s: x,
            max_age_s: y,
        },
        31 => Reason::Tared,
        32 => Reason::MountingMismatch {
            residual,
            value: x,
            allowed: z,
        },
        33 => Reason::RetreatEntered {
            part,
            force_n: z,
            limit_n: x,
        },
        34 => Reason::ForceRising {
            part,
            force_n: x,
            bound_n: y,
        },
        35 => Reason::PublisherStalled { stalled_ms: b },
        36 => Reason::DriveFault {
            axis: k,
            code: (b & 0xFFFF) as u16,
        },
        37 => Reason::RestIncomplete {
            samples: b,
            needed: b / 2,
        },
        38 => Reason::CycleGap {
            gap_ns: u64::from(b),
            max_ns: u64::from(b / 2),
        },
        other => panic!("no reason has code {other}"),
    }
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<u64>().prop_map(f64::from_bits),
        Just(-0.0),
        Just(f64::INFINITY),
        Just(f64::NAN),
        -1e3..1e3f64,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, rng_seed: proptest::test_runner::RngSeed::Fixed(17), ..ProptestConfig::default() })]
    #[test]
    fn every_reason_round_trips_bit_for_bit_with_its_code_as_tag(
        i in 0..REASONS.len(),
        a in any::<u64>(),
        b in any::<u32>(),
        x in any_f64(),
        y in any_f64(),
        z in any_f64(),
        k in any::<u8>(),
    ) {
        let code = REASONS[i].0;
        let r = reason(code, a, b, x, y, z, k);
        prop_assert_eq!(r.code(), code);
        let mut buf = [0u8; 64];
        let mut w = Writer::new(&mut buf);
        r.put(&mut w);
        prop_assert!(!w.overflowed());
        let n = w.position();
        prop_assert_eq!(u16::from(buf[0]), code);
        let mut rd = Reader::new(&buf[..n]);
        let back = Reason::get(&mut rd).unwrap();
        prop_assert_eq!(rd.remaining(), 0);
        // Debug prints every f64 exactly (NaN as NaN), so equal text is
        // equal bits up to NaN payloads; the bytes settle those.
        prop_assert_eq!(format!("{back:?}"), format!("{r:?}"));
        let mut again = [0u8; 64];
        let mut w2 = Writer::new(&mut again);
        back.put(&mut w2);
        prop_assert_eq!(&again[..n], &buf[..n]);
    }
}

#[test]
fn an_unknown_reason_tag_is_refused() {
    for tag in [0u8, 39, 255] {
        let buf = [tag, 0, 0, 0];
        let e = Reason::get(&mut Reader::new(&buf)).unwrap_err();
        assert!(e.to_string().contains("Reason"), "{e}");
    }
}
