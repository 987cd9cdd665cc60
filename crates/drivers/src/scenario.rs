//! Scenario files: a simulated robot (true geometry, manipulator, support,
//! axes, sensor, tip contact, tissues, faults) and the motion script to run on it, as a
//! TOML file under version control (the format is described in
//! `scenarios/README.md`).
//!
//! [`load`] and [`parse`] check every value and build a [`Scenario`]: the
//! simulator's [`SimSpec`] and a [`MotionScript`] for [`crate::runner`]. A bad
//! file is a [`ScenarioError`] whose message names the file, the key (dotted,
//! e.g. `motion[3].hold_s`) and what is wrong; TOML syntax errors keep toml's
//! line and column.

mod contact;
mod ctx;
mod devices;
mod fault;
pub mod locate;
mod raw;
mod robot;
mod script;

use crate::motion::{SlideSign, move_time_s};
use crate::sim::{AxesSpec, SimError, SimSpec};
use ctx::{Ctx, seconds_to_ns_saturating};
use locate::Locator;
use raw::FileToml;
use sar_kinematics::{ActiveJoints, Calibration};
use script::{Machine, MotionFile};
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
/// Default measuring range of the force channels (x, y, z), N: the nominal
/// capacity of the OnRobot HEX-E QC, Fxy 200 N and Fz 200 N (OnRobot, HEX-E
/// QC datasheet, "Nominal capacity"; its noise-free resolution, 0.2 / 0.2 /
/// 0.8 N, is [`DEFAULT_NOISE_N`]).
pub const DEFAULT_RANGE_N: [f64; 3] = [200.0, 200.0, 200.0];
/// Default measuring range of the torque channels (x, y, z), N m: the HEX-E
/// QC's nominal capacity, Txy 10 N m and Tz 13 N m (same datasheet).
pub const DEFAULT_RANGE_NM: [f64; 3] = [10.0, 10.0, 13.0];
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
            f if f.starts_with("tissue.") => "tissue",
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

/// Checks every table of the file, in file order (so that the first problem
/// in the file is the one reported), and builds the scenario.
fn build(ctx: &Ctx<'_>, file: FileToml) -> Result<Scenario, ScenarioError> {
    if file.name.trim().is_empty() {
        return Err(ctx.err("name", "must not be empty"));
    }
    let calibration = robot::calibration(ctx, &file.robot)?;
    let profile = robot::profile(ctx, &file.manipulator)?;
    let friction_n = match &file.support {
        Some(s) => ctx.non_negative("support.friction_n", s.friction_n, "N")?,
        None => 0.0,
    };
    let tip_mass_kg = match &file.tip_mass {
        Some(t) => ctx.non_negative("tip_mass.mass_kg", t.mass_kg, "kg")?,
        None => 0.0,
    };
    let physics_step_ns = physics_step_ns(ctx, file.physics_step_s)?;
    let axes = devices::axes(ctx, &file.axes.unwrap_or_default())?;
    let machine = Machine {
        calibration,
        profile,
        travel_m: axes.travel_m,
    };
    let sensor = devices::sensor(ctx, &file.sensor.unwrap_or_default())?;
    let (start, steps) = script::steps(
        ctx,
        &machine,
        &MotionFile {
            motion: &file.motion,
            random: file.random_motion.as_ref(),
            seed: file.seed,
            start: axes.start,
            limits: (axes.max_speed_mps, axes.max_accel_mps2),
        },
    )?;
    let contact = contact::keys(ctx, &file.contact)?;
    let tissue = contact::tissues(ctx, &file.tissue)?;
    let faults = fault::faults(
        ctx,
        &file.fault,
        axes.lead_m_per_turn / f64::from(axes.counts_per_turn),
    )?;
    let spec = SimSpec {
        seed: file.seed,
        calibration,
        profile,
        friction_n,
        axes: AxesSpec {
            max_speed_mps: axes.max_speed_mps,
            max_accel_mps2: axes.max_accel_mps2,
            lead_m_per_turn: axes.lead_m_per_turn,
            counts_per_turn: axes.counts_per_turn,
            position_period_ns: axes.position_period_ns,
            travel_m: axes.travel_m,
            start,
        },
        sensor,
        contact,
        tissue,
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
            max_speed_mps: axes.max_speed_mps,
            max_accel_mps2: axes.max_accel_mps2,
        },
    })
}

/// `physics_step_s` (default [`DEFAULT_PHYSICS_STEP_S`]) as ns.
fn physics_step_ns(ctx: &Ctx<'_>, physics_step_s: Option<f64>) -> Result<u64, ScenarioError> {
    let physics_step_s = physics_step_s.unwrap_or(DEFAULT_PHYSICS_STEP_S);
    if !(1e-6..=0.01).contains(&physics_step_s) {
        return Err(ctx.err(
            "physics_step_s",
            format!("must be in 1e-6..=0.01 s, got {physics_step_s} s"),
        ));
    }
    Ok(seconds_to_ns_saturating(physics_step_s).max(1))
}
