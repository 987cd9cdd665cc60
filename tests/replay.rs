//! Record and replay (INTERFACES.md 1 and 3, `sarctl replay` and `recover`)
//! on the committed fixtures of `tests/fixtures/replay/` (made by
//! `tests/fixture_gen.rs`; the command that regenerates them is there):
//!
//! - `contact_daemon.mcap`: the daemon's controller over
//!   `random_contact_manipulator_2.toml` at 500 Hz (the sensor's rate, to
//!   keep the file small; 17.5 s: Ok, Warn, Stop);
//! - `fault_daemon.mcap`: the same over `fault_encoder_jump.toml` (3 s; the
//!   joint-jump Fault);
//! - `contact_inputs.mcap`: the contact scenario's motion script, inputs and
//!   truth only;
//! - `fault_daemon_v35.mcap`: the fault fixture as recorded before issue
//!   36's versioned change of `CycleInput` (kept as it was: an older
//!   layout still replays bit for bit).
//!
//! Each daemon fixture replays bit for bit (guard transitions included); a
//! flipped bit in one input is reported at its cycle; the inputs-only one
//! replays and gives the error figures (MODEL.md 6); a file cut short is
//! replayed up to its last chunk and recovered; every fixture and every
//! replay output is decoded by the independent Python reader.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_msgs::msgs::{DriveActionCode, Outgoing, RecorderDrops, Topic};
use sar_record::convert::REPLAY_METADATA;
use sar_record::replay::{Mode, ReplayOptions, replay, replay_file};
use sar_record::{FileOptions, McapReader, RotatingWriter, read_file};
use sar_tests::{replay_dir, scenarios_dir};

// The fixtures' generator (a module of the tests, not of the library: it
// taps the simulator's truth with the dev-only test-support crate).
#[allow(dead_code)]
mod fixture_gen;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[path = "../crates/daemon/tests/common/readers.rs"]
mod readers;

const CONTACT_DAEMON: &str = "contact_daemon.mcap";
const FAULT_DAEMON: &str = "fault_daemon.mcap";
const CONTACT_INPUTS: &str = "contact_inputs.mcap";
/// The fault fixture as `sard` recorded it before issue 36's versioned
/// change of `CycleInput` (its commands' arguments in unit-named fields, a
/// new block of fields): kept, not regenerated, so that a recording of the
/// older layout is shown to replay bit for bit.
const FAULT_DAEMON_V35: &str = "fault_daemon_v35.mcap";
/// Cycles and periods of the daemon fixtures.
const CONTACT_CYCLES: u64 = 8_750;
const CONTACT_PERIOD_NS: u64 = 2_000_000;
const FAULT_CYCLES: u64 = 3_000;
const FAULT_PERIOD_NS: u64 = 1_000_000;

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("sar-replay")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn fixture(name: &str) -> PathBuf {
    replay_dir().join(name)
}

fn options(output: Option<PathBuf>, compare: Option<&str>) -> ReplayOptions {
    let cfg = sar_config::load(&fixture("config.toml")).unwrap();
    ReplayOptions {
        output,
        compare: compare.map(str::to_owned),
        ..ReplayOptions::from_config(&cfg)
    }
}

/// Regenerates the fixtures (ignored; see `fixture_gen.rs`).
#[test]
#[ignore = "regenerates the committed fixtures: SAR_REGEN_FIXTURES=1"]
fn regenerate_fixtures() {
    assert_eq!(
        std::env::var("SAR_REGEN_FIXTURES").as_deref(),
        Ok("1"),
        "set SAR_REGEN_FIXTURES=1 to overwrite tests/fixtures/replay"
    );
    let dir = replay_dir();
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("config.toml"), sar_config::DEFAULT_TOML).unwrap();
    let contact = scenarios_dir().join("random_contact_manipulator_2.toml");
    let fault = scenarios_dir().join("fault_encoder_jump.toml");
    fixture_gen::daemon_recording(
        &contact,
        CONTACT_CYCLES,
        CONTACT_PERIOD_NS,
        &fixture_gen::contact_requests(),
        &dir.join(CONTACT_DAEMON),
    )
    .unwrap();
    fixture_gen::daemon_recording(
        &fault,
        FAULT_CYCLES,
        FAULT_PERIOD_NS,
        &[],
        &dir.join(FAULT_DAEMON),
    )
    .unwrap();
    fixture_gen::inputs_recording(&contact, &dir.join(CONTACT_INPUTS)).unwrap();
}

