//! One cycle of the per-cycle step as recorded messages (INTERFACES.md 1),
//! shared by the daemon's recorder and by `sarctl replay`, so that both write
//! the same bytes for the same cycle:
//!
//! - [`outputs`]: `CycleOutput` (+ the cycle's input) -> `/sar/estimate/tip_wrench`
//!   (every cycle with a number, observable or not), `.../tip_wrench_filtered`,
//!   `.../passive_joints`, `/sar/estimate/state`, `/sar/guard/events`.
//! - [`cycle_input_msg`] and [`loop_input`]: the loop step's `LoopInput`
//!   (and its decision: reference, drive action, reply, limits) to
//!   `/sar/cycle/input` and back, losslessly for every field the step reads.
//!
//! Every message of a cycle is stamped with the cycle's `now` ([`cycle_stamp_ns`]).
//! Nothing here allocates (the recorder's push side calls it every cycle).

use sar_config::ConfigSource;
use sar_estimator::Vec3;
use sar_estimator::cycle::{
    Bias, CycleInput, CycleOutput, DrainedSamples, JointSample, SensorSample, TipOutcome,
};
use sar_estimator::guard::{ForceLimits, GuardState};
use sar_hal::DriveState;
use sar_kinematics::ActiveJoints;
use sar_loop::step::{DriveAction, LoopInput, LoopOutput, Release, Request};
use sar_msgs::msgs::{
    ActiveJointState, ClockStatusCode, CommandKindCode, CycleInput as CycleInputMsg,
    DriveActionCode, DriveStateCode, EstimatorState, GuardEvent, GuardStateCode, Outgoing,
    PassiveJointState, REPLY_NONE, ReasonText, WrenchStamped, flags,
};
use std::fmt::Write as _;

fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn vec3(&[x, y, z]: &[f64; 3]) -> Vec3 {
    Vec3::new(x, y, z)
}

/// The guard state's recorded code.
pub fn guard_code(s: GuardState) -> GuardStateCode {
    match s {
        GuardState::Ok => GuardStateCode::Ok,
        GuardState::Warn => GuardStateCode::Warn,
        GuardState::Stop => GuardStateCode::Stop,
        GuardState::Fault => GuardStateCode::Fault,
        GuardState::Retreat => GuardStateCode::Retreat,
    }
}

/// The stamp of every message of a cycle: its `now`; when the clock could
/// not be read, the newer of the input stamps (never a made-up time).
pub fn cycle_stamp_ns(input: &CycleInput) -> u64 {
    stamp_of(input.now_ns, &input.sensor, &input.joints)
}

/// [`cycle_stamp_ns`] of a loop step's input: the stamp of its
/// [`LoopInput::cycle_input`], without making it.
pub fn loop_stamp_ns(input: &LoopInput) -> u64 {
    stamp_of(input.now_ns, &input.sensor, &input.joints)
}

fn stamp_of(now_ns: Option<u64>, sensor: &SensorSample, joints: &JointSample) -> u64 {
    now_ns.unwrap_or(sensor.stamp_ns.max(joints.stamp_ns))
}

