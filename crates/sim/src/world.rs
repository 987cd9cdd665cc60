//! The simulated world: axes, rod, support, sensor and the fault script, and
//! the event loop that advances it lazily to the clock's time.
//!
//! Everything happens at fixed instants from the start: physics steps at
//! `j * physics_step_ns`, sensor measurements at `k * period_ns` (received
//! `latency_ns` later), position reports at `k * position_period_ns`, scripted
//! drive faults at their time. [`World::advance`] processes these in time order
//! (ties: physics step, drive fault, measurement, reception, position report)
//! up to the present, and commands act at the present time after it. So the
//! results depend on the commands and their times, never on when or how often
//! the simulator is polled.
//!
//! The axes move along closed-form profiles ([`sar_hal::motion`]), exact at any
//! instant; with a servo (`sar_hal::servo`, issue 26) those profiles are the
//! servos' references and each axis follows its own with a lag, sampled at
//! every physics step, except while the drives brake on their own (a quick
//! stop, a disable, a fault), when the axes follow the braking ramp itself. The physics step follows what has memory: the direction of the
//! last slide of the rod in the support, which fixes the (locked) friction and
//! reverses only after the support's pre-sliding displacement
//! ([`sar_hal::motion::SLIDE_THRESHOLD_M`]), as the runner's does.

use super::spec::{
    AxesSpec, ContactKey, Fault, MAX_SUPPORT_SHIFT_M, PlantSpec, SensorSpec, ServoSpec, SimSpec,
    SupportShift, Tissue, TissueModel,
};
use super::statics::{self, Equilibrium, Loads};
use super::{STATUS_OUT_OF_MODEL, SimError, dynamics, tissue};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sar_hal::convert::{joints_from_array, joints_to_array, ns_to_s};
use sar_hal::drives::FAULT_HEARTBEAT_LOST as FAULT_LOST;
use sar_hal::motion::{AxisPlan, AxisState, Limits, SlideDirection, SlideSign};
use sar_hal::servo::ServoAxis;
use sar_hal::{Clock, DriveState, JointPositions, Rail, SensorStatus, Vec3, WrenchSample};
use sar_kinematics::{ActiveJoints, Calibration, Pose, forward};
use std::collections::VecDeque;

/// Shortest accepted period of anything (physics step, samples, positions), ns.
pub const MIN_PERIOD_NS: u64 = 1_000;
/// Longest accepted physics step, ns.
pub const MAX_PHYSICS_STEP_NS: u64 = 10_000_000;
/// Longest pure delay of a simulated servo's reference, ns
/// ([`ServoSpec::delay_ns`]).
pub const MAX_SERVO_DELAY_NS: u64 = 20_000_000;
/// Most physics steps a simulated servo's delay may span (its delay line is
/// fixed at start: nothing allocates while the world runs).
pub const MAX_SERVO_DELAY_STEPS: usize = 200;
/// Most received samples kept for [`sar_hal::ForceSensor::drain`]; the newest
/// beyond are dropped and counted.
pub const DRAIN_CAPACITY: usize = 4096;

/// Most sensor samples that may be in flight (measured, not yet received).
pub const MAX_IN_FLIGHT: u64 = 65_536;

/// The tip force of the contact script at `t_ns` (piecewise linear, zero before
/// the first key, held after the last; at equal key times the later key wins).
pub(crate) fn contact_at(keys: &[ContactKey], t_ns: u64) -> Vec3 {
    let after = keys.partition_point(|k| k.t_ns <= t_ns);
    let Some(last) = after.checked_sub(1).and_then(|i| keys.get(i)) else {
        return Vec3::zeros();
    };
    match keys.get(after) {
        None => last.force_n,
        Some(next) => {
            // next.t_ns > t_ns >= last.t_ns, so the span is > 0.
            let span = ns_to_s(next.t_ns - last.t_ns);
            let f = ns_to_s(t_ns - last.t_ns) / span;
            last.force_n + (next.force_n - last.force_n) * f
        }
    }
}

/// Fx, Fy, Fz, Tx, Ty, Tz from a force and a torque.
fn join6(force: &Vec3, torque: &Vec3) -> [f64; 6] {
    [force.x, force.y, force.z, torque.x, torque.y, torque.z]
}

/// A force and a torque from Fx, Fy, Fz, Tx, Ty, Tz.
fn split6(v: [f64; 6]) -> (Vec3, Vec3) {
    let [fx, fy, fz, tx, ty, tz] = v;
    (Vec3::new(fx, fy, fz), Vec3::new(tx, ty, tz))
}

/// Everything physical at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Physics {
    pub joints: ActiveJoints,
    pub speeds_mps: [f64; 3],
    pub pose: Pose,
    pub loads: Loads,
    /// The tissues' part of `loads.tip_force_n`, {0}, N.
    pub tissue_force_n: Vec3,
    pub equilibrium: Equilibrium,
    /// The axes' accelerations (q1, q2, q3), m/s^2.
    pub accels_mps2: [f64; 3],
    /// Noise-free reading with the bias, before the tare, sensor frame.
    pub reading_n: Vec3,
    pub reading_nm: Vec3,
    pub bias_n: Vec3,
    pub bias_nm: Vec3,
}

fn check_finite(field: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SimError::InvalidSpec {
            field,
            value,
            why: "must be finite",
        })
    }
}

fn check_vec(field: &'static str, v: &Vec3) -> Result<(), SimError> {
    v.iter().try_for_each(|&x| check_finite(field, x))
}

fn check_positive(field: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SimError::InvalidSpec {
            field,
            value,
            why: "must be finite and > 0",
        })
    }
}

fn check_non_negative(field: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(SimError::InvalidSpec {
            field,
            value,
            why: "must be finite and >= 0",
        })
    }
}

/// `Ok` if `ok`, else the spec error naming `field`, its value and what it
/// must be.
fn require(ok: bool, field: &'static str, value: f64, why: &'static str) -> Result<(), SimError> {
    if ok {
        Ok(())
    } else {
        Err(SimError::InvalidSpec { field, value, why })
    }
}

fn check_period(field: &'static str, ns: u64, max_ns: u64) -> Result<(), SimError> {
    if (MIN_PERIOD_NS..=max_ns).contains(&ns) {
        Ok(())
    } else {
        Err(SimError::InvalidSpec {
            field,
            value: ns as f64,
            why: "must be at least 1000 ns (and a physics step at most 10 ms)",
        })
    }
}

/// Checks that a window's end is after its start.
fn check_until(field: &'static str, from_ns: u64, until_ns: Option<u64>) -> Result<(), SimError> {
    match until_ns {
        Some(until) if until <= from_ns => Err(SimError::InvalidSpec {
            field,
            value: until as f64,
            why: "must be after the start",
        }),
        _ => Ok(()),
    }
}

/// Checks that fault `index` names an axis (0 to 2).
fn check_axis(index: usize, axis: usize) -> Result<(), SimError> {
    if axis > 2 {
        Err(SimError::FaultAxis { index, axis })
    } else {
        Ok(())
    }
}

