//! The CANopen axis drives on the in-memory bus with simulated CiA 402
//! drives: the drive conformance suite, start-up, the CiA 402 state machine,
//! CSP streaming, EMCY, heartbeat loss, the drives' own watchdog when the host
//! goes silent, and bus errors. Deterministic: one simulated clock, the bus
//! stepped by hand.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_hal::conformance;

use conformance::{Capability, DrivesHarness};
use sar_canopen::frame::{
    self, COB_RPDO1, COB_SDO_RX, COB_SYNC, Cia402State, RawFrame, Sdo, control, decode_rpdo,
};
use sar_canopen::{
    CanOpenConfig, CanOpenDrives, CanOpenError, FOLLOWING_WINDOW_M, MemBus, MemBusError, MemCan,
    SimCia402Drive, SimDriveFault, SimDriveSpec, StopOptions,
};
use sar_hal::Vec3;
use sar_hal::{AxisDrives, DriveState, Error, ErrorKind, SimClock};
use sar_kinematics::{ActiveJoints, Calibration, CalibrationSpec, Mat3, Profile, ProfileSpec};
use sar_sim::{AxesSpec, ContactKey, Fault, PlantSpec, SensorSpec, SimSpec, Simulator};

const CLOCK_START_NS: u64 = 5_000_000_000_000;
const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;
const LEAD_M: f64 = 0.01;
const COUNTS: u32 = 4096;
const V_MAX: f64 = 0.05;
const A_MAX: f64 = 0.5;
const NODES: [u8; 3] = [1, 2, 3];
const START_M: [f64; 3] = [0.0, 0.28, 0.30];

fn count_m() -> f64 {
    LEAD_M / f64::from(COUNTS)
}

fn config() -> CanOpenConfig {
    let mut c = CanOpenConfig::new(NODES, LEAD_M, COUNTS);
    c.max_speed_mps = V_MAX;
    c.max_accel_mps2 = A_MAX;
    c.travel_m = [(-0.1, 0.1), (0.2, 0.36), (0.12, 0.42)];
    c
}

fn drive_spec(axis: usize) -> SimDriveSpec {
    SimDriveSpec {
        node_id: NODES[axis],
        lead_m: LEAD_M,
        counts_per_turn: COUNTS,
        max_speed_mps: V_MAX,
        max_accel_mps2: A_MAX,
        start_m: START_M[axis],
        following_window_m: FOLLOWING_WINDOW_M,
    }
}

/// The host, the bus and three simulated drives on one simulated clock.
struct Rig {
    clock: SimClock,
    bus: MemBus,
    drives: CanOpenDrives<MemCan, SimClock>,
    next_cycle_ns: u64,
    /// The host runs its cycles (false: the host is stalled).
    host_alive: bool,
    errors: Vec<CanOpenError>,
}

impl Rig {
    fn new() -> Self {
        Self::with_config(config())
    }

    fn with_config(config: CanOpenConfig) -> Self {
        let clock = SimClock::new(CLOCK_START_NS);
        let bus = MemBus::new(clock.clone());
        for axis in 0..3 {
            bus.add_drive(SimCia402Drive::new(drive_spec(axis), clock.now_ns()));
        }
        bus.tick();
        let drives = CanOpenDrives::start(bus.can(), clock.clone(), config).unwrap();
        let next_cycle_ns = clock.now_ns();
        let mut rig = Self {
            clock,
            bus,
            drives,
            next_cycle_ns,
            host_alive: true,
            errors: Vec::new(),
        };
        rig.run(20 * MS);
        rig.errors.clear();
        rig
    }

    fn now(&self) -> u64 {
        self.clock.now_ns()
    }

    /// Lets `ns` pass: the drives tick every 100 µs, the host cycles every
    /// SYNC period.
    fn run(&mut self, ns: u64) {
        let end = self.now() + ns;
        loop {
            let next_tick = (self.now() / (MS / 10) + 1) * (MS / 10);
            let next = next_tick.min(self.next_cycle_ns).min(end);
            if next > self.now() {
                self.clock.advance_ns(next - self.now());
            }
            self.bus.tick();
            if self.now() >= self.next_cycle_ns {
                let result = self.host_alive.then(|| self.drives.cycle());
                if let Some(Err(e)) = result {
                    self.errors.push(e);
                }
                self.next_cycle_ns += MS;
            }
            if self.now() >= end {
                break;
            }
        }
    }

    fn drive<R>(
        &self,
        axis: usize,
        f: impl FnOnce(&mut SimCia402Drive, u64, &mut Vec<RawFrame>) -> R,
    ) -> R {
        self.bus.with_drive(axis, f).unwrap()
    }

    fn true_position(&self, axis: usize) -> f64 {
        self.drive(axis, |d, now, _| d.position_m(now))
    }

    fn cia402(&self, axis: usize) -> Cia402State {
        self.drive(axis, |d, _, _| d.state())
    }

    fn await_state(&mut self, want: DriveState) {
        for _ in 0..200 {
            if self.drives.state().unwrap() == want {
                return;
            }
            self.run(MS);
        }
        panic!("{:?}, not {want:?}", self.drives.state().unwrap());
    }

    fn enable(&mut self) {
        self.drives.enable().unwrap();
        self.await_state(DriveState::Enabled);
    }
}

fn target() -> ActiveJoints {
    ActiveJoints {
        q1_m: 0.01,
        q2_m: 0.27,
        q3_m: 0.35,
    }
}

// ---------------------------------------------------------------------------
// The conformance suite

struct Harness {
    rig: Rig,
}

impl DrivesHarness for Harness {
    type Drives = CanOpenDrives<MemCan, SimClock>;
    fn drives(&mut self) -> &mut Self::Drives {
        &mut self.rig.drives
    }
    fn let_time_pass(&mut self, ns: u64) {
        self.rig.run(ns);
    }
    fn now_ns(&self) -> u64 {
        self.rig.now()
    }
    fn reachable_target(&self) -> ActiveJoints {
        target()
    }
    fn out_of_travel_target(&self) -> Capability<ActiveJoints> {
        Capability::Ready(ActiveJoints {
            q1_m: 0.0,
            q2_m: 0.28,
            q3_m: 0.43,
        })
    }
    fn settle_bound_ns(&self) -> u64 {
        2 * S
    }
    fn tolerance_m(&self) -> f64 {
        count_m()
    }
    fn report_age_bound_ns(&self) -> u64 {
        MS
    }
    fn call_slack_ns(&self) -> u64 {
        0
    }
    fn transition_bound_ns(&self) -> u64 {
        20 * MS
    }
    fn provoke_fault(&mut self) -> Capability<()> {
        self.rig
            .drive(1, |d, now, out| d.inject_fault(0x2310, false, now, out));
        self.rig.run(2 * MS);
        Capability::Ready(())
    }
}

macro_rules! conformance_tests {
    ($suite:ident, $harness:expr, [$($check:ident),* $(,)?]) => {
        mod $suite {
            use super::*;
            $(
                #[test]
                fn $check() {
                    conformance::$suite::$check(&mut $harness);
                }
            )*
        }
    };
}

