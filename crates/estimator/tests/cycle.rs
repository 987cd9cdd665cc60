//! The per-cycle path end to end: simulated sensor readings through kinematics,
//! tip force and guard, against the scripted tip force and the guard's rules.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

mod common;
use common::*;
use nalgebra::Vector3;
use sar_estimator::cycle::{
    Bias, Command, CommandAccepted, CommandRefused, CycleContext, CycleInput, CycleOutput,
    Estimator, EstimatorConfig, JointSample, PlausibilityConfig, PlausibilityLimits, SensorSample,
    TipOutcome, TorqueLimits,
};
use sar_estimator::filter::TipFilter;
use sar_estimator::guard::{Axis, ForcePart, GuardState, Reason};
use sar_kinematics::ActiveJoints;

const PERIOD_NS: u64 = 1_000_000;
/// A: (0.30, 0.20, 0.0): rod horizontal along +X0, a = 0.15 m.
const NOMINAL_Q: [f64; 3] = [0.0, 0.28, 0.30];
/// The example robot's lever from S to A, sensor frame (R_0s = I): the U-joint
/// offset (0, -0.08, 0) less the sensor offset (0, -0.03, 0), m.
const LEVER_S_M: [f64; 3] = [0.0, -0.05, 0.0];

/// The sensor torque of the example robot (d = 0: no torsion) for a force
/// reading with force bias `bias_n` and torque bias `bias_nm`:
/// t = (A - S) x (f - b_f) + b_t (MODEL.md 4, R_0s = I).
fn ideal_torque(
    reading_n: &Vector3<f64>,
    bias_n: &Vector3<f64>,
    bias_nm: &Vector3<f64>,
) -> Vector3<f64> {
    let [x, y, z] = LEVER_S_M;
    Vector3::new(x, y, z).cross(&(reading_n - bias_n)) + bias_nm
}

/// The example configuration with every plausibility check on (the torque
/// check with its defaults) and the given joint speed limit.
fn config_with_speed(max_joint_speed_mps: f64) -> EstimatorConfig {
    let mut config = example_estimator_config();
    config.plausibility = PlausibilityConfig::new(PlausibilityLimits {
        max_joint_speed_mps,
        ..scripted_checks_only()
    })
    .unwrap();
    config
}

struct Rig {
    estimator: Estimator,
    cycle: u64,
    counter: u32,
    /// The sensor's true force bias (what the readings carry).
    bias_n: Vector3<f64>,
    /// The sensor's true torque bias.
    bias_nm: Vector3<f64>,
}

impl Rig {
    /// Tests that jump between poses from one cycle to the next: the joint
    /// speed check is set far above their jumps (it has its own tests).
    fn new() -> Self {
        Self::with_config(&config_with_speed(1e3))
    }

    fn with_config(config: &EstimatorConfig) -> Self {
        let bias_n = Vector3::new(0.4, -1.1, 0.25);
        let bias_nm = Vector3::new(0.02, -0.01, 0.005);
        Self {
            estimator: Estimator::with_bias(
                config,
                Bias {
                    force_n: bias_n,
                    torque_nm: bias_nm,
                },
            )
            .unwrap(),
            cycle: 0,
            counter: 0,
            bias_n,
            bias_nm,
        }
    }

