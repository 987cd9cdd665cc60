//! Issue 34 item 4: push and hold on plants the configuration describes
//! wrongly, over the range `[force_control]` states (FORCE_CONTROL.md,
//! "Stability over the plant's range").
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use crate::rig::{Plant, Rig, TIP_M, rms, tissue};
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_loop::control::{ReplyStatus, Request};
use sar_sim::{RodInertia, ServoSpec, SimSpec};

/// A plant of the range: its name and the change to [`Plant::Moving`]'s
/// spec (the configuration's servo, 30 Hz and 0.7, and its I_perp).
struct RangePlant {
    name: &'static str,
    edit: fn(&mut SimSpec),
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

const PLANTS: [RangePlant; 7] = [
    RangePlant {
        name: "as configured (30 Hz, 0.7)",
        edit: |_| {},
    },
    RangePlant {
        name: "servo 12 Hz, damping 0.45",
        edit: |s| with_servo(s, 12.0, 0.45),
    },
    RangePlant {
        name: "servo 12 Hz, damping 1.0",
        edit: |s| with_servo(s, 12.0, 1.0),
    },
    RangePlant {
        name: "servo 30 Hz, 0.7, a pure delay of 2 ms",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                delay_ns: 2_000_000,
                ..servo(s)
            });
        },
    },
    RangePlant {
        name: "ideal drives",
        edit: |s| s.plant.servo = None,
    },
    RangePlant {
        name: "I_perp 0.5x",
        edit: |s| inertia_times(s, 0.5),
    },
    RangePlant {
        name: "I_perp 2x",
        edit: |s| inertia_times(s, 2.0),
    },
];

const STIFFNESSES: [f64; 4] = [100.0, 300.0, 1000.0, 3000.0];
const BREATH_M: f64 = 0.003;

fn rig(plant: &RangePlant, k: f64, gap_m: f64) -> Rig {
    Rig::with_scenario(
        vec![tissue(k, gap_m, BREATH_M, Vec::new())],
        Vec::new(),
        Plant::Moving,
        plant.edit,
    )
}

/// What a run saw.
#[derive(Debug, Default)]
struct Seen {
    rms_n: f64,
    peak_n: f64,
    warn_ms: usize,
    stop: bool,
}

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

/// Runs `ms` cycles; the error of each cycle from `from_ms` on by `error`.
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

const PUSH_N: f64 = 3.0;
const HOLD_N: f64 = 5.0;

fn push(plant: &RangePlant, k: f64) -> Seen {
    let mut rig = rig(plant, k, 0.0);
    start(&mut rig, Request::Push { axial_n: PUSH_N });
    run(&mut rig, 15_000, 7_000, |f| f.x - PUSH_N)
}

fn hold(plant: &RangePlant, k: f64) -> Seen {
    let mut rig = rig(plant, k, 0.0);
    let depth_m = 6.5 / k - BREATH_M;
    let target = Vec3::new(TIP_M[0] + depth_m, TIP_M[1], TIP_M[2]);
    let r = rig.request(9, Request::MoveTip { tip_m: target });
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let ms = (depth_m.abs() / 0.02 * 1e3) as usize + 300;
    for _ in 0..ms {
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

#[test]
fn push_and_hold_over_the_plant_range() {
    println!("| plant | mode | 100 N/m | 300 N/m | 1000 N/m | 3000 N/m |");
    for p in &PLANTS {
        for (mode, f) in [
            ("push 3 N", push as fn(&RangePlant, f64) -> Seen),
            ("hold 5 N", hold),
        ] {
            let cells: Vec<String> = STIFFNESSES
                .iter()
                .map(|&k| {
                    let s = f(p, k);
                    format!(
                        "{:.3} / {:.2} N{}{}",
                        s.rms_n,
                        s.peak_n,
                        if s.warn_ms > 0 {
                            format!(" W{}", s.warn_ms)
                        } else {
                            String::new()
                        },
                        if s.stop { " STOP" } else { "" }
                    )
                })
                .collect();
            println!("| {} | {mode} | {} |", p.name, cells.join(" | "));
        }
    }
}

#[test]
fn explore_limit_cycle() {
    use sar_loop::step::DriveAction;
    for p in [&PLANTS[0], &PLANTS[1], &PLANTS[4]] {
        for k in [0.0f64, 1000.0, 3000.0] {
            let mut rig = Rig::with_scenario(
                vec![tissue(k.max(1.0), 0.0, 0.0, Vec::new())],
                Vec::new(),
                Plant::Moving,
                p.edit,
            );
            start(&mut rig, Request::Push { axial_n: PUSH_N });
            let (mut f, mut est, mut q) = (Vec::new(), Vec::new(), Vec::new());
            for _ in 0..10_000 {
                let d = rig.step();
                f.push(rig.true_force_n().x);
                if let sar_estimator::cycle::TipOutcome::Estimate(e) = d.estimate.tip {
                    est.push(e.force_n.x);
                }
                if let DriveAction::Stream(j) = d.action {
                    q.push(j.q3_m);
                }
            }
            let tail = &f[8000..];
            let pp = tail.iter().copied().fold(f64::MIN, f64::max)
                - tail.iter().copied().fold(f64::MAX, f64::min);
            let mean = tail.iter().sum::<f64>() / tail.len() as f64;
            let crossings = tail
                .windows(2)
                .filter(|w| (w[0] - mean) * (w[1] - mean) < 0.0)
                .count();
            let qt = &q[q.len() - 2000..];
            let acc: Vec<f64> = qt
                .windows(3)
                .map(|w| (w[2] - 2.0 * w[1] + w[0]) / 1e-6)
                .collect();
            let amax = acc.iter().fold(0.0f64, |m, a| m.max(a.abs()));
            println!(
                "{} k {k}: true p-p {pp:.3} N mean {mean:.3}, {crossings} mean crossings in 2 s, set point accel max {amax:.3} rms {:.3}",
                p.name,
                rms(&acc)
            );
        }
    }
}
