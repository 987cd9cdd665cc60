//! The deployment: `deploy/robot.toml`, the example configuration of the real
//! robot beside the systemd unit, passes `sard --check-config` and names the
//! real devices; `sard` refuses CANopen drives in one line when built without
//! SocketCAN; and `sard --config` as a process runs its loop on the RDT
//! driver against the device emulator over loopback UDP (a real sensor on
//! simulated axes: the bench set-up).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config::{self as config, AxesDriver, SensorDriver};
use sar_daemon::sim;
use sar_hal::ForceSensor;
use sar_rdt::emulator::{Emulator, EmulatorConfig, Pacing};
use std::io::Read;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const SARD: &str = env!("CARGO_BIN_EXE_sard");

/// Runs `sard --config cfg` for 50 cycles under a service prefix of its own
/// (`name`): it must refuse to start, in one line, which is returned.
fn refused_in_one_line(cfg: &Path, name: &str) -> String {
    let out = Command::new(SARD)
        .arg("--config")
        .arg(cfg)
        .args(["--max-cycles", "50"])
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-deploy-{}-{name}", std::process::id()),
        )
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    err
}

fn robot_toml() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/robot.toml")
}

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("sard-deploy-{}-{name}", std::process::id()))
}

#[test]
fn the_robot_configuration_passes_check_config_and_names_the_real_devices() {
    let path = robot_toml();
    let out = sar_test_support::process::run_ok(
        Command::new(SARD).arg("--check-config").arg(&path),
        "the command",
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("valid"));
    let c = config::load(&path).unwrap();
    assert_eq!(
        c.sensor_driver,
        SensorDriver::Rdt {
            address: "192.168.1.1:49152".parse().unwrap(),
            counts_per_n: 10_000.0,
            counts_per_nm: 100_000.0,
        }
    );
    assert_eq!(
        c.axes_driver,
        AxesDriver::Canopen {
            interface: "can0".to_owned(),
            node_ids: [1, 2, 3],
            lead_m: 0.01,
            counts_per_turn: 4096,
            quick_stop_decel_mps2: 1.0,
            max_torque_permille: 1000,
        }
    );
    // The robot keeps the guard's defaults (the demo's relaxed ages are not
    // for a robot).
    let limits = c.estimator.guard.limits();
    assert_eq!(limits.max_sensor_age_ns, 10_000_000);
    assert_eq!(limits.max_joints_age_ns, 10_000_000);
    // The unit reads it where the comment says.
    let unit = std::fs::read_to_string(path.with_file_name("sard.service")).unwrap();
    assert!(unit.contains("--config /etc/sar/robot.toml"));
}

#[cfg(not(feature = "socketcan"))]
#[test]
fn canopen_drives_are_refused_in_one_line_without_socketcan() {
    let out = Command::new(SARD)
        .arg("--config")
        .arg(robot_toml())
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-deploy-{}-refuse", std::process::id()),
        )
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("robot.toml"), "{err}");
    assert!(err.contains("canopen"), "{err}");
    assert!(err.contains("socketcan"), "{err}");
    assert!(err.contains("can0"), "{err}");
}

#[cfg(feature = "socketcan")]
#[test]
fn a_missing_can_interface_is_refused_in_one_line_naming_it() {
    let cfg = temp_path("nocan.toml");
    std::fs::write(
        &cfg,
        config::DEFAULT_TOML.replace(
            "[drivers.axes]\nkind = \"sim\"",
            "[drivers.axes]\nkind = \"canopen\"\ninterface = \"sarnocan0\"\nnode_ids = [1, 2, 3]\nlead_m = 0.01\ncounts_per_turn = 4096",
        ),
    )
    .unwrap();
    let err = refused_in_one_line(&cfg, "nocan");
    assert!(err.contains("sarnocan0"), "{err}");
    let _ = std::fs::remove_file(cfg);
}

#[test]
fn a_silent_sensor_is_refused_at_start_in_one_line_naming_it() {
    // A loopback port where nothing listens: no sample ever comes.
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let cfg = temp_path("silent-rdt.toml");
    std::fs::write(
        &cfg,
        config::DEFAULT_TOML.replace(
            "[drivers.sensor]\nkind = \"sim\"",
            &format!("[drivers.sensor]\nkind = \"rdt\"\naddress = \"127.0.0.1:{port}\"\ncounts_per_n = 10000.0\ncounts_per_nm = 100000.0\n"),
        ),
    )
    .unwrap();
    let err = refused_in_one_line(&cfg, "silent");
    assert!(
        err.contains(&format!("RDT sensor at 127.0.0.1:{port}")),
        "{err}"
    );
    let _ = std::fs::remove_file(cfg);
}