conformance_tests!(
    drives,
    Harness { rig: Rig::new() },
    [
        starts_ready_and_refuses_targets,
        enable_accepts_targets_and_disable_refuses_them,
        invalid_targets_are_invalid_arguments,
        quick_stop_from_ready_and_back,
        quick_stop_while_moving_stops_and_holds,
        fault_reset_outside_fault_is_invalid_state,
        positions_are_stamped_fresh_and_in_order,
        reaches_a_reachable_target_and_holds,
        transient_fault_is_reported_and_reset,
    ]
);

// ---------------------------------------------------------------------------
// Start-up

fn sdo_writes(sent: &[RawFrame], node: u8) -> Vec<(u16, u8, u32)> {
    sent.iter()
        .filter(|f| f.cob_id == COB_SDO_RX + u16::from(node))
        .filter_map(|f| match Sdo::decode(f.payload()) {
            Some(Sdo::Download {
                index, sub, value, ..
            }) => Some((index, sub, value)),
            _ => None,
        })
        .collect()
}

#[test]
fn start_up_maps_the_pdos_sets_csp_and_the_watchdog_and_starts_the_nodes() {
    let rig = Rig::new();
    let sent = rig.bus.take_sent();
    // NMT reset of each node first, NMT start last.
    let nmt: Vec<&[u8]> = sent
        .iter()
        .filter(|f| f.cob_id == 0)
        .map(|f| f.payload())
        .collect();
    assert_eq!(
        nmt,
        [
            &[0x81, 1][..],
            &[0x81, 2],
            &[0x81, 3],
            &[0x01, 1],
            &[0x01, 2],
            &[0x01, 3]
        ]
    );
    for (axis, node) in NODES.iter().enumerate() {
        let w = sdo_writes(&sent, *node);
        let n = u32::from(*node);
        for expected in [
            (0x1A00, 1, 0x6041_0010),
            (0x1A00, 2, 0x6064_0020),
            (0x1A00, 0, 2),
            (0x1800, 1, 0x180 + n),
            (0x1800, 2, 1),
            (0x1600, 1, 0x6040_0010),
            (0x1600, 2, 0x607A_0020),
            (0x1600, 0, 2),
            (0x1400, 1, 0x200 + n),
            (0x6060, 0, 8),
            (0x6007, 0, 3),
            (0x1016, 1, (127 << 16) | 50),
            (0x1017, 0, 10),
        ] {
            assert!(
                w.contains(&expected),
                "node {node}: {expected:x?} not in {w:x?}"
            );
        }
        // The mapping is written with the PDO disabled (COB-ID bit 31).
        let disable = w
            .iter()
            .position(|x| *x == (0x1800, 1, 0x8000_0000 | (0x180 + n)));
        let map = w.iter().position(|x| *x == (0x1A00, 1, 0x6041_0010));
        assert!(disable.unwrap() < map.unwrap());
        rig.drive(axis, |d, _, _| {
            assert_eq!(d.mode(), 8);
            assert_eq!(d.nmt_state(), frame::heartbeat::OPERATIONAL);
        });
        // The first cycles brought the drives to Ready to switch on.
        assert_eq!(rig.cia402(axis), Cia402State::ReadyToSwitchOn);
    }
}

#[test]
fn a_missing_drive_fails_the_start_up_within_the_bound() {
    let clock = SimClock::new(CLOCK_START_NS);
    let bus = MemBus::new(clock.clone());
    bus.add_drive(SimCia402Drive::new(drive_spec(0), clock.now_ns()));
    bus.add_drive(SimCia402Drive::new(drive_spec(1), clock.now_ns()));
    let config = config();
    let err = CanOpenDrives::start(bus.can(), clock.clone(), config.clone()).unwrap_err();
    assert_eq!(
        err,
        CanOpenError::NoBootUp {
            node: 3,
            timeout_ns: config.boot_timeout_ns
        }
    );
    assert_eq!(err.kind(), ErrorKind::Timeout);
    let waited = clock.now_ns() - CLOCK_START_NS;
    assert!(waited >= config.boot_timeout_ns && waited <= config.boot_timeout_ns + MS);
}

#[test]
fn a_bad_configuration_is_refused() {
    let clock = SimClock::new(0);
    let bus = MemBus::new(clock.clone());
    let mut c = config();
    c.node_ids = [1, 2, 2];
    let err = CanOpenDrives::start(bus.can(), clock.clone(), c).unwrap_err();
    assert!(
        matches!(
            err,
            CanOpenError::InvalidConfig {
                field: "node_ids",
                ..
            }
        ),
        "{err}"
    );
    let mut c = config();
    c.lead_m = f64::NAN;
    let err = CanOpenDrives::start(bus.can(), clock, c).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidArgument);
}

// ---------------------------------------------------------------------------
// The cycle and the state machine

/// The (control word, target counts) of the RPDOs sent to `node`.
fn rpdos(sent: &[RawFrame], node: u8) -> Vec<(u16, i32)> {
    sent.iter()
        .filter(|f| f.cob_id == COB_RPDO1 + u16::from(node))
        .map(|f| decode_rpdo(f.payload()).unwrap())
        .collect()
}

#[test]
fn enable_walks_shutdown_switch_on_enable_operation() {
    let mut rig = Rig::new();
    rig.enable();
    let words: Vec<u16> = rpdos(&rig.bus.take_sent(), 2).iter().map(|r| r.0).collect();
    let mut distinct = words.clone();
    distinct.dedup();
    assert_eq!(
        distinct,
        [
            control::SHUTDOWN,
            control::SWITCH_ON,
            control::ENABLE_OPERATION
        ],
        "{words:x?}"
    );
    for axis in 0..3 {
        assert_eq!(rig.cia402(axis), Cia402State::OperationEnabled);
    }
    // Enabling did not move the axes.
    for (axis, start) in START_M.iter().enumerate() {
        assert!((rig.true_position(axis) - start).abs() <= count_m());
    }
}

#[test]
fn every_cycle_sends_one_sync_then_one_limited_set_point_per_axis() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.bus.take_sent();
    rig.run(1500 * MS);
    let sent = rig.bus.take_sent();
    let syncs = sent.iter().filter(|f| f.cob_id == COB_SYNC).count();
    assert_eq!(syncs, 1500);
    // After each SYNC, one RPDO per axis before the next SYNC.
    let mut since_sync = 0;
    let mut first = true;
    for f in &sent {
        if f.cob_id == COB_SYNC {
            assert!(first || since_sync == 3, "{since_sync}");
            first = false;
            since_sync = 0;
        } else if (0x201..=0x203).contains(&f.cob_id) {
            since_sync += 1;
        }
    }
    assert_eq!(since_sync, 3);
    // Set points of q3 (0.30 -> 0.35 m): within the speed and acceleration
    // limits, monotone, ending at the target.
    let dt = 1e-3;
    let q3: Vec<f64> = rpdos(&sent, 3)
        .iter()
        .map(|r| f64::from(r.1) * count_m())
        .collect();
    for w in q3.windows(2) {
        let v = (w[1] - w[0]) / dt;
        assert!(v <= V_MAX + 2.0 * count_m() / dt && v >= -1e-12, "{v}");
    }
    // Acceleration over 25 ms windows, so that the encoder's quantisation
    // (2.4 um) leaves a slack of 0.008 m/s^2, not 10 m/s^2.
    let k = 25;
    let h = k as f64 * dt;
    for i in 0..q3.len().saturating_sub(2 * k) {
        let v1 = (q3[i + k] - q3[i]) / h;
        let v2 = (q3[i + 2 * k] - q3[i + k]) / h;
        assert!(
            (v2 - v1).abs() / h <= A_MAX + 2.0 * count_m() / (h * h),
            "{v1} {v2}"
        );
    }
    assert!((q3.last().unwrap() - 0.35).abs() <= count_m());
    let p = rig.drives.positions().unwrap();
    assert!(p.valid);
    assert!((p.joints.q3_m - 0.35).abs() <= count_m());
    assert!((p.joints.q1_m - 0.01).abs() <= count_m());
}

