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
    CycleInput, CycleOutput, Estimator, JointSample, SensorSample, TipOutcome,
};
use sar_estimator::guard::{ForcePart, GuardState, Reason};
use sar_kinematics::ActiveJoints;

const PERIOD_NS: u64 = 1_000_000;
/// A: (0.30, 0.20, 0.0): rod horizontal along +X0, a = 0.15 m.
const NOMINAL_Q: [f64; 3] = [0.0, 0.28, 0.30];

struct Rig {
    estimator: Estimator,
    cycle: u64,
    bias_n: Vector3<f64>,
}

impl Rig {
    fn new() -> Self {
        let bias_n = Vector3::new(0.4, -1.1, 0.25);
        Self {
            estimator: Estimator::new(&example_estimator_config(), bias_n).unwrap(),
            cycle: 0,
            bias_n,
        }
    }

    fn input(&mut self, q: [f64; 3], reading_n: Vector3<f64>) -> CycleInput {
        self.cycle += 1;
        let now_ns = 1_000_000_000 + self.cycle * PERIOD_NS;
        CycleInput {
            cycle: self.cycle,
            now_ns,
            sensor: SensorSample {
                force_n: reading_n,
                torque_nm: Vector3::zeros(),
                stamp_ns: now_ns - 300_000,
                valid: true,
            },
            joints: JointSample {
                joints: ActiveJoints {
                    q1_m: q[0],
                    q2_m: q[1],
                    q3_m: q[2],
                },
                stamp_ns: now_ns - 100_000,
                valid: true,
            },
        }
    }

    fn push(&mut self, q: [f64; 3], tip_force_n: &Vector3<f64>) -> CycleOutput {
        let reading = example_reading(q, tip_force_n, &self.bias_n);
        let input = self.input(q, reading);
        *self.estimator.cycle(&input)
    }

    /// The next input at the nominal pose with nothing at the tip.
    fn at_rest(&mut self) -> CycleInput {
        let reading = example_reading(NOMINAL_Q, &Vector3::zeros(), &self.bias_n);
        self.input(NOMINAL_Q, reading)
    }

    /// Steps once with no force, then arms the guard.
    fn armed() -> Self {
        let mut rig = Self::new();
        let out = rig.push(NOMINAL_Q, &Vector3::zeros());
        assert_eq!(out.guard_state, GuardState::Fault);
        assert_eq!(out.guard_reason, Reason::NoInputYet);
        let t = rig.estimator.reset_guard(rig.cycle).unwrap().unwrap();
        assert_eq!(
            (t.from, t.to, t.reason),
            (GuardState::Fault, GuardState::Ok, Reason::Reset)
        );
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
    // Still pushing: the reset is refused.
    assert!(rig.estimator.reset_guard(rig.cycle).is_err());
    // The push goes away: Stop stays latched until a reset.
    for _ in 0..10 {
        let out = rig.push(NOMINAL_Q, &Vector3::zeros());
        assert_eq!(out.guard_state, GuardState::Stop);
    }
    let t = rig.estimator.reset_guard(rig.cycle).unwrap().unwrap();
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
    let out = *rig.estimator.cycle(&input);
    assert_eq!(out.tip, TipOutcome::SensorInvalid);
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::SensorInvalid)
    );

    // A sample stamped in the future.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.stamp_ns = input.now_ns + 1;
    let out = *rig.estimator.cycle(&input);
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::SensorInvalid)
    );

    // A stale sensor sample: 6 ms old against a 5 ms limit.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.sensor.stamp_ns = input.now_ns - 6_000_000;
    let out = *rig.estimator.cycle(&input);
    assert_eq!(out.sensor_age_ns, 6_000_000);
    assert_eq!(out.guard_state, GuardState::Fault);
    assert!(matches!(
        out.guard_reason,
        Reason::SensorStale {
            age_ns: 6_000_000,
            ..
        }
    ));

    // Stale joints.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.joints.stamp_ns = input.now_ns - 5_000_001;
    let out = *rig.estimator.cycle(&input);
    assert!(matches!(out.guard_reason, Reason::JointsStale { .. }));

    // A clock that does not advance (stuck, as a failed clock read would leave
    // it): every input is invalid, even freshly stamped ones.
    let mut rig = Rig::armed();
    let first = rig.at_rest();
    let mut stuck = rig.at_rest();
    stuck.now_ns = first.now_ns;
    stuck.sensor.stamp_ns = first.now_ns;
    stuck.joints.stamp_ns = first.now_ns;
    assert_eq!(rig.estimator.cycle(&first).guard_state, GuardState::Ok);
    let out = *rig.estimator.cycle(&stuck);
    assert_eq!((out.sensor_age_ns, out.joints_age_ns), (0, 0));
    assert_eq!(
        (out.guard_state, out.guard_reason),
        (GuardState::Fault, Reason::SensorInvalid)
    );

    // Joints the drives mark invalid: no pose, no estimate, a Fault.
    let mut rig = Rig::armed();
    let mut input = rig.at_rest();
    input.joints.valid = false;
    let out = *rig.estimator.cycle(&input);
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
    let out = *rig.estimator.cycle(&input);
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
    assert!(rig.estimator.reset_guard(rig.cycle).unwrap().is_some());
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
            let e = estimate(rig.estimator.cycle(&input));
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

/// A tare with a NaN or infinite component is refused, at construction and
/// when replaced, with the offending value; a refused tare leaves the old one.
#[test]
fn a_non_finite_tare_is_refused() {
    let bad = Estimator::new(
        &example_estimator_config(),
        Vector3::new(0.0, f64::NEG_INFINITY, 0.0),
    );
    assert!(matches!(
        bad,
        Err(sar_estimator::SettingError::Invalid { field: "bias_n", value, .. })
            if value == f64::NEG_INFINITY
    ));
    let mut rig = Rig::armed();
    let e = rig
        .estimator
        .set_bias(Vector3::new(f64::INFINITY, 0.0, 0.0))
        .unwrap_err();
    assert!(matches!(
        e,
        sar_estimator::SettingError::Invalid { field: "bias_n", value, .. }
            if value == f64::INFINITY
    ));
    assert!(
        rig.estimator
            .set_bias(Vector3::new(0.0, f64::NAN, 0.0))
            .is_err()
    );
    // The old tare is still in use: the scripted force comes back.
    let f = Vector3::new(1.0, -2.0, 0.5);
    let out = rig.push(NOMINAL_Q, &f);
    assert!((estimate(&out).force_n - f).norm() < 1e-9);
}
