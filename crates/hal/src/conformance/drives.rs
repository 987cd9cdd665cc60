//! The [`AxisDrives`] conformance checks. Each takes a fresh harness (drives
//! in `Ready`, at rest, in normal operation).

use super::DrivesHarness;
use crate::{AxisDrives, DriveState, Error, ErrorKind, JointPositions};
use sar_kinematics::ActiveJoints;

fn kind<E: Error>(result: Result<(), E>) -> Option<ErrorKind> {
    result.err().map(|e| e.kind())
}

fn state<H: DrivesHarness>(h: &mut H) -> DriveState {
    h.drives().state().unwrap()
}

/// Commands are requests (a real drive needs several exchanges): polls the
/// state, letting time pass, until it is `want` or the harness's
/// `transition_bound_ns` has passed, and asserts it got there.
fn await_state<H: DrivesHarness>(h: &mut H, want: DriveState) {
    let bound_ns = h.transition_bound_ns();
    let step_ns = (bound_ns / 100).max(100_000);
    let start_ns = h.now_ns();
    loop {
        let now = state(h);
        if now == want {
            return;
        }
        let waited_ns = h.now_ns().saturating_sub(start_ns);
        assert!(
            waited_ns < bound_ns,
            "state {now:?}, not {want:?}, after {waited_ns} ns"
        );
        h.let_time_pass(step_ns);
    }
}

fn positions<H: DrivesHarness>(h: &mut H) -> JointPositions {
    h.drives().positions().unwrap()
}

