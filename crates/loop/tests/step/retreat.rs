//! The way back from a Stop (issue 14 §3) and the loop's own safety rules,
//! through the real controller on the simulator in simulated time: a reset
//! while a force above the stop limit persists enters Retreat; there a move
//! deeper is refused with its exact cause, a back-out along the rod is
//! accepted, streamed to the drives one set point per period and carried out
//! at the retreat speed; the retreat ends in Ok when the force is gone, and
//! stops again when it rises. A publishing thread that stops beating is a
//! Fault of its own. The runs replay bit for bit through a fresh step.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_daemon::sim;
use sar_estimator::Vec3;
use sar_estimator::guard::{GuardState, Reason};
use sar_hal::{DriveState, SimClock};
use sar_loop::control::{Envelope, ReplyStatus, Request};
use sar_loop::step::{DriveAction, ReplyDetail};
use sar_sim::{ContactKey, SimDrives};
use sar_test_support::rig::{RigBuilder, SimRig};

/// The demo robot on the simulator, ready (see [`SimRig`]).
struct Rig(SimRig<SimDrives<SimClock>>);

sar_test_support::deref_rig!(Rig => SimRig<SimDrives<SimClock>>);

impl Rig {
    /// The demo robot with `contact` (simulator keys), reset at the start.
    fn new(contact: Vec<ContactKey>) -> Self {
        Self::with_faults(contact, Vec::new())
    }

    /// [`Rig::new`] with faults on demand.
    fn with_faults(contact: Vec<ContactKey>, faults: Vec<sar_sim::Fault>) -> Self {
        let mut scenario = sim::demo_scenario().unwrap();
        scenario.spec.contact = contact;
        scenario.spec.faults = faults;
        let mut rig = Self(RigBuilder::new(&scenario).build());
        // The automatic reset, accepted once the mean at rest is complete
        // (500 samples of the 500 Hz sensor: 1000 cycles).
        for _ in 0..1020 {
            rig.step();
        }
        assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));
        assert_eq!(rig.c.output().guard_state, GuardState::Ok);
        rig
    }

    fn tip(&self) -> Vec3 {
        self.c.output().pose.unwrap().tip_m
    }
}

/// 20 N along the rod (+X0) from 0.1 s to `off_s`, gone 0.1 s later.
fn push(off_s: f64) -> Vec<ContactKey> {
    let off_ns = (off_s * 1e9) as u64;
    sar_test_support::messages::contact_pulse(
        1_100_000_000,
        1_200_000_000,
        1_000_000_000 + off_ns,
        1_100_000_000 + off_ns,
        Vec3::new(20.0, 0.0, 0.0),
    )
}

#[test]
fn a_reset_above_stop_retreats_backs_out_at_the_retreat_speed_and_ends_in_ok() {
    let mut rig = Rig::new(push(6.0));
    let stop = rig
        .until(2000, |d| d.estimate.guard_state == GuardState::Stop)
        .expect("never stopped");
    assert_eq!(stop.action, DriveAction::QuickStop);
    // Wait until the axes have braked to rest, then reset: Retreat.
    for _ in 0..300 {
        rig.step();
    }
    let r = rig.request(1, Request::Reset);
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    assert_eq!(rig.c.output().guard_state, GuardState::Retreat);
    assert!(matches!(
        rig.c.output().guard_reason,
        Reason::RetreatEntered { .. }
    ));
    rig.until(50, |_| false);
    assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));

    // Deeper along the force: refused, with the exact cause.
    let tip = rig.tip();
    let r = rig.request(
        2,
        Request::MoveTip {
            tip_m: tip + Vec3::new(0.005, 0.0, 0.0),
        },
    );
    assert_eq!(r.status, ReplyStatus::NotReducing);
    assert!(matches!(r.detail, ReplyDetail::NotReducing { .. }));
    assert!(r.detail.to_string().contains("in retreat"), "{}", r.detail);
    // Sideways: not against the force either.
    let r = rig.request(
        3,
        Request::MoveTip {
            tip_m: tip + Vec3::new(0.0, 0.0, 0.005),
        },
    );
    assert_eq!(r.status, ReplyStatus::NotReducing);
    // A bad distance.
    let r = rig.request(4, Request::BackOut { distance_m: 0.5 });
    assert_eq!(r.status, ReplyStatus::BadArgument);

    // Back out 1 cm along the rod: accepted, streamed at the retreat speed.
    let r = rig.request(5, Request::BackOut { distance_m: 0.01 });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let retreat_speed = rig.cfg.axes.retreat_speed_mps;
    let mut streamed = 0;
    let mut last_q3 = rig.c.loop_input().joints.joints.q3_m;
    let mut fastest: f64 = 0.0;
    for _ in 0..3000 {
        let d = rig.step();
        assert_ne!(
            d.estimate.guard_state,
            GuardState::Fault,
            "{:?}",
            d.estimate.guard_reason
        );
        if matches!(d.action, DriveAction::Stream(_)) {
            streamed += 1;
        }
        let q3 = rig.c.loop_input().joints.joints.q3_m;
        fastest = fastest.max((q3 - last_q3).abs() / 1e-3);
        last_q3 = q3;
    }
    // 1 cm at 5 mm/s is 2 s (plus acceleration): one set point per cycle.
    assert!(streamed > 1900 && streamed < 2300, "{streamed} set points");
    // Encoder quantisation (1.2 um per count) over one ms adds to the speed.
    assert!(
        fastest <= retreat_speed * 1.05 + 0.0025,
        "fastest {fastest} m/s"
    );
    let moved = rig.tip() - tip;
    assert!((moved.x + 0.01).abs() < 2e-4, "the tip moved {moved:?}");
    assert!(moved.y.abs() < 2e-4 && moved.z.abs() < 2e-4, "{moved:?}");
    // The force persists (a scripted contact follows the tip): still Retreat.
    assert_eq!(rig.c.output().guard_state, GuardState::Retreat);

    // The contact goes away at 7 s: Ok, by itself.
    let ok = rig
        .until(4000, |d| d.estimate.guard_state == GuardState::Ok)
        .expect("the retreat never ended");
    assert_eq!(ok.estimate.guard_reason, Reason::BelowWarn);
    rig.replays_bit_for_bit();
}

