//! The simulator's encoder-jump fault (a position that jumps while the axis
//! does not move) ends in a Fault with the joint-jump reason, and the drives
//! are quick-stopped in that cycle.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_config as config;
use sar_estimator::guard::{GuardState, Reason};
use sar_test_support::rig::{RigBuilder, SimRig};
use std::path::Path;

#[test]
fn an_encoder_jump_is_a_fault_and_stops_the_drives() {
    let cfg = config::builtin().unwrap();
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/fault_encoder_jump.toml");
    let scenario = sar_config::scenario::load(&path).unwrap();
    let SimRig { mut c, clock, .. } = RigBuilder::new(&scenario).config(&cfg).build();
    let mut fault = None;
    // The jump is at 2.0 s of the simulator's time.
    for cycle in 1..=3000u64 {
        clock.advance_ns(1_000_000);
        let out = *c.step(cycle, || Some(clock.now_ns()));
        if cycle == 1500 {
            assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
        }
        // Before the first reset (the mean at rest, 1000 cycles) the guard
        // is in Fault awaiting it; the fault looked for comes after Ok.
        if out.guard_state == GuardState::Fault && cycle > 1500 {
            fault = Some((cycle, out));
            break;
        }
    }
    let (cycle, out) = fault.expect("the encoder jump did not fault");
    assert!((1990..=2010).contains(&cycle), "fault at cycle {cycle}");
    assert!(
        matches!(out.guard_reason, Reason::JointJump { axis: 3, .. }),
        "{:?}",
        out.guard_reason
    );
    assert!(c.halted());
    assert_eq!(c.counts().quick_stops, 1);
    assert_eq!(c.counts().stops_in_same_cycle, 1);
}
