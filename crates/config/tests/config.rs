//! The configuration file: the minimum of INTERFACES.md 2 works, defaults are
//! as documented, and every bad file is refused naming the file, key and line.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
use sar_config::{self as config, AxesDriver, ConfigError, SensorDriver};

const MINIMUM: &str = r#"
[geometry]
gravity = [0.0, -9.80665, 0.0]
support = [0.45, 0.20, 0.0]
p_home = [0.0, 0.0, 0.0]
ujoint_offset = [0.0, -0.08, 0.0]
sensor_offset = [0.0, -0.03, 0.0]
sensor_rotation = [[1.0, 0.0, 0.0],
                   [0.0, 1.0, 0.0],
                   [0.0, 0.0, 1.0]]

[manipulator]
name = "manipulator-2"
length_m = 0.35
offset_m = 0.0
mass_kg = 2.593
com_m = 0.103

[sensor]
noise_n = [0.2, 0.2, 0.8]
"#;

fn bad(text: &str) -> ConfigError {
    config::parse(text, "robot.toml").unwrap_err()
}

/// The 1-based line of the last line of `text` that contains `needle`.
fn line_of(text: &str, needle: &str) -> Option<usize> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.contains(needle))
        .map(|(i, _)| i + 1)
        .last()
}

fn expect(text: &str, key: &str, at: Option<&str>, words: &str) {
    let line = at.map(|needle| line_of(text, needle).unwrap());
    let e = bad(text);
    let msg = e.to_string();
    assert_eq!(e.key(), Some(key), "{msg}");
    assert_eq!(e.line(), line, "{msg}");
    assert!(msg.starts_with("robot.toml: "), "{msg}");
    assert!(msg.contains(words), "{msg} lacks {words:?}");
}

#[test]
fn the_minimum_file_works_with_the_documented_defaults() {
    let c = config::parse(MINIMUM, "robot.toml").unwrap();
    assert_eq!(c.manipulator_name, "manipulator-2");
    assert_eq!(c.loop_.rate_hz, 1000.0);
    assert_eq!(c.loop_.period_ns, 1_000_000);
    assert_eq!(c.loop_.priority, 80);
    assert_eq!(c.loop_.cpu, None);
    let g = c.estimator.guard.limits();
    assert_eq!((g.force.warn_total_n, g.force.stop_total_n), (10.0, 15.0));
    assert_eq!((g.force.warn_axial_n, g.force.stop_axial_n), (8.0, 12.0));
    assert_eq!(
        (g.force.warn_lateral_n, g.force.stop_lateral_n),
        (6.0, 10.0)
    );
    assert_eq!(g.debounce_samples, 3);
    assert_eq!(g.max_sensor_age_ns, 10_000_000);
    assert_eq!(c.estimator.tip.max_std_n, 2.0);
    assert!(c.estimator.plausibility.limits().torque.is_some());
    assert_eq!(c.sensor_driver, SensorDriver::Sim);
    assert_eq!(c.axes_driver, AxesDriver::Sim);
    assert_eq!(c.estimator.calibration.support_m().x, 0.45);
    assert_eq!(c.estimator.profile.mass_kg(), 2.593);
}

#[test]
fn the_builtin_configuration_equals_the_minimum_with_defaults_but_the_demo_keys() {
    let text = config::DEFAULT_TOML
        .lines()
        .filter(|l| !l.contains("# DEMO"))
        .collect::<Vec<_>>()
        .join("\n");
    let b = config::parse(&text, "builtin without the DEMO lines").unwrap();
    let m = config::parse(MINIMUM, "m").unwrap();
    assert_eq!(b.loop_, m.loop_);
    assert_eq!(b.axes, m.axes);
    assert_eq!(b.estimator.guard, m.estimator.guard);
    assert_eq!(b.estimator.plausibility, m.estimator.plausibility);
    let demo = config::builtin().unwrap();
    assert_eq!(demo.estimator.plausibility.limits().max_counter_gap, 25);
}

#[test]
fn every_section_can_be_set() {
    let text = format!(
        "{MINIMUM}
[loop]
rate_hz = 4000.0
priority = 90
cpu = 1
[guard]
warn_total_n = 5.0
stop_total_n = 7.0
[plausibility]
torque_max_sigma = 0.0
[tip]
max_std_n = 3.0
[drivers.sensor]
kind = \"rdt\"
address = \"192.168.1.1:49152\"
counts_per_n = 10000.0
counts_per_nm = 100000.0
[drivers.axes]
kind = \"canopen\"
interface = \"can0\"
node_ids = [1, 2, 3]
lead_m = 0.01
counts_per_turn = 4096
"
    );
    let c = config::parse(&text, "robot.toml").unwrap();
    assert_eq!(c.loop_.period_ns, 250_000);
    assert_eq!(c.loop_.priority, 90);
    assert_eq!(c.loop_.cpu, Some(1));
    assert_eq!(c.estimator.guard.force_limits().stop_total_n, 7.0);
    assert_eq!(c.estimator.guard.force_limits().stop_axial_n, 12.0);
    assert!(c.estimator.plausibility.limits().torque.is_none());
    assert_eq!(c.estimator.tip.max_std_n, 3.0);
    assert_eq!(
        c.sensor_driver,
        SensorDriver::Rdt {
            address: "192.168.1.1:49152".parse().unwrap(),
            counts_per_n: 10000.0,
            counts_per_nm: 100000.0
        }
    );
    assert!(matches!(
        c.axes_driver,
        AxesDriver::Canopen {
            node_ids: [1, 2, 3],
            ..
        }
    ));
}