#[test]
fn a_rising_force_in_retreat_stops_again_in_the_same_cycle() {
    // 20 N, then from 5 s rising to 30 N at 6 s.
    let contact = [
        (1_100_000_000, 0.0),
        (1_200_000_000, 20.0),
        (5_000_000_000, 20.0),
        (6_000_000_000, 30.0),
    ]
    .into_iter()
    .map(|(t_ns, f)| ContactKey {
        t_ns,
        force_n: Vec3::new(f, 0.0, 0.0),
    })
    .collect();
    let mut rig = Rig::new(contact);
    rig.until(2000, |d| d.estimate.guard_state == GuardState::Stop)
        .expect("never stopped");
    for _ in 0..300 {
        rig.step();
    }
    let r = rig.request(1, Request::Reset);
    assert_eq!(r.status, ReplyStatus::Accepted);
    assert_eq!(rig.c.output().guard_state, GuardState::Retreat);
    let stop = rig
        .until(5000, |d| d.estimate.guard_state == GuardState::Stop)
        .expect("never stopped again");
    assert!(
        matches!(stop.estimate.guard_reason, Reason::ForceRising { .. }),
        "{:?}",
        stop.estimate.guard_reason
    );
    assert_eq!(stop.action, DriveAction::QuickStop);
    rig.replays_bit_for_bit();
}

#[test]
fn a_silent_publishing_thread_is_a_fault_after_the_stall_time() {
    let mut rig = Rig::new(Vec::new());
    // A publishing thread that beats while the loop runs, then dies.
    rig.operator.publisher.watch();
    for _ in 0..100 {
        rig.operator.publisher.beat();
        let d = rig.step();
        assert_eq!(d.estimate.guard_state, GuardState::Ok);
    }
    let stall_ms = rig.cfg.loop_.publisher_stall_ns / 1_000_000;
    let mut faulted_after = None;
    for k in 1..=2 * stall_ms {
        let d = rig.step();
        if d.estimate.guard_state == GuardState::Fault {
            faulted_after = Some((k, d));
            break;
        }
    }
    let (k, d) = faulted_after.expect("no fault");
    // Idle runs from the cycle of the last beat: beyond the stall time at
    // its first millisecond past it.
    assert_eq!(k, stall_ms + 1, "faulted after {k} cycles");
    assert!(matches!(
        d.estimate.guard_reason,
        Reason::PublisherStalled { .. }
    ));
    assert_eq!(d.action, DriveAction::QuickStop);
    // systemd's watchdog is no longer fed (it restarts sard); any other
    // fault keeps it fed (the loop itself is alive).
    assert!(!sar_loop::notify::watchdog_fed(&d.estimate.guard_reason));
    assert!(sar_loop::notify::watchdog_fed(&Reason::SensorInvalid));
    // A reset is refused while it stays silent.
    rig.operator
        .requests
        .push(Envelope {
            id: 9,
            request: Request::Reset,
        })
        .unwrap();
    rig.step();
    let r = rig.operator.replies.pop().unwrap();
    assert_eq!(r.status, ReplyStatus::ResetRefused);
    assert!(
        r.detail.to_string().contains("publishing thread"),
        "{}",
        r.detail
    );
    rig.replays_bit_for_bit();
}

