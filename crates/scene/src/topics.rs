//! The recordings' messages (INTERFACES.md 1) made from the published state,
//! so that the live view and the ROS 2 bridge (`sar-ros2`) carry the same
//! topics, types, encodings and values as a recording of the same cycle.
//!
//! A published state holds what the recorder writes of its cycle
//! (`sar_msgs::wire::StateMsg`: the inputs' validity, the filter, the
//! torsion, the outcome, the guard's reasons whole, the transition and every
//! sensor sample received), so [`messages`] gives the recorder's messages of
//! the cycle (`sar_record::convert::cycle_record_samples` and the simulator's
//! truth), bit for bit, in the recorder's order: `/sar/sensor/wrench` (each
//! sample), `/sar/joints` (when new), `/sar/estimate/state`,
//! `/sar/estimate/tip_wrench`, `.../tip_wrench_filtered`,
//! `.../passive_joints`, `/sar/guard/events`, `/sar/sim/tip_wrench_truth`.
//! Only `/sar/cycle/input` (the step's whole input, for replay) is not made.
//!
//! The mapping between the published state's flags and the recording's is
//! one table, [`RECORDED_FLAGS`], read both ways. The cycle's state itself is
//! flattened once, by `sar_loop::publish::cycle_state`; the recorder makes
//! its output messages of that with [`outputs`].
//!
//! The 3D scene of a cycle is drawn from its recorded messages
//! ([`scene_state`]) by the recorder's writer and by `sar-ros2` alike.

use core::fmt::Write as _;
use sar_msgs::msgs::{
    self, ActiveJointState, EstimatorState, GuardEvent, GuardStateCode, Outgoing,
    PassiveJointState, ReasonText, SceneStatus, TipOutcomeCode, WrenchStamped,
};
use sar_msgs::wire::{
    ReasonBytes, STATE_SENSOR_SAMPLES, StateMsg, flags, guard_state_name, reason_name, reason_of,
};

/// The recording's guard state of a wire code (the same numbers; an unknown
/// one is Fault).
pub fn guard_state(code: u32) -> GuardStateCode {
    u8::try_from(code)
        .ok()
        .and_then(|c| GuardStateCode::from_code(c).ok())
        .unwrap_or(GuardStateCode::Fault)
}

/// The recording's reason code of a wire code (one numbering; beyond a byte:
/// `REASON_OTHER`): the guard's [`sar_estimator::guard::recorded_code`].
pub fn reason_code(code: u32) -> u8 {
    sar_estimator::guard::recorded_code(code)
}

fn reason_text(code: u32) -> ReasonText {
    ReasonText::truncating(reason_name(code))
}

/// The sentence of a reason carried whole (the recording's
/// `guard_reason_text`, `reason_text`: its `Display`, cut at the text's
/// size), and its recorded code; a reason that does not read back gives its
/// code's name and `REASON_OTHER`.
fn reason_whole(bytes: &ReasonBytes) -> (u8, ReasonText) {
    let mut text = ReasonText::default();
    match reason_of(bytes) {
        Some(r) => {
            let _ = write!(text, "{r}");
            (r.recorded_code(), text)
        }
        None => (
            sar_estimator::guard::recorded_code(u32::MAX),
            ReasonText::truncating("unknown"),
        ),
    }
}

/// The cycle's stamp as the recorder writes it (its `now`; when the clock
/// could not be read, the newer input stamp: `sar_record::convert::cycle_stamp_ns`).
pub fn cycle_stamp_ns(s: &StateMsg) -> u64 {
    if s.flags & flags::NOW != 0 {
        s.now_ns
    } else {
        s.sensor_stamp_ns.max(s.joints_stamp_ns)
    }
}

/// The published state's flags and the recording's `EstimatorState` flags
/// they are (`sar_msgs::wire::flags` -> `sar_msgs::msgs::flags`): the one
/// mapping, both ways ([`recorded_flags`], [`state_flags`]). The
/// recording's `CLOCK_ADVANCES` has no flag of its own on the wire: it is a
/// known sensor age.
pub const RECORDED_FLAGS: [(u32, u32); 6] = [
    (flags::POSE, msgs::flags::POSE_VALID),
    (flags::ESTIMATE, msgs::flags::TIP_VALID),
    (flags::OBSERVABLE, msgs::flags::OBSERVABLE),
    (flags::FILTERED, msgs::flags::FILTERED_VALID),
    (flags::SENSOR_VALID, msgs::flags::SENSOR_VALID),
    (flags::JOINTS_VALID, msgs::flags::JOINTS_VALID),
];