#[test]
fn a_missing_key_is_named() {
    let text = MINIMUM.replace("mass_kg = 2.593\n", "");
    expect(
        &text,
        "manipulator.mass_kg",
        Some("[manipulator]"),
        "missing key",
    );
    let text = MINIMUM.replace("[sensor]\nnoise_n = [0.2, 0.2, 0.8]\n", "");
    expect(&text, "sensor", None, "missing key");
}

#[test]
fn an_unknown_key_is_refused_with_its_line() {
    let text = format!("{MINIMUM}\n[guard]\nstop_totl_n = 12.0\n");
    expect(
        &text,
        "guard.stop_totl_n",
        Some("stop_totl_n"),
        "unknown key",
    );
    let text = MINIMUM.replace("[sensor]\n", "[sensor]\nnoise = 1.0\n");
    expect(&text, "sensor.noise", Some("noise = 1.0"), "unknown key");
    let text = format!("{MINIMUM}\n[lop]\nrate_hz = 1000.0\n");
    expect(&text, "lop", Some("[lop]"), "unknown key");
}

#[test]
fn a_wrong_type_is_named() {
    let text = MINIMUM.replace("length_m = 0.35", "length_m = \"0.35\"");
    expect(
        &text,
        "manipulator.length_m",
        Some("length_m"),
        "invalid type",
    );
    let text = format!("{MINIMUM}\n[loop]\npriority = 80.5\n");
    expect(&text, "loop.priority", Some("priority"), "invalid type");
}

#[test]
fn non_finite_numbers_are_refused() {
    let text = MINIMUM.replace("com_m = 0.103", "com_m = nan");
    expect(
        &text,
        "manipulator.com_m",
        Some("com_m"),
        "not a finite number",
    );
    let text = MINIMUM.replace("support = [0.45, 0.20, 0.0]", "support = [0.45, inf, 0.0]");
    expect(
        &text,
        "geometry.support[1]",
        Some("support ="),
        "not a finite number",
    );
}

#[test]
fn a_rotation_that_is_not_orthonormal_is_refused() {
    let text = MINIMUM.replace("[[1.0, 0.0, 0.0],", "[[1.0, 0.1, 0.0],");
    expect(
        &text,
        "geometry.sensor_rotation",
        Some("sensor_rotation"),
        "orthonormal",
    );
    let text = MINIMUM.replace("[0.0, 0.0, 1.0]]", "[0.0, 0.0, -1.0]]");
    expect(
        &text,
        "geometry.sensor_rotation",
        Some("sensor_rotation"),
        "reflection",
    );
}

#[test]
fn a_support_the_carriage_cannot_reach_is_refused() {
    let text = MINIMUM.replace("support = [0.45, 0.20, 0.0]", "support = [2.0, 0.20, 0.0]");
    expect(
        &text,
        "geometry.support",
        Some("support ="),
        "cannot reach the support",
    );
}

#[test]
fn bad_limits_are_refused() {
    let text = format!("{MINIMUM}\n[guard]\nwarn_total_n = 20.0\n");
    expect(&text, "guard.stop_total_n", Some("[guard]"), "warn limit");
    let text = format!("{MINIMUM}\n[loop]\nrate_hz = 50.0\n");
    expect(&text, "loop.rate_hz", Some("rate_hz"), "100..=10000");
    let text = format!("{MINIMUM}\n[guard]\ndebounce_samples = 0\n");
    expect(&text, "guard.debounce_samples", Some("debounce"), "1..=100");
    // Every key's range comes first: a negative length is outside it.
    let text = MINIMUM.replace("length_m = 0.35", "length_m = -0.35");
    expect(
        &text,
        "manipulator.length_m",
        Some("length_m"),
        "within 0.1..=1.5 m, got -0.35",
    );
}

/// `[record] mode`: "full" by default, "inputs" the lean mode (with the
/// configured devices' scales), anything else refused naming the key, its
/// line and the values.
#[test]
fn the_record_mode_is_full_or_inputs() {
    let c = config::parse(MINIMUM, "robot.toml").unwrap();
    assert_eq!(c.record.mode, config::RecordMode::Full);
    assert_eq!(c.record.scales, config::DeviceScales::default());
    let text = format!(
        "{MINIMUM}\n[record]\nmode = \"inputs\"\n[drivers.sensor]\nkind = \"rdt\"\naddress = \"10.0.0.1:49152\"\ncounts_per_n = 10000.0\ncounts_per_nm = 100000.0\n[drivers.axes]\nkind = \"canopen\"\ninterface = \"can0\"\nnode_ids = [1, 2, 3]\nlead_m = 0.01\ncounts_per_turn = 4096\n"
    );
    let c = config::parse(&text, "robot.toml").unwrap();
    assert_eq!(c.record.mode, config::RecordMode::Inputs);
    assert_eq!(
        c.record.scales,
        config::DeviceScales {
            force_counts_per_n: 10000.0,
            torque_counts_per_nm: 100000.0,
            joint_m_per_count: 0.01 / 4096.0,
        }
    );
    for v in ["\"lean\"", "\"Inputs\"", "\"\""] {
        let text = format!("{MINIMUM}\n[record]\nmode = {v}\n");
        expect(
            &text,
            "record.mode",
            Some("mode ="),
            "must be \"full\" or \"inputs\"",
        );
    }
    let text = format!("{MINIMUM}\n[record]\nmode = 1\n");
    expect(&text, "record.mode", Some("mode ="), "string");
}