    /// The next input: a new sample (counter + 1), stamps 0.3 ms (sensor) and
    /// 0.1 ms (joints) before now, the model's torque, no command.
    fn input(&mut self, q: [f64; 3], reading_n: Vector3<f64>) -> CycleInput {
        self.cycle += 1;
        self.counter = self.counter.wrapping_add(1);
        let now_ns = 1_000_000_000 + self.cycle * PERIOD_NS;
        CycleInput {
            cycle: self.cycle,
            now_ns: Some(now_ns),
            sensor: SensorSample {
                force_n: reading_n,
                torque_nm: ideal_torque(&reading_n, &self.bias_n, &self.bias_nm),
                counter: self.counter,
                status: 0,
                stamp_ns: now_ns - 300_000,
                valid: true,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: joint_sample(q, now_ns - 100_000),
            command: None,
        }
    }

    fn push(&mut self, q: [f64; 3], tip_force_n: &Vector3<f64>) -> CycleOutput {
        self.push_command(q, tip_force_n, None)
    }

    fn push_command(
        &mut self,
        q: [f64; 3],
        tip_force_n: &Vector3<f64>,
        command: Option<Command>,
    ) -> CycleOutput {
        let reading = example_reading(q, tip_force_n, &self.bias_n);
        let mut input = self.input(q, reading);
        input.command = command;
        *self.estimator.cycle(&input, &CycleContext::AT_REST)
    }

    /// The next input at the nominal pose with nothing at the tip.
    fn at_rest(&mut self) -> CycleInput {
        let reading = example_reading(NOMINAL_Q, &Vector3::zeros(), &self.bias_n);
        self.input(NOMINAL_Q, reading)
    }

    /// A cycle at rest carrying a reset.
    fn reset(&mut self) -> CycleOutput {
        self.push_command(NOMINAL_Q, &Vector3::zeros(), Some(Command::Reset))
    }

    /// A rig whose first cycle, at rest, carries the reset that arms the guard.
    fn armed() -> Self {
        Self::armed_with(Self::new())
    }

    fn armed_with(mut rig: Self) -> Self {
        let out = rig.reset();
        let t = out.transition.unwrap();
        assert_eq!(
            (t.from, t.to, t.reason, t.cycle),
            (GuardState::Fault, GuardState::Ok, Reason::Reset, 1)
        );
        assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
        assert_eq!(out.guard_state, GuardState::Ok);
        rig
    }
}

fn estimate(out: &CycleOutput) -> sar_estimator::tip_force::TipForceEstimate {
    match out.tip {
        TipOutcome::Estimate(e) => e,
        other => panic!("no estimate: {other:?}"),
    }
}

/// Scripted tip forces at varied poses come back through the whole path to
/// 1e-9 N (noise-free readings from the independent simulator).
#[test]
fn closed_loop_gives_back_the_scripted_tip_force() {
    let mut rig = Rig::armed();
    let poses = [
        NOMINAL_Q,
        [0.02, 0.25, 0.31],
        [-0.03, 0.30, 0.27],
        [0.01, 0.22, 0.33],
    ];
    let forces = [
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(-0.5, 2.0, 0.3),
        Vector3::new(0.2, -1.5, -2.0),
        Vector3::new(3.0, 1.0, -1.0),
    ];
    for q in poses {
        for f in &forces {
            let out = rig.push(q, f);
            let e = estimate(&out);
            assert!((e.force_n - f).norm() < 1e-9, "{:?} vs {f:?}", e.force_n);
            let u = out.pose.unwrap().rod_dir;
            assert!((e.axial_n - f.dot(&u)).abs() < 1e-9);
            assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
        }
    }
}

/// A push along the rod that ramps through the warn and stop limits: Warn after
/// the debounce, then Stop, latched when the force goes away; the reset is
/// refused while the push lasts and accepted after.
#[test]
fn a_push_ramp_warns_then_stops_and_latches() {
    let mut rig = Rig::armed();
    let u = Vector3::x();
    let mut warn_at = None;
    let mut stop_at = None;
    for k in 0..=200u32 {
        // 0.05 .. 20.05 N along u: each step lands 0.05 N past a 0.1 N grid, so
        // no estimate sits exactly on a limit (8 N axial warn, 12 N axial stop).
        let force = f64::from(k) * 0.1 + 0.05;
        let out = rig.push(NOMINAL_Q, &(u * force));
        if let Some(t) = out.transition {
            match t.to {
                GuardState::Warn => warn_at = Some((k, t.reason)),
                GuardState::Stop => stop_at = Some((k, t.reason)),
                other => panic!("unexpected transition to {other:?}: {:?}", t.reason),
            }
        }
    }
    // The axial warn limit (8 N) is passed first: at k = 80 (8.05 N), then 3
    // cycles of debounce (80, 81, 82); the stop limit at k = 120 (12.05 N).
    let (k_warn, reason) = warn_at.unwrap();
    assert_eq!(k_warn, 82);
    assert!(
        matches!(
            reason,
            Reason::AboveWarn {
                part: ForcePart::Axial,
                ..
            }
        ),
        "{reason:?}"
    );
    let (k_stop, reason) = stop_at.unwrap();
    assert_eq!(k_stop, 122);
    assert!(
        matches!(
            reason,
            Reason::AboveStop {
                part: ForcePart::Axial,
                ..
            }
        ),
        "{reason:?}"
    );
    // Still pushing: the reset does not give Ok; it enters Retreat (only
    // motions that reduce the force, issue 14's way back from a Stop).
    let out = rig.push_command(NOMINAL_Q, &(u * 20.0), Some(Command::Reset));
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
    assert_eq!(out.guard_state, GuardState::Retreat);
    assert!(
        matches!(
            out.guard_reason,
            Reason::RetreatEntered {
                part: ForcePart::Total,
                ..
            }
        ),
        "{:?}",
        out.guard_reason
    );
    // Pushing harder during the retreat stops again.
    let mut stopped = None;
    for _ in 0..100 {
        let out = rig.push(NOMINAL_Q, &(u * 24.0));
        if out.guard_state == GuardState::Stop {
            stopped = Some(out.guard_reason);
            break;
        }
        assert_eq!(out.guard_state, GuardState::Retreat);
    }
    assert!(
        matches!(
            stopped,
            Some(Reason::ForceRising {
                part: ForcePart::Total,
                ..
            })
        ),
        "{stopped:?}"
    );
    // The push goes away: Stop stays latched until a reset.
    for _ in 0..10 {
        let out = rig.push(NOMINAL_Q, &Vector3::zeros());
        assert_eq!(out.guard_state, GuardState::Stop);
    }
    let t = rig.reset().transition.unwrap();
    assert_eq!(t.to, GuardState::Ok);
}

/// A lateral push stops on the lateral limit, not the axial one.
#[test]
fn a_lateral_push_stops_on_the_lateral_limit() {
    let mut rig = Rig::armed();
    let mut last = None;
    for _ in 0..5 {
        last = rig
            .push(NOMINAL_Q, &Vector3::new(0.0, 0.0, 11.0))
            .transition
            .or(last);
    }
    let t = last.unwrap();
    assert_eq!(t.to, GuardState::Stop);
    assert!(
        matches!(
            t.reason,
            Reason::AboveStop {
                part: ForcePart::Lateral,
                ..
            }
        ),
        "{:?}",
        t.reason
    );
}

/// Every bad input ends in a latched Fault with its reason, never in a number
/// that looks good.
#[test]
fn bad_inputs_fault_the_guard() {
    // A NaN reading.
    let mut rig = Rig::armed();
    let input = rig.input(NOMINAL_Q, Vector3::new(f64::NAN, 0.0, 0.0));
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert_eq!(out.tip, TipOutcome::SensorInvalid);
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::SensorInvalid)
    );

    // A sample stamped in the future.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.stamp_ns = input.now_ns.unwrap() + 1;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::SensorInvalid)
    );

    // A stale sensor sample: 6 ms old against a 5 ms limit.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.stamp_ns = input.now_ns.unwrap() - 6_000_000;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert_eq!(out.sensor_age_ns, Some(6_000_000));
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(matches!(
        out.guard_reason,
        Reason::SensorStale {
            age_ns: 6_000_000,
            ..
        }
    ));

    // Stale joints: the drives keep delivering the same old sample.
    let mut rig = Rig::armed();
    let first = rig.at_rest();
    rig.estimator.cycle(&first, &CycleContext::AT_REST);
    let mut out = *rig.estimator.last();
    for _ in 0..5 {
        let mut input = rig.at_rest();
        input.joints.stamp_ns = first.joints.stamp_ns;
        out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    }
    assert_eq!(out.joints_age_ns, Some(5_100_000));
    assert!(
        matches!(out.guard_reason, Reason::JointsStale { .. }),
        "{:?}",
        out.guard_reason
    );

    // Joints the drives mark invalid: no pose, no estimate, a Fault.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.joints.valid = false;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert!(out.pose.is_none());
    assert_eq!(out.tip, TipOutcome::JointsInvalid);
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::JointsInvalid)
    );

    // A degenerate pose: the U-joint at the support.
    let mut rig = Rig::armed();
    let q_at_b = [0.0, 0.28, 0.45];
    let input = rig.input(q_at_b, Vector3::zeros());
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert!(out.pose.is_none());
    assert!(matches!(out.tip, TipOutcome::PoseInvalid(_)));
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::PoseInvalid)
    );

    // The tip almost at the support (a = 0.349 m of L = 0.35 m): the force is not
    // observable, which is a Fault, not "no force".
    let mut rig = Rig::armed();
    let q_far = [0.0, 0.28, 0.101];
    let out = rig.push(q_far, &Vector3::zeros());
    // The number is kept, flagged not observable; the guard faults on it.
    assert!(
        matches!(out.tip, TipOutcome::Estimate(e) if !e.observable),
        "{:?}",
        out.tip
    );
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(
        matches!(out.guard_reason, Reason::NotObservable { .. }),
        "{:?}",
        out.guard_reason
    );
    // And the Fault stays after the inputs are good again, until a reset.
    let out = rig.push(NOMINAL_Q, &Vector3::zeros());
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(rig.reset().transition.is_some());
}

