//! The simulator: the driver conformance suites, and its own physics checked
//! against closed forms of MODEL.md and against the estimator's inverse solution.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_hal::conformance;

use conformance::{Capability, DrivesHarness, SensorHarness, TareCheck};
use nalgebra::{Matrix3, Vector3};
use sar_hal::{
    AxisDrives, Clock, Drained, DriveState, Error, ErrorKind, ForceSensor, JointPositions, Rail,
    SimClock, WrenchSample,
};
use sar_kinematics::{ActiveJoints, Calibration, CalibrationSpec, Profile, ProfileSpec, SlideSign};
use sar_sim::{
    AxesSpec, Breathing, ContactKey, Fault, PlantSpec, SensorSpec, SimDrives, SimError, SimSensor,
    SimSpec, Simulator, Tissue, TissueModel, TissueShift, Truth,
};

type Vec3 = Vector3<f64>;

const G: f64 = 9.80665;
/// The clock's time at the start of every test (not zero, to catch mixing
/// of start-relative and clock times).
const CLOCK_START_NS: u64 = 5_000_000_000_000;
const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;

fn gravity() -> Vec3 {
    Vec3::new(0.0, -G, 0.0)
}

/// The example robot of INTERFACES.md 2 (R_0s = I, B = (0.45, 0.20, 0)).
fn calibration() -> Calibration {
    calibration_rotated(Matrix3::identity())
}

fn calibration_rotated(rotation: Matrix3<f64>) -> Calibration {
    Calibration::new(&CalibrationSpec {
        p_home_m: Vec3::zeros(),
        ujoint_offset_m: Vec3::new(0.0, -0.08, 0.0),
        sensor_offset_m: Vec3::new(0.0, -0.03, 0.0),
        sensor_rotation: rotation,
        support_m: Vec3::new(0.45, 0.20, 0.0),
        gravity_mps2: gravity(),
    })
    .unwrap()
}

/// Manipulator 2 of Table 2.
const MASS_KG: f64 = 2.593;
const COM_M: f64 = 0.103;
const LENGTH_M: f64 = 0.35;

fn profile() -> Profile {
    Profile::new(&ProfileSpec {
        length_m: LENGTH_M,
        offset_m: 0.0,
        mass_kg: MASS_KG,
        com_m: COM_M,
    })
    .unwrap()
}

/// Active joints with the rod horizontal at the support's height, A at a
/// distance `a` before B along X0.
fn horizontal(a: f64) -> ActiveJoints {
    ActiveJoints {
        q1_m: 0.0,
        q2_m: 0.28,
        q3_m: 0.45 - a,
    }
}

const LEAD_M: f64 = 0.01;
const COUNTS: u32 = 4096;
const V_MAX: f64 = 0.05;
const A_MAX: f64 = 0.5;

/// The test robot: HEX-6 noise, 500 Hz, 0.5 ms latency, 1 kHz positions, a
/// bias, no drift, no friction, no contact, no faults; the rod horizontal
/// with a = 0.15 m.
fn base_spec() -> SimSpec {
    SimSpec {
        seed: 7,
        calibration: calibration(),
        profile: profile(),
        friction_n: 0.0,
        axes: AxesSpec {
            max_speed_mps: V_MAX,
            drive_max_speed_mps: None,
            max_accel_mps2: A_MAX,
            lead_m_per_turn: LEAD_M,
            counts_per_turn: COUNTS,
            position_period_ns: MS,
            travel_m: [(-0.1, 0.1), (0.2, 0.36), (0.12, 0.42)],
            start: horizontal(0.15),
        },
        sensor: SensorSpec {
            period_ns: 2 * MS,
            latency_ns: MS / 2,
            noise_n: Vec3::new(0.2, 0.2, 0.8),
            noise_nm: Vec3::new(0.01, 0.01, 0.02),
            bias_n: Vec3::new(0.5, -1.2, 0.3),
            bias_nm: Vec3::new(0.02, -0.01, 0.005),
            drift_n_per_s: Vec3::zeros(),
            has_tare: true,
            range_n: Vec3::new(200.0, 200.0, 200.0),
            range_nm: Vec3::new(10.0, 10.0, 13.0),
            counts_per_n: 0.0,
            counts_per_nm: 0.0,
        },
        contact: Vec::new(),
        tissue: Vec::new(),
        tip_mass_kg: 0.0,
        faults: Vec::new(),
        physics_step_ns: 100_000,
        plant: PlantSpec::default(),
        support_shifts: Vec::new(),
    }
}

/// The same without noise.
fn quiet_spec() -> SimSpec {
    let mut spec = base_spec();
    spec.sensor.noise_n = Vec3::zeros();
    spec.sensor.noise_nm = Vec3::zeros();
    spec
}

fn count_m() -> f64 {
    LEAD_M / f64::from(COUNTS)
}