/// The recording's flags of a published state's ([`RECORDED_FLAGS`]; an
/// estimate's observability only with the estimate, and `CLOCK_ADVANCES`
/// when the sensor's age is known).
pub fn recorded_flags(s: &StateMsg) -> u32 {
    let mut wire = s.flags;
    if wire & flags::ESTIMATE == 0 {
        wire &= !flags::OBSERVABLE;
    }
    let mut f = map_flags(wire, RECORDED_FLAGS);
    if s.sensor_age_ns != u64::MAX {
        f |= msgs::flags::CLOCK_ADVANCES;
    }
    f
}

/// The published state's flags of a recording's ([`RECORDED_FLAGS`], the
/// inverse of [`recorded_flags`]).
pub fn state_flags(recorded: u32) -> u32 {
    map_flags(recorded, RECORDED_FLAGS.map(|(w, r)| (r, w)))
}

/// The flags of `to` whose `from` is set in `bits`.
fn map_flags(bits: u32, pairs: [(u32, u32); 6]) -> u32 {
    pairs
        .iter()
        .filter(|(from, _)| bits & from != 0)
        .fold(0, |f, (_, to)| f | to)
}

/// `/sar/estimate/state` of a published state: the recorder's message of
/// the cycle.
pub fn estimator_state(s: &StateMsg) -> EstimatorState {
    let mut m = EstimatorState {
        stamp_ns: cycle_stamp_ns(s),
        cycle: s.cycle,
        now_ns: s.now_ns,
        sensor_stamp_ns: s.sensor_stamp_ns,
        joints_stamp_ns: s.joints_stamp_ns,
        sensor_age_ns: s.sensor_age_ns,
        joints_age_ns: s.joints_age_ns,
        guard_state: guard_state(s.guard_state),
        flags: recorded_flags(s),
        ..EstimatorState::default()
    };
    (m.guard_reason_code, m.guard_reason_text) = reason_whole(&s.guard_reason_bytes);
    m.tip_outcome = u8::try_from(s.tip_outcome)
        .ok()
        .and_then(|c| TipOutcomeCode::from_code(c).ok())
        .unwrap_or(TipOutcomeCode::Refused);
    if s.flags & flags::POSE != 0 {
        m.ujoint_m = s.ujoint_m;
        m.tip_m = s.tip_m;
        m.support_distance_m = s.support_distance_m;
    }
    if s.flags & flags::ESTIMATE != 0 {
        m.ujoint_force_n = s.ujoint_force_n;
        m.tip_force_n = s.tip_force_n;
        m.tip_force_std_n = s.tip_std_n;
        m.axial_n = s.tip_axial_lateral_n[0];
        m.lateral_n = s.tip_axial_lateral_n[1];
        m.torsion_nm = s.torsion_nm;
    }
    if s.flags & flags::FILTERED != 0 {
        m.tip_force_filtered_n = s.tip_force_filtered_n;
    }
    m
}

/// The messages of one published state, in the recorder's order, into `out`
/// (cleared first). `previous` is the state received before it: the joints
/// are written when their stamp changed since (the recorder's rule; every
/// time without one).
pub fn messages(s: &StateMsg, previous: Option<&StateMsg>, out: &mut Vec<Outgoing>) {
    out.clear();
    let samples = usize::try_from(s.sensor_samples)
        .unwrap_or(STATE_SENSOR_SAMPLES)
        .min(STATE_SENSOR_SAMPLES);
    for k in 0..samples {
        if let (Some(stamp), Some(force), Some(torque)) = (
            s.sensor_received_ns.get(k),
            s.sensor_force_n.get(k),
            s.sensor_torque_nm.get(k),
        ) {
            out.push(Outgoing::SensorWrench(WrenchStamped::sensor(
                *stamp, *force, *torque,
            )));
        }
    }
    if previous.is_none_or(|p| p.joints_stamp_ns != s.joints_stamp_ns) {
        out.push(Outgoing::Joints(ActiveJointState {
            stamp_ns: s.joints_stamp_ns,
            q_m: s.q_m,
        }));
    }
    outputs(s, |m| out.push(m));
    out.extend(sim_truth(s));
}

