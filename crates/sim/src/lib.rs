//! The physics simulator of the robot: one simulated world behind both a
//! [`ForceSensor`] ([`SimSensor`]) and an [`AxisDrives`] ([`SimDrives`]);
//! a scenario as typed data ([`scenario`]: the simulated robot and the
//! motion script to run on it) and the [`runner`] that drives any sensor
//! and drives through such a script.
//!
//! What it simulates (from a [`SimSpec`]):
//! - three axes that follow their targets with a speed and an acceleration
//!   limit (time-optimal trapezoids, exact arrival, no overshoot), reported at a
//!   fixed period and quantised to `lead / counts_per_turn`; with a
//!   [`ServoSpec`] (opt-in, issue 26) each axis is a second-order position
//!   loop that follows that profile with a lag;
//! - the rod's statics, by the simulator's own forward solution of the six
//!   equilibrium equations of MODEL.md 4 (F_A, the support's reaction across u,
//!   the U-joint torsion), independent of the estimator's inverse solution, with
//!   the rod's weight, a tip-force script, tissues that push back on the tip
//!   (unilateral spring-dampers, breathing and shifting: [`Tissue`]), a mass
//!   hung at the tip and the support's Coulomb friction (MODEL.md 5: along the rod, opposite to the
//!   slide, locked at its last value when the rod stops, zero before any slide;
//!   it reverses only once the rod has slid the support's pre-sliding
//!   displacement, [`sar_hal::motion::SLIDE_THRESHOLD_M`], the other way);
//! - with a [`RodInertia`] (opt-in, issue 26) the rod's Newton-Euler wrench
//!   instead (MODEL.md 10): the same six equations with the inertial terms of
//!   the axes' true velocity and acceleration (any offset d), and the
//!   adapter's -m_s A'' on the sensor; at rest, the statics bit for bit;
//! - the force/torque sensor: the wrench of MODEL.md 4 in the sensor frame plus
//!   a bias with linear drift and seeded normal noise per sensor axis (ChaCha8),
//!   clipped to its measuring range, sampled at a fixed period and received
//!   after a latency; an optional device-side tare;
//! - faults on demand ([`Fault`]): of the sensor (silent, a NaN sample, frozen,
//!   saturated, a spike, a drift, a gain error), of the encoders (a jump, a
//!   frozen encoder, lost counts: on the reported position only, `valid`
//!   stays true, as with a real silent encoder error that the estimator must
//!   live with) and of the drives (a fault, a lost heartbeat, an EMCY; on these
//!   plain axes all three are a drive fault).
//!
//! A sample's six values: the raw reading (wrench, bias, noise) times the gain
//! of a `sensor_scale`, plus a `sensor_spike`, clipped to the range, with
//! saturated channels pinned at it, less the device-side tare; a frozen sensor
//! then repeats its last values, and a NaN sample replaces them.
//!
//! Time is the clock's ([`sar_hal::SimClock`] in tests and scenario runs). The
//! world advances lazily to the clock's time on every call, on fixed grids of
//! instants from its start, so the same spec, seed and commands (at the same
//! times) give the same samples bit for bit, however often it is polled.
//! Single-threaded: the handles share the world through `Rc<RefCell<_>>`.
//!
//! Drive states follow [`DriveState`]'s doc, with these choices: `disable`
//! brakes at the acceleration limit, `quick_stop` at the quick-stop
//! deceleration ([`PlantSpec`], the acceleration limit when none), then hold
//! (with servos, the axes follow that ramp itself); a drive fault brakes
//! likewise; `quick_stop` in `Fault` is accepted and leaves the state `Fault`
//! (so that a fault is never cleared without `fault_reset`); the cause of a
//! simulated drive fault is gone at once, so `fault_reset` always succeeds from
//! `Fault`. Positions are `valid: false` while in `Fault`.

mod dynamics;
mod error;
pub mod runner;
pub mod scenario;
pub mod spec;
mod statics;
mod tissue;
mod world;

