//! The checks of a simulator's specification ([`validate`]) and of each
//! scripted fault, before anything runs: one error naming the field.

use super::{
    MAX_IN_FLIGHT, MAX_PHYSICS_STEP_NS, MAX_SERVO_DELAY_NS, MAX_SERVO_DELAY_STEPS, MIN_PERIOD_NS,
    delay_steps,
};
use crate::SimError;
use crate::spec::{
    AxesSpec, ContactKey, Fault, MAX_SUPPORT_SHIFT_M, PlantSpec, SensorSpec, SimSpec, SupportShift,
    Tissue, TissueModel,
};
use crate::statics::{self, Loads};
use sar_hal::convert::{joints_to_array, ns_to_s};
use sar_hal::drives::FAULT_HEARTBEAT_LOST as FAULT_LOST;
use sar_hal::{DriveState, Vec3};
use sar_kinematics::forward;

pub(super) fn check_finite(field: &'static str, value: f64) -> Result<(), SimError> {
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

pub(super) fn check_vec(field: &'static str, v: &Vec3) -> Result<(), SimError> {
    v.iter().try_for_each(|&x| check_finite(field, x))
}

pub(super) fn check_positive(field: &'static str, value: f64) -> Result<(), SimError> {
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

pub(super) fn check_non_negative(field: &'static str, value: f64) -> Result<(), SimError> {
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
pub(super) fn require(
    ok: bool,
    field: &'static str,
    value: f64,
    why: &'static str,
) -> Result<(), SimError> {
    if ok {
        Ok(())
    } else {
        Err(SimError::InvalidSpec { field, value, why })
    }
}

pub(super) fn check_period(field: &'static str, ns: u64, max_ns: u64) -> Result<(), SimError> {
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
pub(super) fn check_until(
    field: &'static str,
    from_ns: u64,
    until_ns: Option<u64>,
) -> Result<(), SimError> {
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
pub(super) fn check_axis(index: usize, axis: usize) -> Result<(), SimError> {
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
pub(super) fn drive_fault_event(fault: &Fault) -> Option<(u64, DriveState)> {
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
pub(super) fn check_support_shift(shift: &SupportShift) -> Result<(), SimError> {
    check_vec("support_shift.shift_m", &shift.shift_m)?;
    require(
        shift.shift_m.norm() <= MAX_SUPPORT_SHIFT_M,
        "support_shift.shift_m",
        shift.shift_m.norm(),
        "must be at most 0.1 m long",
    )
}

/// Checks one tissue.
pub(super) fn check_tissue(tissue: &Tissue) -> Result<(), SimError> {
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
pub(super) fn check_spec(spec: &SimSpec) -> Result<(), SimError> {
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
pub(super) fn check_axes(axes: &AxesSpec) -> Result<(), SimError> {
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
pub(super) fn check_sensor(sensor: &SensorSpec) -> Result<(), SimError> {
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
pub(super) fn check_plant(plant: &PlantSpec, physics_step_ns: u64) -> Result<(), SimError> {
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
pub(super) fn check_contact(contact: &[ContactKey]) -> Result<(), SimError> {
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
