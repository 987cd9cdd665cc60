//! Issue 34, when the world is not the model: free moves at 50 mm/s and
//! 1 m/s^2 between three tips (no tissue: the true tip force is 0) through
//! the same controller as `sard --sim`, on plants that the configuration
//! (the built-in one, at those limits) describes wrongly: slower and less
//! damped servos, a pure delay, an inner velocity loop, ideal drives, a rod
//! of 1.6x the configured I_perp with an adapter the configuration leaves
//! out, the support moving 10 mm up during the moves. Printed
//! (`--nocapture`), one row per plant: the phantom tip force (RMS and peak
//! over the moves, the sensor's noise 1 % of the HEX-6's so that the model
//! error shows, not the noise), and the share of the new samples' axes
//! (x, y, z of each) whose error lies within 3 of the estimate's own
//! standard deviations (the configured HEX-6 noise, simulated as
//! configured: what the guard's margin stands on; 99.73 % for a Gaussian
//! error that the standard deviation describes).
//!
//! Also printed: when the daemon named the servo mismatch (the published
//! state's `servo_fit`, `sar_loop::observer::ServoFit::named`), in seconds
//! after the first move was requested.
//!
//! Asserted: on the plant the configuration describes, the phantom is at
//! most 0.3 N RMS and at least 99 % of the samples' axes are within 3 standard
//! deviations, and the servo is never named; every other plant shows a
//! larger phantom (the harness sees each mismatch). Issue 34's goal for the
//! servos (bandwidth 0.4x to ideal, damping 0.45-1.0, a delay of 1-2 ms, an
//! inner loop): the phantom within 0.3 N RMS and 1 N peak, or else the
//! mismatch named within 2 s of motion; and on each, the true error within
//! 3 standard deviations in at least 99 % of the samples' axes (the
//! servo observer, `sar_loop::observer`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use crate::rig::{Plant, READY_MS, Rig, TIP_M, rms};
use sar_config as config;
use sar_estimator::Vec3;
use sar_estimator::cycle::TipOutcome;
use sar_estimator::guard::GuardState;
use sar_loop::control::{ReplyStatus, Request};
use sar_sim::{ContactKey, PlantSpec, RodInertia, ServoSpec, SimSpec, SupportShift};
use sar_test_support::rig::RigBuilder;

/// The sensor's noise in the phantom runs, a fraction of the HEX-6's.
const NOISE_FRACTION: f64 = 0.01;
/// Cycles (ms) given to each move.
const MOVE_MS: u64 = 1500;

/// A plant the configuration does not describe: a name and the change to
/// the simulator's spec (its plant is [`Plant::Moving`]'s first).
struct Mismatch {
    name: &'static str,
    edit: fn(&mut SimSpec),
}

fn servo(spec: &SimSpec) -> ServoSpec {
    spec.plant.servo.expect("the plant in motion has servos")
}

fn inertia(spec: &SimSpec) -> RodInertia {
    spec.plant
        .inertia
        .expect("the plant in motion has a rod inertia")
}

/// How many rows of [`MISMATCHES`] are servos (issue 34 section 1's goal).
const SERVO_ROWS: usize = 7;

const MISMATCHES: [Mismatch; 9] = [
    Mismatch {
        name: "as configured (30 Hz, damping 0.7; I_perp as configured)",
        edit: |_| {},
    },
    Mismatch {
        name: "servos at 12 Hz, damping 0.45",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                bandwidth_hz: 12.0,
                damping: 0.45,
                ..servo(s)
            });
        },
    },
    Mismatch {
        name: "servos at 12 Hz, damping 1.0",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                bandwidth_hz: 12.0,
                damping: 1.0,
                ..servo(s)
            });
        },
    },
    Mismatch {
        name: "servos with a pure delay of 1 ms",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                delay_ns: 1_000_000,
                ..servo(s)
            });
        },
    },
    Mismatch {
        name: "servos with a pure delay of 2 ms",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                delay_ns: 2_000_000,
                ..servo(s)
            });
        },
    },
    Mismatch {
        name: "servos with an inner velocity loop at 60 Hz (third order)",
        edit: |s| {
            s.plant.servo = Some(ServoSpec {
                inner_loop_hz: 60.0,
                ..servo(s)
            });
        },
    },
    Mismatch {
        name: "ideal drives (no lag)",
        edit: |s| s.plant.servo = None,
    },
    Mismatch {
        name: "rod of 1.6x the configured I_perp, a 0.35 kg adapter not configured",
        edit: |s| {
            let rod = inertia(s);
            s.plant.inertia = Some(RodInertia {
                inertia_perp_kgm2: 1.6 * rod.inertia_perp_kgm2,
                adapter_mass_kg: 0.35,
                ..rod
            });
        },
    },
    Mismatch {
        name: "the support shifted 10 mm up over 2 s, tip free",
        edit: |s| {
            s.support_shifts = vec![SupportShift {
                t_ns: READY_MS * 1_000_000 + 200_000_000,
                shift_m: Vec3::new(0.0, 0.01, 0.0),
                duration_ns: 2_000_000_000,
            }];
        },
    },
];

