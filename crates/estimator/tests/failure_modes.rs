//! The failure modes of issue 14 at the estimator's level, with a live,
//! noisy simulated sensor (MODEL.md 7's HEX-6 noise, seeded): a frozen
//! sensor, saturation, spikes, the tare's age and the bias drift, a sensor
//! mounted or scaled otherwise than configured or another manipulator at the
//! first reset, the retreat from a Stop whose force persists, and the reason
//! table. Each check is shown to fire on its fault and to stay quiet on a
//! live sensor at rest. SAFETY.md quotes these tests.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;
use common::*;
use nalgebra::{Matrix3, Rotation3, Vector3};
use sar_estimator::cycle::{
    Bias, Command, CommandAccepted, CommandRefused, CycleContext, CycleInput, CycleOutput,
    Estimator, EstimatorConfig, FrozenCheck, MountingLimits, PlausibilityConfig,
    PlausibilityLimits, SensorRange, SensorSample, SpikeLimits, TareLimits, TareRefused,
    frozen_false_alarms_in_ten_years, frozen_repeat_probability, frozen_repeats,
};
use sar_estimator::guard::{
    Axis, ForcePart, GuardState, REASONS, Reason, RestResidual, SensorChannel, reason_name,
    reduces_force,
};

type V = Vector3<f64>;

const PERIOD_NS: u64 = 1_000_000;
/// A: (0.30, 0.20, 0.0): rod horizontal along +X0, a = 0.15 m.
const NOMINAL_Q: [f64; 3] = [0.0, 0.28, 0.30];
/// A: (0.23, 0.20, 0.0): a = 0.22 m, the tip 0.13 m beyond the support.
const FAR_Q: [f64; 3] = [0.0, 0.28, 0.23];
/// The example robot's lever from S to A, base frame: a_off - s_off, m.
const LEVER_M: [f64; 3] = [0.0, -0.05, 0.0];

/// What the simulated robot really is (it may differ from the configuration).
#[derive(Clone, Copy)]
struct World {
    truth: Truth,
    /// The sensor's true rotation R_0s.
    rotation: Matrix3<f64>,
    /// The sensor's true gain (1: as configured).
    gain: f64,
    bias_n: V,
    bias_nm: V,
}

impl World {
    fn nominal() -> Self {
        Self {
            truth: manipulator2_truth(),
            rotation: Matrix3::identity(),
            gain: 1.0,
            bias_n: V::new(0.4, -1.1, 0.25),
            bias_nm: V::new(0.02, -0.01, 0.005),
        }
    }

    /// The noiseless reading (force N, torque N m, sensor frame) at joints
    /// `q` with `tip_force_n` at the tip: f = g R^T (-F_A) + b_f,
    /// t = g R^T ((A - S) x (-F_A)) + b_t (MODEL.md 4, d = 0).
    fn reading(&self, q: [f64; 3], tip_force_n: &V) -> (V, V) {
        let a_m = V::new(q[2], q[1] - 0.08, q[0]);
        let r = self.truth.support_m - a_m;
        let u = r / r.norm();
        let (_, w) = rod_frame(u.x.atan2(u.z), u.y.asin());
        let (f_a, _) = ujoint_force(&self.truth, &a_m, &u, &w, tip_force_n, 0.0);
        let lever = V::new(LEVER_M[0], LEVER_M[1], LEVER_M[2]);
        let rt = self.rotation.transpose();
        (
            rt * (-f_a) * self.gain + self.bias_n,
            rt * lever.cross(&(-f_a)) * self.gain + self.bias_nm,
        )
    }
}

/// The estimator on a simulated robot, one new sensor sample per 1 ms cycle.
struct Rig {
    estimator: Estimator,
    world: World,
    noise: NoisySensor,
    torque_noise: NoisySensor,
    cycle: u64,
    counter: u32,
    /// The last reading sent (for a frozen sensor).
    last: (V, V),
}

/// Every check of issue 14 on, with the example robot's torque check.
fn all_checks() -> PlausibilityLimits {
    PlausibilityLimits::default()
}

fn config(limits: PlausibilityLimits) -> EstimatorConfig {
    let mut config = example_estimator_config();
    config.plausibility = PlausibilityConfig::new(limits).unwrap();
    config
}

impl Rig {
    fn new(limits: PlausibilityLimits, world: World, seed: u64) -> Self {
        let config = config(limits);
        let nominal = World::nominal();
        Self {
            estimator: Estimator::with_bias(
                &config,
                Bias {
                    force_n: nominal.bias_n,
                    torque_nm: nominal.bias_nm,
                },
            )
            .unwrap(),
            world,
            noise: NoisySensor::new(sar_estimator::SensorNoise::HEX6_STD_N, seed),
            torque_noise: NoisySensor::new([0.01, 0.01, 0.002], seed ^ 0x7070),
            cycle: 0,
            counter: 0,
            last: (V::zeros(), V::zeros()),
        }
    }

    /// A rig whose first reset was accepted, at the nominal pose.
    fn armed(limits: PlausibilityLimits, seed: u64) -> Self {
        let mut rig = Self::new(limits, World::nominal(), seed);
        for _ in 0..REST_SAMPLES {
            rig.step(NOMINAL_Q, &V::zeros(), None);
        }
        let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
        assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
        rig
    }

    /// One cycle with a new, noisy sample of the world.
    fn step(&mut self, q: [f64; 3], tip_force_n: &V, command: Option<Command>) -> CycleOutput {
        let (f, t) = self.world.reading(q, tip_force_n);
        let reading = (self.noise.sample(&f), self.torque_noise.sample(&t));
        self.send(q, reading, command)
    }

