//! The daemon's loop on the real drivers (issue 9): the controller with the
//! RDT sensor driver over real loopback UDP against the device emulator (and
//! simulated axes) reaches Ok, then trips the guard into Fault with the
//! sensor's reason when the emulator goes silent, and when it sends a
//! non-zero status; the controller with the CANopen drives on the in-memory
//! bus with simulated CiA 402 drives (and the simulated sensor) reaches Ok,
//! moves to a target, and quick-stops the drives when the guard trips.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_canopen::{
    CanOpenDrives, FOLLOWING_WINDOW_M, MemBus, MemCan, SimCia402Drive, SimDriveSpec, frame,
};
use sar_config as config;
use sar_daemon::{devices, sim};
use sar_estimator::Vec3;
use sar_estimator::guard::{GuardState, Reason};
use sar_hal::{
    AxisDrives, DriveState, ForceSensor, MonotonicClock, SensorStatus, SimClock, WrenchSample,
};
use sar_kinematics::ActiveJoints;
use sar_loop::control::{Controller, Envelope, Operator, ReplyStatus, Request};
use sar_loop::{logq, rt};
use sar_rdt::emulator::{Action, Emulator, EmulatorConfig, Pacing};
use sar_rdt::{RdtConfig, RdtSensor};
use sar_test_support::rig::controller;
use std::cell::Cell;
use std::rc::Rc;
use std::time::Duration;

const COUNTS_PER_N: f64 = 10_000.0;
const COUNTS_PER_NM: f64 = 100_000.0;
const MS: u64 = 1_000_000;

/// The built-in configuration with sensor and joint ages generous enough for
/// a loaded test machine (the ages are not what these tests are about).
fn test_config() -> config::Config {
    let text = config::DEFAULT_TOML
        .replace("max_sensor_age_s = 0.05", "max_sensor_age_s = 0.5")
        .replace("max_joints_age_s = 0.05", "max_joints_age_s = 0.5");
    config::parse(&text, "(test configuration)").unwrap()
}

/// The demo scenario without its tip contact.
fn quiet_scenario() -> sar_sim::scenario::Scenario {
    let mut scenario = sim::demo_scenario().unwrap();
    scenario.spec.contact = vec![sar_sim::ContactKey {
        t_ns: 0,
        force_n: Vec3::zeros(),
    }];
    scenario
}

// ---------------------------------------------------------------------------
// RDT sensor over loopback UDP, simulated axes.

type RdtController = Controller<RdtSensor, sar_sim::SimDrives<MonotonicClock>>;

/// The emulator (manual pacing: one packet per cycle, sent by the test), the
/// controller on the RDT driver connected to it, and the emulator reading
/// what the simulated sensor reads at the start (so the estimate is sane).
fn rdt_rig(script: Vec<(u64, Action)>) -> (Emulator, RdtController, logq::LogQueue) {
    let cfg = test_config();
    let mut scenario = quiet_scenario();
    // The reading without the simulator's noise (the emulator adds its own):
    // one noisy draw as the base would offset the mean at rest, which the
    // first reset's mounting check compares with the model.
    scenario.spec.sensor.noise_n = sar_estimator::Vec3::zeros();
    scenario.spec.sensor.noise_nm = sar_estimator::Vec3::zeros();
    let clock = MonotonicClock::new().unwrap();
    let (_sim, mut sim_sensor, drives, bias) = sim::simulated(&scenario, clock).unwrap();
    let reading = sim_sensor.wait(1_000 * MS).unwrap();
    let counts = |v: f64, per: f64| (v * per).round() as i32;
    // A live device: seeded noise on every reading (a noiseless one is a
    // frozen one to the loop).
    let mut emu_config = EmulatorConfig::new(Pacing::Manual);
    emu_config.noise_counts = [2_000.0, 2_000.0, 8_000.0, 1_000.0, 1_000.0, 200.0];
    emu_config.seed = 0x4d7;
    emu_config.counts = [
        counts(reading.force_n.x, COUNTS_PER_N),
        counts(reading.force_n.y, COUNTS_PER_N),
        counts(reading.force_n.z, COUNTS_PER_N),
        counts(reading.torque_nm.x, COUNTS_PER_NM),
        counts(reading.torque_nm.y, COUNTS_PER_NM),
        counts(reading.torque_nm.z, COUNTS_PER_NM),
    ];
    emu_config.script = script;
    let emulator = Emulator::start(emu_config).unwrap();
    // The daemon's own translation of [drivers.sensor] (defaults: OnRobot,
    // 500 Hz), with a silence limit for a loaded test machine.
    let text = config::DEFAULT_TOML.replace(
        "[drivers.sensor]\nkind = \"sim\"",
        &format!(
            "[drivers.sensor]\nkind = \"rdt\"\naddress = \"{}\"\ncounts_per_n = {COUNTS_PER_N:?}\ncounts_per_nm = {COUNTS_PER_NM:?}\n",
            emulator.address()
        ),
    );
    let file = config::parse(&text, "(rdt configuration)").unwrap();
    let mut rdt: RdtConfig = devices::rdt_config(&file).unwrap();
    assert_eq!(rdt.address, emulator.address());
    rdt.silence_limit_ns = 200 * MS;
    let mut sensor = devices::connect_rdt(rdt).unwrap();
    assert!(emulator.wait_for_starts(1, Duration::from_secs(10)));
    emulator.step(1);
    devices::first_sample(&mut sensor, 10_000 * MS).unwrap();
    let (log, _thread, queue) = logq::channel(false);
    let controller = controller(&cfg, bias, sensor, drives, Operator::new(), log).unwrap();
    (emulator, controller, queue)
}

