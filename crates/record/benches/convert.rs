//! Criterion benchmark of the recorder's conversion of a cycle's outputs, on
//! the loop's thread (`LiveRecorder` pushes them every cycle): `outputs` is
//! `sar_record::convert::outputs` (the cycle's state flattened once by
//! `sar_loop::publish::cycle_state`, made into messages by
//! `sar_scene::topics::outputs`, as the live view makes them); `direct` is
//! the baseline, the recorder's own flattening into `EstimatorState` before
//! issue 36 (copied here for the comparison only); `cycle_state` is the
//! flattening alone. Over 2,000 cycles of the demo with a 20 N push (Warn,
//! Stop, their transitions), each message handed to `black_box`.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use core::fmt::Write as _;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sar_estimator::Vec3;
use sar_estimator::cycle::{CycleInput, CycleOutput, TipOutcome};
use sar_estimator::guard::GuardState;
use sar_loop::sink::Cycle;
use sar_loop::stats::LoopStats;
use sar_msgs::msgs::{
    EstimatorState, GuardEvent, GuardStateCode, Outgoing, PassiveJointState, ReasonText,
    WrenchStamped, flags,
};
use sar_record::convert;
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};
use std::hint::black_box;

/// Cycles of the demo run before the ones measured, and measured.
const SKIP: u64 = 1_000;
const CYCLES: u64 = 2_000;

/// The cycles' estimator inputs and outputs.
fn cycles() -> Vec<(CycleInput, CycleOutput)> {
    let SimRig { mut c, clock, .. } = RigBuilder::demo(rod_push_20n([
        1_200_000_000,
        1_600_000_000,
        2_000_000_000,
        2_400_000_000,
    ]))
    .build();
    let stats = LoopStats::default();
    let mut out = Vec::new();
    for cycle in 1..=SKIP + CYCLES {
        clock.advance_ns(1_000_000);
        c.step(cycle, || Some(clock.now_ns()));
        if cycle > SKIP {
            let cyc = Cycle::of(&c, &stats, None);
            out.push((cyc.loop_input.cycle_input(), cyc.decision.estimate));
        }
    }
    out
}

fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn guard_code(s: GuardState) -> GuardStateCode {
    match s {
        GuardState::Ok => GuardStateCode::Ok,
        GuardState::Warn => GuardStateCode::Warn,
        GuardState::Stop => GuardStateCode::Stop,
        GuardState::Fault => GuardStateCode::Fault,
        GuardState::Retreat => GuardStateCode::Retreat,
    }
}

/// The recorder's `/sar/estimate/state` before issue 36.
fn direct_state(input: &CycleInput, o: &CycleOutput) -> EstimatorState {
    let mut reason_text = ReasonText::default();
    let _ = write!(reason_text, "{}", o.guard_reason);
    let mut m = EstimatorState {
        stamp_ns: convert::cycle_stamp_ns(input),
        cycle: o.cycle,
        now_ns: input.now_ns.unwrap_or(0),
        sensor_stamp_ns: input.sensor.stamp_ns,
        joints_stamp_ns: input.joints.stamp_ns,
        sensor_age_ns: o.sensor_age_ns.unwrap_or(u64::MAX),
        joints_age_ns: o.joints_age_ns.unwrap_or(u64::MAX),
        guard_state: guard_code(o.guard_state),
        guard_reason_code: o.guard_reason.recorded_code(),
        guard_reason_text: reason_text,
        ..EstimatorState::default()
    };
    m.tip_outcome = sar_loop::publish::tip_outcome_code(&o.tip);
    if let Some(pose) = o.pose {
        m.flags |= flags::POSE_VALID;
        m.ujoint_m = arr(&pose.ujoint_m);
        m.tip_m = arr(&pose.tip_m);
        m.support_distance_m = pose.support_distance_m;
    }
    if let TipOutcome::Estimate(e) = o.tip {
        m.flags |= flags::TIP_VALID;
        if e.observable {
            m.flags |= flags::OBSERVABLE;
        }
        m.ujoint_force_n = arr(&e.ujoint_force_n);
        m.tip_force_n = arr(&e.force_n);
        m.tip_force_std_n = arr(&e.std_n);
        m.axial_n = e.axial_n;
        m.lateral_n = e.lateral_n;
        m.torsion_nm = e.torsion_nm;
    }
    if let Some(f) = o.filtered {
        m.flags |= flags::FILTERED_VALID;
        m.tip_force_filtered_n = arr(&f.force_n);
    }
    if input.sensor.valid {
        m.flags |= flags::SENSOR_VALID;
    }
    if input.joints.valid {
        m.flags |= flags::JOINTS_VALID;
    }
    if o.sensor_age_ns.is_some() {
        m.flags |= flags::CLOCK_ADVANCES;
    }
    m
}

/// The recorder's outputs before issue 36.
fn direct(input: &CycleInput, output: &CycleOutput, mut emit: impl FnMut(Outgoing)) {
    let stamp_ns = convert::cycle_stamp_ns(input);
    emit(Outgoing::EstimatorState(direct_state(input, output)));
    if let TipOutcome::Estimate(e) = output.tip {
        emit(Outgoing::TipWrench(WrenchStamped::base_force(
            stamp_ns,
            arr(&e.force_n),
        )));
    }
    if let Some(f) = output.filtered {
        emit(Outgoing::TipWrenchFiltered(WrenchStamped::base_force(
            stamp_ns,
            arr(&f.force_n),
        )));
    }
    if let Some(pose) = output.pose {
        emit(Outgoing::PassiveJoints(PassiveJointState {
            stamp_ns,
            q_rad: [pose.q4_rad(), pose.q5_rad()],
        }));
    }
    if let Some(t) = output.transition {
        let mut reason_text = ReasonText::default();
        let _ = write!(reason_text, "{}", t.reason);
        emit(Outgoing::GuardEvent(GuardEvent {
            stamp_ns,
            cycle: t.cycle,
            from_state: guard_code(t.from),
            to_state: guard_code(t.to),
            reason_code: t.reason.recorded_code(),
            reason_text,
        }));
    }
}

fn convert_bench(c: &mut Criterion) {
    let cycles = cycles();
    // What the comparison rests on: both give the same messages.
    for (input, output) in &cycles {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        convert::outputs(input, output, |m| a.push(m));
        direct(input, output, |m| b.push(m));
        assert_eq!(a, b, "cycle {}", output.cycle);
    }
    assert!(cycles.iter().any(|(_, o)| o.transition.is_some()));
    let mut g = c.benchmark_group("convert");
    g.throughput(Throughput::Elements(CYCLES));
    g.bench_function("outputs", |b| {
        b.iter(|| {
            for (input, output) in &cycles {
                convert::outputs(input, output, |m| {
                    black_box(m);
                });
            }
        });
    });
    g.bench_function("direct", |b| {
        b.iter(|| {
            for (input, output) in &cycles {
                direct(input, output, |m| {
                    black_box(m);
                });
            }
        });
    });
    g.bench_function("cycle_state", |b| {
        b.iter(|| {
            for (input, output) in &cycles {
                black_box(sar_loop::publish::cycle_state(input, output));
            }
        });
    });
    g.finish();
}

criterion_group!(benches, convert_bench);
criterion_main!(benches);
