//! Scenario files: a simulated robot (true geometry, manipulator, support,
//! axes, sensor, tip contact, faults) and the motion script to run on it, as a
//! TOML file under version control (the format is described in
//! `scenarios/README.md`).
//!
//! [`load`] and [`parse`] check every value and build a [`Scenario`]: the
//! simulator's [`SimSpec`] and a [`MotionScript`] for [`crate::runner`]. A bad
//! file is a [`ScenarioError`] whose message names the file, the key (dotted,
//! e.g. `motion[3].hold_s`) and what is wrong; TOML syntax errors keep toml's
//! line and column.

pub mod locate;
mod raw;

use crate::Vec3;
use crate::convert::{joints_from_array, joints_from_displacement, joints_to_array};
use crate::motion::{SlideSign, SlideTracker, axis_progress_m, move_time_s};
use crate::sim::{AxesSpec, ContactKey, Fault, SensorSpec, SimError, SimSpec};
use locate::Locator;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use raw::{AxisName, FaultKind, FaultToml, FileToml, MotionToml};
use sar_kinematics::{
    ActiveJoints, Calibration, CalibrationSpec, ConfigError, MIN_DISTANCE_M, Mat3, PoseError,
    Profile, ProfileSpec, forward, inverse,
};
use std::path::Path;

/// Default speed limit of each axis, m/s (the article's axes).
pub const DEFAULT_MAX_SPEED_MPS: f64 = 0.05;
/// Default acceleration limit of each axis, m/s^2.
pub const DEFAULT_MAX_ACCEL_MPS2: f64 = 0.5;
/// Default screw lead, m per motor turn.
pub const DEFAULT_LEAD_M_PER_TURN: f64 = 0.005;
/// Default encoder counts per motor turn.
pub const DEFAULT_COUNTS_PER_TURN: u32 = 4096;
/// Default rate of the position reports, Hz.
pub const DEFAULT_POSITION_RATE_HZ: f64 = 1000.0;
/// Default travel of q1, q2, q3: (min, max), m.
pub const DEFAULT_TRAVEL_M: [[f64; 2]; 3] = [[-0.3, 0.3], [0.0, 0.6], [0.0, 0.6]];
/// Default sensor sample rate, Hz.
pub const DEFAULT_SENSOR_RATE_HZ: f64 = 500.0;
/// Default sensor latency (measurement to host receive time), s.
pub const DEFAULT_SENSOR_LATENCY_S: f64 = 0.001;
/// Default force noise std per sensor axis, N (HEX-6, MODEL.md 7).
pub const DEFAULT_NOISE_N: [f64; 3] = [0.2, 0.2, 0.8];
/// Default torque noise std per sensor axis, N m.
pub const DEFAULT_NOISE_NM: [f64; 3] = [0.01, 0.01, 0.002];
/// Default step of the physics integration, s.
pub const DEFAULT_PHYSICS_STEP_S: f64 = 1e-4;
/// Longest time a file may name, s (about 11.6 days): keeps ns in range.
pub const MAX_TIME_S: f64 = 1e6;
/// The path between two targets is checked with the kinematics at least at
/// this many instants...
pub const PATH_CHECK_POINTS: u32 = 32;
/// ...and at least every this long, s...
pub const PATH_CHECK_INTERVAL_S: f64 = 0.01;
/// ...but at most at this many (a move of more than 1000 s).
pub const PATH_CHECK_MAX_POINTS: u32 = 100_000;
/// A path whose U-joint passes this close to the vertical through the
/// support, m, makes the rod vertical.
pub const VERTICAL_CLEARANCE_M: f64 = 1e-9;

/// A checked scenario: what to simulate and what to run on it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The `name` key.
    pub name: String,
    /// The `description` key ("" when absent).
    pub description: String,
    /// Where the scenario came from (the file's path, or the `origin` given to [`parse`]).
    pub origin: String,
    /// `manipulator.name`, when given.
    pub manipulator_name: Option<String>,
    /// The simulated robot.
    pub spec: SimSpec,
    /// The motion to run on it.
    pub script: MotionScript,
}