#[test]
fn refusals_carry_their_exact_cause() {
    let mut rig = Rig::new(Vec::new());
    // Outside the travel: which axis, where, and the travel. The tip
    // 0.15 m past B along (-0.8, 0.6, 0) puts A at x = 0.61 m: q3 beyond
    // its 0.6 m.
    let r = rig.request(
        1,
        Request::MoveTip {
            tip_m: Vec3::new(0.33, 0.29, 0.0),
        },
    );
    assert_eq!(r.status, ReplyStatus::Unreachable, "{}", r.detail);
    match r.detail {
        ReplyDetail::OutsideTravel {
            axis,
            value_m,
            min_m,
            max_m,
        } => {
            assert_eq!(axis, 3);
            assert!((value_m - 0.61).abs() < 1e-9, "{value_m}");
            assert_eq!((min_m, max_m), (0.0, 0.6));
        }
        other => panic!("{other:?}"),
    }
    assert!(r.detail.to_string().contains("outside its travel"));
    // Not a pose at all: the tip farther from the support than the rod.
    let r = rig.request(
        2,
        Request::MoveTip {
            tip_m: Vec3::new(0.6, 0.2, 0.45),
        },
    );
    assert_eq!(r.status, ReplyStatus::Unreachable);
    assert!(matches!(r.detail, ReplyDetail::NoPose(_)), "{:?}", r.detail);
    // Limits above their ceiling: which limit and why.
    let mut limits = rig.c.decision().limits;
    limits.stop_axial_n = 40.0;
    let r = rig.request(3, Request::SetLimits(limits));
    assert_eq!(r.status, ReplyStatus::LimitsRefused);
    let text = r.detail.to_string();
    assert!(
        text.contains("stop_axial_n") && text.contains("40"),
        "{text}"
    );
    // A tare right after another (accepted or not): refused by the tare's
    // own rules (its mean at rest, its rate limit), in words.
    let _ = rig.request(4, Request::Tare);
    let r = rig.request(5, Request::Tare);
    assert_eq!(r.status, ReplyStatus::Refused, "{}", r.detail);
    assert!(
        matches!(
            r.detail,
            ReplyDetail::Tare(
                sar_estimator::cycle::TareRefused::TooSoon { .. }
                    | sar_estimator::cycle::TareRefused::NotAtRest { .. }
            )
        ),
        "{:?}",
        r.detail
    );
    let text = r.detail.to_string();
    assert!(
        text.contains("since the last tare") || text.contains("samples at rest"),
        "{text}"
    );
}

#[test]
fn the_record_switch_loses_no_request() {
    use sar_record::live::RecordSwitch;
    let s = RecordSwitch::default();
    // The manager looks for a start while the operator asks stop, then start:
    // the later request survives the other side's take.
    s.request_stop();
    s.request_start();
    assert!(!s.take_stop(), "a stop overwritten by a start is not taken");
    assert!(s.take_start());
    assert!(!s.take_start(), "taken once");
    // Two threads: one asks start/stop alternately, ending with start; the
    // other takes. Whatever the interleaving, the last request is taken
    // (or still pending) and no take sees a request that was not made.
    for round in 0..200 {
        let s = std::sync::Arc::new(RecordSwitch::default());
        let asker = {
            let s = s.clone();
            std::thread::spawn(move || {
                for k in 0..(round % 7 + 1) * 2 {
                    if k % 2 == 0 {
                        s.request_stop();
                    } else {
                        s.request_start();
                    }
                }
            })
        };
        let mut starts = 0;
        let mut stops = 0;
        while !asker.is_finished() {
            starts += u32::from(s.take_start());
            stops += u32::from(s.take_stop());
            std::hint::spin_loop();
        }
        asker.join().unwrap();
        starts += u32::from(s.take_start());
        stops += u32::from(s.take_stop());
        assert!(
            starts >= 1,
            "round {round}: the final start was lost ({stops} stops)"
        );
        assert!(!s.take_start() && !s.take_stop());
    }
}

/// A drive fault (on the CANopen path: an EMCY or a lost heartbeat) is a
/// guard Fault of its own in the cycle the drives report it, with a quick
/// stop; the cause gone, a reset brings the drives back (fault reset, enable).
#[test]
fn a_drive_fault_is_a_guard_fault_and_a_reset_brings_the_drives_back() {
    let mut rig = Rig::with_faults(
        Vec::new(),
        vec![sar_sim::Fault::DriveFault {
            at_ns: 1_500_000_000,
            code: 0x8130,
        }],
    );
    let fault = rig
        .until(2000, |d| d.estimate.guard_state == GuardState::Fault)
        .expect("no fault");
    assert_eq!(
        fault.estimate.guard_reason,
        Reason::DriveFault {
            axis: 0,
            code: 0x8130
        }
    );
    assert_eq!(fault.action, DriveAction::QuickStop);
    for _ in 0..300 {
        rig.step();
    }
    // Their positions are invalid while they are faulted: the first reset
    // resets the drives, the second (once they are Ready) the guard.
    let r = rig.request(1, Request::Reset);
    assert_eq!(r.status, ReplyStatus::DrivesFaultReset, "{}", r.detail);
    assert_eq!(rig.c.decision().action, DriveAction::FaultReset);
    rig.until(20, |_| false);
    assert_eq!(rig.c.drive_state(), Some(DriveState::Ready));
    let r = rig.request(2, Request::Reset);
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    assert_eq!(
        rig.c.decision().action,
        DriveAction::Release(sar_loop::step::Release::Enable)
    );
    rig.until(20, |_| false);
    assert_eq!(rig.c.drive_state(), Some(DriveState::Enabled));
    assert_eq!(rig.c.output().guard_state, GuardState::Ok);
    rig.replays_bit_for_bit();
}