pub use error::SimError;
pub use spec::{
    AxesSpec, Breathing, ContactKey, Fault, MAX_SUPPORT_SHIFT_M, PlantSpec, RodInertia, SensorSpec,
    ServoSpec, SimSpec, SupportShift, Tissue, TissueModel, TissueShift,
};
pub use world::{
    DRAIN_CAPACITY, MAX_IN_FLIGHT, MAX_PHYSICS_STEP_NS, MAX_PLAN_CHANGES, MAX_SERVO_DELAY_NS,
    MAX_SERVO_DELAY_STEPS, MIN_PERIOD_NS, validate,
};

use sar_hal::{
    AxisDrives, Clock, DriveState, ForceSensor, JointPositions, SensorStatus, Vec3, WrenchSample,
};
use sar_kinematics::{ActiveJoints, Pose};
use std::cell::RefCell;
use std::rc::Rc;
use world::World;

/// Status of a sample taken while the simulated pose is outside the model (no
/// kinematic solution or singular statics): the sample is invalid, its values
/// are the bias alone.
pub const STATUS_OUT_OF_MODEL: SensorStatus = SensorStatus(1);

/// The truth of the simulated world at one instant, for tests: what the
/// estimator should find. All vectors in {0} unless named otherwise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Time from the simulator's start, ns.
    pub elapsed_ns: u64,
    /// The drives' state.
    pub drive_state: DriveState,
    /// The true active joints (not quantised, no encoder jump), m.
    pub joints: ActiveJoints,
    /// The true joint speeds (q1, q2, q3), m/s.
    pub joint_speeds_mps: [f64; 3],
    /// The true joint accelerations (q1, q2, q3), m/s^2, as the sensor's
    /// wrench takes them: on ideal drives the instant's plus the mean over
    /// the sensor's period of the impulses where the velocity stepped
    /// (a streamed set point's; the simulator's module doc).
    pub joint_accels_mps2: [f64; 3],
    /// The true pose, from the true calibration and profile (A, u, w, a, s, ...).
    pub pose: Pose,
    /// F_A: what the robot applies to the rod at A, N.
    pub ujoint_force_n: Vec3,
    /// M_T: the U-joint's torsion on the rod along n = -(s4, 0, c4), N m.
    pub torsion_nm: f64,
    /// The support's reaction across u, N (without the friction).
    pub support_reaction_n: Vec3,
    /// The support's friction on the rod, along u, N.
    pub friction_force_n: Vec3,
    /// Sign of the last slide: inserting (the rod moved along u through the
    /// support), retracting, or unknown before any slide (a slide, or a
    /// reversal, counts once the rod has gone [`sar_hal::motion::SLIDE_THRESHOLD_M`]).
    pub slide_sign: sar_hal::motion::SlideSign,
    /// F_tip: what the tip applies to the tissue, N: the contact script's
    /// force plus the tissues' (`tissue_force_n`).
    pub tip_force_n: Vec3,
    /// The tissues' part of `tip_force_n`, N.
    pub tissue_force_n: Vec3,
    /// The weight of the mass hung at the tip (acts on the rod at D), N.
    pub tip_weight_n: Vec3,
    /// The noise-free sensor force with the bias, before the tare, sensor frame, N.
    pub reading_n: Vec3,
    /// The noise-free sensor torque with the bias, before the tare, sensor frame, N m.
    pub reading_nm: Vec3,
    /// The present force bias, sensor frame, N.
    pub bias_n: Vec3,
    /// The torque bias, sensor frame, N m.
    pub bias_nm: Vec3,
    /// The device-side tare subtracted from the force (zero when none), sensor frame, N.
    pub tare_n: Vec3,
    /// The device-side tare subtracted from the torque (zero when none), sensor frame, N m.
    pub tare_nm: Vec3,
}

type Shared<C> = Rc<RefCell<World<C>>>;

/// Runs `f` on the world after advancing it to the clock's time.
fn with_world<C: Clock, R>(
    world: &Shared<C>,
    f: impl FnOnce(&mut World<C>) -> Result<R, SimError>,
) -> Result<R, SimError> {
    let mut w = world.try_borrow_mut().map_err(|_| SimError::Busy)?;
    w.advance();
    f(&mut w)
}