/// The built-in configuration at the fastest the plausibility check allows
/// (50 mm/s) and 1 m/s^2.
fn fast_config() -> config::Config {
    let mut cfg = config::builtin().unwrap();
    cfg.axes.max_speed_mps = 0.05;
    cfg.axes.max_accel_mps2 = 1.0;
    // A servo of 12 Hz, damping 1.0 lags 2 zeta / wn = 26.5 ms, 1.3 mm at
    // 50 mm/s: beyond the built-in 1 mm following tolerance (a Fault, as
    // it should on a robot whose servo is that slow).
    cfg.axes.following_tolerance_m = 0.002;
    cfg
}

/// The demo on the plant in motion changed by `edit`, without tissue, the
/// sensor's noise scaled by `noise_fraction`, the drives at `cfg`'s
/// profile; ready (reset after the mean at rest).
fn rig(cfg: &config::Config, edit: fn(&mut SimSpec), noise_fraction: f64) -> Rig {
    let scenario = scenario(cfg, edit, noise_fraction);
    let mut rig = Rig(RigBuilder::new(&scenario).config(cfg).build());
    for _ in 0..READY_MS {
        rig.step();
    }
    assert_eq!(rig.c.output().guard_state, GuardState::Ok);
    rig
}

/// The scenario of [`rig`].
fn scenario(
    cfg: &config::Config,
    edit: fn(&mut SimSpec),
    noise_fraction: f64,
) -> sar_config::scenario::Scenario {
    let mut scenario = sar_daemon::sim::demo_scenario().unwrap();
    let spec = &mut scenario.spec;
    spec.sensor.noise_n *= noise_fraction;
    spec.sensor.noise_nm *= noise_fraction;
    spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
    spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
    spec.contact = vec![ContactKey {
        t_ns: 0,
        force_n: Vec3::zeros(),
    }];
    spec.tissue = Vec::new();
    spec.plant = Plant::Moving.spec(spec);
    edit(spec);
    scenario
}

/// What the estimate did over the moves (new samples only).
struct Figures {
    /// |F_tip| estimated (the truth is 0), N.
    phantom_n: Vec<f64>,
    /// Per sample and axis: whether the error was within 3 of the axis's
    /// standard deviations.
    within_3_sigma: Vec<bool>,
    /// When the servo mismatch was named, s after the first move was
    /// requested (`None`: never).
    named_after_s: Option<f64>,
}

/// Three free moves (out, across, back to the start) on `rig`.
fn free_moves(mut rig: Rig) -> Figures {
    let start = Vec3::new(TIP_M[0], TIP_M[1], TIP_M[2]);
    let tips = [
        start + Vec3::new(0.03, 0.015, -0.015),
        start + Vec3::new(-0.01, -0.02, 0.02),
        start,
    ];
    let (mut phantom_n, mut within_3_sigma) = (Vec::new(), Vec::new());
    let mut named_after_s = None;
    let mut cycles = 0u64;
    for (id, tip_m) in (1..).zip(tips) {
        let r = rig.request(id, Request::MoveTip { tip_m });
        assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
        for _ in 0..MOVE_MS {
            let out = rig.step();
            cycles += 1;
            if out.servo_fit.named && named_after_s.is_none() {
                named_after_s = Some(cycles as f64 * 1e-3);
                // Named once, in the cycle it happens: what the log says.
                assert!(out.servo_named_now);
                let text = sar_loop::logq::servo_mismatch_text(
                    &out.servo_fit.follow_rms_per_axis_m(),
                    &out.servo_fit.disturbance_mps2,
                    out.encoder_count_m,
                );
                assert!(text.contains("run `sarctl identify --servo`"), "{text}");
            } else {
                assert!(!out.servo_named_now);
            }
            if !out.estimate.new_sample {
                continue;
            }
            if let TipOutcome::Estimate(e) = out.estimate.tip {
                phantom_n.push(e.force_n.norm());
                within_3_sigma.extend((0..3).map(|i| e.force_n[i].abs() <= 3.0 * e.std_n[i]));
            }
        }
    }
    Figures {
        phantom_n,
        within_3_sigma,
        named_after_s,
    }
}

