//! The daemon's configuration file (TOML, INTERFACES.md 2): parsed with serde,
//! unknown keys refused, then checked into the estimator's validated types.
//!
//! Every key is declared once, in its section's table in [`keys`](mod@keys)
//! (`crates/config/src/keys/`): its type, its default, its range, a one-line
//! doc and the domain field it sets. The README's table of the keys and the
//! built-in configuration, [`DEFAULT_TOML`], are made from the tables
//! ([`docs`]; a test compares them with the files). Only `[geometry]`,
//! `[manipulator]` and `[sensor]` are required; every other section has its
//! defaults.
//!
//! A file is checked in this order ([`parse`]): its syntax and its keys
//! (unknown keys, types, arrays of their exact length, missing required
//! keys); every key's declared range, in the file's order (issue 25: a
//! plausible range for every number, so that a unit mistake is refused
//! with the likely unit, "got 35 (a value in cm? 35 cm is 0.35 m)"); the
//! relations between keys (`relations`: a centre of mass on the rod, a force
//! limit within the sensor's range, ...); the domain types' own checks
//! (warn below stop, a stable force law, ...); the support's reach from the
//! travel; what the drivers would refuse at start ([`devices`]).
//!
//! Every error names the file, the dotted key, the line where the file has it,
//! and the problem ([`ConfigError`]), on one line of at most about 700
//! characters (a long value, key or path is cut). A file is read only if it
//! is a regular file of at most [`MAX_FILE_BYTES`] (1 MB; a FIFO or a device
//! is refused at once, never waited on).
//!
//! The simulator's scenario files (`scenarios/`) are read here too
//! ([`scenario`]: TOML -> `sar_sim::scenario::Scenario`), with the same
//! machinery and the same error type; their keys are the scenario's own.

mod decl;
pub mod devices;
pub mod docs;
mod exact;
pub mod keys;
mod locate;
mod relations;
pub mod scenario;
mod toml_file;

pub use decl::{Applies, Bounds, KeyDecl, KeyDefault, Kind, Range, SectionDecl};
pub use keys::identify::IdentifySettings;
pub use keys::ros2::{MAX_DOMAIN_ID, Ros2Rates, Ros2Settings, TopicRate};
pub use keys::{SECTIONS, keys};
pub use toml_file::{ConfigError, MAX_FILE_BYTES};

use sar_estimator::cycle::EstimatorConfig;
use sar_estimator::tip_force::TipForceConfig;
use sar_loop::runloop::LoopConfig;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use toml_file::Ctx;

/// The configuration of the built-in demo (`sard --sim` without `--config`):
/// the example robot of INTERFACES.md 2, every other key written out with
/// its default ([`docs::default_toml`] makes it; a test compares).
pub const DEFAULT_TOML: &str = include_str!("default_config.toml");

// ---------------------------------------------------------------------------
// The checked configuration.

/// The axes as the daemon plans moves on them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxesConfig {
    /// (min, max) of q1, q2, q3, m.
    pub travel_m: [(f64, f64); 3],
    /// The speed of the moves the daemon plans, m/s (> 0, at most the
    /// plausibility's `max_joint_speed_mps`).
    pub max_speed_mps: f64,
    /// The acceleration of the moves the daemon plans, m/s^2 (> 0, <= 10).
    pub max_accel_mps2: f64,
    /// The accepted distance of each axis from the commanded trajectory, m
    /// (beyond it: a Fault, `FollowingError`).
    pub following_tolerance_m: f64,
    /// The speed of the moves in `Retreat` (only motions that reduce the
    /// tip force), m/s (> 0, at most `max_speed_mps`).
    pub retreat_speed_mps: f64,
    /// The drives as the loop models them (issue 26): their position
    /// loop (`servo_bandwidth_hz`, 0: ideal; `servo_damping`), their quick
    /// stop (`[drivers.axes] quick_stop_decel_mps2`, every kind) and a
    /// guarded move's brake (`brake_decel_mps2`).
    pub motion: sar_loop::motion::MotionConfig,
}

/// The force/torque sensor's driver.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum SensorDriver {
    /// The simulator.
    Sim,
    /// OnRobot HEX / ATI Net F/T over UDP (RDT).
    Rdt {
        /// The sensor's address.
        address: SocketAddr,
        /// Counts per newton.
        counts_per_n: f64,
        /// Counts per newton metre.
        counts_per_nm: f64,
    },
}

