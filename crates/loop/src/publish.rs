//! The loop's side of the shared-memory payloads (`sar_msgs::wire`): a
//! cycle's input, decision and statistics as a [`StateMsg`] (the cycle's
//! state flattened once, [`cycle_state`], for shared memory and for the
//! recording), a [`Reply`] as a [`ReplyMsg`]. The payloads themselves know
//! nothing of the loop. (An operator's `CommandMsg` is decoded by the
//! command table, `sar_msgs::command::decode`.)

use crate::reply::Reply;
use crate::stats::LoopStats;
use crate::step::{LoopInput, LoopOutput, reason_code};
use sar_estimator::Vec3;
use sar_estimator::cycle::{CycleInput, CycleOutput, TipOutcome};
use sar_hal::{DriveState, WrenchSample};
use sar_msgs::msgs::TipOutcomeCode;
use sar_msgs::wire::{
    ReplyMsg, STATE_SENSOR_SAMPLES, StateMsg, drive_code, flags, guard_state_code, reason_bytes,
};

// Every sample the loop drains in a cycle fits a state.
const _: () = assert!(crate::control::DRAIN_CAPACITY <= STATE_SENSOR_SAMPLES);

fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// The drives' state as the wire's code ([`drive_code`]; `None`: not read
/// in this cycle).
pub fn drive_state_code(s: Option<DriveState>) -> u32 {
    match s {
        None => drive_code::UNREAD,
        Some(DriveState::Ready) => drive_code::READY,
        Some(DriveState::Enabled) => drive_code::ENABLED,
        Some(DriveState::QuickStop) => drive_code::QUICK_STOP,
        Some(DriveState::Fault { .. }) => drive_code::FAULT,
    }
}

/// Everything a [`StateMsg`] is made from.
#[derive(Debug, Clone, Copy)]
pub struct StateParts<'a> {
    /// The cycle's input (stamps, joints, the drives' state).
    pub input: &'a LoopInput,
    /// The cycle's decision (the estimator's output, the limits in use).
    pub decision: &'a LoopOutput,
    /// The loop's measurements.
    pub stats: &'a LoopStats,
    /// Quick stops so far.
    pub quick_stops: u64,
    /// Messages the recorder dropped so far.
    pub recorder_drops: u64,
    /// The recording's state (`sar_msgs::wire::recording_code`).
    pub recording: u64,
    /// The simulator's truth, when simulated.
    pub truth: Option<SimTruth>,
    /// Every sensor sample received since the previous cycle, oldest first
    /// (`Cycle::sensor_samples`: the recorder's `/sar/sensor/wrench`).
    pub sensor_samples: &'a [WrenchSample],
}

/// What the simulator says is true at the moment a cycle is published.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimTruth {
    /// The true F_tip, N.
    pub tip_force_n: Vec3,
    /// The support's friction on the rod, N: `tip_force_n` less it is what
    /// the estimator can see (its model has no friction term), the
    /// reference recorded on `/sar/sim/tip_wrench_truth`.
    pub friction_force_n: Vec3,
    /// The simulator's time, ns from its start (the scenario's time axis).
    pub elapsed_ns: u64,
}

/// Asked once per published cycle on the loop's thread, when simulated.
pub type SimTruthFn = Box<dyn FnMut() -> Option<SimTruth>>;

/// One cycle as published: [`cycle_state`] of its estimator's input and
/// output, and what the loop adds (the drives, the limits in use, the
/// loop's measurements and counters, force control, the simulator's truth,
/// the sensor samples drained).
pub fn state_msg(p: &StateParts<'_>) -> StateMsg {
    let mut m = cycle_state(&p.input.cycle_input(), &p.decision.estimate);
    m.drive_state = drive_state_code(p.input.drive_state);
    m.limits_n = p.decision.limits.to_array();
    add_stats(&mut m, p);
    add_force_control(&mut m, p.decision);
    add_inertia(&mut m, p.decision);
    add_servo_fit(&mut m, p.decision);
    if let Some(t) = p.truth {
        add_truth(&mut m, &t);
    }
    add_sensor_samples(&mut m, p.sensor_samples);
    m
}