/// Runs cycles at 1 kHz on the monotonic clock (the emulator sends one
/// packet per cycle while `send`) until `done` holds, at most `max` cycles;
/// returns the cycle reached.
fn run_rdt_until(
    emulator: &Emulator,
    controller: &mut RdtController,
    cycle: &mut u64,
    send: bool,
    max: u64,
    done: impl Fn(&RdtController) -> bool,
) -> bool {
    let mut next = rt::monotonic_ns().unwrap();
    for _ in 0..max {
        if send {
            emulator.step(1);
        }
        next += MS;
        rt::sleep_until_ns(next);
        *cycle += 1;
        controller.step(*cycle, rt::monotonic_ns);
        if done(controller) {
            return true;
        }
    }
    false
}

fn guard(c: &RdtController) -> GuardState {
    c.output().guard_state
}

#[test]
fn rdt_loop_runs_ok_then_faults_when_the_emulator_goes_silent() {
    let (emulator, mut controller, log) = rdt_rig(Vec::new());
    let mut cycle = 0;
    assert!(
        run_rdt_until(&emulator, &mut controller, &mut cycle, true, 10_000, |c| {
            guard(c) == GuardState::Ok
        }),
        "never Ok: {:?} ({:?})",
        guard(&controller),
        controller.output().guard_reason
    );
    // Ok for a while on the emulator's samples, with an estimate.
    assert!(!run_rdt_until(
        &emulator,
        &mut controller,
        &mut cycle,
        true,
        200,
        |c| guard(c) != GuardState::Ok
    ));
    assert!(controller.input().sensor.valid);
    assert_eq!(controller.counts().quick_stops, 0);
    // Silence: no more packets.
    assert!(
        run_rdt_until(&emulator, &mut controller, &mut cycle, false, 20_000, |c| {
            guard(c) == GuardState::Fault
        }),
        "no fault on silence: {:?}",
        guard(&controller)
    );
    let reason = controller.output().guard_reason;
    assert!(
        matches!(reason, Reason::SensorInvalid | Reason::SensorStale { .. }),
        "{reason:?}"
    );
    assert!(controller.counts().sensor_errors > 0);
    // The log line says why the poll failed (the emulator sends nothing).
    let mut causes = Vec::new();
    while let Some(event) = log.pop() {
        if let logq::LogEvent::SensorPollFailed { cause, .. } = event {
            causes.push(cause);
        }
    }
    assert!(!causes.is_empty(), "no sensor poll failure logged");
    assert!(
        causes
            .iter()
            .all(|c| *c == "sensor silent: nothing received from its address"),
        "{causes:?}"
    );
    assert!(controller.halted());
    assert_eq!(controller.counts().quick_stops, 1);
    assert_eq!(
        controller.drives_mut().state().unwrap(),
        DriveState::QuickStop
    );
}

