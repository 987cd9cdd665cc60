//! The loop's pure step with the simulator: a planned move follows the
//! time-optimal plan within the speed limit and arrives; an axis that stops
//! following is a Fault of its own reason with the quick stop in the same
//! cycle; limit changes within their ceilings; a move under way that pushes
//! along a force above the warn limit is braked; and the recorded inputs of a
//! run replay through a fresh step to the same decisions, bit for bit.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

// The other tests of the step on the simulator, in this binary (one binary:
// less to link).
#[path = "step/following.rs"]
mod following;
#[path = "step/guard_action.rs"]
mod guard_action;
#[path = "step/retreat.rs"]
mod retreat;
#[path = "step/shape.rs"]
mod shape;
#[path = "step/snapshot.rs"]
mod snapshot;
#[path = "step/step_properties.rs"]
mod step_properties;

use sar_config as config;
use sar_estimator::Vec3;
use sar_estimator::guard::{ForceLimits, GuardState, Reason};
use sar_hal::{AxisDrives, DriveState, SimClock};
use sar_kinematics::{ActiveJoints, inverse};
use sar_loop::control::{ReplyStatus, Request};
use sar_loop::step::DriveAction;
use sar_sim::{SimDrives, SimError};
use sar_test_support::drives::{DriveHook, Hooked};
use sar_test_support::rig::{RigBuilder, SimRig};

/// Simulated drives that can be blocked: after `block_after` setpoints,
/// further ones are ignored (a blocked, slipping or disconnected axis: the
/// axes stay where they are while the loop's trajectory goes on).
struct Blockable {
    setpoints: u32,
    block_after: Option<u32>,
}

impl DriveHook<SimDrives<SimClock>> for Blockable {
    fn set_targets(
        &mut self,
        inner: &mut SimDrives<SimClock>,
        t: ActiveJoints,
    ) -> Result<(), SimError> {
        self.setpoints += 1;
        if self.block_after.is_some_and(|n| self.setpoints > n) {
            return Ok(());
        }
        inner.set_targets(t)
    }
}

/// The demo robot on blockable drives (every cycle's input and decision
/// kept, for the replay check).
struct Rig(SimRig<Hooked<SimDrives<SimClock>, Blockable>>);

sar_test_support::deref_rig!(Rig => SimRig<Hooked<SimDrives<SimClock>, Blockable>>);

impl Rig {
    fn new(contact: Vec<sar_sim::ContactKey>, block_after: Option<u32>) -> Self {
        let hook = Blockable {
            setpoints: 0,
            block_after,
        };
        let mut rig =
            Self(RigBuilder::demo(contact).build_with(|drives| Hooked::new(drives, hook)));
        // The automatic reset, accepted once the mean at rest is complete
        // (500 samples of the 500 Hz sensor: 1000 cycles), then the drives
        // come up.
        for _ in 0..1020 {
            rig.step();
        }
        assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));
        assert_eq!(rig.c.output().guard_state, GuardState::Ok);
        rig
    }

    fn request(&mut self, id: u64, request: Request) -> ReplyStatus {
        self.0.request(id, request).status
    }

    fn joints(&self) -> [f64; 3] {
        let q = self.c.loop_input().joints.joints;
        [q.q1_m, q.q2_m, q.q3_m]
    }
}

fn quiet() -> Vec<sar_sim::ContactKey> {
    sar_test_support::messages::contact_pulse(0, 1, 2, 3, Vec3::zeros())
}