fn axes(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

/// A simulator on a simulated clock, with its handles.
struct Rig {
    clock: SimClock,
    sim: Simulator<SimClock>,
    sensor: SimSensor<SimClock>,
    drives: SimDrives<SimClock>,
    has_tare: bool,
}

impl Rig {
    fn new(spec: SimSpec) -> Self {
        let clock = SimClock::new(CLOCK_START_NS);
        let has_tare = spec.sensor.has_tare;
        let sim = Simulator::new(spec, clock.clone()).unwrap();
        Self {
            has_tare,
            sensor: sim.sensor(),
            drives: sim.drives(),
            sim,
            clock,
        }
    }

    /// Time from the start, ns.
    fn elapsed(&self) -> u64 {
        self.clock.now_ns() - CLOCK_START_NS
    }

    /// Advances the clock to `t_ns` from the start (not backwards).
    fn run_until(&self, t_ns: u64) {
        self.clock.sleep_until_ns(CLOCK_START_NS + t_ns);
    }

    fn truth(&self) -> Truth {
        self.sim.truth().unwrap()
    }

    /// Enables if needed, sets the targets, runs until the axes rest there,
    /// then 10 ms more, and drops the pending sample (so that the next one is
    /// measured at rest).
    fn move_to(&mut self, target: ActiveJoints) {
        if self.drives.state().unwrap() != DriveState::Enabled {
            self.drives.enable().unwrap();
        }
        self.drives.set_targets(target).unwrap();
        for _ in 0..2000 {
            self.clock.advance_ns(10 * MS);
            let t = self.truth();
            if t.joints == target && t.joint_speeds_mps == [0.0; 3] {
                self.clock.advance_ns(10 * MS);
                let _ = self.sensor.poll().unwrap();
                return;
            }
        }
        panic!("did not reach {target:?}");
    }

    /// Every sample received in the next `duration_ns`, by `wait`.
    fn collect(&mut self, duration_ns: u64) -> Vec<WrenchSample> {
        let end = self.clock.now_ns() + duration_ns;
        let mut samples = Vec::new();
        while self.clock.now_ns() < end {
            match self.sensor.wait(end - self.clock.now_ns()) {
                Ok(s) => samples.push(s),
                Err(e) => assert_eq!(e.kind(), ErrorKind::Timeout),
            }
        }
        samples
    }
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

fn mean_force(samples: &[WrenchSample]) -> Vec3 {
    samples.iter().map(|s| s.force_n).sum::<Vec3>() / samples.len() as f64
}

// ---------------------------------------------------------------------------
// Conformance

struct SimSensorHarness {
    rig: Rig,
}

impl SimSensorHarness {
    fn new() -> Self {
        Self::with_spec(base_spec())
    }

    fn with_spec(spec: SimSpec) -> Self {
        Self {
            rig: Rig::new(spec),
        }
    }
}

impl SensorHarness for SimSensorHarness {
    type Sensor = SimSensor<SimClock>;
    fn sensor(&mut self) -> &mut Self::Sensor {
        &mut self.rig.sensor
    }
    fn let_time_pass(&mut self, ns: u64) {
        self.rig.clock.advance_ns(ns);
    }
    fn now_ns(&self) -> u64 {
        self.rig.clock.now_ns()
    }
    fn period_ns(&self) -> u64 {
        2 * MS
    }
    fn arrival_bound_ns(&self) -> u64 {
        2 * MS + MS / 2
    }
    fn call_slack_ns(&self) -> u64 {
        0
    }
    fn tare_check(&self) -> Capability<TareCheck> {
        if !self.rig.has_tare {
            return Capability::NotApplicable {
                why: "the simulated device is configured without a tare command",
            };
        }
        // At rest, no contact: a steady load. 100 samples of HEX-6 noise
        // (0.8 N on z, 0.02 N m) average to 0.08 N and 0.002 N m.
        Capability::Ready(TareCheck {
            takes_effect_ns: 2 * MS + MS / 2,
            samples: 100,
            tolerance_n: 0.4,
            tolerance_nm: 0.01,
        })
    }
}

struct SimDrivesHarness {
    rig: Rig,
    /// false: the harness says it is `Unable` to provoke a fault (to show
    /// that the fault check then fails).
    can_fault: bool,
}

impl SimDrivesHarness {
    fn new() -> Self {
        Self {
            rig: Rig::new(base_spec()),
            can_fault: true,
        }
    }

    /// The plant in motion (issue 26): the rod's inertia, servos at their
    /// defaults, a 2 m/s^2 quick stop.
    fn in_motion() -> Self {
        let mut spec = base_spec();
        spec.plant = PlantSpec {
            inertia: Some(plant::inertia(0.0265, 0.0, 0.2)),
            servo: Some(plant::SERVO),
            quick_stop_decel_mps2: Some(2.0),
        };
        Self {
            rig: Rig::new(spec),
            can_fault: true,
        }
    }
}

impl DrivesHarness for SimDrivesHarness {
    type Drives = SimDrives<SimClock>;
    fn drives(&mut self) -> &mut Self::Drives {
        &mut self.rig.drives
    }
    fn let_time_pass(&mut self, ns: u64) {
        self.rig.clock.advance_ns(ns);
    }
    fn now_ns(&self) -> u64 {
        self.rig.clock.now_ns()
    }
    fn reachable_target(&self) -> ActiveJoints {
        ActiveJoints {
            q1_m: 0.01,
            q2_m: 0.27,
            q3_m: 0.35,
        }
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
        0
    }
    fn provoke_fault(&mut self) -> Capability<()> {
        if !self.can_fault {
            return Capability::Unable {
                why: "this test harness is told it cannot inject a fault",
            };
        }
        let at_ns = self.rig.elapsed() + 1;
        self.rig
            .sim
            .inject_fault(Fault::DriveFault {
                at_ns,
                code: 0x2310,
            })
            .unwrap();
        self.rig.clock.advance_ns(1);
        Capability::Ready(())
    }
}

/// One `#[test]` per conformance check, each with a fresh harness.
macro_rules! conformance_tests {
    ($suite:ident, $harness:expr, [$($check:ident),* $(,)?]) => {
        conformance_tests!($suite as $suite, $harness, [$($check),*]);
    };
    ($suite:ident as $name:ident, $harness:expr, [$($check:ident),* $(,)?]) => {
        mod $name {
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
    sensor,
    SimSensorHarness::new(),
    [
        poll_does_not_block_and_returns_each_sample_once,
        polled_samples_are_in_order_and_not_from_the_future,
        poll_after_a_pause_returns_the_newest,
        wait_returns_a_newer_sample_within_the_bound,
        wait_times_out_within_its_timeout,
        poll_after_wait_does_not_repeat,
        tare_and_clear_tare_are_ok_or_unsupported,
        tare_takes_effect_and_clear_tare_undoes_it,
        samples_are_valid_and_finite_in_normal_operation,
        drain_hands_over_every_sample_once_in_order,
    ]
);

conformance_tests!(
    drives,
    SimDrivesHarness::new(),
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

conformance_tests!(
    drives as drives_in_motion,
    SimDrivesHarness::in_motion(),
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

/// The simulator's harnesses run every check: nothing is declared not
/// applicable or out of reach.
#[test]
fn the_simulator_harnesses_run_every_check() {
    let mut d = SimDrivesHarness::new();
    assert!(d.out_of_travel_target().is_ready());
    assert!(d.provoke_fault().is_ready());
    assert!(SimSensorHarness::new().tare_check().is_ready());
}

/// A harness unable to provoke a fault fails the fault check (it used to
/// pass it silently).
#[test]
#[should_panic(expected = "the harness cannot run this check")]
fn a_harness_unable_to_provoke_a_fault_fails_the_fault_check() {
    let mut h = SimDrivesHarness::new();
    h.can_fault = false;
    conformance::drives::transient_fault_is_reported_and_reset(&mut h);
}

/// A device without a tare: the harness declares the tare check not
/// applicable, and both tare checks pass (`tare` is `Unsupported`).
#[test]
fn a_device_without_tare_passes_the_tare_checks_as_not_applicable() {
    let mut spec = base_spec();
    spec.sensor.has_tare = false;
    let mut h = SimSensorHarness::with_spec(spec.clone());
    assert!(matches!(h.tare_check(), Capability::NotApplicable { .. }));
    conformance::sensor::tare_and_clear_tare_are_ok_or_unsupported(&mut h);
    conformance::sensor::tare_takes_effect_and_clear_tare_undoes_it(
        &mut SimSensorHarness::with_spec(spec),
    );
}

/// A sensor whose `tare` answers Ok but does nothing.
struct NoOpTare(SimSensor<SimClock>);

impl ForceSensor for NoOpTare {
    type Error = SimError;
    fn poll(&mut self) -> Result<Option<WrenchSample>, SimError> {
        self.0.poll()
    }
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, SimError> {
        self.0.wait(timeout_ns)
    }
    fn tare(&mut self) -> Result<(), SimError> {
        Ok(())
    }
    fn clear_tare(&mut self) -> Result<(), SimError> {
        Ok(())
    }
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<Drained, SimError> {
        self.0.drain(out)
    }
}

struct NoOpTareHarness {
    inner: SimSensorHarness,
    sensor: NoOpTare,
}

impl SensorHarness for NoOpTareHarness {
    type Sensor = NoOpTare;
    fn sensor(&mut self) -> &mut NoOpTare {
        &mut self.sensor
    }
    fn let_time_pass(&mut self, ns: u64) {
        self.inner.let_time_pass(ns);
    }
    fn now_ns(&self) -> u64 {
        self.inner.now_ns()
    }
    fn period_ns(&self) -> u64 {
        self.inner.period_ns()
    }
    fn arrival_bound_ns(&self) -> u64 {
        self.inner.arrival_bound_ns()
    }
    fn call_slack_ns(&self) -> u64 {
        self.inner.call_slack_ns()
    }
    fn tare_check(&self) -> Capability<TareCheck> {
        self.inner.tare_check()
    }
}

/// A tare that answers Ok and does nothing fails the tare check (the old
/// check only looked at the answer).
#[test]
#[should_panic(expected = "force after tare")]
fn a_tare_without_effect_fails_the_tare_check() {
    let inner = SimSensorHarness::new();
    let sensor = NoOpTare(inner.rig.sensor.clone());
    let mut h = NoOpTareHarness { inner, sensor };
    // The old check passes it.
    conformance::sensor::tare_and_clear_tare_are_ok_or_unsupported(&mut h);
    conformance::sensor::tare_takes_effect_and_clear_tare_undoes_it(&mut h);
}

// ---------------------------------------------------------------------------
// Specification checks

fn refused(spec: SimSpec) -> SimError {
    let err = Simulator::new(spec, SimClock::new(0)).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidArgument, "{err}");
    err
}

#[test]
fn invalid_specs_are_refused_with_what_is_wrong() {
    let field = |e: SimError| match e {
        SimError::InvalidSpec { field, .. } => field,
        other => panic!("{other:?}"),
    };
    let mut s = base_spec();
    s.physics_step_ns = 0;
    assert_eq!(field(refused(s)), "physics_step_ns");
    let mut s = base_spec();
    s.sensor.period_ns = 0;
    assert_eq!(field(refused(s)), "sensor.period_ns");
    let mut s = base_spec();
    s.axes.position_period_ns = 10;
    assert_eq!(field(refused(s)), "axes.position_period_ns");
    let mut s = base_spec();
    s.axes.max_speed_mps = 0.0;
    assert_eq!(field(refused(s)), "axes.max_speed_mps");
    let mut s = base_spec();
    s.axes.max_accel_mps2 = f64::INFINITY;
    assert_eq!(field(refused(s)), "axes.max_accel_mps2");
    let mut s = base_spec();
    s.axes.counts_per_turn = 0;
    assert_eq!(field(refused(s)), "axes.counts_per_turn");
    let mut s = base_spec();
    s.axes.travel_m[1] = (0.3, 0.3);
    assert_eq!(field(refused(s)), "axes.travel_m");
    let mut s = base_spec();
    s.axes.start.q3_m = 0.43;
    assert_eq!(field(refused(s)), "axes.start");
    let mut s = base_spec();
    s.sensor.bias_n.y = f64::NAN;
    assert_eq!(field(refused(s)), "sensor.bias_n");
    let mut s = base_spec();
    s.sensor.noise_n.z = -0.1;
    assert_eq!(field(refused(s)), "sensor.noise_n");
    let mut s = base_spec();
    s.friction_n = -0.1;
    assert_eq!(field(refused(s)), "friction_n");
    let mut s = base_spec();
    s.tip_mass_kg = f64::NAN;
    assert_eq!(field(refused(s)), "tip_mass_kg");
    let mut s = base_spec();
    s.faults = vec![Fault::SensorSilent {
        from_ns: S,
        until_ns: Some(S),
    }];
    assert_eq!(field(refused(s)), "faults.sensor_silent.until_ns");
    let mut s = base_spec();
    s.sensor.range_n.y = 0.0;
    assert_eq!(field(refused(s)), "sensor.range_n");
    let mut s = base_spec();
    s.sensor.range_nm.z = f64::NAN;
    assert_eq!(field(refused(s)), "sensor.range_nm");
    // The new faults' own values.
    for (fault, name) in [
        (
            Fault::SensorFrozen {
                from_ns: S,
                until_ns: Some(S),
            },
            "faults.sensor_frozen.until_ns",
        ),
        (
            Fault::SensorSaturated {
                from_ns: S,
                until_ns: None,
                channels: [false; 6],
                rail: None,
            },
            "faults.sensor_saturated.channels",
        ),
        (
            Fault::SensorSpike {
                at_ns: S,
                force_n: Vec3::x(),
                torque_nm: Vec3::zeros(),
                samples: 0,
            },
            "faults.sensor_spike.samples",
        ),
        (
            Fault::SensorSpike {
                at_ns: S,
                force_n: Vec3::new(f64::NAN, 0.0, 0.0),
                torque_nm: Vec3::zeros(),
                samples: 1,
            },
            "faults.sensor_spike.force_n",
        ),
        (
            Fault::SensorDrift {
                from_ns: S,
                drift_n_per_s: Vec3::zeros(),
                drift_nm_per_s: Vec3::new(0.0, f64::INFINITY, 0.0),
            },
            "faults.sensor_drift.drift_nm_per_s",
        ),
        (
            Fault::SensorScale {
                from_ns: S,
                factor: 0.0,
            },
            "faults.sensor_scale.factor",
        ),
        (
            Fault::EncoderFrozen {
                at_ns: S,
                axis: 1,
                until_ns: Some(S / 2),
            },
            "faults.encoder_frozen.until_ns",
        ),
        (
            Fault::EncoderCountLoss {
                at_ns: S,
                axis: 0,
                counts: 0,
            },
            "faults.encoder_count_loss.counts",
        ),
        (
            Fault::DriveEmcy {
                at_ns: S,
                axis: 0,
                code: 0,
            },
            "faults.drive_emcy.code",
        ),
    ] {
        let mut s = base_spec();
        s.faults = vec![fault];
        assert_eq!(field(refused(s)), name);
    }
    for fault in [
        Fault::EncoderFrozen {
            at_ns: S,
            axis: 3,
            until_ns: None,
        },
        Fault::EncoderCountLoss {
            at_ns: S,
            axis: 4,
            counts: 1,
        },
        Fault::DriveHeartbeatLoss { at_ns: S, axis: 3 },
        Fault::DriveEmcy {
            at_ns: S,
            axis: 3,
            code: 1,
        },
    ] {
        let mut s = base_spec();
        s.faults = vec![fault];
        assert!(matches!(refused(s), SimError::FaultAxis { index: 0, .. }));
    }
    // The tissue's own values.
    type Edit = fn(&mut Tissue);
    let edits: [(Edit, &str); 7] = [
        (
            |t| t.direction = Vec3::new(1.0, 1.0, 0.0),
            "tissue.direction",
        ),
        (|t| t.rest_m.x = f64::NAN, "tissue.rest_m"),
        (
            |t| {
                t.model = TissueModel::Linear {
                    stiffness_n_per_m: 0.0,
                }
            },
            "tissue.stiffness_n_per_m",
        ),
        (
            |t| {
                t.model = TissueModel::Exponential {
                    stiffness_n_per_m: 300.0,
                    beta_per_m: -1.0,
                }
            },
            "tissue.beta_per_m",
        ),
        (|t| t.damping_n_s_per_m = -1.0, "tissue.damping_n_s_per_m"),
        (
            |t| {
                t.breathing = Some(Breathing {
                    amplitude_m: 0.003,
                    hz: 0.0,
                    direction: Vec3::x(),
                })
            },
            "tissue.breathing.hz",
        ),
        (
            |t| {
                t.shifts = vec![
                    TissueShift {
                        t_ns: 2 * S,
                        offset_m: 0.0,
                    },
                    TissueShift {
                        t_ns: S,
                        offset_m: 0.0,
                    },
                ]
            },
            "tissue.shift.t_ns",
        ),
    ];
    for (edit, name) in edits {
        let mut s = base_spec();
        let mut t = tissue_along_x(0.64, 300.0);
        edit(&mut t);
        s.tissue = vec![t];
        assert_eq!(field(refused(s)), name);
    }

    // The start pose: the tip short of the support (a = 0.36 > L).
    let mut s = base_spec();
    s.axes.travel_m[2] = (0.0, 0.42);
    s.axes.start = horizontal(0.36);
    assert!(matches!(refused(s), SimError::StartPose(_)));
    let mut s = base_spec();
    s.contact = vec![
        ContactKey {
            t_ns: 2 * S,
            force_n: Vec3::zeros(),
        },
        ContactKey {
            t_ns: S,
            force_n: Vec3::zeros(),
        },
    ];
    assert!(matches!(
        refused(s),
        SimError::ContactNotSorted {
            index: 1,
            t_ns: S,
            previous_ns: 2_000_000_000
        }
    ));
    let mut s = base_spec();
    s.faults = vec![
        Fault::NanSample { at_ns: S },
        Fault::EncoderJump {
            at_ns: S,
            axis: 3,
            jump_m: 0.001,
        },
    ];
    assert!(matches!(
        refused(s),
        SimError::FaultAxis { index: 1, axis: 3 }
    ));
    let mut s = base_spec();
    s.sensor.latency_ns = 200 * S;
    assert!(matches!(refused(s), SimError::LatencyTooLong { .. }));
    // Equal contact times are a step, and allowed.
    let mut s = base_spec();
    s.contact = vec![
        ContactKey {
            t_ns: S,
            force_n: Vec3::zeros(),
        },
        ContactKey {
            t_ns: S,
            force_n: Vec3::x(),
        },
    ];
    assert!(Simulator::new(s, SimClock::new(0)).is_ok());
}

#[test]
fn targets_are_checked() {
    let mut rig = Rig::new(base_spec());
    rig.drives.enable().unwrap();
    let err = rig
        .drives
        .set_targets(ActiveJoints {
            q1_m: 0.0,
            q2_m: 0.37,
            q3_m: 0.3,
        })
        .unwrap_err();
    assert_eq!(
        err,
        SimError::TargetOutOfTravel {
            axis: 1,
            target_m: 0.37,
            min_m: 0.2,
            max_m: 0.36
        }
    );
    // Within travel, but the tip would be short of the support.
    let mut spec = base_spec();
    spec.axes.travel_m[2] = (0.0, 0.42);
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    let err = rig.drives.set_targets(horizontal(0.36)).unwrap_err();
    assert!(matches!(err, SimError::TargetPose(_)), "{err}");
    assert_eq!(err.kind(), ErrorKind::InvalidArgument);
    // A fault given at run time must be in the future.
    rig.clock.advance_ns(S);
    let err = rig
        .sim
        .inject_fault(Fault::NanSample { at_ns: S })
        .unwrap_err();
    assert_eq!(
        err,
        SimError::FaultNotInFuture {
            at_ns: S,
            elapsed_ns: S
        }
    );
}

// ---------------------------------------------------------------------------
// Axes

#[test]
fn axes_respect_their_limits_and_arrive_without_overshoot() {
    let mut rig = Rig::new(quiet_spec());
    let start = axes(&rig.truth().joints);
    let target = ActiveJoints {
        q1_m: 0.004,
        q2_m: 0.25,
        q3_m: 0.40,
    };
    let goal = axes(&target);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(target).unwrap();
    let dt_ns = 500_000;
    let dt = dt_ns as f64 * 1e-9;
    let mut previous = rig.truth();
    let mut peak_speed = [0.0f64; 3];
    let mut arrival_ns = [None; 3];
    for _ in 0..5000 {
        rig.clock.advance_ns(dt_ns);
        let now = rig.truth();
        for i in 0..3 {
            let (x, v) = (axes(&now.joints)[i], now.joint_speeds_mps[i]);
            let dir = (goal[i] - start[i]).signum();
            assert!(v.abs() <= V_MAX * (1.0 + 1e-12), "axis {i}: speed {v}");
            let accel = (v - previous.joint_speeds_mps[i]) / dt;
            assert!(
                accel.abs() <= A_MAX * (1.0 + 1e-9),
                "axis {i}: accel {accel}"
            );
            assert!(dir * (x - goal[i]) <= 1e-15, "axis {i} overshoots: {x}");
            assert!(dir * v >= 0.0, "axis {i} moves backwards");
            peak_speed[i] = peak_speed[i].max(v.abs());
            if x == goal[i] && arrival_ns[i].is_none() {
                arrival_ns[i] = Some(now.elapsed_ns);
            }
        }
        previous = now;
    }
    assert_eq!(rig.truth().joints, target);
    // q3: 0.10 m, a trapezoid at the speed limit: 0.10 / 0.05 + 0.05 / 0.5 = 2.1 s.
    let t3 = arrival_ns[2].unwrap() as f64 * 1e-9;
    assert!((t3 - 2.1).abs() <= 1e-3, "q3 arrived at {t3} s");
    assert!((peak_speed[2] - V_MAX).abs() < 1e-12);
    // q1: 4 mm, a triangle: peak sqrt(a d) = 0.0447 m/s, 2 sqrt(d / a) = 0.179 s.
    let t1 = arrival_ns[0].unwrap() as f64 * 1e-9;
    assert!((t1 - 2.0 * (0.004f64 / A_MAX).sqrt()).abs() <= 1e-3, "{t1}");
    assert!((peak_speed[0] - (A_MAX * 0.004f64).sqrt()).abs() < 2e-4);
    // The reported positions end at the target, quantised.
    let p = rig.drives.positions().unwrap();
    for (reported, wanted) in axes(&p.joints).iter().zip(goal) {
        assert!((reported - wanted).abs() <= count_m() / 2.0 + 1e-15);
    }
}

#[test]
fn positions_are_quantised_to_lead_over_counts_and_reported_at_their_period() {
    let mut rig = Rig::new(quiet_spec());
    rig.drives.enable().unwrap();
    let target = ActiveJoints {
        q3_m: 0.3003,
        ..horizontal(0.15)
    };
    rig.drives.set_targets(target).unwrap();
    let q = count_m();
    assert!((q - 0.01 / 4096.0).abs() < 1e-20);
    let mut seen = Vec::new();
    for k in 0..400 {
        // Poll on the report grid: the report is of now, so truth is its truth.
        rig.run_until(k * MS);
        let p = rig.drives.positions().unwrap();
        assert_eq!(p.stamp_ns, CLOCK_START_NS + k * MS);
        assert!(p.valid);
        let truth = rig.truth();
        for (reported, true_m) in axes(&p.joints).iter().zip(axes(&truth.joints)) {
            let counts = reported / q;
            assert!(
                (counts - counts.round()).abs() < 1e-6,
                "{reported} is not on the grid"
            );
            assert!((reported - true_m).abs() <= q / 2.0 * (1.0 + 1e-9));
        }
        seen.push(p.joints.q3_m);
        // Between two report instants the report does not change.
        rig.clock.advance_ns(MS / 2);
        assert_eq!(rig.drives.positions().unwrap().stamp_ns, p.stamp_ns);
    }
    // The smallest step seen in the slow move is one count.
    let smallest = seen
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::MAX, f64::min);
    assert!(
        (smallest - q).abs() < 1e-12,
        "smallest step {smallest} vs {q}"
    );
}

#[test]
fn quick_stop_decelerates_at_the_limit_and_holds() {
    let mut rig = Rig::new(quiet_spec());
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.04)).unwrap();
    rig.run_until(S); // cruising at the speed limit along +X0
    let before = rig.truth();
    assert!((before.joint_speeds_mps[2] - V_MAX).abs() < 1e-15);
    rig.drives.quick_stop().unwrap();
    assert_eq!(rig.drives.state().unwrap(), DriveState::QuickStop);
    for k in 1..=20 {
        rig.clock.advance_ns(5 * MS);
        let t = rig.truth();
        let expected = (V_MAX - A_MAX * k as f64 * 0.005).max(0.0);
        assert!((t.joint_speeds_mps[2] - expected).abs() < 1e-12, "{k}");
    }
    let stopped = rig.truth();
    let travelled = stopped.joints.q3_m - before.joints.q3_m;
    assert!((travelled - V_MAX * V_MAX / (2.0 * A_MAX)).abs() < 1e-12);
    rig.clock.advance_ns(S);
    assert_eq!(rig.truth().joints, stopped.joints);
    assert_eq!(
        rig.drives.set_targets(horizontal(0.1)).unwrap_err().kind(),
        ErrorKind::InvalidState
    );
}

// ---------------------------------------------------------------------------
// Sensor timing, noise, bias

#[test]
fn samples_come_at_the_rate_with_the_latency() {
    let mut rig = Rig::new(base_spec());
    let samples = rig.collect(S);
    assert_eq!(samples.len(), 500);
    for (k, s) in samples.iter().enumerate() {
        let k = k as u64;
        assert_eq!(s.counter as u64, k);
        assert_eq!(s.received_ns, CLOCK_START_NS + k * 2 * MS + MS / 2);
        assert!(s.is_valid());
    }
}

#[test]
fn a_sample_measures_the_world_one_latency_before_it_is_received() {
    let mut spec = quiet_spec();
    spec.sensor.latency_ns = 5 * MS; // more than two periods in flight
    spec.contact = vec![
        ContactKey {
            t_ns: 0,
            force_n: Vec3::zeros(),
        },
        ContactKey {
            t_ns: 200 * MS,
            force_n: Vec3::new(4.0, -2.0, 1.0),
        },
    ];
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.12)).unwrap();
    // The truth on a 1 ms grid (measurement instants are on it).
    let mut truth_at = std::collections::HashMap::new();
    let mut samples = Vec::new();
    for k in 0..=300 {
        rig.run_until(k * MS);
        truth_at.insert(k * MS, rig.truth());
        if let Some(s) = rig.sensor.poll().unwrap() {
            samples.push(s);
        }
    }
    assert!(samples.len() >= 140);
    for s in &samples {
        let measured = s.received_ns - CLOCK_START_NS - 5 * MS;
        assert_eq!(measured, u64::from(s.counter) * 2 * MS);
        let t = &truth_at[&measured];
        assert!((s.force_n - t.reading_n).amax() < 1e-12, "{s:?} vs {t:?}");
        assert!((s.torque_nm - t.reading_nm).amax() < 1e-12);
    }
    // The contact ramp and the move are visible in the readings.
    let first = samples.first().unwrap().force_n;
    let last = samples.last().unwrap().force_n;
    assert!((first - last).norm() > 1.0);
}