/// Messages per topic, by our reader.
fn counts(path: &Path) -> BTreeMap<String, u64> {
    let bytes = read_file(path).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut per_id: BTreeMap<u16, u64> = BTreeMap::new();
    for m in reader.by_ref() {
        *per_id.entry(m.unwrap().channel_id).or_default() += 1;
    }
    per_id
        .into_iter()
        .map(|(id, n)| (reader.channels()[&id].topic.clone(), n))
        .collect()
}

#[test]
fn the_fault_fixture_is_what_the_generator_makes() {
    let dir = scratch("regen");
    let out = dir.join(FAULT_DAEMON);
    fixture_gen::daemon_recording(
        &scenarios_dir().join("fault_encoder_jump.toml"),
        FAULT_CYCLES,
        FAULT_PERIOD_NS,
        &[],
        &out,
    )
    .unwrap();
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(fixture(FAULT_DAEMON)).unwrap(),
        "the generator no longer makes the committed fixture: regenerate (tests/fixture_gen.rs)"
    );
}

fn guard_events(path: &Path) -> Vec<(u64, u8, u8)> {
    let bytes = read_file(path).unwrap();
    McapReader::new(&bytes)
        .unwrap()
        .decoded()
        .filter_map(|m| match m.unwrap() {
            (_, _, Outgoing::GuardEvent(e)) => {
                Some((e.cycle, e.from_state.code(), e.to_state.code()))
            }
            _ => None,
        })
        .collect()
}

#[test]
fn daemon_fixtures_replay_bit_for_bit_with_their_guard_transitions() {
    let dir = scratch("bit_for_bit");
    for (name, cycles) in [
        (CONTACT_DAEMON, CONTACT_CYCLES),
        (FAULT_DAEMON, FAULT_CYCLES),
        (FAULT_DAEMON_V35, FAULT_CYCLES),
    ] {
        let out = dir.join(name);
        let r = replay_file(&fixture(name), &options(Some(out.clone()), None)).unwrap();
        assert_eq!(r.mode, Mode::CycleInput, "{name}");
        assert_eq!(r.from_first_cycle, Some(true), "{name}");
        assert_eq!(r.cycles, cycles, "{name}");
        assert!(r.input_complete, "{name}");
        assert_eq!(r.first_difference, None, "{name}");
        assert_eq!(r.differences, 0, "{name}");
        assert_eq!(r.compared, r.outputs, "{name}: every output compared");
        // The outputs written are the recorded ones, message for message.
        let recorded = counts(&fixture(name));
        let written = counts(&out);
        for t in sar_record::replay::OUTPUT_TOPICS {
            assert_eq!(
                recorded.get(t.name()),
                written.get(t.name()),
                "{name}: {}",
                t.name()
            );
        }
        let events = guard_events(&fixture(name));
        assert_eq!(events, guard_events(&out), "{name}");
        if name == FAULT_DAEMON_V35 {
            // The older layout's recording is the same run as today's.
            assert_eq!(events, guard_events(&fixture(FAULT_DAEMON)), "{name}");
        }
        assert!(events.len() >= 2, "{name}: {events:?}");
    }
    // The contact run reaches Stop (2) after Warn (1); the fault run Fault (3).
    let contact = guard_events(&fixture(CONTACT_DAEMON));
    assert!(contact.iter().any(|e| e.2 == 1), "{contact:?}");
    assert!(contact.iter().any(|e| e.2 == 2), "{contact:?}");
    let fault = guard_events(&fixture(FAULT_DAEMON));
    assert!(fault.iter().skip(1).any(|e| e.2 == 3), "{fault:?}");
}