#[test]
fn quick_stop_puts_moving_drives_in_quick_stop_active_and_they_hold() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(300 * MS);
    rig.drives.quick_stop().unwrap();
    rig.run(5 * MS);
    for axis in 0..3 {
        assert_eq!(rig.cia402(axis), Cia402State::QuickStopActive);
    }
    rig.run(200 * MS);
    let stopped = rig.true_position(2);
    rig.run(500 * MS);
    assert_eq!(rig.true_position(2), stopped);
    assert!(stopped < 0.35 - 0.005, "{stopped}");
}

#[test]
fn positions_are_valid_only_while_the_encoders_are_referenced() {
    let mut rig = Rig::new();
    assert!(rig.drives.positions().unwrap().valid);
    rig.drive(0, |d, _, _| d.set_referenced(false));
    rig.run(2 * MS);
    assert!(!rig.drives.positions().unwrap().valid);
    rig.drive(0, |d, _, _| d.set_referenced(true));
    rig.run(2 * MS);
    assert!(rig.drives.positions().unwrap().valid);
}

// ---------------------------------------------------------------------------
// Faults

#[test]
fn an_emcy_is_a_typed_fault_the_others_quick_stop_and_the_reset_needs_the_cause_gone() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(200 * MS);
    rig.drive(2, |d, now, out| d.inject_fault(0x7305, true, now, out));
    rig.run(3 * MS);
    let fault = DriveState::Fault {
        axis: Some(2),
        code: 0x7305,
    };
    assert_eq!(rig.drives.state().unwrap(), fault);
    assert!(!rig.drives.positions().unwrap().valid);
    for axis in 0..2 {
        assert_eq!(
            rig.cia402(axis),
            Cia402State::QuickStopActive,
            "axis {axis}"
        );
    }
    // The cause persists: the reset's rising edge does not clear it.
    rig.bus.take_sent();
    rig.drives.fault_reset().unwrap();
    rig.run(10 * MS);
    assert_eq!(rig.drives.state().unwrap(), fault);
    let words: Vec<u16> = rpdos(&rig.bus.take_sent(), 3).iter().map(|r| r.0).collect();
    assert_eq!(words[0], control::DISABLE_VOLTAGE);
    assert!(
        words[1..].iter().all(|w| *w == control::FAULT_RESET),
        "{words:x?}"
    );
    // Cause gone: nothing happens without a new rising edge...
    rig.drive(2, |d, _, _| d.clear_fault_cause());
    rig.run(10 * MS);
    assert_eq!(rig.drives.state().unwrap(), fault, "no new edge yet");
    // ... which a new reset makes.
    rig.drives.fault_reset().unwrap();
    rig.run(20 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    rig.enable();
}

#[test]
fn a_missed_heartbeat_is_a_fault_that_persists_while_the_drive_is_silent() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drive(1, |d, _, _| d.set_silent(true));
    rig.run(40 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled, "not yet");
    rig.run(20 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(1),
            code: 0x8130
        }
    );
    let err = rig.drives.fault_reset().unwrap_err();
    assert_eq!(err.kind(), ErrorKind::DeviceFault);
    rig.drive(1, |d, _, _| d.set_silent(false));
    rig.run(20 * MS);
    rig.drives.fault_reset().unwrap();
    rig.run(20 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
}

#[test]
fn a_drive_whose_heartbeat_stops_is_lost_after_the_timeout_and_stays_lost() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(50 * MS);
    let at_ns = rig.now() + 10 * MS;
    rig.drive(1, |d, _, _| {
        d.schedule(SimDriveFault::HeartbeatLoss { at_ns })
    });
    // Its last heartbeat is at most one period (10 ms) before the loss; the
    // host calls it lost 50 ms after that.
    rig.run(10 * MS + 39 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled, "not yet");
    assert!(rig.drive(1, |d, _, _| d.heartbeat_lost()));
    rig.run(13 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(1),
            code: 0x8130
        }
    );
    // Only the heartbeat was missing: the drive sent no EMCY, its TPDOs came.
    assert!(rig.drive(1, |d, _, _| d.emcys().is_empty()));
    // The cause persists: a reset is refused while the heartbeat is missing.
    let err = rig.drives.fault_reset().unwrap_err();
    assert_eq!(err.kind(), ErrorKind::DeviceFault);
    rig.drive(1, |d, _, _| d.clear_fault_cause());
    rig.run(20 * MS);
    rig.drives.fault_reset().unwrap();
    rig.run(20 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
}

#[test]
fn a_scheduled_emcy_latches_its_code_and_the_others_quick_stop() {
    let mut rig = Rig::new();
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(100 * MS);
    let at_ns = rig.now() + 5 * MS;
    rig.drive(2, |d, _, _| {
        d.schedule(SimDriveFault::Emcy {
            at_ns,
            code: 0x4310,
            persistent: false,
        })
    });
    rig.run(4 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled, "not yet");
    rig.run(3 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(2),
            code: 0x4310
        }
    );
    assert_eq!(rig.drive(2, |d, _, _| d.emcys().to_vec()), [0x4310]);
    assert_eq!(rig.cia402(2), Cia402State::Fault);
    rig.run(5 * MS);
    for axis in 0..2 {
        assert_eq!(
            rig.cia402(axis),
            Cia402State::QuickStopActive,
            "axis {axis}"
        );
    }
    // A transient cause: the reset clears it, and the drives enable again.
    rig.drives.fault_reset().unwrap();
    rig.run(20 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    rig.enable();
    rig.run(50 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled);
}

/// A fault reset completes only on status words read after its rising edge:
/// a TPDO late past its SYNC (a busy bus) leaves the host with the status
/// word from before the fault, which must not clear it. (Seen in the vcan VM
/// before the fix: the host said Ready while the drive was still in Fault,
/// then latched it again as a generic fault, its EMCY code lost.)
#[test]
fn a_fault_reset_never_completes_on_a_status_word_from_before_the_fault() {
    let mut rig = Rig::new();
    rig.enable();
    // The fault's TPDOs are late: the host hears the EMCY, not the state.
    rig.drive(2, |d, now, out| {
        d.skip_tpdos(6);
        d.inject_fault(0x4310, false, now, out);
    });
    rig.run(MS);
    let fault = DriveState::Fault {
        axis: Some(2),
        code: 0x4310,
    };
    assert_eq!(rig.drives.state().unwrap(), fault);
    rig.drives.fault_reset().unwrap();
    for _ in 0..5 {
        rig.run(MS);
        assert_eq!(
            rig.drives.state().unwrap(),
            fault,
            "no fresh status word yet"
        );
    }
    // The TPDOs come back: the reset's edge has reached the drive, which
    // says so, and the reset completes with the code kept until then.
    rig.run(5 * MS);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    assert_ne!(rig.cia402(2), Cia402State::Fault);
    rig.enable();
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled);
}