#[test]
fn noise_has_the_specified_std_per_sensor_axis() {
    let mut spec = base_spec();
    spec.physics_step_ns = MS; // the rod is still: coarse steps suffice
    let mut rig = Rig::new(spec);
    let truth = rig.truth();
    let samples = rig.collect(40 * S);
    assert_eq!(samples.len(), 20_000);
    let specified = [0.2, 0.2, 0.8, 0.01, 0.01, 0.02];
    let mut columns = vec![Vec::new(); 6];
    for s in &samples {
        let dev_n = s.force_n - truth.reading_n;
        let dev_nm = s.torque_nm - truth.reading_nm;
        for i in 0..3 {
            columns[i].push(dev_n[i]);
            columns[3 + i].push(dev_nm[i]);
        }
    }
    let n = samples.len() as f64;
    for (i, (column, std)) in columns.iter().zip(specified).enumerate() {
        let (mean, measured) = mean_std(column);
        eprintln!("axis {i}: std {measured:.5} (specified {std}), mean {mean:+.5}");
        assert!(
            (measured / std - 1.0).abs() < 0.03,
            "axis {i}: std {measured} vs {std}"
        );
        assert!(mean.abs() < 4.0 * std / n.sqrt(), "axis {i}: mean {mean}");
    }
    // Independent axes.
    let (mx, sx) = mean_std(&columns[0]);
    let (mz, sz) = mean_std(&columns[2]);
    let cov = columns[0]
        .iter()
        .zip(&columns[2])
        .map(|(x, z)| (x - mx) * (z - mz))
        .sum::<f64>()
        / (n - 1.0);
    assert!((cov / (sx * sz)).abs() < 0.03);
}