/// The motion of a scenario: where the axes start and the targets in order.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionScript {
    /// Positions of the axes at start (equal to `spec.axes.start`).
    pub start: ActiveJoints,
    /// The steps, `[[motion]]` first, then the `[random_motion]` ones.
    pub steps: Vec<MotionStep>,
    /// The geometry the steps were computed with; the runner uses it to follow
    /// a = |B - A| and so the sign of each slide of the rod in the support.
    pub calibration: Calibration,
    /// Speed limit of each axis, m/s (bounds the wait for arrival).
    pub max_speed_mps: f64,
    /// Acceleration limit of each axis, m/s^2.
    pub max_accel_mps2: f64,
}

/// One step of the motion: go to `target`, then hold it for `hold_ns`.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionStep {
    /// Where the step comes from: `motion[3]` or `random_motion[2]`.
    pub key: String,
    /// Target positions of the axes, m.
    pub target: ActiveJoints,
    /// Time to hold the target after arriving, ns.
    pub hold_ns: u64,
    /// The sign of the last slide of the rod in the support once the step is
    /// done, if each axis moves on its own time-optimal trapezoid from rest to
    /// rest (as the simulator's do): inserting when A last moved towards B (the
    /// rod slid along u), retracting away, the previous step's sign when the
    /// step does not slide the rod, and unknown when nothing has slid yet.
    /// Followed with the same [`SlideTracker`] as the runner's.
    pub planned_slide_sign: SlideSign,
}

impl MotionScript {
    /// A time the script needs at least with straight moves at the limits:
    /// the sum over the steps of the slowest axis's trapezoid and the hold, ns.
    pub fn nominal_duration_ns(&self) -> u64 {
        let mut from = self.start;
        let mut total_ns: u64 = 0;
        for step in &self.steps {
            let move_s = move_time_s(&from, &step.target, self.max_speed_mps, self.max_accel_mps2);
            total_ns = total_ns
                .saturating_add(seconds_to_ns_saturating(move_s))
                .saturating_add(step.hold_ns);
            from = step.target;
        }
        total_ns
    }
}

fn seconds_to_ns_saturating(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        // Saturating float-to-int cast; times here are far below u64::MAX ns.
        (s * 1e9).round() as u64
    } else {
        0
    }
}

/// A scenario file that cannot be used. The message always names the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("{origin}: cannot read the file: {reason}")]
    Read {
        /// The file.
        origin: String,
        /// The system's reason.
        reason: String,
    },
    /// The file is not valid TOML (toml's message, with line and column).
    #[error("{origin}: not valid TOML: {message}")]
    Syntax {
        /// The file.
        origin: String,
        /// toml's message.
        message: String,
    },
    /// A key is missing, unknown, of the wrong type, or has a value that is not allowed.
    #[error("{origin}: {}{}: {problem}", key_or_top(key), line_suffix(*line))]
    Invalid {
        /// The file.
        origin: String,
        /// The dotted key, e.g. `motion[3].hold_s` ("" for the file as a whole).
        key: String,
        /// The 1-based line where the key (or its table) is written, when it is.
        line: Option<usize>,
        /// What is wrong.
        problem: String,
    },
}

fn key_or_top(key: &str) -> &str {
    if key.is_empty() { "(top level)" } else { key }
}

fn line_suffix(line: Option<usize>) -> String {
    line.map(|l| format!(" (line {l})")).unwrap_or_default()
}

impl ScenarioError {
    /// The file (or origin) the error is about.
    pub fn origin(&self) -> &str {
        match self {
            Self::Read { origin, .. }
            | Self::Syntax { origin, .. }
            | Self::Invalid { origin, .. } => origin,
        }
    }

    /// The dotted key the error is about, for [`ScenarioError::Invalid`].
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// Reads and checks a scenario file; errors name `path`.
pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Read {
        origin: origin.clone(),
        reason: e.to_string(),
    })?;
    parse(&text, &origin)
}

/// Checks a scenario given as text; `origin` names it in errors (a path, or
/// anything that tells the reader where the text came from).
pub fn parse(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
    let root = toml::de::DeTable::parse(text).map_err(|e| {
        let mut e = e;
        e.set_input(Some(text));
        ScenarioError::Syntax {
            origin: origin.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        }
    })?;
    let ctx = Ctx {
        origin,
        locator: Locator::new(text, &root),
    };
    // NaN and infinity are valid TOML floats; no value of a scenario may be one.
    if let Some((key, line)) = ctx.locator.first_non_finite() {
        return Err(ScenarioError::Invalid {
            origin: origin.to_owned(),
            key,
            line: Some(line),
            problem: "not a finite number".to_owned(),
        });
    }
    let file: FileToml = serde::Deserialize::deserialize(toml::de::Deserializer::from(root))
        .map_err(|e| ctx.serde_error(&e))?;
    build(&ctx, file)
}