/// The simulated robot of the scenario files `fault_drive_emcy.toml` and
/// `fault_drive_heartbeat_loss.toml` (their values, typed here: this crate
/// does not read scenario files), at rest at its start, with `fault`.
fn fault_file_spec(seed: u64, fault: Fault) -> SimSpec {
    SimSpec {
        seed,
        calibration: Calibration::new(&CalibrationSpec {
            p_home_m: Vec3::zeros(),
            ujoint_offset_m: Vec3::new(0.0, -0.08, 0.0),
            sensor_offset_m: Vec3::new(0.0, -0.03, 0.0),
            sensor_rotation: Mat3::identity(),
            support_m: Vec3::new(0.45, 0.20, 0.0),
            gravity_mps2: Vec3::new(0.0, -9.80665, 0.0),
        })
        .unwrap(),
        profile: Profile::new(&ProfileSpec {
            length_m: 0.35,
            offset_m: 0.0,
            mass_kg: 2.593,
            com_m: 0.103,
        })
        .unwrap(),
        friction_n: 0.3,
        axes: AxesSpec {
            max_speed_mps: 0.05,
            drive_max_speed_mps: None,
            max_accel_mps2: 0.5,
            lead_m_per_turn: 0.005,
            counts_per_turn: 4096,
            position_period_ns: MS,
            travel_m: [(-0.3, 0.3), (0.0, 0.6), (0.0, 0.6)],
            start: ActiveJoints {
                q1_m: 0.0,
                q2_m: 0.28,
                q3_m: 0.25,
            },
        },
        sensor: SensorSpec {
            period_ns: 2 * MS,
            latency_ns: MS,
            noise_n: Vec3::new(0.2, 0.2, 0.8),
            noise_nm: Vec3::new(0.01, 0.01, 0.002),
            bias_n: Vec3::new(1.5, -2.0, 0.7),
            bias_nm: Vec3::new(0.05, -0.03, 0.02),
            drift_n_per_s: Vec3::zeros(),
            has_tare: true,
            range_n: Vec3::new(200.0, 200.0, 200.0),
            range_nm: Vec3::new(10.0, 10.0, 13.0),
            counts_per_n: 0.0,
            counts_per_nm: 0.0,
        },
        contact: vec![ContactKey {
            t_ns: 0,
            force_n: Vec3::new(1.0, -0.5, 0.3),
        }],
        tissue: Vec::new(),
        tip_mass_kg: 0.0,
        faults: vec![fault],
        physics_step_ns: 100_000,
        plant: PlantSpec::default(),
        support_shifts: Vec::new(),
    }
}

/// A scenario's drive faults give on the CANopen drives the fault the plain
/// simulated axes give (the host sees a lost heartbeat a timeout later).
#[test]
fn scenario_drive_faults_latch_the_same_fault_on_the_canopen_drives() {
    for (name, spec, latency_ns) in [
        (
            "drive_emcy",
            fault_file_spec(
                512,
                Fault::DriveEmcy {
                    at_ns: 2 * S,
                    axis: 2,
                    code: 0x4310,
                },
            ),
            2 * MS,
        ),
        (
            "drive_heartbeat_loss",
            fault_file_spec(
                511,
                Fault::DriveHeartbeatLoss {
                    at_ns: 2 * S,
                    axis: 1,
                },
            ),
            62 * MS,
        ),
    ] {
        let fault = spec.faults[0];
        // The plain simulated axes.
        let clock = SimClock::new(0);
        let sim = Simulator::new(spec, clock.clone()).unwrap();
        clock.advance_ns(2 * S);
        let plain = sim.truth().unwrap().drive_state;
        assert!(
            matches!(plain, DriveState::Fault { axis: Some(_), .. }),
            "{plain:?}"
        );
        // The CANopen drives, the scenario started now.
        let mut rig = Rig::new();
        rig.enable();
        let start_ns = rig.now();
        let (axis, drive_fault) = drive_fault_of(&fault, start_ns).unwrap();
        assert_eq!(drive_fault.at_ns(), start_ns + 2 * S);
        rig.drive(axis, |d, _, _| d.schedule(drive_fault));
        rig.run(2 * S - 20 * MS);
        assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled, "{name}");
        rig.run(20 * MS + latency_ns);
        assert_eq!(rig.drives.state().unwrap(), plain, "{name}");
    }
    // The other faults are not a drive's.
    assert_eq!(
        drive_fault_of(
            &Fault::DriveFault {
                at_ns: 0,
                code: 0x2310
            },
            0
        ),
        None
    );
}

/// A scenario's drive fault as the fault of the simulated CANopen drive of
/// its axis: `drive_heartbeat_loss` (for good: a lost drive is refused a
/// reset until its heartbeat is back) and `drive_emcy` (a cause gone at
/// once, so that a reset clears it, as on the plain simulated axes), at
/// the scenario's time plus `start_ns` (the drives' clock at the
/// scenario's start). `(axis, fault)`, or `None` for a fault that is not
/// one drive's.
fn drive_fault_of(fault: &Fault, start_ns: u64) -> Option<(usize, SimDriveFault)> {
    match *fault {
        Fault::DriveHeartbeatLoss { at_ns, axis } => Some((
            axis,
            SimDriveFault::HeartbeatLoss {
                at_ns: start_ns.saturating_add(at_ns),
            },
        )),
        Fault::DriveEmcy { at_ns, axis, code } => Some((
            axis,
            SimDriveFault::Emcy {
                at_ns: start_ns.saturating_add(at_ns),
                code,
                persistent: false,
            },
        )),
        _ => None,
    }
}

/// Writes an SDO straight into a drive (a test's side door).
fn sdo_into(rig: &Rig, axis: usize, index: u16, sub: u8, value: u32) {
    let node = u16::from(NODES[axis]);
    let req = Sdo::Download {
        index,
        sub,
        value,
        size: 4,
    };
    let f = RawFrame::new_data(COB_SDO_RX + node, &req.encode()).unwrap();
    rig.drive(axis, |d, now, out| d.on_frame(&f, now, out));
}

/// Moves q3 at full speed, then stalls the host for `stall_ns`; returns the
/// distance q3 travelled during the stall and its final velocity.
fn stall_while_moving(watchdog: bool, stall_ns: u64) -> (f64, f64, Cia402State, Vec<u16>) {
    let mut rig = Rig::new();
    if !watchdog {
        for axis in 0..3 {
            sdo_into(&rig, axis, 0x1016, 1, 0);
        }
    }
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(400 * MS);
    assert!((rig.drive(2, |d, now, _| d.velocity_mps(now)) - V_MAX).abs() < 0.01);
    let at_stall = rig.true_position(2);
    rig.host_alive = false;
    rig.run(stall_ns);
    let moved = rig.true_position(2) - at_stall;
    let v = rig.drive(2, |d, now, _| d.velocity_mps(now));
    let emcys = rig.drive(2, |d, _, _| d.emcys().to_vec());
    (moved, v, rig.cia402(2), emcys)
}

