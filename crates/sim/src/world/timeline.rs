//! The world's timeline: the pending events processed in time order, the
//! drive faults fired, the axes' plans and servos stepped, and the physics
//! (calibration, bias, the rod's wrench) at any instant.

use super::validate::drive_fault_event;
use super::{DRAIN_CAPACITY, DelayLine, MAX_PLAN_CHANGES, Physics, World, contact_at};
use crate::spec::Fault;
use crate::statics::{self, Equilibrium, Loads};
use crate::{SimError, dynamics, tissue};
use sar_hal::convert::{joints_from_array, ns_to_s};
use sar_hal::motion::{AxisPlan, AxisState, Limits};
use sar_hal::servo::ServoAxis;
use sar_hal::{Clock, Vec3};
use sar_kinematics::{Calibration, Pose, forward};

impl<C: Clock> World<C> {
    /// Processes every pending event at or before `until_ns` (each stream
    /// keeps the index of its next event, so nothing is processed twice).
    pub(super) fn process_until(&mut self, until_ns: u64) {
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

    pub(super) fn next_drive_fault(&self) -> Option<u64> {
        self.faults
            .iter()
            .filter(|(_, fired)| !fired)
            .filter_map(|(f, _)| drive_fault_event(f).map(|(at_ns, _)| at_ns))
            .min()
    }

    /// Fires the drive faults due at `t_ns` (several at once: the last in
    /// the list gives the state).
    pub(super) fn fire_drive_faults(&mut self, t_ns: u64) {
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
    pub(super) fn axes_at(&self, t_ns: u64) -> [AxisState; 3] {
        match &self.servos {
            Some(s) if !s.direct => s.axes.map(|a| a.after(t_ns.saturating_sub(s.t_ns)).state()),
            _ => self.plans.map(|p| p.at(t_ns)),
        }
    }

    /// The axes' accelerations at `t_ns`, m/s^2 (as [`World::axes_at`]).
    pub(super) fn accels_at(&self, t_ns: u64) -> [f64; 3] {
        match &self.servos {
            Some(s) if !s.direct => s.axes.map(|a| a.a_mps2),
            _ => self.plans.map(|p| p.accel_at(t_ns)),
        }
    }

    /// The accelerations the sensor's wrench is made with at `t_ns`, m/s^2:
    /// [`World::accels_at`] and, on ideal drives (no servos), the mean over
    /// the sensor's period of the impulses where the velocity stepped in
    /// `[t_ns - period, t_ns)` (a set point replacing a plan, a segment
    /// stopping at its end; see the module doc).
    pub(super) fn sensed_accels_at(&self, t_ns: u64) -> [f64; 3] {
        let point = self.accels_at(t_ns);
        if self.servos.is_some() {
            return point;
        }
        let period_ns = self.spec.sensor.period_ns;
        let from_ns = t_ns.saturating_sub(period_ns);
        let mut steps_mps = [0.0; 3];
        // The plans in force in turn, oldest first, each with the time it
        // was replaced at (the present ones: none).
        let chain = self
            .past_plans
            .iter()
            .map(|(until_ns, plans)| (Some(*until_ns), plans))
            .chain(core::iter::once((None, &self.plans)));
        let mut before: Option<(u64, &[AxisPlan; 3])> = None;
        for (until_ns, plans) in chain {
            if let Some((at_ns, old)) = before
                && from_ns <= at_ns
                && at_ns < t_ns
            {
                for ((step, new), old) in steps_mps.iter_mut().zip(plans).zip(old) {
                    *step += new.at(at_ns).v_mps - old.at(at_ns).v_mps;
                }
            }
            // Its own end (a segment stopping), while it was in force.
            let last_ns = until_ns.map_or(t_ns, |u| u.min(t_ns));
            for (step, plan) in steps_mps.iter_mut().zip(plans) {
                if !plan.holds_at(from_ns) && plan.holds_at(last_ns) {
                    *step += plan.end_step_mps();
                }
            }
            before = until_ns.map(|u| (u, plans));
        }
        let period_s = ns_to_s(period_ns);
        let mut sensed = point;
        for (a, step) in sensed.iter_mut().zip(steps_mps) {
            *a += step / period_s;
        }
        sensed
    }

    /// Replaces the axes' plans at `t_ns` (the present), remembering the
    /// old ones for one sensor period ([`World::sensed_accels_at`]).
    pub(super) fn replace_plans(&mut self, t_ns: u64, plans: [AxisPlan; 3]) {
        let keep_from_ns = t_ns.saturating_sub(self.spec.sensor.period_ns);
        while self
            .past_plans
            .front()
            .is_some_and(|(until_ns, _)| *until_ns < keep_from_ns)
        {
            self.past_plans.pop_front();
        }
        if self.past_plans.len() >= MAX_PLAN_CHANGES {
            self.past_plans.pop_front();
        }
        self.past_plans.push_back((t_ns, self.plans));
        self.plans = plans;
    }

    /// The plans' states at `t_ns`: the axes' own without servos, else the
    /// servos' references (the drives' set-point profiles).
    pub(super) fn reference_at(&self, t_ns: u64) -> [AxisState; 3] {
        self.plans.map(|p| p.at(t_ns))
    }

    /// Every axis brakes from its present state at `decel_mps2` and holds;
    /// servos follow the ramp directly (the drive's own).
    pub(super) fn brake_all(&mut self, t_ns: u64, decel_mps2: f64) {
        let limits = Limits {
            max_accel_mps2: decel_mps2,
            ..self.limits
        };
        let plans = self.axes_at(t_ns).map(|s| AxisPlan::brake(t_ns, s, limits));
        self.replace_plans(t_ns, plans);
        if let Some(s) = &mut self.servos {
            s.direct = true;
        }
    }

    /// Servos that followed a braking ramp take over from it at `t_ns`
    /// (a new set point after a stop).
    pub(super) fn servos_follow(&mut self, t_ns: u64) {
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
    pub(super) fn step_servos(&mut self, t_ns: u64) {
        let references = self.reference_at(t_ns);
        if let Some(s) = &mut self.servos
            && !s.direct
        {
            let dt_ns = t_ns.saturating_sub(s.t_ns);
            let wn_rad_s = core::f64::consts::TAU * s.gains.bandwidth_hz;
            let limit = Some(s.gains.max_accel_mps2);
            let delayed = s.delay.delayed(references.map(|r| r.x_m));
            // The inner loop's lag over the step: the acceleration moves
            // this fraction of the way to what the position loop asks
            // (None: exactly the position loop's, as without the key).
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
    pub(super) fn physics_step(&mut self, t_ns: u64) {
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
    pub(super) fn calibration_at(&self, t_ns: u64) -> Calibration {
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
    pub(super) fn bias_at(&self, t_ns: u64) -> (Vec3, Vec3) {
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
        let accels_mps2 = self.sensed_accels_at(t_ns);
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
    pub(super) fn rod_wrench(
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
}