/// The file being checked: makes errors that name it, the key and the line.
struct Ctx<'a> {
    origin: &'a str,
    locator: Locator<'a>,
}

impl Ctx<'_> {
    fn err(&self, key: &str, problem: impl Into<String>) -> ScenarioError {
        ScenarioError::Invalid {
            origin: self.origin.to_owned(),
            key: key.to_owned(),
            line: self.locator.line_near(key),
            problem: problem.into(),
        }
    }

    fn serde_error(&self, e: &toml::de::Error) -> ScenarioError {
        let (key, line, problem) = self.locator.serde_problem(e);
        ScenarioError::Invalid {
            origin: self.origin.to_owned(),
            key,
            line,
            problem,
        }
    }

    fn non_negative(&self, key: &str, value: f64, unit: &str) -> Result<f64, ScenarioError> {
        if value >= 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be >= 0, got {value} {unit}")))
        }
    }

    fn positive(&self, key: &str, value: f64, unit: &str) -> Result<f64, ScenarioError> {
        if value > 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be > 0, got {value} {unit}")))
        }
    }

    fn non_negative3(&self, key: &str, v: [f64; 3], unit: &str) -> Result<Vec3, ScenarioError> {
        for (i, x) in v.iter().enumerate() {
            self.non_negative(&format!("{key}[{i}]"), *x, unit)?;
        }
        Ok(Vec3::from(v))
    }

    /// A time in seconds (>= 0, at most [`MAX_TIME_S`]) as ns.
    fn time_ns(&self, key: &str, s: f64) -> Result<u64, ScenarioError> {
        if s < 0.0 {
            return Err(self.err(key, format!("must be >= 0, got {s} s")));
        }
        if s > MAX_TIME_S {
            return Err(self.err(key, format!("must be at most {MAX_TIME_S} s, got {s} s")));
        }
        Ok(seconds_to_ns_saturating(s))
    }

    /// A rate in Hz as a period in ns (>= 1 us).
    fn period_ns(&self, key: &str, rate_hz: f64) -> Result<u64, ScenarioError> {
        if !(rate_hz > 0.0 && rate_hz <= 1e6) {
            return Err(self.err(key, format!("must be in (0, 1e6] Hz, got {rate_hz} Hz")));
        }
        Ok(seconds_to_ns_saturating(1.0 / rate_hz).max(1))
    }
}

fn calibration_error_key(e: &ConfigError) -> String {
    match e {
        ConfigError::NonFinite { field, .. } => format!("robot.{field}"),
        ConfigError::RotationNotOrthonormal { .. } | ConfigError::RotationNotProper { .. } => {
            "robot.sensor_rotation".to_owned()
        }
        ConfigError::GravityOutOfRange { .. } => "robot.gravity".to_owned(),
        _ => "robot".to_owned(),
    }
}

fn profile_error_key(e: &ConfigError) -> String {
    match e {
        ConfigError::NonFinite { field, .. } => format!("manipulator.{field}"),
        ConfigError::NonPositiveLength { .. } => "manipulator.length_m".to_owned(),
        ConfigError::OffsetTooLarge { .. } => "manipulator.offset_m".to_owned(),
        ConfigError::NegativeMass { .. } => "manipulator.mass_kg".to_owned(),
        _ => "manipulator".to_owned(),
    }
}

/// The file's key for a refusal of the simulator's checks.
fn sim_error_key(e: &SimError) -> String {
    match e {
        SimError::InvalidSpec { field, .. } => match *field {
            "friction_n" => "support.friction_n",
            "tip_mass_kg" => "tip_mass.mass_kg",
            "physics_step_ns" => "physics_step_s",
            "axes.position_period_ns" => "axes.position_rate_hz",
            "sensor.period_ns" => "sensor.rate_hz",
            "contact.force_n" => "contact",
            f if f.starts_with("faults.") => "fault",
            other => other,
        }
        .to_owned(),
        SimError::ContactNotSorted { index, .. } => format!("contact[{index}].t_s"),
        SimError::FaultAxis { index, .. } => format!("fault[{index}].axis"),
        SimError::StartPose(_) | SimError::StartStaticsSingular => "axes.start".to_owned(),
        SimError::LatencyTooLong { .. } => "sensor.latency_s".to_owned(),
        _ => String::new(),
    }
}