#[test]
fn a_silent_host_makes_the_drives_quick_stop_on_their_own() {
    // 50 ms consumer time + 10 ms heartbeat period at 0.05 m/s, then a 0.1 s
    // brake at 0.5 m/s^2: at most 3 mm + 2.5 mm.
    let (moved, v, state, emcys) = stall_while_moving(true, S);
    assert_eq!(v, 0.0);
    assert_eq!(state, Cia402State::QuickStopActive);
    assert!(moved > 0.0 && moved <= 0.0055 + 1e-9, "{moved}");
    assert!(emcys.contains(&0x8130), "{emcys:x?}");
    // Without the watchdog the same drive keeps going (its interpolator
    // extrapolates): the test above can fail.
    let (moved, v, state, _) = stall_while_moving(false, S);
    assert_eq!(state, Cia402State::OperationEnabled);
    assert!(v > 0.0 && moved > 0.04, "{moved}");
}

#[test]
fn bus_errors_are_reported_and_a_bus_off_becomes_a_fault() {
    let mut rig = Rig::new();
    rig.bus
        .inject_error(MemBusError::ErrorFrame(embedded_can::ErrorKind::Crc));
    let err = rig.drives.cycle().unwrap_err();
    assert!(
        matches!(
            err,
            CanOpenError::Bus {
                kind: embedded_can::ErrorKind::Crc,
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(err.kind(), ErrorKind::Disconnected);
    rig.run(5 * MS);
    assert!(rig.errors.is_empty(), "{:?}", rig.errors);
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    // Bus-off: every cycle reports it; positions go stale; the heartbeats are
    // lost, a fault.
    rig.bus.set_bus_off(true);
    rig.run(10 * MS);
    assert!(!rig.errors.is_empty());
    assert!(rig.errors.iter().all(|e| matches!(
        e,
        CanOpenError::Bus {
            kind: embedded_can::ErrorKind::Other,
            ..
        }
    )));
    assert!(!rig.drives.positions().unwrap().valid);
    rig.run(60 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(0),
            code: 0x8130
        }
    );
    assert!(rig.drives.bus_errors() > 0);
}

#[test]
fn a_set_point_jump_is_a_following_error_fault() {
    let mut rig = Rig::new();
    rig.enable();
    // A set point 5 cm away, straight into drive 1, applied at the next SYNC.
    let far = ((START_M[0] + 0.05) / count_m()).round() as i32;
    let rpdo = RawFrame::new_data(COB_RPDO1 + 1, &frame::encode_rpdo(0x0F, far)).unwrap();
    let sync = RawFrame::new_data(COB_SYNC, &[]).unwrap();
    rig.drive(0, |d, now, out| {
        d.on_frame(&rpdo, now, out);
        d.on_frame(&sync, now, out);
    });
    rig.run(2 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(0),
            code: 0x8611
        }
    );
    assert!((rig.true_position(0) - START_M[0]).abs() <= count_m());
}

// ---------------------------------------------------------------------------
// Robustness: arbitrary frames never panic the decoders or the simulated drive

use proptest::prelude::*;
use proptest::test_runner::{Config as ProptestConfig, RngSeed};

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 2000,
        rng_seed: RngSeed::Fixed(0xca40_9e11),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn arbitrary_frames_never_panic(
        frames in proptest::collection::vec(
            (
                // Any id, and often the drive's own NMT, SYNC, RPDO and SDO.
                prop_oneof![0u16..0x800, Just(0u16), Just(0x80), Just(0x201), Just(0x601)],
                proptest::collection::vec(any::<u8>(), 0..=8),
            ),
            1..40,
        )
    ) {
        let mut drive = SimCia402Drive::new(drive_spec(0), 0);
        let mut out = Vec::new();
        for (k, (id, data)) in frames.iter().enumerate() {
            let _ = Sdo::decode(data);
            let _ = frame::Emcy::decode(data);
            let _ = frame::decode_tpdo(data);
            let f = RawFrame::new_data(*id, data).unwrap();
            drive.on_frame(&f, k as u64 * MS, &mut out);
            drive.tick(k as u64 * MS, &mut out);
        }
        prop_assert!(drive.position_m(40 * MS).is_finite());
    }
}

#[test]
fn halt_brakes_and_holds_in_operation_enabled_and_release_resumes_the_move() {
    let mut rig = Rig::new();
    assert_eq!(
        rig.drives.set_halt(true).unwrap_err().kind(),
        ErrorKind::InvalidState
    );
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(300 * MS);
    rig.drives.set_halt(true).unwrap();
    rig.run(200 * MS);
    let held = rig.true_position(2);
    rig.run(300 * MS);
    assert_eq!(rig.true_position(2), held);
    assert_eq!(rig.drive(2, |d, now, _| d.velocity_mps(now)), 0.0);
    assert!(held < 0.35 - 0.01, "{held}");
    for axis in 0..3 {
        assert_eq!(rig.cia402(axis), Cia402State::OperationEnabled);
    }
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled);
    rig.drives.set_halt(false).unwrap();
    rig.run(2 * S);
    let p = rig.drives.positions().unwrap();
    assert!((p.joints.q3_m - 0.35).abs() <= count_m(), "{p:?}");
    assert_eq!(rig.drives.state().unwrap(), DriveState::Enabled);
}

// ---------------------------------------------------------------------------
// The drives' own limits: a second channel outside the host (SAFETY.md H40..)

/// The drives' own limits of `config()` (the defaults of the driver): quick
/// stop 1 m/s^2, 0.1 m/s, following window 2 mm for 10 ms, 1000 per mille.
fn own_limits_of(c: &CanOpenConfig, axis: usize) -> Vec<(u16, u8, u32)> {
    c.drive_limit_objects(axis)
        .iter()
        .map(|(i, s, v, _)| (*i, *s, *v))
        .collect()
}

/// One SDO request the host sent a node: a write (index, sub, value) or a
/// read (index, sub).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SdoRequest {
    Write(u16, u8, u32),
    Read(u16, u8),
}

/// The SDO requests the host sent to `node`, in the order sent.
fn sdo_requests(sent: &[RawFrame], node: u8) -> Vec<SdoRequest> {
    sent.iter()
        .filter(|f| f.cob_id == COB_SDO_RX + u16::from(node))
        .filter_map(|f| match Sdo::decode(f.payload()) {
            Some(Sdo::Download {
                index, sub, value, ..
            }) => Some(SdoRequest::Write(index, sub, value)),
            Some(Sdo::Upload { index, sub }) => Some(SdoRequest::Read(index, sub)),
            _ => None,
        })
        .collect()
}