#[test]
fn bias_drifts_linearly() {
    let mut spec = quiet_spec();
    spec.sensor.drift_n_per_s = Vec3::new(0.01, -0.02, 0.005);
    let bias0 = spec.sensor.bias_n;
    let mut rig = Rig::new(spec);
    for t_s in [0u64, 3, 10] {
        rig.run_until(t_s * S + MS / 2); // sample measured at t_s is received
        let s = rig.sensor.poll().unwrap().unwrap();
        let measured_s = (s.received_ns - CLOCK_START_NS - MS / 2) as f64 * 1e-9;
        assert_eq!(measured_s, t_s as f64);
        let truth = rig.truth();
        // What the load alone gives: R^T (-F_A) with R = I.
        let load = -truth.ujoint_force_n;
        let bias = s.force_n - load;
        let drift = Vec3::new(0.01, -0.02, 0.005);
        let expected = bias0 + drift * measured_s;
        assert!(
            (bias - expected).amax() < 1e-12,
            "{t_s}: {bias} vs {expected}"
        );
        // The truth is at now, half a millisecond later.
        let now_s = rig.elapsed() as f64 * 1e-9;
        assert!((truth.bias_n - (bias0 + drift * now_s)).amax() < 1e-12);
    }
}

#[test]
fn tare_subtracts_the_present_reading_and_clear_tare_restores_it() {
    let mut rig = Rig::new(quiet_spec());
    rig.run_until(100 * MS);
    let before = rig.sensor.wait(10 * MS).unwrap();
    assert!(before.force_n.norm() > 5.0);
    // Tare at 100 ms: the sample measured then is still raw, later ones are tared.
    rig.sensor.tare().unwrap();
    let at_tare = rig.sensor.wait(10 * MS).unwrap();
    assert_eq!(at_tare.received_ns, CLOCK_START_NS + 100 * MS + MS / 2);
    assert!((at_tare.force_n - before.force_n).amax() < 1e-12);
    let after = rig.sensor.wait(10 * MS).unwrap();
    assert!(
        after.force_n.amax() < 1e-12 && after.torque_nm.amax() < 1e-12,
        "{after:?}"
    );
    let t = rig.truth();
    assert!((t.tare_n - before.force_n).amax() < 1e-12);
    rig.sensor.clear_tare().unwrap();
    let cleared = rig.sensor.wait(10 * MS).unwrap();
    assert!((cleared.force_n - before.force_n).amax() < 1e-12);

    let mut spec = quiet_spec();
    spec.sensor.has_tare = false;
    let mut rig = Rig::new(spec);
    assert_eq!(
        rig.sensor.tare().unwrap_err(),
        SimError::Unsupported { command: "tare" }
    );
    assert_eq!(
        rig.sensor.clear_tare().unwrap_err().kind(),
        ErrorKind::Unsupported
    );
}

// ---------------------------------------------------------------------------
// Statics against closed forms (MODEL.md 4.1, 5.2) and the estimator

/// Closed form of MODEL.md 4.1 (d = 0), F_D from F_A: along u and across u.
fn tip_force_closed_form(t: &Truth, mass_kg: f64, com_m: f64) -> Vec3 {
    let u = t.pose.rod_dir;
    let a = t.pose.support_distance_m;
    let perp = |v: Vec3| v - u * v.dot(&u);
    let weight = gravity() * mass_kg;
    let f_a = t.ujoint_force_n;
    let along = -(f_a + weight).dot(&u);
    let across = (perp(f_a) * a + perp(weight) * (a - com_m)) / (LENGTH_M - a);
    -(u * along + across)
}

#[test]
fn statics_match_the_closed_form_for_any_pose_and_tip_force() {
    let mut spec = quiet_spec();
    let forces = [
        Vec3::new(3.0, -2.0, 1.5),
        Vec3::new(-1.0, 4.0, -2.5),
        Vec3::new(0.5, 0.5, 6.0),
    ];
    // Steps (equal key times) between holds: f0 until 3 s, f1 until 6 s, then f2.
    let key = |t_ns, force_n| ContactKey { t_ns, force_n };
    spec.contact = vec![
        key(0, forces[0]),
        key(3 * S, forces[0]),
        key(3 * S, forces[1]),
        key(6 * S, forces[1]),
        key(6 * S, forces[2]),
    ];
    let mut rig = Rig::new(spec);
    let targets = [
        ActiveJoints {
            q1_m: 0.05,
            q2_m: 0.33,
            q3_m: 0.33,
        },
        ActiveJoints {
            q1_m: -0.07,
            q2_m: 0.22,
            q3_m: 0.36,
        },
        ActiveJoints {
            q1_m: 0.02,
            q2_m: 0.30,
            q3_m: 0.20,
        },
    ];
    for (i, target) in targets.iter().enumerate() {
        rig.move_to(*target);
        rig.run_until(i as u64 * 3 * S + 2_500 * MS);
        let t = rig.truth();
        assert_eq!(t.tip_force_n, forces[i]);
        assert!(t.pose.rod_dir.y.abs() > 0.05 && t.pose.rod_dir.z.abs() > 0.05);
        // Along the rod: F_A . u = F_tip . u - m g . u (no friction).
        let u = t.pose.rod_dir;
        let along = t.tip_force_n.dot(&u) - MASS_KG * gravity().dot(&u);
        assert!((t.ujoint_force_n.dot(&u) - along).abs() < 1e-9);
        // The whole tip force back from F_A.
        let back = tip_force_closed_form(&t, MASS_KG, COM_M);
        assert!(
            (back - t.tip_force_n).amax() < 1e-9,
            "{back} vs {}",
            t.tip_force_n
        );
        // The support's reaction is across u, and no torsion with d = 0.
        assert!(t.support_reaction_n.dot(&u).abs() < 1e-9);
        assert!(t.torsion_nm.abs() < 1e-9);
        // The sensor's torque is the moment of -F_A about S.
        let lever = t.pose.ujoint_m - t.pose.sensor_m;
        let torque = lever.cross(&(-t.ujoint_force_n)) + t.bias_nm;
        assert!((t.reading_nm - torque).amax() < 1e-9);
    }
}

#[test]
fn horizontal_rod_follows_the_article_line() {
    // F_A,y = m |g| - M |g| / a, nothing at the tip, no friction (MODEL.md 5.2).
    let mut rig = Rig::new(quiet_spec());
    for a in [0.04, 0.07, 0.12, 0.20, 0.30] {
        rig.move_to(horizontal(a));
        let t = rig.truth();
        assert!((t.pose.support_distance_m - a).abs() < 1e-12);
        let expected = MASS_KG * G - MASS_KG * COM_M * G / a;
        assert!((t.ujoint_force_n.y - expected).abs() < 1e-9, "a = {a}");
        assert!(t.ujoint_force_n.x.abs() < 1e-9 && t.ujoint_force_n.z.abs() < 1e-9);
        // The reading is its negative plus the bias (R_0s = I).
        let s = rig.sensor.wait(10 * MS).unwrap();
        assert!((s.force_n.y - (-expected - 1.2)).abs() < 1e-9);
    }
}

#[test]
fn contact_keyframes_ramp_hold_and_push_above_the_stop_limit() {
    // A rotated sensor (90 degrees about Y0), so R_0s is exercised.
    let rotation = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
    let mut spec = quiet_spec();
    spec.calibration = calibration_rotated(rotation);
    spec.contact = vec![
        ContactKey {
            t_ns: 100 * MS,
            force_n: Vec3::zeros(),
        },
        ContactKey {
            t_ns: 600 * MS,
            force_n: Vec3::new(5.0, -1.0, 0.0),
        },
        ContactKey {
            t_ns: 1000 * MS,
            force_n: Vec3::new(5.0, -1.0, 0.0),
        },
        ContactKey {
            t_ns: 1200 * MS,
            force_n: Vec3::new(15.0, -3.0, 2.0),
        },
    ];
    let cal = spec.calibration;
    let mut rig = Rig::new(spec);
    let estimator = sar_estimator::tip_force::TipForceEstimator::new(
        &cal,
        &profile(),
        &sar_estimator::SensorNoise::hex6(),
        sar_estimator::tip_force::TipForceConfig { max_std_n: 5.0 },
    )
    .unwrap();
    let expected = |t_ms: f64| -> Vec3 {
        if t_ms < 100.0 {
            Vec3::zeros()
        } else if t_ms < 600.0 {
            Vec3::new(5.0, -1.0, 0.0) * ((t_ms - 100.0) / 500.0)
        } else if t_ms < 1000.0 {
            Vec3::new(5.0, -1.0, 0.0)
        } else if t_ms < 1200.0 {
            let f = (t_ms - 1000.0) / 200.0;
            Vec3::new(5.0, -1.0, 0.0) * (1.0 - f) + Vec3::new(15.0, -3.0, 2.0) * f
        } else {
            Vec3::new(15.0, -3.0, 2.0)
        }
    };
    for t_ms in [50u64, 100, 350, 600, 800, 1000, 1100, 1200, 1500] {
        rig.run_until(t_ms * MS);
        let truth = rig.truth();
        // The sample measured at t_ms, received half a millisecond later.
        rig.run_until(t_ms * MS + MS / 2);
        let s = rig.sensor.poll().unwrap().unwrap();
        let wanted = expected(t_ms as f64);
        assert!((truth.tip_force_n - wanted).amax() < 1e-12, "{t_ms} ms");
        // The estimator's inverse solution recovers it from the reading.
        let estimate = estimator
            .estimate(&truth.pose, &s.force_n, &truth.bias_n)
            .unwrap();
        assert!(
            (estimate.force_n - wanted).amax() < 1e-9,
            "{t_ms} ms: {} vs {wanted}",
            estimate.force_n
        );
    }
    // The last push is above a 12 N axial stop limit.
    assert!(rig.truth().tip_force_n.dot(&rig.truth().pose.rod_dir) > 12.0);
}