    /// One cycle with a new sample carrying exactly `reading`.
    fn send(&mut self, q: [f64; 3], reading: (V, V), command: Option<Command>) -> CycleOutput {
        self.cycle += 1;
        self.counter = self.counter.wrapping_add(1);
        self.last = reading;
        let now_ns = 1_000_000_000 + self.cycle * PERIOD_NS;
        let input = CycleInput {
            cycle: self.cycle,
            now_ns: Some(now_ns),
            sensor: SensorSample {
                force_n: reading.0,
                torque_nm: reading.1,
                counter: self.counter,
                status: 0,
                stamp_ns: now_ns - 200_000,
                valid: true,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: joint_sample(q, now_ns - 100_000),
            command,
        };
        *self.estimator.cycle(&input, &CycleContext::AT_REST)
    }
}

// ------------------------------------------------------------ a live sensor

/// A live, noisy sensor at rest trips none of the new checks (frozen,
/// saturation, spikes, the first reset's residual, the drift margin) over
/// ten simulated minutes at 1 kHz; `cargo test -- --ignored` runs the hour.
#[test]
fn a_live_sensor_at_rest_trips_nothing_over_ten_minutes() {
    assert_eq!(quiet_run(600_000, 0x11fe), 0);
}

/// The hour of issue 14's closing figure (3.6 million samples).
#[test]
#[ignore = "an hour of simulated samples: run with --ignored (prints the count)"]
fn a_live_sensor_at_rest_trips_nothing_over_an_hour() {
    let trips = quiet_run(3_600_000, 0x0e_0e);
    println!("one hour at rest, 3.6e6 samples: {trips} transitions after the first reset");
    assert_eq!(trips, 0);
}

/// Transitions after the first reset over `cycles` cycles at rest (the tare
/// falls due only after one hour: not within).
fn quiet_run(cycles: u64, seed: u64) -> u64 {
    let mut rig = Rig::armed(all_checks(), seed);
    let mut trips = 0;
    let mut spikes = 0;
    for _ in 0..cycles - u64::from(REST_SAMPLES) - 1 {
        let out = rig.step(NOMINAL_Q, &V::zeros(), None);
        if let Some(t) = out.transition {
            trips += 1;
            eprintln!("{t:?}");
        }
        spikes += u64::from(out.spike);
    }
    assert_eq!(spikes, 0, "no spike at rest");
    trips
}

// ------------------------------------------------------------ frozen

/// A sensor whose six readings repeat bit for bit while the counter advances
/// faults on the N-th repeated sample (N = 3: 3 ms at 1 kHz), and a reset is
/// refused while it stays frozen; when it lives again, a reset is accepted.
#[test]
fn a_frozen_sensor_faults_after_n_repeats() {
    let mut rig = Rig::armed(all_checks(), 0xf0f0);
    let frozen = rig.last;
    for k in 1..=3 {
        let out = rig.send(NOMINAL_Q, frozen, None);
        if k < 3 {
            assert_eq!(out.guard_state, GuardState::Ok, "repeat {k}");
        } else {
            assert_eq!(out.guard_state, GuardState::Fault);
            assert_eq!(out.guard_reason, Reason::SensorFrozen { repeats: 3 });
        }
    }
    let out = rig.send(NOMINAL_Q, frozen, Some(Command::Reset));
    assert_eq!(
        out.command.unwrap().result,
        Err(CommandRefused::Reset {
            reason: Reason::SensorFrozen { repeats: 4 }
        })
    );
    rig.step(NOMINAL_Q, &V::zeros(), None);
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
}

/// A repeated counter (the same sample read twice) is not a repeat: only
/// new samples count.
#[test]
fn the_same_sample_read_again_is_not_frozen() {
    let mut rig = Rig::armed(all_checks(), 0xf1f1);
    let input_cycle = |rig: &mut Rig| {
        rig.cycle += 1;
        let now_ns = 1_000_000_000 + rig.cycle * PERIOD_NS;
        let input = CycleInput {
            cycle: rig.cycle,
            now_ns: Some(now_ns),
            sensor: SensorSample {
                force_n: rig.last.0,
                torque_nm: rig.last.1,
                counter: rig.counter,
                status: 0,
                stamp_ns: now_ns - 400_000,
                valid: true,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: joint_sample(NOMINAL_Q, now_ns - 100_000),
            command: None,
        };
        *rig.estimator.cycle(&input, &CycleContext::AT_REST)
    };
    for _ in 0..3 {
        let out = input_cycle(&mut rig);
        assert!(!out.new_sample);
        assert_eq!(out.guard_state, GuardState::Ok);
    }
}

/// N from the sensor's noise and resolution: the arithmetic of SAFETY.md.
#[test]
fn the_frozen_count_follows_from_noise_and_resolution() {
    let hex = V::new(0.2, 0.2, 0.8);
    let hex_nm = V::new(0.01, 0.01, 0.002);
    // The HEX-6 over RDT: 10000 counts/N, 100000 counts/N m.
    let p = frozen_repeat_probability(&hex, Some(&hex_nm), 1e-4, 1e-5);
    let per_channel =
        |sigma: f64, r: f64| r / ((2.0 * std::f64::consts::PI).sqrt() * 0.25 * 2f64.sqrt() * sigma);
    let expected = per_channel(0.2, 1e-4).powi(2)
        * per_channel(0.8, 1e-4)
        * per_channel(0.01, 1e-5).powi(2)
        * per_channel(0.002, 1e-5);
    assert!((p / expected - 1.0).abs() < 1e-9, "{p} vs {expected}");
    assert!(p > 1e-19 && p < 1e-17, "{p}");
    assert_eq!(frozen_repeats(&hex, Some(&hex_nm), 1e-4, 1e-5), Some(3));
    assert!(frozen_false_alarms_in_ten_years(p, 3) < 1e-40);
    // One repeat alone would already be rarer than once in ten years.
    assert!(frozen_false_alarms_in_ten_years(p, 1) < 1.0);
    // A continuous (simulated) reading never repeats by chance.
    assert_eq!(
        frozen_repeat_probability(&hex, Some(&hex_nm), 0.0, 0.0),
        0.0
    );
    assert_eq!(frozen_repeats(&hex, None, 0.0, 0.0), Some(3));
    // A coarse sensor (0.05 N counts, forces only) needs more repeats.
    let coarse = frozen_repeats(&hex, None, 0.05, 0.0).unwrap();
    let pc = frozen_repeat_probability(&hex, None, 0.05, 0.0);
    assert!(coarse > 3, "{coarse}");
    assert!(frozen_false_alarms_in_ten_years(pc, coarse) < 1.0);
    assert!(frozen_false_alarms_in_ten_years(pc, coarse - 1) >= 1.0);
    // Resolution far coarser than the noise: the check cannot work.
    assert_eq!(frozen_repeats(&hex, None, 1.0, 0.0), None);
}

// ------------------------------------------------------------ saturation

/// A raw reading at the range on any of the six channels, either sign, is a
/// Fault naming the channel; a reset is refused while it lasts.
#[test]
fn saturation_on_any_channel_faults() {
    let range = SensorRange::HEX6;
    let ranges = [
        range.force_n.x,
        range.force_n.y,
        range.force_n.z,
        range.torque_nm.x,
        range.torque_nm.y,
        range.torque_nm.z,
    ];
    for (i, channel) in SensorChannel::ALL.iter().enumerate() {
        for sign in [1.0, -1.0] {
            let mut rig = Rig::armed(all_checks(), 0x5a70 + i as u64);
            let (mut f, mut t) = rig.last;
            let value = sign * ranges[i];
            if i < 3 {
                f[i] = value;
            } else {
                t[i - 3] = value;
            }
            let out = rig.send(NOMINAL_Q, (f, t), None);
            assert_eq!(out.guard_state, GuardState::Fault, "{channel}");
            assert_eq!(
                out.guard_reason,
                Reason::SensorSaturated {
                    channel: *channel,
                    value,
                    range: ranges[i]
                }
            );
            let out = rig.send(NOMINAL_Q, (f, t), Some(Command::Reset));
            assert!(matches!(
                out.command.unwrap().result,
                Err(CommandRefused::Reset {
                    reason: Reason::SensorSaturated { .. }
                })
            ));
        }
    }
    // Just below the range is no fault (by the saturation check).
    let mut rig = Rig::armed(
        PlausibilityLimits {
            torque: None,
            spikes: None,
            ..all_checks()
        },
        0x5a71,
    );
    let (mut f, t) = rig.last;
    f.x = 199.999;
    let out = rig.send(NOMINAL_Q, (f, t), None);
    assert!(
        !matches!(out.guard_reason, Reason::SensorSaturated { .. }),
        "{:?}",
        out.guard_reason
    );
}

// ------------------------------------------------------------ spikes

/// One sample of ten times the stop limit does not stop (the debounce is the
/// filter of single samples) and is reported as a spike; the guard stays Ok.
#[test]
fn a_single_spike_is_reported_and_does_not_stop() {
    let mut rig = Rig::armed(all_checks(), 0x5b1e);
    let (mut f, t) = rig.last;
    // Along the sensor's y, the lever's axis: a spike there leaves the
    // torque model consistent (across the lever the torque check faults on
    // it at once: `a_spike_across_the_lever_faults_through_the_torque`).
    f.y += 150.0;
    let out = rig.send(NOMINAL_Q, (f, t), None);
    assert!(out.spike);
    assert_eq!(out.guard_state, GuardState::Ok);
    let mut spikes = 0;
    for _ in 0..20 {
        let out = rig.step(NOMINAL_Q, &V::zeros(), None);
        spikes += u32::from(out.spike);
        assert_eq!(out.guard_state, GuardState::Ok);
    }
    // The way back is a jump too.
    assert_eq!(spikes, 1);
}

/// A single spike on a force channel across the lever, with no torque to
/// match it (interference on one channel), disagrees with the torque model
/// and faults at once through the torque check.
#[test]
fn a_spike_across_the_lever_faults_through_the_torque() {
    let mut rig = Rig::armed(all_checks(), 0x5b1d);
    let (mut f, t) = rig.last;
    f.x += 150.0;
    let out = rig.send(NOMINAL_Q, (f, t), None);
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(
        matches!(
            out.guard_reason,
            Reason::TorqueImplausible { axis: Axis::Z, .. }
        ),
        "{:?}",
        out.guard_reason
    );
}

/// A step of the tip force that persists is not a fault: it is one spike,
/// and the guard stops within the debounce (3 new samples).
#[test]
fn a_persisting_step_stops_within_the_debounce() {
    let mut rig = Rig::armed(all_checks(), 0x5b1f);
    let push = V::new(25.0, 0.0, 0.0);
    let mut stopped_after = None;
    for k in 1..=10 {
        let out = rig.step(NOMINAL_Q, &push, None);
        if out.guard_state == GuardState::Stop {
            stopped_after = Some(k);
            break;
        }
    }
    assert_eq!(stopped_after, Some(3));
    assert!(matches!(
        rig.estimator.last().guard_reason,
        Reason::AboveStop { .. }
    ));
}

/// A burst of spikes (10 within 500 samples) is a Fault; once the window
/// has passed without spikes a reset is accepted again.
#[test]
fn a_burst_of_spikes_faults_until_the_window_has_passed() {
    let limits = SpikeLimits::default();
    let mut rig = Rig::armed(all_checks(), 0x5b20);
    let mut faulted_at = None;
    for k in 1..=40 {
        let (mut f, t) = {
            let (f, t) = rig.world.reading(NOMINAL_Q, &V::zeros());
            (rig.noise.sample(&f), rig.torque_noise.sample(&t))
        };
        if k % 4 == 0 {
            f.y += 30.0;
        }
        let out = rig.send(NOMINAL_Q, (f, t), None);
        if out.guard_state == GuardState::Fault {
            faulted_at = Some((k, out.guard_reason));
            break;
        }
    }
    // Each spike is two jumps (out at 4j, back at 4j + 1): the 10th jump is
    // the way back of the 5th spike, at sample 21.
    let (k, reason) = faulted_at.unwrap();
    assert_eq!(k, 21, "{reason:?}");
    assert_eq!(
        reason,
        Reason::SensorSpikes {
            spikes: limits.max_spikes,
            window: limits.window_samples
        }
    );
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::Reset {
            reason: Reason::SensorSpikes { .. }
        })
    ));
    // The window opened at the first jump (sample 4); 500 samples later it
    // closes.
    for _ in 0..500 {
        rig.step(NOMINAL_Q, &V::zeros(), None);
    }
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
}