/// The estimator's output messages of one cycle's state, in the recorder's
/// fixed order (state, tip wrench, filtered, passive joints, guard event),
/// each handed to `emit`: the recorder's (`sar_record::convert::outputs`,
/// of `sar_loop::publish::cycle_state`) and the live view's one mapping.
pub fn outputs(s: &StateMsg, mut emit: impl FnMut(Outgoing)) {
    let stamp_ns = cycle_stamp_ns(s);
    emit(Outgoing::EstimatorState(estimator_state(s)));
    if s.flags & flags::ESTIMATE != 0 {
        emit(Outgoing::TipWrench(WrenchStamped::base_force(
            stamp_ns,
            s.tip_force_n,
        )));
    }
    if s.flags & flags::FILTERED != 0 {
        emit(Outgoing::TipWrenchFiltered(WrenchStamped::base_force(
            stamp_ns,
            s.tip_force_filtered_n,
        )));
    }
    if s.flags & flags::POSE != 0 {
        emit(Outgoing::PassiveJoints(PassiveJointState {
            stamp_ns,
            q_rad: s.q45_rad,
        }));
    }
    if s.flags & flags::TRANSITION != 0 {
        let (reason_code, reason_text) = reason_whole(&s.transition_reason_bytes);
        emit(Outgoing::GuardEvent(GuardEvent {
            stamp_ns,
            cycle: s.transition_cycle,
            from_state: guard_state(s.transition_from),
            to_state: guard_state(s.transition_to),
            reason_code,
            reason_text,
        }));
    }
}

/// `/sar/sim/tip_wrench_truth` of a state: the simulator's visible truth
/// (the true tip force less the support's friction) with every new sample,
/// as recorded; `None` otherwise.
pub fn sim_truth(s: &StateMsg) -> Option<Outgoing> {
    (s.flags & flags::SIM_TRUTH != 0 && s.flags & flags::NEW_SAMPLE != 0).then(|| {
        let [t, f] = [s.truth_tip_force_n, s.truth_friction_n];
        Outgoing::SimTruth(WrenchStamped::base_force(
            cycle_stamp_ns(s),
            [t[0] - f[0], t[1] - f[1], t[2] - f[2]],
        ))
    })
}

/// What the scene of a cycle is drawn from, as the recorder's writer gathers
/// it from the cycle's recorded messages: `/sar/estimate/state`,
/// `/sar/estimate/passive_joints`, the joints of `/sar/cycle/input` (or
/// `/sar/joints`), the limits in use, `/sar/sim/tip_wrench_truth`. The
/// recorder and `sar-ros2` both draw from [`scene_state`] of it, so a live
/// scene equals the recorded one of the same cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneInput {
    /// The cycle's `/sar/estimate/state`.
    pub estimator: EstimatorState,
    /// Its `/sar/estimate/passive_joints`, if any.
    pub passive: Option<PassiveJointState>,
    /// The last joints, m.
    pub q_m: [f64; 3],
    /// The limits in use (the last valid ones: [`valid_limits`]).
    pub limits_n: [f64; 6],
    /// Its `/sar/sim/tip_wrench_truth`, N, if any.
    pub truth_n: Option<[f64; 3]>,
}

/// Whether `limits_n` are limits in use (every one a positive number); the
/// scene keeps the last such.
pub fn valid_limits(limits_n: &[f64; 6]) -> bool {
    limits_n.iter().all(|v| v.is_finite() && *v > 0.0)
}

/// The state the scene of a cycle is drawn from ([`SceneInput`]).
pub fn scene_state(i: &SceneInput) -> StateMsg {
    let joints = ActiveJointState {
        stamp_ns: i.estimator.joints_stamp_ns,
        q_m: i.q_m,
    };
    let mut s = state_from_recorded(&i.estimator, &joints, i.passive.as_ref(), i.limits_n);
    if let Some(truth_n) = i.truth_n {
        s.truth_tip_force_n = truth_n;
        s.flags |= flags::SIM_TRUTH;
    }
    s
}