/// Checks one fault (index `index` in the list).
pub(crate) fn check_fault(index: usize, fault: &Fault) -> Result<(), SimError> {
    let axis_ok = |axis: usize| check_axis(index, axis);
    match *fault {
        Fault::SensorSilent { from_ns, until_ns } => {
            check_until("faults.sensor_silent.until_ns", from_ns, until_ns)
        }
        Fault::NanSample { .. } | Fault::DriveFault { .. } => Ok(()),
        Fault::EncoderJump { axis, jump_m, .. } => {
            axis_ok(axis)?;
            check_finite("faults.encoder_jump.jump_m", jump_m)
        }
        Fault::SensorFrozen { from_ns, until_ns } => {
            check_until("faults.sensor_frozen.until_ns", from_ns, until_ns)
        }
        Fault::SensorSaturated {
            from_ns,
            until_ns,
            channels,
            ..
        } => {
            check_until("faults.sensor_saturated.until_ns", from_ns, until_ns)?;
            let (field, why) = (
                "faults.sensor_saturated.channels",
                "must name at least one channel",
            );
            require(channels.contains(&true), field, 0.0, why)
        }
        Fault::SensorSpike {
            force_n,
            torque_nm,
            samples,
            ..
        } => {
            check_vec("faults.sensor_spike.force_n", &force_n)?;
            check_vec("faults.sensor_spike.torque_nm", &torque_nm)?;
            check_positive("faults.sensor_spike.samples", f64::from(samples))
        }
        Fault::SensorDrift {
            drift_n_per_s,
            drift_nm_per_s,
            ..
        } => {
            check_vec("faults.sensor_drift.drift_n_per_s", &drift_n_per_s)?;
            check_vec("faults.sensor_drift.drift_nm_per_s", &drift_nm_per_s)
        }
        Fault::SensorScale { factor, .. } => check_positive("faults.sensor_scale.factor", factor),
        Fault::EncoderFrozen {
            at_ns,
            axis,
            until_ns,
        } => {
            axis_ok(axis)?;
            check_until("faults.encoder_frozen.until_ns", at_ns, until_ns)
        }
        Fault::EncoderCountLoss { axis, counts, .. } => {
            axis_ok(axis)?;
            let field = "faults.encoder_count_loss.counts";
            require(counts != 0, field, 0.0, "must not be 0")
        }
        Fault::DriveHeartbeatLoss { axis, .. } => axis_ok(axis),
        Fault::DriveEmcy { axis, code, .. } => {
            axis_ok(axis)?;
            let why = "must not be 0 (an EMCY with code 0 says the error is gone)";
            require(code != 0, "faults.drive_emcy.code", 0.0, why)
        }
    }
}

/// When a fault starts, ns from start.
pub(crate) fn fault_start_ns(fault: &Fault) -> u64 {
    match *fault {
        Fault::SensorSilent { from_ns, .. }
        | Fault::SensorFrozen { from_ns, .. }
        | Fault::SensorSaturated { from_ns, .. }
        | Fault::SensorDrift { from_ns, .. }
        | Fault::SensorScale { from_ns, .. } => from_ns,
        Fault::NanSample { at_ns }
        | Fault::EncoderJump { at_ns, .. }
        | Fault::DriveFault { at_ns, .. }
        | Fault::SensorSpike { at_ns, .. }
        | Fault::EncoderFrozen { at_ns, .. }
        | Fault::EncoderCountLoss { at_ns, .. }
        | Fault::DriveHeartbeatLoss { at_ns, .. }
        | Fault::DriveEmcy { at_ns, .. } => at_ns,
    }
}

/// The drive state a fault puts the drives in, and when; `None` for a fault
/// that is not the drives'.
fn drive_fault_event(fault: &Fault) -> Option<(u64, DriveState)> {
    let axis_u8 = |axis: usize| u8::try_from(axis).ok();
    match *fault {
        Fault::DriveFault { at_ns, code } => Some((at_ns, DriveState::Fault { axis: None, code })),
        Fault::DriveHeartbeatLoss { at_ns, axis } => Some((
            at_ns,
            DriveState::Fault {
                axis: axis_u8(axis),
                code: FAULT_LOST,
            },
        )),
        Fault::DriveEmcy { at_ns, axis, code } => Some((
            at_ns,
            DriveState::Fault {
                axis: axis_u8(axis),
                code,
            },
        )),
        _ => None,
    }
}

/// Checks one support shift: finite, at most [`MAX_SUPPORT_SHIFT_M`] long.
fn check_support_shift(shift: &SupportShift) -> Result<(), SimError> {
    check_vec("support_shift.shift_m", &shift.shift_m)?;
    require(
        shift.shift_m.norm() <= MAX_SUPPORT_SHIFT_M,
        "support_shift.shift_m",
        shift.shift_m.norm(),
        "must be at most 0.1 m long",
    )
}

/// Checks one tissue.
fn check_tissue(tissue: &Tissue) -> Result<(), SimError> {
    check_vec("tissue.direction", &tissue.direction)?;
    if (tissue.direction.norm() - 1.0).abs() > 1e-9 {
        return Err(SimError::InvalidSpec {
            field: "tissue.direction",
            value: tissue.direction.norm(),
            why: "must be a unit vector",
        });
    }
    check_vec("tissue.rest_m", &tissue.rest_m)?;
    match tissue.model {
        TissueModel::Linear { stiffness_n_per_m } => {
            check_positive("tissue.stiffness_n_per_m", stiffness_n_per_m)?;
        }
        TissueModel::Exponential {
            stiffness_n_per_m,
            beta_per_m,
        } => {
            check_positive("tissue.stiffness_n_per_m", stiffness_n_per_m)?;
            check_positive("tissue.beta_per_m", beta_per_m)?;
        }
    }
    check_non_negative("tissue.damping_n_s_per_m", tissue.damping_n_s_per_m)?;
    if let Some(b) = &tissue.breathing {
        check_non_negative("tissue.breathing.amplitude_m", b.amplitude_m)?;
        check_positive("tissue.breathing.hz", b.hz)?;
        check_vec("tissue.breathing.direction", &b.direction)?;
        if (b.direction.norm() - 1.0).abs() > 1e-9 {
            return Err(SimError::InvalidSpec {
                field: "tissue.breathing.direction",
                value: b.direction.norm(),
                why: "must be a unit vector",
            });
        }
    }
    let mut previous_ns = 0;
    for shift in &tissue.shifts {
        check_finite("tissue.shift.offset_m", shift.offset_m)?;
        if shift.t_ns < previous_ns {
            return Err(SimError::InvalidSpec {
                field: "tissue.shift.t_ns",
                value: shift.t_ns as f64,
                why: "shifts must be sorted by time",
            });
        }
        previous_ns = shift.t_ns;
    }
    Ok(())
}

