//! What the simulator simulates: a validated, plain description of the true
//! robot, manipulator, support, axes, sensor, contact script, tissue and
//! faults.
//! Scenario files are parsed and checked into this by `sar_config::scenario`.
//!
//! Times are nanoseconds from the simulator's start (the clock's time when the
//! simulator was made).

use sar_hal::{Channels, Rail, Vec3};
use sar_kinematics::{ActiveJoints, Calibration, Profile};

/// Everything the simulator needs; built from a scenario file by
/// `sar_config::scenario` (or by hand in tests).
#[derive(Debug, Clone, PartialEq)]
pub struct SimSpec {
    /// Seed of every random number (sensor noise): same seed and spec, same samples.
    pub seed: u64,
    /// The TRUE geometry (the support point B here is the real one; the
    /// daemon's configuration may differ, which is the point of calibration).
    pub calibration: Calibration,
    /// The TRUE manipulator (L, d, m, c).
    pub profile: Profile,
    /// Coulomb friction of the support along the rod, N (>= 0).
    pub friction_n: f64,
    /// The axes and their encoders.
    pub axes: AxesSpec,
    /// The force/torque sensor.
    pub sensor: SensorSpec,
    /// Tip force keyframes, piecewise linear in time, zero before the first
    /// and held after the last. Sorted by time.
    pub contact: Vec<ContactKey>,
    /// Tissues that push back on the tip (unilateral spring-dampers); their
    /// force adds to the contact script's.
    pub tissue: Vec<Tissue>,
    /// A known mass hung at the tip (the article's Table 3), kg (0: none).
    pub tip_mass_kg: f64,
    /// Faults on demand.
    pub faults: Vec<Fault>,
    /// Step of the physics integration, ns (e.g. 100_000). Results do not depend
    /// on when the simulator is polled, only on this grid.
    pub physics_step_ns: u64,
    /// The plant in motion (issue 26): the rod's inertia, the axes' servos,
    /// the drives' quick-stop deceleration. Each part is opt-in: the default
    /// (all `None`) is the plant without inertia and with ideal axes.
    pub plant: PlantSpec,
    /// The support moving (issue 26, MODEL.md 10: the patient shifts): the
    /// true B is `calibration`'s plus the sum of these shifts, each ramped
    /// in over its duration; the daemon's configured B does not move.
    /// Empty: B stays where `calibration` has it (bit for bit as before).
    pub support_shifts: Vec<SupportShift>,
}

/// The true support point B moving by `shift_m` from `t_ns` on, along a
/// smooth ramp (`(1 - cos(pi s)) / 2` of the way at the fraction s of
/// `duration_ns`; a step when 0), then staying there. Shifts add up. The
/// rod's inertial terms (MODEL.md 10) and the tissues' damping (the tip's
/// velocity from the joints') take the support as still: its own velocity
/// and acceleration (at most `pi / 2 |shift| / duration` and
/// `pi^2 / 2 |shift| / duration^2`) are not in them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportShift {
    /// When the shift starts, ns.
    pub t_ns: u64,
    /// The displacement of B once done, {0}, m (finite, at most
    /// [`MAX_SUPPORT_SHIFT_M`] long).
    pub shift_m: Vec3,
    /// How long it takes, ns (0: at once).
    pub duration_ns: u64,
}

/// The longest support shift the simulator accepts, m.
pub const MAX_SUPPORT_SHIFT_M: f64 = 0.1;

impl SupportShift {
    /// Its displacement at `t_ns`, m.
    pub fn at(&self, t_ns: u64) -> Vec3 {
        if t_ns < self.t_ns {
            return Vec3::zeros();
        }
        let since_ns = t_ns - self.t_ns;
        if since_ns >= self.duration_ns {
            return self.shift_m;
        }
        let s = since_ns as f64 / self.duration_ns as f64;
        self.shift_m * (0.5 * (1.0 - (core::f64::consts::PI * s).cos()))
    }
}

