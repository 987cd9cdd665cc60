//! Before and after a refactor, the same decisions: the daemon's real
//! `Controller` over the simulator, for 10 seeds of 8,000 cycles each, with a
//! seeded schedule of every operator request (valid and invalid arguments,
//! in every motion), recorded with every message of the daemon's recorder
//! (inputs, decisions, replies, guard events, estimates, snapshots).
//!
//! Made once on the code before a refactor and once after, the two sets of
//! recordings are compared message by message:
//!
//! ```text
//! SAR_DECISIONS_DIR=/tmp/before cargo test -p sar-tests --test decisions write_decisions -- --ignored
//! (the refactor)
//! SAR_DECISIONS_DIR=/tmp/after  cargo test -p sar-tests --test decisions write_decisions -- --ignored
//! SAR_DECISIONS_BEFORE=/tmp/before SAR_DECISIONS_AFTER=/tmp/after \
//!   cargo test -p sar-tests --test decisions compare_decisions -- --ignored
//! ```
//!
//! Every message must be byte for byte the same, with one exception a
//! versioned schema change may make: a `/sar/cycle/input` message whose
//! bytes differ must decode to the same step input (`convert::loop_input`:
//! the request with its arguments, wherever the schema keeps them) and the
//! same fields apart from the command's arguments. The tests that are not
//! ignored show the comparison itself on short runs: a run equals itself,
//! and one changed request is found at its cycle.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

#[allow(dead_code)]
mod fixture_gen;

use sar_estimator::Vec3;
use sar_estimator::guard::ForceLimits;
use sar_loop::control::Request;
use sar_loop::excite::ExciteRequest;
use sar_msgs::msgs::{CycleInput, Outgoing, Topic};
use sar_record::convert;
use sar_record::{McapReader, read_file};
use sar_tests::scenarios_dir;
use std::path::{Path, PathBuf};

/// Seeds (one recording each) and cycles per recording.
const SEEDS: u64 = 10;
const CYCLES: u64 = 8_000;
/// The loop's period, ns.
const PERIOD_NS: u64 = 1_000_000;

/// SplitMix64: a small seeded generator (no dependency, the same numbers on
/// every machine).
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}

/// The scenario of a seed: contact, the demo, a fault, an offset support, a
/// heavier manipulator, in turn.
fn scenario(seed: u64) -> PathBuf {
    let names = [
        "random_contact_manipulator_2.toml",
        "../crates/daemon/src/demo_scenario.toml",
        "fault_encoder_jump.toml",
        "random_contact_offset_manipulator_2.toml",
        "mount_manipulator_mass_plus_10pct.toml",
    ];
    scenarios_dir().join(names[(seed % names.len() as u64) as usize])
}

/// A tip near the built-in robot's working point, m.
fn tip(rng: &mut Rng) -> Vec3 {
    Vec3::new(
        0.6 + rng.range(-0.02, 0.02),
        0.2 + rng.range(-0.02, 0.02),
        0.002 + rng.range(-0.01, 0.01),
    )
}

/// One request of each kind in turn, with seeded arguments (some outside
/// what the step accepts: a refusal is a decision too).
fn request(kind: u64, rng: &mut Rng) -> Request {
    match kind {
        0 => Request::Reset,
        1 => Request::Tare,
        2 => Request::MoveTip { tip_m: tip(rng) },
        3 => {
            // The built-in limits scaled: mostly accepted, some above their
            // ceiling.
            let [w, s, wa, sa, wl, sl] = ForceLimits::DEFAULT.to_array();
            let (k_warn, k_stop) = (rng.range(0.4, 1.0), rng.range(0.8, 1.1));
            Request::SetLimits(ForceLimits::from_array([
                w * k_warn,
                s * k_stop,
                wa * k_warn,
                sa * k_stop,
                wl * k_warn,
                sl * k_stop,
            ]))
        }
        4 => Request::BackOut {
            distance_m: rng.range(-0.01, 0.06),
        },
        5 => Request::GuardedMove {
            tip_m: tip(rng),
            max_force_n: rng.range(0.5, 9.0),
        },
        6 => Request::Hold {
            max_force_n: rng.range(0.5, 12.0),
        },
        7 => Request::Push {
            axial_n: rng.range(0.2, 6.0),
        },
        8 => Request::Position,
        _ => Request::Excite(ExciteRequest {
            amplitude_m: core::array::from_fn(|_| rng.range(0.0, 0.0025)),
            freq_hz: core::array::from_fn(|_| rng.range(0.2, 1.2)),
            duration_s: rng.range(0.5, 4.0),
            fade_s: rng.range(0.05, 0.5),
        }),
    }
}

