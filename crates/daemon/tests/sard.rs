//! `sard` as a process: `--check-config`, a clean stop on SIGTERM and SIGINT
//! (drives halted, exit 0), and systemd's notify protocol through a fake
//! `NOTIFY_SOCKET` (READY=1, WATCHDOG=1 from the loop, STATUS=, STOPPING=1;
//! no WATCHDOG=1 once the loop is stalled on purpose).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::Read;
use std::os::unix::net::UnixDatagram;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const SARD: &str = env!("CARGO_BIN_EXE_sard");

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("sard-test-{}-{name}", std::process::id()))
}

/// A service prefix no other test (or test run) uses.
fn prefix(name: &str) -> String {
    format!("sar-test-{}-{name}", std::process::id())
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig} failed");
}

fn finish(mut child: Child) -> (i32, String) {
    let status = child.wait().unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    (status.code().unwrap_or(-1), err)
}

/// Collects notify messages until `until` says stop or `limit` passes.
fn collect(sock: &UnixDatagram, limit: Duration, until: impl Fn(&[String]) -> bool) -> Vec<String> {
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let start = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 512];
    while start.elapsed() < limit && !until(&got) {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    got
}

#[test]
fn check_config_accepts_a_good_file_and_names_the_key_of_a_bad_one() {
    let good = temp_path("good.toml");
    std::fs::write(&good, sar_config::DEFAULT_TOML).unwrap();
    let out = Command::new(SARD)
        .arg("--check-config")
        .arg(&good)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bad = temp_path("bad.toml");
    std::fs::write(
        &bad,
        sar_config::DEFAULT_TOML.replace("stop_total_n = 15.0", "stop_total = 15.0"),
    )
    .unwrap();
    let out = Command::new(SARD)
        .arg("--check-config")
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&bad.display().to_string()), "{err}");
    assert!(err.contains("guard.stop_total (line"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    let _ = std::fs::remove_file(good);
    let _ = std::fs::remove_file(bad);
}

#[test]
fn sigterm_and_sigint_stop_the_loop_cleanly_with_the_drives_halted() {
    for sig in ["-TERM", "-INT"] {
        let sock_path = temp_path(&format!("notify{sig}"));
        let _ = std::fs::remove_file(&sock_path);
        let sock = UnixDatagram::bind(&sock_path).unwrap();
        let child = Command::new(SARD)
            .arg("--sim")
            .env("NOTIFY_SOCKET", &sock_path)
            .env("SAR_SERVICE_PREFIX", prefix(&format!("sig{sig}")))
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        // Ok once the automatic reset is accepted (after the mean at rest).
        let got = collect(&sock, Duration::from_secs(60), |g| {
            g.iter().any(|m| m == "WATCHDOG=1")
                && g.iter().any(|m| m.starts_with("STATUS=guard ok"))
        });
        assert!(got.iter().any(|m| m == "READY=1"), "{got:?}");
        assert!(
            got.iter().any(|m| m.starts_with("STATUS=guard ok")),
            "{got:?}"
        );
        signal(&child, sig);
        let (code, err) = finish(child);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("drives halted"), "{err}");
        let rest = collect(&sock, Duration::from_millis(500), |g| {
            g.iter().any(|m| m == "STOPPING=1")
        });
        assert!(rest.iter().any(|m| m == "STOPPING=1"), "{rest:?}");
        let _ = std::fs::remove_file(&sock_path);
    }
}

