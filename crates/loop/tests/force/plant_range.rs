//! Issue 34 item 4: push and hold through the real controller on plants
//! the configuration describes wrongly (FORCE_CONTROL.md, "Stability over
//! the plant's range"). The built-in configuration (servos of 30 Hz,
//! damping 0.7; I_perp m L^2 / 12) on the simulator's plant in motion
//! (`Plant::Moving`: the rod's inertia, compensated by the estimator with
//! the loop's servo model) changed to: the default range's corner (28.5 Hz,
//! damping 0.65), servos of 12 Hz (0.4x) with damping 0.45 and 1.0, a pure
//! delay of 2 ms, ideal drives, a rod of 0.5x and 2x the configured I_perp.
//! Push 3 N into a tissue breathing 3 mm at 0.25 Hz along the rod (RMS of
//! the true axial force's error over 7-15 s, the largest true |F|), and
//! hold 5 N under it pressed in so that position mode would peak at 6.5 N
//! (RMS of the true |F|'s excess over 5 N over 4-12 s, the largest),
//! at 100, 300, 1000 and 3000 N/m. A table is printed (`--nocapture`).
//!
//! Asserted: within the range the check holds (the configured plant, the
//! range's corner, the 2 ms delay) every push keeps RMS at most 0.3 N and
//! its peak below 4 N, every hold its peak below position mode's 6.5 N; an
//! I_perp of 0.5x or 2x changes nothing here (push and hold act along the
//! rod, which I_perp does not enter); no Stop on any plant. Beyond the
//! range (12 Hz, ideal drives) the check refuses the default law
//! (`sar-estimator`'s `force_range` tests); there the default law's pushes
//! stay within 0.05 N of the configured plant's at 1000 and 3000 N/m (the
//! servo observer; without it the loop limit-cycled on the commanded tip's
//! acceleration bound, 0.07 N or more above), and a slower law (D 130 N
//! s/m, M 1 kg, a 12 Hz filter) is run beside and asserted to be the same
//! on them as on the configured plant within 0.02 N (at its own, larger,
//! breathing error). Ideal drives are also held to the checked range's
//! goals (push RMS at most 0.3 N and below 4 N; holds as the configured
//! plant's): with the simulated sensor seeing the velocity's steps at
//! their set points over its period (`sar_sim`'s world, issue 34 item 4)
//! they are at most 0.29 N RMS; the 12 Hz servos (0.30 N at 3000 N/m) are
//! printed.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use crate::rig::{Plant, READY_MS, Rig, TIP_M, rms, tissue};
use sar_estimator::Vec3;
use sar_estimator::force_control::{Admittance, ForceControlConfig, ForceControlLimits};
use sar_estimator::guard::GuardState;
use sar_loop::control::{ReplyStatus, Request};
use sar_sim::{ContactKey, RodInertia, ServoSpec, SimSpec};
use sar_test_support::rig::RigBuilder;

/// A plant of the range: its name, the change to [`Plant::Moving`]'s spec
/// (the configuration's servo and rod) and whether the default range the
/// start-up check holds covers it.
struct RangePlant {
    name: &'static str,
    edit: fn(&mut SimSpec),
    checked: bool,
}

fn servo(s: &SimSpec) -> ServoSpec {
    s.plant.servo.expect("the plant in motion has servos")
}

fn with_servo(s: &mut SimSpec, bandwidth_hz: f64, damping: f64) {
    s.plant.servo = Some(ServoSpec {
        bandwidth_hz,
        damping,
        ..servo(s)
    });
}

fn inertia_times(s: &mut SimSpec, ratio: f64) {
    let rod: RodInertia = s.plant.inertia.expect("the plant in motion has a rod");
    s.plant.inertia = Some(RodInertia {
        inertia_perp_kgm2: ratio * rod.inertia_perp_kgm2,
        ..rod
    });
}

const PLANTS: [RangePlant; 8] = [
    RangePlant {
        name: "as configured (30 Hz, 0.7)",
        edit: |_| {},
        checked: true,
    },
    RangePlant {
        name: "the default range's corner (28.5 Hz, 0.65)",
        edit: |s| with_servo(s, 28.5, 0.65),
        checked: true,
    },
    RangePlant {
        name: "30 Hz, 0.7 and a pure delay of 2 ms",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                delay_ns: 2_000_000,
                ..servo(s)
            });
        },
        checked: true,
    },
    RangePlant {
        name: "I_perp 0.5x",
        edit: |s| inertia_times(s, 0.5),
        checked: true,
    },
    RangePlant {
        name: "I_perp 2x",
        edit: |s| inertia_times(s, 2.0),
        checked: true,
    },
    RangePlant {
        name: "12 Hz (0.4x), damping 0.45",
        edit: |s| with_servo(s, 12.0, 0.45),
        checked: false,
    },
    RangePlant {
        name: "12 Hz (0.4x), damping 1.0",
        edit: |s| with_servo(s, 12.0, 1.0),
        checked: false,
    },
    RangePlant {
        name: "ideal drives",
        edit: |s| s.plant.servo = None,
        checked: false,
    },
];