/// The simulated robot: make it, then take its [`sensor`](Self::sensor) and
/// [`drives`](Self::drives) handles. Clones (and handles) share one world.
#[derive(Debug, Clone)]
pub struct Simulator<C: Clock + Clone> {
    world: Shared<C>,
}

impl<C: Clock + Clone> Simulator<C> {
    /// Checks `spec` (what its types do not: positive periods and limits,
    /// finite numbers, travel, a valid start pose, sorted contact keys, fault
    /// axes) and starts the world at `clock`'s present time.
    pub fn new(spec: SimSpec, clock: C) -> Result<Self, SimError> {
        Ok(Self {
            world: Rc::new(RefCell::new(World::new(spec, clock)?)),
        })
    }

    /// The force/torque sensor of this world.
    pub fn sensor(&self) -> SimSensor<C> {
        SimSensor {
            world: Rc::clone(&self.world),
        }
    }

    /// The axis drives of this world.
    pub fn drives(&self) -> SimDrives<C> {
        SimDrives {
            world: Rc::clone(&self.world),
        }
    }

    /// The encoders' metres per count: a reported position is
    /// `round(x / m) * m` of this `m` (`lead_m_per_turn / counts_per_turn`).
    pub fn encoder_m_per_count(&self) -> Result<f64, SimError> {
        // Read only: the world is not advanced.
        let w = self.world.try_borrow().map_err(|_| SimError::Busy)?;
        let axes = &w.spec().axes;
        Ok(axes.lead_m_per_turn / f64::from(axes.counts_per_turn))
    }

    /// The sensor's counts per newton and per newton metre (0: its floats
    /// are not quantised): a reported force is `counts / counts_per_n`.
    pub fn sensor_counts(&self) -> Result<(f64, f64), SimError> {
        let w = self.world.try_borrow().map_err(|_| SimError::Busy)?;
        let sensor = &w.spec().sensor;
        Ok((sensor.counts_per_n, sensor.counts_per_nm))
    }

    /// Adds a fault on demand. Its start (`at_ns`, `from_ns`; ns from the
    /// simulator's start) must be after the present time.
    pub fn inject_fault(&self, fault: Fault) -> Result<(), SimError> {
        with_world(&self.world, |w| w.inject(fault))
    }

    /// The truth at the clock's present time. `PoseOutOfModel` or
    /// `StaticsSingular` when the present pose has no solution.
    pub fn truth(&self) -> Result<Truth, SimError> {
        with_world(&self.world, |w| {
            let t = w.elapsed_ns();
            let p = w.physics_at(t)?;
            let (tare_n, tare_nm) = w.tare_value().unwrap_or((Vec3::zeros(), Vec3::zeros()));
            Ok(Truth {
                elapsed_ns: t,
                drive_state: w.state(),
                joints: p.joints,
                joint_speeds_mps: p.speeds_mps,
                joint_accels_mps2: p.accels_mps2,
                pose: p.pose,
                ujoint_force_n: p.equilibrium.ujoint_force_n,
                torsion_nm: p.equilibrium.torsion_nm,
                support_reaction_n: p.equilibrium.support_reaction_n,
                friction_force_n: p.loads.friction_n,
                slide_sign: w.slide_sign(),
                tip_force_n: p.loads.tip_force_n,
                tissue_force_n: p.tissue_force_n,
                tip_weight_n: w.spec().calibration.gravity_mps2() * p.loads.tip_mass_kg,
                reading_n: p.reading_n,
                reading_nm: p.reading_nm,
                bias_n: p.bias_n,
                bias_nm: p.bias_nm,
                tare_n,
                tare_nm,
            })
        })
    }
}

/// The simulated force/torque sensor (a handle on the shared world).
#[derive(Debug, Clone)]
pub struct SimSensor<C: Clock> {
    world: Shared<C>,
}

