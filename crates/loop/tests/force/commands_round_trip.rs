//! The command table (`sar_msgs::command`, issue 36): every `Request`
//! variant, with finite random arguments, round-trips through the wire
//! (`to_wire` -> `decode`) and through the recording (`cycle_input_msg` ->
//! CDR bytes -> decode -> `loop_input`); every row of the table has a
//! distinct wire code, a distinct recorded code (or is told apart by its
//! field), help, and arguments whose names carry their units; an unknown
//! wire kind is an error naming it.

use super::rig::Rig;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use sar_estimator::Vec3;
use sar_estimator::guard::ForceLimits;
use sar_loop::control::Request;
use sar_msgs::command::{
    COMMANDS, CommandError, DaemonCommand, ExciteRequest, RecordedAs, WireCommand, decode,
};
use sar_msgs::msgs::{CycleInput, RosMessage};
use sar_msgs::wire::CommandMsg;

fn num() -> impl Strategy<Value = f64> {
    -1.0e3..1.0e3f64
}

fn v3() -> impl Strategy<Value = Vec3> {
    (num(), num(), num()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// Every variant (a new one fails to compile in `variant_name` below until
/// it is placed here too).
fn request() -> impl Strategy<Value = Request> {
    prop_oneof![
        Just(Request::Reset),
        Just(Request::Tare),
        v3().prop_map(|tip_m| Request::MoveTip { tip_m }),
        proptest::array::uniform6(num())
            .prop_map(|a| Request::SetLimits(ForceLimits::from_array(a))),
        num().prop_map(|distance_m| Request::BackOut { distance_m }),
        // A guarded move's limit is not 0 (a 0 is recorded as a plain move).
        (v3(), num().prop_filter("not 0", |n| *n != 0.0))
            .prop_map(|(tip_m, max_force_n)| Request::GuardedMove { tip_m, max_force_n }),
        num().prop_map(|max_force_n| Request::Hold { max_force_n }),
        num().prop_map(|axial_n| Request::Push { axial_n }),
        Just(Request::Position),
        (
            proptest::array::uniform3(num()),
            proptest::array::uniform3(num()),
            num(),
            num()
        )
            .prop_map(|(amplitude_m, freq_hz, duration_s, fade_s)| {
                Request::Excite(ExciteRequest {
                    amplitude_m,
                    freq_hz,
                    duration_s,
                    fade_s,
                })
            }),
        Just(Request::SupportConfirm),
    ]
}

/// The table's name of a request (exhaustive: a variant without its row in
/// the strategy above does not compile here).
fn variant_name(r: &Request) -> &'static str {
    match r {
        Request::Reset => "Reset",
        Request::Tare => "Tare",
        Request::MoveTip { .. } => "MoveTip",
        Request::SetLimits(_) => "SetLimits",
        Request::BackOut { .. } => "BackOut",
        Request::GuardedMove { .. } => "GuardedMove",
        Request::Hold { .. } => "Hold",
        Request::Push { .. } => "Push",
        Request::Position => "Position",
        Request::Excite(_) => "Excite",
        Request::SupportConfirm => "SupportConfirm",
    }
}

fn config() -> Config {
    Config {
        cases: 512,
        rng_seed: RngSeed::Fixed(36),
        failure_persistence: None,
        ..Config::default()
    }
}

#[test]
fn every_request_round_trips_through_the_wire_and_the_recording() {
    // One real cycle of the step gives an input and a decision to record.
    let mut rig = Rig::new(300.0, 0.010, 0.0, Vec::new());
    rig.request(4, Request::Tare);
    let (input, decision) = *rig.log.last().unwrap();
    let seen = std::cell::RefCell::new(std::collections::BTreeSet::new());
    proptest!(config(), |(r in request())| {
        seen.borrow_mut().insert(variant_name(&r));
        // The wire.
        let wire = r.to_wire(77);
        prop_assert_eq!(wire.id, 77);
        prop_assert_eq!(wire.kind, r.wire_code());
        prop_assert_eq!(decode(&wire), Ok(WireCommand::Loop(r)));
        // The recording, through its bytes.
        let mut with = input;
        with.request = Some(r);
        let msg = sar_record::convert::cycle_input_msg(&with, &decision);
        let mut bytes = Vec::new();
        msg.encode(&mut bytes).unwrap();
        let back = CycleInput::decode(&bytes).unwrap();
        prop_assert_eq!(back, msg);
        let replayed = sar_record::convert::loop_input(&back);
        prop_assert_eq!(replayed.request, Some(r));
        prop_assert_eq!(replayed.cycle, with.cycle);
    });
    let seen = seen.into_inner();
    assert_eq!(seen.len(), 11, "every variant generated: {seen:?}");
}

#[test]
fn the_table_has_distinct_codes_help_and_unit_named_arguments() {
    const UNITS: [&str; 5] = ["_m", "_n", "_hz", "_s", "_nm"];
    let unit_named = |name: &str| UNITS.iter().any(|u| name.ends_with(u));
    let mut wire = std::collections::BTreeSet::new();
    let mut recorded = std::collections::BTreeSet::new();
    for c in COMMANDS {
        assert!(
            wire.insert(c.wire),
            "{}: wire code {} twice",
            c.name,
            c.wire
        );
        assert!(!c.help.is_empty(), "{}: no help", c.name);
        match c.recorded {
            RecordedAs::Own(k) => {
                assert!(recorded.insert(k.code()), "{}: recorded code twice", c.name);
                assert_eq!(u32::from(k.code()), c.wire, "{}", c.name);
            }
            // Told apart by a field among its own recorded ones.
            RecordedAs::Shared(_, field) => {
                assert!(
                    c.args.iter().any(|a| a.recorded.contains(&field)),
                    "{}: {field}",
                    c.name
                );
                assert!(c.wire >= 128, "{}", c.name);
            }
            RecordedAs::NotRecorded => assert!(c.wire >= 128, "{}", c.name),
        }
        for a in c.args {
            if a.parts.is_empty() {
                assert!(unit_named(a.name), "{}: {} has no unit", c.name, a.name);
            }
            for p in a.parts {
                assert!(unit_named(p), "{}: {}.{p} has no unit", c.name, a.name);
            }
            for f in a.recorded {
                assert!(unit_named(f), "{}: recorded {f} has no unit", c.name);
            }
        }
    }
    // Every request is a row; the daemon's commands too.
    assert_eq!(COMMANDS.len(), 11 + 3);
    for d in [
        DaemonCommand::Limits,
        DaemonCommand::RecordStart,
        DaemonCommand::RecordStop,
    ] {
        assert_eq!(decode(&d.to_wire(1)), Ok(WireCommand::Daemon(d)));
    }
    // An unknown kind is an error naming it.
    let unknown = CommandMsg {
        kind: 99,
        ..CommandMsg::default()
    };
    assert_eq!(
        decode(&unknown),
        Err(CommandError::UnknownKind { kind: 99 })
    );
    assert_eq!(
        decode(&unknown).unwrap_err().to_string(),
        "unknown command kind 99"
    );
}

#[test]
fn an_older_recording_s_excite_hold_and_push_replay_from_their_old_fields() {
    use sar_msgs::msgs::{CommandKindCode, CommandLayoutCode};
    let old = |kind, f: &dyn Fn(&mut CycleInput)| {
        let mut m = CycleInput {
            command_kind: kind,
            command_layout: CommandLayoutCode::Old,
            ..CycleInput::default()
        };
        f(&mut m);
        sar_record::convert::loop_input(&m).request
    };
    assert_eq!(
        old(CommandKindCode::Hold, &|m| m.command_values[0] = 2.5),
        Some(Request::Hold { max_force_n: 2.5 })
    );
    assert_eq!(
        old(CommandKindCode::Push, &|m| m.command_values[0] = -1.5),
        Some(Request::Push { axial_n: -1.5 })
    );
    assert_eq!(
        old(CommandKindCode::Excite, &|m| {
            m.move_tip_m = [0.001, 0.002, 0.003];
            m.limits_n = [1.3, 1.7, 0.07, 16.0, 3.0, 0.0];
        }),
        Some(Request::Excite(ExciteRequest {
            amplitude_m: [0.001, 0.002, 0.003],
            freq_hz: [1.3, 1.7, 0.07],
            duration_s: 16.0,
            fade_s: 3.0,
        }))
    );
    // A set bias of an older sard gives no request.
    assert_eq!(old(CommandKindCode::SetBias, &|_| {}), None);
}