/// Checks everything [`World::new`] checks: what the types of [`SimSpec`] do
/// not, the start pose and its statics. The scenario loader
/// (`sar_config::scenario`) calls it too, so that a file it accepts is never
/// refused by the simulator later (where the error could not name the file).
pub fn validate(spec: &SimSpec) -> Result<(), SimError> {
    check_spec(spec)?;
    let pose =
        forward(&spec.calibration, &spec.profile, &spec.axes.start).map_err(SimError::StartPose)?;
    let loads = Loads {
        tip_force_n: Vec3::zeros(),
        tip_mass_kg: spec.tip_mass_kg,
        friction_n: Vec3::zeros(),
    };
    statics::equilibrium(&spec.calibration, &spec.profile, &pose, &loads)
        .ok_or(SimError::StartStaticsSingular)?;
    Ok(())
}

/// Checks what the types of [`SimSpec`] do not.
fn check_spec(spec: &SimSpec) -> Result<(), SimError> {
    check_non_negative("friction_n", spec.friction_n)?;
    check_non_negative("tip_mass_kg", spec.tip_mass_kg)?;
    check_period("physics_step_ns", spec.physics_step_ns, MAX_PHYSICS_STEP_NS)?;
    check_axes(&spec.axes)?;
    check_sensor(&spec.sensor)?;
    for tissue in &spec.tissue {
        check_tissue(tissue)?;
    }
    check_contact(&spec.contact)?;
    check_plant(&spec.plant, spec.physics_step_ns)?;
    for shift in &spec.support_shifts {
        check_support_shift(shift)?;
    }
    for (index, fault) in spec.faults.iter().enumerate() {
        check_fault(index, fault)?;
    }
    Ok(())
}

/// The axes' limits positive, each travel finite and not empty, and each
/// start within its travel.
fn check_axes(axes: &AxesSpec) -> Result<(), SimError> {
    check_positive("axes.max_speed_mps", axes.max_speed_mps)?;
    if let Some(v) = axes.drive_max_speed_mps {
        check_positive("axes.drive_max_speed_mps", v)?;
    }
    check_positive("axes.max_accel_mps2", axes.max_accel_mps2)?;
    check_positive("axes.lead_m_per_turn", axes.lead_m_per_turn)?;
    check_positive("axes.counts_per_turn", f64::from(axes.counts_per_turn))?;
    check_period("axes.position_period_ns", axes.position_period_ns, u64::MAX)?;
    for (&(min_m, max_m), start_m) in axes.travel_m.iter().zip(joints_to_array(&axes.start)) {
        check_finite("axes.travel_m", min_m)?;
        check_finite("axes.travel_m", max_m)?;
        let why = "the upper end must be above the lower end";
        require(min_m < max_m, "axes.travel_m", max_m, why)?;
        check_finite("axes.start", start_m)?;
        let within = (min_m..=max_m).contains(&start_m);
        require(
            within,
            "axes.start",
            start_m,
            "must be within the axis' travel",
        )?;
    }
    Ok(())
}

/// The sensor's period, its latency (at most [`MAX_IN_FLIGHT`] samples in
/// flight), its noise (>= 0), bias and drift (finite) and range (> 0).
fn check_sensor(sensor: &SensorSpec) -> Result<(), SimError> {
    check_period("sensor.period_ns", sensor.period_ns, u64::MAX)?;
    let in_flight = sensor.latency_ns / sensor.period_ns + 1;
    if in_flight > MAX_IN_FLIGHT {
        return Err(SimError::LatencyTooLong {
            latency_ns: sensor.latency_ns,
            period_ns: sensor.period_ns,
            limit: MAX_IN_FLIGHT,
        });
    }
    for &x in sensor.noise_n.iter() {
        check_non_negative("sensor.noise_n", x)?;
    }
    check_non_negative("sensor.counts_per_n", sensor.counts_per_n)?;
    check_non_negative("sensor.counts_per_nm", sensor.counts_per_nm)?;
    for &x in sensor.noise_nm.iter() {
        check_non_negative("sensor.noise_nm", x)?;
    }
    check_vec("sensor.bias_n", &sensor.bias_n)?;
    check_vec("sensor.bias_nm", &sensor.bias_nm)?;
    check_vec("sensor.drift_n_per_s", &sensor.drift_n_per_s)?;
    for &x in sensor.range_n.iter() {
        check_positive("sensor.range_n", x)?;
    }
    for &x in sensor.range_nm.iter() {
        check_positive("sensor.range_nm", x)?;
    }
    Ok(())
}

/// The plant in motion: inertias and the adapter's mass >= 0, the servo's
/// gains and limits and the quick-stop deceleration > 0, and a servo that
/// the physics step samples often enough (wn dt <= 0.2).
fn check_plant(plant: &PlantSpec, physics_step_ns: u64) -> Result<(), SimError> {
    if let Some(i) = &plant.inertia {
        check_non_negative("manipulator.inertia_perp_kgm2", i.inertia_perp_kgm2)?;
        check_non_negative("manipulator.inertia_axial_kgm2", i.inertia_axial_kgm2)?;
        check_non_negative("sensor.adapter_mass_kg", i.adapter_mass_kg)?;
    }
    if let Some(servo) = &plant.servo {
        let field = "axes.servo_bandwidth_hz";
        check_positive(field, servo.bandwidth_hz)?;
        let wn_dt = core::f64::consts::TAU * servo.bandwidth_hz * ns_to_s(physics_step_ns);
        let why = "must be at most 0.2 / (2 pi physics_step_s): the physics step samples the servo";
        require(wn_dt <= 0.2, field, servo.bandwidth_hz, why)?;
        check_positive("axes.servo_damping", servo.damping)?;
        check_positive("axes.servo_max_accel_mps2", servo.max_accel_mps2)?;
        check_non_negative("axes.servo_inner_loop_hz", servo.inner_loop_hz)?;
        let delay_s = ns_to_s(servo.delay_ns);
        let why = "must be at most 0.02 s and at most 200 physics steps";
        let steps_ok = delay_steps(servo.delay_ns, physics_step_ns) <= MAX_SERVO_DELAY_STEPS;
        require(
            servo.delay_ns <= MAX_SERVO_DELAY_NS && steps_ok,
            "axes.servo_delay_s",
            delay_s,
            why,
        )?;
    }
    if let Some(decel) = plant.quick_stop_decel_mps2 {
        check_positive("axes.quick_stop_decel_mps2", decel)?;
    }
    Ok(())
}

/// The contact keys' forces finite and their times in order.
fn check_contact(contact: &[ContactKey]) -> Result<(), SimError> {
    let mut previous_ns = 0;
    for (index, key) in contact.iter().enumerate() {
        check_vec("contact.force_n", &key.force_n)?;
        if key.t_ns < previous_ns {
            return Err(SimError::ContactNotSorted {
                index,
                t_ns: key.t_ns,
                previous_ns,
            });
        }
        previous_ns = key.t_ns;
    }
    Ok(())
}