/// Rewrites `input` with `change` applied to every message (same order,
/// same metadata).
fn rewrite(input: &Path, output: &Path, mut change: impl FnMut(&mut Outgoing)) {
    let bytes = read_file(input).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let _ = reader.next();
    let metadata: Vec<_> = reader
        .metadata()
        .iter()
        .filter(|m| m.name == REPLAY_METADATA)
        .map(|m| (m.name.clone(), m.metadata.clone()))
        .collect();
    let mut o = FileOptions::single(output);
    o.metadata = metadata;
    let mut w = RotatingWriter::new(o).unwrap();
    let status = RecorderDrops::default();
    for m in McapReader::new(&bytes).unwrap().decoded() {
        let (topic, _, mut msg) = m.unwrap();
        if topic == Topic::RecorderDrops {
            continue;
        }
        change(&mut msg);
        w.write(&msg, &status).unwrap();
    }
    w.close(&status).unwrap();
}

#[test]
fn a_flipped_bit_in_one_input_is_reported_at_its_cycle() {
    let dir = scratch("flipped");
    // First: the rewrite alone changes nothing.
    let same = dir.join("same.mcap");
    rewrite(&fixture(FAULT_DAEMON), &same, |_| {});
    let r = replay_file(&same, &options(None, None)).unwrap();
    assert_eq!(r.first_difference, None);
    for (cycle, bit) in [(1234u64, 0u32), (2500, 40)] {
        let flipped = dir.join(format!("flipped_{cycle}.mcap"));
        rewrite(&fixture(FAULT_DAEMON), &flipped, |m| {
            if let Outgoing::CycleInput(c) = m
                && c.cycle == cycle
            {
                c.sensor_force_n[0] = f64::from_bits(c.sensor_force_n[0].to_bits() ^ (1 << bit));
            }
        });
        let r = replay_file(&flipped, &options(None, None)).unwrap();
        let d = r.first_difference.expect("the flipped bit is not reported");
        assert_eq!(d.cycle, cycle, "{d:?}");
        assert_eq!(d.topic, "/sar/estimate/state", "{d:?}");
        assert!(
            ["ujoint_force_n", "tip_force_n", "tip_force_std_n"].contains(&d.field.as_str()),
            "{d:?}"
        );
    }
}

#[test]
fn a_changed_decision_is_reported_at_its_cycle_and_field() {
    // The step's decision is recorded beside its input: a set point (of the
    // contact fixture's move) or a drive action that differs is reported.
    let dir = scratch("decision");
    let setpoint = dir.join("setpoint.mcap");
    let mut changed = None;
    rewrite(&fixture(CONTACT_DAEMON), &setpoint, |m| {
        if let Outgoing::CycleInput(c) = m
            && c.drive_action == DriveActionCode::Setpoint
            && changed.is_none()
        {
            c.setpoint_q_m[2] += 1e-9;
            changed = Some(c.cycle);
        }
    });
    let r = replay_file(&setpoint, &options(None, None)).unwrap();
    let d = r.first_difference.unwrap();
    assert_eq!(Some(d.cycle), changed, "{d:?}");
    assert_eq!(
        (d.topic, d.field.as_str()),
        ("/sar/cycle/input", "setpoint_q_m")
    );
    assert_eq!(r.differences, 1);
    let action = dir.join("action.mcap");
    rewrite(&fixture(FAULT_DAEMON), &action, |m| {
        if let Outgoing::CycleInput(c) = m
            && c.drive_action == DriveActionCode::QuickStop
        {
            c.drive_action = DriveActionCode::None;
        }
    });
    let r = replay_file(&action, &options(None, None)).unwrap();
    let d = r.first_difference.unwrap();
    assert_eq!(
        (d.cycle, d.topic, d.field.as_str()),
        (2000, "/sar/cycle/input", "drive_action")
    );
}

