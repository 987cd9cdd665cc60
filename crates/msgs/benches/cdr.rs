//! Criterion benchmarks of the recorded messages' CDR decoding and encoding:
//! `decode/*` decodes one message of each fixed-size type from its bytes
//! (`cycle_input` is the replay's hot path: one per cycle), `encode/*` writes
//! one into a reused buffer (the recorder's path).
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use sar_msgs::msgs::*;
use std::hint::black_box;

fn cycle_input() -> CycleInput {
    CycleInput {
        stamp_ns: 1_234_567_890_123,
        cycle: 42,
        now_ns: 1_234_567_890_123,
        clock_status: ClockStatusCode::Ok,
        sensor_force_n: [0.1, -0.2, 0.3],
        sensor_torque_nm: [0.01, 0.02, -0.03],
        sensor_counter: 7,
        sensor_status: 0,
        sensor_stamp_ns: 1_234_567_800_000,
        sensor_valid: true,
        joints_q_m: [0.02, 0.25, 0.31],
        joints_stamp_ns: 1_234_567_770_000,
        joints_valid: true,
        drive_state: DriveStateCode::Enabled,
        drive_fault_axis: -1,
        drive_fault_code: 0,
        target_q_m: [0.02, 0.25, 0.31],
        target_valid: true,
        command_kind: CommandKindCode::None,
        command_values: [0.0; 6],
        command_arg: 0,
        move_tip_m: [0.0; 3],
        limits_n: [0.0; 6],
        drive_action: DriveActionCode::Stream,
        setpoint_q_m: [0.02, 0.25, 0.31],
        reply_status: REPLY_NONE,
        reply_reason: 0,
        limits_in_use_n: [1.0, 2.0, 1.0, 2.0, 0.5, 1.0],
        publisher_idle_ns: 1_000,
        back_out_m: 0.0,
        move_max_force_n: 0.0,
        sensor_drained_counted: true,
        sensor_drained_samples: 1,
        sensor_drained_jumps: 0,
        command_layout: CommandLayoutCode::Old,
        hold_max_force_n: 0.0,
        push_axial_n: 0.0,
        excite_amplitude_m: [0.0; 3],
        excite_freq_hz: [0.0; 3],
        excite_duration_s: 0.0,
        excite_fade_s: 0.0,
    }
}

fn estimator_state() -> EstimatorState {
    EstimatorState {
        stamp_ns: 1_234_567_890_123,
        cycle: 42,
        now_ns: 1_234_567_890_123,
        tip_outcome: TipOutcomeCode::Estimate,
        tip_force_n: [0.1, 0.2, 0.3],
        guard_state: GuardStateCode::Warn,
        guard_reason_code: 22,
        guard_reason_text: ReasonText::truncating("above warn: 1.2 N"),
        flags: 127,
        ..EstimatorState::default()
    }
}

fn encoded<M: RosMessage>(m: &M) -> Vec<u8> {
    let mut buf = Vec::new();
    m.encode(&mut buf).unwrap();
    buf
}

fn bench(c: &mut Criterion) {
    let ci = encoded(&cycle_input());
    let es = encoded(&estimator_state());
    let ws = encoded(&WrenchStamped::sensor(5, [1.0, 2.0, 3.0], [0.1, 0.2, 0.3]));
    let aj = encoded(&ActiveJointState {
        stamp_ns: 5,
        q_m: [0.02, 0.25, 0.31],
    });
    let mut g = c.benchmark_group("decode");
    g.bench_function("cycle_input", |b| {
        b.iter(|| CycleInput::decode(black_box(&ci)))
    });
    g.bench_function("estimator_state", |b| {
        b.iter(|| EstimatorState::decode(black_box(&es)))
    });
    g.bench_function("wrench_stamped", |b| {
        b.iter(|| WrenchStamped::decode(black_box(&ws)))
    });
    g.bench_function("active_joint_state", |b| {
        b.iter(|| ActiveJointState::decode(black_box(&aj)))
    });
    g.finish();
    let mut g = c.benchmark_group("encode");
    let m = cycle_input();
    let mut buf = Vec::with_capacity(1024);
    g.bench_function("cycle_input", |b| b.iter(|| black_box(&m).encode(&mut buf)));
    let m = estimator_state();
    g.bench_function("estimator_state", |b| {
        b.iter(|| black_box(&m).encode(&mut buf))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