// ------------------------------------------------------------ tare and drift

/// After `max_age` the guard warns that a tare is due; a tare is accepted in
/// that Warn and brings Ok back, and the age restarts.
#[test]
fn a_tare_falls_due_and_a_tare_clears_it() {
    let limits = PlausibilityLimits {
        tare: TareLimits {
            max_age_ns: Some(2_000_000_000),
            drift_n_per_s: 0.0,
            ..TareLimits::default()
        },
        ..all_checks()
    };
    let mut rig = Rig::armed(limits, 0x7a4e);
    let mut due_at = None;
    for _ in 0..3000 {
        let out = rig.step(NOMINAL_Q, &V::zeros(), None);
        if let Some(t) = out.transition {
            assert_eq!(t.to, GuardState::Warn);
            due_at = Some((rig.cycle, t.reason, out.tare_age_ns.unwrap()));
            break;
        }
    }
    let (_, reason, age_ns) = due_at.unwrap();
    assert!(matches!(reason, Reason::TareDue { max_age_s, .. } if max_age_s == 2.0));
    assert_eq!(age_ns, 2_000_000_000 + PERIOD_NS);
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Tare));
    assert!(matches!(
        out.command.unwrap().result,
        Ok(CommandAccepted::BiasSet { .. })
    ));
    let out = rig.step(NOMINAL_Q, &V::zeros(), None);
    assert_eq!(out.guard_state, GuardState::Ok);
    assert_eq!(out.guard_reason, Reason::Tared);
    assert_eq!(out.tare_age_ns, Some(PERIOD_NS));
}