#[test]
fn an_inputs_only_recording_replays_one_cycle_per_sensor_message() {
    let dir = scratch("inputs_only");
    let out = dir.join("out.mcap");
    let r = replay_file(&fixture(CONTACT_INPUTS), &options(Some(out.clone()), None)).unwrap();
    assert_eq!(r.mode, Mode::InputsOnly);
    let recorded = counts(&fixture(CONTACT_INPUTS));
    let sensors = recorded["/sar/sensor/wrench"];
    // One cycle per sensor message that has a joint message at or before it.
    assert!(
        r.cycles <= sensors && r.cycles + 2 >= sensors,
        "{} of {sensors}",
        r.cycles
    );
    let written = counts(&out);
    assert_eq!(written["/sar/estimate/state"], r.cycles);
    // The final push goes above the stop limit: the guard stops.
    let events = guard_events(&out);
    assert!(events.iter().any(|e| e.2 == 2), "{events:?}");
    // And the same outputs again: replay is deterministic.
    let again = dir.join("again.mcap");
    replay_file(
        &fixture(CONTACT_INPUTS),
        &options(Some(again.clone()), None),
    )
    .unwrap();
    let a: Vec<_> = McapReader::new(&read_file(&out).unwrap())
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect();
    let b: Vec<_> = McapReader::new(&read_file(&again).unwrap())
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect();
    assert!(a == b);
}

/// The messages of `input`, in the order `order` gives their indices,
/// written to `output` (same metadata; the recorder's drops left out).
fn reorder(input: &Path, output: &Path, order: impl FnOnce(&mut Vec<Outgoing>)) {
    let bytes = read_file(input).unwrap();
    let mut msgs: Vec<Outgoing> = McapReader::new(&bytes)
        .unwrap()
        .decoded()
        .map(|m| m.unwrap())
        .filter(|(topic, _, _)| *topic != Topic::RecorderDrops)
        .map(|(_, _, m)| m)
        .collect();
    order(&mut msgs);
    let mut w = RotatingWriter::new(FileOptions::single(output)).unwrap();
    let status = RecorderDrops::default();
    for m in &msgs {
        w.write(m, &status).unwrap();
    }
    w.close(&status).unwrap();
}

fn message_data(path: &Path) -> Vec<Vec<u8>> {
    McapReader::new(&read_file(path).unwrap())
        .unwrap()
        .map(|m| m.unwrap().data.to_vec())
        .collect()
}

/// Issue 17: an inputs-only recording is paired in a bounded window
/// (`INPUT_WINDOW` messages) instead of being held whole. Messages out of
/// log-time order within the window replay exactly as the same messages in
/// order; one further out than the window is refused, never paired wrongly.
#[test]
fn inputs_out_of_order_within_the_window_replay_as_in_order_and_beyond_it_are_refused() {
    use sar_record::replay::{INPUT_WINDOW, ReplayError};
    let dir = scratch("inputs_order");
    let in_order = dir.join("in_order.mcap");
    reorder(&fixture(CONTACT_INPUTS), &in_order, |_| {});
    let shuffled = dir.join("shuffled.mcap");
    // Blocks of 64 messages, each reversed: every sensor and joint message
    // leaves its place by up to 63.
    reorder(&fixture(CONTACT_INPUTS), &shuffled, |m| {
        for block in m.chunks_mut(64) {
            block.reverse();
        }
    });
    // One joint message moved later in the file, past `by` sensor and joint
    // messages.
    let moved = |by: usize| {
        let path = dir.join(format!("moved_{by}.mcap"));
        reorder(&fixture(CONTACT_INPUTS), &path, |m| {
            let i = m
                .iter()
                .position(|x| matches!(x, Outgoing::Joints(_)))
                .unwrap()
                + 1000;
            let i = i + m[i..]
                .iter()
                .position(|x| matches!(x, Outgoing::Joints(_)))
                .unwrap();
            let j = m.remove(i);
            // `by` sensor and joint messages (the window's) pass it.
            let is_input =
                |x: &Outgoing| matches!(x, Outgoing::Joints(_) | Outgoing::SensorWrench(_));
            let mut passed = 0;
            let mut k = i;
            while passed < by {
                passed += usize::from(is_input(&m[k]));
                k += 1;
            }
            m.insert(k, j);
        });
        path
    };
    let replayed = |input: &Path, name: &str| {
        let out = dir.join(name);
        let r = replay_file(input, &options(Some(out.clone()), None)).unwrap();
        assert_eq!(r.mode, Mode::InputsOnly);
        assert!(r.cycles > 2 * INPUT_WINDOW as u64, "{}", r.cycles);
        (r.cycles, message_data(&out))
    };
    let reference = replayed(&in_order, "out_in_order.mcap");
    assert_eq!(replayed(&shuffled, "out_shuffled.mcap"), reference);
    let near = moved(INPUT_WINDOW - 100);
    assert_eq!(replayed(&near, "out_near.mcap"), reference);
    // Moving it does change the file: the comparison can fail.
    assert_ne!(message_data(&near), message_data(&in_order));
    let far = moved(INPUT_WINDOW + 100);
    match replay_file(&far, &options(None, None)) {
        Err(e @ ReplayError::Order { window, .. }) => {
            assert_eq!(window, INPUT_WINDOW);
            assert!(e.to_string().contains("time order"), "{e}");
        }
        other => panic!("{other:?}"),
    }
}

