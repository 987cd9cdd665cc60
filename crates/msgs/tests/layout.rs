//! The recorded messages' CDR and schemas, pinned: each message type's
//! encoding of one sample is the bytes the hand-written encoders gave before
//! the field lists (`ros_message!`) replaced them, and decodes back to the
//! sample; every cut of those bytes is an error, never a panic; the `.msg`
//! types' schemas are their files followed by the header's sections, and
//! their field lists are the files' field lines.
#![allow(clippy::unwrap_used, clippy::panic, clippy::indexing_slicing)]

use sar_msgs::cdr::CdrError;
use sar_msgs::msgs::*;

fn samples() -> Vec<(&'static str, Outgoing)> {
    vec![
        (
            "cycle_input",
            Outgoing::CycleInput(CycleInput {
                stamp_ns: 1_234_567_890_123,
                cycle: 42,
                now_ns: 99,
                clock_status: ClockStatusCode::NotAdvancing,
                sensor_force_n: [0.1, -0.2, 0.3],
                sensor_torque_nm: [0.01, 0.02, -0.03],
                sensor_counter: 7,
                sensor_status: 3,
                sensor_stamp_ns: 8,
                sensor_valid: true,
                joints_q_m: [0.02, 0.25, 0.31],
                joints_stamp_ns: 9,
                joints_valid: true,
                drive_state: DriveStateCode::Fault,
                drive_fault_axis: -1,
                drive_fault_code: 0x2310,
                target_q_m: [1.0, 2.0, 3.0],
                target_valid: true,
                command_kind: CommandKindCode::MoveTip,
                command_values: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                command_arg: 77,
                move_tip_m: [7.0, 8.0, 9.0],
                limits_n: [1.5, 2.5, 3.5, 4.5, 5.5, 6.5],
                drive_action: DriveActionCode::Stream,
                setpoint_q_m: [0.5, 0.6, 0.7],
                reply_status: REPLY_NONE,
                reply_reason: 300,
                limits_in_use_n: [9.0, 8.0, 7.0, 6.0, 5.0, 4.0],
                publisher_idle_ns: 1000,
                back_out_m: 0.125,
                move_max_force_n: 2.5,
                sensor_drained_counted: true,
                sensor_drained_samples: 3,
                sensor_drained_jumps: 1,
                command_layout: CommandLayoutCode::UnitNamed,
                hold_max_force_n: 1.25,
                push_axial_n: -2.25,
                excite_amplitude_m: [0.01, 0.02, 0.03],
                excite_freq_hz: [0.5, 0.7, 1.1],
                excite_duration_s: 30.0,
                excite_fade_s: 3.0,
            }),
        ),
        (
            "estimator_state",
            Outgoing::EstimatorState(EstimatorState {
                stamp_ns: 5_000_000_001,
                cycle: 1,
                now_ns: 2,
                sensor_stamp_ns: 3,
                joints_stamp_ns: 4,
                sensor_age_ns: 5,
                joints_age_ns: 6,
                tip_outcome: TipOutcomeCode::SensorInvalid,
                ujoint_m: [1.0, 2.0, 3.0],
                tip_m: [4.0, 5.0, 6.0],
                support_distance_m: 0.5,
                ujoint_force_n: [7.0, 8.0, 9.0],
                tip_force_n: [0.1, 0.2, 0.3],
                tip_force_std_n: [0.01, 0.02, 0.03],
                axial_n: 1.5,
                lateral_n: 2.5,
                torsion_nm: 3.5,
                tip_force_filtered_n: [0.4, 0.5, 0.6],
                guard_state: GuardStateCode::Stop,
                guard_reason_code: 21,
                guard_reason_text: ReasonText::truncating("above stop: 3.1 N ü"),
                flags: 0x55,
            }),
        ),
        (
            "guard_event",
            Outgoing::GuardEvent(GuardEvent {
                stamp_ns: 7,
                cycle: 8,
                from_state: GuardStateCode::Ok,
                to_state: GuardStateCode::Retreat,
                reason_code: 33,
                reason_text: ReasonText::truncating("retreat"),
            }),
        ),
        (
            "recorder_drops",
            Outgoing::RecorderDrops(RecorderDrops {
                stamp_ns: 3_000_000_007,
                dropped: 1,
                written: 2,
                queue_capacity: 3,
            }),
        ),
        (
            "sensor_wrench",
            Outgoing::SensorWrench(WrenchStamped::sensor(11, [1.0, 2.0, 3.0], [4.0, 5.0, 6.0])),
        ),
        (
            "tip_wrench",
            Outgoing::TipWrench(WrenchStamped::base_force(12, [1.0, -2.0, 3.0])),
        ),
        (
            "joints",
            Outgoing::Joints(ActiveJointState {
                stamp_ns: 13,
                q_m: [0.1, 0.2, 0.3],
            }),
        ),
        (
            "passive_joints",
            Outgoing::PassiveJoints(PassiveJointState {
                stamp_ns: 14,
                q_rad: [0.4, 0.5],
            }),
        ),
    ]
}