/// The active joints that put A at `ujoint_m`.
fn joints_for_ujoint(cal: &Calibration, ujoint_m: &Vec3) -> ActiveJoints {
    joints_from_displacement(&(ujoint_m - cal.ujoint_offset_m() - cal.p_home_m()))
}

/// The geometry a script is checked against.
struct Machine {
    calibration: Calibration,
    profile: Profile,
    travel_m: [(f64, f64); 3],
}

impl Machine {
    /// Checks that `q` is inside the travel and a pose the kinematics accepts.
    fn check_pose(&self, ctx: &Ctx<'_>, key: &str, q: &ActiveJoints) -> Result<(), ScenarioError> {
        let values = joints_to_array(q);
        for ((name, value), (min, max)) in ["q1", "q2", "q3"].iter().zip(values).zip(self.travel_m)
        {
            if !(min..=max).contains(&value) {
                return Err(ctx.err(
                    key,
                    format!(
                        "{name} = {value:.6} m is outside the travel {min}..{max} m of that axis"
                    ),
                ));
            }
        }
        forward(&self.calibration, &self.profile, q)
            .map(|_| ())
            .map_err(|e| ctx.err(key, format!("the kinematics refuses this pose: {e}")))
    }

    /// Checks the path from `from` to `to`, each axis on its own trapezoid,
    /// and follows the slide of the rod along it. The kinematics checks the
    /// path at [`PATH_CHECK_POINTS`] instants at least, [`PATH_CHECK_INTERVAL_S`]
    /// apart at most (up to [`PATH_CHECK_MAX_POINTS`]); the conditions that hold
    /// at single points (the U-joint at the support or within the rod offset of
    /// it, a vertical rod) are checked on the chords between those instants too.
    fn check_path(
        &self,
        ctx: &Ctx<'_>,
        key: &str,
        from: &ActiveJoints,
        to: &ActiveJoints,
        limits: (f64, f64),
        tracker: &mut SlideTracker,
    ) -> Result<(), ScenarioError> {
        let (max_speed_mps, max_accel_mps2) = limits;
        let start = from.displacement_m();
        let delta = to.displacement_m() - start;
        let total_s = move_time_s(from, to, max_speed_mps, max_accel_mps2);
        let points = (total_s / PATH_CHECK_INTERVAL_S).ceil().clamp(
            f64::from(PATH_CHECK_POINTS),
            f64::from(PATH_CHECK_MAX_POINTS),
        ) as u32;
        let b = self.calibration.support_m();
        let a_at_zero = self.calibration.p_home_m() + self.calibration.ujoint_offset_m();
        let min_distance_m = self.profile.offset_m().abs() + MIN_DISTANCE_M;
        let mut previous_a = a_at_zero + start;
        for k in 1..=points {
            let t_s = total_s * f64::from(k) / f64::from(points);
            let progress = |d: f64| axis_progress_m(d, max_speed_mps, max_accel_mps2, t_s);
            let p = start + Vec3::new(progress(delta.x), progress(delta.y), progress(delta.z));
            let a = a_at_zero + p;
            let percent = t_s / total_s * 100.0;
            let distance_m = distance_to_segment(&b, &previous_a, &a);
            if distance_m <= min_distance_m {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position takes the U-joint {distance_m:.2e} m \
                         from the support (around {percent:.0} % of the move's time), a pose the \
                         kinematics refuses"
                    ),
                ));
            }
            let flat = |v: Vec3| Vec3::new(v.x, 0.0, v.z);
            let horizontal_m = distance_to_segment(&flat(b), &flat(previous_a), &flat(a));
            if horizontal_m <= VERTICAL_CLEARANCE_M {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position puts the rod vertical (the U-joint \
                         passes {horizontal_m:.2e} m from the vertical through the support, \
                         around {percent:.0} % of the move's time), a pose the kinematics refuses"
                    ),
                ));
            }
            previous_a = a;
            let q = joints_from_displacement(&p);
            if k < points
                && let Err(e) = forward(&self.calibration, &self.profile, &q)
            {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position crosses a pose the kinematics \
                         refuses ({percent:.0} % of the move's time): {e}"
                    ),
                ));
            }
            tracker.update(&q);
        }
        Ok(())
    }
}

/// Distance from `p` to the segment from `a` to `b`.
fn distance_to_segment(p: &Vec3, a: &Vec3, b: &Vec3) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).norm()
}