/// The axis drives' driver.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum AxesDriver {
    /// The simulator.
    Sim,
    /// CiA 402 drives over CANopen (the daemon cannot run them yet).
    Canopen {
        /// The CAN interface, e.g. `can0`.
        interface: String,
        /// Node ids of q1, q2, q3 (1..=127, distinct).
        node_ids: [u8; 3],
        /// Carriage travel per motor turn, m.
        lead_m: f64,
        /// Encoder counts per motor turn.
        counts_per_turn: u32,
        /// The drives' own quick stop deceleration (CiA 402 0x6085), m/s^2:
        /// at least `[axes] max_accel_mps2`, at most 10 (default 1).
        quick_stop_decel_mps2: f64,
        /// The drives' own max torque (0x6072), per mille of the motor's
        /// rated torque, 1..=3000 (default 1000).
        max_torque_permille: u16,
    },
}

/// Default of `[drivers.axes] quick_stop_decel_mps2`, m/s^2 (every kind).
pub const DEFAULT_QUICK_STOP_DECEL_MPS2: f64 = 2.0;

/// Default of `[drivers.axes] max_torque_permille`.
pub const DEFAULT_MAX_TORQUE_PERMILLE: u16 = 1000;

/// A checked configuration.
#[derive(Debug, Clone)]
pub struct Config {
    /// Where it came from.
    pub origin: String,
    /// The manipulator's name.
    pub manipulator_name: String,
    /// Everything the per-cycle step needs.
    pub estimator: EstimatorConfig,
    /// The loop.
    pub loop_: LoopConfig,
    /// The axes.
    pub axes: AxesConfig,
    /// The sensor's driver.
    pub sensor_driver: SensorDriver,
    /// The axes' driver.
    pub axes_driver: AxesDriver,
    /// The recording (`[record]`).
    pub record: RecordSettings,
    /// Force control (`[force_control]`), checked for stability.
    pub force_control: sar_estimator::force_control::ForceControlConfig,
    /// Whether `[manipulator] inertia_perp_kgm2` was given (measured, e.g. by
    /// `sarctl identify --dynamic`); false: the estimator uses the slender
    /// rod's m L^2 / 12, a stated default, not a measurement.
    pub inertia_measured: bool,
    /// The limits of `sarctl identify --dynamic`'s excitation (`[identify]`).
    pub identify: IdentifySettings,
    /// The ROS 2 bridge's settings (`[ros2]`; `sar-ros2` reads them, `sard`
    /// only checks them).
    pub ros2: Ros2Settings,
    /// Every key as the file gives it (its default where absent), each
    /// within its declared range, every check above passed: the typed value
    /// of each key, by section (`file.guard.stop_total_n`), for what the
    /// domain types above do not take.
    pub file: keys::File,
}

/// The recording's settings (`[record]`).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSettings {
    /// Record from the daemon's start.
    pub enabled: bool,
    /// The directory of the files.
    pub directory: PathBuf,
    /// When to start a new file.
    pub rotation: Rotation,
    /// Messages the queue holds.
    pub queue_capacity: usize,
    /// The 3D scene in each recording file, at most one per this much log
    /// time, ns (`[record] scene_hz`; `None`: none). The recording draws it
    /// from the rest of the configuration.
    pub scene_period_ns: Option<u64>,
    /// A snapshot of the loop's decision state every this much time, ns
    /// (`[record] snapshot_s`); one also starts every recording and every
    /// file of a rotation.
    pub snapshot_period_ns: u64,
    /// The configuration's text and where it came from, written into every
    /// recording (`sar_config` metadata) so that it replays without one
    /// (`None`: not written).
    pub config_source: Option<std::sync::Arc<ConfigSource>>,
    /// What a recording holds (`[record] mode`).
    pub mode: RecordMode,
    /// How the devices make floats of counts (the lean mode stores counts
    /// where they give back the floats bit for bit): the configured RDT
    /// sensor's and CANopen drives'; `sard` sets the simulator's encoders.
    pub scales: DeviceScales,
}

/// How the devices' drivers make floats of counts; 0: not known (floats
/// stored as they are).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeviceScales {
    /// force = counts / this, N (the RDT driver's `counts_per_n`).
    pub force_counts_per_n: f64,
    /// torque = counts / this, N m (`counts_per_nm`).
    pub torque_counts_per_nm: f64,
    /// position = counts * this, m (the encoders' `lead_m /
    /// counts_per_turn`).
    pub joint_m_per_count: f64,
}