/// The physics steps a servo's delay spans (rounded to the nearest).
fn delay_steps(delay_ns: u64, physics_step_ns: u64) -> usize {
    let steps = (delay_ns + physics_step_ns / 2) / physics_step_ns.max(1);
    usize::try_from(steps).unwrap_or(usize::MAX)
}

/// The servos of the three axes (with a [`ServoSpec`]): their state at the
/// last physics step, and whether the axes follow their plans directly
/// (the drives' own braking ramp) instead.
#[derive(Debug)]
struct Servos {
    gains: ServoSpec,
    /// The last physics step, ns from start.
    t_ns: u64,
    axes: [ServoAxis; 3],
    direct: bool,
    /// The references of the last physics steps (a pure delay).
    delay: DelayLine,
}

/// A fixed ring of the last `steps + 1` references of the three axes: what
/// a servo with a pure delay of `steps` physics steps acts on.
#[derive(Debug)]
struct DelayLine {
    ring: [[f64; 3]; MAX_SERVO_DELAY_STEPS + 1],
    steps: usize,
    /// Where the newest reference is.
    head: usize,
}

impl DelayLine {
    /// A delay of `steps` (at most [`MAX_SERVO_DELAY_STEPS`]) that has held
    /// `r` for ever.
    fn new(steps: usize, r: [f64; 3]) -> Self {
        Self {
            ring: [r; MAX_SERVO_DELAY_STEPS + 1],
            steps: steps.min(MAX_SERVO_DELAY_STEPS),
            head: 0,
        }
    }

    /// Takes this step's reference and gives the one of `steps` steps ago.
    fn delayed(&mut self, r: [f64; 3]) -> [f64; 3] {
        let len = self.steps + 1;
        self.head = (self.head + 1) % len;
        if let Some(slot) = self.ring.get_mut(self.head) {
            *slot = r;
        }
        let oldest = (self.head + 1) % len;
        self.ring.get(oldest).copied().unwrap_or(r)
    }
}

/// The simulated world. See the module doc.
#[derive(Debug)]
pub(crate) struct World<C> {
    clock: C,
    t0_ns: u64,
    spec: SimSpec,
    limits: Limits,
    /// The faults, with whether a drive fault has fired.
    faults: Vec<(Fault, bool)>,
    /// Every event at or before this time (ns from start) is processed.
    done_ns: u64,
    next_step: u64,
    next_measurement: u64,
    next_report: u64,
    /// The axes' plans: their motion, or with servos their references.
    plans: [AxisPlan; 3],
    servos: Option<Servos>,
    state: DriveState,
    /// The direction of the last slide, from s (A's foot on the rod axis to B).
    slide: SlideDirection,
    rng: ChaCha8Rng,
    /// Measured, not yet received: (receive time from start, sample).
    in_flight: VecDeque<(u64, WrenchSample)>,
    newest: Option<WrenchSample>,
    /// Received, not yet drained (at most [`DRAIN_CAPACITY`]), and how many
    /// were dropped since the last drain because it was full.
    undrained: VecDeque<WrenchSample>,
    drain_lost: u64,
    /// The device-side tare (force, torque), sensor frame.
    tare: Option<(Vec3, Vec3)>,
    /// The six values of the last sample measured (sent or not), for a
    /// sensor that freezes.
    last_output: Option<[f64; 6]>,
    /// While the sensor is frozen: the values it repeats.
    frozen_output: Option<[f64; 6]>,
    positions: JointPositions,
}

impl<C: Clock> World<C> {
    /// Checks `spec` and builds the world at the clock's present time.
    pub fn new(spec: SimSpec, clock: C) -> Result<Self, SimError> {
        validate(&spec)?;
        let t0_ns = clock.now_ns()?;
        let start = joints_to_array(&spec.axes.start);
        let limits = Limits {
            max_speed_mps: spec.axes.max_speed_mps,
            max_accel_mps2: spec.axes.max_accel_mps2,
        };
        let capacity = usize::try_from(spec.sensor.latency_ns / spec.sensor.period_ns + 1)
            .unwrap_or(1)
            .max(1);
        let mut world = Self {
            clock,
            t0_ns,
            limits,
            faults: spec.faults.iter().map(|f| (*f, false)).collect(),
            done_ns: 0,
            // The step at 0 takes the start's slide distance as the reference.
            next_step: 0,
            next_measurement: 0,
            next_report: 0,
            plans: start.map(|x| AxisPlan::hold(0, x)),
            servos: spec.plant.servo.map(|gains| Servos {
                gains,
                t_ns: 0,
                axes: start.map(ServoAxis::rest),
                direct: false,
                delay: DelayLine::new(delay_steps(gains.delay_ns, spec.physics_step_ns), start),
            }),
            state: DriveState::Ready,
            slide: SlideDirection::new(),
            rng: ChaCha8Rng::seed_from_u64(spec.seed),
            in_flight: VecDeque::with_capacity(capacity),
            newest: None,
            undrained: VecDeque::with_capacity(DRAIN_CAPACITY),
            drain_lost: 0,
            tare: None,
            last_output: None,
            frozen_output: None,
            positions: JointPositions {
                joints: spec.axes.start,
                stamp_ns: t0_ns,
                valid: true,
            },
            spec,
        };
        world.process_until(0);
        Ok(world)
    }

    /// The specification.
    pub fn spec(&self) -> &SimSpec {
        &self.spec
    }

    /// Time from the start, ns (processed up to).
    pub fn elapsed_ns(&self) -> u64 {
        self.done_ns
    }

    /// The clock.
    pub fn clock(&self) -> &C {
        &self.clock
    }

    /// Processes every event up to the clock's present time (nothing when the
    /// clock cannot be read: time does not move, samples go stale).
    pub fn advance(&mut self) {
        let Ok(now) = self.clock.now_ns() else {
            return;
        };
        let now = now.saturating_sub(self.t0_ns);
        if now > self.done_ns {
            self.process_until(now);
        }
    }

    /// Processes every pending event at or before `until_ns` (each stream
    /// keeps the index of its next event, so nothing is processed twice).
    fn process_until(&mut self, until_ns: u64) {
        let step = self.spec.physics_step_ns;
        let period = self.spec.sensor.period_ns;
        let report_period = self.spec.axes.position_period_ns;
        loop {
            let t_step = self.next_step.saturating_mul(step);
            let t_fault = self.next_drive_fault();
            let t_measure = self.next_measurement.saturating_mul(period);
            let t_receive = self.in_flight.front().map(|(t, _)| *t);
            let t_report = self.next_report.saturating_mul(report_period);
            let t = [
                Some(t_step),
                t_fault,
                Some(t_measure),
                t_receive,
                Some(t_report),
            ]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(u64::MAX);
            if t > until_ns || t == u64::MAX {
                break;
            }
            if t == t_step {
                self.physics_step(t);
                self.next_step += 1;
            } else if t_fault == Some(t) {
                self.fire_drive_faults(t);
            } else if t == t_measure {
                self.measure(self.next_measurement, t);
                self.next_measurement += 1;
            } else if t_receive == Some(t) {
                if let Some((_, sample)) = self.in_flight.pop_front() {
                    self.newest = Some(sample);
                    if self.undrained.len() < DRAIN_CAPACITY {
                        self.undrained.push_back(sample);
                    } else {
                        self.drain_lost = self.drain_lost.saturating_add(1);
                    }
                }
            } else {
                self.report(t);
                self.next_report += 1;
            }
        }
        self.done_ns = self.done_ns.max(until_ns);
    }

