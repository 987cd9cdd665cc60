//! The per-cycle path allocates nothing: it runs many times under a counting
//! global allocator that counts every allocation made on this test's thread.
#![allow(
    unsafe_code,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // try_with: the thread-local may be gone during thread teardown.
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: forwards every call unchanged to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Counts the allocations `f` makes on this thread.
fn allocations_in<R>(f: impl FnOnce() -> R) -> (R, u64) {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let r = f();
    ARMED.with(|a| a.set(false));
    (r, COUNT.with(Cell::get))
}

#[test]
fn the_counter_sees_an_allocation() {
    let (v, n) = allocations_in(|| std::hint::black_box(vec![1u8; 64]));
    assert_eq!(v.len(), 64);
    assert!(n >= 1, "the counting allocator must see a Vec's allocation");
}

mod common;
use common::*;
use nalgebra::Vector3;
use sar_estimator::SensorNoise;
use sar_estimator::cycle::{
    Bias, Command, CycleContext, CycleInput, Estimator, PlausibilityConfig, PlausibilityLimits,
    SensorSample,
};
use sar_estimator::guard::Reason;

thread_local! {
    /// Which reason codes the allocation-free loop saw (no allocation to record).
    static SEEN_REASONS: [Cell<bool>; 64] = const { [const { Cell::new(false) }; 64] };
}
use sar_estimator::identification::{Identification, IdentificationOptions};
use sar_estimator::support::{SupportCalibration, SupportOptions};

/// Builds a scripted run (before counting): moving poses, pushes through Warn
/// and Stop, a NaN sample, a stale sample, a degenerate pose, an unobservable
/// pose, a failed and a stuck clock, a counter gap, a repeated sample, a bad
/// status, a joint jump, a wrong torque, and reset, tare and set-bias
/// commands, so that every branch of the path is taken.
fn scripted_inputs(cycles: u64) -> Vec<CycleInput> {
    let bias_n = Vector3::new(0.4, -1.1, 0.25);
    let mut sensor = NoisySensor::new(SensorNoise::HEX6_STD_N, 0x5eed_0a11);
    (1..=cycles)
        .map(|cycle| {
            let phase = cycle % 1000;
            let t = cycle as f64 * 1e-3;
            let mut q = [
                0.01 * t.sin(),
                0.28 + 0.02 * (0.7 * t).sin(),
                0.30 + 0.02 * (0.3 * t).cos(),
            ];
            let tip = Vector3::new(f64::from(phase as u32 % 400) * 0.05, 0.5, -0.3);
            let mut reading = sensor.sample(&example_reading(q, &tip, &bias_n));
            let now_ns = 1_000_000_000 + cycle * 1_000_000;
            let mut now = Some(now_ns);
            let mut sensor_stamp_ns = now_ns - 200_000;
            let mut counter = cycle as u32;
            let mut status = 0;
            let mut torque_error_nm = 0.0;
            let mut command = match phase % 97 {
                0 => Some(Command::Reset),
                1 => Some(Command::Tare),
                2 => Some(Command::SetBias(Bias::force_only(bias_n))),
                3 => Some(Command::SetBias(Bias::force_only(Vector3::new(
                    f64::NAN,
                    0.0,
                    0.0,
                )))),
                _ => None,
            };
            match phase {
                500 => reading.x = f64::NAN,
                600 => sensor_stamp_ns = now_ns - 50_000_000,
                700 => q = [0.0, 0.28, 0.45], // U-joint at the support
                800 => q = [0.0, 0.28, 0.1005], // tip almost at the support
                850 => now = None,
                860 => now = Some(now_ns - 2_000_000), // the clock went back
                870 => counter += 10,                  // a counter gap
                880..=883 => counter = 880,            // a repeated sample
                890 => status = 4,
                900 => q[2] += 0.01, // a joint jump
                910 => torque_error_nm = 1.0,
                920 => command = Some(Command::Reset),
                // Issue 14's checks: a frozen sensor, saturation, a burst
                // of spikes.
                930..=934 => reading = Vector3::new(1.0, -9.0, 0.5),
                940 => reading.x = 250.0,
                950..=972 if phase % 2 == 0 => reading.y += 30.0,
                _ => {}
            }
            CycleInput {
                cycle,
                now_ns: now,
                sensor: SensorSample {
                    force_n: reading,
                    // t = (A - S) x (f - b_f), A - S = (0, -0.05, 0) (R_0s = I).
                    torque_nm: Vector3::new(0.0, -0.05, 0.0).cross(&(reading - bias_n))
                        + Vector3::x() * torque_error_nm,
                    counter,
                    status,
                    stamp_ns: sensor_stamp_ns,
                    valid: true,
                    drained: sar_estimator::cycle::DrainedSamples::default(),
                },
                joints: joint_sample(q, now_ns - 100_000),
                command,
            }
        })
        .collect()
}

