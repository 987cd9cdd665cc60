//! What the tests of `sarctl` against a running daemon share: where the
//! daemon's binary is, how to start it and wait for it, how to run `sarctl`
//! against it, and a recording of `sard --sim`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::LazyLock;
use std::time::{Duration, Instant};

/// `sarctl`, this package's binary.
pub const SARCTL: &str = env!("CARGO_BIN_EXE_sarctl");

/// `sard`, sar-daemon's binary, in the same target directory as `sarctl`.
/// `cargo test --workspace` (the README's test command) builds every
/// package's binaries before any test runs, so it is this build's; run alone
/// (`cargo test -p sarctl`), build it first (`cargo build -p sar-daemon`).
pub static SARD: LazyLock<PathBuf> = LazyLock::new(|| {
    let sard = std::path::Path::new(SARCTL).with_file_name("sard");
    assert!(
        sard.exists(),
        "{} is missing: these tests run sar-daemon's binary; run `cargo test --workspace`, \
         or `cargo build -p sar-daemon` first",
        sard.display()
    );
    sard
});

/// A fresh scratch directory `root/name` under the target's tmp dir.
pub fn scratch_in(root: &str, name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(root)
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A fresh scratch directory under the target's tmp dir (where sar-daemon's
/// tests make theirs).
pub fn scratch(name: &str) -> PathBuf {
    scratch_in("sar-daemon", name)
}

/// Makes a FIFO at `path` (`mkfifo`).
pub fn mkfifo(path: &Path) {
    assert!(Command::new("mkfifo").arg(path).status().unwrap().success());
}

/// Lossy UTF-8 of a process's output.
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `sarctl ARGS` against the daemon under `prefix`.
pub fn sarctl(prefix: &str, args: &[&str]) -> Output {
    Command::new(SARCTL)
        .args(args)
        .env("SAR_SERVICE_PREFIX", prefix)
        .output()
        .unwrap()
}

/// `sard` under `prefix`, its standard output and error discarded (a caller
/// may set its own standard error, arguments and directory).
pub fn sard(prefix: &str) -> Command {
    let mut cmd = Command::new(&*SARD);
    cmd.env("SAR_SERVICE_PREFIX", prefix)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    cmd
}

/// A child process (a daemon) ended with SIGTERM, then waited for, when
/// dropped.
pub struct Daemon(pub Child);

impl Daemon {
    /// Spawns `cmd`.
    pub fn spawn(cmd: &mut Command) -> Self {
        Self(cmd.spawn().unwrap())
    }

    /// Spawns `cmd` and waits until `sarctl status` answers under `prefix`.
    pub fn start(cmd: &mut Command, prefix: &str) -> Self {
        let daemon = Self::spawn(cmd);
        wait_until_up(prefix);
        daemon
    }

    /// Ends the daemon with SIGTERM; it must exit with success.
    pub fn stop(mut self) {
        terminate(&self.0);
        let status = self.0.wait().unwrap();
        assert!(status.success(), "sard ended with {status}");
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        terminate(&self.0);
        let _ = self.0.wait();
    }
}

/// Sends SIGTERM to `child`.
fn terminate(child: &Child) {
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
}

/// Waits until `sarctl status` answers under `prefix` (30 s at most).
pub fn wait_until_up(prefix: &str) {
    let start = Instant::now();
    while !sarctl(prefix, &["status"]).status.success() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "sard did not come up"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits (60 s at most) for the daemon under `prefix` to publish a state
/// that `ok` accepts; `what` names it in the failure.
pub fn wait_for_state(prefix: &str, what: &str, ok: impl Fn(&sar_msgs::wire::StateMsg) -> bool) {
    let client = sar_shm::Client::new(prefix).unwrap();
    let start = Instant::now();
    loop {
        if let Ok(sub) = client.subscribe()
            && let Some(s) = sub.latest(Duration::from_secs(1))
            && ok(&s)
        {
            return;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "{what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

pub use sar_test_support::files::{lean_recording_config, recording_config, recordings};

/// `sard --sim` under `prefix` for `cycles` with the configuration of
/// [`recording_config`]: the one recording's file.
pub fn sim_recording(dir: &Path, cycles: u64, prefix: &str) -> PathBuf {
    sim_recording_of(recording_config(dir), cycles, prefix)
}

/// [`sim_recording`] in the lean mode (`[record] mode = "inputs"`).
pub fn sim_lean_recording(dir: &Path, cycles: u64, prefix: &str) -> PathBuf {
    sim_recording_of(lean_recording_config(dir), cycles, prefix)
}

/// `sard --sim` with the configuration and recordings' directory given.
fn sim_recording_of((config, rec_dir): (PathBuf, PathBuf), cycles: u64, prefix: &str) -> PathBuf {
    let out = Command::new(&*SARD)
        .args(["--sim", "--config"])
        .arg(&config)
        .args(["--max-cycles", &cycles.to_string()])
        .env("SAR_SERVICE_PREFIX", prefix)
        .stdout(Stdio::null())
        .output()
        .unwrap();
    assert!(out.status.success(), "sard: {}", text(&out.stderr));
    let files = recordings(&rec_dir);
    assert_eq!(files.len(), 1, "{files:?}");
    files[0].clone()
}