#[test]
fn driver_keys_are_checked() {
    let text = format!(
        "{MINIMUM}\n[drivers.sensor]\nkind = \"rdt\"\naddress = \"sensor\"\ncounts_per_n = 1.0\ncounts_per_nm = 1.0\n"
    );
    expect(
        &text,
        "drivers.sensor.address",
        Some("address"),
        "IP address",
    );
    let text =
        format!("{MINIMUM}\n[drivers.sensor]\nkind = \"rdt\"\naddress = \"10.0.0.1:49152\"\n");
    expect(
        &text,
        "drivers.sensor.counts_per_n",
        Some("[drivers.sensor]"),
        "missing key",
    );
    let text = format!(
        "{MINIMUM}\n[drivers.axes]\nkind = \"canopen\"\ninterface = \"can0\"\nnode_ids = [1, 2, 2]\nlead_m = 0.01\ncounts_per_turn = 4096\n"
    );
    expect(&text, "drivers.axes.node_ids", Some("node_ids"), "differ");
    let text = format!("{MINIMUM}\n[drivers.axes]\nkind = \"ethercat\"\n");
    expect(&text, "drivers.axes.kind", Some("ethercat"), "canopen");
    let text = format!("{MINIMUM}\n[drivers.sensor]\nkind = \"sim\"\naddress = \"10.0.0.1:1\"\n");
    expect(
        &text,
        "drivers.sensor.address",
        Some("address"),
        "simulated",
    );
}

#[test]
fn a_syntax_error_and_a_missing_file_name_the_file() {
    let e = bad("[geometry\n");
    assert!(
        e.to_string().starts_with("robot.toml: not valid TOML"),
        "{e}"
    );
    let e = config::load(std::path::Path::new("/nonexistent/robot.toml")).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("/nonexistent/robot.toml: cannot read"),
        "{e}"
    );
}

/// `[force_control]` (issue 15): a bad value names its key, and settings
/// that would not keep the phase margin at the stiffest tissue are refused
/// naming the damping to raise.
#[test]
fn force_control_settings_are_checked_by_key() {
    let with = |line: &str| format!("{MINIMUM}\n[force_control]\n{line}\n");
    let text = with("lateral_mass_kg = 0.0");
    expect(
        &text,
        "force_control.lateral_mass_kg",
        Some("lateral_mass_kg"),
        "within 0.001..=100 kg, got 0",
    );
    let text = with("axial_damping_n_s_per_m = 1.0");
    expect(
        &text,
        "force_control.axial_damping_n_s_per_m",
        Some("axial_damping_n_s_per_m"),
        "phase",
    );
    let c = config::parse(&with("max_speed_mps = 0.004"), "robot.toml").unwrap();
    assert_eq!(c.force_control.limits().max_speed_mps, 0.004);
    // The axes' servo (issue 26): its lag is part of the margin; a slow
    // one is refused naming the damping and the servo's keys, a bad one
    // under its own key.
    let limits = *config::parse(MINIMUM, "robot.toml")
        .unwrap()
        .force_control
        .limits();
    assert_eq!(
        (limits.servo_bandwidth_hz, limits.servo_damping),
        (30.0, 0.7)
    );
    let axes = |line: &str| format!("{MINIMUM}\n[axes]\n{line}\n");
    let text = axes("servo_bandwidth_hz = 10.0");
    expect(
        &text,
        "force_control.axial_damping_n_s_per_m",
        None,
        "[axes] servo_bandwidth_hz and servo_damping",
    );
    let text = axes("servo_damping = 0.0");
    expect(
        &text,
        "axes.servo_damping",
        Some("servo_damping"),
        "within 0.1..=2",
    );
    let c = config::parse(&axes("servo_bandwidth_hz = 60.0"), "robot.toml").unwrap();
    assert_eq!(c.force_control.limits().servo_bandwidth_hz, 60.0);
}

#[test]
fn the_guard_keys_are_the_force_limits_names_in_wire_order() {
    use sar_estimator::guard::ForceLimits;
    // Six distinct valid limits, each under its name of ForceLimits::NAMES:
    // each lands in its place of ForceLimits::to_array (the wire's order).
    let values = [11.0, 16.0, 9.0, 13.0, 7.0, 11.5];
    let mut text = format!("{MINIMUM}\n[guard]\n");
    for (name, v) in ForceLimits::NAMES.iter().zip(values) {
        text.push_str(&format!("{name} = {v:?}\n"));
    }
    let c = config::parse(&text, "robot.toml").unwrap();
    assert_eq!(c.estimator.guard.force_limits().to_array(), values);
    // And the built-in file spells every one of them.
    for name in ForceLimits::NAMES {
        assert!(
            config::DEFAULT_TOML.contains(&format!("\n{name} = ")),
            "{name}"
        );
    }
}