impl DeviceScales {
    /// The scales of the configured drivers (the simulator's: 0).
    pub fn of_drivers(sensor: &SensorDriver, axes: &AxesDriver) -> Self {
        let mut s = Self::default();
        if let SensorDriver::Rdt {
            counts_per_n,
            counts_per_nm,
            ..
        } = sensor
        {
            s.force_counts_per_n = *counts_per_n;
            s.torque_counts_per_nm = *counts_per_nm;
        }
        if let AxesDriver::Canopen {
            lead_m,
            counts_per_turn,
            ..
        } = axes
        {
            s.joint_m_per_count = lead_m / f64::from(*counts_per_turn);
        }
        s
    }
}

/// What a recording holds (`[record] mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RecordMode {
    /// `"full"`: every topic of INTERFACES.md 1, outputs included.
    #[default]
    Full,
    /// `"inputs"`: the lean mode, what replay needs (the cycles' inputs
    /// in `/sar/cycle/batch`, the snapshots, the guard events, the
    /// recorder's drops, the configuration); `sarctl replay --output`
    /// makes the full recording of it.
    Inputs,
}

impl RecordMode {
    /// Its name in the configuration.
    pub const fn name(self) -> &'static str {
        match self {
            RecordMode::Full => "full",
            RecordMode::Inputs => "inputs",
        }
    }
    /// The mode named `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        [RecordMode::Full, RecordMode::Inputs]
            .into_iter()
            .find(|m| m.name() == name)
    }
}

/// When a recording starts a new file. A file is closed before the message
/// that would take it past either limit (size is counted at chunk
/// granularity: the bytes on disk, which grow a chunk at a time).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rotation {
    /// Bytes on disk after which the next chunk starts a new file.
    pub max_bytes: Option<u64>,
    /// Log-time span after which a new file starts, ns.
    pub max_duration_ns: Option<u64>,
}

/// A configuration's text and where it came from, as a recording carries it
/// (its `sar_config` metadata): what `sarctl replay` runs with when given no
/// `--config`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigSource {
    /// Where it came from (a path, or "the built-in configuration").
    pub origin: String,
    /// The TOML text, as read.
    pub toml: String,
}

/// The text of a configuration file, read as [`load`] reads it (a regular
/// file of at most [`MAX_FILE_BYTES`], never waited on), for a tool that
/// edits the file (`sarctl identify`).
pub fn read_text(path: &Path) -> Result<String, ConfigError> {
    toml_file::read(path).map(|(text, _)| text)
}

/// Reads and checks a configuration file; errors name `path`.
pub fn load(path: &Path) -> Result<Config, ConfigError> {
    let (text, origin) = toml_file::read(path)?;
    parse(&text, &origin)
}

/// The built-in configuration ([`DEFAULT_TOML`]).
pub fn builtin() -> Result<Config, ConfigError> {
    parse(DEFAULT_TOML, "the built-in configuration")
}

