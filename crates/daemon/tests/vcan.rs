//! `sard` as a process on CANopen drives over the kernel's SocketCAN: three
//! simulated CiA 402 drives served on vcan0 by a thread of this test, and
//! `sard --config` naming `canopen` on vcan0 (with the simulated sensor: the
//! bench set-up). Needs vcan0 up, which this machine's kernel cannot do:
//! `.ci/vcan-tests` runs it inside the small VM of
//! `shared/tools/run-in-vcan-vm.sh`. Ignored by default.
#![cfg(all(feature = "socketcan", target_os = "linux"))]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_canopen::{self as canopen, SimCia402Drive, SimDriveSpec};
use sar_config as config;
use sar_hal::{Clock, MonotonicClock};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

const SARD: &str = env!("CARGO_BIN_EXE_sard");

fn interface() -> String {
    std::env::var("SAR_VCAN_IFACE").unwrap_or_else(|_| "vcan0".into())
}

#[test]
#[ignore = "needs vcan0: run by .ci/vcan-tests in the vcan VM"]
fn sard_starts_and_cycles_canopen_drives_over_vcan0() {
    let clock = MonotonicClock::new().unwrap();
    let start_m = [0.0, 0.28, 0.30];
    let mut drives: Vec<_> = (0..3)
        .map(|axis| {
            SimCia402Drive::new(
                SimDriveSpec {
                    node_id: u8::try_from(axis + 1).unwrap(),
                    lead_m: 0.01,
                    counts_per_turn: 4096,
                    max_speed_mps: 0.05,
                    max_accel_mps2: 0.5,
                    start_m: start_m[axis],
                    // A VM is not real-time.
                    following_window_m: 0.02,
                },
                clock.now_ns().unwrap(),
            )
        })
        .collect();
    let mut socket = canopen::socketcan::open(&interface()).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s = Arc::clone(&stop);
    let server = std::thread::spawn(move || {
        let mut out = Vec::new();
        let mut syncs = 0;
        while !s.load(Ordering::Relaxed) {
            let _ = canopen::serve(&mut socket, &mut drives, clock.now_ns().unwrap(), &mut out);
            clock.sleep_until_ns(clock.now_ns().unwrap() + 20_000);
            syncs = drives.iter().map(|d| d.syncs()).min().unwrap_or(0);
        }
        syncs
    });
    let cfg = std::env::temp_dir().join(format!("sard-vcan-{}.toml", std::process::id()));
    std::fs::write(
        &cfg,
        config::DEFAULT_TOML
            .replace("rate_hz = 1000.0", "rate_hz = 250.0")
            .replace(
                "[drivers.axes]\nkind = \"sim\"",
                &format!(
                    "[drivers.axes]\nkind = \"canopen\"\ninterface = \"{}\"\nnode_ids = [1, 2, 3]\nlead_m = 0.01\ncounts_per_turn = 4096",
                    interface()
                ),
            ),
    )
    .unwrap();
    let out = Command::new(SARD)
        .arg("--config")
        .arg(&cfg)
        .args(["--max-cycles", "500"])
        .env(
            "SAR_SERVICE_PREFIX",
            format!("sar-vcan-{}", std::process::id()),
        )
        .output()
        .unwrap();
    stop.store(true, Ordering::Relaxed);
    let syncs = server.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains(&format!("the CANopen drives on {}", interface())),
        "{err}"
    );
    assert!(err.contains("stopped after 500 cycles"), "{err}");
    // Every drive saw the loop's SYNCs (one per cycle; the bring-up's too).
    assert!(syncs >= 500, "{syncs} SYNCs\n{err}");
    eprintln!("{syncs} SYNCs; sard said:\n{err}");
    let _ = std::fs::remove_file(cfg);
}
