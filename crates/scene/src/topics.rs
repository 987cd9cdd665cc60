//! The recordings' messages (INTERFACES.md 1) made from the published state,
//! so that the live view carries the same topics, types and encodings as a
//! recording (one Foxglove layout for both).
//!
//! What the state holds gives `/sar/joints`, `/sar/estimate/tip_wrench`,
//! `/sar/estimate/passive_joints`, `/sar/estimate/state` and
//! `/sar/guard/events` (a transition between two consecutive states the
//! view received). The state does not carry the raw sensor reading, the
//! filtered tip force, the torsion nor the cycle's full input, so
//! `/sar/sensor/wrench`, `/sar/estimate/tip_wrench_filtered` and
//! `/sar/cycle/input` are not served, and in `/sar/estimate/state` the
//! filtered force and the torsion are 0 (flag `FILTERED_VALID` clear) and a
//! cycle without an estimate is `TIP_POSE_INVALID` without a pose, else
//! `TIP_REFUSED` (the state does not say which input was refused).

use sar_msgs::msgs::{
    self, ActiveJointState, EstimatorState, GuardEvent, GuardStateCode, Outgoing,
    PassiveJointState, ReasonText, SceneStatus, TipOutcomeCode, WrenchStamped,
};
use sar_msgs::wire::{StateMsg, flags, guard_state_name, reason_name};

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

/// `/sar/estimate/state` of a published state.
pub fn estimator_state(s: &StateMsg) -> EstimatorState {
    let tip_outcome = if s.flags & flags::ESTIMATE != 0 {
        TipOutcomeCode::Estimate
    } else if s.flags & flags::POSE == 0 {
        TipOutcomeCode::PoseInvalid
    } else {
        TipOutcomeCode::Refused
    };
    let mut f = 0;
    for (wire, rec) in [
        (flags::POSE, msgs::flags::POSE_VALID),
        (flags::ESTIMATE, msgs::flags::TIP_VALID),
        (flags::OBSERVABLE, msgs::flags::OBSERVABLE),
    ] {
        if s.flags & wire != 0 {
            f |= rec;
        }
    }
    EstimatorState {
        stamp_ns: s.now_ns,
        cycle: s.cycle,
        now_ns: s.now_ns,
        sensor_stamp_ns: s.sensor_stamp_ns,
        joints_stamp_ns: s.joints_stamp_ns,
        sensor_age_ns: s.sensor_age_ns,
        joints_age_ns: s.joints_age_ns,
        tip_outcome,
        ujoint_m: s.ujoint_m,
        tip_m: s.tip_m,
        support_distance_m: s.support_distance_m,
        ujoint_force_n: s.ujoint_force_n,
        tip_force_n: s.tip_force_n,
        tip_force_std_n: s.tip_std_n,
        axial_n: s.tip_axial_lateral_n[0],
        lateral_n: s.tip_axial_lateral_n[1],
        torsion_nm: 0.0,
        tip_force_filtered_n: [0.0; 3],
        guard_state: guard_state(s.guard_state),
        guard_reason_code: reason_code(s.guard_reason),
        guard_reason_text: reason_text(s.guard_reason),
        flags: f,
    }
}

/// The messages of one published state, in topic order, into `out`
/// (cleared first). `previous` is the state received before it (for the
/// guard's transitions).
pub fn messages(s: &StateMsg, previous: Option<&StateMsg>, out: &mut Vec<Outgoing>) {
    out.clear();
    out.push(Outgoing::Joints(ActiveJointState {
        stamp_ns: s.joints_stamp_ns,
        q_m: s.q_m,
    }));
    if s.flags & flags::ESTIMATE != 0 {
        out.push(Outgoing::TipWrench(WrenchStamped::base_force(
            s.now_ns,
            s.tip_force_n,
        )));
    }
    if s.flags & flags::POSE != 0 {
        out.push(Outgoing::PassiveJoints(PassiveJointState {
            stamp_ns: s.now_ns,
            q_rad: s.q45_rad,
        }));
    }
    out.push(Outgoing::EstimatorState(estimator_state(s)));
    if let Some(p) = previous
        && p.guard_state != s.guard_state
    {
        out.push(Outgoing::GuardEvent(GuardEvent {
            stamp_ns: s.now_ns,
            cycle: s.cycle,
            from_state: guard_state(p.guard_state),
            to_state: guard_state(s.guard_state),
            reason_code: reason_code(s.guard_reason),
            reason_text: reason_text(s.guard_reason),
        }));
    }
}

/// A state for the scene (`draw::scene`) from the recorded messages of one
/// cycle (the inverse of [`messages`] for what the scene needs): the
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
    let mut f = 0;
    for (wire, rec) in [
        (flags::POSE, msgs::flags::POSE_VALID),
        (flags::ESTIMATE, msgs::flags::TIP_VALID),
        (flags::OBSERVABLE, msgs::flags::OBSERVABLE),
    ] {
        if est.flags & rec != 0 {
            f |= wire;
        }
    }
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
    let [
        warn_total_n,
        stop_total_n,
        warn_axial_n,
        stop_axial_n,
        warn_lateral_n,
        stop_lateral_n,
    ] = s.limits_n;
    SceneStatus {
        stamp_ns: s.now_ns,
        cycle: s.cycle,
        guard_state: guard_state(s.guard_state),
        guard: ReasonText::truncating(guard_state_name(s.guard_state)),
        reason: reason_text(s.guard_reason),
        force_total_n: or_nan((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt()),
        axial_n: or_nan(s.tip_axial_lateral_n[0]),
        lateral_n: or_nan(s.tip_axial_lateral_n[1]),
        warn_total_n,
        stop_total_n,
        warn_axial_n,
        stop_axial_n,
        warn_lateral_n,
        stop_lateral_n,
        truth_tip_force_n: if s.flags & flags::SIM_TRUTH != 0 {
            s.truth_tip_force_n
        } else {
            [f64::NAN; 3]
        },
    }
}