/// With HEX-6 noise on every sample, the estimate's scatter around the scripted
/// force matches the standard deviation it reports (within 5 %, 20 000 cycles,
/// fixed seed), at two poses.
#[test]
fn reported_std_matches_the_scatter_with_sensor_noise() {
    for q in [NOMINAL_Q, [0.02, 0.25, 0.31]] {
        let mut rig = Rig::armed();
        let mut sensor = NoisySensor::new(sar_estimator::SensorNoise::HEX6_STD_N, 0x5eed_0003);
        let tip = Vector3::new(1.0, -0.5, 0.5);
        let ideal = example_reading(q, &tip, &rig.bias_n);
        let n = 20_000;
        let mut sq = Vector3::zeros();
        let mut reported = Vector3::zeros();
        for _ in 0..n {
            let input = rig.input(q, sensor.sample(&ideal));
            let e = estimate(rig.estimator.cycle(&input, &CycleContext::AT_REST));
            let err = e.force_n - tip;
            sq += err.component_mul(&err);
            reported = e.std_n;
        }
        let rms = (sq / f64::from(n)).map(f64::sqrt);
        for i in 0..3 {
            let ratio = rms[i] / reported[i];
            assert!(
                (0.95..1.05).contains(&ratio),
                "axis {i}: scatter {} vs std {}",
                rms[i],
                reported[i]
            );
        }
    }
}

/// A bias with a NaN or infinite component is refused, at construction and
/// as a command, with the offending value; a refused bias leaves the old one.
#[test]
fn a_non_finite_bias_is_refused() {
    let bad = Estimator::new(
        &example_estimator_config(),
        Vector3::new(0.0, f64::NEG_INFINITY, 0.0),
    );
    assert!(matches!(
        bad,
        Err(sar_estimator::SettingError::Invalid { field: "bias", value, .. })
            if value == f64::NEG_INFINITY
    ));
    let mut rig = Rig::armed();
    for (bias, bad) in [
        (
            Bias::force_only(Vector3::new(f64::INFINITY, 0.0, 0.0)),
            f64::INFINITY,
        ),
        (
            Bias {
                force_n: Vector3::zeros(),
                torque_nm: Vector3::new(0.0, 0.0, f64::NAN),
            },
            f64::NAN,
        ),
    ] {
        let out = rig.push_command(NOMINAL_Q, &Vector3::zeros(), Some(Command::SetBias(bias)));
        match out.command.unwrap().result {
            Err(CommandRefused::BiasNonFinite { value }) => {
                assert_eq!(value.to_bits(), bad.to_bits());
            }
            other => panic!("{other:?}"),
        }
    }
    // The old bias is still in use: the scripted force comes back.
    let f = Vector3::new(1.0, -2.0, 0.5);
    let out = rig.push(NOMINAL_Q, &f);
    assert!((estimate(&out).force_n - f).norm() < 1e-9);
    assert_eq!(out.guard_state, GuardState::Ok);
}

// ------------------------------------------------------------- debounce (hole 1)

/// A 4 kHz loop reading a 500 Hz sensor: each sample is seen in 8 cycles. One
/// stop-level sample (a spike) seen 8 times is ONE vote, not 8: no Stop with a
/// debounce of 3 samples. (The old guard counted cycles and stopped.)
#[test]
fn debounce_counts_new_samples_not_loop_cycles() {
    let mut rig = Rig::armed();
    let spike = Vector3::x() * 20.0;
    let reading = |rig: &Rig, f: &Vector3<f64>| example_reading(NOMINAL_Q, f, &rig.bias_n);
    let first_counter = rig.counter;
    let mut now_ns = 1_000_000_000 + rig.cycle * PERIOD_NS;
    for sample in 0..6u32 {
        let counter = first_counter + sample + 1;
        let f = if sample == 1 { spike } else { Vector3::zeros() };
        let r = reading(&rig, &f);
        let stamp_ns = now_ns + 100_000;
        for _ in 0..8 {
            rig.cycle += 1;
            now_ns += 250_000;
            let input = CycleInput {
                cycle: rig.cycle,
                now_ns: Some(now_ns),
                sensor: SensorSample {
                    force_n: r,
                    torque_nm: ideal_torque(&r, &rig.bias_n, &rig.bias_nm),
                    counter,
                    status: 0,
                    stamp_ns,
                    valid: true,
                    drained: sar_estimator::cycle::DrainedSamples::default(),
                },
                joints: joint_sample(NOMINAL_Q, now_ns - 50_000),
                command: None,
            };
            let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
            assert_eq!(
                out.guard_state,
                GuardState::Ok,
                "sample {sample}: {:?}",
                out.guard_reason
            );
        }
    }
}

/// An axial force of 30, 30, 11 N repeating (mean 23.7 N) against a 12 N
/// axial stop limit and a debounce of 3: the up/down count reaches 3 on the
/// fifth sample (1, 2, 1, 2, 3). A count that restarts at 0 after a sample
/// below the limit never stopped.
#[test]
fn a_dip_below_the_limit_does_not_defeat_the_debounce() {
    let mut rig = Rig::armed();
    let u = Vector3::x();
    let mut stop_at = None;
    for k in 0..30 {
        let f = if k % 3 == 2 { 11.0 } else { 30.0 };
        let out = rig.push(NOMINAL_Q, &(u * f));
        if out.guard_state == GuardState::Stop {
            stop_at = Some(k);
            break;
        }
    }
    assert_eq!(stop_at, Some(4));
    // The worst-case time to Stop is exposed: 3 samples of at most 5 ms.
    assert_eq!(rig.estimator.guard_config().stop_within_ns(), 15_000_000);
}