/// A move is planned by the loop: its end point goes to the drives once (they
/// run the same profile under the same limits), the axes stay within a
/// small fraction of the tolerance of the loop's trajectory all along, within
/// the configured speed, and end at the target.
#[test]
fn a_planned_move_follows_its_trajectory_and_arrives() {
    let cfg = config::builtin().unwrap();
    let mut rig = Rig::new(quiet(), None);
    let target_tip = Vec3::new(0.58, 0.21, 0.01);
    let target = inverse(
        &cfg.estimator.calibration,
        &cfg.estimator.profile,
        &target_tip,
    )
    .unwrap();
    assert_eq!(
        rig.request(1, Request::MoveTip { tip_m: target_tip }),
        ReplyStatus::Accepted
    );
    let first = rig.c.decision().action;
    let mut worst_error_m: f64 = 0.0;
    let mut fastest_mps: f64 = 0.0;
    let mut previous = rig.joints();
    let mut setpoints = 0;
    for _ in 0..4000 {
        let d = rig.step();
        assert_eq!(d.estimate.guard_state, GuardState::Ok, "{:?}", d.estimate);
        if let DriveAction::Setpoint(_) = d.action {
            setpoints += 1;
        }
        let q = rig.joints();
        let r = d.reference.expect("a trajectory while released");
        for (m, c) in q.iter().zip([r.q1_m, r.q2_m, r.q3_m]) {
            worst_error_m = worst_error_m.max((m - c).abs());
        }

        for (a, b) in q.iter().zip(previous) {
            fastest_mps = fastest_mps.max((a - b).abs() / 1e-3);
        }
        previous = q;
    }
    let end = rig.joints();
    for (m, t) in end.iter().zip([target.q1_m, target.q2_m, target.q3_m]) {
        assert!((m - t).abs() < 2e-6, "ended at {end:?}, target {target:?}");
    }
    // The same profile on both sides: what is left is the encoder's
    // quantisation and the sample's age (under 2 % of the 1 mm tolerance),
    // and the servos' lag behind the profile (issue 26: the demo's axes are
    // servos of 30 Hz, 0.7: 2 zeta / wn at the planned speed, 0.15 mm).
    let lag_m = cfg.axes.motion.servo_lag_s() * cfg.axes.max_speed_mps;
    assert!(
        worst_error_m < 0.02 * cfg.axes.following_tolerance_m + lag_m,
        "worst following error {worst_error_m} m"
    );
    // The speed limit of planned moves (0.02 m/s) with the encoder's
    // quantisation over one period.
    assert!(
        fastest_mps < cfg.axes.max_speed_mps * 1.1,
        "{fastest_mps} m/s"
    );
    assert_eq!(setpoints, 0, "the end point goes once, with the reply");
    assert_eq!(first, DriveAction::Setpoint(target), "{first:?}");
    println!(
        "planned move: worst following error {:.1} um, fastest {:.4} m/s, {setpoints} setpoints",
        worst_error_m * 1e6,
        fastest_mps
    );
}

/// Axes that do not follow (the move's end point ignored): a Fault with the
/// following-error reason once the trajectory is 1 mm away, the quick stop
/// in the same cycle, moves refused until a reset.
#[test]
fn an_axis_that_stops_following_is_a_fault_with_its_own_reason() {
    let mut rig = Rig::new(quiet(), Some(0));
    assert_eq!(
        rig.request(
            1,
            Request::MoveTip {
                tip_m: Vec3::new(0.56, 0.22, 0.02),
            }
        ),
        ReplyStatus::Accepted
    );
    // The cycle of the reply: the move starts there.
    let moved_at = rig.cycle;
    let mut fault = None;
    for _ in 0..3000 {
        let d = rig.step();
        if d.estimate.guard_state == GuardState::Fault {
            fault = Some(d);
            break;
        }
    }
    let d = fault.expect("no fault");
    // At 0.2 m/s^2 the trajectory is 1 mm away after 100 ms; the fault
    // comes within a few cycles of that.
    let after_ms = d.estimate.cycle - moved_at;
    assert!(
        (95..=110).contains(&after_ms),
        "fault {after_ms} ms after the move"
    );
    assert!(
        matches!(d.estimate.guard_reason, Reason::FollowingError { .. }),
        "{:?}",
        d.estimate.guard_reason
    );
    assert_eq!(d.action, DriveAction::QuickStop);
    assert_eq!(rig.c.counts().stops_in_same_cycle, 1);
    assert_eq!(
        rig.request(
            2,
            Request::MoveTip {
                tip_m: Vec3::new(0.6, 0.2, 0.0),
            }
        ),
        ReplyStatus::Halted
    );
}

/// Limits change within their ceilings; the published limits follow; a stop
/// limit above its ceiling is refused and changes nothing.
#[test]
fn limits_change_within_their_ceilings() {
    let mut rig = Rig::new(quiet(), None);
    let configured = rig.c.decision().limits;
    let lowered = ForceLimits {
        warn_axial_n: 5.0,
        stop_axial_n: 7.0,
        ..configured
    };
    assert_eq!(
        rig.request(1, Request::SetLimits(lowered)),
        ReplyStatus::Accepted
    );
    assert_eq!(rig.c.decision().limits, lowered);
    let above = ForceLimits {
        stop_axial_n: configured.stop_axial_n + 1.0,
        ..configured
    };
    assert_eq!(
        rig.request(2, Request::SetLimits(above)),
        ReplyStatus::LimitsRefused
    );
    assert_eq!(rig.c.decision().limits, lowered);
}