/// A force above warn while a tare is due: Warn for the force (a change of
/// reason is reported), and the tare is refused above warn.
#[test]
fn a_force_above_warn_while_a_tare_is_due_takes_over() {
    let limits = PlausibilityLimits {
        tare: TareLimits {
            max_age_ns: Some(100_000_000),
            drift_n_per_s: 0.0,
            ..TareLimits::default()
        },
        ..all_checks()
    };
    let mut rig = Rig::armed(limits, 0x7a4f);
    for _ in 0..120 {
        rig.step(NOMINAL_Q, &V::zeros(), None);
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Warn);
    let push = V::new(9.0, 0.0, 0.0);
    let mut changed = None;
    for _ in 0..10 {
        if let Some(t) = rig.step(NOMINAL_Q, &push, None).transition {
            changed = Some(t);
            break;
        }
    }
    let t = changed.unwrap();
    assert_eq!((t.from, t.to), (GuardState::Warn, GuardState::Warn));
    assert!(matches!(t.reason, Reason::AboveWarn { .. }), "{t:?}");
    let out = rig.step(NOMINAL_Q, &push, Some(Command::Tare));
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::NotOk { .. } | CommandRefused::AboveWarn { .. })
    ));
}

/// The drift margin: a sensor whose bias drifts at the configured bound
/// (so that the estimate reads low) and a tip force ramping through the stop
/// limit: with the margin the guard stops before the TRUE force passes the
/// stop limit (by more than the noise); without it, it stops late by about
/// the drift since the tare.
#[test]
fn the_drift_margin_keeps_the_stop_limit_for_the_true_force() {
    let drift_n_per_s = 0.05;
    let run = |margin_drift: f64| -> f64 {
        let limits = PlausibilityLimits {
            tare: TareLimits {
                max_age_ns: None,
                drift_n_per_s: margin_drift,
                ..TareLimits::default()
            },
            // The torque check would see this drift across the lever (the
            // predicted torque uses the tared force bias): off here, to show
            // the margin alone.
            torque: None,
            ..all_checks()
        };
        let mut rig = Rig::armed(limits, 0xd41f);
        let start_bias = rig.world.bias_n;
        for k in 0..120_000u64 {
            let t_s = k as f64 * 1e-3;
            // +x in the sensor frame makes the axial estimate read low.
            rig.world.bias_n = start_bias + V::new(drift_n_per_s * t_s, 0.0, 0.0);
            // Axial push ramping from 0 to 24 N over 120 s.
            let true_n = 0.2 * t_s;
            let out = rig.step(NOMINAL_Q, &V::new(true_n, 0.0, 0.0), None);
            if out.guard_state == GuardState::Stop {
                return true_n;
            }
            assert_ne!(out.guard_state, GuardState::Fault, "{:?}", out.guard_reason);
        }
        f64::INFINITY
    };
    // The axial stop limit is 12 N (total 15 N).
    let with_margin = run(drift_n_per_s);
    let without = run(0.0);
    assert!(
        with_margin <= 12.0 + 0.3,
        "stopped at a true {with_margin} N"
    );
    assert!(without > 12.0 + 2.0, "stopped at a true {without} N");
}

// ------------------------------------------------------------ mounting

/// Outcome of the first reset on a world that may differ from the
/// configuration, at joints `q`.
/// The mean at rest the first reset needs (`MountingLimits::default()`).
const REST_SAMPLES: u32 = 500;

fn first_reset(world: World, q: [f64; 3], seed: u64) -> Result<CommandAccepted, CommandRefused> {
    let mut rig = Rig::new(all_checks(), world, seed);
    for _ in 0..REST_SAMPLES {
        rig.step(q, &V::zeros(), None);
    }
    rig.step(q, &V::zeros(), Some(Command::Reset))
        .command
        .unwrap()
        .result
}

fn mismatch(result: &Result<CommandAccepted, CommandRefused>) -> Option<Reason> {
    match result {
        Err(CommandRefused::Reset {
            reason: r @ (Reason::MountingMismatch { .. } | Reason::TorqueImplausible { .. }),
        }) => Some(*r),
        _ => None,
    }
}

/// The configured world passes the first reset at both poses.
#[test]
fn the_first_reset_accepts_the_configured_robot() {
    for q in [NOMINAL_Q, FAR_Q] {
        assert_eq!(
            first_reset(World::nominal(), q, 0x3001),
            Ok(CommandAccepted::Reset)
        );
    }
}

/// Another manipulator (+10 % mass): the residual across the rod is
/// (a - c) dm |g| / (L - a): 0.60 N at a = 0.15 m (within the 1 N
/// tolerance: not detected), 2.29 N at a = 0.22 m (refused).
#[test]
fn a_heavier_manipulator_is_refused_where_its_lever_shows_it() {
    let mut world = World::nominal();
    world.truth.mass_kg *= 1.10;
    assert_eq!(
        first_reset(world, NOMINAL_Q, 0x3002),
        Ok(CommandAccepted::Reset)
    );
    let far = first_reset(world, FAR_Q, 0x3002);
    assert!(
        matches!(
            mismatch(&far),
            Some(Reason::MountingMismatch {
                residual: RestResidual::Lateral,
                value,
                ..
            }) if (value - 2.29).abs() < 0.1
        ),
        "{far:?}"
    );
}

/// A sensor gain 10 % off (a wrong counts_per_n): the torque scales with the
/// force, so only the force residual shows it: a/(L - a) times 10 % of the
/// U-joint's vertical force: 0.60 N at a = 0.15 m (not detected), 2.3 N at
/// a = 0.22 m (refused, either sign).
#[test]
fn a_wrong_sensor_gain_is_refused_where_the_load_shows_it() {
    for gain in [1.10, 0.90] {
        let mut world = World::nominal();
        world.gain = gain;
        assert_eq!(
            first_reset(world, NOMINAL_Q, 0x3003),
            Ok(CommandAccepted::Reset)
        );
        let r = first_reset(world, FAR_Q, 0x3003);
        assert!(
            matches!(
                mismatch(&r),
                Some(Reason::MountingMismatch {
                    residual: RestResidual::Lateral,
                    ..
                })
            ),
            "{gain}: {r:?}"
        );
    }
}