// ---------------------------------------------------------------- tare (hole 2)

/// A model-based tare: the bias drifted since the configured tare, so at rest
/// the estimate shows a force; the tare command makes this pose's reading
/// give zero tip force (the rod's weight stays in the model), and the torque
/// bias follows. It is reported as an event with the old and new bias.
#[test]
fn a_tare_at_rest_zeroes_the_tip_force_and_is_reported() {
    let mut rig = Rig::armed();
    // The true bias drifts by (0.3, -0.2, 0.4) N and the torque bias too.
    let configured = Bias {
        force_n: rig.bias_n,
        torque_nm: rig.bias_nm,
    };
    rig.bias_n += Vector3::new(0.3, -0.2, 0.4);
    rig.bias_nm += Vector3::new(0.001, 0.002, -0.001);
    let q = [0.02, 0.25, 0.31];
    let out = rig.push(q, &Vector3::zeros());
    assert!(estimate(&out).force_n.norm() > 0.3);
    let out = rig.push_command(q, &Vector3::zeros(), Some(Command::Tare));
    let Ok(CommandAccepted::BiasSet { previous, bias }) = out.command.unwrap().result else {
        panic!("{:?}", out.command);
    };
    assert_eq!(previous, configured);
    assert!((bias.force_n - rig.bias_n).norm() < 1e-9, "{bias:?}");
    assert!((bias.torque_nm - rig.bias_nm).norm() < 1e-9, "{bias:?}");
    assert_eq!(rig.estimator.bias(), bias);
    // From the next cycle: the scripted forces come back at every pose, and
    // the torque agrees with the model.
    for (q, f) in [
        (q, Vector3::zeros()),
        (NOMINAL_Q, Vector3::new(1.0, -0.5, 0.3)),
    ] {
        let out = rig.push(q, &f);
        assert!((estimate(&out).force_n - f).norm() < 1e-9);
        assert!(out.torque.unwrap().residual_nm.norm() < 1e-9);
        assert_eq!(out.guard_state, GuardState::Ok);
    }
}

/// A tare can never hide a real force: refused while a part is at or above
/// its warn limit (even before the debounce has entered Warn), in Warn, Stop
/// and Fault, and on invalid input; each refusal is reported with its reason
/// and leaves the bias unchanged. The same rules hold for an explicit bias.
#[test]
fn a_tare_is_refused_above_warn_and_outside_ok() {
    let mut rig = Rig::armed();
    let before = rig.estimator.bias();
    let warn_push = Vector3::x() * 9.0; // axial warn 8 N, stop 12 N
    // Ok, but this sample is above the warn limit.
    for command in [
        Command::Tare,
        Command::SetBias(Bias::force_only(Vector3::zeros())),
    ] {
        let out = rig.push_command(NOMINAL_Q, &warn_push, Some(command));
        assert_eq!(out.guard_state, GuardState::Ok);
        assert!(
            matches!(
                out.command.unwrap().result,
                Err(CommandRefused::AboveWarn {
                    reason: Reason::AboveWarn {
                        part: ForcePart::Axial,
                        ..
                    }
                })
            ),
            "{:?}",
            out.command
        );
    }
    // In Warn.
    let out = rig.push_command(NOMINAL_Q, &warn_push, Some(Command::Tare));
    assert_eq!(out.guard_state, GuardState::Warn);
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::NotOk {
            state: GuardState::Warn,
            ..
        })
    ));
    // In Stop, even once the force is gone.
    for _ in 0..3 {
        rig.push(NOMINAL_Q, &(Vector3::x() * 20.0));
    }
    let out = rig.push_command(NOMINAL_Q, &Vector3::zeros(), Some(Command::Tare));
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::NotOk {
            state: GuardState::Stop,
            ..
        })
    ));
    // On invalid input (a NaN sample): Fault, refused.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.force_n.y = f64::NAN;
    input.command = Some(Command::Tare);
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::NotOk {
            state: GuardState::Fault,
            reason: Reason::SensorInvalid
        })
    ));
    assert_eq!(rig.estimator.bias(), before);
    // An explicit bias in Ok below warn is accepted.
    let mut rig = Rig::armed();
    let new = Bias {
        force_n: Vector3::new(0.1, 0.2, 0.3),
        torque_nm: Vector3::new(0.0, 0.01, 0.0),
    };
    let out = rig.push_command(NOMINAL_Q, &Vector3::zeros(), Some(Command::SetBias(new)));
    assert_eq!(
        out.command.unwrap().result,
        Ok(CommandAccepted::BiasSet {
            previous: before,
            bias: new
        })
    );
}

// ---------------------------------------------------------------- reset (hole 3)

/// A reset is judged on the input of the cycle that carries it: the force
/// had gone in the previous cycle, but it is back at stop level in this one,
/// so the reset is refused (the old `reset_guard` judged the last stepped
/// input, however old). And a guard reset must name the cycle just stepped.
#[test]
fn a_reset_is_judged_on_the_input_of_its_own_cycle() {
    let mut rig = Rig::armed();
    for _ in 0..3 {
        rig.push(NOMINAL_Q, &(Vector3::x() * 20.0));
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Stop);
    rig.push(NOMINAL_Q, &Vector3::zeros());
    let out = rig.push_command(NOMINAL_Q, &(Vector3::x() * 20.0), Some(Command::Reset));
    // Judged on this cycle's force (at stop level): not Ok, but Retreat.
    assert_eq!(out.command.unwrap().result, Ok(CommandAccepted::Reset));
    assert_eq!(out.guard_state, GuardState::Retreat);
    // In Retreat a reset is a no-op; the force gone, Retreat ends in Ok.
    let out = rig.reset();
    assert_eq!(
        out.command.unwrap().result,
        Ok(CommandAccepted::NothingToReset)
    );
    for _ in 0..3 {
        rig.push(NOMINAL_Q, &Vector3::zeros());
    }
    assert_eq!(rig.estimator.guard_state(), GuardState::Ok);
    // In Ok a reset is a no-op, reported as such.
    let out = rig.reset();
    assert_eq!(out.guard_state, GuardState::Ok);
    let out = rig.reset();
    assert_eq!(
        out.command.unwrap().result,
        Ok(CommandAccepted::NothingToReset)
    );
    assert_eq!(out.transition, None);

    // The guard itself: a reset that names a later cycle than the one just
    // stepped is refused.
    use sar_estimator::guard::{Guard, GuardConfig, GuardInput, TipInput};
    let mut g = Guard::new(GuardConfig::new(test_guard_limits()).unwrap());
    let input = GuardInput {
        cycle: 10,
        input_fault: None,
        new_sample: true,
        sensor_age_ns: 0,
        sensor_valid: true,
        joints_age_ns: 0,
        joints_valid: true,
        tip: TipInput::Estimate {
            force_n: Vector3::zeros(),
            std_n: Vector3::zeros(),
            rod_dir: Vector3::x(),
            observable: true,
            max_std_n: 2.0,
        },
        extra_margin_n: 0.0,
        tare_due: None,
        smoothed_force_n: None,
    };
    g.step(&input);
    assert_eq!(
        g.reset(11).unwrap_err().reason,
        Reason::ResetNotCurrent { last: 10, got: 11 }
    );
    assert_eq!(g.reset(10).unwrap().unwrap().to, GuardState::Ok);
}

