//! The support watch (issue 34 section 3): the simulator's support moves
//! (`[[support_shift]]`, ramped in over 0.5 s from 1.3 s), then the tip
//! makes the free moves of `sarctl support check` (the pose sequence of
//! `SUPPORT_CHECK_OFFSETS_M` about the start, at the configured speed) through the
//! real controller in simulated time. Asserted: a 10 mm shift upwards is
//! named and force control is then refused with the reason, until the
//! operator confirms; a still support over the same moves is never named;
//! a contact makes the check say it could not run. Printed
//! (`--nocapture`; SAFETY.md and the README quote them): the estimated
//! shift +- its standard error against the truth for 3, 5 and 10 mm along
//! X0 (along the rod), Y0 (up, across) and Z0 (across, horizontal).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use crate::rig::{Plant, Rig, TIP_M};
use sar_estimator::Vec3;
use sar_estimator::support::{SupportStatus, SupportVerdict};
use sar_loop::control::{ReplyStatus, Request};
use sar_loop::step::{ReplyDetail, SUPPORT_CHECK_OFFSETS_M, SUPPORT_CHECK_ROUNDS, SupportWhy};
use sar_sim::{ContactKey, SupportShift};

/// When the shift starts, ns (the rig is ready at 1.1 s).
const SHIFT_AT_NS: u64 = 1_300_000_000;
/// Its ramp, ns.
const RAMP_NS: u64 = 500_000_000;

/// What one run shows.
struct Run {
    /// The status after the sequence.
    status: SupportStatus,
    /// Whether a shift was named during the run (a note with Shifted).
    named: bool,
    /// The cycle it was first named in.
    named_cycle: Option<u64>,
    /// The cycle of the first move.
    moves_cycle: u64,
    /// The status logged at the first reset.
    first_reset: Option<SupportStatus>,
    /// `[support]`'s max_std_m.
    max_std_m: f64,
}

/// The moves of [`SUPPORT_CHECK_OFFSETS_M`], each until the trajectory rests, then
/// 0.3 s at the pose; `rounds` times. With `hold_ms`, each move held that
/// many cycles instead (whether the pose was reached or not: a move slower
/// than the hold is replaced by the next one on its way).
fn held_moves(rig: &mut Rig, rounds: usize, hold_ms: Option<u32>, named: &mut Option<u64>) {
    let mut id = 10;
    for _ in 0..rounds {
        for off in SUPPORT_CHECK_OFFSETS_M {
            let tip_m = Vec3::new(TIP_M[0] + off[0], TIP_M[1] + off[1], TIP_M[2] + off[2]);
            id += 1;
            let r = rig.request(id, Request::MoveTip { tip_m });
            if hold_ms.is_some() && r.status != ReplyStatus::Accepted {
                // A move replacing one on its way may be refused (the
                // estimate's transient at the switch): counted, not a failure.
                println!("  move {id} refused: {}", r.detail);
            } else {
                assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
            }
            if let Some(hold_ms) = hold_ms {
                for _ in 0..hold_ms {
                    let d = rig.step();
                    note(named, &d, rig.cycle);
                }
                continue;
            }
            for _ in 0..4000 {
                let d = rig.step();
                note(named, &d, rig.cycle);
                if let (Some(_), Some(pose)) = (d.reference, d.estimate.pose)
                    && (pose.tip_m - tip_m).norm() < 2e-4
                {
                    break;
                }
            }
            for _ in 0..300 {
                let d = rig.step();
                note(named, &d, rig.cycle);
            }
        }
    }
}

/// The first cycle whose verdict is Shifted.
fn note(named: &mut Option<u64>, d: &sar_loop::step::LoopOutput, cycle: u64) {
    if named.is_none() && d.support.verdict == SupportVerdict::Shifted {
        *named = Some(cycle);
    }
}

/// The support shifted by `shift_m` (none: still), its friction 0.3 N, a
/// tip force `contact_n` from 1.9 s on, then the check's moves.
fn run(shift_m: Vec3, contact_n: Vec3, rounds: usize) -> (Rig, Run) {
    run_held(shift_m, contact_n, rounds, None)
}