    fn next_drive_fault(&self) -> Option<u64> {
        self.faults
            .iter()
            .filter(|(_, fired)| !fired)
            .filter_map(|(f, _)| drive_fault_event(f).map(|(at_ns, _)| at_ns))
            .min()
    }

    /// Fires the drive faults due at `t_ns` (several at once: the last in
    /// the list gives the state).
    fn fire_drive_faults(&mut self, t_ns: u64) {
        let mut state_now = None;
        for (fault, fired) in &mut self.faults {
            if let Some((at_ns, state)) = drive_fault_event(fault)
                && !*fired
                && at_ns == t_ns
            {
                *fired = true;
                state_now = Some(state);
            }
        }
        if let Some(state) = state_now {
            self.state = state;
            self.brake_all(t_ns, self.limits.max_accel_mps2);
        }
    }

    /// The axes' states at `t_ns` (>= the plans' start and the last physics
    /// step).
    fn axes_at(&self, t_ns: u64) -> [AxisState; 3] {
        match &self.servos {
            Some(s) if !s.direct => s.axes.map(|a| a.after(t_ns.saturating_sub(s.t_ns)).state()),
            _ => self.plans.map(|p| p.at(t_ns)),
        }
    }

    /// The axes' accelerations at `t_ns`, m/s^2 (as [`World::axes_at`]).
    fn accels_at(&self, t_ns: u64) -> [f64; 3] {
        match &self.servos {
            Some(s) if !s.direct => s.axes.map(|a| a.a_mps2),
            _ => self.plans.map(|p| p.accel_at(t_ns)),
        }
    }

    /// The plans' states at `t_ns`: the axes' own without servos, else the
    /// servos' references (the drives' set-point profiles).
    fn reference_at(&self, t_ns: u64) -> [AxisState; 3] {
        self.plans.map(|p| p.at(t_ns))
    }

    /// Every axis brakes from its present state at `decel_mps2` and holds;
    /// servos follow the ramp directly (the drive's own).
    fn brake_all(&mut self, t_ns: u64, decel_mps2: f64) {
        let limits = Limits {
            max_accel_mps2: decel_mps2,
            ..self.limits
        };
        self.plans = self.axes_at(t_ns).map(|s| AxisPlan::brake(t_ns, s, limits));
        if let Some(s) = &mut self.servos {
            s.direct = true;
        }
    }

    /// Servos that followed a braking ramp take over from it at `t_ns`
    /// (a new set point after a stop).
    fn servos_follow(&mut self, t_ns: u64) {
        let states = self.reference_at(t_ns);
        let accels = self.plans.map(|p| p.accel_at(t_ns));
        if let Some(s) = &mut self.servos
            && s.direct
        {
            s.t_ns = t_ns;
            s.direct = false;
            // The drive's delayed reference starts where it took over.
            s.delay = DelayLine::new(s.delay.steps, states.map(|st| st.x_m));
            for ((axis, state), a_mps2) in s.axes.iter_mut().zip(states).zip(accels) {
                *axis = ServoAxis {
                    x_m: state.x_m,
                    v_mps: state.v_mps,
                    a_mps2,
                };
            }
        }
    }

    /// Samples the servos at the physics step `t_ns`.
    fn step_servos(&mut self, t_ns: u64) {
        let references = self.reference_at(t_ns);
        if let Some(s) = &mut self.servos
            && !s.direct
        {
            let dt_ns = t_ns.saturating_sub(s.t_ns);
            let wn_rad_s = core::f64::consts::TAU * s.gains.bandwidth_hz;
            let limit = Some(s.gains.max_accel_mps2);
            let delayed = s.delay.delayed(references.map(|r| r.x_m));
            // The inner loop's lag over the step: the acceleration moves
            // this fraction of the way to what the position loop asks.
            // (None: exactly the position loop's, as without the key.)
            let inner = (s.gains.inner_loop_hz > 0.0).then(|| {
                1.0 - (-core::f64::consts::TAU * s.gains.inner_loop_hz * ns_to_s(dt_ns)).exp()
            });
            for (axis, r_m) in s.axes.iter_mut().zip(delayed) {
                let before_mps2 = axis.a_mps2;
                axis.step(dt_ns, r_m, wn_rad_s, s.gains.damping, limit);
                if let Some(k) = inner {
                    axis.a_mps2 = before_mps2 + k * (axis.a_mps2 - before_mps2);
                }
            }
            s.t_ns = t_ns;
        }
    }

    /// The physics step at `t_ns`: follows the slide of the rod in the
    /// support, s = sqrt(|B - A|^2 - d^2) (from A's foot on the rod axis to B,
    /// along the rod). Inserting (slide +1, the rod moving along u through the
    /// support) shrinks s; a reversal counts once s has come back by more than
    /// the pre-sliding displacement.
    fn physics_step(&mut self, t_ns: u64) {
        self.step_servos(t_ns);
        let joints = joints_from_array(self.axes_at(t_ns).map(|s| s.x_m));
        let cal = &self.calibration_at(t_ns);
        let a_m = cal.p_home_m() + joints.displacement_m() + cal.ujoint_offset_m();
        let r = cal.support_m() - a_m;
        let d = self.spec.profile.offset_m();
        let along_sq = r.norm_squared() - d * d;
        if along_sq <= 0.0 {
            return;
        }
        self.slide.update(along_sq.sqrt());
    }

    /// The true geometry at `t_ns`: the support B moved by the support
    /// shifts so far (none: the spec's calibration as it is).
    fn calibration_at(&self, t_ns: u64) -> Calibration {
        let cal = self.spec.calibration;
        if self.spec.support_shifts.is_empty() {
            return cal;
        }
        let shift_m: Vec3 = self.spec.support_shifts.iter().map(|s| s.at(t_ns)).sum();
        // `with_support` refuses only a non-finite B: the shifts are checked
        // finite and bounded at construction, so the `or` is never taken.
        cal.with_support(cal.support_m() + shift_m).unwrap_or(cal)
    }

    /// The sensor bias at `t_ns` (force drifts linearly; `sensor_drift`
    /// faults add their drift from their start), sensor frame.
    fn bias_at(&self, t_ns: u64) -> (Vec3, Vec3) {
        let sensor = &self.spec.sensor;
        let mut bias_n = sensor.bias_n + sensor.drift_n_per_s * ns_to_s(t_ns);
        let mut bias_nm = sensor.bias_nm;
        for (f, _) in &self.faults {
            if let Fault::SensorDrift {
                from_ns,
                drift_n_per_s,
                drift_nm_per_s,
            } = *f
                && from_ns <= t_ns
            {
                let since_s = ns_to_s(t_ns - from_ns);
                bias_n += drift_n_per_s * since_s;
                bias_nm += drift_nm_per_s * since_s;
            }
        }
        (bias_n, bias_nm)
    }