#[test]
fn rod_offset_statics_agree_with_the_estimator_and_show_the_torsion() {
    let mut spec = quiet_spec();
    spec.profile = Profile::new(&ProfileSpec {
        length_m: LENGTH_M,
        offset_m: 0.01,
        mass_kg: MASS_KG,
        com_m: COM_M,
    })
    .unwrap();
    spec.axes.start = ActiveJoints {
        q1_m: 0.04,
        q2_m: 0.31,
        q3_m: 0.30,
    };
    spec.contact = vec![ContactKey {
        t_ns: 0,
        force_n: Vec3::new(2.0, 1.0, -3.0),
    }];
    spec.friction_n = 0.3;
    spec.tip_mass_kg = 0.51;
    let cal = spec.calibration;
    let prof = spec.profile;
    let mut rig = Rig::new(spec);
    rig.run_until(10 * MS);
    let t = rig.truth();
    rig.run_until(10 * MS + MS / 2);
    let s = rig.sensor.poll().unwrap().unwrap();
    let estimator = sar_estimator::tip_force::TipForceEstimator::new(
        &cal,
        &prof,
        &sar_estimator::SensorNoise::hex6(),
        sar_estimator::tip_force::TipForceConfig { max_std_n: 5.0 },
    )
    .unwrap();
    let e = estimator.estimate(&t.pose, &s.force_n, &t.bias_n).unwrap();
    // No slide yet (no friction); the estimator's profile has no tip mass, so
    // it sees the mass's weight as a tip force pulling down.
    assert_eq!(t.slide_sign, SlideSign::Unknown);
    let seen = t.tip_force_n - t.tip_weight_n;
    assert!((e.force_n - seen).amax() < 1e-9, "{} vs {seen}", e.force_n);
    assert!((e.torsion_nm - t.torsion_nm).abs() < 1e-9);
    assert!(t.torsion_nm.abs() > 1e-3, "torsion {}", t.torsion_nm);
    // The torque reading carries -M_T n.
    let n = -Vec3::new(t.pose.q4_rad().sin(), 0.0, t.pose.q4_rad().cos());
    let lever = t.pose.ujoint_m - t.pose.sensor_m;
    let torque = lever.cross(&(-t.ujoint_force_n)) - n * t.torsion_nm + t.bias_nm;
    assert!((s.torque_nm - torque).amax() < 1e-9);

    // After an inserting move, with friction: the six equations of MODEL.md
    // 4.3 hold for the truth's forces (force balance, moments about A).
    rig.move_to(ActiveJoints {
        q1_m: 0.05,
        q2_m: 0.30,
        q3_m: 0.33,
    });
    let t = rig.truth();
    assert_eq!(t.slide_sign, SlideSign::Inserting);
    let u = t.pose.rod_dir;
    assert!((t.friction_force_n + u * 0.3).amax() < 1e-15);
    let weight = gravity() * MASS_KG;
    let f_d = -t.tip_force_n + t.tip_weight_n;
    let support = t.support_reaction_n + t.friction_force_n;
    let force_sum = t.ujoint_force_n + support + weight + f_d;
    assert!(force_sum.amax() < 1e-9, "{force_sum}");
    let a = t.pose.ujoint_m;
    let n = -Vec3::new(t.pose.q4_rad().sin(), 0.0, t.pose.q4_rad().cos());
    let moment_sum = (Vec3::new(0.45, 0.20, 0.0) - a).cross(&support)
        + (t.pose.com_m - a).cross(&weight)
        + (t.pose.tip_m - a).cross(&f_d)
        + n * t.torsion_nm;
    assert!(moment_sum.amax() < 1e-9, "{moment_sum}");
    assert!(t.support_reaction_n.dot(&u).abs() < 1e-9);
}

#[test]
fn tip_mass_is_identified_back_as_in_table_3() {
    // 1.03 kg hung at the tip, HEX-6 noise; the article's line fit over the
    // protocol's distances gives m + m_x and m c + m_x L.
    let mut spec = base_spec();
    spec.tip_mass_kg = 1.03;
    let cal = spec.calibration;
    let bias = spec.sensor.bias_n;
    let mut rig = Rig::new(spec);
    let mut fit = sar_estimator::line_fit::LineFit::new(&cal, bias, 1e-3).unwrap();
    for a in [0.04, 0.07, 0.12, 0.20, 0.30] {
        rig.move_to(horizontal(a));
        let t = rig.truth();
        assert_eq!(t.tip_weight_n, gravity() * 1.03);
        // Closed form with the tip mass.
        let expected = (MASS_KG + 1.03) * G - (MASS_KG * COM_M + 1.03 * LENGTH_M) * G / a;
        assert!((t.ujoint_force_n.y - expected).abs() < 1e-9);
        let samples = rig.collect(200 * MS);
        fit.add(&sar_estimator::StaticPose {
            ujoint_m: t.pose.ujoint_m,
            mean_reading_n: mean_force(&samples),
            samples: samples.len() as u32,
            slide_sign: SlideSign::Unknown,
        })
        .unwrap();
    }
    let result = fit.solve().unwrap();
    let tip_mass = result.mass_kg - MASS_KG;
    let tip_moment = result.mass_kg * result.com_m - MASS_KG * COM_M;
    eprintln!(
        "identified tip mass {tip_mass:.4} kg ({:+.3} %), at {:.4} m",
        (tip_mass / 1.03 - 1.0) * 100.0,
        tip_moment / tip_mass
    );
    assert!((tip_mass - 1.03).abs() < 0.01, "{tip_mass}");
    assert!((tip_moment / tip_mass - LENGTH_M).abs() < 0.01);
}

// ---------------------------------------------------------------------------
// Friction

#[test]
fn friction_opposes_the_slide_and_locks_when_the_rod_stops() {
    let mut spec = quiet_spec();
    spec.friction_n = 0.3;
    let mut rig = Rig::new(spec);
    // Before any slide: none.
    let t = rig.truth();
    assert_eq!(t.slide_sign, SlideSign::Unknown);
    assert_eq!(t.friction_force_n, Vec3::zeros());
    assert!(t.ujoint_force_n.x.abs() < 1e-12);
    // Inserting: A moves towards B, s decreases, the rod slides along u.
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.10)).unwrap();
    rig.clock.advance_ns(300 * MS);
    let moving = rig.truth();
    assert!(moving.joint_speeds_mps[2] > 0.0);
    assert_eq!(moving.slide_sign, SlideSign::Inserting);
    rig.move_to(horizontal(0.10));
    rig.clock.advance_ns(2 * S); // locked while at rest
    let t = rig.truth();
    let u = t.pose.rod_dir;
    assert_eq!(t.slide_sign, SlideSign::Inserting);
    assert!((t.friction_force_n - u * -0.3).amax() < 1e-15);
    // After an inserting move, F_A . u exceeds the frictionless value (0 for
    // a horizontal rod, nothing at the tip) by the friction.
    assert!((t.ujoint_force_n.dot(&u) - 0.3).abs() < 1e-12);
    let s = rig.sensor.wait(10 * MS).unwrap();
    assert!((s.force_n.x - (-0.3 + 0.5)).abs() < 1e-12);
    // Retracting: the other sign, locked likewise.
    rig.move_to(horizontal(0.20));
    rig.clock.advance_ns(2 * S);
    let t = rig.truth();
    assert_eq!(t.slide_sign, SlideSign::Retracting);
    assert!((t.ujoint_force_n.dot(&t.pose.rod_dir) + 0.3).abs() < 1e-12);
    // Inserting again: +1.
    rig.move_to(horizontal(0.15));
    assert_eq!(rig.truth().slide_sign, SlideSign::Inserting);
    // A purely vertical move of A also slides the rod (s changes): down from
    // the support's height, |B - A| grows: retracting; back up: inserting.
    let low = ActiveJoints {
        q2_m: 0.24,
        ..horizontal(0.15)
    };
    rig.move_to(low);
    assert_eq!(rig.truth().slide_sign, SlideSign::Retracting);
    rig.move_to(horizontal(0.15));
    assert_eq!(rig.truth().slide_sign, SlideSign::Inserting);
}

// ---------------------------------------------------------------------------
// Faults

#[test]
fn silent_sensor_times_out_and_comes_back_with_a_counter_gap() {
    let mut spec = base_spec();
    spec.faults = vec![Fault::SensorSilent {
        from_ns: 200 * MS,
        until_ns: Some(500 * MS),
    }];
    let mut rig = Rig::new(spec);
    rig.run_until(250 * MS);
    let last = rig.sensor.poll().unwrap().unwrap();
    // The last sample measured before the silence (at 198 ms).
    assert_eq!(last.counter, 99);
    let err = rig.sensor.wait(100 * MS).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Timeout);
    assert_eq!(rig.elapsed(), 350 * MS);
    // A long wait ends at the first sample after the silence.
    let next = rig.sensor.wait(S).unwrap();
    assert_eq!(next.counter, 250);
    assert_eq!(next.received_ns, CLOCK_START_NS + 500 * MS + MS / 2);
    assert_eq!(rig.elapsed(), 500 * MS + MS / 2);
    assert!(next.is_valid());

    // Silent for good: every wait times out, after exactly its timeout.
    let mut spec = base_spec();
    spec.faults = vec![Fault::SensorSilent {
        from_ns: 100 * MS,
        until_ns: None,
    }];
    let mut rig = Rig::new(spec);
    rig.run_until(100 * MS);
    let _ = rig.sensor.poll().unwrap();
    for _ in 0..3 {
        let before = rig.elapsed();
        assert_eq!(
            rig.sensor.wait(S).unwrap_err(),
            SimError::Timeout { timeout_ns: S }
        );
        assert_eq!(rig.elapsed() - before, S);
    }
}

/// `wait(u64::MAX)` on a sensor silenced for good, or for centuries, does not
/// step the physics through centuries: it returns `Timeout` (with the timeout
/// asked for) after `SimSensor::MAX_WAIT_NS` of simulated time. (On the
/// original code this test never ended.)
#[test]
fn a_huge_wait_on_a_silenced_sensor_times_out_after_the_cap() {
    let cap = SimSensor::<SimClock>::MAX_WAIT_NS;
    for until_ns in [None, Some(u64::MAX / 2)] {
        let mut spec = base_spec();
        spec.faults = vec![Fault::SensorSilent {
            from_ns: 100 * MS,
            until_ns,
        }];
        let mut rig = Rig::new(spec);
        rig.run_until(100 * MS);
        let _ = rig.sensor.poll().unwrap();
        for _ in 0..2 {
            let before = rig.elapsed();
            assert_eq!(
                rig.sensor.wait(u64::MAX).unwrap_err(),
                SimError::Timeout {
                    timeout_ns: u64::MAX
                },
                "{until_ns:?}"
            );
            assert_eq!(rig.elapsed() - before, cap, "{until_ns:?}");
        }
        // The world is still usable: a poll finds nothing, the drives answer.
        assert_eq!(rig.sensor.poll().unwrap(), None);
        assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    }
    // A sensor in normal operation still answers a huge wait with its next
    // sample.
    let mut rig = Rig::new(base_spec());
    let s = rig.sensor.wait(u64::MAX).unwrap();
    assert!(s.is_valid());
    assert!(rig.elapsed() <= 3 * MS);
}

#[test]
fn nan_sample_is_one_invalid_sample() {
    let mut spec = base_spec();
    spec.faults = vec![Fault::NanSample {
        at_ns: 100 * MS + 1,
    }];
    let mut rig = Rig::new(spec);
    let samples = rig.collect(300 * MS);
    let invalid: Vec<_> = samples.iter().filter(|s| !s.is_valid()).collect();
    assert_eq!(invalid.len(), 1);
    // The first sample measured at or after 100 ms + 1 ns: 102 ms, k = 51.
    assert_eq!(invalid[0].counter, 51);
    assert!(invalid[0].force_n.iter().all(|x| x.is_nan()));
    assert!(invalid[0].status.is_ok());
    assert_eq!(samples.len(), 150);
}