// ---------------------------------------------------------------- clock (hole 4)

/// A clock that cannot be read, or one that does not advance, is a Fault with
/// a clock reason of its own, and no age (no sentinel time) is reported.
#[test]
fn clock_failures_are_faults_with_their_own_reason() {
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.now_ns = None;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert_eq!((out.sensor_age_ns, out.joints_age_ns), (None, None));
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::ClockFailed)
    );

    // Stuck: the same time twice, every stamp fresh.
    let mut rig = Rig::armed();
    let first = rig.at_rest();
    let mut stuck = rig.at_rest();
    let t = first.now_ns.unwrap();
    stuck.now_ns = Some(t);
    stuck.sensor.stamp_ns = t;
    stuck.joints.stamp_ns = t;
    assert_eq!(
        rig.estimator
            .cycle(&first, &CycleContext::AT_REST)
            .guard_state,
        GuardState::Ok
    );
    let out = *rig.estimator.cycle(&stuck, &CycleContext::AT_REST);
    assert_eq!((out.sensor_age_ns, out.joints_age_ns), (None, None));
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (
            GuardState::Fault,
            Reason::ClockNotAdvancing {
                previous_ns: t,
                now_ns: t
            }
        )
    );
}

// ------------------------------------------------------------ input plausibility

/// A joint that moves faster than the axes can between two joint samples is
/// a Fault (an encoder jump); a move within the speed limit is not.
#[test]
fn a_joint_jump_is_a_fault() {
    let mut rig = Rig::armed_with(Rig::with_config(&config_with_speed(0.05)));
    // 0.05 m/s over 1 ms is 50 um, plus the 0.2 mm margin: 0.24 mm is fine.
    let mut q = NOMINAL_Q;
    q[2] += 0.000_24;
    assert_eq!(rig.push(q, &Vector3::zeros()).guard_state, GuardState::Ok);
    // A 2 mm jump of q3.
    q[2] += 0.002;
    let out = rig.push(q, &Vector3::zeros());
    assert_eq!(out.guard_state, GuardState::Fault);
    match out.guard_reason {
        Reason::JointJump {
            axis,
            moved_m,
            allowed_m,
        } => {
            assert_eq!(axis, 3);
            assert!((moved_m - 0.002).abs() < 1e-12);
            assert!((allowed_m - 0.000_25).abs() < 1e-12);
        }
        other => panic!("{other:?}"),
    }
    // A joint stamp that goes back.
    let mut rig = Rig::armed_with(Rig::with_config(&config_with_speed(0.05)));
    let first = rig.at_rest();
    let mut back = rig.at_rest();
    back.joints.stamp_ns = first.joints.stamp_ns - 1;
    rig.estimator.cycle(&first, &CycleContext::AT_REST);
    let out = *rig.estimator.cycle(&back, &CycleContext::AT_REST);
    assert!(matches!(
        out.guard_reason,
        Reason::JointsStampBackwards { .. }
    ));
}

/// The sensor counter: a gap beyond the limit is a Fault; a wrap from
/// u32::MAX to 0 is not; the same counter re-stamped every cycle goes stale
/// 5 ms after its first stamp; a status other than 0 is a Fault.
#[test]
fn the_sensor_counter_and_status_are_checked() {
    let mut rig = Rig::new();
    rig.counter = u32::MAX - 2;
    let mut rig = Rig::armed_with(rig);
    assert_eq!(
        rig.push(NOMINAL_Q, &Vector3::zeros()).guard_state,
        GuardState::Ok
    );
    assert_eq!(
        rig.push(NOMINAL_Q, &Vector3::zeros()).guard_state,
        GuardState::Ok
    );
    assert_eq!(rig.counter, 0);
    // 4 samples lost against a gap of 3.
    rig.counter += 3;
    let out = rig.push(NOMINAL_Q, &Vector3::zeros());
    assert_eq!(
        out.guard_reason,
        Reason::SensorCounterGap {
            previous: 0,
            got: 4,
            max_gap: 3
        }
    );

    // The same sample, re-stamped fresh every cycle by a broken driver.
    let mut rig = Rig::armed();
    let first = rig.at_rest();
    let counter = first.sensor.counter;
    rig.estimator.cycle(&first, &CycleContext::AT_REST);
    let mut last = None;
    for _ in 0..6 {
        let mut input = rig.at_rest();
        input.sensor.counter = counter;
        rig.counter = counter;
        let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
        assert!(!out.new_sample);
        last = Some(out);
    }
    let out = last.unwrap();
    assert_eq!(out.sensor_age_ns, Some(6_300_000));
    // Latched at the first cycle beyond 5 ms.
    assert!(matches!(
        out.guard_reason,
        Reason::SensorStale {
            age_ns: 5_300_000,
            ..
        }
    ));

    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.status = 0x10;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    assert_eq!(out.guard_reason, Reason::SensorStatus { status: 0x10 });
}

