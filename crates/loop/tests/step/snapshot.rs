//! Snapshots of the loop's decision state (issue 17), as a replay meets
//! them: taken from a step that ran a session (reset, a push, a Stop), they
//! restore exactly into a step built from the same configuration, are
//! refused by one built from another, and are never trusted when a byte is
//! changed: every single-bit corruption is refused with a clear error and
//! leaves the step as it was. (That a restored step replays the rest of a
//! run bit for bit is checked over seeded random runs in `step_properties`.)

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config as config;
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_loop::control::{Envelope, Request};
use sar_loop::step::LoopStep;
use sar_snapshot::{Snapshot, SnapshotError};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};

/// A step after 3 s of the demo: reset, a push of 1 N into a contact that
/// rises to a Stop. Returns it and its configuration.
fn session() -> (LoopStep, config::Config) {
    let SimRig {
        mut c,
        clock,
        operator,
        cfg,
        ..
    } = RigBuilder::demo(rod_push_20n([
        2_000_000_000,
        3_000_000_000,
        3_500_000_000,
        4_000_000_000,
    ]))
    .build();
    let mut seen_stop = false;
    for cycle in 1..=3200u64 {
        if cycle == 1100 {
            let request = Request::Push { axial_n: 1.0 };
            operator
                .requests
                .push(Envelope { id: cycle, request })
                .unwrap();
        }
        clock.advance_ns(1_000_000);
        let now = clock.now_ns();
        seen_stop |= c.step(cycle, || Some(now)).guard_state == GuardState::Stop;
        while operator.replies.pop().is_some() {}
    }
    assert!(seen_stop, "the session never stopped");
    (c.loop_step().clone(), cfg)
}

#[test]
fn a_snapshot_restores_exactly_into_a_step_of_the_same_configuration() {
    let (step, cfg) = session();
    let mut snap = Snapshot::new();
    step.snapshot(&mut snap).unwrap();
    let bytes = snap.as_bytes();
    println!("snapshot of a loop step: {} bytes", bytes.len());
    // The fingerprint cached at construction is the configuration's now.
    assert_eq!(snap.fingerprint(), sar_snapshot::fingerprint(&step));
    assert!(bytes.len() < sar_snapshot::CAPACITY / 2);
    let other = sar_estimator::cycle::Bias::force_only(Vec3::new(0.5, 0.5, 0.5));
    let mut fresh = LoopStep::new(&cfg.estimator, other, cfg.step_config()).unwrap();
    assert_ne!(format!("{fresh:?}"), format!("{step:?}"));
    fresh.restore(bytes).unwrap();
    // Taken again, the restored step gives the same bytes.
    let mut again = Snapshot::new();
    fresh.snapshot(&mut again).unwrap();
    assert_eq!(again.as_bytes(), bytes);
}

#[test]
fn another_configuration_refuses_the_snapshot() {
    let (step, cfg) = session();
    let mut snap = Snapshot::new();
    step.snapshot(&mut snap).unwrap();
    let mut changed = cfg.clone();
    changed.axes.following_tolerance_m *= 2.0;
    let bias = sar_estimator::cycle::Bias::force_only(Vec3::zeros());
    let mut other = LoopStep::new(&changed.estimator, bias, changed.step_config()).unwrap();
    let before = format!("{other:?}");
    let e = other.restore(snap.as_bytes()).unwrap_err();
    assert!(matches!(e, SnapshotError::ConfigMismatch { .. }), "{e}");
    assert!(e.to_string().contains("another configuration"), "{e}");
    assert_eq!(format!("{other:?}"), before);
}

#[test]
fn every_single_bit_corruption_is_refused_and_changes_nothing() {
    let (step, cfg) = session();
    let mut snap = Snapshot::new();
    step.snapshot(&mut snap).unwrap();
    let good = snap.as_bytes().to_vec();
    let bias = sar_estimator::cycle::Bias::force_only(Vec3::zeros());
    let mut target = LoopStep::new(&cfg.estimator, bias, cfg.step_config()).unwrap();
    let before = format!("{target:?}");
    let mut checksum_errors = 0;
    for i in 0..good.len() {
        for bit in 0..8 {
            let mut bad = good.clone();
            bad[i] ^= 1 << bit;
            let e = target.restore(&bad).unwrap_err();
            checksum_errors += u32::from(matches!(e, SnapshotError::Checksum { .. }));
            assert!(!e.to_string().is_empty());
        }
    }
    // The body and the checksum's own bytes fail the checksum; the header's
    // magic, version and length fail before it.
    assert!(checksum_errors as usize > (good.len() - sar_snapshot::HEADER_BYTES) * 8 - 1);
    for len in [0, 1, 8, sar_snapshot::HEADER_BYTES, good.len() - 1] {
        assert!(target.restore(&good[..len]).is_err(), "length {len}");
    }
    let mut longer = good.clone();
    longer.push(0);
    assert!(matches!(
        target.restore(&longer).unwrap_err(),
        SnapshotError::Length { .. }
    ));
    assert_eq!(format!("{target:?}"), before);
    target.restore(&good).unwrap();
    assert_ne!(format!("{target:?}"), before);
}