#[test]
fn encoder_jump_moves_the_report_only() {
    let mut spec = quiet_spec();
    spec.faults = vec![Fault::EncoderJump {
        at_ns: 300 * MS,
        axis: 1,
        jump_m: 0.001,
    }];
    let mut rig = Rig::new(spec);
    rig.run_until(299 * MS);
    let before = rig.drives.positions().unwrap();
    rig.run_until(300 * MS);
    let after = rig.drives.positions().unwrap();
    assert!(after.valid, "a jump is silent: the drive still says valid");
    assert!((after.joints.q2_m - before.joints.q2_m - 0.001).abs() <= count_m());
    assert_eq!(after.joints.q1_m, before.joints.q1_m);
    assert_eq!(after.joints.q3_m, before.joints.q3_m);
    // The world did not move: the truth and the sensor are unchanged.
    assert_eq!(rig.truth().joints, horizontal(0.15));
}

#[test]
fn drive_fault_stops_the_axes_and_reset_clears_it() {
    let mut spec = quiet_spec();
    spec.faults = vec![Fault::DriveFault {
        at_ns: S,
        code: 0x7305,
    }];
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.04)).unwrap();
    rig.run_until(S);
    let at_fault = rig.truth();
    assert_eq!(
        at_fault.drive_state,
        DriveState::Fault {
            axis: None,
            code: 0x7305
        }
    );
    assert!((at_fault.joint_speeds_mps[2] - V_MAX).abs() < 1e-15);
    rig.clock.advance_ns(50 * MS);
    assert!((rig.truth().joint_speeds_mps[2] - V_MAX / 2.0).abs() < 1e-12);
    rig.clock.advance_ns(200 * MS);
    let stopped = rig.truth();
    assert_eq!(stopped.joint_speeds_mps, [0.0; 3]);
    let travelled = stopped.joints.q3_m - at_fault.joints.q3_m;
    assert!((travelled - V_MAX * V_MAX / (2.0 * A_MAX)).abs() < 1e-12);
    assert!(!rig.drives.positions().unwrap().valid);
    let kind = |r: Result<(), SimError>| r.unwrap_err().kind();
    assert_eq!(
        kind(rig.drives.set_targets(horizontal(0.1))),
        ErrorKind::InvalidState
    );
    assert_eq!(kind(rig.drives.enable()), ErrorKind::InvalidState);
    assert_eq!(kind(rig.drives.disable()), ErrorKind::InvalidState);
    // A quick stop does not hide the fault.
    rig.drives.quick_stop().unwrap();
    assert_eq!(
        rig.drives.state().unwrap(),
        DriveState::Fault {
            axis: None,
            code: 0x7305
        }
    );
    rig.drives.fault_reset().unwrap();
    assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    rig.clock.advance_ns(MS);
    assert!(rig.drives.positions().unwrap().valid);
    rig.move_to(horizontal(0.1));
    assert_eq!(rig.truth().joints, horizontal(0.1));
}

/// Samples of a quiet robot at rest for `duration_ns`, with `faults`.
fn quiet_samples(faults: Vec<Fault>, duration_ns: u64) -> Vec<WrenchSample> {
    let mut spec = quiet_spec();
    spec.faults = faults;
    Rig::new(spec).collect(duration_ns)
}

#[test]
fn the_sensor_clips_at_its_measuring_range_as_a_real_one_does() {
    let mut spec = quiet_spec();
    // Ranges below the reading at rest on the force's y axis (about 9 N)
    // and on the torque's x axis (its bias, 0.02 N m).
    spec.sensor.range_n = Vec3::new(200.0, 5.0, 200.0);
    spec.sensor.range_nm = Vec3::new(0.01, 10.0, 13.0);
    let mut rig = Rig::new(spec);
    let truth = rig.truth();
    assert!(truth.reading_n.y.abs() > 5.0 && truth.reading_nm.x.abs() > 0.01);
    let s = rig.sensor.wait(10 * MS).unwrap();
    assert_eq!(s.force_n.y, 5.0f64.copysign(truth.reading_n.y));
    assert_eq!(s.torque_nm.x, 0.01f64.copysign(truth.reading_nm.x));
    // The other channels are untouched.
    assert!((s.force_n.x - truth.reading_n.x).abs() < 1e-12);
    assert!((s.torque_nm.z - truth.reading_nm.z).abs() < 1e-12);
    assert!(
        s.is_valid(),
        "a clipped reading looks valid: the guard must know the range"
    );
}

#[test]
fn a_frozen_sensor_repeats_its_last_values_bit_for_bit_while_the_counter_runs() {
    let mut spec = base_spec();
    spec.faults = vec![Fault::SensorFrozen {
        from_ns: 200 * MS,
        until_ns: Some(400 * MS),
    }];
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    let mut samples = rig.collect(250 * MS);
    // The world changes during the freeze: the axes move.
    rig.drives.set_targets(horizontal(0.12)).unwrap();
    samples.extend(rig.collect(350 * MS));
    assert_eq!(samples.len(), 300, "the samples keep coming at the rate");
    for (k, s) in samples.iter().enumerate() {
        assert_eq!(s.counter as usize, k, "the counter advances");
        assert_eq!(s.received_ns, CLOCK_START_NS + k as u64 * 2 * MS + MS / 2);
        assert!(s.is_valid());
    }
    // The last sample measured before 200 ms is k = 99; 100..=199 repeat it.
    let held = bits(&samples[99]);
    for s in &samples[100..200] {
        assert_eq!(bits(s), held, "sample {}", s.counter);
    }
    // A live sensor never repeats itself (noise), before or after.
    for w in samples[..100].windows(2).chain(samples[200..].windows(2)) {
        assert_ne!(bits(&w[0]), bits(&w[1]), "sample {}", w[1].counter);
    }
    // After the freeze the reading is live again: the new pose (a smaller a,
    // so about 4 N more on the sensor's y axis) shows.
    let before = mean_force(&samples[80..100]);
    let after = mean_force(&samples[280..300]);
    assert!((after.y - before.y).abs() > 1.0, "{before} vs {after}");
}

#[test]
fn saturated_channels_sit_at_the_end_of_the_range() {
    let range = Vec3::new(200.0, 200.0, 200.0);
    let fz_tx = [false, false, true, true, false, false];
    let window = |rail| Fault::SensorSaturated {
        from_ns: 100 * MS,
        until_ns: Some(200 * MS),
        channels: fz_tx,
        rail,
    };
    let clean = quiet_samples(vec![], 300 * MS);
    for rail in [None, Some(Rail::Positive), Some(Rail::Negative)] {
        let samples = quiet_samples(vec![window(rail)], 300 * MS);
        for (s, c) in samples.iter().zip(&clean) {
            let inside = (50..100).contains(&s.counter);
            if !inside {
                assert_eq!(bits(s), bits(c), "{rail:?} sample {}", s.counter);
                continue;
            }
            let side =
                |reading: f64| rail.map_or(if reading >= 0.0 { 1.0 } else { -1.0 }, Rail::sign);
            assert_eq!(s.force_n.z, side(c.force_n.z) * range.z, "{rail:?}");
            assert_eq!(s.torque_nm.x, side(c.torque_nm.x) * 10.0, "{rail:?}");
            assert_eq!(
                (s.force_n.x, s.force_n.y, s.torque_nm.y, s.torque_nm.z),
                (c.force_n.x, c.force_n.y, c.torque_nm.y, c.torque_nm.z)
            );
            assert!(s.is_valid());
        }
    }
}

#[test]
fn a_spike_is_added_to_exactly_its_samples_then_gone() {
    let spike_n = Vec3::new(40.0, -3.0, 0.0);
    let spike_nm = Vec3::new(0.0, 0.2, 0.0);
    let spike = Fault::SensorSpike {
        at_ns: 100 * MS + 1,
        force_n: spike_n,
        torque_nm: spike_nm,
        samples: 3,
    };
    // With the noise: the same seed, so the same noise in both runs.
    let run = |faults: Vec<Fault>| {
        let mut spec = base_spec();
        spec.faults = faults;
        Rig::new(spec).collect(200 * MS)
    };
    let clean = run(vec![]);
    let spiked = run(vec![spike]);
    let mut hit = Vec::new();
    for (s, c) in spiked.iter().zip(&clean) {
        if bits(s) == bits(c) {
            continue;
        }
        hit.push(s.counter);
        assert!((s.force_n - c.force_n - spike_n).amax() < 1e-12);
        assert!((s.torque_nm - c.torque_nm - spike_nm).amax() < 1e-12);
    }
    // The first sample measured at or after 100 ms + 1 ns is 102 ms, k = 51.
    assert_eq!(hit, [51, 52, 53]);
}

#[test]
fn a_drift_fault_drifts_the_bias_from_its_start() {
    let drift_n = Vec3::new(0.2, -0.1, 0.05);
    let drift_nm = Vec3::new(0.0, 0.01, 0.0);
    let samples = quiet_samples(
        vec![Fault::SensorDrift {
            from_ns: 400 * MS,
            drift_n_per_s: drift_n,
            drift_nm_per_s: drift_nm,
        }],
        2 * S,
    );
    let reference = &samples[0];
    for s in &samples {
        let measured_s = f64::from(s.counter) * 2e-3;
        let since_s = (measured_s - 0.4).max(0.0);
        assert!(
            (s.force_n - reference.force_n - drift_n * since_s).amax() < 1e-12,
            "sample {}",
            s.counter
        );
        assert!((s.torque_nm - reference.torque_nm - drift_nm * since_s).amax() < 1e-12);
    }
    // The truth's bias says the same.
    let mut spec = quiet_spec();
    spec.faults = vec![Fault::SensorDrift {
        from_ns: 400 * MS,
        drift_n_per_s: drift_n,
        drift_nm_per_s: drift_nm,
    }];
    let rig = Rig::new(spec.clone());
    rig.run_until(1400 * MS);
    assert!((rig.truth().bias_n - spec.sensor.bias_n - drift_n).amax() < 1e-12);
    assert!((rig.truth().bias_nm - spec.sensor.bias_nm - drift_nm).amax() < 1e-12);
}

#[test]
fn a_scale_fault_multiplies_the_raw_reading_by_its_gain() {
    let scale = |from_ns| Fault::SensorScale {
        from_ns,
        factor: 1.25,
    };
    let clean = quiet_samples(vec![], 200 * MS);
    let scaled = quiet_samples(vec![scale(100 * MS)], 200 * MS);
    for (s, c) in scaled.iter().zip(&clean) {
        if s.counter < 50 {
            assert_eq!(bits(s), bits(c));
        } else {
            assert!(
                (s.force_n - c.force_n * 1.25).amax() < 1e-12,
                "{}",
                s.counter
            );
            assert!((s.torque_nm - c.torque_nm * 1.25).amax() < 1e-12);
        }
    }
    // A tare taken under the wrong gain zeroes the scaled reading.
    let mut spec = quiet_spec();
    spec.faults = vec![scale(0)];
    let mut rig = Rig::new(spec);
    rig.run_until(10 * MS);
    rig.sensor.tare().unwrap();
    rig.run_until(20 * MS);
    let s = rig.sensor.wait(10 * MS).unwrap();
    assert!(
        s.force_n.amax() < 1e-12 && s.torque_nm.amax() < 1e-12,
        "{s:?}"
    );
}