/// Every limit, every object of how the drive stops and the heartbeat
/// consumer is written once and read back by the very next request to that
/// node (issue 35: the test used to check only that a read existed, not
/// that it followed its write), with the value in the drive's units; the
/// drive then holds them.
#[test]
fn start_up_writes_the_drives_own_limits_and_reads_each_back() {
    let rig = Rig::new();
    let sent = rig.bus.take_sent();
    let c = config();
    for (axis, node) in NODES.iter().enumerate() {
        let requests = sdo_requests(&sent, *node);
        let limits = own_limits_of(&c, axis);
        assert_eq!(limits.len(), 7);
        let stops: Vec<(u16, u8, u32)> = c
            .safe_stop_objects()
            .iter()
            .map(|(i, s, v, _)| (*i, *s, *v))
            .collect();
        let consumer = (
            0x1016,
            1,
            (127 << 16) | u32::from(c.host_heartbeat_timeout_ms),
        );
        for (index, sub, value) in limits.iter().chain(&stops).chain([&consumer]) {
            let writes: Vec<usize> = requests
                .iter()
                .enumerate()
                .filter(|(_, r)| matches!(r, SdoRequest::Write(i, s, _) if i == index && s == sub))
                .map(|(k, _)| k)
                .collect();
            assert_eq!(
                writes.len(),
                1,
                "node {node}: {index:#x}:{sub} written {} times",
                writes.len()
            );
            let w = writes[0];
            assert_eq!(
                requests[w],
                SdoRequest::Write(*index, *sub, *value),
                "node {node}: {index:#x}:{sub}"
            );
            // Read back by the next request to the node, after its write.
            assert_eq!(
                requests.get(w + 1),
                Some(&SdoRequest::Read(*index, *sub)),
                "node {node}: {index:#x}:{sub} not read back right after its write"
            );
        }
        // How the drive stops: ramps, never the motor left to coast.
        assert_eq!(
            stops.iter().map(|(i, _, v)| (*i, *v)).collect::<Vec<_>>(),
            [
                (0x605A, 6),
                (0x605B, 1),
                (0x605C, 1),
                (0x605E, 2),
                (0x6007, 3),
                (0x6084, 409_600)
            ]
        );
        // The drive holds them, in its units (counts).
        rig.drive(axis, |d, _, _| {
            assert!((d.quick_stop_decel_mps2() - c.quick_stop_decel_mps2).abs() < count_m());
            assert!((d.profile_decel_mps2() - c.quick_stop_decel_mps2).abs() < count_m());
            assert_eq!(
                d.stop_options(),
                StopOptions {
                    quick_stop: 6,
                    shutdown: 1,
                    disable_operation: 1,
                    fault_reaction: 2,
                    abort_connection: 3,
                }
            );
            let (lo, hi) = d.position_limits_m();
            let (t_lo, t_hi) = c.travel_m[axis];
            // The travel, rounded outwards by less than a count.
            assert!(lo <= t_lo && t_lo - lo < count_m(), "{lo} {t_lo}");
            assert!(hi >= t_hi && hi - t_hi < count_m(), "{hi} {t_hi}");
            assert!(d.max_velocity_mps() >= c.drive_max_speed_mps);
            assert!(d.max_velocity_mps() - c.drive_max_speed_mps < count_m());
        });
    }
    // Values: 1 m/s^2 = 409600 counts/s^2, 0.1 m/s = 40960 counts/s, 2 mm =
    // 820 counts (819.2 rounded up), 10 ms, 1000 per mille.
    let q1 = own_limits_of(&c, 0);
    assert!(q1.contains(&(0x6085, 0, 409_600)), "{q1:?}");
    assert!(q1.contains(&(0x607F, 0, 40_960)), "{q1:?}");
    assert!(q1.contains(&(0x6065, 0, 820)), "{q1:?}");
    assert!(q1.contains(&(0x6066, 0, 10)), "{q1:?}");
    assert!(q1.contains(&(0x6072, 0, 1000)), "{q1:?}");
}

/// A drive that keeps its own way of stopping (stores another value of
/// 0x605A, 0x605B, 0x605C, 0x605E, 0x6007 or 0x6084 than written: a coast,
/// many drives' default) refuses the start, naming the node, the object
/// and both values; the drives are never enabled.
#[test]
fn a_drive_that_keeps_its_own_way_of_stopping_refuses_the_start() {
    let c = config();
    for (index, sub, value, _) in c.safe_stop_objects() {
        // A coast for an option code; half the deceleration for 0x6084.
        let other = if index == 0x6084 { value / 2 } else { 0 };
        let (clock, bus) = bus_with(|axis, d| {
            if axis == 2 {
                d.store_instead(index, sub, other);
            }
        });
        let err = CanOpenDrives::start(bus.can(), clock.clone(), config()).unwrap_err();
        match &err {
            CanOpenError::LimitMismatch {
                node: 3,
                index: i,
                written,
                read,
                ..
            } if *i == index && *written == i64::from(value) && *read == i64::from(other) => {}
            other => panic!("{index:#x}: {other}"),
        }
        assert!(err.to_string().contains(frame::od::name(index)), "{err}");
        for axis in 0..3 {
            assert_ne!(
                bus.with_drive(axis, |d, _, _| d.state()).unwrap(),
                Cia402State::OperationEnabled
            );
        }
    }
}

/// Writes `value` into `axis`'s drive's object `index` (sub 0) over SDO
/// from outside the host (a service tool), after the start-up.
fn sdo_write_behind(rig: &Rig, axis: usize, index: u16, value: u32) {
    let request = Sdo::Download {
        index,
        sub: 0,
        value,
        size: 2,
    };
    let f = RawFrame::new_data(COB_SDO_RX + u16::from(NODES[axis]), &request.encode()).unwrap();
    rig.drive(axis, |d, now, out| d.on_frame(&f, now, out));
}

/// The third axis moving at full speed (0.05 m/s), then `stop` applied;
/// how far it runs from there in 300 ms, and its speed then.
fn run_on_after(rig: &mut Rig, stop: impl FnOnce(&mut Rig)) -> (f64, f64) {
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(400 * MS);
    assert!((rig.drive(2, |d, now, _| d.velocity_mps(now)) - V_MAX).abs() < 1e-9);
    let x0 = rig.true_position(2);
    stop(rig);
    rig.run(300 * MS);
    (
        rig.true_position(2) - x0,
        rig.drive(2, |d, now, _| d.velocity_mps(now)),
    )
}