/// The torque check: the model's torque passes (residual ~0); an untared
/// torque bias, or a torque on its own (a contact that the force model does
/// not explain), beyond 7 standard deviations is a Fault that names the axis.
#[test]
fn an_implausible_sensor_torque_is_a_fault() {
    let mut rig = Rig::armed();
    let out = rig.push(NOMINAL_Q, &Vector3::new(1.0, 2.0, -1.0));
    let t = out.torque.unwrap();
    assert!(t.residual_nm.norm() < 1e-12);
    // std: z axis sqrt(0.002^2 + 0.05^2 0.2^2) = 0.01020 N m.
    assert!((t.std_nm.z - (0.002f64.powi(2) + (0.05f64 * 0.2).powi(2)).sqrt()).abs() < 1e-12);
    let mut input = rig.at_rest();
    input.sensor.torque_nm.z += 8.0 * t.std_nm.z;
    let out = *rig.estimator.cycle(&input, &CycleContext::AT_REST);
    match out.guard_reason {
        Reason::TorqueImplausible {
            axis: Axis::Z,
            residual_nm,
            max_sigma,
            ..
        } => {
            assert!((residual_nm - 8.0 * t.std_nm.z).abs() < 1e-12);
            assert_eq!(max_sigma, TorqueLimits::DEFAULT_MAX_SIGMA);
        }
        other => panic!("{other:?}"),
    }
    // 6 standard deviations pass.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.torque_nm.x -= 6.0 * t.std_nm.x;
    assert_eq!(
        rig.estimator
            .cycle(&input, &CycleContext::AT_REST)
            .guard_state,
        GuardState::Ok
    );
}

/// The guard acts on the estimator's observability flag, with the
/// estimator's own limit in the reason; the number is kept in the output.
#[test]
fn the_guard_faults_on_the_observability_flag() {
    let mut config = config_with_speed(1e3);
    config.tip.max_std_n = 0.1; // below the nominal pose's std
    let mut rig = Rig::with_config(&config);
    let out = rig.reset();
    let TipOutcome::Estimate(e) = out.tip else {
        panic!("{:?}", out.tip)
    };
    assert!(!e.observable);
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(
        matches!(
            out.command.unwrap().result,
            Err(CommandRefused::Reset {
                reason: Reason::NotObservable { max_std_n, std_max_n }
            }) if max_std_n == 0.1 && std_max_n == e.std_n.max()
        ),
        "{:?}",
        out.command
    );
}

/// The filtered tip force beside the estimate: the cycle's `filtered` is a
/// [`TipFilter`] stepped once per NEW sample with the observable estimate
/// (a repeated counter does not step it), it is reset when there is no
/// estimate, and restarts at the next one with no memory of before.
#[test]
fn the_filtered_tip_force_is_stepped_per_new_sample_and_reset_without_input() {
    let config = config_with_speed(1e3);
    let filter_config = config.filter.expect("the example config has a filter");
    let mut reference = TipFilter::new(filter_config).unwrap();
    let mut rig = Rig::with_config(&config);
    let armed = rig.reset();
    assert_eq!(armed.guard_state, GuardState::Ok);
    let e = estimate(&armed);
    let expected = reference.update(&e.force_n, &e.std_n).unwrap();
    assert_eq!(armed.filtered, Some(expected));
    // A ramp of the tip force: the cycle's filter is the reference filter,
    // bit for bit, and it lags behind the estimate.
    for k in 1..=50 {
        let tip = Vector3::new(0.05 * f64::from(k), 0.0, 0.0);
        let out = rig.push(NOMINAL_Q, &tip);
        let e = estimate(&out);
        let expected = reference.update(&e.force_n, &e.std_n).unwrap();
        assert_eq!(out.filtered, Some(expected), "cycle {k}");
    }
    let out = *rig.estimator.last();
    assert!(out.filtered.unwrap().force_n.x < estimate(&out).force_n.x - 0.1);
    let filtered_before = out.filtered;
    // The same sample again (a loop faster than the sensor): not stepped.
    let mut repeat = rig.input(
        NOMINAL_Q,
        example_reading(NOMINAL_Q, &Vector3::new(2.5, 0.0, 0.0), &rig.bias_n),
    );
    rig.counter = rig.counter.wrapping_sub(1);
    repeat.sensor.counter = rig.counter;
    let out = *rig.estimator.cycle(&repeat, &CycleContext::AT_REST);
    assert!(!out.new_sample);
    assert_eq!(out.filtered, filtered_before);
    // A sample missed (counter + 2, within the accepted gap: a late cycle,
    // issue 33): the filter steps over the gap with the new sample held,
    // each step with its deviation times sqrt(2) (an upper bound), rather
    // than restart at one noisy sample or lag by the samples it never saw.
    rig.counter = rig.counter.wrapping_add(1);
    let out = rig.push(NOMINAL_Q, &Vector3::new(2.5, 0.0, 0.0));
    let e = estimate(&out);
    let held_std_n = e.std_n * 2f64.sqrt();
    reference.update(&e.force_n, &held_std_n).unwrap();
    let expected = reference.update(&e.force_n, &held_std_n).unwrap();
    assert_eq!(out.filtered, Some(expected));
    assert_ne!(out.filtered.unwrap().force_n, e.force_n);
    // No estimate (invalid joints): no filtered output, and the filter resets.
    let mut bad = rig.at_rest();
    bad.joints.valid = false;
    let out = *rig.estimator.cycle(&bad, &CycleContext::AT_REST);
    assert_eq!(out.filtered, None);
    assert_eq!(out.guard_state, GuardState::Fault);
    // With the next estimate the filter restarts at it: no memory of the ramp.
    let out = rig.reset();
    assert_eq!(out.guard_state, GuardState::Ok);
    let e = estimate(&out);
    let restarted = out.filtered.unwrap();
    assert_eq!((restarted.force_n, restarted.std_n), (e.force_n, e.std_n));
}