/// Ideal drives' index in [`PLANTS`].
const IDEAL: usize = 7;

const STIFFNESSES: [f64; 4] = [100.0, 300.0, 1000.0, 3000.0];
const BREATH_M: f64 = 0.003;
const PUSH_N: f64 = 3.0;
const HOLD_N: f64 = 5.0;

/// What a run saw.
#[derive(Debug, Default, Clone, Copy)]
struct Seen {
    rms_n: f64,
    peak_n: f64,
    warn_ms: usize,
    stop: bool,
}

impl Seen {
    fn cell(&self) -> String {
        let warn = if self.warn_ms > 0 {
            format!(", Warn {} ms", self.warn_ms)
        } else {
            String::new()
        };
        let stop = if self.stop { ", **Stop**" } else { "" };
        format!("{:.3} / {:.2} N{warn}{stop}", self.rms_n, self.peak_n)
    }
}

/// The demo on `plant`, a breathing tissue of stiffness `k` at the tip,
/// the built-in configuration with `limits` for its force control if given.
fn rig(plant: &RangePlant, k: f64, limits: Option<ForceControlLimits>) -> Rig {
    let tissues = vec![tissue(k, 0.0, BREATH_M, Vec::new())];
    let Some(limits) = limits else {
        return Rig::with_scenario(tissues, Vec::new(), Plant::Moving, plant.edit);
    };
    let mut cfg = sar_config::builtin().unwrap();
    cfg.force_control = ForceControlConfig::new(limits).unwrap();
    let mut scenario = sar_daemon::sim::demo_scenario().unwrap();
    scenario.spec.contact = vec![ContactKey {
        t_ns: 0,
        force_n: Vec3::zeros(),
    }];
    scenario.spec.tissue = tissues;
    scenario.spec.plant = Plant::Moving.spec(&scenario.spec);
    (plant.edit)(&mut scenario.spec);
    let mut rig = Rig(RigBuilder::new(&scenario).config(&cfg).build());
    for _ in 0..READY_MS {
        rig.step();
    }
    assert_eq!(rig.c.output().guard_state, GuardState::Ok);
    rig
}

/// Asks for `request` until the guard lets it start (Ok only).
fn start(rig: &mut Rig, request: Request) {
    for id in 1..=20_000 {
        let r = rig.request(id, request);
        if r.status == ReplyStatus::Accepted {
            return;
        }
        assert_eq!(r.status, ReplyStatus::NotOk, "{}", r.detail);
    }
    panic!("{request:?} never accepted");
}

/// Runs `ms` cycles (a Stop ends it); the error of each cycle from
/// `from_ms` on by `error` of the true F_tip.
fn run(rig: &mut Rig, ms: usize, from_ms: usize, error: impl Fn(&Vec3) -> f64) -> Seen {
    let mut seen = Seen::default();
    let mut errors = Vec::new();
    for t in 0..ms {
        let d = rig.step();
        let f = rig.true_force_n();
        seen.peak_n = seen.peak_n.max(f.norm());
        seen.warn_ms += usize::from(d.estimate.guard_state == GuardState::Warn);
        if d.estimate.guard_state.is_halting() {
            seen.stop = true;
            break;
        }
        if t >= from_ms {
            errors.push(error(&f));
        }
    }
    seen.rms_n = rms(&errors);
    seen
}

/// Push 3 N from the surface: 15 s, the RMS over 7-15 s (two breaths,
/// after the softest tissue's approach).
fn push(plant: &RangePlant, k: f64, limits: Option<ForceControlLimits>) -> Seen {
    let mut rig = rig(plant, k, limits);
    start(&mut rig, Request::Push { axial_n: PUSH_N });
    run(&mut rig, 15_000, 7_000, |f| f.x - PUSH_N)
}

/// Hold 5 N, the tissue pressed in so that position mode peaks at 6.5 N:
/// 12 s, the RMS of the excess over 5 N over 4-12 s.
fn hold(plant: &RangePlant, k: f64) -> Seen {
    let mut rig = rig(plant, k, None);
    let depth_m = 6.5 / k - BREATH_M;
    let target = Vec3::new(TIP_M[0] + depth_m, TIP_M[1], TIP_M[2]);
    let r = rig.request(9, Request::MoveTip { tip_m: target });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    for _ in 0..(depth_m.abs() / 0.02 * 1e3) as usize + 300 {
        rig.step();
    }
    start(
        &mut rig,
        Request::Hold {
            max_force_n: HOLD_N,
        },
    );
    run(&mut rig, 12_000, 4_000, |f| (f.norm() - HOLD_N).max(0.0))
}