#[test]
fn a_frozen_encoder_stops_reporting_while_its_axis_moves() {
    let mut spec = quiet_spec();
    spec.faults = vec![Fault::EncoderFrozen {
        at_ns: 100 * MS,
        axis: 2,
        until_ns: Some(600 * MS),
    }];
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.13)).unwrap();
    rig.run_until(99 * MS);
    let before = rig.drives.positions().unwrap();
    for t_ms in [100, 200, 400, 599] {
        rig.run_until(t_ms * MS);
        let p = rig.drives.positions().unwrap();
        assert!(
            p.valid,
            "a frozen encoder is silent: the drive still says valid"
        );
        assert_eq!(p.joints.q3_m, before.joints.q3_m, "{t_ms} ms");
        assert_eq!(
            p.stamp_ns,
            CLOCK_START_NS + t_ms * MS,
            "reports keep coming"
        );
    }
    // The axis itself moved as commanded.
    let truth = rig.truth();
    assert!(truth.joints.q3_m - before.joints.q3_m > 0.01, "{truth:?}");
    rig.run_until(600 * MS);
    let after = rig.drives.positions().unwrap();
    assert!((after.joints.q3_m - rig.truth().joints.q3_m).abs() <= count_m());
}

#[test]
fn lost_encoder_counts_offset_the_report_by_whole_counts() {
    let mut spec = quiet_spec();
    spec.faults = vec![Fault::EncoderCountLoss {
        at_ns: 300 * MS,
        axis: 0,
        counts: 37,
    }];
    let mut rig = Rig::new(spec);
    rig.run_until(299 * MS);
    let before = rig.drives.positions().unwrap();
    rig.run_until(300 * MS);
    let after = rig.drives.positions().unwrap();
    assert!(after.valid);
    let lost = (before.joints.q1_m - after.joints.q1_m) / count_m();
    assert!((lost - 37.0).abs() < 1e-6, "{lost} counts");
    assert_eq!(after.joints.q2_m, before.joints.q2_m);
    assert_eq!(after.joints.q3_m, before.joints.q3_m);
    assert_eq!(rig.truth().joints, horizontal(0.15));
}

#[test]
fn a_lost_heartbeat_or_an_emcy_is_a_drive_fault_of_its_axis_on_the_plain_axes() {
    for (fault, axis, code) in [
        (Fault::DriveHeartbeatLoss { at_ns: S, axis: 1 }, 1, 0x8130),
        (
            Fault::DriveEmcy {
                at_ns: S,
                axis: 2,
                code: 0x7305,
            },
            2,
            0x7305,
        ),
    ] {
        let mut spec = quiet_spec();
        spec.faults = vec![fault];
        let mut rig = Rig::new(spec);
        rig.drives.enable().unwrap();
        rig.drives.set_targets(horizontal(0.04)).unwrap();
        rig.run_until(S - 1);
        assert_eq!(rig.truth().drive_state, DriveState::Enabled);
        rig.run_until(S);
        let at_fault = rig.truth();
        assert_eq!(
            at_fault.drive_state,
            DriveState::Fault {
                axis: Some(axis),
                code
            }
        );
        // The axes brake at the limit, as for a drive fault.
        rig.clock.advance_ns(300 * MS);
        assert_eq!(rig.truth().joint_speeds_mps, [0.0; 3]);
        assert!(!rig.drives.positions().unwrap().valid);
        rig.drives.fault_reset().unwrap();
        assert_eq!(rig.drives.state().unwrap(), DriveState::Ready);
    }
}

// ---------------------------------------------------------------------------
// The tissue

/// A linear tissue along +X0 (the rod's direction at the nominal poses)
/// whose surface is the plane x = `surface_x_m`.
fn tissue_along_x(surface_x_m: f64, stiffness_n_per_m: f64) -> Tissue {
    Tissue {
        direction: Vec3::x(),
        rest_m: Vec3::new(surface_x_m, 0.2, 0.0),
        model: TissueModel::Linear { stiffness_n_per_m },
        damping_n_s_per_m: 0.0,
        breathing: None,
        shifts: Vec::new(),
    }
}

#[test]
fn the_tissue_force_follows_its_spring_law() {
    let still = Vec3::zeros();
    let at = |x: f64| Vec3::new(x, 0.2, 0.0);
    let linear = tissue_along_x(0.64, 300.0);
    // Zero outside (and on the surface), k delta inside, along +direction.
    assert_eq!(linear.force_n(0, &at(0.62), &still), Vec3::zeros());
    assert_eq!(linear.force_n(0, &at(0.64), &still), Vec3::zeros());
    let f = linear.force_n(0, &at(0.65), &still);
    assert!((f - Vec3::new(3.0, 0.0, 0.0)).amax() < 1e-12, "{f}");
    // Only the part along the direction counts (the surface is a plane).
    assert_eq!(linear.force_n(0, &Vec3::new(0.65, 0.3, 0.1), &still), f);
    // A tissue facing another way pushes along its own direction.
    let mut lateral = linear.clone();
    lateral.direction = Vec3::new(0.0, 0.0, -1.0);
    lateral.rest_m = Vec3::new(0.0, 0.0, 0.01);
    let f = lateral.force_n(0, &Vec3::new(0.6, 0.2, 0.005), &still);
    assert!((f - Vec3::new(0.0, 0.0, -1.5)).amax() < 1e-12, "{f}");

    // Exponential: (k0 / beta)(exp(beta delta) - 1), stiffness k0 at the surface.
    let mut exponential = linear.clone();
    exponential.model = TissueModel::Exponential {
        stiffness_n_per_m: 300.0,
        beta_per_m: 200.0,
    };
    for delta in [1e-4f64, 0.005, 0.01, 0.02] {
        let want = 300.0 / 200.0 * ((200.0 * delta).exp() - 1.0);
        let got = exponential.force_n(0, &at(0.64 + delta), &still).x;
        assert!(
            (got - want).abs() < 1e-9 * want.max(1.0),
            "{delta}: {got} vs {want}"
        );
    }
    let slope = exponential.force_n(0, &at(0.64 + 1e-7), &still).x / 1e-7;
    assert!(
        (slope - 300.0).abs() < 0.01,
        "stiffness at the surface {slope}"
    );
    let stiffer = (exponential.spring_n(0.02001) - exponential.spring_n(0.01999)) / 2e-5;
    assert!(
        (stiffer - 300.0 * (200.0f64 * 0.02).exp()).abs() < 1.0,
        "{stiffer}"
    );

    // Damping: c times the penetration's rate, never pulling.
    let mut damped = linear.clone();
    damped.damping_n_s_per_m = 50.0;
    let pushing_in = damped.force_n(0, &at(0.65), &Vec3::new(0.02, 0.0, 0.0));
    assert!((pushing_in.x - (3.0 + 50.0 * 0.02)).abs() < 1e-12);
    let pulling_out = damped.force_n(0, &at(0.65), &Vec3::new(-0.04, 0.0, 0.0));
    assert!((pulling_out.x - (3.0 - 2.0)).abs() < 1e-12);
    let fast_out = damped.force_n(0, &at(0.65), &Vec3::new(-0.2, 0.0, 0.0));
    assert_eq!(fast_out, Vec3::zeros(), "the damping never pulls");
    // Outside, no damping force either.
    assert_eq!(
        damped.force_n(0, &at(0.63), &Vec3::new(0.05, 0.0, 0.0)),
        Vec3::zeros()
    );
}

#[test]
fn the_tissue_breathes_with_its_period_and_shifts_at_its_keys() {
    let mut t = tissue_along_x(0.64, 300.0);
    t.breathing = Some(Breathing {
        amplitude_m: 0.003,
        hz: 0.25,
        direction: Vec3::x(),
    });
    t.shifts = vec![
        TissueShift {
            t_ns: 10 * S,
            offset_m: 0.004,
        },
        TissueShift {
            t_ns: 20 * S,
            offset_m: -0.002,
        },
    ];
    let x = |t_ns| t.rest_at(t_ns).0.x;
    // Period 4 s, amplitude 3 mm, at the rest point at t = 0.
    assert!((x(0) - 0.64).abs() < 1e-15);
    assert!((x(S) - 0.643).abs() < 1e-12);
    assert!((x(3 * S) - 0.637).abs() < 1e-12);
    for k in 0..8u64 {
        let t0 = k * 250 * MS;
        assert!((x(t0) - x(t0 + 4 * S)).abs() < 1e-12);
    }
    // Its velocity: amplitude * 2 pi f at the rest point.
    let v0 = t.rest_at(0).1.x;
    assert!((v0 - 0.003 * std::f64::consts::TAU * 0.25).abs() < 1e-15);
    // The shifts: none before the first key, each from its key on.
    assert!((x(10 * S - 1) - (0.64 + 0.003 * (2.5 * std::f64::consts::TAU).sin())).abs() < 1e-9);
    assert!((x(12 * S) - 0.644).abs() < 1e-12);
    assert!((x(20 * S) - 0.638).abs() < 1e-12);
    // A tip held still: the force follows the breathing, and is zero when
    // the surface breathes away from it.
    let tip = Vec3::new(0.641, 0.2, 0.0);
    let f = |t_ns| t.force_n(t_ns, &tip, &Vec3::zeros()).x;
    assert!((f(0) - 0.3).abs() < 1e-9);
    assert_eq!(f(S), 0.0);
    assert!((f(3 * S) - 300.0 * 0.004).abs() < 1e-9);
}

#[test]
fn the_tissue_pushes_back_on_the_tip_where_the_scripted_contact_does() {
    // The tip at the nominal pose is at x = 0.65; the tissue 1 cm before it.
    let mut spec = quiet_spec();
    spec.tissue = vec![tissue_along_x(0.64, 300.0)];
    let rig = Rig::new(spec);
    let t = rig.truth();
    assert!((t.pose.tip_m.x - 0.65).abs() < 1e-12);
    assert!((t.tissue_force_n - Vec3::new(3.0, 0.0, 0.0)).amax() < 1e-9);
    assert_eq!(t.tip_force_n, t.tissue_force_n, "no scripted contact");
    // The same force as a scripted contact gives the same world.
    let mut scripted = quiet_spec();
    scripted.contact = vec![ContactKey {
        t_ns: 0,
        force_n: t.tissue_force_n,
    }];
    let s = Rig::new(scripted).truth();
    assert!((s.ujoint_force_n - t.ujoint_force_n).amax() < 1e-12);
    assert!((s.reading_n - t.reading_n).amax() < 1e-12);
    assert!((s.reading_nm - t.reading_nm).amax() < 1e-12);
    // Both present: they add.
    let mut both = quiet_spec();
    both.tissue = vec![tissue_along_x(0.64, 300.0)];
    both.contact = vec![ContactKey {
        t_ns: 0,
        force_n: Vec3::new(0.0, 1.0, 0.0),
    }];
    let b = Rig::new(both).truth();
    assert!((b.tip_force_n - Vec3::new(3.0, 1.0, 0.0)).amax() < 1e-9);
    // The estimator's closed form (MODEL.md 4.1) finds it back from F_A.
    let back = tip_force_closed_form(&b, MASS_KG, COM_M);
    assert!((back - b.tip_force_n).amax() < 1e-9, "{back}");
}