/// The drives' safe stop, a control outside the software: a drive that
/// faults mid-move reacts as 0x605E (written 2 at start-up, read back)
/// says, a ramp at its quick stop deceleration (v^2 / 2a = 0.625 mm at 2
/// m/s^2 from 0.05 m/s); the same drive set to coast (0x605E = 0 behind
/// the host's back, many drives' default) runs on at its speed (15 mm in
/// 300 ms). The host's disable (a shutdown) ramps as 0x605B = 1 says, at
/// the profile deceleration 0x6084 (the quick stop's); set to 0, the axis
/// coasts.
#[test]
fn the_drives_fault_reaction_and_disable_ramp_as_written_and_would_coast_otherwise() {
    let mut c = config();
    c.quick_stop_decel_mps2 = 2.0;
    let ramp_m = V_MAX * V_MAX / (2.0 * 2.0);
    let fault = |rig: &mut Rig| rig.drive(2, |d, now, out| d.inject_fault(0x5000, false, now, out));
    let mut rig = Rig::with_config(c.clone());
    let (run_on, v) = run_on_after(&mut rig, fault);
    assert_eq!(v, 0.0);
    assert!(
        (run_on - ramp_m).abs() < 1e-9,
        "fault reaction: {run_on} m, not {ramp_m}"
    );
    assert_eq!(rig.cia402(2), Cia402State::Fault);
    let mut rig = Rig::with_config(c.clone());
    sdo_write_behind(&rig, 2, 0x605E, 0);
    let (run_on, v) = run_on_after(&mut rig, fault);
    // Coasting at its speed (the last set points' step, in whole counts).
    assert!(v > 0.95 * V_MAX, "coasting: {v} m/s");
    assert!((run_on - 0.3 * v).abs() < 1e-9, "coasting: {run_on} m");
    // The host's disable.
    let disable = |rig: &mut Rig| rig.drives.disable().unwrap();
    let mut rig = Rig::with_config(c.clone());
    let (run_on, v) = run_on_after(&mut rig, disable);
    assert_eq!(v, 0.0);
    // (The shutdown reaches the drive at the next SYNC: up to 2 ms at speed.)
    assert!(
        run_on >= ramp_m && run_on - ramp_m <= 2.0e-3 * V_MAX + 1e-9,
        "disable: {run_on} m"
    );
    assert_eq!(rig.cia402(2), Cia402State::ReadyToSwitchOn);
    let mut rig = Rig::with_config(c);
    sdo_write_behind(&rig, 2, 0x605B, 0);
    let (run_on, v) = run_on_after(&mut rig, disable);
    assert!(v > 0.95 * V_MAX, "coasting: {v} m/s");
    assert!(run_on > 0.25 * V_MAX, "coasting: {run_on} m");
}

/// The bus and three drives at power-on, `hook` applied to each drive.
fn bus_with(hook: impl Fn(usize, &mut SimCia402Drive)) -> (SimClock, MemBus) {
    let clock = SimClock::new(CLOCK_START_NS);
    let bus = MemBus::new(clock.clone());
    for axis in 0..3 {
        let mut d = SimCia402Drive::new(drive_spec(axis), clock.now_ns());
        hook(axis, &mut d);
        bus.add_drive(d);
    }
    bus.tick();
    (clock, bus)
}