#[test]
fn a_stalled_loop_stops_feeding_the_watchdog() {
    let sock_path = temp_path("notify-stall");
    let _ = std::fs::remove_file(&sock_path);
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    // Pings every 100 cycles at 1 kHz; the loop stalls after cycle 300: at
    // most 3 pings, however long we listen.
    let child = Command::new(SARD)
        .args(["--sim", "--stall-after-cycles", "300"])
        .env("NOTIFY_SOCKET", &sock_path)
        .env("SAR_SERVICE_PREFIX", prefix("stall"))
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let got = collect(&sock, Duration::from_secs(3), |_| false);
    signal(&child, "-TERM");
    let (code, err) = finish(child);
    assert_eq!(code, 0, "{err}");
    let pings = got.iter().filter(|m| *m == "WATCHDOG=1").count();
    assert!(got.iter().any(|m| m == "READY=1"), "{got:?}");
    assert!(
        pings <= 3,
        "{pings} pings from a loop stalled after 300 cycles: {got:?}"
    );
    let _ = std::fs::remove_file(&sock_path);
}

/// Issue 25, finding 4: `--check-config` reported `length_m = 35.0` (for
/// 0.35) valid, blocked on a FIFO and read /dev/zero until memory ran out.
/// Now each is refused at once, in one line, naming the range and the
/// likely unit or what the path is.
#[test]
fn check_config_refuses_a_unit_mistake_and_a_non_regular_file_at_once() {
    let cm = temp_path("length-cm.toml");
    std::fs::write(
        &cm,
        sar_config::DEFAULT_TOML.replace("length_m = 0.35 ", "length_m = 35.0 "),
    )
    .unwrap();
    let fifo = temp_path("config.fifo");
    let _ = std::fs::remove_file(&fifo);
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    for (path, words) in [
        (
            cm.clone(),
            "manipulator.length_m (line 19): must be within 0.1..=1.5 m, got 35 (a value in cm?",
        ),
        (
            fifo.clone(),
            "cannot read the file: not a regular file (a FIFO)",
        ),
        (
            PathBuf::from("/dev/zero"),
            "cannot read the file: not a regular file (a character device)",
        ),
    ] {
        let mut child = Command::new(SARD)
            .arg("--check-config")
            .arg(&path)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{}: not refused within 10 s", path.display());
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let mut err = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut err)
            .unwrap();
        assert!(!status.success(), "{}: {err}", path.display());
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(words), "{err} lacks {words:?}");
        assert!(err.len() < 700, "{err}");
    }
    let _ = std::fs::remove_file(cm);
    let _ = std::fs::remove_file(fifo);
}

/// Finding 2 of issue 25: `sard` stuck in iceoryx2 (there: spinning on a
/// truncated management file) ignored SIGTERM until killed. A damaged file
/// in the runtime directory that blocks iceoryx2 (a node's details file that
/// is a FIFO: reading it never returns): `sard` gives up after 2 s with a
/// line naming the directory, and a SIGTERM meanwhile ends it at once.
#[test]
fn sard_stuck_in_iceoryx2_answers_sigterm_and_gives_up_in_two_seconds() {
    let run = temp_path("stuck-run");
    let _ = std::fs::remove_dir_all(&run);
    std::fs::create_dir_all(run.join("nodes/111")).unwrap();
    // A node "111": its monitor token (no process holds its lock: dead) and
    // its details, a FIFO.
    std::fs::write(run.join("nodes/iox2_111.node_monitor"), b"").unwrap();
    let fifo = run.join("nodes/111/iox2_node.details");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let start = |name: &str| {
        Command::new(SARD)
            .args(["--sim", "--max-cycles", "3000"])
            .env("SAR_RUNTIME_DIR", &run)
            .env("SAR_SERVICE_PREFIX", prefix(name))
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .unwrap()
    };
    let t = Instant::now();
    let (code, err) = finish(start("stuck"));
    assert!(t.elapsed() < Duration::from_secs(3), "{:?}", t.elapsed());
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("did not create the services within 2000 ms")
            && err.contains(&run.display().to_string()),
        "{err}"
    );
    let child = start("stuck-term");
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    signal(&child, "-TERM");
    let (code, err) = finish(child);
    assert!(
        t.elapsed() < Duration::from_millis(500),
        "{:?}",
        t.elapsed()
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("stopped while creating"), "{err}");
    let _ = std::fs::remove_dir_all(&run);
}