/// The plant in motion; each `None` keeps the plant of before issue 26.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantSpec {
    /// The rod's inertia and the adapter's mass: the sensor reads the
    /// Newton-Euler wrench (MODEL.md 10) instead of the statics (MODEL.md 4).
    pub inertia: Option<RodInertia>,
    /// Each axis a second-order position loop that lags its set point;
    /// `None`: ideal axes on their closed-form profiles.
    pub servo: Option<ServoSpec>,
    /// The drives' quick-stop deceleration (CiA 402 0x6085), m/s^2; `None`:
    /// a quick stop brakes at `axes.max_accel_mps2`.
    pub quick_stop_decel_mps2: Option<f64>,
}

/// The rod's inertia about its centre of mass and the adapter's mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RodInertia {
    /// I_perp: about any axis across the rod through C, kg m^2 (>= 0).
    pub inertia_perp_kgm2: f64,
    /// I_axial: about the rod's axis, kg m^2 (>= 0).
    pub inertia_axial_kgm2: f64,
    /// m_s: the mass between the sensor and the U-joint, lumped at A, kg
    /// (>= 0); its weight is in the bias, its inertia reads -m_s A''.
    pub adapter_mass_kg: f64,
}

/// A servo per axis: `x'' = wn^2 (r - x) - 2 zeta wn x'` with
/// `wn = 2 pi bandwidth_hz`, the acceleration clipped to +-`max_accel_mps2`,
/// sampled every physics step (constant acceleration over the step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoSpec {
    /// Natural frequency of the loop, Hz (> 0).
    pub bandwidth_hz: f64,
    /// Damping ratio (> 0).
    pub damping: f64,
    /// The servo's own acceleration limit, m/s^2 (> 0).
    pub max_accel_mps2: f64,
    /// A pure delay of the reference, ns (0: none; at most
    /// [`crate::MAX_SERVO_DELAY_NS`], and at most
    /// [`crate::MAX_SERVO_DELAY_STEPS`] physics steps): the drive acts on
    /// the set point's profile as it was this long ago (a fieldbus's, an
    /// interpolator's delay), rounded to whole physics steps. Not in the
    /// loop's model (issue 34: a plant that is not the model).
    pub delay_ns: u64,
    /// The bandwidth of the drive's inner (velocity) loop, Hz (0: none, the
    /// loop is second order): the acceleration the position loop asks for
    /// is reached through a first-order lag at this frequency, which makes
    /// the axis third order, `wn^2 / (tau s^3 + s^2 + 2 zeta wn s + wn^2)`
    /// with `tau = 1 / (2 pi inner_loop_hz)`. Not in the loop's model.
    pub inner_loop_hz: f64,
}

/// The three prismatic axes (q1, q2, q3; index 0, 1, 2 in arrays).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxesSpec {
    /// Speed limit of each axis, m/s (the drives' own planner's).
    pub max_speed_mps: f64,
    /// The drives' own velocity limit (CiA 402 0x607F max profile
    /// velocity), m/s: a streamed set point farther than it allows over a
    /// period from the drives' reference is refused. `None`:
    /// `max_speed_mps`. `sard --sim` sets what it writes into CANopen
    /// drives (`sar_daemon::devices::drive_max_speed_mps`), so that a
    /// stream at the planned speed has the same margin for the loop's
    /// jitter as on the robot.
    pub drive_max_speed_mps: Option<f64>,
    /// Acceleration limit of each axis, m/s^2.
    pub max_accel_mps2: f64,
    /// Screw lead, metres per motor turn.
    pub lead_m_per_turn: f64,
    /// Encoder counts per motor turn (4096 = 12 bits).
    pub counts_per_turn: u32,
    /// Period at which positions are reported, ns.
    pub position_period_ns: u64,
    /// Travel of each axis, (min, max) metres; targets outside are refused.
    pub travel_m: [(f64, f64); 3],
    /// Positions at start, m.
    pub start: ActiveJoints,
}