/// A seed's schedule: about one request every 150 cycles, each kind in
/// turn from a seeded start, at seeded cycles.
fn requests(seed: u64, cycles: u64) -> Vec<(u64, Request)> {
    let mut rng = Rng(seed);
    let mut kind = rng.below(10);
    let mut cycle = 50 + rng.below(100);
    let mut out = Vec::new();
    while cycle < cycles {
        out.push((cycle, request(kind, &mut rng)));
        kind = (kind + 1 + rng.below(3)) % 10;
        cycle += 20 + rng.below(260);
    }
    out
}

fn write_seed(dir: &Path, seed: u64, cycles: u64, schedule: &[(u64, Request)]) -> PathBuf {
    let path = dir.join(format!("seed-{seed:02}.mcap"));
    fixture_gen::daemon_recording_at_level(&scenario(seed), cycles, PERIOD_NS, schedule, &path, 0)
        .unwrap();
    path
}

/// A cycle input without its command's arguments (compared through
/// `convert::loop_input` instead).
fn without_command_arguments(m: &CycleInput) -> CycleInput {
    let mut m = *m;
    m.command_values = [0.0; 6];
    m.command_arg = 0;
    m.move_tip_m = [0.0; 3];
    m.limits_n = [0.0; 6];
    m.back_out_m = 0.0;
    m.move_max_force_n = 0.0;
    // Issue 36's versioned block: the layout and the unit-named fields.
    m.command_layout = sar_msgs::msgs::CommandLayoutCode::Old;
    m.hold_max_force_n = 0.0;
    m.push_axial_n = 0.0;
    m.excite_amplitude_m = [0.0; 3];
    m.excite_freq_hz = [0.0; 3];
    m.excite_duration_s = 0.0;
    m.excite_fade_s = 0.0;
    m
}

/// Whether two `/sar/cycle/input` messages whose bytes differ carry the
/// same step input and the same other fields.
fn same_cycle_input(a: &[u8], b: &[u8]) -> bool {
    let (Ok(Outgoing::CycleInput(a)), Ok(Outgoing::CycleInput(b))) = (
        Outgoing::decode(Topic::CycleInput, a),
        Outgoing::decode(Topic::CycleInput, b),
    ) else {
        return false;
    };
    convert::loop_input(&a) == convert::loop_input(&b)
        && without_command_arguments(&a) == without_command_arguments(&b)
}

/// The differences between two recordings, as "topic at log time: why"
/// lines (at most `max`), and how many messages were compared.
fn differences(a: &Path, b: &Path, max: usize) -> (Vec<String>, u64) {
    let (bytes_a, bytes_b) = (read_file(a).unwrap(), read_file(b).unwrap());
    let mut ra = McapReader::new(&bytes_a).unwrap();
    let mut rb = McapReader::new(&bytes_b).unwrap();
    let (mut diffs, mut compared) = (Vec::new(), 0u64);
    loop {
        let (ma, mb) = (ra.next().map(Result::unwrap), rb.next().map(Result::unwrap));
        let (ma, mb) = match (ma, mb) {
            (None, None) => break,
            (Some(_), None) | (None, Some(_)) => {
                diffs.push(format!("{} messages, then one file ends", compared));
                break;
            }
            (Some(ma), Some(mb)) => (ma, mb),
        };
        compared += 1;
        let topic_a = ra.channels()[&ma.channel_id].topic.clone();
        let topic_b = rb.channels()[&mb.channel_id].topic.clone();
        let why = if topic_a != topic_b || ma.log_time_ns != mb.log_time_ns {
            Some(format!("{topic_b} at {} instead", mb.log_time_ns))
        } else if ma.data == mb.data
            || (topic_a == Topic::CycleInput.name() && same_cycle_input(&ma.data, &mb.data))
        {
            None
        } else {
            Some("other bytes".to_owned())
        };
        if let Some(why) = why
            && diffs.len() < max
        {
            diffs.push(format!("{topic_a} at {}: {why}", ma.log_time_ns));
        }
    }
    (diffs, compared)
}

fn env_dir(name: &str) -> PathBuf {
    PathBuf::from(std::env::var(name).unwrap_or_else(|_| panic!("set {name} to a directory")))
}

#[test]
#[ignore = "writes the before/after recordings: SAR_DECISIONS_DIR=DIR"]
fn write_decisions() {
    let dir = env_dir("SAR_DECISIONS_DIR");
    std::fs::create_dir_all(&dir).unwrap();
    for seed in 1..=SEEDS {
        let path = write_seed(&dir, seed, CYCLES, &requests(seed, CYCLES));
        println!("{}: {}", path.display(), replies(&path));
    }
}

/// What the requests of each recording in SAR_DECISIONS_DIR became (a
/// change of plant may change decisions on purpose: compare the tallies).
#[test]
#[ignore = "prints what the requests became in SAR_DECISIONS_DIR"]
fn tally_decisions() {
    let dir = env_dir("SAR_DECISIONS_DIR");
    for seed in 1..=SEEDS {
        let path = dir.join(format!("seed-{seed:02}.mcap"));
        println!("{}: {}", path.display(), replies(&path));
    }
}