/// The torque check and the tare with d != 0 and a sensor turned against the
/// base frame: the sensor torque of MODEL.md 4,
/// t = R^T ((A - S) x (-F_A) - M_T n) + b_t with n = -(sin q4, 0, cos q4),
/// built here from the independent statics of `common`, leaves a residual of
/// round-off; a torsion of the wrong sign, or R where R^T belongs, does not;
/// and a tare at rest zeroes the tip force.
#[test]
fn the_torque_check_and_the_tare_hold_with_a_rod_offset_and_a_turned_sensor() {
    let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    let spec = sar_estimator::CalibrationSpec {
        sensor_rotation: rotation,
        ..example_calibration().spec()
    };
    let calibration = sar_estimator::Calibration::new(&spec).unwrap();
    let offset_m = 0.004;
    let profile = sar_estimator::Profile::new(&sar_estimator::ProfileSpec {
        offset_m,
        ..manipulator2().spec()
    })
    .unwrap();
    let mut config = config_with_speed(1e3);
    config.calibration = calibration;
    config.profile = profile;
    let truth = common::Truth {
        offset_m,
        ..manipulator2_truth()
    };
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let bias_nm = Vector3::new(0.02, -0.01, 0.005);
    // The model's reading for a tip force, with a torsion sign `sign`
    // (+1 right) and the rotation applied as R^T (`transpose` true, right).
    let reading = |q: &ActiveJoints, tip_n: &Vector3<f64>, sign: f64, transpose: bool| {
        let pose = sar_kinematics::forward(&calibration, &profile, q).unwrap();
        let (f_a, torsion_nm) = ujoint_force(
            &truth,
            &pose.ujoint_m,
            &pose.rod_dir,
            &pose.rod_normal,
            tip_n,
            0.0,
        );
        let q4 = pose.rod_dir.x.atan2(pose.rod_dir.z);
        let n = -Vector3::new(q4.sin(), 0.0, q4.cos());
        let to_sensor = if transpose {
            rotation.transpose()
        } else {
            rotation
        };
        let lever = pose.ujoint_m - pose.sensor_m;
        let torque = to_sensor * (lever.cross(&(-f_a)) - n * (sign * torsion_nm)) + bias_nm;
        (ideal_reading(&rotation, &f_a, &bias_n), torque)
    };
    let q = ActiveJoints {
        q1_m: 0.02,
        q2_m: 0.25,
        q3_m: 0.31,
    };
    let tip_n = Vector3::new(1.5, -0.5, 2.0);
    let mut estimator = Estimator::with_bias(
        &config,
        Bias {
            force_n: bias_n,
            torque_nm: bias_nm,
        },
    )
    .unwrap();
    let input = |cycle: u64, (force_n, torque_nm): (Vector3<f64>, Vector3<f64>)| CycleInput {
        cycle,
        now_ns: Some(1_000_000_000 + cycle * PERIOD_NS),
        sensor: SensorSample {
            force_n,
            torque_nm,
            counter: cycle as u32,
            status: 0,
            stamp_ns: 1_000_000_000 + cycle * PERIOD_NS,
            valid: true,
            drained: sar_estimator::cycle::DrainedSamples::default(),
        },
        joints: JointSample {
            joints: q,
            stamp_ns: 1_000_000_000 + cycle * PERIOD_NS,
            valid: true,
        },
        command: Some(Command::Reset),
    };
    let out = *estimator.cycle(
        &input(1, reading(&q, &tip_n, 1.0, true)),
        &CycleContext::AT_REST,
    );
    assert_eq!(out.guard_state, GuardState::Ok, "{:?}", out.guard_reason);
    let e = estimate(&out);
    assert!(e.torsion_nm.abs() > 1e-3, "the pose must load the torsion");
    assert!((e.force_n - tip_n).norm() < 1e-9, "{:?}", e.force_n);
    let residual = out.torque.unwrap().residual_nm;
    assert!(residual.norm() < 1e-12, "{residual:?}");
    // The torsion's sign and the rotation's direction are seen.
    for (sign, transpose) in [(-1.0, true), (1.0, false)] {
        let mut rig = Estimator::with_bias(
            &config,
            Bias {
                force_n: bias_n,
                torque_nm: bias_nm,
            },
        )
        .unwrap();
        let out = *rig.cycle(
            &input(1, reading(&q, &tip_n, sign, transpose)),
            &CycleContext::AT_REST,
        );
        let r = out.torque.unwrap();
        // Far from round-off (the model's error, not noise, is measured).
        assert!(
            r.residual_nm.norm() > 1e-3,
            "sign {sign}, transpose {transpose}: {:?}",
            r.residual_nm
        );
    }
    // A tare at rest: the next reading at rest gives zero tip force.
    let mut tare = input(2, reading(&q, &Vector3::zeros(), 1.0, true));
    tare.command = Some(Command::Tare);
    let out = *estimator.cycle(&tare, &CycleContext::AT_REST);
    assert!(out.command.unwrap().result.is_ok(), "{:?}", out.command);
    let mut after = input(3, reading(&q, &Vector3::zeros(), 1.0, true));
    after.command = None;
    let out = *estimator.cycle(&after, &CycleContext::AT_REST);
    assert!(estimate(&out).force_n.norm() < 1e-9);
    assert!(out.torque.unwrap().residual_nm.norm() < 1e-12);
}

/// Following error: joints within the tolerance of the commanded reference
/// are fine; one axis beyond it is a Fault with its own reason, axis and
/// error; a reference that is not finite, or a tolerance that is not > 0,
/// faults too; a reset is refused while the error lasts.
#[test]
fn leaving_the_commanded_trajectory_is_a_fault() {
    use sar_estimator::cycle::FollowingReference;
    let reference = |q: [f64; 3], tolerance_m: f64| FollowingReference {
        joints: ActiveJoints {
            q1_m: q[0],
            q2_m: q[1],
            q3_m: q[2],
        },
        tolerance_m,
    };
    let following = |reference: FollowingReference| CycleContext {
        reference: Some(reference),
        ..CycleContext::AT_REST
    };
    let mut rig = Rig::armed();
    let mut commanded = NOMINAL_Q;
    commanded[1] += 0.000_9;
    let input = rig.at_rest();
    let out = *rig
        .estimator
        .cycle(&input, &following(reference(commanded, 0.001)));
    assert_eq!(out.guard_state, GuardState::Ok);
    // 1.1 mm off on q2 with a 1 mm tolerance.
    commanded[1] += 0.000_2;
    let input = rig.at_rest();
    let out = *rig
        .estimator
        .cycle(&input, &following(reference(commanded, 0.001)));
    assert_eq!(out.guard_state, GuardState::Fault);
    match out.guard_reason {
        Reason::FollowingError {
            axis,
            error_m,
            tolerance_m,
        } => {
            assert_eq!(axis, 2);
            assert!((error_m - 0.0011).abs() < 1e-12, "{error_m}");
            assert_eq!(tolerance_m, 0.001);
        }
        other => panic!("{other:?}"),
    }
    // The reset is judged with the same reference: refused while it lasts.
    let mut input = rig.at_rest();
    input.command = Some(Command::Reset);
    let out = *rig
        .estimator
        .cycle(&input, &following(reference(commanded, 0.001)));
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::Reset {
            reason: Reason::FollowingError { axis: 2, .. }
        })
    ));
    // Without the error it is accepted.
    let mut input = rig.at_rest();
    input.command = Some(Command::Reset);
    let out = *rig
        .estimator
        .cycle(&input, &following(reference(NOMINAL_Q, 0.001)));
    assert_eq!(out.guard_state, GuardState::Ok);
    // A NaN reference and a zero tolerance fault.
    for (q, tol) in [
        ([f64::NAN, NOMINAL_Q[1], NOMINAL_Q[2]], 0.001),
        (NOMINAL_Q, 0.0),
        (NOMINAL_Q, f64::NAN),
    ] {
        let mut rig = Rig::armed();
        let input = rig.at_rest();
        let out = *rig.estimator.cycle(&input, &following(reference(q, tol)));
        assert!(
            matches!(out.guard_reason, Reason::FollowingError { axis: 1, .. }),
            "{q:?} {tol}: {:?}",
            out.guard_reason
        );
    }
}