#[test]
fn plants_that_are_not_the_model_show_their_phantom() {
    let cfg = fast_config();
    let mut rows = Vec::new();
    println!(
        "| the plant, against what the configuration says | phantom tip force, RMS / peak | named after | within 3 std |"
    );
    for m in &MISMATCHES {
        let quiet = free_moves(rig(&cfg, m.edit, NOISE_FRACTION));
        let noisy = free_moves(rig(&cfg, m.edit, 1.0));
        let peak = quiet.phantom_n.iter().copied().fold(0.0, f64::max);
        let share = noisy.within_3_sigma.iter().filter(|w| **w).count() as f64
            / noisy.within_3_sigma.len() as f64;
        let named = match quiet.named_after_s {
            Some(s) => format!("{s:.3} s"),
            None => "not named".to_string(),
        };
        println!(
            "| {} | {:.3} N / {:.2} N | {named} | {:.2} % of {} sample axes |",
            m.name,
            rms(&quiet.phantom_n),
            peak,
            100.0 * share,
            noisy.within_3_sigma.len()
        );
        rows.push((
            rms(&quiet.phantom_n),
            peak,
            share,
            quiet.named_after_s,
            noisy.named_after_s,
        ));
    }
    let (matched_rms, matched_peak, matched_share, named_quiet, named_noisy) = rows[0];
    // The matched plant as before the observer (0.011 N RMS, 0.04 N peak),
    // and never named.
    assert!(matched_rms <= 0.012, "{matched_rms}");
    assert!(matched_peak <= 0.05, "{matched_peak}");
    assert!(matched_share >= 0.99, "{matched_share}");
    assert_eq!(
        (named_quiet, named_noisy),
        (None, None),
        "the matched plant named"
    );
    for (m, (rms_n, ..)) in MISMATCHES.iter().zip(&rows).skip(1) {
        assert!(
            *rms_n > matched_rms,
            "{}: {rms_n} N, no more than the matched plant's {matched_rms} N",
            m.name
        );
    }
    // Issue 34's goal on the servos: within 0.3 N RMS and 1 N peak, or
    // named within 2 s of motion; the guard's margin covers the error.
    for (m, &(rms_n, peak_n, share, named, _)) in
        MISMATCHES.iter().zip(&rows).take(SERVO_ROWS).skip(1)
    {
        let within_goal = rms_n <= 0.3 && peak_n <= 1.0;
        assert!(
            within_goal || named.is_some_and(|s| s <= 2.0),
            "{}: {rms_n} N RMS, {peak_n} N peak, named {named:?}",
            m.name
        );
        assert!(share >= 0.99, "{}: {share}", m.name);
    }
}

/// The plant the rig builds for the matched row is the configuration's:
/// the servo and the rod as the built-in configuration says.
#[test]
fn the_matched_plant_is_the_configuration() {
    let cfg = fast_config();
    let plant: PlantSpec = scenario(&cfg, MISMATCHES[0].edit, NOISE_FRACTION)
        .spec
        .plant;
    let s = plant.servo.unwrap();
    assert_eq!(s.bandwidth_hz, cfg.axes.motion.servo_bandwidth_hz);
    assert_eq!(s.damping, cfg.axes.motion.servo_damping);
    assert_eq!((s.delay_ns, s.inner_loop_hz), (0, 0.0));
}

/// What the inertia watch said over free moves.
struct Watched {
    /// Cycles (ms) from the first move's request to the first name.
    named_after_ms: Option<u64>,
    /// The verdict after the moves.
    verdict: sar_estimator::inertia_watch::InertiaVerdict,
}