/// A sensor turned 5 degrees about a horizontal axis: the mean torque
/// residual at rest sees it (the lever turns with the sensor: about 0.035 N m
/// against the 0.02 N m tolerance). Turned about the vertical (the lever axis
/// A - S): neither the torque nor, with a horizontal rod, the force shows
/// it: the first reset is accepted. SAFETY.md lists this as undetectable at
/// rest.
#[test]
fn a_rotated_sensor_is_seen_unless_turned_about_the_lever() {
    for axis in [V::x_axis(), V::z_axis()] {
        let mut world = World::nominal();
        world.rotation = *Rotation3::from_axis_angle(&axis, 5f64.to_radians()).matrix();
        let r = first_reset(world, NOMINAL_Q, 0x3004);
        assert!(mismatch(&r).is_some(), "about {axis:?}: {r:?}");
    }
    let mut world = World::nominal();
    world.rotation = *Rotation3::from_axis_angle(&V::y_axis(), 5f64.to_radians()).matrix();
    assert_eq!(
        first_reset(world, NOMINAL_Q, 0x3004),
        Ok(CommandAccepted::Reset)
    );
}

/// The check acts only on the first reset: later resets are judged by the
/// guard alone; without it (None) a mismatch is accepted at once.
#[test]
fn the_mounting_check_is_for_the_first_reset_only() {
    let mut world = World::nominal();
    world.truth.mass_kg *= 1.10;
    let mut rig = Rig::new(
        PlausibilityLimits {
            mounting: None,
            ..all_checks()
        },
        world,
        0x3005,
    );
    for _ in 0..REST_SAMPLES {
        rig.step(FAR_Q, &V::zeros(), None);
    }
    let out = rig.step(FAR_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
    // The poses jump from cycle to cycle here: no joint speed check.
    let fast = PlausibilityLimits {
        max_joint_speed_mps: 1e3,
        ..all_checks()
    };
    let mut rig = Rig::new(fast, world, 0x3006);
    for _ in 0..REST_SAMPLES {
        rig.step(FAR_Q, &V::zeros(), None);
    }
    let limits = MountingLimits::default();
    let out = rig.step(FAR_Q, &V::zeros(), Some(Command::Reset));
    match out.command.unwrap().result {
        Err(CommandRefused::Reset {
            reason:
                Reason::MountingMismatch {
                    residual: RestResidual::Lateral,
                    allowed,
                    ..
                },
        }) => {
            // The tolerance and the noise of the mean of 500 samples.
            assert!(
                allowed > limits.tolerance_n && allowed < limits.tolerance_n + 0.6,
                "{allowed}"
            );
        }
        other => panic!("{other:?}"),
    }
    // After that refusal and an accepted first reset elsewhere, the check
    // is over: a reset after a Stop is the guard's alone.
    for _ in 0..REST_SAMPLES {
        rig.step(NOMINAL_Q, &V::zeros(), None);
    }
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
    let push = V::new(20.0, 0.0, 0.0);
    for _ in 0..5 {
        rig.step(FAR_Q, &push, None);
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Stop);
    for _ in 0..REST_SAMPLES {
        rig.step(FAR_Q, &V::zeros(), None);
    }
    let out = rig.step(FAR_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
}

/// A first reset before the mean at rest is complete is refused (the stated
/// tolerances hold only for the full mean), saying how far it is; a move
/// starts the mean again; once complete the same robot is accepted.
#[test]
fn the_first_reset_waits_for_the_full_mean_at_rest() {
    assert_eq!(MountingLimits::default().rest_samples, REST_SAMPLES);
    let mut rig = Rig::new(all_checks(), World::nominal(), 0x3007);
    for _ in 0..100 {
        rig.step(NOMINAL_Q, &V::zeros(), None);
    }
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(
        out.command.unwrap().result,
        Err(CommandRefused::Reset {
            reason: Reason::RestIncomplete {
                samples: 101,
                needed: REST_SAMPLES
            }
        })
    );
    // Moved (beyond the joint margin, within the joint speed): the mean
    // starts again.
    let moved = [NOMINAL_Q[0] + 0.001, NOMINAL_Q[1], NOMINAL_Q[2]];
    for _ in 0..REST_SAMPLES - 10 {
        rig.step(moved, &V::zeros(), None);
    }
    let out = rig.step(moved, &V::zeros(), Some(Command::Reset));
    assert!(
        matches!(
            out.command.unwrap().result,
            Err(CommandRefused::Reset {
                reason: Reason::RestIncomplete { samples, .. }
            }) if samples == REST_SAMPLES - 9
        ),
        "{out:?}"
    );
    for _ in 0..10 {
        rig.step(moved, &V::zeros(), None);
    }
    let out = rig.step(moved, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
}

// ------------------------------------------------------------ retreat

/// A rig in Retreat: pushed to 20 N axial (above the 12 N stop), stopped,
/// and reset while the push persists.
fn in_retreat(seed: u64) -> Rig {
    let mut rig = Rig::armed(all_checks(), seed);
    let push = V::new(20.0, 0.0, 0.0);
    for _ in 0..200 {
        rig.step(NOMINAL_Q, &push, None);
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Stop);
    let out = rig.step(NOMINAL_Q, &push, Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
    assert_eq!(out.guard_state, GuardState::Retreat);
    assert!(matches!(out.guard_reason, Reason::RetreatEntered { .. }));
    assert_eq!(out.transition.unwrap().to, GuardState::Retreat);
    rig
}

/// A still, noisy retreat (the force holding at 20 N) never stops by
/// itself over a minute; a reset in Retreat is a no-op.
#[test]
fn a_still_noisy_retreat_does_not_stop_by_itself() {
    let mut rig = in_retreat(0x4e70);
    let push = V::new(20.0, 0.0, 0.0);
    for _ in 0..60_000 {
        let out = rig.step(NOMINAL_Q, &push, None);
        assert_eq!(
            out.guard_state,
            GuardState::Retreat,
            "{:?}",
            out.guard_reason
        );
    }
    let out = rig.step(NOMINAL_Q, &push, Some(Command::Reset));
    assert_eq!(
        out.command.unwrap().result,
        Ok(CommandAccepted::NothingToReset)
    );
}

/// In Retreat a rising force stops again; a force that falls ends the
/// retreat in Ok; a fault is a Fault.
#[test]
fn retreat_stops_on_a_rise_ends_below_warn_and_faults_on_a_fault() {
    // Rising by more than the allowance (2 N) above the lowest: Stop.
    let mut rig = in_retreat(0x4e71);
    let mut stop = None;
    for k in 0..200 {
        let f = 20.0 + 0.05 * f64::from(k);
        let out = rig.step(NOMINAL_Q, &V::new(f, 0.0, 0.0), None);
        if out.guard_state == GuardState::Stop {
            stop = Some((f, out.guard_reason));
            break;
        }
    }
    let (f, reason) = stop.unwrap();
    assert!(matches!(reason, Reason::ForceRising { .. }), "{reason:?}");
    assert!(f > 22.0 && f < 23.5, "stopped at {f} N");

    // Falling: after the force has dropped below warn - hysteresis
    // (total 10 - 1 N) for the debounce, Ok.
    let mut rig = in_retreat(0x4e72);
    let mut ok_at = None;
    for k in 0..400 {
        let f = (20.0 - 0.1 * f64::from(k)).max(0.0);
        let out = rig.step(NOMINAL_Q, &V::new(f, 0.0, 0.0), None);
        assert_ne!(out.guard_state, GuardState::Stop, "at {f} N");
        if out.guard_state == GuardState::Ok {
            ok_at = Some((f, out.guard_reason));
            break;
        }
    }
    let (f, reason) = ok_at.unwrap();
    assert_eq!(reason, Reason::BelowWarn);
    assert!(f < 8.0, "Ok at {f} N");

    // A fault in Retreat.
    let mut rig = in_retreat(0x4e73);
    let frozen = rig.last;
    for _ in 0..3 {
        rig.send(NOMINAL_Q, frozen, None);
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Fault);
}

/// Without a filtered force (no filter configured) there is no Retreat: a
/// reset above the stop limit is refused as before.
#[test]
fn without_a_filter_a_reset_above_stop_is_refused() {
    let mut config = config(all_checks());
    config.filter = None;
    let mut rig = Rig::armed(all_checks(), 0x4e74);
    rig.estimator = Estimator::with_bias(
        &config,
        Bias {
            force_n: World::nominal().bias_n,
            torque_nm: World::nominal().bias_nm,
        },
    )
    .unwrap();
    for _ in 0..REST_SAMPLES {
        rig.step(NOMINAL_Q, &V::zeros(), None);
    }
    let out = rig.step(NOMINAL_Q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
    let push = V::new(20.0, 0.0, 0.0);
    for _ in 0..10 {
        rig.step(NOMINAL_Q, &push, None);
    }
    let out = rig.step(NOMINAL_Q, &push, Some(Command::Reset));
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::Reset {
            reason: Reason::AboveStop { .. }
        })
    ));
}

/// The motion rule of Retreat: against the force (within 60 degrees) or
/// backing out along the rod; nothing else, nothing degenerate.
#[test]
fn the_retreat_motion_rule() {
    let u = V::x();
    let axial = V::new(20.0, 0.0, 0.0);
    let lateral = V::new(0.0, 0.0, 12.0);
    let step = |x: f64, y: f64, z: f64| V::new(x, y, z);
    assert!(reduces_force(&axial, &u, &step(-0.001, 0.0, 0.0)));
    assert!(!reduces_force(&axial, &u, &step(0.001, 0.0, 0.0)));
    assert!(!reduces_force(&axial, &u, &step(0.0, 0.0, 0.001)));
    assert!(reduces_force(&lateral, &u, &step(0.0, 0.0, -0.001)));
    assert!(!reduces_force(&lateral, &u, &step(0.0, 0.0, 0.001)));
    // Backing out along the rod, whatever the force's direction.
    assert!(reduces_force(&lateral, &u, &step(-0.001, 0.0, 0.0)));
    // 61 degrees off -F is a drag across, refused; 59 accepted.
    for (deg, ok) in [(59.0, true), (61.0, false)] {
        let a = f64::to_radians(deg);
        let s = step(0.0, -a.sin(), -a.cos()) * 0.001;
        assert_eq!(reduces_force(&lateral, &u, &s), ok, "{deg} degrees");
    }
    assert!(!reduces_force(&axial, &u, &V::zeros()));
    assert!(!reduces_force(&V::zeros(), &u, &step(0.0, 0.0, -0.001)));
    assert!(!reduces_force(&axial, &u, &step(f64::NAN, 0.0, 0.0)));
}

// ------------------------------------------------------------ the table

/// One value of every reason; the match below has no wildcard, so a new
/// variant does not compile until it is listed here (and then in REASONS).
fn every_reason() -> Vec<Reason> {
    use sar_estimator::guard::TipField;
    let all = vec![
        Reason::NoInputYet,
        Reason::CycleOutOfOrder {
            previous: 1,
            got: 1,
        },
        Reason::ClockFailed,
        Reason::ClockNotAdvancing {
            previous_ns: 2,
            now_ns: 1,
        },
        Reason::SensorCounterGap {
            previous: 1,
            got: 9,
            max_gap: 3,
        },
        Reason::SensorStatus { status: 4 },
        Reason::JointJump {
            axis: 1,
            moved_m: 0.01,
            allowed_m: 0.001,
        },
        Reason::JointsStampBackwards {
            previous_ns: 2,
            got_ns: 1,
        },
        Reason::TorqueImplausible {
            axis: Axis::X,
            residual_nm: 1.0,
            std_nm: 0.01,
            max_sigma: 7.0,
        },
        Reason::ResetNotCurrent { last: 1, got: 2 },
        Reason::SensorInvalid,
        Reason::SensorStale {
            age_ns: 9,
            max_age_ns: 1,
        },
        Reason::JointsInvalid,
        Reason::JointsStale {
            age_ns: 9,
            max_age_ns: 1,
        },
        Reason::PoseInvalid,
        Reason::NonFinite {
            field: TipField::Force,
            axis: Axis::Y,
        },
        Reason::NegativeStd {
            axis: Axis::Z,
            std_n: -1.0,
        },
        Reason::RodDirNotUnit { norm: 2.0 },
        Reason::EstimatorNotObservable,
        Reason::NotObservable {
            std_max_n: 3.0,
            max_std_n: 2.0,
        },
        Reason::AboveStop {
            part: ForcePart::Total,
            force_n: 16.0,
            limit_n: 15.0,
        },
        Reason::AboveWarn {
            part: ForcePart::Axial,
            force_n: 9.0,
            limit_n: 8.0,
        },
        Reason::BelowWarn,
        Reason::Reset,
        Reason::FollowingError {
            axis: 2,
            error_m: 0.002,
            tolerance_m: 0.001,
        },
        Reason::AwaitingFirstReset,
        Reason::SensorFrozen { repeats: 3 },
        Reason::SensorSaturated {
            channel: SensorChannel::Tz,
            value: 6.5,
            range: 6.5,
        },
        Reason::SensorSpikes {
            spikes: 10,
            window: 500,
        },
        Reason::TareDue {
            age_s: 3601.0,
            max_age_s: 3600.0,
        },
        Reason::Tared,
        Reason::MountingMismatch {
            residual: RestResidual::Torque(Axis::X),
            value: 0.05,
            allowed: 0.02,
        },
        Reason::RetreatEntered {
            part: ForcePart::Axial,
            force_n: 20.0,
            limit_n: 12.0,
        },
        Reason::ForceRising {
            part: ForcePart::Axial,
            force_n: 23.0,
            bound_n: 22.0,
        },
        Reason::PublisherStalled { stalled_ms: 500 },
        Reason::DriveFault {
            axis: 2,
            code: 0x8130,
        },
        Reason::RestIncomplete {
            samples: 12,
            needed: 500,
        },
        Reason::CycleGap {
            gap_ns: 120_000_000,
            max_ns: 50_000_000,
        },
    ];
    for r in &all {
        match r {
            Reason::NoInputYet
            | Reason::CycleOutOfOrder { .. }
            | Reason::ClockFailed
            | Reason::ClockNotAdvancing { .. }
            | Reason::SensorCounterGap { .. }
            | Reason::SensorStatus { .. }
            | Reason::JointJump { .. }
            | Reason::JointsStampBackwards { .. }
            | Reason::TorqueImplausible { .. }
            | Reason::ResetNotCurrent { .. }
            | Reason::SensorInvalid
            | Reason::SensorStale { .. }
            | Reason::JointsInvalid
            | Reason::JointsStale { .. }
            | Reason::PoseInvalid
            | Reason::NonFinite { .. }
            | Reason::NegativeStd { .. }
            | Reason::RodDirNotUnit { .. }
            | Reason::EstimatorNotObservable
            | Reason::NotObservable { .. }
            | Reason::AboveStop { .. }
            | Reason::AboveWarn { .. }
            | Reason::BelowWarn
            | Reason::Reset
            | Reason::FollowingError { .. }
            | Reason::AwaitingFirstReset
            | Reason::SensorFrozen { .. }
            | Reason::SensorSaturated { .. }
            | Reason::SensorSpikes { .. }
            | Reason::TareDue { .. }
            | Reason::Tared
            | Reason::MountingMismatch { .. }
            | Reason::RetreatEntered { .. }
            | Reason::ForceRising { .. }
            | Reason::PublisherStalled { .. }
            | Reason::DriveFault { .. }
            | Reason::RestIncomplete { .. }
            | Reason::CycleGap { .. } => {}
        }
    }
    all
}

/// Every reason has one code and one name, the table lists them all in code
/// order, and each says something.
#[test]
fn every_reason_has_one_code_and_name_in_the_table() {
    let all = every_reason();
    assert_eq!(all.len(), REASONS.len());
    for (reason, (code, name)) in all.iter().zip(REASONS.iter()) {
        assert_eq!(reason.code(), *code, "{reason:?}");
        assert_eq!(reason.name(), *name);
        assert_eq!(reason_name(*code), *name);
        assert!(!reason.to_string().is_empty());
    }
    let mut codes: Vec<u16> = REASONS.iter().map(|(c, _)| *c).collect();
    codes.dedup();
    assert_eq!(
        codes.len(),
        REASONS.len(),
        "codes must be unique and sorted"
    );
    let mut names: Vec<&str> = REASONS.iter().map(|(_, n)| *n).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), REASONS.len(), "names must be unique");
    assert_eq!(reason_name(999), "unknown");
    for state in GuardState::ALL {
        assert_eq!(GuardState::from_code(state.code()), Some(state));
    }
    assert_eq!(GuardState::from_code(5), None);
}