/// Limit changes: lowered limits act from the next cycle (a force between the
/// old and new warn limits now warns); a stop limit above its ceiling (by
/// default the configured stop limit), warn >= stop, or NaN are refused and
/// change nothing; a raised ceiling lets the limits go up to it.
#[test]
fn force_limits_change_at_run_time_within_their_ceiling() {
    use sar_estimator::guard::ForceLimits;
    let mut rig = Rig::armed();
    let configured = rig.estimator.guard_config().force_limits();
    let u = Vector3::x();
    // 6 N along the rod: below the 8 N axial warn limit.
    for _ in 0..5 {
        assert_eq!(rig.push(NOMINAL_Q, &(u * 6.0)).guard_state, GuardState::Ok);
    }
    let lowered = ForceLimits {
        warn_axial_n: 4.0,
        stop_axial_n: 9.0,
        ..configured
    };
    let out = rig.push_command(NOMINAL_Q, &(u * 6.0), Some(Command::SetLimits(lowered)));
    assert_eq!(
        out.command.unwrap().result,
        Ok(CommandAccepted::LimitsSet {
            previous: configured,
            limits: lowered
        })
    );
    assert_eq!(rig.estimator.guard_config().force_limits(), lowered);
    let mut warned = false;
    for _ in 0..5 {
        warned |= rig.push(NOMINAL_Q, &(u * 6.0)).guard_state == GuardState::Warn;
    }
    assert!(warned, "6 N did not warn under a 4 N warn limit");
    // Refused: above the ceiling, warn >= stop, NaN. Nothing changes.
    for bad in [
        ForceLimits {
            stop_axial_n: configured.stop_axial_n + 0.1,
            ..lowered
        },
        ForceLimits {
            warn_total_n: 9.0,
            stop_total_n: 9.0,
            ..lowered
        },
        ForceLimits {
            warn_lateral_n: f64::NAN,
            ..lowered
        },
    ] {
        let out = rig.push_command(NOMINAL_Q, &Vector3::zeros(), Some(Command::SetLimits(bad)));
        assert!(
            matches!(
                out.command.unwrap().result,
                Err(CommandRefused::Limits { .. })
            ),
            "{bad:?}"
        );
        assert_eq!(rig.estimator.guard_config().force_limits(), lowered);
    }
    // A configuration with raised ceilings accepts up to them.
    let mut config = config_with_speed(1e3);
    config.guard = config.guard.with_ceiling([30.0, 20.0, 15.0]).unwrap();
    assert!(config.guard.with_ceiling([1.0, 20.0, 15.0]).is_err());
    let mut rig = Rig::armed_with(Rig::with_config(&config));
    let raised = ForceLimits {
        stop_axial_n: 20.0,
        ..configured
    };
    let out = rig.push_command(
        NOMINAL_Q,
        &Vector3::zeros(),
        Some(Command::SetLimits(raised)),
    );
    assert!(matches!(
        out.command.unwrap().result,
        Ok(CommandAccepted::LimitsSet { .. })
    ));
    let too_high = ForceLimits {
        stop_axial_n: 20.5,
        ..configured
    };
    let out = rig.push_command(
        NOMINAL_Q,
        &Vector3::zeros(),
        Some(Command::SetLimits(too_high)),
    );
    assert!(matches!(
        out.command.unwrap().result,
        Err(CommandRefused::Limits {
            field: "stop_axial_n",
            ..
        })
    ));
}

/// MODEL.md 10 in the cycle (at `CarriageMotion::REST` the estimate is the
/// static one to the bit: `tip_force.rs`); in motion the guard judges the compensated force with
/// the grown standard deviation. A reading without the rod's inertial part
/// while the loop says the carriage accelerates at 4 m/s^2 along the rod is
/// a tip force of m A'' = 10.4 N against the rod: the guard acts on it.
#[test]
fn in_motion_the_guard_judges_the_compensated_force() {
    use sar_estimator::motion::CarriageMotion;
    let mut plain = Rig::armed();
    let mut moving = Rig::armed();
    let accel = CarriageMotion {
        velocity_mps: Vector3::new(0.05, 0.0, 0.0),
        accel_mps2: Vector3::new(4.0, 0.0, 0.0),
        accel_std_mps2: 0.2,
    };
    let mut last = None;
    for _ in 0..6 {
        let input = plain.at_rest();
        let expected = *plain.estimator.cycle(&input, &CycleContext::AT_REST);
        let in_motion = CycleContext {
            motion: accel,
            ..CycleContext::AT_REST
        };
        last = Some((*moving.estimator.cycle(&input, &in_motion), expected));
    }
    let (out, still) = last.unwrap();
    let (e, s) = (estimate(&out), estimate(&still));
    let m = example_estimator_config().profile.mass_kg();
    // Along the rod (u = X0 at the nominal pose): -m A''.
    assert!(
        (e.force_n.x - (s.force_n.x - m * 4.0)).abs() < 1e-9,
        "{:?}",
        e.force_n
    );
    // Its std: the acceleration's 0.2 m/s^2 times M = m along the rod.
    let expected_x = (s.std_n.x * s.std_n.x + (m * 0.2) * (m * 0.2)).sqrt();
    assert!(
        (e.std_n.x - expected_x).abs() < 1e-9,
        "{} vs {expected_x}",
        e.std_n.x
    );
    assert_eq!(still.guard_state, GuardState::Ok);
    assert!(
        matches!(out.guard_state, GuardState::Warn | GuardState::Stop),
        "{:?} {:?}",
        out.guard_state,
        out.guard_reason
    );
}