/// [`run`] with each pose held `hold_ms` cycles (see [`held_moves`]).
fn run_held(shift_m: Vec3, contact_n: Vec3, rounds: usize, hold_ms: Option<u32>) -> (Rig, Run) {
    let key = |t_ns: u64, force_n: Vec3| ContactKey { t_ns, force_n };
    let mut rig = Rig::with_scenario(
        Vec::new(),
        vec![
            key(0, Vec3::zeros()),
            key(1_900_000_000, Vec3::zeros()),
            key(2_300_000_000, contact_n),
        ],
        Plant::Moving,
        |spec| {
            // The support's Coulomb friction along the rod (the shipped
            // scenarios' 0.3 N), which the watch estimates.
            spec.friction_n = 0.3;
            if shift_m != Vec3::zeros() {
                spec.support_shifts = vec![SupportShift {
                    t_ns: SHIFT_AT_NS,
                    shift_m,
                    duration_ns: RAMP_NS,
                }];
            }
        },
    );
    let first_reset = rig
        .log
        .iter()
        .find_map(|(_, o)| o.support_note.filter(|n| n.why == SupportWhy::FirstReset))
        .map(|n| n.status);
    let mut named = None;
    for _ in 0..1300 {
        let d = rig.step();
        note(&mut named, &d, rig.cycle);
    }
    let moves_cycle = rig.cycle;
    held_moves(&mut rig, rounds, hold_ms, &mut named);
    let last = rig.log.last().unwrap().1;
    let run = Run {
        status: last.support,
        named: named.is_some(),
        named_cycle: named,
        moves_cycle,
        first_reset,
        max_std_m: last.support_limits_m.1,
    };
    (rig, run)
}