/// A sensor faster than the loop (issue 17): the emulator sends two packets
/// per 1 ms cycle (2 kHz), the loop drains every sample the driver received
/// and the recorder writes each as `/sar/sensor/wrench`: the recording
/// holds every packet the emulator produced, in order, and the sample each
/// cycle's step used (`/sar/cycle/input`) is among them.
#[test]
fn rdt_at_2_khz_against_a_1_khz_loop_records_every_sample() {
    use sar_config::{RecordSettings, Rotation};
    use sar_loop::sink::{Cycle, Sink, SinkHealth};
    use sar_loop::stats::LoopStats;
    use sar_msgs::msgs::{CycleInput, RosMessage, Topic, WrenchStamped};
    use sar_record::live::{RecordManager, RecordSwitch};
    use sar_record::{McapReader, read_file};
    use std::sync::Arc;
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rdt_2khz");
    let _ = std::fs::remove_dir_all(&dir);
    let (emulator, mut controller, _) = rdt_rig(Vec::new());
    let switch = Arc::new(RecordSwitch::default());
    let (manager, mut publisher) = RecordManager::start(
        RecordSettings {
            enabled: true,
            directory: dir.clone(),
            rotation: Rotation::default(),
            queue_capacity: 65536,
            scene_period_ns: None,
            snapshot_period_ns: 1_000_000_000,
            config_source: None,
            mode: sar_config::RecordMode::Full,
            scales: sar_config::DeviceScales::default(),
        },
        None,
        sar_estimator::cycle::Bias::force_only(Vec3::zeros()),
        Arc::clone(&switch),
    )
    .unwrap();
    let stats = LoopStats::default();
    let mut cycle = 0u64;
    let mut drained = 0usize;
    let mut most = 0usize;
    let mut step = |c: &mut RdtController, p: &mut dyn Sink, drained: &mut usize| {
        cycle += 1;
        p.before_cycle();
        c.step(cycle, rt::monotonic_ns);
        *drained += c.sensor_samples().len();
        most = most.max(c.sensor_samples().len());
        p.cycle(&Cycle::of(c, &stats, None), &mut SinkHealth::default());
    };
    let mut next = rt::monotonic_ns().unwrap();
    for _ in 0..600 {
        emulator.step(2);
        next += MS;
        rt::sleep_until_ns(next);
        step(&mut controller, &mut publisher, &mut drained);
    }
    // The last packets: drained once the driver has them (bounded wait).
    let produced = emulator.produced() as usize;
    for _ in 0..2_000 {
        if drained >= produced {
            break;
        }
        next += MS;
        rt::sleep_until_ns(next);
        step(&mut controller, &mut publisher, &mut drained);
    }
    assert_eq!(drained, produced, "drained {drained} of {produced} samples");
    assert!(most >= 2, "never more than {most} sample per cycle");
    assert_eq!(controller.counts().sensor_samples_lost, 0);
    publisher.release();
    manager.finish();
    assert_eq!(switch.dropped(), 0);
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| !p.to_string_lossy().ends_with(".scene.mcap"))
        .unwrap();
    let bytes = read_file(&file).unwrap();
    let mut stamps = Vec::new();
    let mut used = Vec::new();
    let mut reader = McapReader::new(&bytes).unwrap();
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        let topic = reader.channels()[&m.channel_id].topic.clone();
        if topic == Topic::SensorWrench.name() {
            stamps.push(WrenchStamped::decode(&m.data).unwrap().stamp_ns);
        } else if topic == Topic::CycleInput.name() {
            let c = CycleInput::decode(&m.data).unwrap();
            if c.sensor_valid {
                used.push(c.sensor_stamp_ns);
            }
        }
    }
    println!(
        "{produced} packets at 2 kHz, {cycle} cycles at 1 kHz: {} /sar/sensor/wrench messages, at most {most} per cycle",
        stamps.len()
    );
    assert_eq!(stamps.len(), produced);
    assert!(stamps.windows(2).all(|w| w[0] < w[1]), "out of order");
    let recorded: std::collections::BTreeSet<u64> = stamps.iter().copied().collect();
    assert!(!used.is_empty());
    for s in &used {
        assert!(recorded.contains(s), "the used sample {s} is not recorded");
    }
}