fn snapshot() -> StateSnapshot {
    StateSnapshot {
        stamp_ns: 15,
        after_cycle: 16,
        format_version: 3,
        data: (0..40u8).collect(),
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The bytes of each sample as the hand-written encoders wrote them.
fn pinned(name: &str) -> &'static str {
    match name {
        "cycle_input" => concat!(
            "00010000d2040000cb50d921050000006261736500000000000000002a000000",
            "00000000630000000000000001000000000000009a9999999999b93f9a999999",
            "9999c9bf333333333333d33f7b14ae47e17a843f7b14ae47e17a943fb81e85eb",
            "51b89ebf0700000003000000080000000000000001000000000000007b14ae47",
            "e17a943f000000000000d03fd7a3703d0ad7d33f09000000000000000103ff00",
            "10230000000000000000f03f00000000000000400000000000000840010a0000",
            "00000000000000000000f03f0000000000000040000000000000084000000000",
            "00001040000000000000144000000000000018404d0000000000000000000000",
            "00001c4000000000000020400000000000002240000000000000f83f00000000",
            "000004400000000000000c400000000000001240000000000000164000000000",
            "00001a400600000000000000000000000000e03f333333333333e33f66666666",
            "6666e63fff002c01000000000000000000002240000000000000204000000000",
            "00001c40000000000000184000000000000014400000000000001040e8030000",
            "00000000000000000000c03f0000000000000440010003000100010000000000",
            "0000f43f00000000000002c07b14ae47e17a843f7b14ae47e17a943fb81e85eb",
            "51b89e3f000000000000e03f666666666666e63f9a9999999999f13f00000000",
            "00003e400000000000000840",
        ),
        "estimator_state" => concat!(
            "0001000005000000010000000500000062617365000000000000000001000000",
            "0000000002000000000000000300000000000000040000000000000005000000",
            "0000000006000000000000000300000000000000000000000000f03f00000000",
            "0000004000000000000008400000000000001040000000000000144000000000",
            "00001840000000000000e03f0000000000001c40000000000000204000000000",
            "000022409a9999999999b93f9a9999999999c93f333333333333d33f7b14ae47",
            "e17a843f7b14ae47e17a943fb81e85eb51b89e3f000000000000f83f00000000",
            "000004400000000000000c409a9999999999d93f000000000000e03f33333333",
            "3333e33f021500001500000061626f76652073746f703a20332e31204e20c3bc",
            "0000000055000000",
        ),
        "guard_event" => concat!(
            "0001000000000000070000000500000062617365000000000000000008000000",
            "0000000000042100080000007265747265617400",
        ),
        "recorder_drops" => concat!(
            "0001000003000000070000000100000000000000010000000000000002000000",
            "000000000300000000000000",
        ),
        "sensor_wrench" => concat!(
            "00010000000000000b0000000700000073656e736f7200000000000000000000",
            "0000f03f00000000000000400000000000000840000000000000104000000000",
            "000014400000000000001840",
        ),
        "tip_wrench" => concat!(
            "00010000000000000c0000000500000062617365000000000000000000000000",
            "0000f03f00000000000000c00000000000000840000000000000000000000000",
            "000000000000000000000000",
        ),
        "joints" => concat!(
            "00010000000000000d0000000100000000000000030000000300000071310000",
            "03000000713200000300000071330000030000009a9999999999b93f9a999999",
            "9999c93f333333333333d33f0000000000000000",
        ),
        "passive_joints" => concat!(
            "00010000000000000e0000000100000000000000020000000300000071340000",
            "0300000071350000020000009a9999999999d93f000000000000e03f00000000",
            "00000000",
        ),
        "snapshot" => concat!(
            "00010000000000000f0000000100000000000000100000000000000003000000",
            "28000000000102030405060708090a0b0c0d0e0f101112131415161718191a1b",
            "1c1d1e1f2021222324252627",
        ),
        _ => panic!("no pinned bytes for {name}"),
    }
}

#[test]
fn encodings_are_the_pinned_bytes_and_decode_back() {
    let mut buf = Vec::new();
    for (name, m) in samples() {
        m.encode(&mut buf).unwrap();
        assert_eq!(hex(&buf), pinned(name), "{name}");
        assert_eq!(Outgoing::decode(m.topic(), &buf).unwrap(), m, "{name}");
    }
    let s = snapshot();
    s.encode(&mut buf).unwrap();
    assert_eq!(hex(&buf), pinned("snapshot"));
    assert_eq!(StateSnapshot::decode(&buf).unwrap(), s);
}

/// A refused value gives the error of the field-by-field reading (its
/// offset), also where the whole run is present and read in one window.
#[test]
fn refused_values_name_their_offset() {
    let mut b = Vec::new();
    samples()[0].1.encode(&mut b).unwrap();
    let with = |i: usize, v: u8| {
        let mut c = b.clone();
        c[i] = v;
        CycleInput::decode(&c)
    };
    // Offsets count from after the 4-byte encapsulation header.
    assert_eq!(
        with(116, 2),
        Err(CdrError::BadBool {
            offset: 112,
            value: 2
        })
    );
    assert_eq!(
        with(188, 7),
        Err(CdrError::BadBool {
            offset: 184,
            value: 7
        })
    );
    // clock_status, after cycle and now_ns.
    assert_eq!(
        with(44, 9),
        Err(CdrError::BadValue {
            field: "clock_status",
            value: 9
        })
    );
    // The first refused value wins, also in a cut message.
    let mut c = b.clone();
    c[116] = 2;
    c[188] = 2;
    assert_eq!(
        CycleInput::decode(&c[..300]),
        Err(CdrError::BadBool {
            offset: 112,
            value: 2
        })
    );
    assert_eq!(
        CycleInput::decode(&b[..300]),
        Err(CdrError::UnexpectedEnd {
            offset: 296,
            needed: 8
        })
    );
}

const HEADER_SECTIONS: &str = "\
================================================================================
MSG: std_msgs/Header
# Standard metadata for higher-level stamped data types.
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

fn msg_file(name: &str) -> String {
    let path = format!("{}/msg/{name}.msg", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The field lines of a `.msg` file (`float64[3] joints_q_m`): comments,
/// blank lines and constants left out.
fn field_lines(msg: &str) -> Vec<String> {
    msg.lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty() && !l.contains('='))
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect()
}

/// The `sar_msgs` types: their schema is their `.msg` file and the header's
/// sections, and the field list that encodes and decodes them is the
/// file's field lines, in order.
#[test]
fn the_schemas_and_field_lists_are_the_msg_files() {
    let types: [(&str, &str, &str, &[MsgField]); 6] = [
        (
            "CycleInput",
            CycleInput::TYPE_NAME,
            CycleInput::SCHEMA,
            CycleInput::MSG_FIELDS,
        ),
        (
            "EstimatorState",
            EstimatorState::TYPE_NAME,
            EstimatorState::SCHEMA,
            EstimatorState::MSG_FIELDS,
        ),
        (
            "GuardEvent",
            GuardEvent::TYPE_NAME,
            GuardEvent::SCHEMA,
            GuardEvent::MSG_FIELDS,
        ),
        (
            "RecorderDrops",
            RecorderDrops::TYPE_NAME,
            RecorderDrops::SCHEMA,
            RecorderDrops::MSG_FIELDS,
        ),
        (
            "StateSnapshot",
            StateSnapshot::TYPE_NAME,
            StateSnapshot::SCHEMA,
            StateSnapshot::MSG_FIELDS,
        ),
        (
            "SceneStatus",
            SceneStatus::TYPE_NAME,
            SceneStatus::SCHEMA,
            SceneStatus::MSG_FIELDS,
        ),
    ];
    for (name, type_name, schema, fields) in types {
        let msg = msg_file(name);
        assert_eq!(type_name, format!("sar_msgs/msg/{name}"));
        assert_eq!(schema, format!("{msg}{HEADER_SECTIONS}"), "{name}");
        let listed: Vec<String> = fields.iter().map(|f| f.to_string()).collect();
        assert_eq!(listed, field_lines(&msg), "{name}");
    }
    // The geometry_msgs and sensor_msgs types: the header's sections too.
    assert!(WrenchStamped::SCHEMA.contains(HEADER_SECTIONS));
    assert!(JointState::SCHEMA.ends_with(HEADER_SECTIONS));
    assert_eq!(
        WrenchStamped::MSG_FIELDS
            .iter()
            .map(|f| f.to_string())
            .collect::<Vec<_>>(),
        [
            "std_msgs/Header header",
            "float64[3] force_n",
            "float64[3] torque_nm"
        ]
    );
}

/// The constants of a `.msg` file (`uint8 DRIVE_READY=0`), by name.
fn msg_constants(name: &str) -> std::collections::BTreeMap<String, i64> {
    msg_file(name)
        .lines()
        .filter_map(|l| l.split('#').next()?.split_once('='))
        .filter_map(|(decl, value)| {
            let (_, key) = decl.split_once(' ')?;
            Some((key.trim().to_owned(), value.trim().parse().ok()?))
        })
        .collect()
}

/// `QuickStop` as a `.msg` constant's name: `QUICK_STOP`.
fn upper_snake(name: &str) -> String {
    let mut out = String::new();
    for (i, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

/// Every value of `values` is the constant `PREFIX_NAME` of `constants`
/// with its code, and the file has no other constant of that prefix but
/// `reserved` (codes no value of the type carries).
fn assert_code_list(
    constants: &std::collections::BTreeMap<String, i64>,
    prefix: &str,
    values: &[(&str, u8)],
    reserved: &[&str],
) {
    for (name, code) in values {
        let key = format!("{prefix}_{}", upper_snake(name));
        assert_eq!(constants.get(&key), Some(&i64::from(*code)), "{key}");
    }
    let mut in_file: Vec<&str> = constants
        .keys()
        .filter(|k| k.starts_with(&format!("{prefix}_")))
        .map(String::as_str)
        .collect();
    in_file.retain(|k| {
        !values
            .iter()
            .any(|(name, _)| *k == format!("{prefix}_{}", upper_snake(name)))
    });
    assert_eq!(in_file, reserved, "{prefix}_* of the .msg without a value");
}

/// One numbering per code: each `.msg` constant (`DRIVE_*`, `COMMAND_*`,
/// `ACTION_*`, `CLOCK_*`, `TIP_*`, `GUARD_*`) equals the shared constant
/// of its name (the recording's code types, and through them the wire's
/// `drive_code`, `command_kind` and `guard_code`, which `sarctl` reads).
#[test]
fn each_msg_constant_is_the_shared_code() {
    use sar_msgs::wire::{command_kind, drive_code, guard_code};
    macro_rules! values {
        ($t:ty) => {
            <$t>::ALL
                .iter()
                .map(|v| (v.name(), v.code()))
                .collect::<Vec<_>>()
        };
    }
    let cycle = msg_constants("CycleInput");
    assert_code_list(&cycle, "DRIVE", &values!(DriveStateCode), &[]);
    let reserved = [
        "COMMAND_CLEAR_TARE",
        "COMMAND_DISABLE",
        "COMMAND_ENABLE",
        "COMMAND_FAULT_RESET",
        "COMMAND_MOVE_TO",
        "COMMAND_QUICK_STOP",
    ];
    assert_code_list(&cycle, "COMMAND", &values!(CommandKindCode), &reserved);
    assert_code_list(&cycle, "LAYOUT", &values!(CommandLayoutCode), &[]);
    assert_code_list(&cycle, "ACTION", &values!(DriveActionCode), &[]);
    assert_code_list(&cycle, "CLOCK", &values!(ClockStatusCode), &[]);
    let state = msg_constants("EstimatorState");
    assert_code_list(&state, "TIP", &values!(TipOutcomeCode), &[]);
    let guard_values = values!(GuardStateCode);
    let event = msg_constants("GuardEvent");
    assert_code_list(&event, "GUARD", &guard_values, &[]);
    // EstimatorState.msg was written before Retreat: the others, the same.
    let before_retreat: Vec<_> = guard_values
        .into_iter()
        .filter(|v| v.0 != "Retreat")
        .collect();
    assert_code_list(&state, "GUARD", &before_retreat, &[]);
    assert_eq!(event.get("REASON_OTHER"), Some(&i64::from(reason::OTHER)));

    // The wire's constants are the recording's numbers.
    let drive = [
        ("DRIVE_READY", drive_code::READY),
        ("DRIVE_ENABLED", drive_code::ENABLED),
        ("DRIVE_QUICK_STOP", drive_code::QUICK_STOP),
        ("DRIVE_FAULT", drive_code::FAULT),
        ("DRIVE_UNREAD", drive_code::UNREAD),
    ];
    let commands = [
        ("COMMAND_GUARD_RESET", command_kind::RESET),
        ("COMMAND_TARE", command_kind::TARE),
        ("COMMAND_MOVE_TIP", command_kind::MOVE_TIP),
        ("COMMAND_SET_LIMITS", command_kind::SET_LIMITS),
        ("COMMAND_BACK_OUT", command_kind::BACK_OUT),
        ("COMMAND_HOLD", command_kind::HOLD),
        ("COMMAND_PUSH", command_kind::PUSH),
        ("COMMAND_POSITION", command_kind::POSITION),
        ("COMMAND_EXCITE", command_kind::EXCITE),
        ("COMMAND_SUPPORT_CONFIRM", command_kind::SUPPORT_CONFIRM),
    ];
    for (key, code) in drive.into_iter().chain(commands) {
        assert_eq!(cycle.get(key), Some(&i64::from(code)), "{key}");
    }
    let guard = [
        ("GUARD_OK", guard_code::OK),
        ("GUARD_WARN", guard_code::WARN),
        ("GUARD_STOP", guard_code::STOP),
        ("GUARD_FAULT", guard_code::FAULT),
        ("GUARD_RETREAT", guard_code::RETREAT),
    ];
    for (key, code) in guard {
        assert_eq!(event.get(key), Some(&i64::from(code)), "{key}");
    }
    // The kinds never recorded as themselves are apart from every recorded
    // code.
    for kind in [
        command_kind::LIMITS,
        command_kind::RECORD_START,
        command_kind::RECORD_STOP,
        command_kind::GUARDED_MOVE,
    ] {
        assert!(kind >= 128, "{kind}");
        assert!(CommandKindCode::from_code(u8::try_from(kind).unwrap()).is_err());
    }
}

/// `sar_msgs/msg/CycleBatch` (the lean recording's): its schema is its
/// `.msg` file, the header's sections and the nested `CycleInput`'s
/// section; its field list is the file's; its flags are the file's
/// constants; a batch round-trips, and every cut of it is an error.
#[test]
fn the_cycle_batch_is_its_msg_file_and_round_trips() {
    let msg = msg_file("CycleBatch");
    assert_eq!(CycleBatch::TYPE_NAME, "sar_msgs/msg/CycleBatch");
    let sep = "=".repeat(80);
    assert_eq!(
        CycleBatch::SCHEMA,
        format!(
            "{msg}{HEADER_SECTIONS}{sep}\nMSG: sar_msgs/CycleInput\n{}",
            msg_file("CycleInput")
        )
    );
    let listed: Vec<String> = CycleBatch::MSG_FIELDS
        .iter()
        .map(|f| f.to_string())
        .collect();
    assert_eq!(listed, field_lines(&msg));
    let constants = msg_constants("CycleBatch");
    for (name, value) in [
        ("FLAG_SENSOR_VALID", batch_flags::SENSOR_VALID),
        ("FLAG_JOINTS_VALID", batch_flags::JOINTS_VALID),
        ("FLAG_JOINTS_MESSAGE", batch_flags::JOINTS_MESSAGE),
        ("FLAG_SENSOR_MESSAGE", batch_flags::SENSOR_MESSAGE),
        ("FLAG_SENSOR_RAW", batch_flags::SENSOR_RAW),
        ("FLAG_JOINTS_RAW", batch_flags::JOINTS_RAW),
        ("FLAG_SENSOR_REPEAT", batch_flags::SENSOR_REPEAT),
        ("FLAG_JOINTS_REPEAT", batch_flags::JOINTS_REPEAT),
    ] {
        assert_eq!(constants.get(name), Some(&i64::from(value)), "{name}");
    }
    assert_eq!(constants.len(), 8);
    let Outgoing::CycleInput(command) = samples()[0].1 else {
        panic!("the first sample is a cycle input")
    };
    let b = CycleBatch {
        stamp_ns: 1_000_000_007,
        force_counts_per_n: 10_000.0,
        torque_counts_per_nm: 100_000.0,
        joint_m_per_count: 1e-6,
        flags: vec![1, 2, 255],
        cycle: vec![7, 1, -1],
        now_ns: vec![i64::MAX, 1_000_000, i64::MIN],
        clock_status: vec![0, 1, 2],
        publisher_idle_ns: vec![0, 5, -5],
        sensor_counter: vec![1, -1, i32::MAX],
        sensor_status: vec![0, 3, u32::MAX],
        sensor_stamp_ns: vec![1, 2, 3],
        sensor_counts: (0..18).map(|i| i - 9).collect(),
        sensor_raw: vec![0.5, -0.25, f64::NAN, 1e300, -0.0, 7.0],
        joints_stamp_ns: vec![4, 5, 6],
        joint_counts: (0..9).collect(),
        joints_raw: vec![0.1, 0.2, 0.3],
        drive_state: vec![0, 1, 3],
        drive_fault_axis: vec![-1, -1, 2],
        drive_fault_code: vec![0, 0, 0x2310],
        extra_cycles: vec![1],
        extra_stamp_ns: vec![u64::MAX],
        extra_wrench: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        command_cycles: vec![2],
        commands: vec![command],
        drained_counts: vec![2, 0, 0, 0, 17, 3],
    };
    let mut bytes = Vec::new();
    b.encode(&mut bytes).unwrap();
    let back = CycleBatch::decode(&bytes).unwrap();
    // (NaN != NaN: compared as bits.)
    assert_eq!(format!("{back:?}"), format!("{b:?}"));
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&back.sensor_raw), bits(&b.sensor_raw));
    assert_eq!(back.commands, b.commands);
    // A lean file older than the drained counts ends before them: it
    // reads them empty (not counted); every other cut is refused.
    let older = bytes.len() - (4 + 2 * b.drained_counts.len());
    for cut in 0..bytes.len() {
        let decoded = CycleBatch::decode(&bytes[..cut]);
        if cut == older {
            let old = decoded.unwrap();
            assert!(old.drained_counts.is_empty());
            assert_eq!(old.commands, b.commands);
        } else {
            assert!(decoded.is_err(), "cut at {cut}");
        }
    }
}