fn build(ctx: &Ctx<'_>, file: FileToml) -> Result<Scenario, ScenarioError> {
    if file.name.trim().is_empty() {
        return Err(ctx.err("name", "must not be empty"));
    }

    // The true geometry and manipulator.
    let r = &file.robot;
    let [r0, r1, r2] = r.sensor_rotation;
    let [[m00, m01, m02], [m10, m11, m12], [m20, m21, m22]] = [r0, r1, r2];
    let rotation = Mat3::new(m00, m01, m02, m10, m11, m12, m20, m21, m22);
    let calibration = Calibration::new(&CalibrationSpec {
        p_home_m: Vec3::from(r.p_home),
        ujoint_offset_m: Vec3::from(r.ujoint_offset),
        sensor_offset_m: Vec3::from(r.sensor_offset),
        sensor_rotation: rotation,
        support_m: Vec3::from(r.support),
        gravity_mps2: Vec3::from(r.gravity),
    })
    .map_err(|e| ctx.err(&calibration_error_key(&e), e.to_string()))?;
    let m = &file.manipulator;
    let profile = Profile::new(&ProfileSpec {
        length_m: m.length_m,
        offset_m: m.offset_m,
        mass_kg: m.mass_kg,
        com_m: m.com_m,
    })
    .map_err(|e| ctx.err(&profile_error_key(&e), e.to_string()))?;
    if m.name.as_deref().is_some_and(|n| n.trim().is_empty()) {
        return Err(ctx.err("manipulator.name", "must not be empty when given"));
    }
    let friction_n = match &file.support {
        Some(s) => ctx.non_negative("support.friction_n", s.friction_n, "N")?,
        None => 0.0,
    };
    let tip_mass_kg = match &file.tip_mass {
        Some(t) => ctx.non_negative("tip_mass.mass_kg", t.mass_kg, "kg")?,
        None => 0.0,
    };
    let physics_step_s = file.physics_step_s.unwrap_or(DEFAULT_PHYSICS_STEP_S);
    if !(1e-6..=0.01).contains(&physics_step_s) {
        return Err(ctx.err(
            "physics_step_s",
            format!("must be in 1e-6..=0.01 s, got {physics_step_s} s"),
        ));
    }
    let physics_step_ns = seconds_to_ns_saturating(physics_step_s).max(1);

    // Axes.
    let axes = file.axes.unwrap_or_default();
    let max_speed_mps = ctx.positive(
        "axes.max_speed_mps",
        axes.max_speed_mps.unwrap_or(DEFAULT_MAX_SPEED_MPS),
        "m/s",
    )?;
    let max_accel_mps2 = ctx.positive(
        "axes.max_accel_mps2",
        axes.max_accel_mps2.unwrap_or(DEFAULT_MAX_ACCEL_MPS2),
        "m/s^2",
    )?;
    let lead_m_per_turn = ctx.positive(
        "axes.lead_m_per_turn",
        axes.lead_m_per_turn.unwrap_or(DEFAULT_LEAD_M_PER_TURN),
        "m",
    )?;
    let counts_per_turn = axes.counts_per_turn.unwrap_or(DEFAULT_COUNTS_PER_TURN);
    if counts_per_turn == 0 {
        return Err(ctx.err("axes.counts_per_turn", "must be >= 1, got 0"));
    }
    let position_period_ns = ctx.period_ns(
        "axes.position_rate_hz",
        axes.position_rate_hz.unwrap_or(DEFAULT_POSITION_RATE_HZ),
    )?;
    let mut travel_m = [(0.0, 0.0); 3];
    for (i, (slot, [min, max])) in travel_m
        .iter_mut()
        .zip(axes.travel_m.unwrap_or(DEFAULT_TRAVEL_M))
        .enumerate()
    {
        if min >= max {
            return Err(ctx.err(
                &format!("axes.travel_m[{i}]"),
                format!("min must be below max, got [{min}, {max}] m"),
            ));
        }
        *slot = (min, max);
    }
    let machine = Machine {
        calibration,
        profile,
        travel_m,
    };

    // Sensor.
    let sensor = file.sensor.unwrap_or_default();
    let period_ns = ctx.period_ns(
        "sensor.rate_hz",
        sensor.rate_hz.unwrap_or(DEFAULT_SENSOR_RATE_HZ),
    )?;
    let latency_ns = ctx.time_ns(
        "sensor.latency_s",
        sensor.latency_s.unwrap_or(DEFAULT_SENSOR_LATENCY_S),
    )?;
    let sensor_spec = SensorSpec {
        period_ns,
        latency_ns,
        noise_n: ctx.non_negative3(
            "sensor.noise_n",
            sensor.noise_n.unwrap_or(DEFAULT_NOISE_N),
            "N",
        )?,
        noise_nm: ctx.non_negative3(
            "sensor.noise_nm",
            sensor.noise_nm.unwrap_or(DEFAULT_NOISE_NM),
            "N m",
        )?,
        bias_n: Vec3::from(sensor.bias_n.unwrap_or_default()),
        bias_nm: Vec3::from(sensor.bias_nm.unwrap_or_default()),
        drift_n_per_s: Vec3::from(sensor.drift_n_per_s.unwrap_or_default()),
        has_tare: sensor.has_tare.unwrap_or(true),
    };

    // Motion.
    let mut targets: Vec<(String, ActiveJoints, u64)> = Vec::new();
    for (i, step) in file.motion.iter().enumerate() {
        let key = format!("motion[{i}]");
        let (target_key, q) = resolve_step(ctx, &machine, &key, step)?;
        machine.check_pose(ctx, &target_key, &q)?;
        let hold_ns = ctx.time_ns(&format!("{key}.hold_s"), step.hold_s.unwrap_or(0.0))?;
        targets.push((key, q, hold_ns));
    }
    if let Some(random) = &file.random_motion {
        targets.extend(random_steps(ctx, &machine, random, file.seed)?);
    }
    if targets.is_empty() {
        return Err(ctx.err(
            "motion",
            "the script has no steps: give at least one [[motion]] or a [random_motion]",
        ));
    }
    let start = match axes.start {
        Some(q) => {
            let q = joints_from_array(q);
            machine.check_pose(ctx, "axes.start", &q)?;
            q
        }
        None => targets.first().map(|t| t.1).unwrap_or_default(),
    };
    let mut steps = Vec::with_capacity(targets.len());
    let mut from = start;
    let mut tracker = SlideTracker::new(&calibration);
    tracker.update(&start);
    for (key, target, hold_ns) in targets {
        machine.check_path(
            ctx,
            &key,
            &from,
            &target,
            (max_speed_mps, max_accel_mps2),
            &mut tracker,
        )?;
        steps.push(MotionStep {
            key,
            target,
            hold_ns,
            planned_slide_sign: tracker.sign(),
        });
        from = target;
    }

    // Contact.
    let mut contact = Vec::with_capacity(file.contact.len());
    let mut last_t: Option<(f64, usize)> = None;
    for (i, key) in file.contact.iter().enumerate() {
        let t_key = format!("contact[{i}].t_s");
        let t_ns = ctx.time_ns(&t_key, key.t_s)?;
        if let Some((t, j)) = last_t
            && key.t_s < t
        {
            return Err(ctx.err(
                &t_key,
                format!(
                    "contact keyframes must be sorted by time: {} s is before \
                     contact[{j}].t_s = {t} s",
                    key.t_s
                ),
            ));
        }
        last_t = Some((key.t_s, i));
        contact.push(ContactKey {
            t_ns,
            force_n: Vec3::from(key.force_n),
        });
    }

    // Faults.
    let mut faults = Vec::with_capacity(file.fault.len());
    for (i, f) in file.fault.iter().enumerate() {
        faults.push(resolve_fault(ctx, &format!("fault[{i}]"), f)?);
    }

    let spec = SimSpec {
        seed: file.seed,
        calibration,
        profile,
        friction_n,
        axes: AxesSpec {
            max_speed_mps,
            max_accel_mps2,
            lead_m_per_turn,
            counts_per_turn,
            position_period_ns,
            travel_m,
            start,
        },
        sensor: sensor_spec,
        contact,
        tip_mass_kg,
        faults,
        physics_step_ns,
    };
    // The simulator's own checks (e.g. more samples in flight than it holds,
    // times equal once in ns), so that it never refuses a loaded file later
    // with an error that cannot name the file.
    crate::sim::validate(&spec).map_err(|e| ctx.err(&sim_error_key(&e), e.to_string()))?;
    Ok(Scenario {
        name: file.name,
        description: file.description.unwrap_or_default(),
        origin: ctx.origin.to_owned(),
        manipulator_name: file.manipulator.name,
        spec,
        script: MotionScript {
            start,
            steps,
            calibration,
            max_speed_mps,
            max_accel_mps2,
        },
    })
}