/// The defaults pass their own validation, and bad settings are refused.
#[test]
fn new_settings_are_validated() {
    assert!(PlausibilityConfig::new(PlausibilityLimits::default()).is_ok());
    let bad = [
        PlausibilityLimits {
            frozen: FrozenCheck::On { repeats: 0 },
            ..Default::default()
        },
        PlausibilityLimits {
            range: Some(SensorRange {
                force_n: V::new(200.0, f64::NAN, 200.0),
                ..SensorRange::HEX6
            }),
            ..Default::default()
        },
        PlausibilityLimits {
            spikes: Some(SpikeLimits {
                jump_sigma: 2.0,
                ..SpikeLimits::default()
            }),
            ..Default::default()
        },
        PlausibilityLimits {
            tare: TareLimits {
                max_age_ns: Some(0),
                drift_n_per_s: 0.0,
                ..TareLimits::default()
            },
            ..Default::default()
        },
        PlausibilityLimits {
            tare: TareLimits {
                max_age_ns: None,
                drift_n_per_s: -1.0,
                ..TareLimits::default()
            },
            ..Default::default()
        },
        PlausibilityLimits {
            mounting: Some(MountingLimits {
                tolerance_n: 0.0,
                ..MountingLimits::default()
            }),
            ..Default::default()
        },
        PlausibilityLimits {
            mounting: Some(MountingLimits {
                rest_samples: 0,
                ..MountingLimits::default()
            }),
            ..Default::default()
        },
    ];
    for limits in bad {
        assert!(PlausibilityConfig::new(limits).is_err(), "{limits:?}");
    }
}