/// A replay that neither writes nor compares counts each decision where it
/// lies instead of making its messages (the fast path of `sarctl replay`'s
/// speed): its report is the one of the full replay, cycle for cycle, and so
/// is the tip-force series it keeps.
#[test]
fn a_replay_without_output_or_comparison_reports_what_the_full_replay_does() {
    let full = ReplayOptions {
        keep_series: true,
        ..options(None, Some("/sar/sim/tip_wrench_truth"))
    };
    let bare = ReplayOptions {
        check_recorded: false,
        ..full.clone()
    };
    for name in [CONTACT_DAEMON, FAULT_DAEMON] {
        let a = replay_file(&fixture(name), &full).unwrap();
        let b = replay_file(&fixture(name), &bare).unwrap();
        assert!(a.compared > 0 && b.compared == 0, "{name}");
        assert_eq!(
            (
                a.cycles,
                a.outputs,
                a.input_complete,
                &a.series,
                a.comparison.as_ref().map(|c| c.pairs)
            ),
            (
                b.cycles,
                b.outputs,
                b.input_complete,
                &b.series,
                b.comparison.as_ref().map(|c| c.pairs)
            ),
            "{name}"
        );
        assert!(!a.series.is_empty(), "{name}");
    }
}

#[test]
fn compare_gives_the_error_measure_on_the_contact_scenario() {
    for name in [CONTACT_INPUTS, CONTACT_DAEMON] {
        let r = replay_file(
            &fixture(name),
            &options(None, Some("/sar/sim/tip_wrench_truth")),
        )
        .unwrap();
        let c = r.comparison.expect("figures");
        eprintln!(
            "{name}: {} pairs ({} left out); e_ra {:.4} {:.4} {:.4}; RMS {:.3} {:.3} {:.3} N; max {:.3} {:.3} {:.3} N",
            c.pairs,
            c.left_out,
            c.axes[0].e_ra,
            c.axes[1].e_ra,
            c.axes[2].e_ra,
            c.axes[0].rms_n,
            c.axes[1].rms_n,
            c.axes[2].rms_n,
            c.axes[0].max_n,
            c.axes[1].max_n,
            c.axes[2].max_n
        );
        assert!(c.pairs > 5000, "{name}: {}", c.pairs);
        for a in c.axes {
            assert!(a.e_ra.is_finite() && a.e_ra > 0.0, "{name}: {a:?}");
            assert!(a.rms_n > 0.0 && a.rms_n < 2.0, "{name}: {a:?}");
            assert!(a.max_n >= a.rms_n, "{name}: {a:?}");
        }
    }
    // A topic that is not there is refused.
    let e = replay_file(&fixture(CONTACT_INPUTS), &options(None, Some("/nothing"))).unwrap_err();
    assert!(e.to_string().contains("/nothing"), "{e}");
}

