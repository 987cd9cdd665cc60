//! Guard action on the drives: a quick stop that the drives refuse is
//! repeated every cycle until they stop; moves are refused while halted and
//! after a reset accepted again.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;
use common::sim_rig::{RigBuilder, SimRig};
use sar_config as config;
use sar_daemon::sim;
use sar_drivers::sim::{SimDrives, SimError};
use sar_drivers::{AxisDrives, DriveState, JointPositions, SimClock};
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_kinematics::ActiveJoints;
use sar_loop::control::{Controller, Envelope, ReplyStatus, Request};

/// Simulated drives whose first `refuse` quick stops fail.
struct Stubborn {
    inner: SimDrives<SimClock>,
    refuse: u32,
}

impl AxisDrives for Stubborn {
    type Error = SimError;
    fn positions(&mut self) -> Result<JointPositions, SimError> {
        self.inner.positions()
    }
    fn state(&mut self) -> Result<DriveState, SimError> {
        self.inner.state()
    }
    fn enable(&mut self) -> Result<(), SimError> {
        self.inner.enable()
    }
    fn disable(&mut self) -> Result<(), SimError> {
        self.inner.disable()
    }
    fn stream(&mut self, t: ActiveJoints, period_ns: u64) -> Result<(), SimError> {
        self.inner.stream(t, period_ns)
    }
    fn set_targets(&mut self, t: ActiveJoints) -> Result<(), SimError> {
        self.inner.set_targets(t)
    }
    fn quick_stop(&mut self) -> Result<(), SimError> {
        if self.refuse > 0 {
            self.refuse -= 1;
            return Err(SimError::Busy);
        }
        self.inner.quick_stop()
    }
    fn fault_reset(&mut self) -> Result<(), SimError> {
        self.inner.fault_reset()
    }
}

#[test]
fn a_refused_quick_stop_is_repeated_and_moves_wait_for_a_reset() {
    let cfg = config::builtin().unwrap();
    let mut scenario = sim::demo_scenario().unwrap();
    // 20 N along the rod from 2 s to 4 s, then nothing (after the first
    // reset, which needs the mean at rest: 1 s).
    scenario.spec.contact = common::contact_pulse(
        1_500_000_000,
        2_000_000_000,
        4_000_000_000,
        4_100_000_000,
        Vec3::new(20.0, 0.0, 0.0),
    );
    let SimRig {
        mut c,
        clock,
        operator,
        ..
    } = RigBuilder::new(&scenario)
        .config(&cfg)
        .build_with(|drives| Stubborn {
            inner: drives,
            refuse: 3,
        });
    let mut cycle = 0u64;
    let mut step = |c: &mut Controller<_, _>| {
        cycle += 1;
        clock.advance_ns(1_000_000);
        *c.step(cycle, || Some(clock.now_ns()))
    };
    let mut stopped_at = None;
    for _ in 0..3000 {
        let out = step(&mut c);
        if out.guard_state == GuardState::Stop {
            stopped_at = Some(out.cycle);
            break;
        }
    }
    let stopped_at = stopped_at.expect("no Stop");
    assert!(c.halted());
    // The first quick stop and two repeats were refused; the third repeat works.
    for _ in 0..5 {
        step(&mut c);
    }
    assert_eq!(c.counts().quick_stops, 1);
    assert_eq!(c.counts().quick_stop_retries, 3);
    assert_eq!(
        c.drive_state(),
        Some(DriveState::QuickStop),
        "stopped at {stopped_at}"
    );

    // A move while halted is refused.
    operator
        .requests
        .push(Envelope {
            id: 1,
            request: Request::MoveTip {
                tip_m: Vec3::new(0.59, 0.2, 0.0),
            },
        })
        .unwrap();
    step(&mut c);
    let r = operator.replies.pop().unwrap();
    assert_eq!(r.status, ReplyStatus::Halted);

    // After the contact is gone (4.1 s), a reset is accepted and moves work again.
    for _ in 0..2500 {
        step(&mut c);
    }
    operator
        .requests
        .push(Envelope {
            id: 2,
            request: Request::Reset,
        })
        .unwrap();
    step(&mut c);
    let r = operator.replies.pop().unwrap();
    assert_eq!(r.status, ReplyStatus::Accepted, "{r:?}");
    assert!(!c.halted());
    step(&mut c);
    assert_eq!(c.drive_state(), Some(DriveState::Enabled));
    operator
        .requests
        .push(Envelope {
            id: 3,
            request: Request::MoveTip {
                tip_m: Vec3::new(0.59, 0.2, 0.0),
            },
        })
        .unwrap();
    step(&mut c);
    let r = operator.replies.pop().unwrap();
    assert_eq!(r.status, ReplyStatus::Accepted, "{r:?}");
}

/// The drives are enabled only by an accepted reset: before it (the guard
/// starts in Fault, no input yet) they stay Ready however many cycles run.
#[test]
fn the_drives_are_enabled_only_after_an_accepted_reset() {
    let cfg = config::builtin().unwrap();
    let scenario = sim::demo_scenario().unwrap();
    let SimRig {
        mut c,
        clock,
        operator,
        ..
    } = RigBuilder::new(&scenario)
        .config(&cfg)
        .without_auto_reset()
        .build();
    let mut cycle = 0u64;
    // The first reset needs the full mean at rest (500 samples: 1000 cycles).
    for _ in 0..1010 {
        cycle += 1;
        clock.advance_ns(1_000_000);
        let out = *c.step(cycle, || Some(clock.now_ns()));
        assert_eq!(out.guard_state, GuardState::Fault);
        assert!(c.halted());
        assert_eq!(c.drive_state(), Some(DriveState::Ready), "cycle {cycle}");
    }
    operator
        .requests
        .push(Envelope {
            id: 1,
            request: Request::Reset,
        })
        .unwrap();
    for _ in 0..5 {
        cycle += 1;
        clock.advance_ns(1_000_000);
        c.step(cycle, || Some(clock.now_ns()));
    }
    assert_eq!(
        operator.replies.pop().unwrap().status,
        ReplyStatus::Accepted
    );
    assert!(!c.halted());
    assert_eq!(c.drive_state(), Some(DriveState::Enabled));
}