/// The output messages of one cycle, in a fixed order (state, tip wrench,
/// filtered, passive joints, guard event), each handed to `emit`.
pub fn outputs(input: &CycleInput, output: &CycleOutput, mut emit: impl FnMut(Outgoing)) {
    let stamp_ns = cycle_stamp_ns(input);
    emit(Outgoing::EstimatorState(estimator_state(input, output)));
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

/// Every message of one cycle of a daemon recording, in the recorded order:
/// `/sar/cycle/input`, `/sar/sensor/wrench` (a new sample), `/sar/joints`
/// (when `joints_new`), then [`outputs`]. The recorder and the fixtures'
/// generator both use it.
pub fn cycle_record(
    input: &LoopInput,
    decision: &LoopOutput,
    joints_new: bool,
    emit: impl FnMut(Outgoing),
) {
    let sensor = decision
        .estimate
        .new_sample
        .then(|| sensor_wrench(&input.sensor));
    record_cycle(input, decision, joints_new, sensor.into_iter(), emit);
}

/// [`cycle_record`] as the daemon's recorder writes it: every sensor
/// sample received since the previous cycle (`samples`, oldest first) as
/// `/sar/sensor/wrench`, instead of only the one the step used (its counter
/// and stamp are in `/sar/cycle/input`; its message is among these).
pub fn cycle_record_samples(
    input: &LoopInput,
    decision: &LoopOutput,
    joints_new: bool,
    samples: &[sar_hal::WrenchSample],
    emit: impl FnMut(Outgoing),
) {
    let sensor = samples
        .iter()
        .map(|s| WrenchStamped::sensor(s.received_ns, arr(&s.force_n), arr(&s.torque_nm)));
    record_cycle(input, decision, joints_new, sensor, emit);
}

/// One cycle's messages in their fixed order: the cycle input, the sensor
/// messages given, the joints when new, the outputs.
fn record_cycle(
    input: &LoopInput,
    decision: &LoopOutput,
    joints_new: bool,
    sensor: impl Iterator<Item = WrenchStamped>,
    mut emit: impl FnMut(Outgoing),
) {
    emit(Outgoing::CycleInput(cycle_input_msg(input, decision)));
    for w in sensor {
        emit(Outgoing::SensorWrench(w));
    }
    if joints_new {
        emit(Outgoing::Joints(joints_msg(&input.joints)));
    }
    outputs(&input.cycle_input(), &decision.estimate, emit);
}

/// How many messages [`outputs`] gives for `output`.
pub fn output_count(output: &CycleOutput) -> u64 {
    1 + u64::from(matches!(output.tip, TipOutcome::Estimate(_)))
        + u64::from(output.filtered.is_some())
        + u64::from(output.pose.is_some())
        + u64::from(output.transition.is_some())
}

/// `/sar/estimate/state` of one cycle.
pub fn estimator_state(input: &CycleInput, o: &CycleOutput) -> EstimatorState {
    let mut reason_text = ReasonText::default();
    let _ = write!(reason_text, "{}", o.guard_reason);
    let mut m = EstimatorState {
        stamp_ns: cycle_stamp_ns(input),
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

/// The drive state's recorded code, the faulted axis (-1 for none) and the
/// fault code.
pub fn drive_state_fields(s: Option<DriveState>) -> (DriveStateCode, i8, u16) {
    match s {
        None => (DriveStateCode::Unread, -1, 0),
        Some(DriveState::Ready) => (DriveStateCode::Ready, -1, 0),
        Some(DriveState::Enabled) => (DriveStateCode::Enabled, -1, 0),
        Some(DriveState::QuickStop) => (DriveStateCode::QuickStop, -1, 0),
        Some(DriveState::Fault { axis, code }) => (
            DriveStateCode::Fault,
            axis.map_or(-1, |a| i8::try_from(a).unwrap_or(-1)),
            code,
        ),
    }
}

/// The drive state of its recorded fields (the inverse of
/// [`drive_state_fields`]).
pub fn drive_state_of(code: DriveStateCode, axis: i8, fault: u16) -> Option<DriveState> {
    match code {
        DriveStateCode::Unread => None,
        DriveStateCode::Ready => Some(DriveState::Ready),
        DriveStateCode::Enabled => Some(DriveState::Enabled),
        DriveStateCode::QuickStop => Some(DriveState::QuickStop),
        DriveStateCode::Fault => Some(DriveState::Fault {
            axis: u8::try_from(axis).ok(),
            code: fault,
        }),
    }
}

fn joints_arr(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

fn joints_of(&[q1_m, q2_m, q3_m]: &[f64; 3]) -> ActiveJoints {
    ActiveJoints { q1_m, q2_m, q3_m }
}

/// `/sar/cycle/input` of one cycle: the loop step's input and its decision
/// (see `msg/CycleInput.msg`).
pub fn cycle_input_msg(input: &LoopInput, decision: &LoopOutput) -> CycleInputMsg {
    let (drive_state, drive_fault_axis, drive_fault_code) = drive_state_fields(input.drive_state);
    let mut m = CycleInputMsg {
        stamp_ns: cycle_stamp_ns(&input.cycle_input()),
        cycle: input.cycle,
        now_ns: input.now_ns.unwrap_or(0),
        clock_status: if input.now_ns.is_some() {
            ClockStatusCode::Ok
        } else {
            ClockStatusCode::ReadFailed
        },
        sensor_force_n: arr(&input.sensor.force_n),
        sensor_torque_nm: arr(&input.sensor.torque_nm),
        sensor_counter: input.sensor.counter,
        sensor_status: input.sensor.status,
        sensor_stamp_ns: input.sensor.stamp_ns,
        sensor_valid: input.sensor.valid,
        joints_q_m: joints_arr(&input.joints.joints),
        joints_stamp_ns: input.joints.stamp_ns,
        joints_valid: input.joints.valid,
        drive_state,
        drive_fault_axis,
        drive_fault_code,
        target_q_m: decision.reference.as_ref().map_or([0.0; 3], joints_arr),
        target_valid: decision.reference.is_some(),
        limits_in_use_n: decision.limits.to_array(),
        reply_status: REPLY_NONE,
        ..CycleInputMsg::default()
    };
    record_request(&mut m, input.request, input.cycle);
    m.publisher_idle_ns = input.publisher_idle_ns;
    let d = input.sensor.drained;
    (
        m.sensor_drained_counted,
        m.sensor_drained_samples,
        m.sensor_drained_jumps,
    ) = (d.counted, d.samples, d.jumps);
    (m.drive_action, m.setpoint_q_m) = drive_action_fields(decision.action);
    if let Some((status, reason)) = decision.reply {
        m.reply_status = u8::try_from(status as u16).unwrap_or(REPLY_NONE);
        m.reply_reason = reason;
    }
    m
}

/// The operator's request of a cycle in its `/sar/cycle/input` fields
/// (command kind and arguments; a reset carries the cycle).
fn record_request(m: &mut CycleInputMsg, request: Option<Request>, cycle: u64) {
    match request {
        None => {}
        Some(Request::Reset) => {
            m.command_kind = CommandKindCode::GuardReset;
            m.command_arg = cycle;
        }
        Some(Request::Tare) => m.command_kind = CommandKindCode::Tare,
        Some(Request::MoveTip { tip_m }) => {
            m.command_kind = CommandKindCode::MoveTip;
            m.move_tip_m = arr(&tip_m);
        }
        Some(Request::GuardedMove { tip_m, max_force_n }) => {
            m.command_kind = CommandKindCode::MoveTip;
            m.move_tip_m = arr(&tip_m);
            m.move_max_force_n = max_force_n;
        }
        Some(Request::SetLimits(l)) => {
            m.command_kind = CommandKindCode::SetLimits;
            m.limits_n = l.to_array();
        }
        Some(Request::BackOut { distance_m }) => {
            m.command_kind = CommandKindCode::BackOut;
            m.back_out_m = distance_m;
        }
        Some(Request::Hold { max_force_n }) => {
            m.command_kind = CommandKindCode::Hold;
            m.command_values[0] = max_force_n;
        }
        Some(Request::Push { axial_n }) => {
            m.command_kind = CommandKindCode::Push;
            m.command_values[0] = axial_n;
        }
        Some(Request::Position) => m.command_kind = CommandKindCode::Position,
        Some(Request::Excite(e)) => {
            m.command_kind = CommandKindCode::Excite;
            (m.move_tip_m, m.limits_n) = sar_loop::publish::excite_fields(&e);
        }
        Some(Request::SupportConfirm) => m.command_kind = CommandKindCode::SupportConfirm,
    }
}

/// The step's drive action as recorded: its code and set point (zero
/// without one).
fn drive_action_fields(action: DriveAction) -> (DriveActionCode, [f64; 3]) {
    match action {
        DriveAction::None => (DriveActionCode::None, [0.0; 3]),
        DriveAction::QuickStop => (DriveActionCode::QuickStop, [0.0; 3]),
        DriveAction::Release(Release::Enable) => (DriveActionCode::ReleaseEnable, [0.0; 3]),
        DriveAction::Release(Release::DisableEnable) => {
            (DriveActionCode::ReleaseDisableEnable, [0.0; 3])
        }
        DriveAction::Release(Release::FaultResetEnable) => {
            (DriveActionCode::ReleaseFaultResetEnable, [0.0; 3])
        }
        DriveAction::Setpoint(q) => (DriveActionCode::Setpoint, joints_arr(&q)),
        DriveAction::Stream(q) => (DriveActionCode::Stream, joints_arr(&q)),
        DriveAction::FaultReset => (DriveActionCode::FaultReset, [0.0; 3]),
    }
}

/// The loop step's input recorded in a `/sar/cycle/input` message (the
/// inverse of [`cycle_input_msg`] for every field the step reads). A command
/// the step does not take (drive commands, a set bias) gives no request.
pub fn loop_input(m: &CycleInputMsg) -> LoopInput {
    let request = match m.command_kind {
        CommandKindCode::GuardReset => Some(Request::Reset),
        CommandKindCode::Tare => Some(Request::Tare),
        // A guarded move's limit is > 0 when it was accepted as one; a
        // recorded 0 (or an older recording) is a plain move. A non-finite or
        // negative recorded limit goes to the step as it was, which refuses it.
        CommandKindCode::MoveTip if m.move_max_force_n != 0.0 => Some(Request::GuardedMove {
            tip_m: vec3(&m.move_tip_m),
            max_force_n: m.move_max_force_n,
        }),
        CommandKindCode::MoveTip => Some(Request::MoveTip {
            tip_m: vec3(&m.move_tip_m),
        }),
        CommandKindCode::SetLimits => Some(Request::SetLimits(ForceLimits::from_array(m.limits_n))),
        CommandKindCode::BackOut => Some(Request::BackOut {
            distance_m: m.back_out_m,
        }),
        CommandKindCode::Hold => Some(Request::Hold {
            max_force_n: m.command_values[0],
        }),
        CommandKindCode::Push => Some(Request::Push {
            axial_n: m.command_values[0],
        }),
        CommandKindCode::Position => Some(Request::Position),
        CommandKindCode::Excite => Some(Request::Excite(sar_loop::publish::excite_of(
            m.move_tip_m,
            m.limits_n,
        ))),
        CommandKindCode::SupportConfirm => Some(Request::SupportConfirm),
        _ => None,
    };
    LoopInput {
        cycle: m.cycle,
        now_ns: (m.clock_status != ClockStatusCode::ReadFailed).then_some(m.now_ns),
        sensor: SensorSample {
            force_n: vec3(&m.sensor_force_n),
            torque_nm: vec3(&m.sensor_torque_nm),
            counter: m.sensor_counter,
            status: m.sensor_status,
            stamp_ns: m.sensor_stamp_ns,
            valid: m.sensor_valid,
            drained: DrainedSamples {
                counted: m.sensor_drained_counted,
                samples: m.sensor_drained_samples,
                jumps: m.sensor_drained_jumps,
            },
        },
        joints: JointSample {
            joints: joints_of(&m.joints_q_m),
            stamp_ns: m.joints_stamp_ns,
            valid: m.joints_valid,
        },
        drive_state: drive_state_of(m.drive_state, m.drive_fault_axis, m.drive_fault_code),
        request,
        publisher_idle_ns: m.publisher_idle_ns,
    }
}

/// The raw sensor sample of a cycle as `/sar/sensor/wrench`.
pub fn sensor_wrench(s: &SensorSample) -> WrenchStamped {
    WrenchStamped::sensor(s.stamp_ns, arr(&s.force_n), arr(&s.torque_nm))
}

/// The joint sample of a cycle as `/sar/joints`.
pub fn joints_msg(j: &JointSample) -> ActiveJointState {
    ActiveJointState {
        stamp_ns: j.stamp_ns,
        q_m: [j.joints.q1_m, j.joints.q2_m, j.joints.q3_m],
    }
}

/// The key of the metadata record that carries what replay needs beyond
/// the messages.
pub const REPLAY_METADATA: &str = "sar_replay";

/// The `sar_replay` key of a recording whose files start with a snapshot
/// (`/sar/cycle/snapshot`): the snapshot format's version.
pub const SNAPSHOT_FORMAT_KEY: &str = "snapshot_format";

/// `sar_replay` metadata: the bias the estimator started with (sensor frame;
/// each value as its IEEE bits in hex, so it round-trips exactly), and
/// whether the recording starts at the daemon's first cycle.
pub fn replay_metadata(
    bias: &Bias,
    from_first_cycle: bool,
) -> (String, std::collections::BTreeMap<String, String>) {
    let hex = |v: &Vec3| {
        format!(
            "{:016x} {:016x} {:016x}",
            v.x.to_bits(),
            v.y.to_bits(),
            v.z.to_bits()
        )
    };
    (
        REPLAY_METADATA.to_owned(),
        std::collections::BTreeMap::from([
            ("bias_force_n_bits".to_owned(), hex(&bias.force_n)),
            ("bias_torque_nm_bits".to_owned(), hex(&bias.torque_nm)),
            (
                "bias_force_n".to_owned(),
                format!("{} {} {}", bias.force_n.x, bias.force_n.y, bias.force_n.z),
            ),
            (
                "bias_torque_nm".to_owned(),
                format!(
                    "{} {} {}",
                    bias.torque_nm.x, bias.torque_nm.y, bias.torque_nm.z
                ),
            ),
            ("from_first_cycle".to_owned(), from_first_cycle.to_string()),
        ]),
    )
}

/// The name of the metadata record that holds the daemon's configuration.
pub const CONFIG_METADATA: &str = "sar_config";

/// `sar_config` metadata: `origin` and `toml`.
pub fn config_metadata(
    source: &ConfigSource,
) -> (String, std::collections::BTreeMap<String, String>) {
    (
        CONFIG_METADATA.to_owned(),
        std::collections::BTreeMap::from([
            ("origin".to_owned(), source.origin.clone()),
            ("toml".to_owned(), source.toml.clone()),
        ]),
    )
}

/// The configuration of a `sar_config` metadata record, if it holds one.
pub fn config_from_metadata(
    m: &std::collections::BTreeMap<String, String>,
) -> Option<ConfigSource> {
    Some(ConfigSource {
        origin: m.get("origin")?.clone(),
        toml: m.get("toml")?.clone(),
    })
}

/// The bias of a `sar_replay` metadata record, if it holds one.
pub fn bias_from_metadata(m: &std::collections::BTreeMap<String, String>) -> Option<Bias> {
    let parse = |key: &str| -> Option<Vec3> {
        let mut it = m
            .get(key)?
            .split_whitespace()
            .map(|w| u64::from_str_radix(w, 16).ok().map(f64::from_bits));
        let v = Vec3::new(it.next()??, it.next()??, it.next()??);
        it.next().is_none().then_some(v)
    };
    Some(Bias {
        force_n: parse("bias_force_n_bits")?,
        torque_nm: parse("bias_torque_nm_bits")?,
    })
}