/// The tissue force along a move into a stiff, damped, breathing tissue,
/// sampled by the sensor, with physics step `step_ns`.
fn stiff_tissue_run(step_ns: u64) -> (Vec<WrenchSample>, Vec<(Truth, Tissue)>) {
    let mut spec = quiet_spec();
    spec.physics_step_ns = step_ns;
    let mut tissue = tissue_along_x(0.648, 5000.0);
    tissue.damping_n_s_per_m = 20.0;
    tissue.breathing = Some(Breathing {
        amplitude_m: 0.001,
        hz: 0.3,
        direction: Vec3::x(),
    });
    spec.tissue = vec![tissue.clone()];
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.145)).unwrap();
    let mut samples = Vec::new();
    let mut truths = Vec::new();
    for k in 1..=400 {
        rig.run_until(k * MS);
        truths.push((rig.truth(), tissue.clone()));
        if let Some(s) = rig.sensor.poll().unwrap() {
            samples.push(s);
        }
    }
    (samples, truths)
}

#[test]
fn a_stiff_tissue_is_evaluated_not_integrated_so_every_physics_step_is_stable() {
    let (fine, truths) = stiff_tissue_run(10_000);
    // At every instant the force is the law at the tip the axes put there.
    let mut peak_n = 0.0f64;
    for (t, tissue) in &truths {
        let v = rig_tip_velocity(t);
        let want = tissue.force_n(t.elapsed_ns, &t.pose.tip_m, &v);
        assert!((t.tissue_force_n - want).amax() < 1e-6, "{t:?}");
        assert!(t.tissue_force_n.x >= 0.0 && t.tissue_force_n.x.is_finite());
        peak_n = peak_n.max(t.tissue_force_n.x);
    }
    // 5 mm into 5000 N/m (less the breathing): about 25 N, never more than
    // the spring at the deepest point and the damping at full speed.
    assert!(
        peak_n > 15.0 && peak_n < 5000.0 * 0.0085 + 20.0 * 0.05,
        "{peak_n}"
    );
    // Coarser physics steps give the same samples: nothing is integrated.
    // (Equal values, not bits: the support is frictionless here, and when the
    // step grid sees the first slide decides only the sign of its zero friction.)
    for step_ns in [100_000, MS, 10 * MS] {
        let (coarse, _) = stiff_tissue_run(step_ns);
        assert_eq!(coarse.len(), fine.len());
        for (a, b) in coarse.iter().zip(&fine) {
            assert_eq!(
                (a.force_n, a.torque_nm),
                (b.force_n, b.torque_nm),
                "step {step_ns} ns, sample {}",
                a.counter
            );
        }
    }
}

/// The tip's velocity from the truth's joint speeds, by a central
/// difference of the forward kinematics (the same derivative the simulator
/// takes, written again here).
fn rig_tip_velocity(t: &Truth) -> Vec3 {
    let h = 1e-6;
    let [v1, v2, v3] = t.joint_speeds_mps;
    let at = |sign: f64| {
        let q = ActiveJoints {
            q1_m: t.joints.q1_m + sign * h * v1,
            q2_m: t.joints.q2_m + sign * h * v2,
            q3_m: t.joints.q3_m + sign * h * v3,
        };
        sar_kinematics::forward(&calibration(), &profile(), &q)
            .unwrap()
            .tip_m
    };
    (at(1.0) - at(-1.0)) / (2.0 * h)
}

// ---------------------------------------------------------------------------
// Determinism

/// A busy script: moves, contact, friction, drift, faults, tare.
fn busy_spec(seed: u64) -> SimSpec {
    let mut spec = base_spec();
    spec.seed = seed;
    spec.friction_n = 0.25;
    spec.tip_mass_kg = 0.51;
    spec.sensor.latency_ns = 3 * MS + 100_000;
    spec.sensor.drift_n_per_s = Vec3::new(0.01, 0.0, -0.01);
    spec.contact = vec![
        ContactKey {
            t_ns: 100 * MS,
            force_n: Vec3::zeros(),
        },
        ContactKey {
            t_ns: 400 * MS,
            force_n: Vec3::new(3.0, -1.0, 0.5),
        },
    ];
    spec.faults = vec![
        Fault::NanSample { at_ns: 250 * MS },
        Fault::SensorSilent {
            from_ns: 300 * MS,
            until_ns: Some(320 * MS),
        },
        Fault::EncoderJump {
            at_ns: 350 * MS,
            axis: 2,
            jump_m: -0.0005,
        },
        Fault::SensorFrozen {
            from_ns: 130 * MS,
            until_ns: Some(160 * MS),
        },
        Fault::SensorSpike {
            at_ns: 170 * MS,
            force_n: Vec3::new(30.0, 0.0, -5.0),
            torque_nm: Vec3::new(0.0, 0.5, 0.0),
            samples: 3,
        },
        Fault::SensorDrift {
            from_ns: 180 * MS,
            drift_n_per_s: Vec3::new(0.5, 0.0, 0.0),
            drift_nm_per_s: Vec3::new(0.0, 0.0, 0.01),
        },
        Fault::SensorScale {
            from_ns: 450 * MS,
            factor: 1.1,
        },
        Fault::SensorSaturated {
            from_ns: 500 * MS,
            until_ns: Some(520 * MS),
            channels: [false, false, true, false, false, false],
            rail: None,
        },
        Fault::EncoderFrozen {
            at_ns: 90 * MS,
            axis: 2,
            until_ns: Some(120 * MS),
        },
        Fault::EncoderCountLoss {
            at_ns: 380 * MS,
            axis: 0,
            counts: 7,
        },
    ];
    // A breathing, shifting, damped tissue the rod's tip moves into.
    let mut tissue = tissue_along_x(0.66, 800.0);
    tissue.model = TissueModel::Exponential {
        stiffness_n_per_m: 800.0,
        beta_per_m: 30.0,
    };
    tissue.damping_n_s_per_m = 40.0;
    tissue.breathing = Some(Breathing {
        amplitude_m: 0.003,
        hz: 3.0,
        direction: Vec3::x(),
    });
    tissue.shifts = vec![TissueShift {
        t_ns: 330 * MS,
        offset_m: -0.002,
    }];
    spec.tissue = vec![tissue];
    spec
}

/// Runs the busy script, polling every `poll_ns`; commands at fixed times
/// (multiples of 7 ms and of 0.1 ms). Returns the samples and position reports.
fn run_busy(seed: u64, poll_ns: u64) -> (Vec<WrenchSample>, Vec<JointPositions>) {
    run_busy_spec(busy_spec(seed), poll_ns)
}

fn run_busy_spec(spec: SimSpec, poll_ns: u64) -> (Vec<WrenchSample>, Vec<JointPositions>) {
    let mut rig = Rig::new(spec);
    let mut samples = Vec::new();
    let mut reports = Vec::new();
    let mut commands = vec![
        (0, 0u8),
        (70 * MS, 1),
        (210 * MS, 2),
        (280 * MS, 3),
        (420 * MS, 4),
    ];
    commands.reverse();
    while rig.elapsed() < 600 * MS {
        while let Some(&(at, command)) = commands.last() {
            if at > rig.elapsed() {
                break;
            }
            assert_eq!(at, rig.elapsed(), "commands must fall on the poll grid");
            match command {
                0 => rig.drives.enable().unwrap(),
                1 => rig.drives.set_targets(horizontal(0.10)).unwrap(),
                2 => rig.sensor.tare().unwrap(),
                3 => rig.drives.set_targets(horizontal(0.13)).unwrap(),
                _ => rig.drives.quick_stop().unwrap(),
            }
            commands.pop();
        }
        if let Some(s) = rig.sensor.poll().unwrap() {
            samples.push(s);
        }
        reports.push(rig.drives.positions().unwrap());
        rig.clock.advance_ns(poll_ns);
    }
    (samples, reports)
}

fn bits(s: &WrenchSample) -> Vec<u64> {
    s.force_n
        .iter()
        .chain(s.torque_nm.iter())
        .map(|x| x.to_bits())
        .collect()
}

#[test]
fn same_seed_and_script_give_the_same_samples_bit_for_bit() {
    let (a, pa) = run_busy(11, 100_000);
    let (b, pb) = run_busy(11, 100_000);
    assert_eq!(a.len(), b.len());
    assert!(a.len() > 250);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(bits(x), bits(y));
        assert_eq!(
            (x.counter, x.received_ns, x.status),
            (y.counter, y.received_ns, y.status)
        );
    }
    assert_eq!(pa.len(), pb.len());
    for (x, y) in pa.iter().zip(&pb) {
        assert_eq!(
            axes(&x.joints).map(f64::to_bits),
            axes(&y.joints).map(f64::to_bits)
        );
        assert_eq!((x.stamp_ns, x.valid), (y.stamp_ns, y.valid));
    }
    // Another seed: other noise.
    let (c, _) = run_busy(12, 100_000);
    let differing = a
        .iter()
        .zip(&c)
        .filter(|(x, y)| x.is_valid() && bits(x) != bits(y))
        .count();
    assert!(differing > a.len() - 5);
}

#[test]
fn results_do_not_depend_on_how_often_the_simulator_is_polled() {
    polling_does_not_change_the_results(busy_spec(3));
    // The plant in motion too: the servos are sampled on the physics grid.
    let mut spec = busy_spec(3);
    spec.plant = PlantSpec {
        inertia: Some(plant::inertia(0.0265, 0.001, 0.2)),
        servo: Some(plant::SERVO),
        quick_stop_decel_mps2: Some(2.0),
    };
    polling_does_not_change_the_results(spec);
}

fn polling_does_not_change_the_results(spec: SimSpec) {
    let (fine, fine_reports) = run_busy_spec(spec.clone(), 100_000);
    let (coarse, coarse_reports) = run_busy_spec(spec, 7 * MS);
    // Fine polling returns every sample; coarse polling only the newest ones.
    assert!(fine.len() > 2 * coarse.len() && coarse.len() > 50);
    let by_counter: std::collections::HashMap<u32, &WrenchSample> =
        fine.iter().map(|s| (s.counter, s)).collect();
    for s in &coarse {
        let f = by_counter[&s.counter];
        assert_eq!(bits(s), bits(f), "sample {}", s.counter);
        assert_eq!((s.received_ns, s.status), (f.received_ns, f.status));
    }
    let by_stamp: std::collections::HashMap<u64, &JointPositions> =
        fine_reports.iter().map(|p| (p.stamp_ns, p)).collect();
    for p in &coarse_reports {
        let f = by_stamp[&p.stamp_ns];
        assert_eq!(
            axes(&p.joints).map(f64::to_bits),
            axes(&f.joints).map(f64::to_bits)
        );
        assert_eq!(p.valid, f.valid);
    }
}

// The plant in motion (issue 26).
#[path = "sim/plant.rs"]
mod plant;