#[test]
fn a_drive_that_does_not_hold_its_limits_refuses_the_start_and_is_never_enabled() {
    // q2's drive caps its max profile velocity at 1000 counts/s (as a drive
    // whose motor cannot go faster clamps the value) and says nothing.
    let (clock, bus) = bus_with(|axis, d| {
        if axis == 1 {
            d.store_instead(0x607F, 0, 1000);
        }
    });
    let err = CanOpenDrives::start(bus.can(), clock.clone(), config()).unwrap_err();
    assert_eq!(
        err,
        CanOpenError::LimitMismatch {
            node: 2,
            index: 0x607F,
            sub: 0,
            name: "max profile velocity",
            written: 40_960,
            read: 1000,
        }
    );
    assert_eq!(err.kind(), ErrorKind::DeviceFault);
    let text = err.to_string();
    for part in [
        "node 2",
        "max profile velocity",
        "0x607f:0",
        "40960",
        "1000",
    ] {
        assert!(text.contains(part), "{part:?} not in {text:?}");
    }
    // No drive was started (NMT start), so none can be enabled.
    assert!(
        !bus.take_sent()
            .iter()
            .any(|f| f.cob_id == 0 && f.payload().first() == Some(&frame::nmt::START)),
        "an NMT start was sent"
    );
    // A signed limit shows signed: q1's minimum (-0.1 m = -40960 counts)
    // stored as 0.
    let (clock, bus) = bus_with(|axis, d| {
        if axis == 0 {
            d.store_instead(0x607D, 1, 0);
        }
    });
    let err = CanOpenDrives::start(bus.can(), clock, config()).unwrap_err();
    assert!(
        matches!(
            err,
            CanOpenError::LimitMismatch {
                node: 1,
                index: 0x607D,
                sub: 1,
                written: -40_960,
                read: 0,
                ..
            }
        ),
        "{err}"
    );
    // The drive's own watchdog is checked the same way.
    let (clock, bus) = bus_with(|axis, d| {
        if axis == 2 {
            d.store_instead(0x1016, 1, 0);
        }
    });
    let err = CanOpenDrives::start(bus.can(), clock, config()).unwrap_err();
    assert!(
        matches!(
            err,
            CanOpenError::LimitMismatch {
                node: 3,
                index: 0x1016,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn the_drives_own_limits_are_checked_in_the_configuration() {
    for (field, change) in [
        (
            "quick_stop_decel_mps2",
            (|c: &mut CanOpenConfig| c.quick_stop_decel_mps2 = 0.4) as fn(&mut CanOpenConfig),
        ),
        ("drive_max_speed_mps", |c| c.drive_max_speed_mps = V_MAX),
        ("following_window_m", |c| c.following_window_m = 0.0),
        ("max_torque_permille", |c| c.max_torque_permille = 0),
    ] {
        let mut c = config();
        change(&mut c);
        let err = c.validate().unwrap_err();
        assert!(
            matches!(err, CanOpenError::InvalidConfig { field: f, .. } if f == field),
            "{field}: {err}"
        );
    }
}

/// The host stalled (it sends nothing); a rogue host's frames straight to the
/// drives instead, once per ms: its heartbeat, then to drive `axis` an RPDO
/// (enable operation, the set point `target_m(k)` of the k-th ms), then a
/// SYNC to all. Returns the true position and velocity of `axis` after
/// each ms.
fn rogue_host(
    rig: &mut Rig,
    axis: usize,
    ms: usize,
    target_m: impl Fn(usize) -> f64,
) -> Vec<(f64, f64)> {
    rig.host_alive = false;
    let heartbeat = RawFrame::new_data(0x700 + 127, &[frame::heartbeat::OPERATIONAL]).unwrap();
    let sync = RawFrame::new_data(COB_SYNC, &[]).unwrap();
    let mut at = Vec::new();
    for k in 0..ms {
        let counts = (target_m(k) / count_m()).round() as i32;
        let rpdo = RawFrame::new_data(
            COB_RPDO1 + u16::from(NODES[axis]),
            &frame::encode_rpdo(control::ENABLE_OPERATION, counts),
        )
        .unwrap();
        for a in 0..3 {
            rig.drive(a, |d, now, out| d.on_frame(&heartbeat, now, out));
        }
        rig.drive(axis, |d, now, out| d.on_frame(&rpdo, now, out));
        for a in 0..3 {
            rig.drive(a, |d, now, out| d.on_frame(&sync, now, out));
        }
        rig.run(MS);
        at.push((
            rig.true_position(axis),
            rig.drive(axis, |d, now, _| d.velocity_mps(now)),
        ));
    }
    at
}

#[test]
fn a_set_point_beyond_the_travel_is_clamped_by_the_drive_itself() {
    let mut c = config();
    c.travel_m[0] = (-0.1, 0.002);
    let mut rig = Rig::with_config(c);
    rig.enable();
    // The host refuses such a target itself...
    let beyond = ActiveJoints {
        q1_m: 0.004,
        ..target()
    };
    let err = rig.drives.set_targets(beyond).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidArgument);
    // ... a host that sends it anyway (its checks bypassed): 40 mm/s from
    // 0 to 4 mm, then held there. The drive stops at its limit, 2 mm,
    // staying enabled, with bit 11 (internal limit active) set.
    let x = rogue_host(&mut rig, 0, 200, |k| (0.00004 * k as f64).min(0.004));
    let (_, hi) = rig.drive(0, |d, _, _| d.position_limits_m());
    assert!((hi - 0.002).abs() < count_m());
    let highest = x.iter().map(|p| p.0).fold(f64::MIN, f64::max);
    assert!(highest <= hi + 1e-12, "{highest} beyond {hi}");
    assert_eq!(x[199], (hi, 0.0));
    assert!(rig.drive(0, |d, _, _| d.internal_limit()));
    assert_eq!(rig.cia402(0), Cia402State::OperationEnabled);
    assert!(rig.drive(0, |d, _, _| d.emcys().is_empty()));
    // The status word says so (bit 11 in the TPDO the host reads).
    let sync = RawFrame::new_data(COB_SYNC, &[]).unwrap();
    let mut out = Vec::new();
    rig.drive(0, |d, now, _| d.on_frame(&sync, now, &mut out));
    let tpdo = out.iter().find(|f| f.cob_id == 0x180 + 1).unwrap();
    let (sw, _) = frame::decode_tpdo(tpdo.payload()).unwrap();
    assert_ne!(sw & frame::STATUS_INTERNAL_LIMIT, 0, "{sw:#06x}");
}

#[test]
fn a_set_point_too_fast_is_limited_by_the_drive_and_its_lag_faults() {
    // The host plans at 20 mm/s; the drives' own limit is 40 mm/s (below
    // the axis's 50 mm/s, so that the drive's limit is what shows).
    let mut c = config();
    c.max_speed_mps = 0.02;
    c.drive_max_speed_mps = 0.04;
    let mut rig = Rig::with_config(c.clone());
    rig.enable();
    // The host refuses a streamed set point beyond its own speed...
    let far = ActiveJoints {
        q1_m: START_M[0] + 0.0003,
        q2_m: START_M[1],
        q3_m: START_M[2],
    };
    assert_eq!(
        rig.drives.stream(far, MS).unwrap_err().kind(),
        ErrorKind::InvalidArgument
    );
    // ... a rogue host streams 0.3 mm per ms (0.3 m/s, each step within the
    // 2 mm window). The drive moves at its 40 mm/s (bit 11 set), lags
    // 0.26 mm more each ms, and faults once the lag has been beyond the
    // window for its time out: after about 8 ms + 10 ms.
    let v_cmd = 0.3;
    let v_lim = rig.drive(0, |d, _, _| d.max_velocity_mps());
    assert!(v_lim >= c.drive_max_speed_mps && v_lim < c.drive_max_speed_mps + 1e-4);
    let mut limited = false;
    let mut x = Vec::new();
    for k in 0..40 {
        x.extend(rogue_host(&mut rig, 0, 1, |_| {
            START_M[0] + v_cmd * 1e-3 * (k + 1) as f64
        }));
        limited |= rig.drive(0, |d, _, _| d.internal_limit());
    }
    assert!(limited, "bit 11 never set");
    let emcys = rig.drive(0, |d, _, _| d.emcys().to_vec());
    assert_eq!(emcys, [0x8611], "{emcys:x?}");
    assert_eq!(rig.cia402(0), Cia402State::Fault);
    // Never faster than its own limit; the farthest point is what 40 mm/s
    // reach before the fault (lag beyond the window after
    // window / (v_cmd - v_lim), then the time out), short of the set point.
    for (k, (_, v)) in x.iter().enumerate() {
        assert!(v.abs() <= v_lim + 1e-12, "ms {k}: {v} m/s");
    }
    let lag_ms = c.following_window_m / (v_cmd - v_lim) * 1e3;
    let fault_ms = lag_ms + f64::from(c.following_timeout_ms);
    let moved = x.iter().map(|p| p.0).fold(f64::MIN, f64::max) - START_M[0];
    let braking_m = v_lim * v_lim / (2.0 * c.quick_stop_decel_mps2);
    assert!(
        moved <= v_lim * (fault_ms + 2.0) * 1e-3 + braking_m,
        "{moved}"
    );
    assert!(moved >= v_lim * (fault_ms - 2.0) * 1e-3, "{moved}");
    assert!(moved < v_cmd * fault_ms * 1e-3 / 2.0, "{moved}");
    // The host sees the drive's fault with its code.
    rig.host_alive = true;
    rig.run(3 * MS);
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: Some(0),
            code: 0x8611
        }
    );
}

#[test]
fn a_silent_host_ends_in_the_drives_quick_stop_at_its_own_deceleration() {
    // A quick stop deceleration (2 m/s^2) other than the axis's acceleration
    // limit (0.5 m/s^2): the stop shows which one the drive used.
    let mut c = config();
    c.quick_stop_decel_mps2 = 2.0;
    let mut rig = Rig::with_config(c);
    rig.enable();
    rig.drives.set_targets(target()).unwrap();
    rig.run(400 * MS);
    assert!((rig.drive(2, |d, now, _| d.velocity_mps(now)) - V_MAX).abs() < 1e-9);
    assert!((rig.drive(2, |d, _, _| d.quick_stop_decel_mps2()) - 2.0).abs() < count_m());
    rig.host_alive = false;
    // Step 0.1 ms until the drive's watchdog acts (50 ms + a heartbeat period).
    let mut waited_us = 0;
    while rig.cia402(2) != Cia402State::QuickStopActive {
        rig.run(MS / 10);
        waited_us += 100;
        assert!(waited_us <= 70_000, "no quick stop after {waited_us} us");
    }
    assert!(waited_us >= 40_000, "{waited_us}");
    let x0 = rig.true_position(2);
    let v0 = rig.drive(2, |d, now, _| d.velocity_mps(now));
    assert!(v0 > 0.9 * V_MAX, "{v0}");
    // The stop: a ramp (no jump), the speed never rising, to rest.
    let (mut x_prev, mut v_prev) = (x0, v0);
    for _ in 0..1000 {
        rig.run(MS / 10);
        let x = rig.true_position(2);
        let v = rig.drive(2, |d, now, _| d.velocity_mps(now));
        assert!(x >= x_prev && x - x_prev <= v_prev * 1e-4 + 1e-12, "a jump");
        assert!(v <= v_prev && v >= 0.0);
        (x_prev, v_prev) = (x, v);
    }
    assert_eq!(v_prev, 0.0);
    let distance = x_prev - x0;
    let expected = v0 * v0 / (2.0 * 2.0);
    assert!(
        (distance - expected).abs() < 1e-9,
        "{distance} vs {expected}"
    );
    // At the axis's acceleration limit it would have been 4 times as long.
    assert!(distance < v0 * v0 / (2.0 * A_MAX) / 3.0);
    assert_eq!(rig.drive(2, |d, _, _| d.emcys().to_vec()), [0x8130]);
}
