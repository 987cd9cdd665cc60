//! The CANopen drives over the kernel's SocketCAN on vcan0: the host
//! ([`CanOpenDrives`] on one socket) and three simulated CiA 402 drives (on
//! another socket, served by a thread) in real time. Needs vcan0 up, which
//! this machine's kernel cannot do: `.ci/vcan-tests` runs it inside the small
//! VM of `shared/tools/run-in-vcan-vm.sh`. Ignored by default.
#![cfg(all(feature = "socketcan", target_os = "linux"))]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_canopen::frame::Cia402State;
use sar_canopen::{
    self as canopen, CanOpenConfig, CanOpenDrives, SimCia402Drive, SimDriveFault, SimDriveSpec,
};
use sar_hal::{AxisDrives, Clock, DriveState, Error, ErrorKind, JointPositions, MonotonicClock};
use sar_kinematics::ActiveJoints;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

const LEAD_M: f64 = 0.01;
const COUNTS: u32 = 4096;
const MS: u64 = 1_000_000;
const START_M: [f64; 3] = [0.0, 0.28, 0.30];

fn interface() -> String {
    std::env::var("SAR_VCAN_IFACE").unwrap_or_else(|_| "vcan0".into())
}

struct Drives {
    drives: Arc<Mutex<Vec<SimCia402Drive>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drives {
    fn spawn(clock: MonotonicClock) -> Self {
        let drives: Vec<_> = (0..3)
            .map(|axis| {
                SimCia402Drive::new(
                    SimDriveSpec {
                        node_id: u8::try_from(axis + 1).unwrap(),
                        lead_m: LEAD_M,
                        counts_per_turn: COUNTS,
                        max_speed_mps: 0.05,
                        max_accel_mps2: 0.5,
                        start_m: START_M[axis],
                        // A busy VM is not real-time: a host or drive thread
                        // late by tens of ms is not a fault here.
                        following_window_m: 0.02,
                    },
                    clock.now_ns().unwrap(),
                )
            })
            .collect();
        let drives = Arc::new(Mutex::new(drives));
        let stop = Arc::new(AtomicBool::new(false));
        let mut socket = canopen::socketcan::open(&interface()).unwrap();
        let (d, s) = (Arc::clone(&drives), Arc::clone(&stop));
        let thread = std::thread::spawn(move || {
            let mut out = Vec::new();
            while !s.load(Ordering::Relaxed) {
                {
                    let mut drives = d.lock().unwrap();
                    let _ =
                        canopen::serve(&mut socket, &mut drives, clock.now_ns().unwrap(), &mut out);
                }
                clock.sleep_until_ns(clock.now_ns().unwrap() + 20_000);
            }
        });
        Self {
            drives,
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Drives {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn config() -> CanOpenConfig {
    let mut c = CanOpenConfig::new([1, 2, 3], LEAD_M, COUNTS);
    c.travel_m = [(-0.1, 0.1), (0.2, 0.36), (0.12, 0.42)];
    c.sync_period_ns = 2 * MS;
    // A VM without hardware acceleration is slow: generous bounds.
    c.host_heartbeat_ms = 20;
    c.host_heartbeat_timeout_ms = 200;
    c.drive_heartbeat_ms = 20;
    c.drive_heartbeat_timeout_ms = 500;
    c.sdo_timeout_ns = 200 * MS;
    c.pdo_wait_ns = MS;
    // The drives' own following check as loose as their spec's (a late
    // thread is not a following error here).
    c.following_window_m = 0.02;
    c.following_timeout_ms = 500;
    c
}

/// Runs `n` cycles of the host at its SYNC period; returns how many missed
/// a TPDO of their SYNC (a busy VM is not real-time).
fn cycles<C: embedded_can::nb::Can, K: Clock>(
    host: &mut CanOpenDrives<C, K>,
    clock: &MonotonicClock,
    n: usize,
) -> usize {
    let period = host.config().sync_period_ns;
    let mut next = clock.now_ns().unwrap();
    let mut missed = 0;
    for _ in 0..n {
        if !host.cycle().is_ok_and(|r| r.tpdos == 3) {
            missed += 1;
        }
        next += period;
        clock.sleep_until_ns(next);
    }
    missed
}

/// The positions of the next cycle whose three TPDOs arrived in time (at
/// most 100 cycles).
fn fresh_positions<C: embedded_can::nb::Can, K: Clock>(
    host: &mut CanOpenDrives<C, K>,
    clock: &MonotonicClock,
) -> JointPositions {
    for _ in 0..100 {
        cycles(host, clock, 1);
        let p = host.positions().unwrap();
        if p.valid {
            return p;
        }
    }
    panic!("no valid positions in 100 cycles");
}

/// The three simulated drives served on the interface, and the host started
/// on another socket of it, both on `clock`.
fn drives_and_host(
    clock: MonotonicClock,
) -> (
    Drives,
    CanOpenDrives<canopen::socketcan::CanSocket, MonotonicClock>,
) {
    let sim = Drives::spawn(clock);
    let socket = canopen::socketcan::open(&interface()).unwrap();
    let host = CanOpenDrives::start(socket, clock, config()).unwrap();
    // How each drive stops, written over vcan0 and read back by the host:
    // held by every drive (ramps, never a coast).
    for d in sim.drives.lock().unwrap().iter() {
        assert_eq!(
            d.stop_options(),
            canopen::StopOptions {
                quick_stop: 6,
                shutdown: 1,
                disable_operation: 1,
                fault_reaction: 2,
                abort_connection: 3,
            },
            "node {}",
            d.node_id()
        );
    }
    (sim, host)
}

/// Asserts that the third drive of `sim` quick-stopped on the host's
/// silence (QuickStopActive, at rest, EMCY 0x8130): its position now, m.
fn assert_quick_stopped(sim: &Drives, clock: &MonotonicClock) -> f64 {
    let (state, v, emcys, x) = {
        let d = sim.drives.lock().unwrap();
        let now = clock.now_ns().unwrap();
        (
            d[2].state(),
            d[2].velocity_mps(now),
            d[2].emcys().to_vec(),
            d[2].position_m(now),
        )
    };
    assert_eq!(state, Cia402State::QuickStopActive);
    assert_eq!(v, 0.0);
    assert!(emcys.contains(&0x8130), "{emcys:x?}");
    x
}

#[test]
#[ignore = "needs SocketCAN with vcan0 up: run .ci/vcan-tests"]
fn drives_over_vcan0_start_move_and_stop_when_the_host_goes_silent() {
    let started = std::time::Instant::now();
    let clock = MonotonicClock::new().unwrap();
    let (sim, mut host) = drives_and_host(clock);
    let mut missed = cycles(&mut host, &clock, 50);
    assert_eq!(host.state().unwrap(), DriveState::Ready);
    let p = fresh_positions(&mut host, &clock);
    assert!((p.joints.q2_m - 0.28).abs() < 1e-4, "{p:?}");

    host.enable().unwrap();
    missed += cycles(&mut host, &clock, 50);
    assert_eq!(host.state().unwrap(), DriveState::Enabled);
    let target = ActiveJoints {
        q1_m: 0.0,
        q2_m: 0.28,
        q3_m: 0.32,
    };
    host.set_targets(target).unwrap();
    // 20 mm at 0.05 m/s: 0.5 s; give it 1 s.
    missed += cycles(&mut host, &clock, 500);
    assert_eq!(host.state().unwrap(), DriveState::Enabled);
    let p = fresh_positions(&mut host, &clock);
    assert!(
        (p.joints.q3_m - 0.32).abs() <= LEAD_M / f64::from(COUNTS),
        "{p:?}"
    );

    // Start a move back, then the host goes silent mid-move.
    host.set_targets(ActiveJoints {
        q3_m: 0.25,
        ..target
    })
    .unwrap();
    missed += cycles(&mut host, &clock, 100);
    clock.sleep_until_ns(clock.now_ns().unwrap() + 600 * MS);
    let x1 = assert_quick_stopped(&sim, &clock);
    assert!(x1 > 0.25 + 0.01, "stopped short of the target: {x1}");
    eprintln!(
        "vcan0 test: {:.2} s, {} bus errors, {missed} of 700 cycles missed a TPDO",
        started.elapsed().as_secs_f64(),
        host.bus_errors()
    );
}

/// Streaming (issue 15, section 3: force control changes the set point every
/// period): the host streams one set point per SYNC in cyclic synchronous
/// position (`AxisDrives::stream`), a slow sine on q3 (3 mm at 0.5 Hz: 9.4
/// mm/s at most, 19 um per 2 ms SYNC), computed from the cycle's index so
/// that a late cycle never asks for a jump. The drives follow: no following
/// fault, and every fresh position within 1 mm (the loop's
/// `following_tolerance_m`; a VM without KVM is late by tens of ms, and the
/// drives extrapolate at the set point's speed meanwhile) of the set point
/// of its SYNC. Then the host goes silent at the sine's fastest: the drives
/// keep extrapolating until their own watchdog (the host's heartbeat, 200 ms
/// here) sends EMCY 0x8130 and quick-stops them, short of where the
/// extrapolation would have run on.
#[test]
#[ignore = "needs SocketCAN with vcan0 up: run .ci/vcan-tests"]
fn drives_over_vcan0_follow_streamed_set_points_and_stop_when_the_stream_ends() {
    let started = std::time::Instant::now();
    let clock = MonotonicClock::new().unwrap();
    let (sim, mut host) = drives_and_host(clock);
    cycles(&mut host, &clock, 50);
    host.enable().unwrap();
    assert_eq!(
        cycles_until(&mut host, &clock, DriveState::Enabled, 200),
        DriveState::Enabled
    );
    let period_ns = host.config().sync_period_ns;
    let (amplitude_m, hz) = (0.003, 0.5);
    let omega = std::f64::consts::TAU * hz;
    let set_point = |k: u64| ActiveJoints {
        q1_m: START_M[0],
        q2_m: START_M[1],
        q3_m: START_M[2] + amplitude_m * (omega * (k * period_ns) as f64 * 1e-9).sin(),
    };
    // One full period of the sine: it ends at its fastest (+9.4 mm/s).
    let n = (1.0 / hz * 1e9) as u64 / period_ns;
    let (mut worst_m, mut compared, mut missed) = (0.0f64, 0, 0);
    let mut next = clock.now_ns().unwrap();
    for k in 1..=n {
        host.stream(set_point(k), period_ns).unwrap();
        if !host.cycle().is_ok_and(|r| r.tpdos == 3) {
            missed += 1;
        }
        // The positions of this SYNC: the drives applied the set point
        // written in the previous cycle and extrapolate from it; compare
        // with the nearest of the last two set points.
        let p = host.positions().unwrap();
        if p.valid && k > 2 {
            let d = [k - 1, k - 2]
                .map(|j| (p.joints.q3_m - set_point(j).q3_m).abs())
                .into_iter()
                .fold(f64::MAX, f64::min);
            worst_m = worst_m.max(d);
            compared += 1;
        }
        assert_eq!(host.state().unwrap(), DriveState::Enabled, "cycle {k}");
        // Never a burst of SYNCs to catch up after a stall of the VM: a
        // streamed set point is reached at constant speed over one SYNC
        // period, so SYNCs closer than that leave each segment unfinished
        // and the next set point out of reach (the host refuses it:
        // `InvalidTarget`, seen once in CI after a stall). The next SYNC is
        // a period after the schedule's, or half a period after now if that
        // is later (the daemon's loop skips the periods it missed too): each
        // segment is then at least half done when the next set point comes,
        // so the commanded position stays within two steps (38 um) of the
        // set points, a stall or not, well inside the 100 um reach.
        next = (next + period_ns).max(clock.now_ns().unwrap() + period_ns / 2);
        clock.sleep_until_ns(next);
    }
    assert!(
        compared > n / 2,
        "{compared} of {n} cycles had fresh positions"
    );
    assert!(worst_m < 0.001, "followed within {:.3} mm", worst_m * 1e3);
    {
        let d = sim.drives.lock().unwrap();
        let now = clock.now_ns().unwrap();
        assert_eq!(d[2].state(), Cia402State::OperationEnabled);
        // Moving (its speed is the set points' step over the time between
        // SYNCs, which a late host stretches).
        assert!(d[2].velocity_mps(now) > 0.001, "{}", d[2].velocity_mps(now));
    }

    // Silence: no SYNC, no set point, no heartbeat from the host.
    let last_m = set_point(n).q3_m;
    let silent_ns = clock.now_ns().unwrap();
    clock.sleep_until_ns(silent_ns + 800 * MS);
    let x = assert_quick_stopped(&sim, &clock);
    // It ran on past the last set point (extrapolating), and stopped within
    // the watchdog's time (200 ms, one heartbeat period, the VM's lateness:
    // 600 ms at most here) at 9.4 mm/s, plus the quick stop's ramp.
    let v_max = amplitude_m * omega;
    let bound_m = v_max * 0.6 + v_max * v_max / (2.0 * 0.5);
    assert!(x > last_m, "stopped at {x}, the last set point {last_m}");
    assert!(x - last_m < bound_m, "ran on {:.2} mm", (x - last_m) * 1e3);
    eprintln!(
        "vcan0 streaming: {:.2} s, {n} set points, {missed} cycles missed a TPDO, followed within {:.3} mm; silent: ran on {:.2} mm past the last set point before the watchdog's quick stop",
        started.elapsed().as_secs_f64(),
        worst_m * 1e3,
        (x - last_m) * 1e3
    );
}

/// Runs cycles until the host's state is `want` (at most `max` cycles); the
/// state reached.
fn cycles_until<C: embedded_can::nb::Can, K: Clock>(
    host: &mut CanOpenDrives<C, K>,
    clock: &MonotonicClock,
    want: DriveState,
    max: usize,
) -> DriveState {
    for _ in 0..max {
        cycles(host, clock, 1);
        if host.state().unwrap() == want {
            break;
        }
    }
    host.state().unwrap()
}

/// A drive's EMCY and a drive's lost heartbeat, each scheduled on the
/// simulated drive, latch the host's typed fault over the kernel's SocketCAN.
#[test]
#[ignore = "needs SocketCAN with vcan0 up: run .ci/vcan-tests"]
fn drive_faults_over_vcan0_latch_the_hosts_fault() {
    let clock = MonotonicClock::new().unwrap();
    let (sim, mut host) = drives_and_host(clock);
    cycles(&mut host, &clock, 50);
    host.enable().unwrap();
    let state = cycles_until(&mut host, &clock, DriveState::Enabled, 200);
    assert_eq!(state, DriveState::Enabled);

    // q3's drive faults with an EMCY.
    let at_ns = clock.now_ns().unwrap() + 20 * MS;
    sim.drives.lock().unwrap()[2].schedule(SimDriveFault::Emcy {
        at_ns,
        code: 0x4310,
        persistent: false,
    });
    let emcy = DriveState::Fault {
        axis: Some(2),
        code: 0x4310,
    };
    assert_eq!(cycles_until(&mut host, &clock, emcy, 500), emcy);
    host.fault_reset().unwrap();
    assert_eq!(
        cycles_until(&mut host, &clock, DriveState::Ready, 500),
        DriveState::Ready
    );

    // q2's drive stops sending its heartbeat (its TPDOs go on).
    host.enable().unwrap();
    assert_eq!(
        cycles_until(&mut host, &clock, DriveState::Enabled, 200),
        DriveState::Enabled
    );
    let at_ns = clock.now_ns().unwrap() + 20 * MS;
    sim.drives.lock().unwrap()[1].schedule(SimDriveFault::HeartbeatLoss { at_ns });
    let lost = DriveState::Fault {
        axis: Some(1),
        code: 0x8130,
    };
    // The drives' heartbeat timeout here is 500 ms: give it 2 s of cycles.
    assert_eq!(cycles_until(&mut host, &clock, lost, 1000), lost);
    let since_loss_ns = clock.now_ns().unwrap().saturating_sub(at_ns);
    assert!(
        since_loss_ns >= 480 * MS,
        "lost too early: {since_loss_ns} ns"
    );
    assert_eq!(
        host.fault_reset().unwrap_err().kind(),
        ErrorKind::DeviceFault,
        "a reset is refused while the heartbeat is missing"
    );
    sim.drives.lock().unwrap()[1].clear_fault_cause();
    cycles(&mut host, &clock, 50);
    host.fault_reset().unwrap();
    assert_eq!(
        cycles_until(&mut host, &clock, DriveState::Ready, 500),
        DriveState::Ready
    );
}

/// Serves the three simulated drives on vcan0 for `SAR_SERVE_MS` ms (default
/// 5000), for a third-party CANopen master (`.ci/canopen-peer.py`, the Python
/// `canopen` package) to check our slave's reading of the standard.
#[test]
#[ignore = "a peer's counterpart: run by .ci/vcan-tests"]
fn serve_simulated_drives_for_an_external_peer() {
    let clock = MonotonicClock::new().unwrap();
    let ms: u64 = std::env::var("SAR_SERVE_MS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5000);
    let sim = Drives::spawn(clock);
    clock.sleep_until_ns(clock.now_ns().unwrap() + ms * MS);
    drop(sim);
}