/// The target of one `[[motion]]` step as active joints, with the key of the
/// target that the file gave.
fn resolve_step(
    ctx: &Ctx<'_>,
    machine: &Machine,
    key: &str,
    step: &MotionToml,
) -> Result<(String, ActiveJoints), ScenarioError> {
    let given: Vec<&str> = [
        ("joints", step.joints.is_some()),
        ("ujoint", step.ujoint.is_some()),
        ("tip", step.tip.is_some()),
        ("rod_dir", step.rod_dir.is_some()),
    ]
    .iter()
    .filter(|(_, present)| *present)
    .map(|(name, _)| *name)
    .collect();
    match given.as_slice() {
        [] => {
            return Err(ctx.err(
                key,
                "no target: give exactly one of joints, ujoint, tip, rod_dir (with \
                 support_distance_m)",
            ));
        }
        [_] => {}
        several => {
            return Err(ctx.err(
                key,
                format!(
                    "{} targets ({}): give exactly one of joints, ujoint, tip, rod_dir",
                    several.len(),
                    several.join(", ")
                ),
            ));
        }
    }
    if step.support_distance_m.is_some() && step.rod_dir.is_none() {
        return Err(ctx.err(
            &format!("{key}.support_distance_m"),
            "only allowed with rod_dir",
        ));
    }
    let cal = &machine.calibration;
    if let Some(q) = step.joints {
        return Ok((format!("{key}.joints"), joints_from_array(q)));
    }
    if let Some(a) = step.ujoint {
        return Ok((
            format!("{key}.ujoint"),
            joints_for_ujoint(cal, &Vec3::from(a)),
        ));
    }
    if let Some(d) = step.tip {
        let tip_key = format!("{key}.tip");
        let q = inverse(cal, &machine.profile, &Vec3::from(d)).map_err(|e| {
            ctx.err(
                &tip_key,
                format!("the kinematics cannot put the tip there: {e}"),
            )
        })?;
        return Ok((tip_key, q));
    }
    let dir_key = format!("{key}.rod_dir");
    let u = Vec3::from(step.rod_dir.unwrap_or_default());
    let norm = u.norm();
    if norm < 1e-9 {
        return Err(ctx.err(&dir_key, "must not be the zero vector"));
    }
    let Some(a) = step.support_distance_m else {
        return Err(ctx.err(
            &format!("{key}.support_distance_m"),
            "missing key (rod_dir needs it)",
        ));
    };
    ctx.positive(&format!("{key}.support_distance_m"), a, "m")?;
    let ujoint_m = cal.support_m() - u * (a / norm);
    Ok((dir_key, joints_for_ujoint(cal, &ujoint_m)))
}

