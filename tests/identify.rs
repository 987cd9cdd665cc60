//! `sarctl identify` on the committed fixtures (`tests/fixtures/identify/`,
//! made from the simulator's scenarios by `tests/identify_fixtures.rs`):
//! m, c and B against the scenarios' truth with the configured support 2 mm
//! off (Table 2 article protocol and cone set, Table 3 hung masses), the
//! refusal of poses that cannot be trusted, the write-back keeping comments,
//! the minimum configuration of INTERFACES.md 2, the figure, the fixtures'
//! reproducibility and their decoding by an independent reader (Python's
//! `mcap` + `mcap-ros2-support`).
//!
//! `--nocapture` prints the table of errors.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::needless_range_loop
)]

use sar_config::Config;
use sar_tests::identify_fixtures::{self, TABLE2};
use sarctl::identify::{
    self, Identified, IdentifyError, IdentifyOptions, find_dwells, identify_dwells, plot, writeback,
};
use std::path::PathBuf;

#[path = "../crates/daemon/tests/common/readers.rs"]
mod readers;

/// The true support of every scenario.
const TRUE_B: [f64; 3] = [0.45, 0.20, 0.0];
/// The tip length of every scenario, m.
const LENGTH_M: f64 = 0.35;

/// The configured B: 2 mm from the true one along (1, -1, 1)/sqrt(3).
fn off_2mm() -> [f64; 3] {
    let d = 2e-3 / 3f64.sqrt();
    [TRUE_B[0] + d, TRUE_B[1] - d, TRUE_B[2] + d]
}

/// The minimum keys of INTERFACES.md 2 (and nothing else), with comments.
fn minimal_config(support: [f64; 3]) -> String {
    format!(
        r#"# The robot of INTERFACES.md 2, minimum keys only.
[geometry]
gravity = [0.0, -9.80665, 0.0]         # m/s^2, base frame
support = [{}, {}, {}]   # B, base frame, m (measured by hand)
p_home = [0.0, 0.0, 0.0]               # P at q = 0, base frame (x, y, z), m
ujoint_offset = [0.0, -0.08, 0.0]      # a_off = A - P, base frame, m
sensor_offset = [0.0, -0.03, 0.0]      # s_off = S - P, base frame, m
sensor_rotation = [[1.0, 0.0, 0.0],    # R_0s, row-major; its columns are the
                   [0.0, 1.0, 0.0],    # sensor's axes written in the base frame
                   [0.0, 0.0, 1.0]]

[manipulator]
name = "under-test"
length_m = 0.35                        # L
offset_m = 0.0                         # d
mass_kg = 2.0                          # m (written by `sarctl identify`)
com_m = 0.09                           # c (written by `sarctl identify`)

[sensor]
noise_n = [0.2, 0.2, 0.8]              # force noise std per sensor axis, N
"#,
        support[0], support[1], support[2]
    )
}

fn config(support: [f64; 3]) -> Config {
    sar_config::parse(&minimal_config(support), "test").unwrap_or_else(|e| panic!("{e}"))
}

fn fixture(name: &str) -> PathBuf {
    identify_fixtures::dir().join(format!("{name}.mcap"))
}