#[test]
fn rdt_loop_runs_ok_then_faults_on_a_non_zero_status() {
    // Packets 1300..1400 carry a fault status (the loop polls the newest
    // sample: a run of them is seen whatever the scheduling); before them
    // the first reset, after the mean at rest (500 samples).
    let script = (1300..1400)
        .map(|i| (i, Action::Status(0x8000_0001)))
        .collect();
    let (emulator, mut controller, _) = rdt_rig(script);
    let mut cycle = 0;
    assert!(run_rdt_until(
        &emulator,
        &mut controller,
        &mut cycle,
        true,
        10_000,
        |c| guard(c) == GuardState::Ok
    ));
    assert!(
        emulator.produced() < 1300,
        "Ok only after {} packets",
        emulator.produced()
    );
    assert!(
        run_rdt_until(&emulator, &mut controller, &mut cycle, true, 10_000, |c| {
            guard(c) == GuardState::Fault
        }),
        "no fault on a status: {:?}",
        guard(&controller)
    );
    let reason = controller.output().guard_reason;
    assert!(
        matches!(reason, Reason::SensorStatus { .. } | Reason::SensorInvalid),
        "{reason:?}"
    );
    assert!(emulator.produced() > 1300);
    assert!(controller.halted());
    assert_eq!(
        controller.drives_mut().state().unwrap(),
        DriveState::QuickStop
    );
}

// ---------------------------------------------------------------------------
// CANopen drives on the in-memory bus, simulated sensor.

/// The simulated sensor, with a switch that makes every sample report a
/// fault status (the guard's trip in the CANopen test).
struct Switchable<S> {
    inner: S,
    fault: Rc<Cell<bool>>,
}

impl<S: ForceSensor> ForceSensor for Switchable<S> {
    type Error = S::Error;
    fn poll(&mut self) -> Result<Option<WrenchSample>, S::Error> {
        Ok(self.inner.poll()?.map(|s| self.mark(s)))
    }
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, S::Error> {
        let s = self.inner.wait(timeout_ns)?;
        Ok(self.mark(s))
    }
    fn tare(&mut self) -> Result<(), S::Error> {
        self.inner.tare()
    }
    fn clear_tare(&mut self) -> Result<(), S::Error> {
        self.inner.clear_tare()
    }
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<sar_hal::Drained, S::Error> {
        self.inner.drain(out)
    }
}

impl<S> Switchable<S> {
    fn mark(&self, mut s: WrenchSample) -> WrenchSample {
        if self.fault.get() {
            s.status = SensorStatus(0x40);
        }
        s
    }
}

type CanController =
    Controller<Switchable<sar_sim::SimSensor<SimClock>>, CanOpenDrives<MemCan, SimClock>>;

struct CanRig {
    clock: SimClock,
    bus: MemBus,
    controller: CanController,
    operator: Operator,
    fault: Rc<Cell<bool>>,
    cycle: u64,
    period_ns: u64,
}

