//! `sarctl identify --live` end to end: `sard --sim` on a scenario whose
//! manipulator (Table 2's manipulator 2: m = 2.593 kg, c = 0.103 m, support
//! at (0.45, 0.20, 0)) differs from the configured one (2.5 kg, 0.100 m, B
//! 1 mm too high). The travel of the configuration shrinks the cone set to
//! half its distances (a shorter test). `sarctl` drives the daemon through
//! it with move-tip, identifies from the published state and writes the
//! right values back.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod support;
use std::process::Command;
use std::time::{Duration, Instant};
use support::{Daemon, SARCTL, sard};

const CONFIG: &str = r#"# identify --live test
[geometry]
gravity = [0.0, -9.80665, 0.0]
support = [0.45, 0.201, 0.0]             # B, 1 mm too high
p_home = [0.0, 0.0, 0.0]
ujoint_offset = [0.0, -0.08, 0.0]
sensor_offset = [0.0, -0.03, 0.0]
sensor_rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

[manipulator]
name = "manipulator-2"
length_m = 0.35
offset_m = 0.0
mass_kg = 2.5                            # m (written by `sarctl identify`)
com_m = 0.100                            # c (written by `sarctl identify`)

[sensor]
noise_n = [0.2, 0.2, 0.8]

[axes]
travel_m = [[-0.3, 0.3], [0.18, 0.38], [0.0, 0.6]]
max_speed_mps = 0.05

[guard]
# A test machine without real-time scheduling (a VM, two CPU hogs beside
# it) stalls even a SCHED_FIFO thread now and then for tens of ms
# (cyclictest's largest wake-up beside two hogs: 23 ms; sard's, 33 ms);
# beyond the age the guard faults (`cycle_gap`) and the procedure stops.
# Within it a late cycle is carried on (issue 33): what these tests are
# about is the identification, so they give the host 0.2 s.
max_sensor_age_s = 0.2
max_joints_age_s = 0.2

[plausibility]
max_counter_gap = 25
"#;

fn scenario() -> String {
    let demo = sar_daemon::sim::DEMO_SCENARIO_TOML;
    // No tip contact: nothing may touch the tip during identification.
    demo.split("[[contact]]").next().unwrap().to_owned()
}