/// `rounds` times the three free moves of [`free_moves`], watching the
/// inertia watch's verdict.
fn watched_moves(mut rig: Rig, rounds: usize) -> Watched {
    let start = Vec3::new(TIP_M[0], TIP_M[1], TIP_M[2]);
    let tips = [
        start + Vec3::new(0.03, 0.015, -0.015),
        start + Vec3::new(-0.01, -0.02, 0.02),
        start,
    ];
    let mut named_after_ms = None;
    let mut ms = 0;
    for (id, tip_m) in (1..).zip(tips.iter().cycle().take(3 * rounds)) {
        let r = rig.request(id, Request::MoveTip { tip_m: *tip_m });
        assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
        ms += 1;
        for _ in 0..MOVE_MS {
            let out = rig.step();
            ms += 1;
            if named_after_ms.is_none() && out.inertia.named.any() {
                named_after_ms = Some(ms);
            }
        }
    }
    Watched {
        named_after_ms,
        verdict: rig.c.decision().inertia,
    }
}

/// Issue 34 item 2: on the free moves above, the inertia watch names the
/// rod of 1.6x the configured I_perp and the 0.35 kg adapter left out,
/// with the I_perp and the adapter's mass the free motion implies (within
/// 10 % and 50 g of the truth, and within 3 of their standard errors); on
/// the plant the configuration describes it names nothing, at the sensor's
/// full noise and at 1 % of it. The name comes within the first move (the
/// time from its request printed). Printed too: what each other plant of
/// the table makes it say (measured: nothing named; the ideal drives read
/// as 1.16-1.18x I_perp and -0.18 kg of adapter, below the limits and
/// impossible).
#[test]
fn the_inertia_watch_names_the_rod_and_the_adapter_and_not_the_matched_plant() {
    let cfg = fast_config();
    let configured = cfg.estimator.inertia;
    let rod_row = MISMATCHES
        .iter()
        .find(|m| m.name.starts_with("rod of 1.6x"))
        .expect("the rod's row");
    let truth = inertia(&scenario(&cfg, rod_row.edit, 1.0).spec);
    for (fraction, rounds) in [(NOISE_FRACTION, 1), (1.0, 2)] {
        for (i, m) in MISMATCHES.iter().enumerate() {
            let w = watched_moves(rig(&cfg, m.edit, fraction), rounds);
            let v = &w.verdict;
            println!(
                "noise x{fraction}, {}: named {:?} after {:?} ms; I_perp {:.5} +- {:.5} kg m^2 ({:.2}x the configured {:.5}), m_s {:.3} +- {:.3} kg, {:.0} free samples",
                m.name,
                v.named,
                w.named_after_ms,
                v.inertia_perp_kgm2,
                v.inertia_perp_std_kgm2,
                v.inertia_perp_ratio,
                configured.inertia_perp_kgm2,
                v.adapter_mass_kg,
                v.adapter_mass_std_kg,
                v.samples
            );
            if i == 0 {
                assert!(!v.named.any(), "the matched plant named: {v:?}");
                assert!(w.named_after_ms.is_none());
            }
            if std::ptr::eq(m, rod_row) {
                assert!(v.named.inertia_perp && v.named.adapter, "{v:?}");
                let i_err = v.inertia_perp_kgm2 - truth.inertia_perp_kgm2;
                let s_err = v.adapter_mass_kg - truth.adapter_mass_kg;
                assert!(
                    i_err.abs() < 0.1 * truth.inertia_perp_kgm2,
                    "I_perp {i_err}"
                );
                assert!(
                    i_err.abs() < 3.0 * v.inertia_perp_std_kgm2,
                    "I_perp {i_err}"
                );
                assert!(s_err.abs() < 0.05, "m_s {s_err}");
                assert!(s_err.abs() < 3.0 * v.adapter_mass_std_kg, "m_s {s_err}");
                let line = sar_loop::logq::inertia_text(
                    v,
                    (configured.inertia_perp_kgm2, configured.adapter_mass_kg),
                );
                println!("{line}");
                assert!(line.contains("I_perp reads 1.6"), "{line}");
                assert!(line.contains("the adapter's mass reads 0.3"), "{line}");
                assert!(line.contains("run `sarctl identify --dynamic`"), "{line}");
                // Within the first move.
                assert!(
                    w.named_after_ms.is_some_and(|ms| ms <= MOVE_MS),
                    "{:?}",
                    w.named_after_ms
                );
            }
        }
    }
}