#[test]
fn sard_runs_its_loop_on_the_rdt_driver_against_the_emulator() {
    // The emulator reads what the simulated sensor reads at the demo's start,
    // without its bias (a real sensor starts with no bias): an estimate.
    let scenario = sim::demo_scenario().unwrap();
    let (_sim, mut sensor, _drives, bias) =
        sim::simulated(&scenario, sar_hal::SimClock::new(1_000_000_000)).unwrap();
    let s = sensor.wait(1_000_000_000).unwrap();
    let f = s.force_n - bias.force_n;
    let t = s.torque_nm - bias.torque_nm;
    let mut emu = EmulatorConfig::new(Pacing::Periodic {
        period_ns: 2_000_000,
    });
    emu.counts = [
        (f.x * 1e4).round() as i32,
        (f.y * 1e4).round() as i32,
        (f.z * 1e4).round() as i32,
        (t.x * 1e5).round() as i32,
        (t.y * 1e5).round() as i32,
        (t.z * 1e5).round() as i32,
    ];
    // A live sensor's noise (the HEX-E's at OnRobot's scale): a constant
    // reading is what a frozen sensor sends, and the guard faults on it.
    emu.noise_counts = [2000.0, 2000.0, 8000.0, 1000.0, 1000.0, 200.0];
    emu.seed = 0xde91;
    let emulator = Emulator::start(emu).unwrap();
    let cfg = temp_path("rdt.toml");
    std::fs::write(
        &cfg,
        config::DEFAULT_TOML.replace(
            "[drivers.sensor]\nkind = \"sim\"",
            &format!(
                "[drivers.sensor]\nkind = \"rdt\"\naddress = \"{}\"\ncounts_per_n = 10000.0\ncounts_per_nm = 100000.0\n",
                emulator.address()
            ),
        ),
    )
    .unwrap();
    let sock_path = temp_path("notify");
    let _ = std::fs::remove_file(&sock_path);
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    let mut child = Command::new(SARD)
        .arg("--config")
        .arg(&cfg)
        .args(["--max-cycles", "3000"])
        .env("NOTIFY_SOCKET", &sock_path)
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-deploy-{}-rdt", std::process::id()),
        )
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // READY=1 comes after the first cycle with an estimate: the loop ran on
    // the emulator's samples.
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let start = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 512];
    while start.elapsed() < Duration::from_secs(60) && !got.iter().any(|m| m == "READY=1") {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    let status = child.wait().unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "{err}");
    assert!(got.iter().any(|m| m == "READY=1"), "{got:?}\n{err}");
    assert!(
        err.contains(&format!("the RDT sensor at {}", emulator.address())),
        "{err}"
    );
    assert!(err.contains("stopped after 3000 cycles"), "{err}");
    // The sinks' counters in the stop line (recording off: the recorder
    // dropped nothing).
    assert!(err.contains("0 messages dropped by the recorder"), "{err}");
    assert!(emulator.starts() >= 1);
    assert!(emulator.produced() > 0);
    let _ = std::fs::remove_file(cfg);
    let _ = std::fs::remove_file(sock_path);
}

/// The unit states the access model (issue 25, README "Access"): the
/// runtime directory where `sard` and its clients meet is systemd's
/// `RuntimeDirectory=sar` (the transport's default), the group's and
/// sticky (3770: a member removes or renames none of `sard`'s files),
/// nothing is shared through /dev/shm or /tmp, and the comment says how an
/// operator is added.
#[test]
fn the_unit_states_the_access_model() {
    let unit = std::fs::read_to_string(robot_toml().with_file_name("sard.service")).unwrap();
    let lines: Vec<&str> = unit.lines().map(str::trim).collect();
    assert_eq!(sar_shm::DEFAULT_RUNTIME_DIR, "/run/sar");
    for line in [
        "User=sar",
        "Group=sar",
        "RuntimeDirectory=sar",
        "RuntimeDirectoryMode=3770",
        "UMask=0027",
        "PrivateTmp=yes",
        "ReadWritePaths=/run/sar",
    ] {
        assert!(lines.contains(&line), "{line} missing");
    }
    assert!(unit.contains("usermod -aG sar alice"), "{unit}");
    assert!(
        !lines
            .iter()
            .any(|l| l.starts_with("ReadWritePaths=")
                && (l.contains("/dev/shm") || l.contains("/tmp"))),
        "{unit}"
    );
}