#[test]
fn identify_live_writes_back_the_simulated_manipulator() {
    let prefix = format!("sar-idlive-{}", std::process::id());
    let dir = std::env::temp_dir().join(&prefix);
    std::fs::create_dir_all(&dir).unwrap();
    let scenario_path = dir.join("scenario.toml");
    std::fs::write(&scenario_path, scenario()).unwrap();
    let config_path = dir.join("robot.toml");
    std::fs::write(&config_path, CONFIG).unwrap();
    let _daemon = Daemon::spawn(
        sard(&prefix)
            .arg("--sim")
            .arg("--config")
            .arg(&config_path)
            .arg("--scenario")
            .arg(&scenario_path),
    );
    let client = sar_shm::Client::new(&prefix).unwrap();
    let start = Instant::now();
    let sub = loop {
        match client.subscribe() {
            Ok(s) => break s,
            Err(_) => {
                assert!(start.elapsed() < Duration::from_secs(30), "no daemon");
                std::thread::sleep(Duration::from_millis(50));
            }
        }
    };
    // The demo's automatic reset is accepted once the mean at rest is
    // complete (1 s): identification starts from Ok.
    loop {
        let s = sub.latest(Duration::from_secs(5)).unwrap();
        if s.guard_state == sar_msgs::wire::guard_code::OK {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "never Ok");
    }
    let out = Command::new(SARCTL)
        .arg("--config")
        .arg(&config_path)
        .args(["--format", "json", "identify", "--live", "--yes"])
        .env("SAR_SERVICE_PREFIX", &prefix)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("{json}");
    let m = json["mass_kg"].as_f64().unwrap();
    let c = json["com_m"].as_f64().unwrap();
    let b = json["support_m"][1].as_f64().unwrap();
    assert!((m - 2.593).abs() < 0.01 * 2.593, "m {m}");
    assert!((c - 0.103).abs() < 0.01 * 0.103, "c {c}");
    assert!((b - 0.20).abs() < 0.3e-3, "B_y {b}");
    let written = sar_config::load(&config_path).unwrap();
    assert!((written.estimator.profile.mass_kg() - m).abs() < 1e-5);
    let text = std::fs::read_to_string(&config_path).unwrap();
    assert!(text.contains("# m (written by `sarctl identify`)"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Waits for the daemon under `prefix` to publish a state that `ok` accepts.
fn wait_for(prefix: &str, ok: impl Fn(&sar_msgs::wire::StateMsg) -> bool) {
    support::wait_for_state(prefix, "never so", ok);
}

/// The README's recipe: `sard --sim --scenario
/// scenarios/identify_cone_manipulator_2.toml` (the built-in configuration,
/// its whole travel) and `sarctl --config COPY identify --live`: every pose
/// reached (the moves the guard's Warn braked near the support asked
/// again), the progress on stderr, m and c of the simulated manipulator.
#[test]
fn identify_live_works_with_the_readme_recipe() {
    let prefix = format!("sar-idrecipe-{}", std::process::id());
    let dir = std::env::temp_dir().join(&prefix);
    std::fs::create_dir_all(&dir).unwrap();
    let config_path = dir.join("my-sim.toml");
    std::fs::write(&config_path, sar_config::DEFAULT_TOML).unwrap();
    let scenario = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios/identify_cone_manipulator_2.toml");
    let _daemon = Daemon::spawn(sard(&prefix).args(["--sim", "--scenario"]).arg(&scenario));
    wait_for(&prefix, |s| s.guard_state == sar_msgs::wire::guard_code::OK);
    let out = Command::new(SARCTL)
        .arg("--config")
        .arg(&config_path)
        .args([
            "--format",
            "json",
            "identify",
            "--live",
            "--yes",
            "--dry-run",
        ])
        .env("SAR_SERVICE_PREFIX", &prefix)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("pose 1 of 22"), "{stderr}");
    assert!(stderr.contains("pose 22 of 22"), "{stderr}");
    assert!(stderr.contains("s left"), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let m = json["mass_kg"].as_f64().unwrap();
    let c = json["com_m"].as_f64().unwrap();
    assert!((m - 2.593).abs() < 0.01 * 2.593, "m {m}");
    assert!((c - 0.103).abs() < 0.01 * 0.103, "c {c}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Out of the box (`sard --sim`, the demo's contact in Warn) identification
/// is refused at once, with the recipe.
#[test]
fn identify_live_refuses_the_demo_contact_at_once() {
    let prefix = format!("sar-iddemo-{}", std::process::id());
    let _daemon = Daemon::spawn(sard(&prefix).arg("--sim"));
    wait_for(&prefix, |s| {
        s.guard_state == sar_msgs::wire::guard_code::WARN
    });
    let start = Instant::now();
    let out = Command::new(SARCTL)
        .args(["identify", "--live", "--yes", "--dry-run"])
        .arg("--config")
        .arg(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../config/src/default_config.toml"),
        )
        .env("SAR_SERVICE_PREFIX", &prefix)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(start.elapsed() < Duration::from_secs(10), "not at once");
    assert!(stderr.contains("free tip"), "{stderr}");
    assert!(
        stderr.contains("--scenario scenarios/identify_cone_manipulator_2.toml"),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
}

/// `identify --dynamic --live` (issue 26 section 3) on `sard --sim` with the
/// plant in motion (the rod's I_perp = m L^2 / 12, servos on), a 16 s
/// excitation at 0.02 m/s and 1 m/s^2 (at 0.04 m/s the sweep along the rod
/// comes close enough to the support that the estimate's noise, growing as
/// L/a, crosses the lateral warn limit, and the Warn ends it): first the loop's refusals
/// (above the speed limit; while the axes move), each with its one-line
/// reason; then the plan printed, the excitation recorded, I_perp
/// identified within 15 % and written back; the recording replays bit for
/// bit.
#[test]
fn identify_dynamic_live_identifies_the_rods_inertia() {
    use sar_msgs::command::{ExciteRequest, Request};
    let prefix = format!("sar-iddyn-{}", std::process::id());
    let dir = std::env::temp_dir().join(&prefix);
    std::fs::create_dir_all(&dir).unwrap();
    // The demo's rod: I_perp = m L^2 / 12, rounded.
    let i_true = 0.02647;
    // The demo's axes have their servos (30 Hz, 0.7), its rod its inertia.
    let scenario = scenario();
    assert!(scenario.contains("servo_bandwidth_hz = 30.0"), "{scenario}");
    assert!(
        scenario.contains("inertia_perp_kgm2 = 0.02647\n"),
        "{scenario}"
    );
    let scenario_path = dir.join("scenario.toml");
    std::fs::write(&scenario_path, scenario).unwrap();
    let config_path = dir.join("robot.toml");
    // The rod as identified statically (m, c and B right): the tip free
    // reads near 0 N.
    let config = CONFIG
        .replace("[0.45, 0.201, 0.0]", "[0.45, 0.20, 0.0]")
        .replace("mass_kg = 2.5 ", "mass_kg = 2.593 ")
        .replace("com_m = 0.100 ", "com_m = 0.103 ")
        // The built-in configuration's axes (the demo's): the simulated
        // drives refuse a streamed set point beyond `max_speed_mps` over a
        // period from their last one, and the excitation streams at that
        // very speed; a late cycle of the loop (a loaded test machine has
        // no real-time scheduling) delays it rather than making it jump
        // (issue 33: before, this test ran the axes at 0.2 m/s to survive).
        .replace("max_speed_mps = 0.05\n", "max_speed_mps = 0.02\n")
        + &format!(
            "\n[identify]\nexcitation_duration_s = 16.0\nexcitation_max_speed_mps = 0.02\n\n[record]\ndirectory = \"{}\"\n",
            dir.display()
        );
    std::fs::write(&config_path, &config).unwrap();
    // What the daemon runs (the replay's configuration: the file is
    // written back).
    let run_config_path = dir.join("run.toml");
    std::fs::write(&run_config_path, &config).unwrap();
    let _daemon = Daemon::spawn(
        sard(&prefix)
            .arg("--sim")
            .arg("--config")
            .arg(&run_config_path)
            .arg("--scenario")
            .arg(&scenario_path),
    );
    wait_for(&prefix, |s| s.guard_state == sar_msgs::wire::guard_code::OK);
    let client = sar_shm::Client::new(&prefix).unwrap();
    let ask = |request: Request| {
        client
            .command(request.to_wire(26), Duration::from_secs(5))
            .unwrap()
    };
    let excite = |amplitude_m| {
        Request::Excite(ExciteRequest {
            amplitude_m,
            freq_hz: [1.3, 1.7, 0.07],
            duration_s: 16.0,
            fade_s: 3.0,
        })
    };
    // 1 cm at 1.3 Hz is 0.082 m/s: above the 0.02 m/s limit.
    let r = ask(excite([0.01, 0.0, 0.0]));
    assert_eq!(r.status, 15, "{}", r.detail_text());
    assert!(
        r.detail_text()
            .contains("the excitation of q1 peaks at 0.0816814 m/s (its fades included), above [identify] excitation_max_speed_mps = 0.02 m/s"),
        "{}",
        r.detail_text()
    );
    // While a move runs: refused, the axes move.
    let r = ask(Request::MoveTip {
        tip_m: sar_estimator::Vec3::new(0.62, 0.2, 0.0),
    });
    assert_eq!(r.status, 0, "{}", r.detail_text());
    std::thread::sleep(Duration::from_millis(200));
    let r = ask(excite([0.001, 0.001, 0.001]));
    assert_eq!(r.status, 12, "{}", r.detail_text());
    assert!(
        r.detail_text().starts_with("the axes still move at"),
        "{}",
        r.detail_text()
    );
    let out = Command::new(SARCTL)
        .arg("--config")
        .arg(&config_path)
        .args([
            "--format",
            "json",
            "identify",
            "--dynamic",
            "--live",
            "--sensor-latency-s",
            "0.001",
            // The default centre: the farthest from the support whose sweep
            // keeps the estimate's noise clear of the warn limits (at
            // a = 0.2 m the noise, growing as 1 / (L - a), reached the
            // lateral warn limit and a Warn ended the excitation).
        ])
        .env("SAR_SERVICE_PREFIX", &prefix)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    println!("{stderr}");
    assert!(stderr.contains("condition number"), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("{json}");
    let i = json["inertia_perp_kgm2"].as_f64().unwrap();
    println!(
        "I_perp {i} against {i_true}: {:+.2} %",
        100.0 * (i / i_true - 1.0)
    );
    assert!(
        (i / i_true - 1.0).abs() < 0.15,
        "I_perp {i}, truth {i_true}"
    );
    let written = std::fs::read_to_string(&config_path).unwrap();
    assert!(written.contains("inertia_perp_kgm2"), "{written}");
    // The recording replays bit for bit (from its snapshot).
    let rec = stderr
        .lines()
        .find_map(|l| l.split("recorded in ").nth(1))
        .and_then(|l| l.split("; identifying").next())
        .unwrap()
        .to_owned();
    let out = Command::new(SARCTL)
        .args(["replay", "--format", "json", "--config"])
        .arg(&run_config_path)
        .arg("--input")
        .arg(&rec)
        .arg("--output")
        .arg(dir.join("replayed.mcap"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    std::fs::remove_dir_all(&dir).unwrap();
}