impl<C: Clock> SimSensor<C> {
    /// The longest one [`ForceSensor::wait`] sleeps the simulated clock, ns
    /// (60 s). The world steps its physics through every instant the clock
    /// passes, so an unbounded wait on a sensor silenced for good (or for
    /// centuries) would step physics for centuries: a wait asked for longer
    /// returns `Timeout` after 60 s of simulated time, as a driver that gives
    /// up on a dead device would. No sample period of a real sensor comes
    /// close to it.
    pub const MAX_WAIT_NS: u64 = 60_000_000_000;
}

impl<C: Clock> ForceSensor for SimSensor<C> {
    type Error = SimError;

    fn poll(&mut self) -> Result<Option<WrenchSample>, SimError> {
        with_world(&self.world, |w| Ok(w.take_newest()))
    }

    /// Sleeps on the clock (a [`sar_hal::SimClock`] jumps) until the next sample
    /// arrives or the wait ends, whichever is first. The wait is capped at
    /// [`SimSensor::MAX_WAIT_NS`] of simulated time: a longer timeout returns
    /// `Timeout` (with the timeout asked for) once the cap has passed.
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, SimError> {
        with_world(&self.world, |w| {
            let deadline_ns = w
                .clock()
                .now_ns()?
                .saturating_add(timeout_ns.min(SimSensor::<C>::MAX_WAIT_NS));
            // Each pass moves the clock to the next reception or the deadline.
            loop {
                w.advance();
                if let Some(sample) = w.take_newest() {
                    return Ok(sample);
                }
                let now_ns = w.clock().now_ns()?;
                if now_ns >= deadline_ns {
                    return Err(SimError::Timeout { timeout_ns });
                }
                let next_ns = w
                    .next_receive_ns()
                    .map_or(deadline_ns, |t| t.min(deadline_ns))
                    .max(now_ns.saturating_add(1))
                    .min(deadline_ns);
                w.clock().sleep_until_ns(next_ns);
            }
        })
    }

    fn tare(&mut self) -> Result<(), SimError> {
        with_world(&self.world, |w| {
            if w.spec().sensor.has_tare {
                w.tare()
            } else {
                Err(SimError::Unsupported { command: "tare" })
            }
        })
    }

    fn clear_tare(&mut self) -> Result<(), SimError> {
        with_world(&self.world, |w| {
            if w.spec().sensor.has_tare {
                w.clear_tare();
                Ok(())
            } else {
                Err(SimError::Unsupported {
                    command: "clear_tare",
                })
            }
        })
    }

    /// Every sample received since the last drain; at most
    /// [`DRAIN_CAPACITY`] wait, the newest beyond are dropped and counted.
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<sar_hal::Drained, SimError> {
        with_world(&self.world, |w| Ok(w.drain(out)))
    }
}

/// The simulated axis drives (a handle on the shared world).
#[derive(Debug, Clone)]
pub struct SimDrives<C: Clock> {
    world: Shared<C>,
}

impl<C: Clock> AxisDrives for SimDrives<C> {
    type Error = SimError;

    fn positions(&mut self) -> Result<JointPositions, SimError> {
        with_world(&self.world, |w| Ok(w.positions()))
    }

    fn state(&mut self) -> Result<DriveState, SimError> {
        with_world(&self.world, |w| Ok(w.state()))
    }

    fn enable(&mut self) -> Result<(), SimError> {
        with_world(&self.world, World::enable)
    }

    fn disable(&mut self) -> Result<(), SimError> {
        with_world(&self.world, World::disable)
    }

    fn set_targets(&mut self, targets: ActiveJoints) -> Result<(), SimError> {
        with_world(&self.world, |w| w.set_targets(&targets))
    }

    fn stream(&mut self, targets: ActiveJoints, period_ns: u64) -> Result<(), SimError> {
        with_world(&self.world, |w| w.stream(&targets, period_ns))
    }

    fn quick_stop(&mut self) -> Result<(), SimError> {
        with_world(&self.world, World::quick_stop)
    }

    fn fault_reset(&mut self) -> Result<(), SimError> {
        with_world(&self.world, World::fault_reset)
    }
}