/// Stream of the random motion: the seed mixed with a constant, so that it
/// differs from the simulator's noise streams made from the same seed.
const RANDOM_MOTION_STREAM: u64 = 0x6d6f_7469_6f6e_0001;

/// The `[random_motion]` steps: tip targets with the rod within
/// `max_angle_deg` of +X0 (uniform over the cap) and the tip `beyond_m` past
/// the support.
fn random_steps(
    ctx: &Ctx<'_>,
    machine: &Machine,
    random: &raw::RandomMotionToml,
    seed: u64,
) -> Result<Vec<(String, ActiveJoints, u64)>, ScenarioError> {
    if random.count == 0 || random.count > 10_000 {
        return Err(ctx.err(
            "random_motion.count",
            format!("must be in 1..=10000, got {}", random.count),
        ));
    }
    if !(0.0..=80.0).contains(&random.max_angle_deg) {
        return Err(ctx.err(
            "random_motion.max_angle_deg",
            format!("must be in 0..=80 deg, got {}", random.max_angle_deg),
        ));
    }
    let [min_m, max_m] = random.beyond_m;
    let length_m = machine.profile.length_m();
    if !(min_m > 0.0 && min_m <= max_m && max_m < length_m) {
        return Err(ctx.err(
            "random_motion.beyond_m",
            format!("must satisfy 0 < min <= max < L = {length_m} m, got [{min_m}, {max_m}] m"),
        ));
    }
    let hold_ns = ctx.time_ns("random_motion.hold_s", random.hold_s)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ RANDOM_MOTION_STREAM);
    let cos_max = random.max_angle_deg.to_radians().cos();
    let mut steps = Vec::new();
    for i in 0..random.count {
        let key = format!("random_motion[{i}]");
        // Uniform over the spherical cap: cos(theta) uniform in [cos_max, 1].
        let cos_theta = 1.0 - rng.random::<f64>() * (1.0 - cos_max);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = rng.random::<f64>() * std::f64::consts::TAU;
        let beyond = min_m + rng.random::<f64>() * (max_m - min_m);
        let u = Vec3::new(cos_theta, sin_theta * phi.cos(), sin_theta * phi.sin());
        let tip_m = machine.calibration.support_m() + u * beyond;
        let q =
            inverse(&machine.calibration, &machine.profile, &tip_m).map_err(|e: PoseError| {
                ctx.err(
                    &key,
                    format!("the kinematics cannot reach tip {tip_m:?}: {e}"),
                )
            })?;
        machine.check_pose(ctx, &key, &q)?;
        steps.push((key, q, hold_ns));
    }
    Ok(steps)
}