/// A push along the rod (the demo's contact, 9 N) reaches Warn while the tip
/// is moving deeper along it: the move is braked, a further move along the
/// force is refused, and a move back out is accepted. Then the run's recorded
/// inputs replay through a fresh step to the same decisions, bit for bit.
#[test]
fn a_move_into_a_warning_force_is_braked_and_a_run_replays_bit_for_bit() {
    // 9 N along +x (the rod's direction at the start) from 1.02 s to 1.52 s.
    let contact = sar_test_support::messages::contact_pulse(
        1_020_000_000,
        1_520_000_000,
        60_000_000_000,
        60_100_000_000,
        Vec3::new(9.0, 0.0, 0.0),
    );
    let mut rig = Rig::new(contact, None);
    // Deeper along +x by 4 cm: 2 s at 0.02 m/s, so Warn comes mid-move.
    let deeper = Vec3::new(0.64, 0.2, 0.0);
    assert_eq!(
        rig.request(1, Request::MoveTip { tip_m: deeper }),
        ReplyStatus::Accepted
    );
    let mut warned_at = None;
    for _ in 0..3000 {
        let d = rig.step();
        if warned_at.is_none() && d.estimate.guard_state == GuardState::Warn {
            warned_at = Some(d.estimate.cycle);
        }
        assert_ne!(d.estimate.guard_state, GuardState::Stop);
    }
    assert!(warned_at.is_some(), "no Warn");
    let tip_now = rig.c.output().pose.unwrap().tip_m;
    assert!(
        tip_now.x < deeper.x - 0.005,
        "the move was not braked: tip at {tip_now:?}"
    );
    // Still in Warn: further along the force is refused, back out accepted.
    assert_eq!(rig.c.output().guard_state, GuardState::Warn);
    assert_eq!(
        rig.request(2, Request::MoveTip { tip_m: deeper }),
        ReplyStatus::TowardForce
    );
    assert_eq!(
        rig.request(
            3,
            Request::MoveTip {
                tip_m: Vec3::new(0.59, 0.2, 0.0),
            }
        ),
        ReplyStatus::Accepted
    );
    for _ in 0..200 {
        rig.step();
    }

    // Replay: the same inputs through a fresh step (Debug prints every f64
    // exactly: shortest round trip).
    assert!(rig.log.len() > 3000);
    rig.replays_bit_for_bit();
}