// ---------------------------------------------------------------------------
// Issue 25, finding 4: plausible configurations only.

/// `length_m = 35.0` (for 0.35) put the tip 34.8 m past the support, was
/// reported valid, and blinded the lateral guard (a true (1.0, 2.0, -2.5) N
/// read as (1.07, 0.01, -0.01) N): refused with the range and the likely
/// unit.
#[test]
fn a_length_in_cm_is_refused_with_its_range_and_the_likely_unit() {
    let text = MINIMUM.replace("length_m = 0.35", "length_m = 35.0");
    expect(
        &text,
        "manipulator.length_m",
        Some("length_m"),
        "must be within 0.1..=1.5 m, got 35",
    );
    let msg = bad(&text).to_string();
    assert!(msg.contains("a value in cm?"), "{msg}");
    let text = MINIMUM.replace("length_m = 0.35", "length_m = 350.0");
    let msg = bad(&text).to_string();
    assert!(msg.contains("a value in mm?"), "{msg}");
    // A mass in g; a travel in mm.
    let text = MINIMUM.replace("mass_kg = 2.593", "mass_kg = 2593.0");
    expect(&text, "manipulator.mass_kg", Some("mass_kg"), "in g?");
    let text =
        format!("{MINIMUM}\n[axes]\ntravel_m = [[-300.0, 300.0], [0.0, 600.0], [0.0, 600.0]]\n");
    expect(
        &text,
        "axes.travel_m[0][0]",
        Some("travel_m"),
        "got -300 (a value in mm? -300 mm is -0.3 m)",
    );
}

/// `1e308` for a mass, a length or a limit was valid.
#[test]
fn values_of_1e308_are_refused() {
    for (from, to, key) in [
        ("mass_kg = 2.593", "mass_kg = 1e308", "manipulator.mass_kg"),
        (
            "length_m = 0.35",
            "length_m = 1e308",
            "manipulator.length_m",
        ),
        ("com_m = 0.103", "com_m = 1e308", "manipulator.com_m"),
        (
            "p_home = [0.0, 0.0, 0.0]",
            "p_home = [1e308, 0.0, 0.0]",
            "geometry.p_home[0]",
        ),
        (
            "noise_n = [0.2, 0.2, 0.8]",
            "noise_n = [0.2, 1e308, 0.8]",
            "sensor.noise_n[1]",
        ),
    ] {
        let text = MINIMUM.replace(from, to);
        let at = to.split(" =").next().unwrap();
        expect(&text, key, Some(at), "must be within");
    }
    for (key, section) in [
        ("stop_total_n", "guard"),
        ("max_stop_lateral_n", "guard"),
        ("max_joint_speed_mps", "plausibility"),
        ("max_std_n", "tip"),
    ] {
        let text = format!("{MINIMUM}\n[{section}]\n{key} = 1e308\n");
        let msg = bad(&text).to_string();
        assert_eq!(
            bad(&text).key(),
            Some(&*format!("{section}.{key}")),
            "{msg}"
        );
        assert!(msg.contains("1e308"), "{msg}");
    }
    // A limit beyond the sensor's range: the sensor saturates first.
    let text = format!(
        "{}range_n = [50.0, 50.0, 50.0]\n[guard]\nmax_stop_total_n = 60.0\n",
        MINIMUM
    );
    expect(
        &text,
        "guard.max_stop_total_n",
        Some("max_stop_total_n"),
        "sensor.range_n",
    );
    // The centre of mass within the rod.
    let text = MINIMUM.replace("com_m = 0.103", "com_m = 0.5");
    expect(&text, "manipulator.com_m", Some("com_m"), "on the rod");
}

/// `support = [0.45, 0.2, 0.0, 7.0]`, a 4-row rotation and a 1e6-element
/// `noise_n` were accepted silently.
#[test]
fn arrays_have_their_exact_length() {
    let text = MINIMUM.replace(
        "support = [0.45, 0.20, 0.0]",
        "support = [0.45, 0.2, 0.0, 7.0]",
    );
    expect(
        &text,
        "geometry.support",
        Some("support ="),
        "invalid length 4, expected an array of length 3",
    );
    let text = MINIMUM.replace(
        "[0.0, 0.0, 1.0]]",
        "[0.0, 0.0, 1.0],\n                   [0.0, 0.0, 0.0]]",
    );
    expect(
        &text,
        "geometry.sensor_rotation",
        Some("sensor_rotation"),
        "invalid length 4",
    );
    let text = MINIMUM.replace("[[1.0, 0.0, 0.0],", "[[1.0, 0.0, 0.0, 0.0],");
    expect(
        &text,
        "geometry.sensor_rotation[0]",
        Some("sensor_rotation"),
        "invalid length 4",
    );
    let long = vec!["0.2"; 1_000_000].join(", ");
    let text = MINIMUM.replace("noise_n = [0.2, 0.2, 0.8]", &format!("noise_n = [{long}]"));
    let e = bad(&text);
    assert_eq!(e.key(), Some("sensor.noise_n"), "{e}");
    assert!(
        e.to_string()
            .contains("invalid length 1000000, expected an array of length 3"),
        "{e}"
    );
    assert!(e.to_string().len() < 200, "{e}");
    // The axes' travel and the drivers' node ids too.
    let text = format!(
        "{MINIMUM}\n[axes]\ntravel_m = [[-0.3, 0.3], [0.0, 0.6], [0.0, 0.6], [0.0, 0.6]]\n"
    );
    expect(&text, "axes.travel_m", Some("travel_m"), "invalid length 4");
}