impl CanRig {
    fn new() -> Self {
        let cfg = test_config();
        let scenario = quiet_scenario();
        let clock = SimClock::new(7_000_000_000_000);
        let (_sim, sensor, _sim_drives, bias) = sim::simulated(&scenario, clock.clone()).unwrap();
        let text = config::DEFAULT_TOML.replace(
            "[drivers.axes]\nkind = \"sim\"",
            "[drivers.axes]\nkind = \"canopen\"\ninterface = \"can0\"\nnode_ids = [1, 2, 3]\nlead_m = 0.01\ncounts_per_turn = 4096",
        );
        let file = config::parse(&text, "(canopen configuration)").unwrap();
        let (interface, can_config) = devices::canopen_config(&file).unwrap();
        assert_eq!(interface, "can0");
        // SYNC at the loop's rate, the daemon's travel and move speed.
        assert_eq!(can_config.sync_period_ns, file.loop_.period_ns);
        assert_eq!(can_config.travel_m, file.axes.travel_m);
        assert_eq!(can_config.max_speed_mps, file.axes.max_speed_mps);
        assert_eq!(can_config.node_ids, [1, 2, 3]);
        // The drives' own limits, each looser than sard's check: the travel,
        // the plausibility's joint speed (above the planned speed), twice the
        // following tolerance, the quick stop key's default.
        assert_eq!(
            can_config.drive_max_speed_mps,
            file.estimator.plausibility.limits().max_joint_speed_mps
        );
        assert!(can_config.drive_max_speed_mps > file.axes.max_speed_mps);
        assert_eq!(
            can_config.following_window_m,
            2.0 * file.axes.following_tolerance_m
        );
        assert_eq!(can_config.quick_stop_decel_mps2, 2.0);
        assert_eq!(file.axes.motion.quick_stop_decel_mps2, 2.0);
        assert!(can_config.quick_stop_decel_mps2 >= file.axes.max_accel_mps2);
        assert_eq!(can_config.max_torque_permille, 1000);
        let limits = can_config.clone();
        let bus = MemBus::new(clock.clone());
        let start = scenario.spec.axes.start;
        for (i, start_m) in [start.q1_m, start.q2_m, start.q3_m].into_iter().enumerate() {
            bus.add_drive(SimCia402Drive::new(
                SimDriveSpec {
                    node_id: can_config.node_ids[i],
                    lead_m: can_config.lead_m,
                    counts_per_turn: can_config.counts_per_turn,
                    max_speed_mps: 0.05,
                    max_accel_mps2: 0.5,
                    start_m,
                    following_window_m: FOLLOWING_WINDOW_M,
                },
                clock.now_ns(),
            ));
        }
        bus.tick();
        let period_ns = can_config.sync_period_ns;
        let mut drives = CanOpenDrives::start(bus.can(), clock.clone(), can_config).unwrap();
        // Written and read back at start-up: the drives hold them.
        for axis in 0..3 {
            bus.with_drive(axis, |d, _, _| {
                let (lo, hi) = d.position_limits_m();
                let (t_lo, t_hi) = limits.travel_m[axis];
                assert!(lo <= t_lo && hi >= t_hi && t_lo - lo < 1e-5 && hi - t_hi < 1e-5);
                assert!((d.quick_stop_decel_mps2() - 2.0).abs() < 1e-5);
                assert!((d.max_velocity_mps() - limits.drive_max_speed_mps).abs() < 1e-5);
            })
            .unwrap();
        }
        devices::bring_up(&mut drives, &interface, 100, || {
            advance(&clock, &bus, period_ns)
        })
        .unwrap();
        assert_eq!(drives.state().unwrap(), DriveState::Ready);
        let fault = Rc::new(Cell::new(false));
        let operator = Operator::new();
        let (log, _thread, _queue) = logq::channel(false);
        let sensor = Switchable {
            inner: sensor,
            fault: Rc::clone(&fault),
        };
        let controller = controller(&cfg, bias, sensor, drives, operator.clone(), log)
            .unwrap()
            .with_drives_cycle(devices::canopen_cycle);
        Self {
            clock,
            bus,
            controller,
            operator,
            fault,
            cycle: 0,
            period_ns,
        }
    }

    /// One period of simulated time, then one cycle of the controller.
    fn cycle(&mut self) {
        advance(&self.clock, &self.bus, self.period_ns);
        self.cycle += 1;
        let clock = self.clock.clone();
        self.controller
            .step(self.cycle, move || Some(clock.now_ns()));
    }

    fn run_until(&mut self, max: u64, done: impl Fn(&mut Self) -> bool) -> bool {
        for _ in 0..max {
            self.cycle();
            if done(self) {
                return true;
            }
        }
        false
    }

    fn velocities(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| {
            self.bus
                .with_drive(i, |d, now, _| d.velocity_mps(now))
                .unwrap()
        })
    }

    fn positions(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| {
            self.bus
                .with_drive(i, |d, now, _| d.position_m(now))
                .unwrap()
        })
    }
}