fn axes(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

fn distance_m(a: &ActiveJoints, b: &ActiveJoints) -> f64 {
    axes(a)
        .iter()
        .zip(axes(b))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn with_axis(q: &ActiveJoints, axis: usize, value: f64) -> ActiveJoints {
    let mut v = axes(q);
    v[axis] = value;
    ActiveJoints {
        q1_m: v[0],
        q2_m: v[1],
        q3_m: v[2],
    }
}

/// Lets the settle bound pass in small steps (a real harness sleeps).
fn settle<H: DrivesHarness>(h: &mut H) {
    let step = (h.settle_bound_ns() / 20).max(1);
    for _ in 0..20 {
        h.let_time_pass(step);
        let _ = positions(h);
    }
}

/// Fresh drives are `Ready` and refuse targets with `InvalidState`.
pub fn starts_ready_and_refuses_targets<H: DrivesHarness>(h: &mut H) {
    assert_eq!(state(h), DriveState::Ready);
    let target = h.reachable_target();
    assert_eq!(
        kind(h.drives().set_targets(target)),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(state(h), DriveState::Ready);
}

/// `enable` leads to `Enabled`, where targets are accepted; `disable` back to
/// `Ready`, where they are refused again.
pub fn enable_accepts_targets_and_disable_refuses_them<H: DrivesHarness>(h: &mut H) {
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    let target = h.reachable_target();
    h.drives().set_targets(target).unwrap();
    h.drives().disable().unwrap();
    await_state(h, DriveState::Ready);
    assert_eq!(
        kind(h.drives().set_targets(target)),
        Some(ErrorKind::InvalidState)
    );
}

/// Non-finite and out-of-travel targets are `InvalidArgument`, leave the state
/// `Enabled` and do not move the axes.
pub fn invalid_targets_are_invalid_arguments<H: DrivesHarness>(h: &mut H) {
    let start = positions(h).joints;
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    let good = h.reachable_target();
    for axis in 0..3 {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let target = with_axis(&good, axis, bad);
            assert_eq!(
                kind(h.drives().set_targets(target)),
                Some(ErrorKind::InvalidArgument),
                "axis {axis} = {bad}"
            );
        }
    }
    if let Some(target) = h
        .out_of_travel_target()
        .require("invalid_targets_are_invalid_arguments (out of travel)")
    {
        assert!(axes(&target).iter().all(|x| x.is_finite()), "{target:?}");
        assert_eq!(
            kind(h.drives().set_targets(target)),
            Some(ErrorKind::InvalidArgument),
            "out-of-travel target {target:?}"
        );
    }
    assert_eq!(state(h), DriveState::Enabled);
    settle(h);
    let now = positions(h).joints;
    assert!(
        distance_m(&start, &now) <= h.tolerance_m(),
        "moved from {start:?} to {now:?}"
    );
}

/// `quick_stop` from `Ready` leads to `QuickStop`, which refuses targets and
/// `enable`; `disable` leads back to `Ready`, from which `enable` works.
pub fn quick_stop_from_ready_and_back<H: DrivesHarness>(h: &mut H) {
    h.drives().quick_stop().unwrap();
    await_state(h, DriveState::QuickStop);
    let target = h.reachable_target();
    assert_eq!(
        kind(h.drives().set_targets(target)),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(kind(h.drives().enable()), Some(ErrorKind::InvalidState));
    h.drives().disable().unwrap();
    await_state(h, DriveState::Ready);
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
}

/// `quick_stop` during a move stops the axes short of the target and holds them.
pub fn quick_stop_while_moving_stops_and_holds<H: DrivesHarness>(h: &mut H) {
    let start = positions(h).joints;
    let target = h.reachable_target();
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    h.drives().set_targets(target).unwrap();
    h.let_time_pass(h.settle_bound_ns() / 10);
    h.drives().quick_stop().unwrap();
    await_state(h, DriveState::QuickStop);
    settle(h);
    let stopped = positions(h).joints;
    settle(h);
    let later = positions(h).joints;
    assert!(
        distance_m(&stopped, &later) <= h.tolerance_m(),
        "{stopped:?} -> {later:?}"
    );
    assert!(
        distance_m(&later, &target) > h.tolerance_m(),
        "the quick stop did not stop the move ({start:?} -> {later:?}, target {target:?})"
    );
    assert_eq!(
        kind(h.drives().set_targets(target)),
        Some(ErrorKind::InvalidState)
    );
    h.drives().disable().unwrap();
    await_state(h, DriveState::Ready);
}

/// `fault_reset` outside `Fault` is `InvalidState` (and changes nothing).
pub fn fault_reset_outside_fault_is_invalid_state<H: DrivesHarness>(h: &mut H) {
    assert_eq!(
        kind(h.drives().fault_reset()),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(state(h), DriveState::Ready);
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    assert_eq!(
        kind(h.drives().fault_reset()),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(state(h), DriveState::Enabled);
    h.drives().quick_stop().unwrap();
    assert_eq!(
        kind(h.drives().fault_reset()),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(state(h), DriveState::QuickStop);
}

/// Position reports are finite, valid, never from the future, never older
/// than the bound, and their stamps never go back; calls do not block.
pub fn positions_are_stamped_fresh_and_in_order<H: DrivesHarness>(h: &mut H) {
    let step = h.report_age_bound_ns() / 3 + 1;
    let mut last_stamp = 0;
    for _ in 0..60 {
        h.let_time_pass(step);
        let before = h.now_ns();
        let p = positions(h);
        let now = h.now_ns();
        assert!(now - before <= h.call_slack_ns());
        assert!(p.stamp_ns <= now, "stamp {} after now {now}", p.stamp_ns);
        assert!(now - p.stamp_ns <= h.report_age_bound_ns() + h.call_slack_ns());
        assert!(p.stamp_ns >= last_stamp);
        assert!(p.valid);
        assert!(axes(&p.joints).iter().all(|x| x.is_finite()));
        last_stamp = p.stamp_ns;
    }
}

/// An enabled drive reaches a reachable target within the bound, then holds it.
pub fn reaches_a_reachable_target_and_holds<H: DrivesHarness>(h: &mut H) {
    let target = h.reachable_target();
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    h.drives().set_targets(target).unwrap();
    settle(h);
    let p = positions(h);
    assert!(p.valid);
    assert!(
        distance_m(&p.joints, &target) <= h.tolerance_m(),
        "{p:?} vs {target:?}"
    );
    settle(h);
    let p = positions(h);
    assert!(
        distance_m(&p.joints, &target) <= h.tolerance_m(),
        "{p:?} vs {target:?}"
    );
    assert_eq!(state(h), DriveState::Enabled);
}

/// A transient fault shows as `Fault` with invalid positions, refuses targets,
/// `enable` and `disable`, accepts `quick_stop` but stays `Fault` (a fault is
/// only ever cleared by `fault_reset`, as [`sar_hal::DriveState`] says),
/// and `fault_reset` clears it to `Ready`. (Fails when the harness is unable
/// to provoke a fault; passes, saying so, only when it declares the check not
/// applicable.)
pub fn transient_fault_is_reported_and_reset<H: DrivesHarness>(h: &mut H) {
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    if h.provoke_fault()
        .require("transient_fault_is_reported_and_reset")
        .is_none()
    {
        return;
    }
    assert!(
        matches!(state(h), DriveState::Fault { .. }),
        "{:?}",
        state(h)
    );
    h.let_time_pass(h.report_age_bound_ns());
    assert!(!positions(h).valid);
    let target = h.reachable_target();
    assert_eq!(
        kind(h.drives().set_targets(target)),
        Some(ErrorKind::InvalidState)
    );
    assert_eq!(kind(h.drives().enable()), Some(ErrorKind::InvalidState));
    assert_eq!(kind(h.drives().disable()), Some(ErrorKind::InvalidState));
    let faulted = state(h);
    assert!(matches!(faulted, DriveState::Fault { .. }), "{faulted:?}");
    h.drives().quick_stop().unwrap();
    assert_eq!(
        state(h),
        faulted,
        "quick_stop in Fault must leave the fault"
    );
    h.drives().fault_reset().unwrap();
    await_state(h, DriveState::Ready);
    h.drives().enable().unwrap();
    await_state(h, DriveState::Enabled);
    h.let_time_pass(h.report_age_bound_ns());
    assert!(positions(h).valid);
}