/// Runs `f` on another thread; a call that does not return within 10 s
/// ends the test process (a read of /dev/zero must not run on).
fn at_once<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(std::time::Duration::from_secs(10)) {
        Ok(v) => v,
        Err(_) => {
            // Past the test harness's capture: the process ends here.
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "{what}: not refused within 10 s");
            std::process::abort();
        }
    }
}

fn scratch_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("sar-config-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `--check-config /dev/zero` grew to 10.5 GB; a FIFO blocked: a
/// configuration (and a scenario) is a regular file of at most 1 MB, checked
/// before it is read.
#[test]
fn only_a_regular_file_of_at_most_1_mb_is_read() {
    use std::path::{Path, PathBuf};
    let dir = scratch_dir("files");
    let fifo = dir.join("robot.fifo");
    sar_test_support::files::mkfifo(&fifo);
    let big = dir.join("big.toml");
    // A valid file padded past 1 MB with comments.
    let padding = "# padding\n".repeat(110_000);
    std::fs::write(&big, format!("{MINIMUM}{padding}")).unwrap();
    let cases: [(PathBuf, &str); 5] = [
        (
            PathBuf::from("/dev/zero"),
            "not a regular file (a character device)",
        ),
        (
            PathBuf::from("/dev/null"),
            "not a regular file (a character device)",
        ),
        (fifo.clone(), "not a regular file (a FIFO)"),
        (dir.clone(), "not a regular file (a directory)"),
        (big.clone(), "more than 1 MB"),
    ];
    for (path, words) in cases {
        let p = path.clone();
        let e = at_once(&path.display().to_string(), move || {
            config::load(&p).unwrap_err()
        });
        let msg = e.to_string();
        assert!(matches!(e, ConfigError::Read { .. }), "{msg}");
        assert!(
            msg.starts_with(&format!("{}: cannot read the file: ", path.display())),
            "{msg}"
        );
        assert!(msg.contains(words), "{msg} lacks {words:?}");
        // Scenario files share the reader.
        let p = path.clone();
        let e = at_once(&path.display().to_string(), move || {
            config::scenario::load(&p).unwrap_err()
        });
        assert!(e.to_string().contains(words), "{e}");
    }
    // Exactly 1 MB is still read (and refused for its content only).
    let edge = dir.join("edge.toml");
    let mut text = MINIMUM.to_string();
    text.push_str(&"#".repeat(1_000_000 - text.len() - 1));
    text.push('\n');
    assert_eq!(text.len(), 1_000_000);
    std::fs::write(&edge, &text).unwrap();
    config::load(Path::new(&edge)).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 35 (finding 12): a control character in `manipulator.name` was
/// reported as "too long" (a 5-character name), and a bidi override
/// (U+202E, which reverses how the rest of a log line reads) was accepted.
/// Each is refused with its own reason, naming the character and where.
#[test]
fn a_name_with_a_control_or_a_direction_changing_character_is_refused_as_such() {
    let named =
        |name: &str| MINIMUM.replace("name = \"manipulator-2\"", &format!("name = \"{name}\""));
    let msg = bad(&named("rod\\u0007x")).to_string();
    assert!(
        msg.contains("manipulator.name")
            && msg.contains("must not hold a control character, got U+0007 at character 4"),
        "{msg}"
    );
    assert!(!msg.contains("at most"), "{msg}");
    for (c, code) in [
        ("\\u202E", "U+202E"),
        ("\\u2066", "U+2066"),
        ("\\u200F", "U+200F"),
        ("\\u200B", "U+200B"),
        ("\\u2028", "U+2028"),
        ("\\uFEFF", "U+FEFF"),
        ("\\U000E0041", "U+E0041"),
    ] {
        let msg = bad(&named(&format!("rod-{c}2"))).to_string();
        assert!(
            msg.contains(&format!("must not hold an invisible or direction-changing character (it changes how the log and the tools show the text), got {code} at character 5")),
            "{code}: {msg}"
        );
    }
    let msg = bad(&named(&"m".repeat(101))).to_string();
    assert!(
        msg.contains("must be at most 100 characters, got 101 characters"),
        "{msg}"
    );
    // Letters of every script stay welcome (Hebrew is right-to-left by
    // itself, without an override).
    let c = config::parse(&named("Zervikal-Manipulator μ2 שלום"), "t.toml").unwrap();
    assert_eq!(c.manipulator_name, "Zervikal-Manipulator μ2 שלום");
}

/// An error about a nested array printed 200 KB: every error is one line
/// of at most a few hundred characters (values are cut).
#[test]
fn every_error_is_one_short_line() {
    let row = vec!["0.5"; 50_000].join(", ");
    let cases = [
        // A syntax error in a 200 KB line of a nested array.
        MINIMUM.replace(
            "sensor_rotation = [[1.0, 0.0, 0.0],",
            &format!("sensor_rotation = [[{row}] [1.0, 0.0, 0.0],"),
        ),
        // A wrong type deep in a nested array.
        MINIMUM.replace(
            "sensor_rotation = [[1.0, 0.0, 0.0],",
            &format!("sensor_rotation = [[[{row}]], [1.0, 0.0, 0.0],"),
        ),
        // A 100 KB string where a kind is expected.
        format!(
            "{MINIMUM}\n[drivers.sensor]\nkind = \"{}\"\n",
            "x".repeat(100_000)
        ),
        // A 100 KB address.
        format!(
            "{MINIMUM}\n[drivers.sensor]\nkind = \"rdt\"\naddress = \"{}\"\ncounts_per_n = 1.0\ncounts_per_nm = 1.0\n",
            "1".repeat(100_000)
        ),
        // A 100 KB unknown key.
        format!("{MINIMUM}\n[guard]\n{} = 1.0\n", "k".repeat(100_000)),
        // A 100 KB string where a number is expected.
        MINIMUM.replace(
            "com_m = 0.103",
            &format!("com_m = \"{}\"", "9".repeat(100_000)),
        ),
        // A 100 KB manipulator name (`--check-config` prints the name).
        MINIMUM.replace(
            "name = \"manipulator-2\"",
            &format!("name = \"{}\"", "m".repeat(100_000)),
        ),
    ];
    for text in cases {
        let msg = bad(&text).to_string();
        let head: String = msg.chars().take(300).collect();
        assert!(msg.chars().count() <= 600, "{} chars: {head}", msg.len());
        assert_eq!(msg.lines().count(), 1, "{head}");
    }
    // The worst case: a long path, a long key and a long problem together.
    let origin = format!("/{}/robot.toml", "d".repeat(5000));
    let text = format!("{MINIMUM}\n[guard]\n{} = 1.0\n", "k".repeat(100_000));
    let msg = config::parse(&text, &origin).unwrap_err().to_string();
    assert!(msg.chars().count() <= 700, "{} chars: {msg}", msg.len());
    // A long origin is cut too (it keeps its end: the file's name).
    let origin = format!("/{}/robot.toml", "d".repeat(5000));
    let msg = config::parse("[geometry\n", &origin)
        .unwrap_err()
        .to_string();
    assert!(msg.chars().count() <= 600, "{msg}");
    assert!(msg.contains("robot.toml: not valid TOML"), "{msg}");
}

/// The configurations the repository ships are plausible (and read through
/// the bounded reader).
#[test]
fn every_shipped_configuration_is_plausible() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    for file in ["deploy/robot.toml", "tests/fixtures/replay/config.toml"] {
        config::load(&root.join(file)).unwrap_or_else(|e| panic!("{e}"));
    }
    config::builtin().unwrap();
}

/// The CANopen drives' own limits that no other key gives: the quick stop
/// deceleration (0x6085) and the max torque (0x6072), with their defaults
/// and ranges (the quick stop brakes at least as hard as the planned moves
/// accelerate).
#[test]
fn the_canopen_drives_own_limits_have_defaults_and_ranges() {
    let canopen = "[drivers.axes]\nkind = \"canopen\"\ninterface = \"can0\"\nnode_ids = [1, 2, 3]\nlead_m = 0.01\ncounts_per_turn = 4096\n";
    let c = config::parse(&format!("{MINIMUM}\n{canopen}"), "robot.toml").unwrap();
    assert!(matches!(
        c.axes_driver,
        AxesDriver::Canopen {
            quick_stop_decel_mps2: 2.0,
            max_torque_permille: 1000,
            ..
        }
    ));
    // Issue 26: the loop's model of the drives takes the same quick stop;
    // a guarded move brakes at it unless told otherwise.
    assert_eq!(c.axes.motion.quick_stop_decel_mps2, 2.0);
    assert_eq!(c.axes.motion.brake_decel_mps2, 2.0);
    assert_eq!(c.axes.motion.servo_bandwidth_hz, 30.0);
    assert_eq!(c.axes.motion.servo_damping, 0.7);
    assert_eq!(c.axes.motion.sensor_latency_ns, 1_000_000);
    // Every kind takes the quick stop (the simulated drives too).
    let sim = "[drivers.axes]\nkind = \"sim\"\nquick_stop_decel_mps2 = 3.0\n";
    let c = config::parse(&format!("{MINIMUM}\n{sim}"), "robot.toml").unwrap();
    assert_eq!(c.axes.motion.quick_stop_decel_mps2, 3.0);
    assert_eq!(c.axes.motion.brake_decel_mps2, 3.0);
    assert_eq!(c.step_config().motion, c.axes.motion);
    // The brake: between the planned acceleration and the quick stop.
    for bad in ["0.1", "2.5"] {
        let text = format!("{MINIMUM}\n[axes]\nbrake_decel_mps2 = {bad}\n");
        expect(
            &text,
            "axes.brake_decel_mps2",
            Some("brake_decel_mps2"),
            "at most [drivers.axes] quick_stop_decel_mps2",
        );
    }
    let text = format!("{MINIMUM}\n[axes]\nbrake_decel_mps2 = 1.0\nservo_bandwidth_hz = 0.0\n");
    let c = config::parse(&text, "robot.toml").unwrap();
    assert_eq!(c.axes.motion.brake_decel_mps2, 1.0);
    assert_eq!(c.axes.motion.servo_bandwidth_hz, 0.0);
    let text = format!("{MINIMUM}\n[axes]\nservo_damping = 0.0\n");
    expect(
        &text,
        "axes.servo_damping",
        Some("servo_damping"),
        "0.1..=2",
    );
    let text =
        format!("{MINIMUM}\n{canopen}quick_stop_decel_mps2 = 2.5\nmax_torque_permille = 800\n");
    let c = config::parse(&text, "robot.toml").unwrap();
    assert!(matches!(
        c.axes_driver,
        AxesDriver::Canopen {
            quick_stop_decel_mps2: 2.5,
            max_torque_permille: 800,
            ..
        }
    ));
    // Gentler than the planned moves' 0.2 m/s^2: refused.
    let text = format!("{MINIMUM}\n{canopen}quick_stop_decel_mps2 = 0.1\n");
    expect(
        &text,
        "drivers.axes.quick_stop_decel_mps2",
        Some("quick_stop_decel_mps2"),
        "at least [axes] max_accel_mps2",
    );
    let text = format!("{MINIMUM}\n{canopen}max_torque_permille = 0\n");
    expect(
        &text,
        "drivers.axes.max_torque_permille",
        Some("max_torque_permille"),
        "1..=3000",
    );
    // Not keys of the simulated axes.
    let text = format!("{MINIMUM}\n[drivers.axes]\nkind = \"sim\"\nmax_torque_permille = 800\n");
    expect(
        &text,
        "drivers.axes.max_torque_permille",
        Some("max_torque_permille"),
        "not a key of the simulated axes",
    );
}

/// The rod's inertia (MODEL.md 10): the slender rod's m L^2 / 12 with a 50 %
/// standard deviation when I_perp is not given (a stated default, flagged
/// not measured), 5 % of a given I_perp without its own, I_axial and the
/// adapter 0 by default; every key's error names it, with its line.
#[test]
fn the_inertia_keys_have_stated_defaults_and_are_checked_by_key() {
    let c = config::parse(MINIMUM, "robot.toml").unwrap();
    let i = c.estimator.inertia;
    let slender = 2.593 * 0.35 * 0.35 / 12.0;
    assert!(!c.inertia_measured);
    assert_eq!(i.inertia_perp_kgm2, slender);
    assert_eq!(i.inertia_perp_std_kgm2, slender * 0.5);
    assert_eq!((i.inertia_axial_kgm2, i.adapter_mass_kg), (0.0, 0.0));
    assert!(!config::builtin().unwrap().inertia_measured);
    let manipulator =
        |lines: &str| MINIMUM.replace("com_m = 0.103\n", &format!("com_m = 0.103\n{lines}\n"));
    let c = config::parse(&manipulator("inertia_perp_kgm2 = 0.031"), "robot.toml").unwrap();
    assert!(c.inertia_measured);
    assert_eq!(c.estimator.inertia.inertia_perp_kgm2, 0.031);
    assert_eq!(c.estimator.inertia.inertia_perp_std_kgm2, 0.031 * 0.05);
    let text = manipulator(
        "inertia_perp_kgm2 = 0.031\ninertia_perp_std_kgm2 = 0.0004\ninertia_axial_kgm2 = 0.0002",
    );
    let sensor = |text: &str, line: &str| {
        text.replace(
            "noise_n = [0.2, 0.2, 0.8]\n",
            &format!("noise_n = [0.2, 0.2, 0.8]\n{line}\n"),
        )
    };
    let c = config::parse(&sensor(&text, "adapter_mass_kg = 0.12"), "robot.toml").unwrap();
    let i = c.estimator.inertia;
    assert_eq!(
        [
            i.inertia_perp_std_kgm2,
            i.inertia_axial_kgm2,
            i.adapter_mass_kg
        ],
        [0.0004, 0.0002, 0.12]
    );
    // Errors name the key and its line.
    let text = manipulator("inertia_perp_kgm2 = -0.01");
    expect(
        &text,
        "manipulator.inertia_perp_kgm2",
        Some("inertia_perp_kgm2"),
        "within 0..=2 kg m^2, got -0.01",
    );
    let text = manipulator("inertia_perp_std_kgm2 = 0.001");
    expect(
        &text,
        "manipulator.inertia_perp_std_kgm2",
        Some("inertia_perp_std_kgm2"),
        "without manipulator.inertia_perp_kgm2",
    );
    let text = manipulator("inertia_perp_kgm2 = 30.0");
    expect(
        &text,
        "manipulator.inertia_perp_kgm2",
        Some("inertia_perp_kgm2"),
        "0..=2 kg m^2",
    );
    let text = manipulator("inertia_axial_kgm2 = 0.5");
    expect(
        &text,
        "manipulator.inertia_axial_kgm2",
        Some("inertia_axial_kgm2"),
        "0..=0.1 kg m^2",
    );
    let text = sensor(MINIMUM, "adapter_mass_kg = 120.0");
    expect(
        &text,
        "sensor.adapter_mass_kg",
        Some("adapter_mass_kg"),
        "(a value in g? 120 g is 0.12 kg)",
    );
    let text = sensor(MINIMUM, "adapter_mass_kg = -1.0");
    expect(
        &text,
        "sensor.adapter_mass_kg",
        Some("adapter_mass_kg"),
        "within 0..=5 kg, got -1",
    );
}

/// `[identify]` (issue 26): defaults, a value read, and each key's refusal
/// naming it (the speed must stay below the plausibility check's, and at
/// most the drives' streamed speed, `[axes] max_speed_mps`: issue 33, where
/// the shipped 0.04 m/s above the axes' 0.02 made `identify --dynamic
/// --live` refused by the loop after the tool had moved and recorded).
#[test]
fn the_identify_keys() {
    let c = config::parse(MINIMUM, "robot.toml").unwrap();
    assert_eq!(c.identify, config::IdentifySettings::default());
    assert_eq!(c.identify.excitation_max_speed_mps, 0.02);
    assert_eq!(c.identify.excitation_max_jerk_mps3, 10.0);
    // The shipped configurations run the excitation as shipped.
    for c in [config::builtin().unwrap(), c] {
        assert!(c.identify.excitation_max_speed_mps <= c.axes.max_speed_mps);
    }
    let e = config::parse(
        &format!("{MINIMUM}\n[identify]\nexcitation_max_speed_mps = 0.03\n"),
        "robot.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("identify.excitation_max_speed_mps")
            && e.contains("above axes.max_speed_mps (0.02 m/s)"),
        "{e}"
    );
    // Raised with the axes' speed, it is accepted.
    let c = config::parse(
        &format!(
            "{MINIMUM}\n[axes]\nmax_speed_mps = 0.03\n[identify]\nexcitation_max_speed_mps = 0.03\n"
        ),
        "robot.toml",
    )
    .unwrap();
    assert_eq!(c.identify.excitation_max_speed_mps, 0.03);
    let c = config::parse(
        &format!("{MINIMUM}\n[identify]\nexcitation_duration_s = 30.0\n"),
        "robot.toml",
    )
    .unwrap();
    assert_eq!(c.identify.excitation_duration_s, 30.0);
    for (line, key) in [
        (
            "excitation_max_speed_mps = 0.05",
            "identify.excitation_max_speed_mps",
        ),
        (
            "excitation_max_accel_mps2 = 0.0",
            "identify.excitation_max_accel_mps2",
        ),
        (
            "excitation_duration_s = 5.0",
            "identify.excitation_duration_s",
        ),
        (
            "excitation_max_jerk_mps3 = 0.0",
            "identify.excitation_max_jerk_mps3",
        ),
        (
            "excitation_max_jerk_mps3 = 2000.0",
            "identify.excitation_max_jerk_mps3",
        ),
    ] {
        let e = config::parse(&format!("{MINIMUM}\n[identify]\n{line}\n"), "robot.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{e}");
    }
    assert!(config::DEFAULT_TOML.contains("\n[identify]"));
}

/// Issue 35, finding 8: a configuration that loads is one the CANopen
/// drives' own checks at start take (`CanOpenConfig::validate`, run on the
/// one conversion `sar_config::devices::canopen_drives` that `sard` starts
/// the drives with). Before, `sard --check-config` said "valid" for a
/// quick stop of 4.3e15 counts/s^2 (a lead of 10 um over 2^32 - 1 counts),
/// a travel of 2.6e14 counts, and 1 m per count (the following window
/// below one count), all refused by the drivers at start. Each is refused
/// at load now, naming the key it comes from and the drives' units.
#[test]
fn canopen_limits_the_drives_refuse_are_refused_at_load() {
    let canopen = |lead: &str, cpt: &str| {
        format!(
            "{MINIMUM}\n[drivers.axes]\nkind = \"canopen\"\ninterface = \"can0\"\nnode_ids = [1, 2, 3]\nlead_m = {lead}\ncounts_per_turn = {cpt}\nquick_stop_decel_mps2 = 10.0\n"
        )
    };
    // A lead of 10 um over 2^32 - 1 counts (2.3e-15 m a count): the
    // travel's 0.6 m is 2.6e14 counts, beyond the drives' 32-bit position.
    let e = bad(&canopen("0.00001", "4294967295"));
    assert_eq!(e.key(), Some("axes.travel_m"), "{e}");
    assert!(
        e.to_string()
            .contains("the CANopen drives would refuse it at start"),
        "{e}"
    );
    assert!(e.to_string().contains("32-bit position"), "{e}");
    // The travel within 32 bits (2.8e-10 m a count), the quick stop not:
    // 10 m/s^2 is 3.6e10 counts/s^2, beyond 0x6085's 32 bits.
    let text = canopen("0.001", "3579139");
    expect(
        &text,
        "drivers.axes.quick_stop_decel_mps2",
        Some("quick_stop_decel_mps2"),
        "the CANopen drives would refuse it at start",
    );
    assert!(
        bad(&text).to_string().contains("3.57914e10 counts/s^2"),
        "{}",
        bad(&text)
    );
    // 1 m per count: the following window (2 x 1 mm) is below one count.
    let text = canopen("1.0", "1");
    let e = bad(&text);
    assert_eq!(e.key(), Some("axes.following_tolerance_m"), "{e}");
    assert!(e.to_string().contains("at least one count"), "{e}");
    // The shipped robot's configuration loads, and its drives take it.
    let robot = config::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/robot.toml"),
    )
    .unwrap();
    let (_, c) = config::devices::canopen_drives(&robot).unwrap();
    c.validate().unwrap();
}