/// What the requests of a recording became: "kind/status x count" (the
/// recorded codes), so that a schedule that only meets refusals shows.
fn replies(path: &Path) -> String {
    let bytes = read_file(path).unwrap();
    let mut tally = std::collections::BTreeMap::<(u8, u8), u32>::new();
    for m in McapReader::new(&bytes).unwrap().decoded() {
        if let (_, _, Outgoing::CycleInput(c)) = m.unwrap()
            && c.command_kind as u8 != 0
        {
            *tally
                .entry((c.command_kind as u8, c.reply_status))
                .or_default() += 1;
        }
    }
    let parts: Vec<String> = tally
        .iter()
        .map(|((k, s), n)| format!("{k}/{s}x{n}"))
        .collect();
    parts.join(" ")
}

#[test]
#[ignore = "compares SAR_DECISIONS_BEFORE with SAR_DECISIONS_AFTER"]
fn compare_decisions() {
    let (before, after) = (
        env_dir("SAR_DECISIONS_BEFORE"),
        env_dir("SAR_DECISIONS_AFTER"),
    );
    let (mut total, mut bytes) = (0u64, 0u64);
    for seed in 1..=SEEDS {
        let name = format!("seed-{seed:02}.mcap");
        let (a, b) = (before.join(&name), after.join(&name));
        let (diffs, compared) = differences(&a, &b, 5);
        assert!(diffs.is_empty(), "{name}: {diffs:#?}");
        total += compared;
        bytes += std::fs::metadata(&a).unwrap().len();
    }
    println!("{SEEDS} recordings, {total} messages, {bytes} bytes: the same decisions");
}

/// Short runs: the schedule has every kind; a run equals itself; one
/// request's argument changed is found, at its cycle's input and after.
#[test]
fn the_comparison_finds_a_changed_request_and_nothing_in_a_rerun() {
    const SHORT: u64 = 1_500;
    let schedule = requests(3, SHORT);
    let kinds: std::collections::HashSet<_> = requests(1, CYCLES)
        .iter()
        .map(|(_, r)| core::mem::discriminant(r))
        .collect();
    assert_eq!(kinds.len(), 10, "a seed's schedule has every request kind");
    let dir =
        sar_test_support::files::scratch_in(env!("CARGO_TARGET_TMPDIR"), "sar-decisions", "short");
    let (one, two, changed) = (dir.join("one"), dir.join("two"), dir.join("changed"));
    for d in [&one, &two, &changed] {
        std::fs::create_dir_all(d).unwrap();
    }
    let a = write_seed(&one, 3, SHORT, &schedule);
    let b = write_seed(&two, 3, SHORT, &schedule);
    let (diffs, compared) = differences(&a, &b, 5);
    assert!(diffs.is_empty(), "{diffs:#?}");
    assert!(compared > SHORT, "{compared} messages");

    let mut other = schedule.clone();
    let (cycle, _) = other[0];
    other[0].1 = Request::SetLimits(ForceLimits::from_array([3.0, 4.0, 3.0, 4.0, 3.0, 4.0]));
    let c = write_seed(&changed, 3, SHORT, &other);
    let (diffs, _) = differences(&a, &c, 1);
    let first = diffs.first().expect("a changed request is a difference");
    assert!(
        first.starts_with(&format!(
            "{} at {}",
            Topic::CycleInput.name(),
            1_000_000_000 + cycle * PERIOD_NS
        )),
        "{first}"
    );
}

/// Issue 34 section 3's false alarm, kept away: the demo (seeds 2 and 7, a
/// still support with a small tip force at one pose before its contact
/// rises) never has force control refused. Before the support watch took a
/// contact as an unknown, seed 2's Push at cycle 1175, just after the first
/// reset, was refused "the support has shifted" (about 6 mm along the rod
/// read from 0.5 N at one pose). Hold (13) and Push (14) are refused here
/// only for the reasons main refuses them (status 10, "refused for another
/// reason", never).
#[test]
fn the_demo_still_support_never_refuses_force_control() {
    let dir =
        sar_test_support::files::scratch_in(env!("CARGO_TARGET_TMPDIR"), "sar-decisions", "demo");
    std::fs::create_dir_all(&dir).unwrap();
    for seed in [2, 7] {
        let path = write_seed(&dir, seed, CYCLES, &requests(seed, CYCLES));
        let bytes = read_file(&path).unwrap();
        let mut force_requests = 0;
        for m in McapReader::new(&bytes).unwrap().decoded() {
            if let (_, _, Outgoing::CycleInput(c)) = m.unwrap()
                && matches!(c.command_kind as u8, 13 | 14)
                && c.reply_status != sar_msgs::msgs::REPLY_NONE
            {
                force_requests += 1;
                assert_ne!(c.reply_status, 10, "seed {seed}: {}", replies(&path));
            }
        }
        assert!(force_requests > 3, "seed {seed}: {}", replies(&path));
    }
}