/// The slower law run beside beyond the range: D 130 N s/m and M 1 kg
/// along the rod, a 12 Hz filter (FORCE_CONTROL.md).
fn slower_law() -> ForceControlLimits {
    ForceControlLimits {
        axial: Admittance {
            mass_kg: 1.0,
            damping_n_s_per_m: 130.0,
        },
        filter_cutoff_hz: 12.0,
        max_stiffness_n_per_m: 3000.0,
        ..ForceControlLimits::default()
    }
}

#[test]
fn push_and_hold_over_the_servo_and_inertia_ranges() {
    println!(
        "| plant | mode: RMS / largest | 100 N/m | 300 N/m | 1000 N/m | 3000 N/m |\n|---|---|---|---|---|---|"
    );
    let mut pushes = Vec::new();
    let mut holds = Vec::new();
    for p in &PLANTS {
        let push_row: Vec<Seen> = STIFFNESSES.iter().map(|&k| push(p, k, None)).collect();
        let hold_row: Vec<Seen> = STIFFNESSES.iter().map(|&k| hold(p, k)).collect();
        for (mode, row) in [("push 3 N", &push_row), ("hold 5 N", &hold_row)] {
            let cells: Vec<String> = row.iter().map(Seen::cell).collect();
            println!("| {} | {mode} | {} |", p.name, cells.join(" | "));
        }
        pushes.push(push_row);
        holds.push(hold_row);
    }
    for (i, p) in PLANTS.iter().enumerate() {
        for (j, k) in STIFFNESSES.iter().enumerate() {
            let (s, h) = (pushes[i][j], holds[i][j]);
            assert!(!s.stop && !h.stop, "{} at {k} N/m: a Stop", p.name);
            // Ideal drives meet the goal too (issue 34 item 4; 0.29 N at
            // 3000 N/m), though the check refuses them.
            if p.checked || i == IDEAL {
                assert!(s.rms_n <= 0.3, "{} at {k} N/m: push RMS {s:?}", p.name);
                assert!(s.peak_n < 4.0, "{} at {k} N/m: push {s:?}", p.name);
                assert!(h.peak_n < 6.5, "{} at {k} N/m: hold {h:?}", p.name);
                // The hold's excess within 0.05 N of the configured plant's.
                assert!(h.rms_n <= holds[0][j].rms_n + 0.05, "{} {k}", p.name);
            }
        }
    }
    // I_perp does not enter a push or a hold along the rod.
    for i in [3, 4] {
        for j in 0..STIFFNESSES.len() {
            assert!((pushes[i][j].rms_n - pushes[0][j].rms_n).abs() < 0.005);
            assert!((holds[i][j].peak_n - holds[0][j].peak_n).abs() < 0.05);
        }
    }
    // Beyond the range: the slower law, pushing. It gives up accuracy
    // (its breathing error D v is larger) for a loop the servo's mismatch
    // no longer changes.
    println!(
        "| slower law (D 130, M 1, 12 Hz filter) | push 3 N: RMS / largest | 1000 N/m | 3000 N/m |"
    );
    let mut slower = Vec::new();
    for i in [0, 5, 6, 7] {
        let row: Vec<Seen> = [1000.0, 3000.0]
            .iter()
            .map(|&k| push(&PLANTS[i], k, Some(slower_law())))
            .collect();
        println!(
            "| {} | | {} | {} |",
            PLANTS[i].name,
            row[0].cell(),
            row[1].cell()
        );
        slower.push(row);
    }
    // The 12 Hz servos and ideal drives.
    for (row, i) in slower.iter().zip([0, 5, 6, 7]).skip(1) {
        for (j, seen) in row.iter().enumerate() {
            assert!(!seen.stop, "{}", PLANTS[i].name);
            // The default law on this plant: 0.08-0.24 N above the
            // configured plant's at 1000 and 3000 N/m with the servo model
            // alone; with the servo observer (issue 34), which follows the
            // slower servo once its encoders leave the model, 0.03 N (ideal
            // drives: 0.02 N, since the simulated sensor sees their
            // velocity's steps over its period, `sar_sim`'s world); the
            // slower law: the same within 0.02 N.
            let default_law = pushes[i][j + 2].rms_n - pushes[0][j + 2].rms_n;
            let slower_law = seen.rms_n - slower[0][j].rms_n;
            assert!(
                (0.0..0.05).contains(&default_law),
                "{} {default_law}",
                PLANTS[i].name
            );
            assert!(slower_law.abs() < 0.02, "{} {slower_law}", PLANTS[i].name);
        }
    }
}