// ------------------------------------------------ the tare over a mean at rest

/// A rig whose first reset was accepted at joints `q` (a = 0.22 m at
/// [`FAR_Q`]: the lateral part sees the sensor's noise amplified by
/// a / (L - a) = 1.7).
fn armed_at(limits: PlausibilityLimits, q: [f64; 3], seed: u64) -> Rig {
    let mut rig = Rig::new(limits, World::nominal(), seed);
    for _ in 0..REST_SAMPLES {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Reset));
    assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
    rig
}

/// Where the mean tip force at rest sits with the bias in use: the estimate
/// of one noiseless reading of the world at `q` with no force at the tip
/// (the mean of the noisy estimates, without their noise).
fn tip_force_at_rest(rig: &mut Rig, q: [f64; 3]) -> V {
    let exact = rig.world.reading(q, &V::zeros());
    let out = rig.send(q, exact, None);
    let sar_estimator::cycle::TipOutcome::Estimate(e) = out.tip else {
        panic!("no estimate at rest: {:?}", out.tip);
    };
    e.force_n
}

/// Issue 25, finding 8: eight tares at rest, 6 s apart (past the rate
/// limit, each mean complete), with no force at the tip: the mean tip force
/// after each must stay where it was. With a one-sample tare each carried
/// that sample's noise into the bias: here, at a = 0.22 m (the lateral part
/// amplified 1.7 times), the mean moved by up to 4.51 N (0.17 N in `sard`'s
/// demo). Over the mean at rest (500 samples, an exponential mean beyond:
/// the noise divided by about sqrt(2 x 500 - 1) = 31.6) it moves by up to
/// 0.13 N (a tare's own error: 0.045 N std across the rod).
/// (`--nocapture` prints the figure.)
#[test]
fn eight_tares_at_rest_keep_the_mean_tip_force_in_place() {
    let mut rig = armed_at(all_checks(), FAR_Q, 0x8a7e);
    let mut means = Vec::new();
    for _ in 0..8 {
        for _ in 0..6000 {
            rig.step(FAR_Q, &V::zeros(), None);
        }
        let out = rig.step(FAR_Q, &V::zeros(), Some(Command::Tare));
        assert!(
            matches!(
                out.command.unwrap().result,
                Ok(CommandAccepted::BiasSet { .. })
            ),
            "{:?}",
            out.command
        );
        rig.step(FAR_Q, &V::zeros(), None);
        means.push(tip_force_at_rest(&mut rig, FAR_Q));
    }
    let spread = means
        .iter()
        .flat_map(|a| means.iter().map(move |b| (a - b).norm()))
        .fold(0.0, f64::max);
    println!("eight tares at rest: the mean tip force moved by up to {spread:.3} N");
    assert!(
        spread < 0.2,
        "eight tares at rest moved the mean tip force by up to {spread:.3} N: {means:?}"
    );
}