fn bytes(name: &str) -> Vec<u8> {
    std::fs::read(fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn run(name: &str, support: [f64; 3]) -> Identified {
    identify::identify(&bytes(name), &config(support), &IdentifyOptions::default())
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Prints one row: relative errors of m and c (with their reported std, %),
/// errors of B in mm (std or held).
fn print_row(name: &str, r: &Identified, m: f64, c: f64) {
    let b: Vec<String> = (0..3)
        .map(|k| {
            let std = r.support_std_m[k].map_or("held".into(), |s| format!("{:.3}", s * 1e3));
            format!("{:+.3} ({std})", (r.support_m[k] - TRUE_B[k]) * 1e3)
        })
        .collect();
    println!(
        "{name:<30} m {:+.3} % ({:.3})  c {:+.3} % ({:.3})  B mm {}  f {:.3} N  chi2 {:.2}  cond {:.1}  {} poses",
        (r.mass_kg - m) / m * 100.0,
        r.mass_std_kg / m * 100.0,
        (r.com_m - c) / c * 100.0,
        r.com_std_m / c * 100.0,
        b.join(" "),
        r.friction_n.unwrap_or(f64::NAN),
        r.chi2_dof,
        r.condition,
        r.poses
    );
}

/// The error is within `n` reported standard errors and within `bound`.
fn assert_within(who: &str, what: &str, err: f64, std: f64, n: f64, bound: f64) {
    assert!(
        err.abs() <= n * std,
        "{who}: {what} error {err:e} beyond {n} std ({std:e})"
    );
    assert!(
        err.abs() <= bound,
        "{who}: {what} error {err:e} beyond {bound:e}"
    );
}

/// The article's protocol (rod horizontal at the support's height, 10 poses),
/// B configured 2 mm off: m and c within 4 reported standard errors (the
/// errors of one seeded run; 4 std leaves a false failure below 1e-4) and
/// within 1 %; B_x and B_y within 4 std and 0.3 mm; B_z held at its
/// configured value (the protocol cannot determine it, MODEL.md 5.1), so it
/// stays 1.15 mm off and is reported null.
#[test]
fn table2_article_protocol_with_the_support_2mm_off() {
    for (k, (_, m, c)) in TABLE2.iter().enumerate() {
        let name = format!("identify_manipulator_{}", k + 1);
        let r = run(&name, off_2mm());
        print_row(&name, &r, *m, *c);
        assert_eq!(r.poses, 10, "{name}");
        assert_within(&name, "m", r.mass_kg - m, r.mass_std_kg, 4.0, 0.01 * m);
        assert_within(&name, "c", r.com_m - c, r.com_std_m, 4.0, 0.01 * c);
        for i in 0..2 {
            let std = r.support_std_m[i].unwrap();
            assert_within(&name, "B", r.support_m[i] - TRUE_B[i], std, 4.0, 0.3e-3);
        }
        assert_eq!(r.support_std_m[2], None, "{name}: B_z held");
        assert_eq!(r.support_m[2], off_2mm()[2], "{name}: B_z as configured");
        assert!(r.chi2_dof < 2.0, "{name}: chi2 {}", r.chi2_dof);
        let json = r.to_json(None);
        assert!(json["support_std_m"][2].is_null(), "{name}: {json}");
        assert!(r.to_text(None).contains("B_z = 0.00115 m held"), "{name}");
    }
}

/// The cone set (20 poses), B configured 2 mm off: every component of B is
/// determined and comes back within 0.3 mm, m and c within 0.3 % (the
/// simulation study's bound, MODEL.md 5.1), each also within 4 reported std.
#[test]
fn table2_cone_set_recovers_a_support_2mm_off() {
    for (k, (_, m, c)) in TABLE2.iter().enumerate() {
        let name = format!("identify_cone_manipulator_{}", k + 1);
        let r = run(&name, off_2mm());
        print_row(&name, &r, *m, *c);
        assert_eq!(r.poses, 20, "{name}");
        assert_within(&name, "m", r.mass_kg - m, r.mass_std_kg, 4.0, 3e-3 * m);
        assert_within(&name, "c", r.com_m - c, r.com_std_m, 4.0, 3e-3 * c);
        for i in 0..3 {
            let std = r.support_std_m[i].expect("determined");
            assert_within(&name, "B", r.support_m[i] - TRUE_B[i], std, 4.0, 0.3e-3);
        }
        assert!(r.chi2_dof < 2.0, "{name}: chi2 {}", r.chi2_dof);
        let f = r.friction_n.unwrap();
        assert!(
            (f - 0.3).abs() <= 4.0 * r.friction_std_n.unwrap(),
            "{name}: f {f}"
        );
    }
}

/// The article's Table 3: a known mass hung at the tip of manipulator 2 comes
/// back as the difference of two identifications (article protocol, B 2 mm
/// off, so both share B_z's error) within 4 combined std and 1 %, acting at L.
#[test]
fn table3_the_hung_masses_come_back() {
    let (_, m2, c2) = TABLE2[1];
    let base = run("identify_manipulator_2", off_2mm());
    print_row("identify_manipulator_2", &base, m2, c2);
    for (name, hung_kg) in [
        ("table3_mass_0_51kg", 0.51),
        ("table3_mass_1_03kg", 1.03),
        ("table3_mass_2_04kg", 2.04),
    ] {
        let r = run(name, off_2mm());
        let m = m2 + hung_kg;
        let c = (m2 * c2 + hung_kg * LENGTH_M) / m;
        print_row(name, &r, m, c);
        let found = r.mass_kg - base.mass_kg;
        let std = r.mass_std_kg.hypot(base.mass_std_kg);
        println!(
            "  hung {hung_kg} kg: identified {found:.4} +- {std:.4} kg ({:+.3} %)",
            (found - hung_kg) / hung_kg * 100.0
        );
        assert_within(name, "hung mass", found - hung_kg, std, 4.0, 0.01 * hung_kg);
        let lever = (r.moment_kgm - base.moment_kgm) / found;
        assert!(
            (lever - LENGTH_M).abs() < 0.01 * LENGTH_M,
            "{name}: lever {lever}"
        );
    }
}

/// Too few poses, and poses that cannot tell m from M (all at one support
/// distance with the rod horizontal), are refused with one line that names
/// the poses to add; so is a fit whose chi-square shows a model error (a
/// wrong tare).
#[test]
fn poses_that_cannot_be_trusted_are_refused() {
    let cfg = config(off_2mm());
    let options = IdentifyOptions::default();
    let dwells = find_dwells(&bytes("identify_manipulator_1"), &cfg, &options.dwell).unwrap();
    assert_eq!(dwells.len(), 10);
    let check = |e: &IdentifyError| {
        let text = e.to_string();
        assert!(!text.contains('\n'), "one line: {text}");
        assert!(text.contains("add static poses"), "{text}");
        assert!(text.contains("cone set"), "{text}");
        text
    };
    // Three poses for three unknowns (m, M, f).
    let e = identify_dwells(&dwells[..3], &cfg, &options).unwrap_err();
    assert!(
        matches!(e, IdentifyError::TooFewPoses { found: 3, .. }),
        "{e}"
    );
    check(&e);
    // The first (a = 0.04 m, outward) and the last (a = 0.04 m, inward) pose,
    // twice each: one distance, rod horizontal: m and M cannot be told apart.
    // With the true B the rod is exactly horizontal: rank deficient.
    let same_a = [dwells[0], dwells[9], dwells[0], dwells[9]];
    let e = identify_dwells(&same_a, &config(TRUE_B), &options).unwrap_err();
    assert!(matches!(e, IdentifyError::IllConditioned { .. }), "{e}");
    println!("refused: {}", check(&e));
    // With B 2 mm off the rod looks tilted by 1.6 degrees: the axial row
    // carries a little of m, and the fit gives a mass below zero.
    let e = identify_dwells(&same_a, &cfg, &options).unwrap_err();
    println!("refused: {}", check(&e));
    // The article's protocol (condition about 18) under a limit of 10.
    let strict = IdentifyOptions {
        max_condition: 10.0,
        ..options
    };
    let e = identify_dwells(&dwells, &cfg, &strict).unwrap_err();
    assert!(
        matches!(e, IdentifyError::IllConditioned { limit: 10.0, .. }),
        "{e}"
    );
    check(&e);
    // A tare 1 N off across gravity on the cone set: the model cannot fit.
    let dwells = find_dwells(&bytes("identify_cone_manipulator_2"), &cfg, &options.dwell).unwrap();
    let wrong = IdentifyOptions {
        tare_n: [1.0, 0.0, 1.0],
        ..options
    };
    let e = identify_dwells(&dwells, &cfg, &wrong).unwrap_err();
    assert!(matches!(e, IdentifyError::PoorFit { .. }), "{e}");
    println!("refused: {}", check(&e));
}

/// The tare given (the bias measured with the rod detached) is removed: a
/// recording whose readings carry a bias b, identified with the tare b,
/// gives the same m and c as the unbiased one.
#[test]
fn a_given_tare_is_removed() {
    let cfg = config(off_2mm());
    let options = IdentifyOptions::default();
    let mut dwells =
        find_dwells(&bytes("identify_cone_manipulator_2"), &cfg, &options.dwell).unwrap();
    let plain = identify_dwells(&dwells, &cfg, &options).unwrap();
    let bias = [1.5, -2.0, 0.7];
    for d in &mut dwells {
        let k = f64::from(d.sensor_samples);
        for (s, b) in d.force_sum_n.iter_mut().zip(bias) {
            *s += k * b;
        }
    }
    let tared = identify_dwells(
        &dwells,
        &cfg,
        &IdentifyOptions {
            tare_n: bias,
            ..options
        },
    )
    .unwrap();
    assert!((tared.mass_kg - plain.mass_kg).abs() < 1e-9);
    assert!((tared.com_m - plain.com_m).abs() < 1e-9);
}

/// The write-back replaces m, c and B in the text and nothing else: the
/// comments, the key order and the layout survive, and the file is still a
/// valid configuration holding the new values.
#[test]
fn the_write_back_keeps_comments_and_key_order() {
    let text = minimal_config(off_2mm());
    let r = run("identify_cone_manipulator_2", off_2mm());
    let new = writeback::write_back(&text, r.mass_kg, r.com_m, r.support_m).unwrap();
    // Every line but the three written is unchanged, in order.
    let (old_lines, new_lines): (Vec<&str>, Vec<&str>) =
        (text.lines().collect(), new.lines().collect());
    assert_eq!(old_lines.len(), new_lines.len());
    for (o, n) in old_lines.iter().zip(&new_lines) {
        let written = ["support =", "mass_kg =", "com_m ="]
            .iter()
            .any(|k| o.starts_with(k));
        if written {
            // The comment after the value survives.
            let comment = &o[o.find('#').unwrap()..];
            assert!(n.ends_with(comment), "{n}");
            assert_ne!(o, n);
        } else {
            assert_eq!(o, n);
        }
    }
    assert!(new.contains("mass_kg = 2.59"), "{new}");
    let cfg = sar_config::parse(&new, "written").unwrap();
    let profile = cfg.estimator.profile;
    assert!((profile.mass_kg() - r.mass_kg).abs() < 1e-5);
    assert!((profile.com_m() - r.com_m).abs() < 1e-6);
    let b = cfg.estimator.calibration.support_m();
    for k in 0..3 {
        assert!((b[k] - r.support_m[k]).abs() < 1e-6);
        assert!((b[k] - TRUE_B[k]).abs() < 0.3e-3);
    }
}

/// The INTERFACES.md 3 keys, named as written, in the JSON object.
#[test]
fn the_json_has_the_interface_keys() {
    let r = run("identify_cone_manipulator_2", off_2mm());
    let json = r.to_json(Some("robot.toml"));
    for key in [
        "mass_kg",
        "com_m",
        "mass_std_kg",
        "com_std_m",
        "support_m",
        "support_std_m",
        "friction_n",
        "chi2_dof",
        "poses",
        "residual_rms_n",
        "condition",
        "method",
    ] {
        assert!(json.get(key).is_some(), "{key} missing: {json}");
    }
    assert_eq!(json["poses"], 20);
    assert_eq!(json["support_m"].as_array().unwrap().len(), 3);
}

/// The figure is an SVG with its text (axis names, caption) drawn as text.
#[test]
fn the_figure_is_an_svg_with_text() {
    let r = run("identify_manipulator_2", off_2mm());
    let svg = plot::svg(&r).unwrap();
    assert!(svg.starts_with("<svg"), "{}", &svg[..80.min(svg.len())]);
    assert!(svg.contains("<text"), "no text elements");
    assert!(svg.contains("1/a"), "no axis name");
    assert!(svg.contains("residual"), "no residual panel");
}

/// The fixtures are what the generator makes today (it is deterministic):
/// one regenerated into a temporary folder equals the committed one byte
/// for byte.
#[test]
fn a_fixture_regenerates_byte_for_byte() {
    let all = identify_fixtures::all();
    let f = all
        .iter()
        .find(|f| f.name == "identify_manipulator_1")
        .unwrap();
    let dir = std::env::temp_dir().join(format!("sar-identify-fixture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = identify_fixtures::write(f, &dir);
    let made = std::fs::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        made == bytes(&f.name),
        "tests/fixtures/identify/{}.mcap differs from what the generator makes: run `cargo run -p sar-tests --example make_identify_fixtures`",
        f.name
    );
}

const PY_READER: &str = r#"
import sys
try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as e:
    print(f"missing Python package: {e}", file=sys.stderr)
    sys.exit(3)
for path in sys.argv[1:]:
    counts = {}
    fsum = [0.0, 0.0, 0.0]
    qsum = [0.0, 0.0, 0.0]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, m in reader.iter_decoded_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/sar/sensor/wrench":
                stamp = m.header.stamp.sec * 1000000000 + m.header.stamp.nanosec
                assert stamp == message.log_time, (stamp, message.log_time)
                assert m.header.frame_id == "sensor"
                fsum = [fsum[0] + m.wrench.force.x, fsum[1] + m.wrench.force.y, fsum[2] + m.wrench.force.z]
            elif channel.topic == "/sar/joints":
                assert list(m.name) == ["q1", "q2", "q3"], m.name
                qsum = [a + b for a, b in zip(qsum, m.position)]
    print(path.split("/")[-1], counts.get("/sar/sensor/wrench", 0), counts.get("/sar/joints", 0),
          " ".join(repr(x) for x in fsum + qsum))
"#;

/// Python's `mcap` + `mcap-ros2-support` decode every fixture from the
/// schemas the files carry: the same number of sensor and joint messages as
/// our reader, header stamps equal to log times, joint names q1..q3, and the
/// same sums of the forces and positions. The packages are installed on
/// first use under `target/test-readers/` (scripts/setup-test-readers.sh);
/// ignored when built with `SAR_SKIP_PYTHON=1`.
#[test]
#[cfg_attr(sar_skip_python, ignore = "SAR_SKIP_PYTHON=1")]
fn the_fixtures_decode_with_the_python_reader() {
    use sar_msgs::msgs::{ActiveJointState, WrenchStamped};
    use sar_record::McapReader;
    let names: Vec<String> = identify_fixtures::all()
        .into_iter()
        .map(|f| f.name)
        .collect();
    let paths: Vec<PathBuf> = names.iter().map(|n| fixture(n)).collect();
    let out = sar_test_support::process::run_ok(
        readers::python().arg("-c").arg(PY_READER).args(&paths),
        "the Python reader failed",
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), names.len());
    for (name, line) in names.iter().zip(lines) {
        let data = bytes(name);
        let wrenches: Vec<WrenchStamped> = McapReader::new(&data)
            .unwrap()
            .typed::<WrenchStamped>("/sar/sensor/wrench")
            .map(|m| m.unwrap().1)
            .collect();
        let joints: Vec<ActiveJointState> = McapReader::new(&data)
            .unwrap()
            .typed::<ActiveJointState>("/sar/joints")
            .map(|m| m.unwrap().1)
            .collect();
        let f: Vec<f64> = (0..3)
            .map(|k| wrenches.iter().map(|w| w.force_n[k]).sum())
            .collect();
        let q: Vec<f64> = (0..3)
            .map(|k| joints.iter().map(|j| j.q_m[k]).sum())
            .collect();
        let fields: Vec<&str> = line.split(' ').collect();
        assert_eq!(fields[0], format!("{name}.mcap"));
        assert_eq!(
            fields[1].parse::<usize>().unwrap(),
            wrenches.len(),
            "{name}"
        );
        assert_eq!(fields[2].parse::<usize>().unwrap(), joints.len(), "{name}");
        assert!(wrenches.len() > 1000 && joints.len() > 1000, "{name}");
        // Summed in the same order from the same bits: equal exactly.
        for (k, x) in f.iter().chain(&q).enumerate() {
            let py: f64 = fields[3 + k].parse().unwrap();
            assert_eq!(py.to_bits(), x.to_bits(), "{name}: sum {k}");
        }
    }
}

// ---------------------------------------------------------------------------
// `sarctl identify --dynamic` (MODEL.md 10) on recordings of the simulator
// with the plant in motion (`sar_tests::dynamic_recordings`).

mod dynamic {
    use super::*;
    use sar_estimator::identification::dynamic::InertialParameters;
    use sar_tests::dynamic_recordings::{self, CENTRE_M, ROD, SENSOR_LATENCY_S};
    use sarctl::identify::dynamic::{DynamicError, DynamicOptions, identify_file};
    use sarctl::identify::excitation::{Excitation, ExcitationSpec};

    fn scratch(tag: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("sar-identify-dynamic-{}-{tag}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The excitation of the README's figures: `duration_s` at up to
    /// 0.04 m/s and 1 m/s^2 per axis.
    fn excitation(config: &Config, duration_s: f64) -> Excitation {
        Excitation::plan(
            &ExcitationSpec::around(CENTRE_M, duration_s, (0.04, 1.0, 10.0)),
            config,
        )
        .unwrap()
    }

    fn options() -> DynamicOptions {
        DynamicOptions {
            sensor_latency_s: SENSOR_LATENCY_S,
            ..DynamicOptions::default()
        }
    }

    /// Three rods whose I_perp is m L^2 / 12 times 0.7, 1 and 1.5 (scenario
    /// seeds 2611, 2612, 2613), 60 s of the excitation each: I_perp within
    /// 5 %, m and c within 0.2 % (the static identification's accuracy on
    /// the fixtures), each within 3 standard errors; the standard error
    /// close to what the plan promised. A fourth run has an adapter of
    /// 0.3 kg between the sensor and the U-joint (seed 2615), given to the
    /// identification (`--adapter-mass-kg`).
    #[test]
    fn three_rods_on_the_simulator_in_motion() {
        let dir = scratch("rods");
        let config = config(TRUE_B);
        let (m, c, l) = ROD;
        let ex = excitation(&config, 60.0);
        println!(
            "excitation: amplitudes {:?} m, peak speeds {:?} m/s, peak accelerations {:?} m/s^2",
            ex.amplitude_m, ex.peak_speed_mps, ex.peak_accel_mps2
        );
        for (factor, seed, adapter_kg) in [
            (0.7, 2611, 0.0),
            (1.0, 2612, 0.0),
            (1.5, 2613, 0.0),
            (1.0, 2615, 0.3),
        ] {
            let i_true = factor * m * l * l / 12.0;
            let text = dynamic_recordings::scenario_text(i_true, adapter_kg, seed);
            let name = format!("excitation_{seed}");
            let path = dynamic_recordings::write(&text, &ex, &dir, &name);
            let o = DynamicOptions {
                adapter_mass_kg: adapter_kg,
                ..options()
            };
            let r = identify_file(&path, &config, &o).unwrap_or_else(|e| panic!("{e}"));
            let truth = InertialParameters {
                mass_kg: m,
                com_m: c,
                inertia_perp_kgm2: i_true,
                friction_n: 0.0,
            };
            let plan = ex.expected(&config, &truth, 500.0, 1e5).unwrap();
            let f = &r.fit;
            let i_err = f.inertia_perp_kgm2 / i_true - 1.0;
            let (m_err, c_err) = (f.mass_kg / m - 1.0, f.com_m / c - 1.0);
            println!(
                "I_perp x{factor} (adapter {adapter_kg} kg): err {:+.2} % (std {:.2} %, planned {:.2} %, condition planned {:.1}), m err {:+.3} % (std {:.3} %), c err {:+.3} % (std {:.3} %), f {:.3} N, condition {:.1}, chi2/dof {:.3}, residual {:.3} N, {} samples, peak {:.3} m/s^2",
                100.0 * i_err,
                100.0 * f.inertia_perp_std_kgm2 / i_true,
                100.0 * plan.inertia_perp_model_std_kgm2 / i_true,
                plan.condition,
                100.0 * m_err,
                100.0 * f.mass_std_kg / m,
                100.0 * c_err,
                100.0 * f.com_std_m / c,
                f.friction_n.unwrap_or(f64::NAN),
                f.condition,
                f.chi2_dof,
                f.residual_rms_n,
                f.samples,
                r.peak_accel_mps2
            );
            assert!(i_err.abs() < 0.05, "I_perp x{factor}: {i_err}");
            assert!((f.inertia_perp_kgm2 - i_true).abs() < 3.0 * f.inertia_perp_std_kgm2);
            assert!(
                m_err.abs() < 2e-3 && c_err.abs() < 2e-3,
                "m {m_err}, c {c_err}"
            );
            assert!((f.mass_kg - m).abs() < 3.0 * f.mass_std_kg, "m x{factor}");
            assert!((f.com_m - c).abs() < 3.0 * f.com_std_m, "c x{factor}");
            let ratio = f.inertia_perp_model_std_kgm2 / plan.inertia_perp_model_std_kgm2;
            assert!(
                (0.8..1.25).contains(&ratio),
                "planned vs achieved std: {ratio}"
            );
            let svg = sarctl::identify::plot_dynamic::svg(
                &r,
                config.estimator.calibration.gravity_mps2().into(),
            )
            .unwrap();
            assert!(
                svg.starts_with("<svg") && svg.contains("I_perp ="),
                "the figure"
            );
            std::fs::remove_file(&path).unwrap();
        }
    }

    /// Issue 34: the adapter's mass estimated with I_perp. A rod of 1.6x
    /// m L^2 / 12 with a 0.35 kg adapter the configuration leaves out (seed
    /// 2617), and a rod without adapter (seed 2618), 60 s of the excitation
    /// each, the adapter not given (the configuration's 0 where the fit
    /// starts): I_perp within 5 % and 3 of its standard errors, m_s within
    /// 3 of its standard errors and 10 g of the truth, m and c as before;
    /// the adapter's correlation with the other unknowns below 0.95 (the
    /// excitation separates it). Held at 0 instead (`--adapter-mass-kg 0`),
    /// the adapter reads on I_perp.
    #[test]
    fn an_adapter_left_out_is_found_with_i_perp() {
        let dir = scratch("adapter");
        let config = config(TRUE_B);
        let (m, c, l) = ROD;
        let ex = excitation(&config, 60.0);
        for (factor, seed, adapter_kg) in [(1.6, 2617, 0.35), (1.0, 2618, 0.0)] {
            let i_true = factor * m * l * l / 12.0;
            let text = dynamic_recordings::scenario_text(i_true, adapter_kg, seed);
            let path = dynamic_recordings::write(&text, &ex, &dir, &format!("adapter_{seed}"));
            let r = identify_file(&path, &config, &options()).unwrap_or_else(|e| panic!("{e}"));
            let held = DynamicOptions {
                estimate_adapter: false,
                ..options()
            };
            let h = identify_file(&path, &config, &held).unwrap_or_else(|e| panic!("{e}"));
            let f = &r.fit;
            let s_std = f.adapter_mass_std_kg.unwrap();
            let corr = f.adapter_correlation.unwrap();
            let i_err = f.inertia_perp_kgm2 / i_true - 1.0;
            let s_err = f.adapter_mass_kg - adapter_kg;
            println!(
                "I_perp x{factor}, adapter {adapter_kg} kg not configured: m_s {:.4} +- {:.4} kg (err {:+.4} kg), I_perp err {:+.2} % (std {:.2} %), m err {:+.3} %, c err {:+.3} %, correlation {:.3}, condition {:.1}, chi2/dof {:.3}; with m_s held at 0: I_perp err {:+.2} % (std {:.2} %), chi2/dof {:.3}",
                f.adapter_mass_kg,
                s_std,
                s_err,
                100.0 * i_err,
                100.0 * f.inertia_perp_std_kgm2 / i_true,
                100.0 * (f.mass_kg / m - 1.0),
                100.0 * (f.com_m / c - 1.0),
                corr,
                f.condition,
                f.chi2_dof,
                100.0 * (h.fit.inertia_perp_kgm2 / i_true - 1.0),
                100.0 * h.fit.inertia_perp_std_kgm2 / i_true,
                h.fit.chi2_dof,
            );
            assert!(s_err.abs() < 3.0 * s_std, "m_s {s_err} vs std {s_std}");
            assert!(s_err.abs() < 0.01, "m_s {s_err}");
            assert!(i_err.abs() < 0.05, "I_perp {i_err}");
            assert!((f.inertia_perp_kgm2 - i_true).abs() < 3.0 * f.inertia_perp_std_kgm2);
            assert!((f.mass_kg - m).abs() < 3.0 * f.mass_std_kg, "m");
            assert!((f.com_m - c).abs() < 3.0 * f.com_std_m, "c");
            assert!(corr < 0.95, "the adapter is not separated: {corr}");
            let json = r.to_json(None);
            assert_eq!(
                json["adapter_mass_kg"],
                serde_json::json!(f.adapter_mass_kg)
            );
            assert!(r.to_text(None).contains("adapter m_s = "));
            if adapter_kg > 0.0 {
                let held_err = h.fit.inertia_perp_kgm2 / i_true - 1.0;
                assert!(
                    held_err > 0.1,
                    "the adapter held at 0 reads on I_perp: {held_err}"
                );
            }
            std::fs::remove_file(&path).unwrap();
        }
    }

    /// The spread over seeds (measured once for the README, `--ignored
    /// --nocapture`): the mean I_perp error against its standard error.
    #[test]
    #[ignore]
    fn inertia_error_over_seeds() {
        let dir = scratch("seeds");
        let config = config(TRUE_B);
        let (m, _, l) = ROD;
        let ex = excitation(&config, 60.0);
        for factor in [0.7, 1.0] {
            let i_true = factor * m * l * l / 12.0;
            let mut errs = Vec::new();
            for seed in 2700..2710 {
                let text = dynamic_recordings::scenario_text(i_true, 0.0, seed);
                let path = dynamic_recordings::write(&text, &ex, &dir, &format!("seed_{seed}"));
                let r = identify_file(&path, &config, &options()).unwrap();
                errs.push(r.fit.inertia_perp_kgm2 / i_true - 1.0);
                std::fs::remove_file(&path).unwrap();
            }
            let n = errs.len() as f64;
            let mean = errs.iter().sum::<f64>() / n;
            let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            println!(
                "I_perp x{factor}: mean error {:+.3} %, spread {:.3} % over {} seeds",
                100.0 * mean,
                100.0 * sd,
                errs.len()
            );
        }
    }

    /// A recording at rest: "the recording holds no excitation"; a sweep
    /// along the rod only (the rod never turns): refused with its condition
    /// number. Each message is one line.
    #[test]
    fn no_excitation_and_a_singular_fit_are_refused() {
        let dir = scratch("refused");
        let config = config(TRUE_B);
        let text = dynamic_recordings::scenario_text(0.0265, 0.0, 2614);
        let mut rest = ExcitationSpec::around(CENTRE_M, 8.0, (0.04, 1.0, 10.0));
        for s in &mut rest.sines {
            s.amplitude_m = 0.0;
        }
        let rest = Excitation::plan(&rest, &config).unwrap();
        let path = dynamic_recordings::write(&text, &rest, &dir, "rest");
        let e = identify_file(&path, &config, &options()).unwrap_err();
        assert!(matches!(e, DynamicError::NoExcitation { .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.starts_with("the recording holds no excitation: "),
            "{msg}"
        );
        assert!(!msg.contains('\n'));

        let mut along = ExcitationSpec::around(CENTRE_M, 8.0, (0.04, 1.0, 10.0));
        along.sines[0].amplitude_m = 0.0;
        along.sines[1].amplitude_m = 0.0;
        along.sines[2].freq_hz = 1.1;
        let along = Excitation::plan(&along, &config).unwrap();
        let path = dynamic_recordings::write(&text, &along, &dir, "along");
        let e = identify_file(&path, &config, &options()).unwrap_err();
        match &e {
            DynamicError::IllConditioned { condition, limit } => {
                assert!(condition > limit, "{condition}")
            }
            other => panic!("{other}"),
        }
        let msg = e.to_string();
        assert!(msg.contains("condition number"), "{msg}");
        assert!(!msg.contains('\n'));
    }

    /// The messages of a recording, decoded, in file order.
    fn messages(path: &std::path::Path) -> Vec<sar_record::Outgoing> {
        let bytes = std::fs::read(path).unwrap();
        sar_record::McapReader::new(&bytes)
            .unwrap()
            .decoded()
            .map(|m| m.unwrap().2)
            .collect()
    }

    /// `msgs` written in their order into `dir/{name}.mcap`.
    fn rewrite(msgs: &[sar_record::Outgoing], dir: &std::path::Path, name: &str) -> PathBuf {
        use sar_msgs::msgs::RecorderDrops;
        let tmp = dir.join(format!(".{name}-tmp"));
        let mut w =
            sar_record::RotatingWriter::new(sar_record::FileOptions::new(&tmp, name)).unwrap();
        for m in msgs {
            w.write(m, &RecorderDrops::default()).unwrap();
        }
        w.close(&RecorderDrops::default()).unwrap();
        let out = dir.join(format!("{name}.mcap"));
        std::fs::rename(&w.files()[0], &out).unwrap();
        std::fs::remove_dir(&tmp).unwrap();
        out
    }

    /// Issue 35, findings 12 and 13: a recording the fit cannot trust is
    /// refused, naming what is wrong, in one line. Before: one NaN sensor
    /// sample refused the whole fit as a "non-finite motion sample";
    /// joint stamps out of order were sorted silently; sensor stamps
    /// shifted on every other sample (3 ms, or 1.2 ms at 500 Hz) were
    /// fitted silently; a recording whose excitation ended in a Fault (and
    /// the drives' quick stop) was fitted. Each of these is made from one
    /// good recording of the simulator (which fits).
    #[test]
    fn a_recording_the_fit_cannot_trust_is_refused_naming_what_is_wrong() {
        use sar_msgs::msgs::{GuardEvent, GuardStateCode, Topic};
        use sar_record::Outgoing;
        let dir = scratch("untrusted");
        let config = config(TRUE_B);
        let text = dynamic_recordings::scenario_text(0.0265, 0.0, 2616);
        let ex = excitation(&config, 12.0);
        let good = dynamic_recordings::write(&text, &ex, &dir, "good");
        identify_file(&good, &config, &options()).unwrap_or_else(|e| panic!("{e}"));
        let msgs = messages(&good);
        let refused = |msgs: &[Outgoing], name: &str| {
            let path = rewrite(msgs, &dir, name);
            let e = identify_file(&path, &config, &options()).unwrap_err();
            let text = e.to_string();
            println!("{name}: {text}");
            assert!(
                !text.contains('\n') && !text.contains("motion sample"),
                "{text}"
            );
            e
        };
        let sensor_at = |k: usize| {
            msgs.iter()
                .enumerate()
                .filter(|(_, m)| m.topic() == Topic::SensorWrench)
                .nth(k)
                .unwrap()
                .0
        };
        // One NaN force: named, with its place and stamp.
        let mut nan = msgs.clone();
        let i = sensor_at(3000);
        let Outgoing::SensorWrench(w) = &mut nan[i] else {
            unreachable!()
        };
        w.force_n[1] = f64::NAN;
        let stamp = w.stamp_ns;
        let e = refused(&nan, "nan");
        assert!(
            matches!(e, DynamicError::NonFinite { topic: "/sar/sensor/wrench", index: 3000, stamp_ns, .. } if stamp_ns == stamp),
            "{e}"
        );
        // Two joint samples swapped: the stamps go back.
        let mut swapped = msgs.clone();
        let joints: Vec<usize> = msgs
            .iter()
            .enumerate()
            .filter(|(_, m)| m.topic() == Topic::Joints)
            .map(|(i, _)| i)
            .collect();
        swapped.swap(joints[5000], joints[5001]);
        let e = refused(&swapped, "swapped");
        assert!(
            matches!(
                e,
                DynamicError::StampsBack {
                    topic: "/sar/joints",
                    index: 5001,
                    ..
                }
            ),
            "{e}"
        );
        // Sensor stamps shifted on every other sample: 3 ms (they go
        // back: the sensor's period is 2 ms), then 1.2 ms (off the grid).
        for (shift_ns, name) in [(3_000_000u64, "shift_3ms"), (1_200_000, "shift_1_2ms")] {
            let mut shifted = msgs.clone();
            let mut k = 0;
            for m in &mut shifted {
                if let Outgoing::SensorWrench(w) = m {
                    if k % 2 == 1 {
                        w.stamp_ns += shift_ns;
                    }
                    k += 1;
                }
            }
            let e = refused(&shifted, name);
            match (shift_ns, &e) {
                (
                    3_000_000,
                    DynamicError::StampsBack {
                        topic: "/sar/sensor/wrench",
                        ..
                    },
                ) => {}
                (
                    1_200_000,
                    DynamicError::IrregularStamps {
                        topic: "/sar/sensor/wrench",
                        irregular,
                        steps,
                        ..
                    },
                ) => {
                    assert!(2 * *irregular + 1 >= *steps, "{e}")
                }
                _ => panic!("{name}: {e}"),
            }
        }
        // The guard leaves Ok (a Fault) half way through the excitation.
        let mut faulted = msgs.clone();
        let i = sensor_at(3000);
        let at_ns = faulted[i].stamp_ns();
        faulted.insert(
            i,
            Outgoing::GuardEvent(GuardEvent {
                stamp_ns: at_ns,
                cycle: 6000,
                from_state: GuardStateCode::Ok,
                to_state: GuardStateCode::Fault,
                reason_code: 1,
                ..GuardEvent::default()
            }),
        );
        let e = refused(&faulted, "faulted");
        assert!(
            matches!(
                e,
                DynamicError::GuardLeftOk {
                    state: "fault",
                    cycle: 6000,
                    ..
                }
            ),
            "{e}"
        );
        // A transition that does not leave Ok (the first reset, before
        // the excitation) is no reason to refuse.
        let mut reset = msgs.clone();
        reset.insert(
            0,
            Outgoing::GuardEvent(GuardEvent {
                stamp_ns: msgs[0].stamp_ns(),
                cycle: 1,
                from_state: GuardStateCode::Fault,
                to_state: GuardStateCode::Ok,
                ..GuardEvent::default()
            }),
        );
        let path = rewrite(&reset, &dir, "reset");
        identify_file(&path, &config, &options()).unwrap_or_else(|e| panic!("{e}"));
    }
}