    /// Everything physical at `t_ns` (ns from start, not before the last
    /// command), with the friction of the last physics step.
    pub fn physics_at(&self, t_ns: u64) -> Result<Physics, SimError> {
        let states = self.axes_at(t_ns);
        let joints = joints_from_array(states.map(|s| s.x_m));
        let spec = &self.spec;
        let cal = self.calibration_at(t_ns);
        let pose = forward(&cal, &spec.profile, &joints).map_err(SimError::PoseOutOfModel)?;
        let contact_n = contact_at(&spec.contact, t_ns);
        let tissue_force_n = if spec.tissue.is_empty() {
            Vec3::zeros()
        } else {
            let speeds_mps = states.map(|s| s.v_mps);
            let tip_velocity_mps =
                tissue::tip_velocity_mps(&cal, &spec.profile, &joints, speeds_mps, &pose.tip_m);
            tissue::force_n(&spec.tissue, t_ns, &pose.tip_m, &tip_velocity_mps)
        };
        let loads = Loads {
            // Without tissue the script's force as it is (bit for bit).
            tip_force_n: if spec.tissue.is_empty() {
                contact_n
            } else {
                contact_n + tissue_force_n
            },
            tip_mass_kg: spec.tip_mass_kg,
            // The support's friction on the rod opposes the last slide; before
            // any slide there is none (physics, not an estimate: 0 is the truth).
            friction_n: pose.rod_dir
                * (-self.slide.sign().sigma().unwrap_or(0.0) * spec.friction_n),
        };
        let accels_mps2 = self.accels_at(t_ns);
        let (equilibrium, ideal_n, ideal_nm) =
            self.rod_wrench(&cal, &pose, &loads, (states.map(|s| s.v_mps), accels_mps2))?;
        let (bias_n, bias_nm) = self.bias_at(t_ns);
        Ok(Physics {
            joints,
            speeds_mps: states.map(|s| s.v_mps),
            accels_mps2,
            pose,
            loads,
            tissue_force_n,
            equilibrium,
            reading_n: ideal_n + bias_n,
            reading_nm: ideal_nm + bias_nm,
            bias_n,
            bias_nm,
        })
    }

    /// The rod's equilibrium and the ideal sensor's wrench: the statics
    /// (MODEL.md 4) without a rod inertia, else Newton-Euler (MODEL.md 10)
    /// at the axes' speeds and accelerations.
    fn rod_wrench(
        &self,
        cal: &Calibration,
        pose: &Pose,
        loads: &Loads,
        (speeds_mps, accels_mps2): ([f64; 3], [f64; 3]),
    ) -> Result<(Equilibrium, Vec3, Vec3), SimError> {
        let profile = &self.spec.profile;
        let Some(inertia) = &self.spec.plant.inertia else {
            let eq =
                statics::equilibrium(cal, profile, pose, loads).ok_or(SimError::StaticsSingular)?;
            let (ideal_n, ideal_nm) = statics::ideal_wrench(cal, pose, &eq);
            return Ok((eq, ideal_n, ideal_nm));
        };
        let a_dot = joints_from_array(speeds_mps).displacement_m();
        let a_ddot = joints_from_array(accels_mps2).displacement_m();
        let inertial = dynamics::inertial(cal, profile, pose, &a_dot, &a_ddot, inertia);
        let eq = statics::equilibrium_in_motion(cal, profile, pose, loads, &inertial)
            .ok_or(SimError::StaticsSingular)?;
        let (ideal_n, ideal_nm) =
            statics::ideal_wrench_in_motion(cal, pose, &eq, &inertial.adapter_force_n);
        Ok((eq, ideal_n, ideal_nm))
    }