/// The cycle's state, flattened once for shared memory and the recording:
/// what the estimator's input and output of one cycle say (stamps, ages,
/// joints, the guard's state and reasons whole, the pose, the estimate, the
/// filter, the inputs' validity, the outcome, the transition). The
/// recording's messages of the cycle are made of it
/// (`sar_scene::topics::outputs`, used by `sar_record::convert` and by the
/// live view alike); the loop's parts are zero.
pub fn cycle_state(input: &CycleInput, o: &CycleOutput) -> StateMsg {
    let mut m = StateMsg {
        cycle: o.cycle,
        now_ns: input.now_ns.unwrap_or(0),
        sensor_stamp_ns: input.sensor.stamp_ns,
        joints_stamp_ns: input.joints.stamp_ns,
        sensor_age_ns: o.sensor_age_ns.unwrap_or(u64::MAX),
        joints_age_ns: o.joints_age_ns.unwrap_or(u64::MAX),
        q_m: [
            input.joints.joints.q1_m,
            input.joints.joints.q2_m,
            input.joints.joints.q3_m,
        ],
        guard_state: guard_state_code(o.guard_state),
        guard_reason: u32::from(reason_code(&o.guard_reason)),
        ..StateMsg::default()
    };
    add_pose(&mut m, o);
    add_estimate(&mut m, o);
    if o.new_sample {
        m.flags |= flags::NEW_SAMPLE;
    }
    // Halted: the guard's Stop or Fault (quick-stopped or never released).
    if o.guard_state.is_halting() {
        m.flags |= flags::HALTED;
    }
    add_recorded(&mut m, input, o);
    m
}

/// The simulator's truth in a state (`flags::SIM_TRUTH`).
pub fn add_truth(m: &mut StateMsg, t: &SimTruth) {
    m.flags |= flags::SIM_TRUTH;
    m.truth_tip_force_n = arr(&t.tip_force_n);
    m.truth_friction_n = arr(&t.friction_force_n);
    m.truth_elapsed_ns = t.elapsed_ns;
}

/// The recording's `TIP_*` code of a tip outcome (the recorder's and the
/// published state's one mapping).
pub fn tip_outcome_code(tip: &TipOutcome) -> TipOutcomeCode {
    match tip {
        TipOutcome::Estimate(_) => TipOutcomeCode::Estimate,
        TipOutcome::Refused(_) => TipOutcomeCode::Refused,
        TipOutcome::PoseInvalid(_) => TipOutcomeCode::PoseInvalid,
        TipOutcome::SensorInvalid => TipOutcomeCode::SensorInvalid,
        TipOutcome::JointsInvalid => TipOutcomeCode::JointsInvalid,
    }
}

/// What the recorder writes of the cycle beyond the rest of the state: the
/// inputs' validity, the filter, the torsion, the outcome, the reasons
/// whole and the transition.
fn add_recorded(m: &mut StateMsg, i: &CycleInput, o: &CycleOutput) {
    if i.now_ns.is_some() {
        m.flags |= flags::NOW;
    }
    if i.sensor.valid {
        m.flags |= flags::SENSOR_VALID;
    }
    if i.joints.valid {
        m.flags |= flags::JOINTS_VALID;
    }
    if let Some(f) = o.filtered {
        m.flags |= flags::FILTERED;
        m.tip_force_filtered_n = arr(&f.force_n);
    }
    if let TipOutcome::Estimate(e) = o.tip {
        m.torsion_nm = e.torsion_nm;
    }
    m.tip_outcome = u32::from(tip_outcome_code(&o.tip).code());
    m.guard_reason_bytes = reason_bytes(&o.guard_reason);
    if let Some(t) = o.transition {
        m.flags |= flags::TRANSITION;
        m.transition_cycle = t.cycle;
        m.transition_from = guard_state_code(t.from);
        m.transition_to = guard_state_code(t.to);
        m.transition_reason_bytes = reason_bytes(&t.reason);
    }
}

/// Every sensor sample received since the previous cycle (the recorder's
/// `/sar/sensor/wrench`), up to [`STATE_SENSOR_SAMPLES`].
fn add_sensor_samples(m: &mut StateMsg, samples: &[WrenchSample]) {
    let mut n = 0;
    for (k, s) in samples.iter().take(STATE_SENSOR_SAMPLES).enumerate() {
        if let (Some(stamp), Some(force), Some(torque)) = (
            m.sensor_received_ns.get_mut(k),
            m.sensor_force_n.get_mut(k),
            m.sensor_torque_nm.get_mut(k),
        ) {
            *stamp = s.received_ns;
            *force = arr(&s.force_n);
            *torque = arr(&s.torque_nm);
            n += 1;
        }
    }
    m.sensor_samples = n;
}