/// Checks that a `[[fault]]` gives exactly the keys its kind takes.
fn resolve_fault(ctx: &Ctx<'_>, key: &str, f: &FaultToml) -> Result<Fault, ScenarioError> {
    let present = [
        ("from_s", f.from_s.is_some()),
        ("until_s", f.until_s.is_some()),
        ("at_s", f.at_s.is_some()),
        ("axis", f.axis.is_some()),
        ("jump_m", f.jump_m.is_some()),
        ("code", f.code.is_some()),
    ];
    let (kind_name, takes): (&str, &[&str]) = match f.kind {
        FaultKind::SensorSilent => ("sensor_silent", &["from_s", "until_s"]),
        FaultKind::NanSample => ("nan_sample", &["at_s"]),
        FaultKind::EncoderJump => ("encoder_jump", &["at_s", "axis", "jump_m"]),
        FaultKind::DriveFault => ("drive_fault", &["at_s", "code"]),
    };
    if let Some((name, _)) = present
        .iter()
        .find(|(name, is)| *is && !takes.contains(name))
    {
        return Err(ctx.err(
            &format!("{key}.{name}"),
            format!(
                "not a key of a {kind_name} fault (it takes: {})",
                takes.join(", ")
            ),
        ));
    }
    let missing = |name: &str| ctx.err(&format!("{key}.{name}"), "missing key");
    let at_ns = |ctx: &Ctx<'_>| -> Result<u64, ScenarioError> {
        let at_s = f.at_s.ok_or_else(|| missing("at_s"))?;
        ctx.time_ns(&format!("{key}.at_s"), at_s)
    };
    Ok(match f.kind {
        FaultKind::SensorSilent => {
            let from_s = f.from_s.ok_or_else(|| missing("from_s"))?;
            let from_ns = ctx.time_ns(&format!("{key}.from_s"), from_s)?;
            let until_ns = match f.until_s {
                None => None,
                Some(until_s) => {
                    let until_key = format!("{key}.until_s");
                    let until_ns = ctx.time_ns(&until_key, until_s)?;
                    if until_s <= from_s {
                        return Err(ctx.err(
                            &until_key,
                            format!("must be after from_s = {from_s} s, got {until_s} s"),
                        ));
                    }
                    Some(until_ns)
                }
            };
            Fault::SensorSilent { from_ns, until_ns }
        }
        FaultKind::NanSample => Fault::NanSample { at_ns: at_ns(ctx)? },
        FaultKind::EncoderJump => {
            let at_ns = at_ns(ctx)?;
            let axis = match f.axis.ok_or_else(|| missing("axis"))? {
                AxisName::Q1 => 0,
                AxisName::Q2 => 1,
                AxisName::Q3 => 2,
            };
            let jump_m = f.jump_m.ok_or_else(|| missing("jump_m"))?;
            if jump_m == 0.0 || jump_m.abs() > 1.0 {
                return Err(ctx.err(
                    &format!("{key}.jump_m"),
                    format!("must be non-zero and at most 1 m in size, got {jump_m} m"),
                ));
            }
            Fault::EncoderJump {
                at_ns,
                axis,
                jump_m,
            }
        }
        FaultKind::DriveFault => {
            let at_ns = at_ns(ctx)?;
            let code = f.code.ok_or_else(|| missing("code"))?;
            Fault::DriveFault { at_ns, code }
        }
    })
}