    fn silent_at(&self, t_ns: u64) -> bool {
        self.faults.iter().any(|(f, _)| match *f {
            Fault::SensorSilent { from_ns, until_ns } => {
                from_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until)
            }
            _ => false,
        })
    }

    fn nan_at(&self, k: u64) -> bool {
        let period = self.spec.sensor.period_ns;
        self.faults.iter().any(|(f, _)| match *f {
            Fault::NanSample { at_ns } => at_ns.div_ceil(period) == k,
            _ => false,
        })
    }

    fn frozen_at(&self, t_ns: u64) -> bool {
        self.faults.iter().any(|(f, _)| match *f {
            Fault::SensorFrozen { from_ns, until_ns } => {
                from_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until)
            }
            _ => false,
        })
    }

    /// The gain of the active `sensor_scale` faults (their product), `None`
    /// when none is active.
    fn scale_at(&self, t_ns: u64) -> Option<f64> {
        self.faults
            .iter()
            .filter_map(|(f, _)| match *f {
                Fault::SensorScale { from_ns, factor } if from_ns <= t_ns => Some(factor),
                _ => None,
            })
            .reduce(|a, b| a * b)
    }

    /// The wrench the active `sensor_spike` faults add to sample `k` (their
    /// sum), `None` when none is active.
    fn spike_at(&self, k: u64) -> Option<(Vec3, Vec3)> {
        let period = self.spec.sensor.period_ns;
        self.faults
            .iter()
            .filter_map(|(f, _)| match *f {
                Fault::SensorSpike {
                    at_ns,
                    force_n,
                    torque_nm,
                    samples,
                } => {
                    let first = at_ns.div_ceil(period);
                    (first <= k && k - first < u64::from(samples)).then_some((force_n, torque_nm))
                }
                _ => None,
            })
            .reduce(|(f, t), (g, u)| (f + g, t + u))
    }

    /// Per channel, whether a `sensor_saturated` fault pins it at `t_ns`, and
    /// at which rail (`None` inside: the reading's side); the later fault in
    /// the list wins.
    fn saturated_at(&self, t_ns: u64) -> [Option<Option<Rail>>; 6] {
        let mut pinned = [None; 6];
        for (f, _) in &self.faults {
            if let Fault::SensorSaturated {
                from_ns,
                until_ns,
                channels,
                rail,
            } = *f
                && from_ns <= t_ns
                && until_ns.is_none_or(|until| t_ns < until)
            {
                for (p, on) in pinned.iter_mut().zip(channels) {
                    if on {
                        *p = Some(rail);
                    }
                }
            }
        }
        pinned
    }

    /// What the device sends for measurement `k` at `t_ns` (before a freeze
    /// or a NaN): the raw reading (the world's wrench and bias, the noise,
    /// times the gain of a `sensor_scale`, plus a `sensor_spike`), clipped to
    /// the measuring range, saturated channels pinned at it, less the
    /// device-side tare. Fx, Fy, Fz, Tx, Ty, Tz, sensor frame.
    fn device_output(
        &self,
        k: u64,
        t_ns: u64,
        p: &Physics,
        noise_n: &Vec3,
        noise_nm: &Vec3,
    ) -> [f64; 6] {
        let sensor = &self.spec.sensor;
        let (tare_n, tare_nm) = self.tare.unwrap_or((Vec3::zeros(), Vec3::zeros()));
        let scale = self.scale_at(t_ns);
        let spike = self.spike_at(k);
        let (raw, mut out) = if scale.is_none() && spike.is_none() {
            (
                join6(&(p.reading_n + noise_n), &(p.reading_nm + noise_nm)),
                // The fault-free arithmetic, bit for bit as it always was.
                join6(
                    &(p.reading_n - tare_n + noise_n),
                    &(p.reading_nm - tare_nm + noise_nm),
                ),
            )
        } else {
            let gain = scale.unwrap_or(1.0);
            let (spike_n, spike_nm) = spike.unwrap_or((Vec3::zeros(), Vec3::zeros()));
            let raw_n = (p.reading_n + noise_n) * gain + spike_n;
            let raw_nm = (p.reading_nm + noise_nm) * gain + spike_nm;
            (
                join6(&raw_n, &raw_nm),
                join6(&(raw_n - tare_n), &(raw_nm - tare_nm)),
            )
        };
        let range = join6(&sensor.range_n, &sensor.range_nm);
        let tare = join6(&tare_n, &tare_nm);
        let pinned = self.saturated_at(t_ns);
        for ((((o, r), range), tare), pin) in
            out.iter_mut().zip(raw).zip(range).zip(tare).zip(pinned)
        {
            if let Some(rail) = pin {
                let sign = rail.map_or(if r >= 0.0 { 1.0 } else { -1.0 }, Rail::sign);
                *o = sign * range - tare;
            } else if r.abs() > range {
                *o = range.copysign(r) - tare;
            }
        }
        quantise(&mut out, sensor.counts_per_n, sensor.counts_per_nm);
        out
    }

    /// Sensor measurement `k` at `t_ns`.
    fn measure(&mut self, k: u64, t_ns: u64) {
        // Draw the noise of every sample, sent or not, so that the noise of a
        // sample depends only on the seed and its index.
        let mut draw = [0.0; 6];
        for x in &mut draw {
            *x = self.rng.sample(StandardNormal);
        }
        if self.silent_at(t_ns) {
            return;
        }
        let sensor = &self.spec.sensor;
        let [n0, n1, n2, n3, n4, n5] = draw;
        let noise_n = Vec3::new(n0, n1, n2).component_mul(&sensor.noise_n);
        let noise_nm = Vec3::new(n3, n4, n5).component_mul(&sensor.noise_nm);
        let (mut output, status) = match self.physics_at(t_ns) {
            Ok(p) => (
                self.device_output(k, t_ns, &p, &noise_n, &noise_nm),
                SensorStatus::OK,
            ),
            Err(_) => {
                let (bias_n, bias_nm) = self.bias_at(t_ns);
                (join6(&bias_n, &bias_nm), STATUS_OUT_OF_MODEL)
            }
        };
        // A frozen sensor repeats the last sample measured before the freeze
        // (this one's own values when there was none).
        if self.frozen_at(t_ns) {
            output = *self
                .frozen_output
                .get_or_insert(self.last_output.unwrap_or(output));
        } else {
            self.frozen_output = None;
        }
        self.last_output = Some(output);
        let (mut force_n, mut torque_nm) = split6(output);
        if self.nan_at(k) {
            force_n = Vec3::repeat(f64::NAN);
            torque_nm = Vec3::repeat(f64::NAN);
        }
        let receive_ns = t_ns.saturating_add(self.spec.sensor.latency_ns);
        self.in_flight.push_back((
            receive_ns,
            WrenchSample {
                force_n,
                torque_nm,
                // The device's counter wraps at u32::MAX by design.
                counter: (k & u64::from(u32::MAX)) as u32,
                status,
                received_ns: self.t0_ns.saturating_add(receive_ns),
            },
        ));
    }

    /// Position report at `t_ns`.
    fn report(&mut self, t_ns: u64) {
        let axes = &self.spec.axes;
        let count_m = axes.lead_m_per_turn / f64::from(axes.counts_per_turn);
        let mut offsets = [0.0; 3];
        let mut frozen = [false; 3];
        for (f, _) in &self.faults {
            match *f {
                Fault::EncoderJump {
                    at_ns,
                    axis,
                    jump_m,
                } if at_ns <= t_ns => {
                    if let Some(o) = offsets.get_mut(axis) {
                        *o += jump_m;
                    }
                }
                Fault::EncoderCountLoss {
                    at_ns,
                    axis,
                    counts,
                } if at_ns <= t_ns => {
                    if let Some(o) = offsets.get_mut(axis) {
                        *o -= f64::from(counts) * count_m;
                    }
                }
                Fault::EncoderFrozen {
                    at_ns,
                    axis,
                    until_ns,
                } if at_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until) => {
                    if let Some(x) = frozen.get_mut(axis) {
                        *x = true;
                    }
                }
                _ => {}
            }
        }
        // A frozen encoder repeats its previous report.
        let previous = joints_to_array(&self.positions.joints);
        let mut reported = [0.0; 3];
        for ((((r, s), o), stuck), before) in reported
            .iter_mut()
            .zip(self.axes_at(t_ns))
            .zip(offsets)
            .zip(frozen)
            .zip(previous)
        {
            *r = if stuck {
                before
            } else {
                ((s.x_m + o) / count_m).round() * count_m
            };
        }
        self.positions = JointPositions {
            joints: joints_from_array(reported),
            stamp_ns: self.t0_ns.saturating_add(t_ns),
            valid: !matches!(self.state, DriveState::Fault { .. }),
        };
    }

    /// Takes the newest received sample not yet returned.
    pub fn take_newest(&mut self) -> Option<WrenchSample> {
        self.newest.take()
    }

    /// Moves the undrained samples, oldest first, into `out` (as many as fit).
    pub fn drain(&mut self, out: &mut [WrenchSample]) -> sar_hal::Drained {
        let mut count = 0;
        for slot in out.iter_mut() {
            let Some(sample) = self.undrained.pop_front() else {
                break;
            };
            *slot = sample;
            count += 1;
        }
        sar_hal::Drained {
            count,
            lost: core::mem::take(&mut self.drain_lost),
            remaining: self.undrained.len(),
        }
    }

    /// The clock time at which the next sample will be received, if any will.
    pub fn next_receive_ns(&self) -> Option<u64> {
        if let Some((t, _)) = self.in_flight.front() {
            return Some(self.t0_ns.saturating_add(*t));
        }
        let period = self.spec.sensor.period_ns;
        let mut t = self.next_measurement.saturating_mul(period);
        // Each pass leaves at least one silent window behind for good, so
        // faults.len() + 1 passes suffice.
        for _ in 0..=self.faults.len() {
            let mut moved = false;
            for (f, _) in &self.faults {
                if let Fault::SensorSilent { from_ns, until_ns } = *f
                    && from_ns <= t
                    && until_ns.is_none_or(|until| t < until)
                {
                    let until = until_ns?;
                    t = until.div_ceil(period).saturating_mul(period);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        Some(
            self.t0_ns
                .saturating_add(t)
                .saturating_add(self.spec.sensor.latency_ns),
        )
    }

    /// Sets the device-side tare to the present noise-free reading (as the
    /// device reads it: times the gain of an active `sensor_scale`).
    pub fn tare(&mut self) -> Result<(), SimError> {
        let p = self.physics_at(self.done_ns)?;
        self.tare = Some(match self.scale_at(self.done_ns) {
            None => (p.reading_n, p.reading_nm),
            Some(gain) => (p.reading_n * gain, p.reading_nm * gain),
        });
        Ok(())
    }

    /// Removes the device-side tare.
    pub fn clear_tare(&mut self) {
        self.tare = None;
    }

    /// The device-side tare, if set (force, torque; sensor frame).
    pub fn tare_value(&self) -> Option<(Vec3, Vec3)> {
        self.tare
    }

    /// The sign of the last slide (unknown before any slide).
    pub fn slide_sign(&self) -> SlideSign {
        self.slide.sign()
    }

    /// The latest position report.
    pub fn positions(&self) -> JointPositions {
        self.positions
    }

    /// The drives' state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Adds a fault; it must start after the present time.
    pub fn inject(&mut self, fault: Fault) -> Result<(), SimError> {
        check_fault(self.faults.len(), &fault)?;
        let at_ns = fault_start_ns(&fault);
        if at_ns <= self.done_ns {
            return Err(SimError::FaultNotInFuture {
                at_ns,
                elapsed_ns: self.done_ns,
            });
        }
        self.faults.push((fault, false));
        Ok(())
    }

    // Commands (at the present time, after `advance`).

    /// `Ready -> Enabled`.
    pub fn enable(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Ready | DriveState::Enabled => {
                // The axes keep their present plan (a hold, or the stop that
                // followed a disable): enabling does not move them.
                self.state = DriveState::Enabled;
                Ok(())
            }
            state => Err(SimError::InvalidState {
                command: "enable",
                state,
            }),
        }
    }

    /// `Enabled | QuickStop -> Ready`; the axes brake to a stop.
    pub fn disable(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Enabled | DriveState::QuickStop => {
                self.state = DriveState::Ready;
                self.brake_all(self.done_ns, self.limits.max_accel_mps2);
                Ok(())
            }
            DriveState::Ready => Ok(()),
            state @ DriveState::Fault { .. } => Err(SimError::InvalidState {
                command: "disable",
                state,
            }),
        }
    }

    /// New targets (only while `Enabled`).
    pub fn set_targets(&mut self, targets: &ActiveJoints) -> Result<(), SimError> {
        let wanted = self.check_targets("set_targets", targets)?;
        let now = self.done_ns;
        let limits = self.limits;
        self.servos_follow(now);
        let states = self.reference_at(now);
        for ((plan, state), target) in self.plans.iter_mut().zip(states).zip(wanted) {
            *plan = AxisPlan::to_target(now, state, target, limits);
        }
        Ok(())
    }

    /// A cyclic set point (only while `Enabled`): each axis moves at constant
    /// speed from where it is to its set point in `period_ns` and holds
    /// there (an ideal CSP servo; with servos, their reference). A set point
    /// beyond the speed limit over the period (from the reference) is refused.
    pub fn stream(&mut self, targets: &ActiveJoints, period_ns: u64) -> Result<(), SimError> {
        let wanted = self.check_targets("stream", targets)?;
        let now = self.done_ns;
        self.servos_follow(now);
        let states = self.reference_at(now);
        let speed_mps = self
            .spec
            .axes
            .drive_max_speed_mps
            .unwrap_or(self.limits.max_speed_mps);
        let reach_m = speed_mps * ns_to_s(period_ns.max(1)) * (1.0 + 1e-9);
        for (axis, (state, target)) in states.iter().zip(wanted).enumerate() {
            if (target - state.x_m).abs() > reach_m {
                return Err(SimError::SetPointTooFar {
                    axis,
                    distance_m: (target - state.x_m).abs(),
                    reach_m,
                });
            }
        }
        for ((plan, state), target) in self.plans.iter_mut().zip(states).zip(wanted) {
            *plan = AxisPlan::segment(now, state.x_m, target, period_ns);
        }
        Ok(())
    }

    /// Checks targets for `command`: Enabled, finite, within the travel, a
    /// pose the kinematics accepts.
    fn check_targets(
        &self,
        command: &'static str,
        targets: &ActiveJoints,
    ) -> Result<[f64; 3], SimError> {
        if self.state != DriveState::Enabled {
            return Err(SimError::InvalidState {
                command,
                state: self.state,
            });
        }
        let wanted = joints_to_array(targets);
        for (axis, (&value_m, &(min_m, max_m))) in wanted
            .iter()
            .zip(self.spec.axes.travel_m.iter())
            .enumerate()
        {
            if !value_m.is_finite() {
                return Err(SimError::TargetNonFinite { axis, value_m });
            }
            if !(min_m..=max_m).contains(&value_m) {
                return Err(SimError::TargetOutOfTravel {
                    axis,
                    target_m: value_m,
                    min_m,
                    max_m,
                });
            }
        }
        forward(
            &self.calibration_at(self.done_ns),
            &self.spec.profile,
            targets,
        )
        .map_err(SimError::TargetPose)?;
        Ok(wanted)
    }

    /// Quick stop: brake at the quick-stop deceleration (the acceleration
    /// limit when none is given) and hold (a fault stays a fault).
    pub fn quick_stop(&mut self) -> Result<(), SimError> {
        if !matches!(self.state, DriveState::Fault { .. }) {
            self.state = DriveState::QuickStop;
            let decel = self.spec.plant.quick_stop_decel_mps2;
            self.brake_all(self.done_ns, decel.unwrap_or(self.limits.max_accel_mps2));
        }
        Ok(())
    }

    /// `Fault -> Ready` (the simulated cause is gone at once).
    pub fn fault_reset(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Fault { .. } => {
                self.state = DriveState::Ready;
                Ok(())
            }
            state => Err(SimError::InvalidState {
                command: "fault_reset",
                state,
            }),
        }
    }
}

/// The device's counts (`[sensor] counts_per_n`, `counts_per_nm`; 0: none):
/// each channel as `counts / per` with the counts rounded to an i32, as
/// the RDT driver makes its floats (`f64::from(counts) / per`); a value that
/// is not finite stays as it is.
fn quantise(out: &mut [f64; 6], counts_per_n: f64, counts_per_nm: f64) {
    for (k, v) in out.iter_mut().enumerate() {
        let per = if k < 3 { counts_per_n } else { counts_per_nm };
        if per > 0.0 && v.is_finite() {
            let counts = (*v * per)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX));
            *v = counts / per;
        }
    }
}
