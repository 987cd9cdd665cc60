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
//!
//! **What the sensor sees of the velocity's steps.** The rod's inertial
//! wrench (MODEL.md 10) takes the axes' acceleration at the sample's
//! instant: the servos' (continuous), or the plans' (piecewise constant).
//! Ideal drives (no servo) also step their velocity: each streamed set
//! point starts a segment of constant speed ([`AxisPlan::segment`]), and a
//! segment not followed in time stops dead. The acceleration there is an
//! impulse, which no sample instant meets: point-sampled, an ideal drive
//! streaming every 1 ms would show the sensor no inertia at all, while the
//! rod's mass takes m dv at every set point. A physical sensor does not
//! sample a point: its converter integrates, its filters average, over its
//! sample period. So on ideal drives each sample's acceleration is the
//! instant's plus the mean over the sensor's period before it of the
//! impulses (their velocity steps over the period `[sensor] rate_hz`
//! gives: the steps at or after `t - period` and before `t`, each step
//! seen once by the samples every period; a step at a sample's own instant,
//! made by a command after it, falls to the next). The period is the
//! shortest window a sensor sending one sample per period can average over
//! (one sample's worth of signal; any longer filter is the device's own and
//! the loop's to model); at the demo's 500 Hz, 2 ms, two set points of
//! the loop's 1 ms. Over a segment's constant speed this is the period's
//! mean acceleration, (v(t) - v(t - period)) / period. The continuous part
//! stays point-sampled, as with servos (MODEL.md 10, "Sampling in step
//! with the set points"), so planned moves and brakes read as before. The
//! truth's accelerations are the ones the wrench is made with.
//!
//! The modules: `validate` (the specification and the faults checked),
//! `timeline` (events in time order, the axes, the physics), `sensor` (the
//! simulated sensor), `drives` (the simulated drives).

mod drives;
mod sensor;
mod timeline;
mod validate;

pub use validate::validate;

use crate::SimError;
use crate::spec::{ContactKey, Fault, ServoSpec, SimSpec};
use crate::statics::{Equilibrium, Loads};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sar_hal::convert::{joints_to_array, ns_to_s};
use sar_hal::motion::{AxisPlan, Limits, SlideDirection};
use sar_hal::servo::ServoAxis;
use sar_hal::{Clock, DriveState, JointPositions, Vec3, WrenchSample};
use sar_kinematics::{ActiveJoints, Pose};
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

/// Most changes of the axes' plans remembered over one sensor period (for
/// the velocity's steps the sensor averages on ideal drives; fixed at
/// start, nothing allocates while the world runs): beyond, the oldest are
/// forgotten and their steps no longer seen. A loop streaming every 1 ms
/// makes two per period of the demo's 500 Hz sensor.
pub const MAX_PLAN_CHANGES: usize = 64;

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
    /// The axes' accelerations (q1, q2, q3) the sensor's wrench is made
    /// with (on ideal drives with the velocity's steps of the sensor's
    /// period: see the module doc), m/s^2.
    pub accels_mps2: [f64; 3],
    /// Noise-free reading with the bias, before the tare, sensor frame.
    pub reading_n: Vec3,
    pub reading_nm: Vec3,
    pub bias_n: Vec3,
    pub bias_nm: Vec3,
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

/// The physics steps a servo's delay spans (rounded to the nearest).
pub(super) fn delay_steps(delay_ns: u64, physics_step_ns: u64) -> usize {
    let steps = (delay_ns + physics_step_ns / 2) / physics_step_ns.max(1);
    usize::try_from(steps).unwrap_or(usize::MAX)
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
    /// The plans replaced over the last sensor period, oldest first, each
    /// with the time it was replaced at (ns from start; in force up to and
    /// including it): where the velocity stepped (at most
    /// [`MAX_PLAN_CHANGES`]).
    past_plans: VecDeque<(u64, [AxisPlan; 3])>,
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
            past_plans: VecDeque::with_capacity(MAX_PLAN_CHANGES),
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
}