/// Checks a configuration given as text; `origin` names it in errors.
pub fn parse(text: &str, origin: &str) -> Result<Config, ConfigError> {
    let (ctx, file): (Ctx<'_>, keys::FileRaw) = toml_file::parse(text, origin)?;
    let mut config = build(&ctx, file)?;
    // Recorded with every recording: it replays without hunting for this file.
    config.record.config_source = Some(std::sync::Arc::new(ConfigSource {
        origin: origin.to_owned(),
        toml: text.to_owned(),
    }));
    Ok(config)
}

/// Everything the file says, checked: the keys and their ranges, the
/// relations between keys, then each section through its domain types'
/// own checks (each section's function names its own keys in its errors).
fn build(ctx: &Ctx<'_>, raw: keys::FileRaw) -> Result<Config, ConfigError> {
    let f = raw.resolve(ctx)?;
    f.check_ranges(ctx)?;
    relations::check(ctx, &f)?;
    let calibration = keys::geometry::build(ctx, &f.geometry)?;
    let profile = keys::manipulator::profile(ctx, &f.manipulator)?;
    let noise = keys::sensor::noise(ctx, &f.sensor)?;
    let sensor_driver = keys::drivers_sensor::build(ctx, &f.drivers_sensor)?;
    let axes_driver = keys::drivers_axes::build(ctx, &f.drivers_axes)?;
    let guard = keys::guard::build(ctx, &f.guard)?;
    let tip = keys::tip::build(ctx, &f.tip)?;
    let plausibility = keys::plausibility::build(ctx, &f, &sensor_driver)?;
    let loop_ = keys::loop_::build(&f.loop_);
    let mut record = keys::record::build(ctx, &f.record)?;
    record.scales = DeviceScales::of_drivers(&sensor_driver, &axes_driver);
    let axes = keys::axes::build(&f);
    let rates = (tip.sample_rate_hz, loop_.rate_hz);
    // The slender rod's default is m L^2 / 12 of the checked rod.
    let (inertia, inertia_measured) = keys::manipulator::inertia(ctx, &f, &profile)?;
    let force_control = keys::force_control::build(ctx, &f, rates, (&profile, &inertia))?;
    let identify = keys::identify::build(&f.identify);
    let ros2 = keys::ros2::build(ctx, &f.ros2, record.scene_period_ns)?;
    relations::check_reach(ctx, &calibration, &profile, &axes.travel_m)?;
    let config = Config {
        origin: ctx.origin.to_owned(),
        manipulator_name: f.manipulator.name.clone(),
        estimator: EstimatorConfig {
            calibration,
            profile,
            noise,
            tip: TipForceConfig {
                max_std_n: tip.max_std_n,
            },
            guard,
            plausibility,
            filter: tip.filter,
            inertia,
        },
        loop_,
        axes,
        sensor_driver,
        axes_driver,
        record,
        force_control,
        inertia_measured,
        identify,
        ros2,
        file: f,
    };
    // What the drivers' own checks at start would refuse (one conversion
    // for the start and for every load, `--check-config` included).
    devices::check(ctx, &config)?;
    Ok(config)
}

/// The longest manipulator name, characters.
pub const MAX_NAME_CHARS: usize = 100;

/// Whether `c` is a format character (Unicode's general category Cf: the
/// bidirectional controls U+061C, U+200E, U+200F, U+202A-U+202E,
/// U+2066-U+2069, the invisible and zero-width ones, the tags) or a line or
/// paragraph separator (U+2028, U+2029): characters that are not shown as
/// themselves but change how the text around them is shown. (Unicode 15's
/// Cf list, written out: the crate links no Unicode tables.)
pub fn is_format_char(c: char) -> bool {
    matches!(
        u32::from(c),
        0x00AD
            | 0x0600..=0x0605
            | 0x061C
            | 0x06DD
            | 0x070F
            | 0x0890..=0x0891
            | 0x08E2
            | 0x180E
            | 0x200B..=0x200F
            | 0x2028..=0x202E
            | 0x2060..=0x2064
            | 0x2066..=0x206F
            | 0xFEFF
            | 0xFFF9..=0xFFFB
            | 0x110BD
            | 0x110CD
            | 0x13430..=0x1343F
            | 0x1BCA0..=0x1BCA3
            | 0x1D173..=0x1D17A
            | 0xE0001
            | 0xE0020..=0xE007F
    )
}

impl Config {
    /// The loop step's settings: the axes' travel, the speed and
    /// acceleration of planned moves, the following tolerance.
    pub fn step_config(&self) -> sar_loop::step::StepConfig {
        sar_loop::step::StepConfig {
            travel_m: self.axes.travel_m,
            axis_limits: sar_hal::motion::Limits {
                max_speed_mps: self.axes.max_speed_mps,
                max_accel_mps2: self.axes.max_accel_mps2,
            },
            following_tolerance_m: self.axes.following_tolerance_m,
            retreat_speed_mps: self.axes.retreat_speed_mps,
            period_ns: self.loop_.period_ns,
            publisher_stall_ns: self.loop_.publisher_stall_ns,
            force_control: self.force_control,
            motion: self.axes.motion,
            excite: sar_loop::excite::ExciteLimits {
                max_speed_mps: self.identify.excitation_max_speed_mps,
                max_accel_mps2: self.identify.excitation_max_accel_mps2,
                max_jerk_mps3: self.identify.excitation_max_jerk_mps3,
                axes_max_speed_mps: self.axes.max_speed_mps,
                period_ns: self.loop_.period_ns,
            },
            inertia_watch: keys::manipulator::inertia_watch(&self.file.manipulator),
            support: keys::support::build(&self.file.support, self.file.tip.sample_rate_hz),
        }
    }
}