/// The loop's measurements and counters.
fn add_stats(m: &mut StateMsg, p: &StateParts<'_>) {
    m.wakeup_ns = [
        p.stats.wakeup.quantile_ns(0.5),
        p.stats.wakeup.quantile_ns(0.99),
        p.stats.wakeup.max_ns(),
    ];
    m.compute_ns = [
        p.stats.compute.quantile_ns(0.5),
        p.stats.compute.quantile_ns(0.99),
        p.stats.compute.max_ns(),
    ];
    m.overruns = p.stats.overruns;
    m.quick_stops = p.quick_stops;
    m.recorder_drops = p.recorder_drops;
    m.recording = p.recording;
}

/// The pose, when there is one.
fn add_pose(m: &mut StateMsg, o: &CycleOutput) {
    if let Some(pose) = o.pose {
        m.flags |= flags::POSE;
        m.q45_rad = [pose.q4_rad(), pose.q5_rad()];
        m.ujoint_m = arr(&pose.ujoint_m);
        m.tip_m = arr(&pose.tip_m);
        m.support_distance_m = pose.support_distance_m;
    }
}

/// The tip-force estimate, when there is one.
fn add_estimate(m: &mut StateMsg, o: &CycleOutput) {
    if let TipOutcome::Estimate(e) = o.tip {
        m.flags |= flags::ESTIMATE;
        if e.observable {
            m.flags |= flags::OBSERVABLE;
        }
        m.ujoint_force_n = arr(&e.ujoint_force_n);
        m.tip_force_n = arr(&e.force_n);
        m.tip_std_n = arr(&e.std_n);
        m.tip_axial_lateral_n = [e.axial_n, e.lateral_n];
    }
}

/// Force control: the mode and its setpoint, and the last guarded move's
/// stop.
fn add_force_control(m: &mut StateMsg, decision: &LoopOutput) {
    match decision.force_mode {
        Some(sar_estimator::force_control::ForceMode::Hold { max_force_n }) => {
            m.force_mode = sar_msgs::wire::force_mode::HOLD;
            m.force_setpoint_n = max_force_n;
        }
        Some(sar_estimator::force_control::ForceMode::Push { axial_n }) => {
            m.force_mode = sar_msgs::wire::force_mode::PUSH;
            m.force_setpoint_n = axial_n;
        }
        None => {}
    }
    if let Some(g) = decision.guarded_stop {
        m.guarded_stop_cycle = g.cycle;
        m.guarded_stop_tip_m = arr(&g.tip_m);
        m.guarded_stop_force_n = arr(&g.force_n);
    }
    let s = &decision.support;
    m.support_shift_m = arr(&s.shift_m);
    m.support_std_m = arr(&s.std_m);
    m.support_verdict = s.verdict.code();
    m.support_chi2_dof = s.chi2_dof;
    m.support_samples = s.samples;
    m.support_limits_m = [decision.support_limits_m.0, decision.support_limits_m.1];
}

/// The inertia watch's verdict (issue 34).
fn add_inertia(m: &mut StateMsg, decision: &LoopOutput) {
    let v = &decision.inertia;
    m.inertia_named = v.named.code();
    m.inertia_implied = [
        v.inertia_perp_kgm2,
        v.inertia_perp_std_kgm2,
        v.adapter_mass_kg,
        v.adapter_mass_std_kg,
    ];
}

/// How far the axes follow the servo model (issue 34).
fn add_servo_fit(m: &mut StateMsg, decision: &LoopOutput) {
    let fit = &decision.servo_fit;
    m.servo_follow_rms_m = fit.follow_rms_per_axis_m();
    m.servo_disturbance_mps2 = fit.disturbance_mps2;
    let mut bits = 0;
    if fit.named {
        bits |= sar_msgs::wire::servo_fit::NAMED;
    }
    for (i, engaged) in fit.engaged.iter().enumerate() {
        if *engaged {
            bits |= sar_msgs::wire::servo_fit::ENGAGED_Q1 << i;
        }
    }
    m.servo_fit = bits;
}

/// The reply as published, with the guard's limits.
pub fn reply_msg(r: &Reply, limits_n: [f64; 6]) -> ReplyMsg {
    ReplyMsg::with_detail(
        r.id,
        r.cycle,
        r.status as u32,
        u32::from(r.reason),
        limits_n,
        format_args!("{}", r.detail),
    )
}