/// The shift per axis as "+x.xx +- y.yy mm" (or "not determined").
fn text(s: &SupportStatus, max_std_m: f64) -> String {
    (0..3)
        .map(|k| {
            if s.determined(k, max_std_m) {
                format!("{:+.2} +- {:.2}", s.shift_m[k] * 1e3, s.std_m[k] * 1e3)
            } else {
                format!(
                    "n.d. ({:+.1} +- {:.1})",
                    s.shift_m[k] * 1e3,
                    s.std_m[k] * 1e3
                )
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[test]
fn a_10_mm_support_shift_is_named_and_refuses_force_control_until_confirmed() {
    let (mut rig, shifted) = run(Vec3::new(0.0, 0.01, 0.0), Vec3::zeros(), 1);
    println!(
        "support up 10 mm, one check sequence: named {:.2} s after the first move; {:?} chi2/dof {:.2}, shift (X0, Y0, Z0) mm {}",
        shifted
            .named_cycle
            .map_or(f64::NAN, |c| (c as f64 - shifted.moves_cycle as f64) * 1e-3),
        shifted.status.verdict,
        shifted.status.chi2_dof,
        text(&shifted.status, shifted.max_std_m)
    );
    assert!(shifted.named, "{:?}", shifted.status);
    assert_eq!(shifted.status.verdict, SupportVerdict::Shifted);
    let named = shifted.status.named_m.unwrap();
    assert!(named.y > 0.003, "{named:?}");
    // Force control is refused, with the reason.
    let r = rig.request(90, Request::Hold { max_force_n: 2.0 });
    assert_eq!(r.status, ReplyStatus::Refused, "{}", r.detail);
    assert!(
        matches!(r.detail, ReplyDetail::SupportShifted(_)),
        "{}",
        r.detail
    );
    assert!(
        r.detail.to_string().contains("support confirm"),
        "{}",
        r.detail
    );
    // Confirmed: accepted.
    let r = rig.request(91, Request::SupportConfirm);
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    assert_ne!(
        rig.log.last().unwrap().1.support.verdict,
        SupportVerdict::Shifted
    );
    let r = rig.request(92, Request::Hold { max_force_n: 2.0 });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    rig.replays_bit_for_bit();
}

#[test]
fn a_still_support_is_never_named_over_the_same_moves() {
    let (_, still) = run(Vec3::zeros(), Vec3::zeros(), SUPPORT_CHECK_ROUNDS);
    println!(
        "support still, two check sequences: {:?} chi2/dof {:.2}, shift (X0, Y0, Z0) mm {}; at the first reset: {}",
        still.status.verdict,
        still.status.chi2_dof,
        text(&still.status, still.max_std_m),
        still.first_reset.map_or("none".into(), |s| format!(
            "{:?} {}",
            s.verdict,
            text(&s, still.max_std_m)
        ))
    );
    assert!(!still.named, "{:?}", still.status);
    assert_eq!(still.status.verdict, SupportVerdict::Within);
    // The moves determine every axis.
    for k in 0..3 {
        assert!(
            still.status.determined(k, still.max_std_m),
            "{k}: {:?}",
            still.status
        );
        assert!(still.status.shift_m[k].abs() < 4.0 * still.status.std_m[k] + 1e-3);
    }
    assert!(still.first_reset.is_some());
}

#[test]
fn a_contact_during_the_check_says_it_could_not_run() {
    // 1.5 N across the rod (below `free_tip_max_n`, so the samples are
    // taken): the force does not follow the poses as a shift's phantom.
    let (_, touched) = run(Vec3::zeros(), Vec3::new(0.0, 0.0, 1.5), 1);
    println!(
        "tip touched (1.5 N across), one check sequence: {:?} chi2/dof {:.2}, shift (X0, Y0, Z0) mm {}",
        touched.status.verdict,
        touched.status.chi2_dof,
        text(&touched.status, touched.max_std_m)
    );
    assert_eq!(touched.status.verdict, SupportVerdict::NotFree);
    assert!(!touched.named);
}

/// The figures: 3, 5 and 10 mm along each base axis, two check sequences
/// (as `sarctl support check` runs them: longer than the 5 s window, so
/// that the samples from before the shift weigh little).
#[test]
fn support_shifts_are_estimated_within_their_standard_error() {
    for (name, axis) in [
        ("X0 (along the rod)", Vec3::x()),
        ("Y0 (up, across)", Vec3::y()),
        ("Z0 (across, horizontal)", Vec3::z()),
    ] {
        for mm in [3.0, 5.0, 10.0] {
            let truth = axis * (mm * 1e-3);
            let (_, r) = run(truth, Vec3::zeros(), SUPPORT_CHECK_ROUNDS);
            let s = &r.status;
            println!(
                "support {mm:>4} mm along {name}: estimated (X0, Y0, Z0) mm {}; {:?}, named: {}",
                text(s, r.max_std_m),
                s.verdict,
                r.named
            );
            // The axis shifted: within 3 standard errors plus 10 % (the
            // linearisation about the configured B).
            let k = axis.iamax();
            let err = (s.shift_m[k] - truth[k]).abs();
            assert!(
                err < 3.0 * s.std_m[k] + 0.1 * mm * 1e-3,
                "{name} {mm}: {s:?}"
            );
            // 5 and 10 mm are named (beyond the 3 mm limit by more than the
            // error); 3 mm may or may not be.
            if mm >= 5.0 {
                assert!(r.named, "{name} {mm}: {s:?}");
            }
        }
    }
}

/// The estimate does not depend on how long each pose is held (issue 34
/// item 3): each pose held a fixed 2.5 s or 3 s (the check's moves take up
/// to about 4 s, so most are replaced on their way), one round or two, the
/// 10 mm shift up is named and read within 3 standard errors; a still
/// support is never named. Before the friction's sign was left unknown
/// after the turning moves (`SLIDE_SHIFT_M`), the turns slid the rod one
/// way about the configured B and the other way about the shifted one (13 %
/// of the moving samples): 0.3 N of friction read with the wrong sign, one
/// round held 2.5 s said "could not run" (a contact of -0.78 N found, Y0
/// +12.1 mm) and two rounds read +7.49 +- 0.40 mm.
#[test]
fn a_shift_is_read_alike_whatever_the_holds_at_the_poses() {
    for rounds in [1, SUPPORT_CHECK_ROUNDS] {
        for hold_ms in [2500, 3000] {
            let truth = Vec3::new(0.0, 0.01, 0.0);
            let (_, shifted) = run_held(truth, Vec3::zeros(), rounds, Some(hold_ms));
            let (_, still) = run_held(Vec3::zeros(), Vec3::zeros(), rounds, Some(hold_ms));
            let s = &shifted.status;
            println!(
                "each pose held {hold_ms} ms, {rounds} round(s): up 10 mm {:?} chi2/dof {:.2}, contact {:.2?} N, shift (X0, Y0, Z0) mm {}; still {:?} {}",
                s.verdict,
                s.chi2_dof,
                s.contact_n.as_slice(),
                text(s, shifted.max_std_m),
                still.status.verdict,
                text(&still.status, still.max_std_m)
            );
            assert!(shifted.named, "{hold_ms} {rounds}: {s:?}");
            assert!(
                (s.shift_m.y - truth.y).abs() < 3.0 * s.std_m.y,
                "{hold_ms} {rounds}: {s:?}"
            );
            assert!(!still.named, "{hold_ms} {rounds}: {:?}", still.status);
        }
    }
}

/// The demo's false alarm (tests/decisions.rs seed 2): a tip force below
/// `free_tip_max_n` just after the first reset, at rest and then over the
/// check's moves, on a still support. At rest one pose determines nothing
/// (a contact reads there as a shift would); over the moves the contact,
/// an unknown of the fit, is told from a shift. Never named, force control
/// accepted.
#[test]
fn a_small_contact_after_the_first_reset_is_never_named() {
    for contact_n in [Vec3::new(1.0, -0.5, 0.3), Vec3::new(0.0, -0.8, 0.0)] {
        let (mut rig, touched) = run(Vec3::zeros(), contact_n, 1);
        println!(
            "still support, tip force {:?} N from 1.9 s: {:?} chi2/dof {:.2}, contact {:.2?} N, shift (X0, Y0, Z0) mm {}",
            contact_n.as_slice(),
            touched.status.verdict,
            touched.status.chi2_dof,
            touched.status.contact_n.as_slice(),
            text(&touched.status, touched.max_std_m)
        );
        assert!(!touched.named, "{:?}", touched.status);
        let r = rig.request(95, Request::Hold { max_force_n: 2.0 });
        assert!(
            !matches!(r.detail, ReplyDetail::SupportShifted(_)),
            "{}",
            r.detail
        );
    }
}