/// The force/torque sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSpec {
    /// Sample period, ns (2_000_000 for 500 Hz).
    pub period_ns: u64,
    /// From the instant a sample measures to its host receive time, ns.
    pub latency_ns: u64,
    /// Force noise std per sensor axis, N (HEX-6: 0.2, 0.2, 0.8).
    pub noise_n: Vec3,
    /// Torque noise std per sensor axis, N m.
    pub noise_nm: Vec3,
    /// Force bias at start, sensor frame, N.
    pub bias_n: Vec3,
    /// Torque bias at start, sensor frame, N m.
    pub bias_nm: Vec3,
    /// Slow drift of the force bias, N/s.
    pub drift_n_per_s: Vec3,
    /// Whether the device has a device-side tare command.
    pub has_tare: bool,
    /// Measuring range of the force channels, N (> 0): the raw reading (before
    /// the device-side tare) is clipped to +-range, as a real sensor's is.
    pub range_n: Vec3,
    /// Measuring range of the torque channels, N m (> 0).
    pub range_nm: Vec3,
    /// The device's counts per newton (>= 0; 0: the forces reported as
    /// computed): each force channel is reported as `counts / counts_per_n`
    /// with the counts rounded, as the RDT driver makes its floats.
    pub counts_per_n: f64,
    /// Counts per newton metre of the torque channels (0: as computed).
    pub counts_per_nm: f64,
}

/// How a tissue's spring stiffens with the penetration delta (m, > 0 inside).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TissueModel {
    /// F = k delta.
    Linear {
        /// k, N/m.
        stiffness_n_per_m: f64,
    },
    /// F = (k0 / beta) (exp(beta delta) - 1): stiffness k0 at zero
    /// penetration, k0 exp(beta delta) deeper (soft tissue stiffens).
    Exponential {
        /// k0, N/m.
        stiffness_n_per_m: f64,
        /// beta, 1/m.
        beta_per_m: f64,
    },
}

/// Breathing: the tissue's rest point moves as
/// `direction * amplitude_m * sin(2 pi hz t)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breathing {
    /// Amplitude, m (>= 0).
    pub amplitude_m: f64,
    /// Frequency, Hz (> 0).
    pub hz: f64,
    /// Unit direction of the motion, {0} (the tissue's own direction unless
    /// the file gives another; only its part along the tissue's direction
    /// changes the force, the surface being a plane).
    pub direction: Vec3,
}

/// A sudden shift of a tissue: from `t_ns` on, its rest point sits
/// `offset_m` along the tissue's direction from `rest_m` (the latest shift
/// at or before the time counts; none before the first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TissueShift {
    /// From when, ns from start.
    pub t_ns: u64,
    /// Offset of the rest point along the direction, m.
    pub offset_m: f64,
}

/// A tissue at the tip: a unilateral spring-damper along a unit `direction`
/// (base frame), whose surface is the plane through the rest point normal to
/// it. With the penetration `delta = (D - rest(t)) . direction` and its rate,
/// the force is zero while `delta <= 0` (the tip outside), else
/// `F = max(0, spring(delta) + damping * d(delta)/dt)` along `direction`:
/// F_tip (what the tip applies to the tissue, MODEL.md 4) is `F * direction`,
/// so a tip that penetrates along +direction pushes along +direction. The
/// damping never pulls (no stickiness). The tissue has no state: the tip is
/// carried by the axes' positions, so the law is evaluated at each instant,
/// never integrated, and no physics step makes it unstable.
#[derive(Debug, Clone, PartialEq)]
pub struct Tissue {
    /// Unit direction, {0}: the tip penetrates along +direction.
    pub direction: Vec3,
    /// A point of the tissue's surface at rest, {0}, m.
    pub rest_m: Vec3,
    /// The spring.
    pub model: TissueModel,
    /// Damping, N s/m (>= 0).
    pub damping_n_s_per_m: f64,
    /// Breathing motion of the rest point, if any.
    pub breathing: Option<Breathing>,
    /// Sudden shifts of the rest point, sorted by time.
    pub shifts: Vec<TissueShift>,
}

/// One keyframe of the tip force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactKey {
    /// Time from start, ns.
    pub t_ns: u64,
    /// F_tip: the force the tip applies to the tissue, base frame, N.
    pub force_n: Vec3,
}

