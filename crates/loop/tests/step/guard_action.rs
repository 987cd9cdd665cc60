//! Guard action on the drives: a quick stop that the drives refuse is
//! repeated every cycle until they stop; moves are refused while halted and
//! after a reset accepted again.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_config as config;
use sar_daemon::sim;
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_hal::{AxisDrives, DriveState, SimClock};
use sar_loop::control::{Envelope, ReplyStatus, Request};
use sar_sim::{SimDrives, SimError};
use sar_test_support::drives::{DriveHook, Hooked};
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::RigBuilder;

/// Simulated drives whose first `refuse` quick stops fail.
struct Stubborn {
    refuse: u32,
}

impl DriveHook<SimDrives<SimClock>> for Stubborn {
    fn quick_stop(&mut self, inner: &mut SimDrives<SimClock>) -> Result<(), SimError> {
        if self.refuse > 0 {
            self.refuse -= 1;
            return Err(SimError::Busy);
        }
        inner.quick_stop()
    }
}

#[test]
fn a_refused_quick_stop_is_repeated_and_moves_wait_for_a_reset() {
    // 20 N along the rod from 2 s to 4 s, then nothing (after the first
    // reset, which needs the mean at rest: 1 s).
    let mut rig = RigBuilder::demo(rod_push_20n([
        1_500_000_000,
        2_000_000_000,
        4_000_000_000,
        4_100_000_000,
    ]))
    .build_with(|drives| Hooked::new(drives, Stubborn { refuse: 3 }));
    let mut stopped_at = None;
    for _ in 0..3000 {
        rig.step();
        let out = rig.c.output();
        if out.guard_state == GuardState::Stop {
            stopped_at = Some(out.cycle);
            break;
        }
    }
    let stopped_at = stopped_at.expect("no Stop");
    assert!(rig.c.halted());
    // The first quick stop and two repeats were refused; the third repeat works.
    for _ in 0..5 {
        rig.step();
    }
    assert_eq!(rig.c.counts().quick_stops, 1);
    assert_eq!(rig.c.counts().quick_stop_retries, 3);
    assert_eq!(
        rig.c.drive_state(),
        Some(DriveState::QuickStop),
        "stopped at {stopped_at}"
    );

    // A move while halted is refused.
    let tip_m = Vec3::new(0.59, 0.2, 0.0);
    let r = rig.request(1, Request::MoveTip { tip_m });
    assert_eq!(r.status, ReplyStatus::Halted);

    // After the contact is gone (4.1 s), a reset is accepted and moves work again.
    for _ in 0..2500 {
        rig.step();
    }
    let r = rig.request(2, Request::Reset);
    assert_eq!(r.status, ReplyStatus::Accepted, "{r:?}");
    assert!(!rig.c.halted());
    rig.step();
    assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));
    let r = rig.request(3, Request::MoveTip { tip_m });
    assert_eq!(r.status, ReplyStatus::Accepted, "{r:?}");
}

/// The drives are enabled only by an accepted reset: before it (the guard
/// starts in Fault, no input yet) they stay Ready however many cycles run.
#[test]
fn the_drives_are_enabled_only_after_an_accepted_reset() {
    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let mut rig = RigBuilder::new(&scenario)
        .config(&cfg)
        .without_auto_reset()
        .build();
    // The first reset needs the full mean at rest (500 samples: 1000 cycles).
    for _ in 0..1010 {
        rig.step();
        assert_eq!(rig.c.output().guard_state, GuardState::Fault);
        assert!(rig.c.halted());
        assert_eq!(
            rig.c.drive_state(),
            Some(DriveState::Ready),
            "cycle {}",
            rig.cycle
        );
    }
    rig.operator
        .requests
        .push(Envelope {
            id: 1,
            request: Request::Reset,
        })
        .unwrap();
    for _ in 0..5 {
        rig.step();
    }
    assert_eq!(
        rig.operator.replies.pop().unwrap().status,
        ReplyStatus::Accepted
    );
    assert!(!rig.c.halted());
    assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));
}