/// Lets `ns` pass on the simulated clock, the drives ticking every 100 µs.
fn advance(clock: &SimClock, bus: &MemBus, ns: u64) {
    let step = 100_000;
    let mut left = ns;
    while left > 0 {
        let dt = left.min(step);
        clock.advance_ns(dt);
        bus.tick();
        left -= dt;
    }
}

#[test]
fn canopen_loop_reaches_ok_moves_to_a_target_and_quick_stops_on_a_trip() {
    let mut rig = CanRig::new();
    assert!(
        rig.run_until(2_000, |r| {
            r.controller.output().guard_state == GuardState::Ok
                && r.controller.drive_state() == Some(DriveState::Enabled)
        }),
        "never Ok: {:?} ({:?}), drives {:?}",
        rig.controller.output().guard_state,
        rig.controller.output().guard_reason,
        rig.controller.drive_state()
    );
    assert!(rig.controller.input().joints.valid);
    // Every cycle sent one SYNC.
    let syncs = rig
        .bus
        .take_sent()
        .iter()
        .filter(|f| f.cob_id == frame::COB_SYNC)
        .count();
    assert!(
        syncs as u64 >= rig.cycle,
        "{syncs} SYNCs in {} cycles",
        rig.cycle
    );

    // A move of the tip: 3 mm along q2 in joint space.
    let q0 = rig.controller.input().joints.joints;
    let target = ActiveJoints {
        q2_m: q0.q2_m + 0.003,
        ..q0
    };
    let cfg = test_config();
    let tip = sar_kinematics::forward(&cfg.estimator.calibration, &cfg.estimator.profile, &target)
        .unwrap()
        .tip_m;
    rig.operator
        .requests
        .push(Envelope {
            id: 1,
            request: Request::MoveTip { tip_m: tip },
        })
        .unwrap();
    rig.cycle();
    let reply = rig.operator.replies.pop().unwrap();
    assert_eq!(reply.status, ReplyStatus::Accepted, "{reply:?}");
    let reached = |r: &mut CanRig| {
        let p = r.positions();
        (p[1] - target.q2_m).abs() < 1e-5 && r.velocities().iter().all(|v| v.abs() < 1e-9)
    };
    assert!(
        rig.run_until(5_000, reached),
        "not at the target: {:?}",
        rig.positions()
    );
    let q = rig.controller.input().joints.joints;
    assert!((q.q2_m - target.q2_m).abs() < 1e-5, "{q:?}");
    assert!((q.q1_m - target.q1_m).abs() < 1e-5, "{q:?}");
    assert_eq!(rig.controller.output().guard_state, GuardState::Ok);

    // Back to the start, and trip the guard mid-move.
    rig.operator
        .requests
        .push(Envelope {
            id: 2,
            request: Request::MoveTip {
                tip_m: sar_kinematics::forward(
                    &cfg.estimator.calibration,
                    &cfg.estimator.profile,
                    &q0,
                )
                .unwrap()
                .tip_m,
            },
        })
        .unwrap();
    assert!(rig.run_until(1_000, |r| r.velocities()[1].abs() > 0.005));
    rig.fault.set(true);
    // The next sample (500 Hz: within two cycles) trips the guard.
    assert!(rig.run_until(2, |r| r.controller.output().guard_state
        == GuardState::Fault));
    assert!(matches!(
        rig.controller.output().guard_reason,
        Reason::SensorStatus { .. } | Reason::SensorInvalid
    ));
    assert!(rig.controller.halted());
    assert_eq!(rig.controller.counts().quick_stops, 1);
    assert_eq!(rig.controller.counts().stops_in_same_cycle, 1);
    // The drives enter Quick stop active and come to rest short of the goal.
    assert!(rig.run_until(1_000, |r| {
        r.controller
            .drives_mut()
            .axis_states()
            .iter()
            .all(|s| *s == Some(frame::Cia402State::QuickStopActive))
            && r.velocities().iter().all(|v| v.abs() < 1e-9)
    }));
    assert_eq!(rig.controller.drive_state(), Some(DriveState::QuickStop));
    let p = rig.positions();
    assert!(
        (p[1] - q0.q2_m).abs() > 1e-4,
        "the move went on to its goal: {p:?}"
    );
    // And they stay there.
    rig.run_until(200, |_| false);
    assert_eq!(rig.positions(), p);
}