/// Issue 25, finding 8: a few hundred tares in a row at rest (one every
/// 50 ms, a shell loop of `sarctl tare`), no force at the tip: the guard
/// must stay Ok. With one-sample tares, 498 of 500 accepted, an unlucky
/// sample's bias put the lateral part beyond its warn limit (up to 8.5 N
/// with its margin) and the guard left Ok; now the rate limit (5 s) refuses
/// all but one tare in 5 s, and each is over the mean at rest.
#[test]
fn hundreds_of_tares_in_a_row_do_not_make_the_guard_flap() {
    const TARES: u32 = 500;
    let mut rig = armed_at(all_checks(), FAR_Q, 0xf1a9);
    let (mut accepted, mut refused, mut warns) = (0, 0, 0);
    let mut worst_lateral_n: f64 = 0.0;
    for _ in 0..TARES {
        let out = rig.step(FAR_Q, &V::zeros(), Some(Command::Tare));
        match out.command.unwrap().result {
            Ok(_) => accepted += 1,
            Err(_) => refused += 1,
        }
        if out.guard_state != GuardState::Ok {
            warns += 1;
        }
        // One tare every 50 ms (`sarctl tare` in a shell loop).
        for _ in 0..49 {
            let out = rig.step(FAR_Q, &V::zeros(), None);
            if out.guard_state != GuardState::Ok {
                warns += 1;
            }
            if let (sar_estimator::cycle::TipOutcome::Estimate(e), Some(p)) = (out.tip, out.pose) {
                let lateral = e.force_n - p.rod_dir * e.force_n.dot(&p.rod_dir);
                worst_lateral_n = worst_lateral_n.max(lateral.norm());
            }
        }
    }
    println!(
        "{TARES} tares: {accepted} accepted, {refused} refused, {warns} cycles out of Ok, largest lateral {worst_lateral_n:.2} N"
    );
    assert!(accepted <= 5 && refused >= 495, "{accepted} accepted");
    assert_eq!(
        warns, 0,
        "{accepted} tares accepted; the guard left Ok in {warns} cycles (lateral up to {worst_lateral_n:.2} N)"
    );
}

/// Issue 25, finding 8: the tare's refusals, each with its cause: before
/// its mean at rest is complete (after a move), while the readings spread
/// beyond twice the noise (a contact that changes: not at rest), and sooner
/// than the rate limit after the last accepted tare.
#[test]
fn a_tare_is_refused_until_at_rest_while_not_steady_and_too_soon() {
    let mut rig = armed_at(all_checks(), NOMINAL_Q, 0x7a5e);
    // A move of 1 mm restarts the mean.
    let mut q = NOMINAL_Q;
    for _ in 0..20 {
        q[2] += 5e-5;
        rig.step(q, &V::zeros(), None);
    }
    for _ in 0..99 {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Tare));
    // The mean restarts whenever the joints are 0.2 mm from where it began:
    // it holds the last samples of the move and the 99 after it.
    let result = out.command.unwrap().result;
    assert!(
        matches!(result, Err(CommandRefused::Tare(TareRefused::NotAtRest { samples, needed: 500 }))
            if (100..120).contains(&samples)),
        "{result:?}"
    );
    // A contact that changes (1.5 N across the rod, vertical, at 2 Hz:
    // 2 N at the U-joint, on the sensor's Y axis whose noise is 0.2 N):
    // below every warn limit, but not at rest.
    let wobble = |i: u32| {
        V::new(
            0.0,
            1.5 * (f64::from(i) * 2e-3 * std::f64::consts::TAU).sin(),
            0.0,
        )
    };
    let mut i = 0;
    for _ in 0..1000 {
        i += 1;
        rig.step(q, &wobble(i), None);
    }
    let out = rig.step(q, &wobble(i + 1), Some(Command::Tare));
    let result = out.command.unwrap().result;
    assert!(
        matches!(result, Err(CommandRefused::Tare(TareRefused::NotSteady { std_n, allowed_n, .. })) if std_n > allowed_n),
        "{result:?}"
    );
    assert_eq!(out.guard_state, GuardState::Ok);
    // The refusal restarted the mean: at rest again, a tare is refused
    // until the fresh mean is complete, then accepted; 1 s later too soon;
    // 5 s after it, accepted again.
    for _ in 0..400 {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Tare));
    let result = out.command.unwrap().result;
    assert!(
        matches!(
            result,
            Err(CommandRefused::Tare(TareRefused::NotAtRest {
                samples: 401,
                ..
            }))
        ),
        "{result:?}"
    );
    for _ in 0..599 {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Tare));
    assert!(matches!(
        out.command.unwrap().result,
        Ok(CommandAccepted::BiasSet { .. })
    ));
    for _ in 0..999 {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Tare));
    let result = out.command.unwrap().result;
    assert!(
        matches!(result, Err(CommandRefused::Tare(TareRefused::TooSoon { since_s, min_interval_s }))
            if (since_s - 1.0).abs() < 1e-9 && min_interval_s == 5.0),
        "{result:?}"
    );
    for _ in 0..3999 {
        rig.step(q, &V::zeros(), None);
    }
    let out = rig.step(q, &V::zeros(), Some(Command::Tare));
    assert!(
        matches!(
            out.command.unwrap().result,
            Ok(CommandAccepted::BiasSet { .. })
        ),
        "{:?}",
        out.command
    );
}
