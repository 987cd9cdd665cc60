//! Scenario files: a simulated robot (true geometry, manipulator, support,
//! axes, sensor, tip contact, tissues, faults) and the motion script to run on it, as a
//! TOML file under version control (the format is described in
//! `scenarios/README.md`).
//!
//! [`load`] and [`parse`] check every value and build a [`Scenario`]
//! (`sar_sim::scenario`'s typed data): the simulator's `SimSpec` and a
//! [`MotionScript`] for `sar_sim::runner`. A bad file is a
//! [`ConfigError`] whose message names the file, the key (dotted, e.g.
//! `motion[3].hold_s`) and what is wrong; TOML syntax errors keep toml's line
//! and column.

mod contact;
mod ctx;
mod devices;
mod fault;
mod plant;
mod raw;
mod robot;
mod script;
mod support;

pub use sar_sim::scenario::{MotionScript, MotionStep, Scenario};

use crate::ConfigError;
use crate::toml_file::{self, Ctx};
use raw::FileToml;
use sar_sim::scenario::seconds_to_ns_saturating;
use sar_sim::{SimError, SimSpec};
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
/// Default bandwidth (natural frequency) of an axis's servo, Hz, once any
/// servo key is given (issue 26; opt-in until the estimator compensates).
pub const DEFAULT_SERVO_BANDWIDTH_HZ: f64 = 30.0;
/// Default damping ratio of an axis's servo, once any servo key is given.
pub const DEFAULT_SERVO_DAMPING: f64 = 0.7;
/// Default acceleration limit of an axis's servo, m/s^2, once any servo key
/// is given.
pub const DEFAULT_SERVO_MAX_ACCEL_MPS2: f64 = 5.0;
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

/// Reads and checks a scenario file; errors name `path`.
pub fn load(path: &Path) -> Result<Scenario, ConfigError> {
    let (text, origin) = toml_file::read(path)?;
    parse(&text, &origin)
}

/// Checks a scenario given as text; `origin` names it in errors (a path, or
/// anything that tells the reader where the text came from).
pub fn parse(text: &str, origin: &str) -> Result<Scenario, ConfigError> {
    let (ctx, file): (Ctx<'_>, FileToml) = toml_file::parse(text, origin)?;
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
fn build(ctx: &Ctx<'_>, file: FileToml) -> Result<Scenario, ConfigError> {
    if file.name.trim().is_empty() {
        return Err(ctx.err("name", "must not be empty"));
    }
    let calibration = robot::calibration(ctx, &file.robot)?;
    let profile = robot::profile(ctx, &file.manipulator)?;
    let (friction_n, tip_mass_kg) = loads(ctx, &file)?;
    let physics_step_ns = physics_step_ns(ctx, file.physics_step_s)?;
    let plant = plant::plant(ctx, &file, &profile)?;
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
    let faults = fault::faults(ctx, &file.fault, axes.count_m())?;
    let support_shifts = support::support_shifts(ctx, &file.support_shift)?;
    let spec = SimSpec {
        seed: file.seed,
        calibration,
        profile,
        friction_n,
        axes: axes.spec(start),
        sensor,
        contact,
        tissue,
        tip_mass_kg,
        faults,
        physics_step_ns,
        plant,
        support_shifts,
    };
    // The simulator's own checks (e.g. more samples in flight than it holds,
    // times equal once in ns), so that it never refuses a loaded file later
    // with an error that cannot name the file.
    sar_sim::validate(&spec).map_err(|e| ctx.err(&sim_error_key(&e), e.to_string()))?;
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

/// The support's friction, N, and the tip's mass, kg (each 0 when its table
/// is not given).
fn loads(ctx: &Ctx<'_>, file: &FileToml) -> Result<(f64, f64), ConfigError> {
    let friction_n = match &file.support {
        Some(s) => ctx.non_negative("support.friction_n", s.friction_n, "N")?,
        None => 0.0,
    };
    let tip_mass_kg = match &file.tip_mass {
        Some(t) => ctx.non_negative("tip_mass.mass_kg", t.mass_kg, "kg")?,
        None => 0.0,
    };
    Ok((friction_n, tip_mass_kg))
}

/// `physics_step_s` (default [`DEFAULT_PHYSICS_STEP_S`]) as ns.
fn physics_step_ns(ctx: &Ctx<'_>, physics_step_s: Option<f64>) -> Result<u64, ConfigError> {
    let physics_step_s = physics_step_s.unwrap_or(DEFAULT_PHYSICS_STEP_S);
    if !(1e-6..=0.01).contains(&physics_step_s) {
        return Err(ctx.err(
            "physics_step_s",
            format!("must be in 1e-6..=0.01 s, got {physics_step_s} s"),
        ));
    }
    Ok(seconds_to_ns_saturating(physics_step_s).max(1))
}