/// 20 000 cycles of the whole per-cycle path (plausibility with the torque
/// check and every check of issue 14 on: frozen, saturation, spikes, a tare
/// falling due 50 ms after each tare, the first reset's check at rest; kinematics, tip
/// force, guard with Retreat, commands) allocate nothing; and the run did
/// visit every guard state (Retreat too: resets above the stop limit), and
/// accepted and refused commands.
#[test]
fn the_per_cycle_path_allocates_nothing() {
    let mut inputs = scripted_inputs(20_000);
    let mut config = example_estimator_config();
    config.plausibility = PlausibilityConfig::new(PlausibilityLimits {
        tare: sar_estimator::cycle::TareLimits {
            max_age_ns: Some(50_000_000),
            drift_n_per_s: 1e-3,
            ..sar_estimator::cycle::TareLimits::default()
        },
        // The script's joints move every cycle, so the mean at rest starts
        // again every sample: a mean of one sample is complete, and the
        // first reset's verdict runs (its refusal while incomplete is the
        // same function's other branch).
        mounting: Some(sar_estimator::cycle::MountingLimits {
            rest_samples: 1,
            ..Default::default()
        }),
        ..PlausibilityLimits::default()
    })
    .unwrap();
    let mut estimator = Estimator::new(&config, Vector3::new(0.4, -1.1, 0.25)).unwrap();
    let mut seen = [false; 5];
    let mut commands = [0usize; 2];
    let mut reasons = std::collections::BTreeSet::new();
    let (_, allocations) = allocations_in(|| {
        for input in inputs.iter_mut() {
            // After a Stop or Fault the next cycle carries a reset.
            if estimator.last().guard_state.is_halting() && input.command.is_none() {
                input.command = Some(Command::Reset);
            }
            let out = estimator.cycle(input, &CycleContext::AT_REST);
            if let Some(event) = out.command {
                commands[usize::from(event.result.is_ok())] += 1;
            }
            seen[usize::from(out.guard_state.code())] = true;
            // A plain array: no allocation while counting.
            let code = out.guard_reason.code();
            SEEN_REASONS.with(|r| {
                if let Some(slot) = r.get(usize::from(code)) {
                    slot.set(true);
                }
            });
        }
    });
    SEEN_REASONS.with(|r| {
        for (code, seen) in r.iter().enumerate() {
            if seen.get() {
                reasons.insert(code);
            }
        }
    });
    assert_eq!(allocations, 0, "the per-cycle path allocated");
    assert_eq!(seen, [true; 5], "the script must visit every guard state");
    for reason in [
        Reason::SensorFrozen { repeats: 0 },
        Reason::SensorSaturated {
            channel: sar_estimator::guard::SensorChannel::Fx,
            value: 0.0,
            range: 0.0,
        },
        Reason::SensorSpikes {
            spikes: 0,
            window: 0,
        },
        Reason::TareDue {
            age_s: 0.0,
            max_age_s: 0.0,
        },
        Reason::RetreatEntered {
            part: sar_estimator::guard::ForcePart::Total,
            force_n: 0.0,
            limit_n: 0.0,
        },
    ] {
        assert!(
            reasons.contains(&usize::from(reason.code())),
            "the script must reach {}: {reasons:?}",
            reason.name()
        );
    }
    assert!(
        commands[0] > 10 && commands[1] > 10,
        "refused, accepted: {commands:?}"
    );
}

/// Identification updates and solves, and a support fit, allocate nothing either.
#[test]
fn identification_and_support_fit_allocate_nothing() {
    let (truth, cal, bias_n, poses) = cone_identification_inputs(7);
    let options = IdentificationOptions {
        bias_across_gravity: true,
        friction: true,
    };
    let mut ident = Identification::new(&cal, &SensorNoise::hex6(), bias_n, options).unwrap();
    let mut support = SupportCalibration::new(
        &cal,
        &SensorNoise::hex6(),
        bias_n,
        SupportOptions::default(),
    )
    .unwrap();
    let ((m_ident, m_support), allocations) = allocations_in(|| {
        for p in &poses {
            ident.add(p).unwrap();
            support.push(p).unwrap();
        }
        (
            ident.solve().unwrap().mass_kg,
            support.fit().unwrap().mass_kg,
        )
    });
    assert_eq!(allocations, 0);
    assert!(
        (m_ident / truth.mass_kg - 1.0).abs() < 0.01
            && (m_support / truth.mass_kg - 1.0).abs() < 0.01
    );
}

