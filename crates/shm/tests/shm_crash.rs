//! Stale shared-memory resources after a crash are cleaned at start: a child
//! process (this test binary, re-run in child mode) creates the daemon's
//! services with its publishing thread, publishes, holds a subscriber's
//! borrowed sample, and is killed with SIGKILL (no destructor runs). A new
//! daemon with the same prefix then starts in this process, and a client
//! receives its state. (`crates/daemon/tests/e2e.rs` does the same with `sard`
//! itself.) The test has a runtime directory of its own: the other tests
//! of this binary create daemons too, and a daemon's start cleans every dead
//! node of its directory, which would race this test's own cleaning.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

// The slow-subscriber tests, in this binary (one binary: less to link).
#[path = "shm/shm_slow_subscriber.rs"]
mod shm_slow_subscriber;

use sar_loop::control::Operator;
use sar_msgs::wire::StateMsg;
use sar_shm::{Client, DaemonShm};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const CHILD_ENV: &str = "SAR_SHM_CRASH_CHILD_PREFIX";
/// The child's runtime directory (the parent's own, given to the child).
const CHILD_DIR_ENV: &str = "SAR_SHM_CRASH_CHILD_DIR";
/// The child's states carry this in `cycle`'s high bits; the new daemon's
/// do not.
const CHILD_MARK: u64 = 1 << 40;

/// The child's body (a no-op in a normal test run): a daemon that publishes
/// every millisecond until killed (at most 60 s, should the parent die).
#[test]
fn child_daemon() {
    let (Ok(prefix), Some(dir)) = (std::env::var(CHILD_ENV), std::env::var_os(CHILD_DIR_ENV))
    else {
        return;
    };
    let dir = PathBuf::from(dir);
    let mut shm = create_in(&dir, &prefix).unwrap();
    // A subscriber of its own that holds a sample: the child's node owns
    // ports of every kind when it dies.
    let client = Client::in_dir(&dir, &prefix).unwrap();
    let sub = client.subscribe().unwrap();
    let start = Instant::now();
    let mut cycle = 0;
    while start.elapsed() < Duration::from_secs(60) {
        cycle += 1;
        shm.push_state(StateMsg {
            cycle: CHILD_MARK + cycle,
            ..StateMsg::default()
        });
        sub.drain(|_| {});
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// A daemon's shared memory in the runtime directory `dir`.
fn create_in(dir: &Path, prefix: &str) -> Result<DaemonShm, sar_shm::ShmError> {
    DaemonShm::create_in(dir, prefix, Operator::new(), [1.0; 6], &|| false)
}

/// Waits (bounded) for a state for which `wanted` holds.
fn wait_state(client: &Client, wanted: impl Fn(&StateMsg) -> bool) -> StateMsg {
    let start = Instant::now();
    loop {
        if let Ok(sub) = client.subscribe() {
            let t = Instant::now();
            while t.elapsed() < Duration::from_secs(2) {
                let mut found = None;
                sub.wait(Duration::from_millis(50), |s| {
                    if wanted(s) {
                        found = Some(*s);
                    }
                });
                if let Some(s) = found {
                    return s;
                }
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no such state within 30 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn after_a_sigkill_a_new_daemon_cleans_the_stale_services_and_publishes() {
    let prefix = format!("sar-crash-{}", std::process::id());
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(&prefix);
    let _ = std::fs::remove_dir_all(&dir);
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_daemon", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, &prefix)
        .env(CHILD_DIR_ENV, &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let client = Client::in_dir(&dir, &prefix).unwrap();
    let s = wait_state(&client, |s| s.cycle > CHILD_MARK);
    assert!(s.cycle > CHILD_MARK);
    // While the child lives, a second daemon with its prefix is refused.
    let refused = create_in(&dir, &prefix);
    assert!(
        matches!(refused, Err(sar_shm::ShmError::DaemonRuns { .. })),
        "a second daemon started beside a living one: {:?}",
        refused.map(|_| ())
    );

    let ok = Command::new("kill")
        .args(["-KILL", &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok);
    let _ = child.wait();

    // The killed child's node is dead and its resources stale: the cleaning
    // that the daemon runs first at start finds and removes them (iceoryx2's
    // own cleaning when a node is made depends on its configuration file;
    // this one does not).
    let cleaned = sar_shm::clean_dead_nodes_in(&dir);
    assert!(cleaned >= 1, "no dead node cleaned");
    // Then a new daemon creates its services on the same prefix.
    let mut shm = create_in(&dir, &prefix).unwrap();
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let reader_dir = dir.clone();
    let reader = std::thread::spawn(move || {
        let client = Client::in_dir(&reader_dir, &prefix).unwrap();
        let s = wait_state(&client, |s| s.cycle < CHILD_MARK && s.cycle > 0);
        done_tx.send(()).unwrap();
        s
    });
    let mut cycle = 0;
    while done_rx.try_recv().is_err() {
        assert!(cycle < 60_000, "the new daemon's states were not received");
        cycle += 1;
        shm.push_state(StateMsg {
            cycle,
            ..StateMsg::default()
        });
        std::thread::sleep(Duration::from_millis(1));
    }
    let got = reader.join().unwrap();
    assert!(got.cycle >= 1 && got.cycle <= cycle, "{got:?}");
    assert_eq!(shm.publish_errors(), 0);
    drop(shm);
    let _ = std::fs::remove_dir_all(&dir);
}