/// An excitation (issue 26, `Request::Excite`): accepted at rest, streamed
/// one period ahead about where the axes rest (the axes follow it within a
/// small fraction of the tolerance, they move by about its amplitude, it
/// ends at rest at its centre); refused above `[identify]`'s limits and
/// while the axes move, each with its exact detail; a new move ends one
/// under way from its position and velocity. The run replays bit for bit.
#[test]
fn an_excitation_runs_about_the_rest_and_replays_bit_for_bit() {
    use sar_loop::excite::{ExciteRefusal, ExciteRequest};
    use sar_loop::step::ReplyDetail;
    let cfg = config::builtin().unwrap();
    let mut rig = Rig::new(quiet(), None);
    let centre = rig.joints();
    // Peaks 0.012, 0.016, 0.009 m/s (below the drives' 0.02 m/s).
    let request = ExciteRequest {
        amplitude_m: [0.0015, 0.0015, 0.003],
        freq_hz: [1.3, 1.7, 0.5],
        duration_s: 3.0,
        fade_s: 1.0,
    };
    // 1 cm at 1.3 Hz: 0.082 m/s, above the 0.02 m/s of [identify].
    let too_fast = ExciteRequest {
        amplitude_m: [0.01, 0.0, 0.0],
        ..request
    };
    let r = rig.0.request(1, Request::Excite(too_fast));
    assert_eq!(r.status, ReplyStatus::BadArgument);
    assert_eq!(
        r.detail.to_string(),
        "the excitation of q1 peaks at 0.0816814 m/s (its fades included), above [identify] excitation_max_speed_mps = 0.02 m/s"
    );
    // Issue 33: a fade of 1 us, of one period (1 ms) or of 50 periods
    // would end in a step of the set points: refused before anything
    // moves (below 100 periods), whatever the amplitude; a slow sine of
    // 3 cm whose peaks are within the limits but whose 0.2 s fade is not
    // (0.24 m/s), refused by its faded peaks.
    let sweep = ExciteRequest {
        amplitude_m: [0.0, 0.0, 0.03],
        freq_hz: [1.0, 1.0, 0.05],
        duration_s: 10.0,
        fade_s: 1e-6,
    };
    for (id, fade_s) in [(11, 1e-6), (12, 1e-3), (13, 0.05)] {
        let r = rig
            .0
            .request(id, Request::Excite(ExciteRequest { fade_s, ..sweep }));
        assert_eq!(r.status, ReplyStatus::BadArgument, "fade {fade_s} s");
        assert!(
            matches!(
                r.detail,
                ReplyDetail::Excitation(ExciteRefusal::Bad {
                    field: "fade_s",
                    ..
                })
            ),
            "fade {fade_s} s: {}",
            r.detail
        );
        assert!(r.detail.to_string().contains("100 periods"), "{}", r.detail);
    }
    let r = rig.0.request(
        14,
        Request::Excite(ExciteRequest {
            fade_s: 0.2,
            ..sweep
        }),
    );
    assert_eq!(r.status, ReplyStatus::BadArgument);
    assert!(
        r.detail
            .to_string()
            .starts_with("the excitation of q3 peaks at 0.2356"),
        "{}",
        r.detail
    );
    assert!(
        matches!(rig.c.decision().action, DriveAction::None),
        "{:?}",
        rig.c.decision().action
    );
    let r = rig.0.request(2, Request::Excite(request));
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let mut worst_error_m: f64 = 0.0;
    let mut span_m = [0.0f64; 3];
    let mut peak_accel_mps2: f64 = 0.0;
    for k in 0..3100 {
        let d = rig.step();
        peak_accel_mps2 = peak_accel_mps2.max(d.motion.accel_mps2.norm());
        assert_eq!(d.estimate.guard_state, GuardState::Ok, "{:?}", d.estimate);
        if k < 2990 {
            assert!(matches!(d.action, DriveAction::Stream(_)), "{:?}", d.action);
        }
        let q = rig.joints();
        let r = d.reference.unwrap();
        for (m, c) in q.iter().zip([r.q1_m, r.q2_m, r.q3_m]) {
            worst_error_m = worst_error_m.max((m - c).abs());
        }
        for ((s, a), c) in span_m.iter_mut().zip(q).zip(centre) {
            *s = s.max((a - c).abs());
        }
        if k == 500 {
            // Moving: a second excitation is refused.
            let r = rig.0.request(3, Request::Excite(request));
            assert_eq!(r.status, ReplyStatus::AxesMoving);
            assert!(matches!(r.detail, ReplyDetail::AxesMoving { .. }));
        }
    }
    // The estimator is handed the excitation's motion (the servo model
    // following its set points): its peak near the largest axis's A w^2.
    let planned_mps2 = request
        .amplitude_m
        .iter()
        .zip(request.freq_hz)
        .map(|(a, f)| a * (std::f64::consts::TAU * f).powi(2))
        .fold(0.0, f64::max);
    assert!(
        peak_accel_mps2 > 0.8 * planned_mps2 && peak_accel_mps2 < 1.6 * planned_mps2,
        "motion's peak {peak_accel_mps2} m/s^2, the plan's {planned_mps2}"
    );
    for (s, a) in span_m.iter().zip(request.amplitude_m) {
        assert!(*s > 0.8 * a && *s < 1.05 * a, "span {span_m:?}");
    }
    for (m, c) in rig.joints().iter().zip(centre) {
        assert!(
            (m - c).abs() < 2e-6,
            "ended at {:?}, centre {centre:?}",
            rig.joints()
        );
    }
    assert!(
        worst_error_m < 0.3 * cfg.axes.following_tolerance_m,
        "worst following error {worst_error_m} m"
    );
    // A move during an excitation ends it, from where it is and how fast.
    assert_eq!(
        rig.request(4, Request::Excite(request)),
        ReplyStatus::Accepted
    );
    for _ in 0..1500 {
        rig.step();
    }
    let tip = rig.c.output().pose.unwrap().tip_m;
    assert_eq!(
        rig.request(5, Request::MoveTip { tip_m: tip }),
        ReplyStatus::Accepted
    );
    for _ in 0..1500 {
        let d = rig.step();
        assert_eq!(d.estimate.guard_state, GuardState::Ok, "{:?}", d.estimate);
    }
    println!(
        "excitation: worst following error {:.1} um, spans {span_m:?} m, motion's peak {peak_accel_mps2:.3} m/s^2 (plan {planned_mps2:.3})",
        worst_error_m * 1e6
    );
    rig.replays_bit_for_bit();
}