/// The identification of the inertia (MODEL.md 10) allocates nothing: 2000
/// samples of a turning rod, added and solved.
#[test]
fn the_dynamic_identification_allocates_nothing() {
    use sar_estimator::identification::dynamic::{DynamicIdentification, MotionSample};
    let (_, cal, bias_n, _) = cone_identification_inputs(7);
    let mut id = DynamicIdentification::new(&cal, &SensorNoise::hex6(), bias_n, 0.1, true).unwrap();
    let samples: Vec<MotionSample> = (0..2000)
        .map(|k| {
            let t = f64::from(k) * 0.002;
            let w = 2.0 * std::f64::consts::PI;
            MotionSample {
                ujoint_m: Vector3::new(
                    0.25 + 0.05 * (0.4 * t).sin(),
                    0.2 + 0.004 * (w * t).sin(),
                    0.003 * (1.3 * w * t).sin(),
                ),
                velocity_mps: Vector3::new(
                    0.02 * (0.4 * t).cos(),
                    0.004 * w * (w * t).cos(),
                    0.0039 * w * (1.3 * w * t).cos(),
                ),
                accel_mps2: Vector3::new(
                    -0.008 * (0.4 * t).sin(),
                    -0.004 * w * w * (w * t).sin(),
                    -0.003 * 1.69 * w * w * (1.3 * w * t).sin(),
                ),
                reading_n: Vector3::new(
                    0.1 * (7.0 * t).sin(),
                    25.0 + 0.2 * (w * t).sin(),
                    0.3 * (3.0 * t).cos(),
                ),
            }
        })
        .collect();
    let (solved, allocations) = allocations_in(|| {
        for s in &samples {
            id.add(s).unwrap();
        }
        id.solve(f64::INFINITY).map(|r| r.condition)
    });
    assert_eq!(allocations, 0);
    // Arbitrary readings: solved or refused, but never allocating.
    let _ = solved;
}

/// The same with d != 0 (the closed form of MODEL.md 4.3): 20 000 cycles
/// allocate nothing and visit every guard state. The script's readings are
/// those of the d = 0 rod (the estimates are off by the offset's small effect,
/// which does not matter here): every branch of the d != 0 path is taken.
#[test]
fn the_per_cycle_path_with_a_rod_offset_allocates_nothing() {
    let mut inputs = scripted_inputs(20_000);
    let config = sar_estimator::cycle::EstimatorConfig {
        profile: sar_estimator::Profile::new(&sar_estimator::ProfileSpec {
            length_m: 0.35,
            offset_m: 0.004,
            mass_kg: 2.593,
            com_m: 0.103,
        })
        .unwrap(),
        // The torque check's d != 0 branch runs too (its limit far off: the
        // script's readings carry no torque).
        plausibility: PlausibilityConfig::new(PlausibilityLimits {
            torque: Some(sar_estimator::cycle::TorqueLimits {
                noise_nm: Vector3::new(0.01, 0.01, 0.002),
                max_sigma: 1e9,
            }),
            // As above: the joints move every cycle.
            mounting: Some(sar_estimator::cycle::MountingLimits {
                rest_samples: 1,
                ..Default::default()
            }),
            ..PlausibilityLimits::default()
        })
        .unwrap(),
        // The compensation's general path (d != 0, I_axial, an adapter).
        inertia: sar_estimator::inertial::RodInertia {
            inertia_axial_kgm2: 0.001,
            adapter_mass_kg: 0.1,
            ..sar_estimator::inertial::RodInertia::slender_rod(&example_estimator_config().profile)
        },
        ..example_estimator_config()
    };
    let mut estimator = Estimator::new(&config, Vector3::new(0.4, -1.1, 0.25)).unwrap();
    // d = 0: the slender rod's closed form, beside it.
    let mut slender = Estimator::new(&example_estimator_config(), Vector3::zeros()).unwrap();
    let mut seen = [false; 5];
    let mut estimates = 0u32;
    let (_, allocations) = allocations_in(|| {
        for (i, input) in inputs.iter_mut().enumerate() {
            // After a Stop or Fault the next cycle carries a reset.
            if estimator.last().guard_state.is_halting() && input.command.is_none() {
                input.command = Some(Command::Reset);
            }
            // The carriage in motion, every cycle a different one.
            let phase = i as f64 * 0.01;
            let motion = sar_estimator::motion::CarriageMotion {
                velocity_mps: Vector3::new(0.02 * phase.cos(), 0.01, -0.01),
                accel_mps2: Vector3::new(2.0 * phase.sin(), -0.5, 1.0 * phase.cos()),
                accel_std_mps2: 0.1,
            };
            let in_motion = CycleContext {
                motion,
                ..CycleContext::AT_REST
            };
            slender.cycle(input, &in_motion);
            let out = estimator.cycle(input, &in_motion);
            if let sar_estimator::cycle::TipOutcome::Estimate(e) = out.tip {
                estimates += 1;
                assert!(out.torque.is_some());
                assert!(e.torsion_nm != 0.0 || e.ujoint_force_n.norm() == 0.0);
            }
            seen[usize::from(out.guard_state.code())] = true;
        }
    });
    assert_eq!(allocations, 0, "the per-cycle path allocated");
    assert_eq!(
        seen[..4],
        [true; 4],
        "the script must visit every guard state"
    );
    assert!(estimates > 19_000, "{estimates} estimates");
}