/// A fault on demand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The sensor sends nothing from `from_ns` until `until_ns` (or forever).
    SensorSilent {
        /// Start, ns from start.
        from_ns: u64,
        /// End, ns from start; `None`: never comes back.
        until_ns: Option<u64>,
    },
    /// The first sample measured at or after `at_ns` carries NaN values.
    NanSample {
        /// When, ns from start.
        at_ns: u64,
    },
    /// From `at_ns`, the encoder of one axis reads `jump_m` off (the axis
    /// itself does not move).
    EncoderJump {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// The jump, m.
        jump_m: f64,
    },
    /// At `at_ns` the drives fault with `code` and stop; `fault_reset` clears it.
    DriveFault {
        /// When, ns from start.
        at_ns: u64,
        /// Fault code.
        code: u16,
    },
    /// The sensor freezes: from `from_ns` (until `until_ns`, or for good) every
    /// sample repeats, bit for bit, the six values of the last sample measured
    /// before (stuck-at), while the counter advances and the samples keep
    /// coming at the rate with a good status.
    SensorFrozen {
        /// Start, ns from start.
        from_ns: u64,
        /// End, ns from start; `None`: for good.
        until_ns: Option<u64>,
    },
    /// The chosen channels sit at the end of the measuring range (an amplifier
    /// at its rail) from `from_ns` until `until_ns` (or for good).
    SensorSaturated {
        /// Start, ns from start.
        from_ns: u64,
        /// End, ns from start; `None`: for good.
        until_ns: Option<u64>,
        /// Which channels (at least one).
        channels: Channels,
        /// Which end; `None`: the side of each channel's reading (+ at 0).
        rail: Option<Rail>,
    },
    /// The `samples` samples measured from the first at or after `at_ns` carry
    /// an added wrench (sensor frame), then it is gone: an outlier.
    SensorSpike {
        /// When, ns from start.
        at_ns: u64,
        /// Added force, sensor frame, N.
        force_n: Vec3,
        /// Added torque, sensor frame, N m.
        torque_nm: Vec3,
        /// How many samples (>= 1).
        samples: u32,
    },
    /// From `from_ns` the bias drifts linearly (besides the sensor's own
    /// `drift_n_per_s`): a temperature drift after a tare.
    SensorDrift {
        /// Start, ns from start.
        from_ns: u64,
        /// Force drift, sensor frame, N/s.
        drift_n_per_s: Vec3,
        /// Torque drift, sensor frame, N m/s.
        drift_nm_per_s: Vec3,
    },
    /// From `from_ns` the sensor's gain is off by `factor` (a wrong
    /// counts-per-newton or a damaged gauge): the raw reading (with its
    /// noise) is multiplied by it, on all six channels.
    SensorScale {
        /// Start, ns from start.
        from_ns: u64,
        /// The gain factor (> 0).
        factor: f64,
    },
    /// From `at_ns` (until `until_ns`, or for good) the encoder of one axis
    /// reports the same position, while the axis itself moves as commanded.
    EncoderFrozen {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// End, ns from start; `None`: for good.
        until_ns: Option<u64>,
    },
    /// At `at_ns` the encoder of one axis loses `counts` counts: from then on
    /// it reads `counts * lead / counts_per_turn` less than the axis's
    /// position (negative counts: more); the axis itself is unaffected.
    EncoderCountLoss {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// Counts lost (non-zero).
        counts: i32,
    },
    /// At `at_ns` one drive stops sending its CANopen heartbeat. The plain
    /// simulated axes have no heartbeat: here it is a drive fault of that
    /// axis with the code a CANopen host gives a lost drive
    /// ([`sar_hal::drives::FAULT_HEARTBEAT_LOST`], 0x8130), at `at_ns` itself
    /// (the CANopen host sees it a heartbeat timeout later; see
    /// `sar_canopen::SimDriveFault`); the axes brake and `fault_reset`
    /// clears it, as [`Fault::DriveFault`].
    DriveHeartbeatLoss {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
    },
    /// At `at_ns` one drive faults and sends an EMCY with `code`. On the plain
    /// simulated axes: a drive fault of that axis with that code, as
    /// [`Fault::DriveFault`].
    DriveEmcy {
        /// When, ns from start.
        at_ns: u64,
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: usize,
        /// The EMCY error code (non-zero).
        code: u16,
    },
}