#[test]
fn a_file_cut_short_replays_to_its_last_chunk_and_is_recovered() {
    let dir = scratch("cut");
    let bytes = std::fs::read(fixture(CONTACT_DAEMON)).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let r = replay_file(&cut, &options(None, None)).unwrap();
    assert!(!r.input_complete);
    assert!(r.stopped.is_some());
    assert!(r.cycles > 500 && r.cycles < CONTACT_CYCLES, "{}", r.cycles);
    assert_eq!(r.first_difference, None);
    // Recovered: complete, the same messages.
    let recovered = dir.join("recovered.mcap");
    sarctl::cli::recover::run(&cut, Some(&recovered), false).unwrap();
    let r2 = replay_file(&recovered, &options(None, None)).unwrap();
    assert!(r2.input_complete);
    assert_eq!(r2.cycles, r.cycles);
    assert_eq!(r2.first_difference, None);
    assert_eq!(counts(&recovered), {
        let b = read_file(&cut).unwrap();
        let mut reader = McapReader::new(&b).unwrap();
        let mut per_id: BTreeMap<u16, u64> = BTreeMap::new();
        for m in reader.by_ref().map_while(Result::ok) {
            *per_id.entry(m.channel_id).or_default() += 1;
        }
        per_id
            .into_iter()
            .map(|(id, n)| (reader.channels()[&id].topic.clone(), n))
            .collect::<BTreeMap<_, _>>()
    });
    // Never over the input, under any spelling.
    let e = sarctl::cli::recover::run(&cut, Some(&cut), false).unwrap_err();
    assert!(e.contains("refusing to write over the input"), "{e}");
    let spelled = dir.join(".").join("cut.mcap");
    let e = sarctl::cli::recover::run(&cut, Some(&spelled), false).unwrap_err();
    assert!(e.contains("refusing to write over the input"), "{e}");
    assert_eq!(std::fs::read(&cut).unwrap(), &bytes[..bytes.len() / 2]);
}

/// Messages per topic by the Python reader (`mcap` + `mcap-ros2-support`,
/// installed on first use under `target/test-readers/`).
fn python_counts(file: &Path) -> Option<BTreeMap<String, u64>> {
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../crates/record/tests/read_recording.py");
    let out = readers::python().arg(&script).arg(file).output().unwrap();
    assert!(
        out.status.success(),
        "the Python reader failed on {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let mut counts = BTreeMap::new();
    for line in String::from_utf8(out.stdout).unwrap().lines() {
        if let Some(rest) = line.strip_prefix("msg ") {
            let topic = rest.split('|').next().unwrap().to_owned();
            *counts.entry(topic).or_default() += 1;
        }
    }
    Some(counts)
}

#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
fn the_python_reader_decodes_every_fixture_and_every_replay_output() {
    let dir = scratch("python");
    let mut files = vec![
        fixture(CONTACT_DAEMON),
        fixture(FAULT_DAEMON),
        fixture(CONTACT_INPUTS),
    ];
    for name in [FAULT_DAEMON, CONTACT_INPUTS, CONTACT_DAEMON] {
        let out = dir.join(name);
        replay_file(&fixture(name), &options(Some(out.clone()), None)).unwrap();
        files.push(out);
    }
    // One reader process per file, all at once: each decodes every message
    // of its file in Python (the longest test of this binary when they ran
    // one after the other). The same files, the same comparison.
    std::thread::scope(|s| {
        let readers: Vec<_> = files
            .iter()
            .map(|f| s.spawn(move || (f, python_counts(f))))
            .collect();
        for r in readers {
            let (f, py) = r.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            let Some(py) = py else {
                return;
            };
            assert_eq!(py, counts(f), "{}", f.display());
        }
    });
}

#[test]
fn replay_of_bytes_in_memory_equals_replay_of_the_file() {
    let bytes = read_file(&fixture(FAULT_DAEMON)).unwrap();
    let a = replay(&bytes, &options(None, None)).unwrap();
    let b = replay_file(&fixture(FAULT_DAEMON), &options(None, None)).unwrap();
    assert_eq!(a, b);
    // The output is never the input.
    let e = replay_file(
        &fixture(FAULT_DAEMON),
        &options(Some(fixture(FAULT_DAEMON)), None),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("refusing to write over the input"),
        "{e}"
    );
}