/// A state for the scene (`draw::scene`) from the recorded messages of one
/// cycle (the inverse of [`outputs`] for every field and flag the
/// recording's state carries, [`state_flags`]; the guard's reason as its
/// code, not whole): the
/// recorder, which holds `EstimatorState`, the joints and the passive
/// joints rather than the published state, draws the same scene with it.
/// `limits_n` are the guard's (`ForceLimits::to_array`), which the recordings
/// do not carry per cycle.
pub fn state_from_recorded(
    est: &EstimatorState,
    joints: &ActiveJointState,
    passive: Option<&PassiveJointState>,
    limits_n: [f64; 6],
) -> StateMsg {
    let mut f = state_flags(est.flags);
    if passive.is_none() {
        f &= !flags::POSE;
    }
    StateMsg {
        cycle: est.cycle,
        now_ns: est.now_ns,
        sensor_stamp_ns: est.sensor_stamp_ns,
        joints_stamp_ns: est.joints_stamp_ns,
        sensor_age_ns: est.sensor_age_ns,
        joints_age_ns: est.joints_age_ns,
        q_m: joints.q_m,
        q45_rad: passive.map_or([0.0; 2], |p| p.q_rad),
        ujoint_m: est.ujoint_m,
        tip_m: est.tip_m,
        support_distance_m: est.support_distance_m,
        ujoint_force_n: est.ujoint_force_n,
        tip_force_n: est.tip_force_n,
        tip_std_n: est.tip_force_std_n,
        tip_axial_lateral_n: [est.axial_n, est.lateral_n],
        torsion_nm: est.torsion_nm,
        tip_force_filtered_n: est.tip_force_filtered_n,
        flags: f,
        guard_state: u32::from(est.guard_state.code()),
        guard_reason: u32::from(est.guard_reason_code),
        limits_n,
        ..StateMsg::default()
    }
}

/// `/sar/scene/status` of a published state: the guard's state and reason,
/// |F_tip| and its axial and lateral parts (NaN without an estimate), the
/// limits in use, and the simulator's truth (NaN without one).
pub fn scene_status(s: &StateMsg) -> SceneStatus {
    let estimate = s.flags & flags::ESTIMATE != 0;
    let or_nan = |v: f64| if estimate { v } else { f64::NAN };
    let f = s.tip_force_n;
    // The wire's order of the six limits is the estimator's (one home).
    let limits = sar_estimator::guard::ForceLimits::from_array(s.limits_n);
    SceneStatus {
        stamp_ns: s.now_ns,
        cycle: s.cycle,
        guard_state: guard_state(s.guard_state),
        guard: ReasonText::truncating(guard_state_name(s.guard_state)),
        reason: reason_text(s.guard_reason),
        force_total_n: or_nan((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt()),
        axial_n: or_nan(s.tip_axial_lateral_n[0]),
        lateral_n: or_nan(s.tip_axial_lateral_n[1]),
        warn_total_n: limits.warn_total_n,
        stop_total_n: limits.stop_total_n,
        warn_axial_n: limits.warn_axial_n,
        stop_axial_n: limits.stop_axial_n,
        warn_lateral_n: limits.warn_lateral_n,
        stop_lateral_n: limits.stop_lateral_n,
        truth_tip_force_n: if s.flags & flags::SIM_TRUTH != 0 {
            s.truth_tip_force_n
        } else {
            [f64::NAN; 3]
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every subset of the mapped flags crosses to the recording and back
    /// whole, each to its own recorded flag; observability only with an
    /// estimate; `CLOCK_ADVANCES` from a known sensor age alone.
    #[test]
    fn the_flag_mapping_reads_both_ways() {
        let wire_all = RECORDED_FLAGS.iter().fold(0, |f, (w, _)| f | w);
        let recorded_all = RECORDED_FLAGS.iter().fold(0, |f, (_, r)| f | r);
        assert_eq!(wire_all.count_ones(), 6);
        assert_eq!(recorded_all.count_ones(), 6);
        assert_eq!(recorded_all & msgs::flags::CLOCK_ADVANCES, 0);
        for bits in 0..64u32 {
            let wire = RECORDED_FLAGS
                .iter()
                .enumerate()
                .filter(|(k, _)| bits & (1 << k) != 0)
                .fold(0, |f, (_, (w, _))| f | w);
            let s = StateMsg {
                flags: wire | flags::NEW_SAMPLE,
                sensor_age_ns: u64::from(bits),
                ..StateMsg::default()
            };
            let recorded = recorded_flags(&s);
            assert_ne!(recorded & msgs::flags::CLOCK_ADVANCES, 0, "{bits}");
            let expected = if wire & flags::ESTIMATE == 0 {
                wire & !flags::OBSERVABLE
            } else {
                wire
            };
            assert_eq!(state_flags(recorded), expected, "{bits:#b}");
        }
        let unknown_age = StateMsg {
            sensor_age_ns: u64::MAX,
            ..StateMsg::default()
        };
        assert_eq!(recorded_flags(&unknown_age), 0);
    }
}
