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

use sar_test_support::files::{mkfifo, recording_config};
use std::ffi::OsStr;
use std::io::Read;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
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

/// A notify socket bound at `path` (a stale one removed first).
fn notify_socket(path: &Path) -> UnixDatagram {
    let _ = std::fs::remove_file(path);
    UnixDatagram::bind(path).unwrap()
}

/// `sard` with `args`, speaking systemd's notify protocol to `sock_path`,
/// under the service prefix of `name`: stderr piped, stdout dropped.
fn spawn_notifying<A: AsRef<OsStr>>(args: &[A], sock_path: &Path, name: &str) -> Child {
    Command::new(SARD)
        .args(args)
        .env("NOTIFY_SOCKET", sock_path)
        .env("SAR_SERVICE_PREFIX", prefix(name))
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap()
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig} failed");
}

/// Waits for the child's exit, reading its stderr meanwhile (a log larger
/// than the pipe's buffer must not block it).
fn finish(child: Child) -> (i32, String) {
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code().unwrap_or(-1), err)
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
    sar_test_support::process::run_ok(
        Command::new(SARD).arg("--check-config").arg(&good),
        "the command",
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
        let sock = notify_socket(&sock_path);
        let child = spawn_notifying(&["--sim"], &sock_path, &format!("sig{sig}"));
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
    let sock = notify_socket(&sock_path);
    // Pings every 100 cycles at 1 kHz; the loop stalls after cycle 300: at
    // most 3 pings, however long we listen.
    let args = ["--sim", "--stall-after-cycles", "300"];
    let child = spawn_notifying(&args, &sock_path, "stall");
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
    mkfifo(&fifo);
    let line = 1 + sar_config::DEFAULT_TOML
        .lines()
        .position(|l| l.starts_with("length_m = "))
        .unwrap();
    let unit_mistake = format!(
        "manipulator.length_m (line {line}): must be within 0.1..=1.5 m, got 35 (a value in cm?"
    );
    for (path, words) in [
        (cm.clone(), unit_mistake.as_str()),
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
    mkfifo(&fifo);
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

/// Issue 25, finding 7: the terminal that runs `sard` closes (SIGHUP), or
/// someone sends SIGUSR1: the daemon stops as on SIGTERM, with the drives
/// halted, the stop line (naming the signal) logged, exit 0, and a complete
/// recording (readable, its summary written).
#[test]
fn sighup_and_sigusr1_stop_cleanly_with_the_recording_complete() {
    for sig in ["-HUP", "-USR1"] {
        let dir = temp_path(&format!("sig{sig}"));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let (config, rec_dir) = recording_config(&dir);
        let sock_path = dir.join("notify");
        let sock = notify_socket(&sock_path);
        let args = [
            OsStr::new("--sim"),
            OsStr::new("--config"),
            config.as_os_str(),
        ];
        let child = spawn_notifying(&args, &sock_path, &format!("sig{sig}"));
        // Two watchdog pings: 200 cycles into the loop, recording.
        let got = collect(&sock, Duration::from_secs(30), |g| {
            g.iter().filter(|m| *m == "WATCHDOG=1").count() >= 2
        });
        assert!(got.iter().any(|m| m == "READY=1"), "{got:?}");
        signal(&child, sig);
        let (code, err) = finish(child);
        assert_eq!(code, 0, "{sig}: exit {code}: {err}");
        assert!(err.contains("drives halted"), "{sig}: {err}");
        let name = format!("SIG{}", &sig[1..]);
        assert!(err.contains(&name), "{sig}: the stop line names it: {err}");
        let files: Vec<PathBuf> = std::fs::read_dir(&rec_dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| !p.to_string_lossy().ends_with(".scene.mcap"))
            .collect();
        assert_eq!(files.len(), 1, "{files:?}");
        let bytes = std::fs::read(&files[0]).unwrap();
        let mut reader = sar_record::McapReader::new(&bytes).unwrap();
        let mut messages = 0;
        for m in reader.by_ref() {
            m.unwrap();
            messages += 1;
        }
        assert!(messages > 100, "{sig}: {messages} messages");
        assert!(reader.is_complete(), "{sig}: the data section is cut");
        // The footer (opcode 0x02, 20 bytes) before the closing magic names
        // where the summary starts: 0 would be a file without one.
        let footer = bytes.len() - 8 - 29;
        assert_eq!(bytes[footer], 0x02, "{sig}: no footer");
        let summary_start = u64::from_le_bytes(bytes[footer + 9..footer + 17].try_into().unwrap());
        assert!(summary_start > 0, "{sig}: the summary is missing");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// Issue 25, finding 7: after a stall (SIGSTOP for a second, then SIGCONT)
/// the loop skips the missed periods, counted in one log line, instead of
/// running them back to back (it used to run about 1000 cycles at once and
/// log an "overran" line for each). The guard's reaction to the jump in
/// time is the one SAFETY.md C4 states: the inputs are too old on waking.
#[test]
fn after_a_stall_the_missed_periods_are_skipped_and_counted_once() {
    let sock_path = temp_path("notify-stop-cont");
    let sock = notify_socket(&sock_path);
    let child = spawn_notifying(&["--sim"], &sock_path, "stop-cont");
    // Ok once the automatic reset is accepted (after the mean at rest).
    let got = collect(&sock, Duration::from_secs(60), |g| {
        g.iter().any(|m| m == "WATCHDOG=1") && g.iter().any(|m| m.starts_with("STATUS=guard ok"))
    });
    assert!(
        got.iter().any(|m| m.starts_with("STATUS=guard ok")),
        "{got:?}"
    );
    signal(&child, "-STOP");
    // The stall itself (the process cannot run: nothing to race with).
    std::thread::sleep(Duration::from_millis(1000));
    // What the loop sent before it was stopped.
    let _ = collect(&sock, Duration::from_millis(200), |_| false);
    signal(&child, "-CONT");
    // The loop runs again: its status after the stall, then two pings
    // (200 cycles later) or the faulted guard's status.
    let after = collect(&sock, Duration::from_secs(30), |g| {
        g.iter().filter(|m| *m == "WATCHDOG=1").count() >= 2
    });
    signal(&child, "-TERM");
    let (code, err) = finish(child);
    assert_eq!(code, 0, "{err}");
    let overran = err.lines().filter(|l| l.contains("overran")).count();
    let skipped: Vec<u64> = err
        .lines()
        .filter_map(|l| {
            let (_, rest) = l.split_once("overran its period by ")?;
            let (_, rest) = rest.split_once(": ")?;
            rest.split_whitespace().next()?.parse().ok()
        })
        .collect();
    assert!(
        overran < 50,
        "{overran} overrun lines after one stall of 1 s:\n{err}"
    );
    let stall = skipped.iter().copied().max().unwrap_or(0);
    assert!(
        (900..=1300).contains(&stall),
        "the stall of 1 s at 1 kHz skipped {skipped:?} periods:\n{err}"
    );
    // The jump in time faults the guard on the inputs' age (C4).
    let status: Vec<&String> = after.iter().filter(|m| m.starts_with("STATUS=")).collect();
    assert!(
        status.iter().any(|m| m.starts_with("STATUS=guard FAULT")),
        "{after:?}\n{err}"
    );
    let fault = err.lines().find(|l| l.contains("guard ok -> fault"));
    let fault = fault.unwrap_or_else(|| panic!("no fault after the stall:\n{err}"));
    // `--nocapture` shows which input aged first.
    println!("after the stall: {fault}");
    let _ = std::fs::remove_file(&sock_path);
}
