//! The daemon's configuration file (TOML, INTERFACES.md 2): parsed with serde,
//! unknown keys refused, then checked into the estimator's validated types.
//!
//! Only `[geometry]`, `[manipulator]` and `[sensor]` are required. Every other
//! section has documented defaults ([`DEFAULT_TOML`] shows them all):
//!
//! - `[manipulator]`'s optional keys, the rod's inertia (MODEL.md 10):
//!   `inertia_perp_kgm2` (I_perp about the centre of mass; absent: the
//!   slender rod's m L^2 / 12, a stated default, not a measurement:
//!   [`Config::inertia_measured`] is false), `inertia_perp_std_kgm2` (its
//!   standard deviation; absent: 50 % of the default, 5 % of a given value),
//!   `inertia_axial_kgm2` (0); `[sensor] adapter_mass_kg`, the mass between
//!   the sensor and the U-joint (0).
//! - `[loop]`: `rate_hz` (1000; 100..=10000), `priority` (SCHED_FIFO priority,
//!   80; 1..=99), `cpu` (the CPU the loop thread is pinned to; absent: none).
//! - `[guard]`: warn/stop limits in N on the total (10/15), axial (8/12) and
//!   lateral (6/10) parts of the tip force, `hysteresis_n` (1), `debounce_samples`
//!   (3), `max_sensor_age_s` and `max_joints_age_s` (0.01), `std_margin` (2),
//!   and the ceilings that `sarctl limits --set` may raise the stop limits to,
//!   `max_stop_total_n`, `max_stop_axial_n`, `max_stop_lateral_n` (default:
//!   the stop limits: limits can only be lowered at run time).
//! - `[plausibility]`: `max_joint_speed_mps` (0.05), `joint_margin_m` (0.0002),
//!   `max_counter_gap` (3), `torque_noise_nm` ([0.01, 0.01, 0.002]),
//!   `torque_max_sigma` (7; 0 switches the torque check off).
//! - `[tip]`: `max_std_n`, the observability limit (2 N); `filter_cutoff_hz`,
//!   the cutoff of the filtered tip force beside the estimate (5 Hz; 0 switches
//!   it off), stepped once per sensor sample at `sample_rate_hz` (500, the
//!   HEX-6's rate); `sensor_latency_s` (0.001; 0..=0.05), the sensor's
//!   latency from measurement to the sample's stamp (the carriage's motion
//!   is evaluated where the sample was measured, issue 26).
//! - `[axes]`: `travel_m`, (min, max) of q1, q2, q3 ([[-0.3, 0.3], [0, 0.6], [0, 0.6]]),
//!   `max_speed_mps` (0.02) and `max_accel_mps2` (0.2) for moves the daemon
//!   plans, `following_tolerance_m` (0.001: an axis farther than this from
//!   the commanded trajectory is a Fault), `servo_bandwidth_hz` (30) and
//!   `servo_damping` (0.7): the drives' position loop, whose lag is part of
//!   `[force_control]`'s stability check (FORCE_CONTROL.md) and which the
//!   loop models (issue 26, `sar_loop::motion`: the motion handed to the
//!   estimator); `brake_decel_mps2`, a guarded move's brake (default: the
//!   quick stop's; at least `max_accel_mps2`, at most `[drivers.axes]
//!   quick_stop_decel_mps2`).
//! - `[record]`: recording from the daemon's start (`sarctl record start|stop`
//!   at any time): `enabled` (false), `directory` ("recordings", relative to
//!   the working directory `sard` starts in; `sard` makes it absolute at
//!   start and logs it), `max_file_mb` (1024; 0: no size rotation),
//!   `max_file_s` (600; 0: no time rotation), `queue_capacity` (65536
//!   messages, about 2.7 s of disk stall at 4 kHz; 1024..=16777216).
//! - `[drivers.sensor]` and `[drivers.axes]`: `kind = "sim"` (default) or a real
//!   device (`rdt`, `canopen`) with its keys (INTERFACES.md 2). Every kind
//!   takes `quick_stop_decel_mps2` (2; at least `[axes] max_accel_mps2`, at
//!   most 10), the deceleration of the drives' own quick stop (CiA 402
//!   0x6085; `sard --sim` sets the simulated drives' from it). `canopen`
//!   also takes the drives' own limits that no other key gives (beyond
//!   INTERFACES.md): `max_torque_permille` (1000; 1..=3000), their
//!   max torque (0x6072) in per mille of the motor's rated torque. The
//!   drives' other limits come from `[axes]` and `[plausibility]` (see
//!   [`devices::canopen_drives`]; a configuration that loads is one the
//!   drivers' own checks at start take).
//! - `[identify]`: the limits of `sarctl identify --dynamic`'s excitation
//!   (not the operator's move limits): `excitation_max_speed_mps` (0.02;
//!   at most `[axes] max_speed_mps`, below `[plausibility]
//!   max_joint_speed_mps`), `excitation_max_accel_mps2` (1; at most 5),
//!   `excitation_max_jerk_mps3` (10; at most 1000), `excitation_duration_s`
//!   (60; 10..=600).
//! - `[ros2]`: the ROS 2 bridge's (`sar-ros2`; `sard` only checks it): the
//!   DDS domain, the local addresses DDS uses, each topic's rate
//!   (`Ros2Settings`, module `ros2`).
//!
//! Every error names the file, the dotted key, the line where the file has it,
//! and the problem ([`ConfigError`]), on one line of at most about 700
//! characters (a long value, key or path is cut).
//!
//! Plausible values only (issue 25): a file is read only if it is a regular
//! file of at most [`MAX_FILE_BYTES`] (1 MB; a FIFO or a device is refused
//! at once, never waited on); every array has its exact length (more
//! elements are refused, as fewer were); and beyond what the model can
//! compute with, every physical key has a plausible range, [`PLAUSIBLE`]
//! (the README's "Plausible configurations" lists it as a table): the rod
//! 0.1..=1.5 m long, its mass 0..=10 kg, its centre of mass on the rod, the
//! positions within 2 m of the base frame's origin, the sensor's noise at
//! most a tenth of its range, every force limit at most 100 N and at most
//! the sensor's smallest force range, ... A value outside is refused with
//! the range and, when the value read in a smaller unit falls within it, that
//! unit ("got 35 (a value in cm? 35 cm is 0.35 m)"). These checks follow the
//! validity checks of each section; the support's reach from the travel
//! comes last.
//!
//! The simulator's scenario files (`scenarios/`) are read here too
//! ([`scenario`]: TOML -> `sar_sim::scenario::Scenario`), with the same
//! machinery and the same error type.

pub mod devices;
mod exact;
mod identify;
mod locate;
mod plausible;
mod ros2;
pub mod scenario;
mod toml_file;

pub use plausible::{Applies, PLAUSIBLE, Plausible};
pub use toml_file::{ConfigError, MAX_FILE_BYTES};

use locate::join;
use sar_estimator::SensorNoise;
use sar_estimator::cycle::{
    EstimatorConfig, FrozenCheck, MountingLimits, PlausibilityConfig, PlausibilityLimits,
    SensorRange, SpikeLimits, TareLimits, TorqueLimits, frozen_repeats,
};
use sar_estimator::filter::{FilterConfig, TipFilter};
use sar_estimator::guard::{ForceLimits, GuardConfig, GuardLimits};
use sar_estimator::inertial::RodInertia;
use sar_estimator::tip_force::TipForceConfig;
use sar_kinematics::{Calibration, CalibrationSpec, Mat3, Profile, ProfileSpec, Vec3};
use sar_loop::runloop::LoopConfig;
use serde::Deserialize;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use toml_file::Ctx;

pub use identify::IdentifySettings;
pub use ros2::{MAX_DOMAIN_ID, Ros2Rates, Ros2Settings, TopicRate};

/// The configuration of the built-in demo (`sard --sim` without `--config`):
/// the example robot of INTERFACES.md 2, every optional section written out
/// with its default.
pub const DEFAULT_TOML: &str = include_str!("default_config.toml");

// ---------------------------------------------------------------------------
// The file as written.

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    geometry: GeometryToml,
    manipulator: ManipulatorToml,
    sensor: SensorToml,
    #[serde(default, rename = "loop")]
    loop_: LoopToml,
    #[serde(default)]
    guard: GuardToml,
    #[serde(default)]
    plausibility: PlausibilityToml,
    #[serde(default)]
    tip: TipToml,
    #[serde(default)]
    axes: AxesToml,
    #[serde(default)]
    drivers: DriversToml,
    #[serde(default)]
    record: RecordToml,
    #[serde(default)]
    force_control: ForceControlToml,
    #[serde(default)]
    identify: identify::IdentifyToml,
    #[serde(default)]
    ros2: ros2::Ros2Toml,
}

/// `[force_control]` (FORCE_CONTROL.md): the admittance law's settings.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct ForceControlToml {
    axial_damping_n_s_per_m: f64,
    axial_mass_kg: f64,
    lateral_damping_n_s_per_m: f64,
    lateral_mass_kg: f64,
    hold_return_n_per_m: f64,
    max_speed_mps: f64,
    max_accel_mps2: f64,
    max_excursion_m: f64,
    filter_cutoff_hz: f64,
    other_delay_s: f64,
    max_stiffness_n_per_m: f64,
    min_phase_margin_deg: f64,
}

impl Default for ForceControlToml {
    fn default() -> Self {
        let d = sar_estimator::force_control::ForceControlLimits::default();
        Self {
            axial_damping_n_s_per_m: d.axial.damping_n_s_per_m,
            axial_mass_kg: d.axial.mass_kg,
            lateral_damping_n_s_per_m: d.lateral.damping_n_s_per_m,
            lateral_mass_kg: d.lateral.mass_kg,
            hold_return_n_per_m: d.hold_return_n_per_m,
            max_speed_mps: d.max_speed_mps,
            max_accel_mps2: d.max_accel_mps2,
            max_excursion_m: d.max_excursion_m,
            filter_cutoff_hz: d.filter_cutoff_hz,
            other_delay_s: d.other_delay_s,
            max_stiffness_n_per_m: d.max_stiffness_n_per_m,
            min_phase_margin_deg: d.min_phase_margin_deg,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RecordToml {
    enabled: bool,
    directory: String,
    max_file_mb: f64,
    max_file_s: f64,
    queue_capacity: i64,
    scene_hz: f64,
    snapshot_s: f64,
    mode: String,
}

impl Default for RecordToml {
    fn default() -> Self {
        Self {
            enabled: false,
            directory: "recordings".to_owned(),
            max_file_mb: 1024.0,
            max_file_s: 600.0,
            queue_capacity: 65536,
            scene_hz: 30.0,
            snapshot_s: 10.0,
            mode: "full".to_owned(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryToml {
    #[serde(deserialize_with = "crate::exact::array")]
    gravity: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    support: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    p_home: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    ujoint_offset: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    sensor_offset: [f64; 3],
    #[serde(deserialize_with = "crate::exact::rows")]
    sensor_rotation: [[f64; 3]; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ManipulatorToml {
    name: String,
    length_m: f64,
    offset_m: f64,
    mass_kg: f64,
    com_m: f64,
    #[serde(default)]
    inertia_perp_kgm2: Option<f64>,
    #[serde(default)]
    inertia_perp_std_kgm2: Option<f64>,
    #[serde(default)]
    inertia_axial_kgm2: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorToml {
    #[serde(deserialize_with = "crate::exact::array")]
    noise_n: [f64; 3],
    #[serde(default = "default_range_n")]
    #[serde(deserialize_with = "crate::exact::array")]
    range_n: [f64; 3],
    #[serde(default = "default_range_nm")]
    #[serde(deserialize_with = "crate::exact::array")]
    range_nm: [f64; 3],
    #[serde(default = "default_drift_n_per_s")]
    drift_n_per_s: f64,
    #[serde(default = "default_max_tare_age_s")]
    max_tare_age_s: f64,
    #[serde(default = "default_tare_window_samples")]
    tare_window_samples: i64,
    #[serde(default = "default_tare_max_spread")]
    tare_max_spread: f64,
    #[serde(default = "default_tare_min_interval_s")]
    tare_min_interval_s: f64,
    #[serde(default)]
    adapter_mass_kg: Option<f64>,
}

fn default_tare_window_samples() -> i64 {
    i64::from(TareLimits::default().window_samples)
}

fn default_tare_max_spread() -> f64 {
    TareLimits::default().max_spread
}

fn default_tare_min_interval_s() -> f64 {
    TareLimits::default().min_interval_ns as f64 * 1e-9
}

fn default_range_n() -> [f64; 3] {
    SensorRange::HEX6.force_n.into()
}

fn default_range_nm() -> [f64; 3] {
    SensorRange::HEX6.torque_nm.into()
}

fn default_drift_n_per_s() -> f64 {
    TareLimits::default().drift_n_per_s
}

fn default_max_tare_age_s() -> f64 {
    TareLimits::default()
        .max_age_ns
        .map_or(0.0, |ns| ns as f64 * 1e-9)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct LoopToml {
    rate_hz: f64,
    priority: i64,
    cpu: Option<i64>,
    publisher_stall_s: f64,
}

impl Default for LoopToml {
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            priority: 80,
            cpu: None,
            publisher_stall_s: 0.5,
        }
    }
}

/// `[guard]`. Its six force limits keep their own keys (INTERFACES.md 2,
/// the names of [`ForceLimits::NAMES`]; `deny_unknown_fields` cannot
/// flatten) and become a [`ForceLimits`] in one place,
/// [`GuardToml::force_limits`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct GuardToml {
    warn_total_n: f64,
    stop_total_n: f64,
    warn_axial_n: f64,
    stop_axial_n: f64,
    warn_lateral_n: f64,
    stop_lateral_n: f64,
    hysteresis_n: f64,
    debounce_samples: i64,
    max_sensor_age_s: f64,
    max_joints_age_s: f64,
    std_margin: f64,
    max_stop_total_n: Option<f64>,
    max_stop_axial_n: Option<f64>,
    max_stop_lateral_n: Option<f64>,
    retreat_rise_n: f64,
}

impl GuardToml {
    /// The six force limits, the only place they leave the TOML's fields.
    fn force_limits(&self) -> ForceLimits {
        ForceLimits {
            warn_total_n: self.warn_total_n,
            stop_total_n: self.stop_total_n,
            warn_axial_n: self.warn_axial_n,
            stop_axial_n: self.stop_axial_n,
            warn_lateral_n: self.warn_lateral_n,
            stop_lateral_n: self.stop_lateral_n,
        }
    }
}

impl Default for GuardToml {
    fn default() -> Self {
        Self {
            warn_total_n: 10.0,
            stop_total_n: 15.0,
            warn_axial_n: 8.0,
            stop_axial_n: 12.0,
            warn_lateral_n: 6.0,
            stop_lateral_n: 10.0,
            hysteresis_n: 1.0,
            debounce_samples: 3,
            max_sensor_age_s: 0.01,
            max_joints_age_s: 0.01,
            std_margin: 2.0,
            max_stop_total_n: None,
            max_stop_axial_n: None,
            max_stop_lateral_n: None,
            retreat_rise_n: sar_estimator::guard::DEFAULT_RETREAT_RISE_N,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct PlausibilityToml {
    max_joint_speed_mps: f64,
    joint_margin_m: f64,
    max_counter_gap: i64,
    #[serde(deserialize_with = "crate::exact::array")]
    torque_noise_nm: [f64; 3],
    torque_max_sigma: f64,
    frozen_check: bool,
    frozen_repeats: Option<i64>,
    spike_check: bool,
    spike_sigma: f64,
    spike_max: i64,
    spike_window_samples: i64,
    rest_check: bool,
    rest_sigma: f64,
    rest_tolerance_n: f64,
    rest_tolerance_nm: f64,
    rest_samples: i64,
    support_friction_n: f64,
}

impl Default for PlausibilityToml {
    fn default() -> Self {
        let d = PlausibilityLimits::default();
        let spikes = SpikeLimits::default();
        let rest = MountingLimits::default();
        Self {
            max_joint_speed_mps: d.max_joint_speed_mps,
            joint_margin_m: d.joint_margin_m,
            max_counter_gap: i64::from(d.max_counter_gap),
            torque_noise_nm: TorqueLimits::DEFAULT_NOISE_NM,
            torque_max_sigma: TorqueLimits::DEFAULT_MAX_SIGMA,
            frozen_check: true,
            frozen_repeats: None,
            spike_check: true,
            spike_sigma: spikes.jump_sigma,
            spike_max: i64::from(spikes.max_spikes),
            spike_window_samples: i64::from(spikes.window_samples),
            rest_check: true,
            rest_sigma: rest.sigma,
            rest_tolerance_n: rest.tolerance_n,
            rest_tolerance_nm: rest.tolerance_nm,
            rest_samples: i64::from(rest.rest_samples),
            support_friction_n: rest.friction_n,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct TipToml {
    max_std_n: f64,
    filter_cutoff_hz: f64,
    sample_rate_hz: f64,
    sensor_latency_s: f64,
}

impl Default for TipToml {
    fn default() -> Self {
        Self {
            max_std_n: TipForceConfig::DEFAULT_MAX_STD_N,
            filter_cutoff_hz: 5.0,
            sample_rate_hz: 500.0,
            sensor_latency_s: 0.001,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct AxesToml {
    #[serde(deserialize_with = "crate::exact::rows")]
    travel_m: [[f64; 2]; 3],
    max_speed_mps: f64,
    max_accel_mps2: f64,
    following_tolerance_m: f64,
    retreat_speed_mps: f64,
    servo_bandwidth_hz: f64,
    servo_damping: f64,
    brake_decel_mps2: Option<f64>,
}

impl Default for AxesToml {
    fn default() -> Self {
        Self {
            travel_m: [[-0.3, 0.3], [0.0, 0.6], [0.0, 0.6]],
            max_speed_mps: 0.02,
            max_accel_mps2: 0.2,
            following_tolerance_m: 0.001,
            retreat_speed_mps: 0.005,
            servo_bandwidth_hz: scenario::DEFAULT_SERVO_BANDWIDTH_HZ,
            servo_damping: scenario::DEFAULT_SERVO_DAMPING,
            brake_decel_mps2: None,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct DriversToml {
    sensor: Option<SensorDriverToml>,
    axes: Option<AxesDriverToml>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorDriverToml {
    kind: String,
    address: Option<String>,
    counts_per_n: Option<f64>,
    counts_per_nm: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AxesDriverToml {
    kind: String,
    interface: Option<String>,
    node_ids: Option<Vec<i64>>,
    lead_m: Option<f64>,
    counts_per_turn: Option<i64>,
    quick_stop_decel_mps2: Option<f64>,
    max_torque_permille: Option<i64>,
}

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
    pub fn name(self) -> &'static str {
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
    let (ctx, file): (Ctx<'_>, FileToml) = toml_file::parse(text, origin)?;
    let mut config = build(&ctx, file)?;
    // Recorded with every recording: it replays without hunting for this file.
    config.record.config_source = Some(std::sync::Arc::new(ConfigSource {
        origin: origin.to_owned(),
        toml: text.to_owned(),
    }));
    Ok(config)
}

/// The configuration's own checks of a value.
impl Ctx<'_> {
    fn range_f(&self, key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Result<f64, ConfigError> {
        if (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.err(
                key,
                format!(
                    "must be within {lo}..={hi} {unit}, got {}",
                    toml_file::num(v)
                ),
            ))
        }
    }

    fn range_i(&self, key: &str, v: i64, lo: i64, hi: i64) -> Result<i64, ConfigError> {
        if (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(self.err(key, format!("must be within {lo}..={hi}, got {v}")))
        }
    }

    /// An integer within `lo..=hi` (both within `u32`) as a `u32`.
    fn range_u32(&self, key: &str, v: i64, lo: u32, hi: u32) -> Result<u32, ConfigError> {
        let v = self.range_i(key, v, i64::from(lo), i64::from(hi))?;
        // In range by the check above.
        Ok(u32::try_from(v).unwrap_or(lo))
    }

    /// Seconds (> 0, at most an hour) to ns.
    fn seconds_ns(&self, key: &str, s: f64) -> Result<u64, ConfigError> {
        let s = self.range_f(key, s, 0.0, 3600.0, "s")?;
        let ns = (s * 1e9).round();
        if ns < 1.0 {
            return Err(self.err(key, format!("must be > 0 s, got {s}")));
        }
        // In range by the check above (at most 3.6e12).
        Ok(ns as u64)
    }
}

/// A vector whose every component is finite and > 0.
fn positive_vec3(ctx: &Ctx<'_>, key: &str, v: [f64; 3]) -> Result<Vec3, ConfigError> {
    for (i, x) in v.iter().enumerate() {
        if !(x.is_finite() && *x > 0.0) {
            return Err(ctx.err(&format!("{key}[{i}]"), format!("must be > 0, got {x}")));
        }
    }
    Ok(vec3(v))
}

/// The frozen-sensor check: off only when the file says so; otherwise the
/// count given, or derived from the noise and the sensor's resolution
/// (`frozen_repeats`: fewer than one false alarm in ten years of 1 kHz); a
/// sensor that would repeat by itself is refused with what to change.
fn frozen_check(
    ctx: &Ctx<'_>,
    p: &PlausibilityToml,
    sensor: &SensorToml,
    torque: Option<&TorqueLimits>,
    driver: &SensorDriver,
) -> Result<FrozenCheck, ConfigError> {
    if !p.frozen_check {
        if p.frozen_repeats.is_some() {
            return Err(ctx.err(
                "plausibility.frozen_repeats",
                "given while plausibility.frozen_check = false",
            ));
        }
        return Ok(FrozenCheck::Off);
    }
    if let Some(n) = p.frozen_repeats {
        let n = ctx.range_i(
            "plausibility.frozen_repeats",
            n,
            1,
            i64::from(FrozenCheck::MAX_REPEATS),
        )?;
        return Ok(FrozenCheck::On {
            repeats: u32::try_from(n).unwrap_or(FrozenCheck::DEFAULT_REPEATS),
        });
    }
    let (resolution_n, resolution_nm) = match driver {
        SensorDriver::Rdt {
            counts_per_n,
            counts_per_nm,
            ..
        } => (1.0 / counts_per_n, 1.0 / counts_per_nm),
        SensorDriver::Sim => (0.0, 0.0),
    };
    let noise_nm = torque.map(|t| t.noise_nm);
    match frozen_repeats(
        &vec3(sensor.noise_n),
        noise_nm.as_ref(),
        resolution_n,
        resolution_nm,
    ) {
        Some(repeats) => Ok(FrozenCheck::On { repeats }),
        None => Err(ctx.err(
            "plausibility.frozen_check",
            "the sensor's noise is too small for its resolution to tell a frozen sensor from \
             a live one; set plausibility.frozen_repeats, or frozen_check = false to switch \
             the check off",
        )),
    }
}

fn vec3(v: [f64; 3]) -> Vec3 {
    Vec3::from(v)
}

/// Everything the file says, checked section by section (each section's
/// function names its own keys in its errors).
fn build(ctx: &Ctx<'_>, f: FileToml) -> Result<Config, ConfigError> {
    let calibration = geometry(ctx, &f.geometry)?;
    let profile = manipulator(ctx, &f.manipulator)?;
    let noise = SensorNoise::new(vec3(f.sensor.noise_n))
        .map_err(|e| ctx.err("sensor.noise_n", e.to_string()))?;
    let mut axes = axes(ctx, &f.axes, f.plausibility.max_joint_speed_mps)?;
    let guard = guard(ctx, &f.guard)?;
    let sensor_driver = sensor_driver(ctx, f.drivers.sensor.as_ref())?;
    let tip = tip(ctx, &f.tip)?;
    let plausibility = plausibility(ctx, &f.plausibility, &f.sensor, &sensor_driver, &tip)?;
    let loop_ = loop_config(ctx, &f.loop_)?;
    let mut record = record(ctx, &f.record)?;
    let axes_driver = axes_driver(ctx, f.drivers.axes.as_ref(), axes.max_accel_mps2)?;
    axes.motion = drives_motion(ctx, &f, axes.max_accel_mps2)?;
    record.scales = DeviceScales::of_drivers(&sensor_driver, &axes_driver);
    let force_control = force_control(
        ctx,
        &f.force_control,
        (tip.sample_rate_hz, loop_.rate_hz),
        (f.axes.servo_bandwidth_hz, f.axes.servo_damping),
    )?;
    let identify = identify::identify(
        ctx,
        &f.identify,
        f.plausibility.max_joint_speed_mps,
        f.axes.max_speed_mps,
    )?;
    let ros2 = ros2::ros2(ctx, &f.ros2, record.scene_period_ns)?;
    // Valid values, then plausible ones (a unit mistake is named with its
    // range), then the geometry against the travel.
    plausible::check(ctx, &f)?;
    check_reach(ctx, &calibration, &profile, &axes.travel_m)?;
    // After the plausible ranges: the slender rod's default is m L^2 / 12
    // of a plausible rod.
    let (inertia, inertia_measured) = inertia(ctx, &f.manipulator, &f.sensor, &profile)?;
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
    };
    // What the drivers' own checks at start would refuse (one conversion
    // for the start and for every load, `--check-config` included).
    devices::check(ctx, &config)?;
    Ok(config)
}

/// `[geometry]`, through the kinematics' own checks.
fn geometry(ctx: &Ctx<'_>, g: &GeometryToml) -> Result<Calibration, ConfigError> {
    let r = g.sensor_rotation;
    let rotation = Mat3::from_row_slice(&[
        r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
    ]);
    Calibration::new(&CalibrationSpec {
        p_home_m: vec3(g.p_home),
        ujoint_offset_m: vec3(g.ujoint_offset),
        sensor_offset_m: vec3(g.sensor_offset),
        sensor_rotation: rotation,
        support_m: vec3(g.support),
        gravity_mps2: vec3(g.gravity),
    })
    .map_err(|e| ctx.err(&join("geometry", e.field()), e.to_string()))
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

/// `[manipulator]`, through the kinematics' own checks.
fn manipulator(ctx: &Ctx<'_>, m: &ManipulatorToml) -> Result<Profile, ConfigError> {
    if m.name.trim().is_empty() {
        return Err(ctx.err("manipulator.name", "must not be empty"));
    }
    // Shown by `--check-config`, the log and the recordings: one line,
    // shown as written (a control character broke the line; a bidi override
    // such as U+202E reversed how the rest of a log line reads).
    let chars = m.name.chars().count();
    if chars > MAX_NAME_CHARS {
        return Err(ctx.err(
            "manipulator.name",
            format!("must be at most {MAX_NAME_CHARS} characters, got {chars} characters"),
        ));
    }
    if let Some((at, c)) = m.name.chars().enumerate().find(|(_, c)| c.is_control()) {
        return Err(ctx.err(
            "manipulator.name",
            format!(
                "must not hold a control character, got U+{:04X} at character {}",
                u32::from(c),
                at + 1
            ),
        ));
    }
    if let Some((at, c)) = m.name.chars().enumerate().find(|(_, c)| is_format_char(*c)) {
        return Err(ctx.err(
            "manipulator.name",
            format!(
                "must not hold an invisible or direction-changing character (it changes how the log and the tools show the text), got U+{:04X} at character {}",
                u32::from(c),
                at + 1
            ),
        ));
    }
    Profile::new(&ProfileSpec {
        length_m: m.length_m,
        offset_m: m.offset_m,
        mass_kg: m.mass_kg,
        com_m: m.com_m,
    })
    .map_err(|e| ctx.err(&join("manipulator", e.field()), e.to_string()))
}

/// The rod's inertia (`[manipulator] inertia_perp_kgm2`,
/// `inertia_perp_std_kgm2`, `inertia_axial_kgm2`) and the adapter's mass
/// (`[sensor] adapter_mass_kg`), MODEL.md 10, and whether I_perp was given.
/// Without I_perp: the slender rod's m L^2 / 12 with a 50 % standard
/// deviation (a stated default); I_perp without its standard deviation: 5 %
/// of it; a standard deviation without I_perp is refused.
fn inertia(
    ctx: &Ctx<'_>,
    m: &ManipulatorToml,
    s: &SensorToml,
    profile: &Profile,
) -> Result<(RodInertia, bool), ConfigError> {
    let (perp_kgm2, fraction) = match m.inertia_perp_kgm2 {
        Some(v) => (v, RodInertia::GIVEN_STD_FRACTION),
        None => {
            if m.inertia_perp_std_kgm2.is_some() {
                return Err(ctx.err(
                    "manipulator.inertia_perp_std_kgm2",
                    "given without manipulator.inertia_perp_kgm2 (the default m L^2 / 12 \
                     has its own)",
                ));
            }
            (
                RodInertia::slender_rod_kgm2(profile),
                RodInertia::SLENDER_ROD_STD_FRACTION,
            )
        }
    };
    let inertia = RodInertia {
        inertia_perp_kgm2: perp_kgm2,
        inertia_perp_std_kgm2: m.inertia_perp_std_kgm2.unwrap_or(perp_kgm2 * fraction),
        inertia_axial_kgm2: m.inertia_axial_kgm2.unwrap_or(0.0),
        adapter_mass_kg: s.adapter_mass_kg.unwrap_or(0.0),
    };
    inertia.check().map_err(|e| match e {
        sar_estimator::SettingError::Invalid { field, .. } => {
            let section = if field == "adapter_mass_kg" {
                "sensor"
            } else {
                "manipulator"
            };
            setting_error(ctx, section, &e)
        }
        _ => setting_error(ctx, "manipulator", &e),
    })?;
    Ok((inertia, m.inertia_perp_kgm2.is_some()))
}

/// `[axes]` (the planned speed at most the plausibility's joint speed).
fn axes(ctx: &Ctx<'_>, a: &AxesToml, max_joint_speed_mps: f64) -> Result<AxesConfig, ConfigError> {
    let mut travel_m = [(0.0, 0.0); 3];
    for (i, (slot, [lo, hi])) in travel_m.iter_mut().zip(a.travel_m).enumerate() {
        if lo >= hi {
            return Err(ctx.err(
                &format!("axes.travel_m[{i}]"),
                format!("min must be below max, got [{lo}, {hi}]"),
            ));
        }
        *slot = (lo, hi);
    }
    let speed = a.max_speed_mps;
    if !(speed > 0.0 && speed <= max_joint_speed_mps) {
        return Err(ctx.err(
            "axes.max_speed_mps",
            format!(
                "must be > 0 and at most plausibility.max_joint_speed_mps ({} m/s), got {speed}",
                max_joint_speed_mps
            ),
        ));
    }
    let accel = ctx.range_f("axes.max_accel_mps2", a.max_accel_mps2, 1e-6, 10.0, "m/s^2")?;
    let following_tolerance_m = ctx.range_f(
        "axes.following_tolerance_m",
        a.following_tolerance_m,
        1e-5,
        0.05,
        "m",
    )?;
    let retreat_speed_mps = a.retreat_speed_mps;
    if !(retreat_speed_mps > 0.0 && retreat_speed_mps <= speed) {
        return Err(ctx.err(
            "axes.retreat_speed_mps",
            format!(
                "must be > 0 and at most axes.max_speed_mps ({speed} m/s), got {retreat_speed_mps}"
            ),
        ));
    }

    Ok(AxesConfig {
        travel_m,
        max_speed_mps: speed,
        max_accel_mps2: accel,
        following_tolerance_m,
        retreat_speed_mps,
        // Set from `[drivers.axes]` too (drives_motion).
        motion: sar_loop::motion::MotionConfig {
            servo_bandwidth_hz: 0.0,
            servo_damping: scenario::DEFAULT_SERVO_DAMPING,
            quick_stop_decel_mps2: DEFAULT_QUICK_STOP_DECEL_MPS2,
            brake_decel_mps2: DEFAULT_QUICK_STOP_DECEL_MPS2,
            sensor_latency_ns: 0,
        },
    })
}

/// The drives as the loop models them (issue 26): `[axes]
/// servo_bandwidth_hz` (0..=300 Hz; 0: ideal drives), `servo_damping`
/// (0.1..=2), `[drivers.axes] quick_stop_decel_mps2` (any kind; at least
/// `max_accel_mps2`, at most 10) and `[axes] brake_decel_mps2` (a guarded
/// move's brake: default the quick stop's, at least `max_accel_mps2`, at
/// most the quick stop's); `[tip] sensor_latency_s` (0..=0.05 s), where the
/// motion is evaluated.
fn drives_motion(
    ctx: &Ctx<'_>,
    f: &FileToml,
    max_accel_mps2: f64,
) -> Result<sar_loop::motion::MotionConfig, ConfigError> {
    let (a, drivers) = (&f.axes, f.drivers.axes.as_ref());
    let latency_s = ctx.range_f(
        "tip.sensor_latency_s",
        f.tip.sensor_latency_s,
        0.0,
        0.05,
        "s",
    )?;
    let servo_bandwidth_hz = ctx.range_f(
        "axes.servo_bandwidth_hz",
        a.servo_bandwidth_hz,
        0.0,
        300.0,
        "Hz",
    )?;
    let servo_damping = ctx.range_f("axes.servo_damping", a.servo_damping, 0.1, 2.0, "")?;
    let quick_stop_decel_mps2 = ctx.range_f(
        "drivers.axes.quick_stop_decel_mps2",
        drivers
            .and_then(|d| d.quick_stop_decel_mps2)
            .unwrap_or(DEFAULT_QUICK_STOP_DECEL_MPS2),
        max_accel_mps2,
        10.0,
        "m/s^2 (at least [axes] max_accel_mps2)",
    )?;
    let brake_decel_mps2 = ctx.range_f(
        "axes.brake_decel_mps2",
        a.brake_decel_mps2.unwrap_or(quick_stop_decel_mps2),
        max_accel_mps2,
        quick_stop_decel_mps2,
        "m/s^2 (at least [axes] max_accel_mps2, at most [drivers.axes] quick_stop_decel_mps2)",
    )?;
    Ok(sar_loop::motion::MotionConfig {
        servo_bandwidth_hz,
        servo_damping,
        quick_stop_decel_mps2,
        brake_decel_mps2,
        sensor_latency_ns: (latency_s * 1e9).round() as u64,
    })
}

/// `[guard]`.
fn guard(ctx: &Ctx<'_>, gt: &GuardToml) -> Result<GuardConfig, ConfigError> {
    let debounce = ctx.range_i(
        "guard.debounce_samples",
        gt.debounce_samples,
        1,
        i64::from(sar_estimator::guard::MAX_DEBOUNCE_SAMPLES),
    )?;
    let force = gt.force_limits();
    let limits = GuardLimits {
        force,
        hysteresis_n: gt.hysteresis_n,
        debounce_samples: u32::try_from(debounce).unwrap_or(1),
        max_sensor_age_ns: ctx.seconds_ns("guard.max_sensor_age_s", gt.max_sensor_age_s)?,
        max_joints_age_ns: ctx.seconds_ns("guard.max_joints_age_s", gt.max_joints_age_s)?,
        std_margin: gt.std_margin,
    };
    let guard = GuardConfig::new(limits).map_err(|e| setting_error(ctx, "guard", &e))?;
    let guard = guard
        .with_ceiling({
            let [total_n, axial_n, lateral_n] = force.stop_n();
            [
                gt.max_stop_total_n.unwrap_or(total_n),
                gt.max_stop_axial_n.unwrap_or(axial_n),
                gt.max_stop_lateral_n.unwrap_or(lateral_n),
            ]
        })
        .map_err(|e| setting_error(ctx, "guard", &e))?;
    guard
        .with_retreat_rise_n(gt.retreat_rise_n)
        .map_err(|e| setting_error(ctx, "guard", &e))
}

/// `[plausibility]`, with the `[sensor]` keys it checks against.
fn plausibility(
    ctx: &Ctx<'_>,
    p: &PlausibilityToml,
    sensor: &SensorToml,
    sensor_driver: &SensorDriver,
    tip: &Tip,
) -> Result<PlausibilityConfig, ConfigError> {
    let gap = ctx.range_u32(
        "plausibility.max_counter_gap",
        p.max_counter_gap,
        1,
        1_000_000,
    )?;
    let torque = if p.torque_max_sigma == 0.0 {
        None
    } else {
        Some(TorqueLimits {
            noise_nm: vec3(p.torque_noise_nm),
            max_sigma: p.torque_max_sigma,
        })
    };
    PlausibilityConfig::new(PlausibilityLimits {
        max_joint_speed_mps: p.max_joint_speed_mps,
        joint_margin_m: p.joint_margin_m,
        max_counter_gap: gap,
        // Checked finite and > 0 by `tip`.
        sample_period_ns: (1e9 / tip.sample_rate_hz).round() as u64,
        torque,
        frozen: frozen_check(ctx, p, sensor, torque.as_ref(), sensor_driver)?,
        range: Some(SensorRange {
            force_n: positive_vec3(ctx, "sensor.range_n", sensor.range_n)?,
            torque_nm: positive_vec3(ctx, "sensor.range_nm", sensor.range_nm)?,
        }),
        spikes: spike_limits(ctx, p)?,
        tare: tare_limits(ctx, sensor)?,
        mounting: mounting_limits(ctx, p)?,
    })
    .map_err(|e| setting_error(ctx, "plausibility", &e))
}

/// The spike check (`plausibility.spike_*`), if on.
fn spike_limits(ctx: &Ctx<'_>, p: &PlausibilityToml) -> Result<Option<SpikeLimits>, ConfigError> {
    if !p.spike_check {
        return Ok(None);
    }
    Ok(Some(SpikeLimits {
        jump_sigma: ctx.range_f("plausibility.spike_sigma", p.spike_sigma, 3.0, 1e3, "")?,
        max_spikes: ctx.range_u32("plausibility.spike_max", p.spike_max, 2, 100_000)?,
        window_samples: ctx.range_u32(
            "plausibility.spike_window_samples",
            p.spike_window_samples,
            1,
            10_000_000,
        )?,
    }))
}

/// The tare's limits (`sensor.*tare*`, `sensor.drift_n_per_s`).
fn tare_limits(ctx: &Ctx<'_>, sensor: &SensorToml) -> Result<TareLimits, ConfigError> {
    let max_age_s = ctx.range_f(
        "sensor.max_tare_age_s",
        sensor.max_tare_age_s,
        0.0,
        7.0 * 86_400.0,
        "s (0: never)",
    )?;
    let drift_n_per_s = ctx.range_f(
        "sensor.drift_n_per_s",
        sensor.drift_n_per_s,
        0.0,
        10.0,
        "N/s",
    )?;
    let window_samples = ctx.range_u32(
        "sensor.tare_window_samples",
        sensor.tare_window_samples,
        1,
        100_000,
    )?;
    let max_spread = ctx.range_f(
        "sensor.tare_max_spread",
        sensor.tare_max_spread,
        1.0,
        100.0,
        "(times the noise)",
    )?;
    let min_interval_s = ctx.range_f(
        "sensor.tare_min_interval_s",
        sensor.tare_min_interval_s,
        0.0,
        3600.0,
        "s (0: no limit)",
    )?;
    Ok(TareLimits {
        max_age_ns: (max_age_s > 0.0).then(|| (max_age_s * 1e9).round() as u64),
        drift_n_per_s,
        window_samples,
        max_spread,
        min_interval_ns: (min_interval_s * 1e9).round() as u64,
    })
}

/// The check of the wrench at rest before the first reset
/// (`plausibility.rest_*`), if on.
fn mounting_limits(
    ctx: &Ctx<'_>,
    p: &PlausibilityToml,
) -> Result<Option<MountingLimits>, ConfigError> {
    if !p.rest_check {
        return Ok(None);
    }
    let (sigma, friction) = (p.rest_sigma, p.support_friction_n);
    Ok(Some(MountingLimits {
        sigma: ctx.range_f("plausibility.rest_sigma", sigma, 0.0, 100.0, "")?,
        friction_n: ctx.range_f("plausibility.support_friction_n", friction, 0.0, 100.0, "N")?,
        tolerance_n: ctx.range_f(
            "plausibility.rest_tolerance_n",
            p.rest_tolerance_n,
            1e-3,
            100.0,
            "N",
        )?,
        tolerance_nm: ctx.range_f(
            "plausibility.rest_tolerance_nm",
            p.rest_tolerance_nm,
            1e-4,
            10.0,
            "N m",
        )?,
        rest_samples: ctx.range_u32("plausibility.rest_samples", p.rest_samples, 1, 100_000)?,
    }))
}

/// `[tip]`: the observability limit, the sensor's rate and the filter.
struct Tip {
    max_std_n: f64,
    sample_rate_hz: f64,
    filter: Option<FilterConfig>,
}

/// `[tip]`.
fn tip(ctx: &Ctx<'_>, t: &TipToml) -> Result<Tip, ConfigError> {
    let max_std_n = t.max_std_n;
    if !(max_std_n.is_finite() && max_std_n > 0.0) {
        return Err(ctx.err("tip.max_std_n", format!("must be > 0 N, got {max_std_n}")));
    }
    let sample_rate_hz =
        ctx.range_f("tip.sample_rate_hz", t.sample_rate_hz, 1.0, 100_000.0, "Hz")?;
    let cutoff_hz = t.filter_cutoff_hz;
    let filter = if cutoff_hz == 0.0 {
        None
    } else {
        let filter = FilterConfig {
            cutoff_hz,
            sample_period_s: 1.0 / sample_rate_hz,
        };
        // Checked here so that the error names the key.
        TipFilter::new(filter).map_err(|e| ctx.err("tip.filter_cutoff_hz", e.to_string()))?;
        Some(filter)
    };

    Ok(Tip {
        max_std_n,
        sample_rate_hz,
        filter,
    })
}

/// `[loop]`.
fn loop_config(ctx: &Ctx<'_>, l: &LoopToml) -> Result<LoopConfig, ConfigError> {
    let rate_hz = ctx.range_f("loop.rate_hz", l.rate_hz, 100.0, 10_000.0, "Hz")?;
    let priority = ctx.range_i("loop.priority", l.priority, 1, 99)?;
    let cpu = match l.cpu {
        None => None,
        Some(c) => Some(ctx.range_i("loop.cpu", c, 0, 1023)?),
    };

    Ok(LoopConfig {
        rate_hz,
        // 100..=10000 Hz: 1e5..=1e7 ns.
        period_ns: (1e9 / rate_hz).round() as u64,
        priority: i32::try_from(priority).unwrap_or(1),
        cpu: cpu.and_then(|c| usize::try_from(c).ok()),
        publisher_stall_ns: (ctx.range_f(
            "loop.publisher_stall_s",
            l.publisher_stall_s,
            0.01,
            60.0,
            "s",
        )? * 1e9)
            .round() as u64,
    })
}

/// `[record]`.
fn record(ctx: &Ctx<'_>, rec: &RecordToml) -> Result<RecordSettings, ConfigError> {
    if rec.directory.is_empty() {
        return Err(ctx.err("record.directory", "must not be empty"));
    }
    let max_mb = ctx.range_f("record.max_file_mb", rec.max_file_mb, 0.0, 1e6, "MB")?;
    let max_s = ctx.range_f("record.max_file_s", rec.max_file_s, 0.0, 86_400.0, "s")?;
    let queue_capacity = ctx.range_i("record.queue_capacity", rec.queue_capacity, 1024, 1 << 24)?;
    let scene_hz = ctx.range_f("record.scene_hz", rec.scene_hz, 0.0, 1000.0, "Hz")?;
    let snapshot_s = ctx.range_f("record.snapshot_s", rec.snapshot_s, 0.01, 3600.0, "s")?;
    let mode = RecordMode::from_name(&rec.mode).ok_or_else(|| {
        ctx.err(
            "record.mode",
            format!("must be \"full\" or \"inputs\", got {:?}", rec.mode),
        )
    })?;
    Ok(RecordSettings {
        mode,
        scales: DeviceScales::default(),
        enabled: rec.enabled,
        directory: std::path::PathBuf::from(&rec.directory),
        rotation: Rotation {
            max_bytes: (max_mb > 0.0).then(|| (max_mb * 1e6).round() as u64),
            max_duration_ns: (max_s > 0.0).then(|| (max_s * 1e9).round() as u64),
        },
        queue_capacity: usize::try_from(queue_capacity).unwrap_or(65536),
        scene_period_ns: (scene_hz > 0.0).then(|| (1e9 / scene_hz).round() as u64),
        snapshot_period_ns: (snapshot_s * 1e9).round() as u64,
        config_source: None,
    })
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
        }
    }
}

/// `[force_control]`: the law's settings, with the sensor's and the loop's
/// rates and the axes' servo (`[axes] servo_bandwidth_hz`, `servo_damping`);
/// refused (naming the key) when out of range or not stable at
/// `max_stiffness_n_per_m` with `min_phase_margin_deg`.
fn force_control(
    ctx: &Ctx<'_>,
    t: &ForceControlToml,
    (sample_rate_hz, rate_hz): (f64, f64),
    (servo_bandwidth_hz, servo_damping): (f64, f64),
) -> Result<sar_estimator::force_control::ForceControlConfig, ConfigError> {
    use sar_estimator::force_control::{Admittance, ForceControlConfig, ForceControlLimits};
    let limits = ForceControlLimits {
        axial: Admittance {
            mass_kg: t.axial_mass_kg,
            damping_n_s_per_m: t.axial_damping_n_s_per_m,
        },
        lateral: Admittance {
            mass_kg: t.lateral_mass_kg,
            damping_n_s_per_m: t.lateral_damping_n_s_per_m,
        },
        max_speed_mps: t.max_speed_mps,
        max_accel_mps2: t.max_accel_mps2,
        max_excursion_m: t.max_excursion_m,
        hold_return_n_per_m: t.hold_return_n_per_m,
        filter_cutoff_hz: t.filter_cutoff_hz,
        sample_period_s: 1.0 / sample_rate_hz,
        period_s: 1.0 / rate_hz,
        other_delay_s: t.other_delay_s,
        max_stiffness_n_per_m: t.max_stiffness_n_per_m,
        min_phase_margin_deg: t.min_phase_margin_deg,
        servo_bandwidth_hz,
        servo_damping,
    };
    ForceControlConfig::new(limits).map_err(|e| {
        let field = match &e {
            sar_estimator::SettingError::Invalid { field, .. } => *field,
            _ => "",
        };
        let key = match field {
            "axial.mass_kg" => "axial_mass_kg",
            "axial.damping_n_s_per_m" => "axial_damping_n_s_per_m",
            "lateral.mass_kg" => "lateral_mass_kg",
            "lateral.damping_n_s_per_m" => "lateral_damping_n_s_per_m",
            "servo_bandwidth_hz" => return ctx.err("axes.servo_bandwidth_hz", e.to_string()),
            "servo_damping" => return ctx.err("axes.servo_damping", e.to_string()),
            other => other,
        };
        ctx.err(&join("force_control", key), e.to_string())
    })
}

/// Maps an estimator setting error to its key in `section`.
fn setting_error(ctx: &Ctx<'_>, section: &str, e: &sar_estimator::SettingError) -> ConfigError {
    let field = match e {
        sar_estimator::SettingError::Invalid { field, .. } => *field,
        _ => "",
    };
    let key = match field {
        "max_sensor_age_ns" => "max_sensor_age_s",
        "max_joints_age_ns" => "max_joints_age_s",
        "torque.noise_nm" => "torque_noise_nm",
        "torque.max_sigma" => "torque_max_sigma",
        other => other,
    };
    ctx.err(&join(section, key), e.to_string())
}

/// The support must be reachable: some U-joint position A within the travel
/// must be closer to B than the rod's length (the rod goes through B with
/// its tip beyond it), and not at B itself.
fn check_reach(
    ctx: &Ctx<'_>,
    cal: &Calibration,
    profile: &Profile,
    travel_m: &[(f64, f64); 3],
) -> Result<(), ConfigError> {
    // A = P_home + (q3, q2, q1) + a_off: a box in {0}.
    let base = cal.p_home_m() + cal.ujoint_offset_m();
    let (lo, hi) = (
        base + Vec3::new(travel_m[2].0, travel_m[1].0, travel_m[0].0),
        base + Vec3::new(travel_m[2].1, travel_m[1].1, travel_m[0].1),
    );
    let b = cal.support_m();
    let nearest = Vec3::new(
        b.x.clamp(lo.x, hi.x),
        b.y.clamp(lo.y, hi.y),
        b.z.clamp(lo.z, hi.z),
    );
    let distance_m = (b - nearest).norm();
    if distance_m >= profile.length_m() {
        return Err(ctx.err(
            "geometry.support",
            format!(
                "the carriage cannot reach the support: it is at least {distance_m:.4} m from \
                 every U-joint position in axes.travel_m, the rod is {:.4} m long",
                profile.length_m()
            ),
        ));
    }
    Ok(())
}

fn sensor_driver(ctx: &Ctx<'_>, s: Option<&SensorDriverToml>) -> Result<SensorDriver, ConfigError> {
    let Some(s) = s else {
        return Ok(SensorDriver::Sim);
    };
    match s.kind.as_str() {
        "sim" => refuse_given(ctx, "drivers.sensor", "the simulated sensor", &s.rdt_keys())
            .map(|()| SensorDriver::Sim),
        "rdt" => {
            let address = s
                .address
                .as_deref()
                .ok_or_else(|| ctx.err("drivers.sensor.address", "missing key"))?;
            let address: SocketAddr = address.parse().map_err(|_| {
                ctx.err(
                    "drivers.sensor.address",
                    format!(
                        "not an IP address with a port (e.g. \"192.168.1.1:49152\"): {address:?}"
                    ),
                )
            })?;
            let mut counts = [0.0; 2];
            for (slot, (key, v)) in counts.iter_mut().zip([
                ("counts_per_n", s.counts_per_n),
                ("counts_per_nm", s.counts_per_nm),
            ]) {
                let key = format!("drivers.sensor.{key}");
                let v = v.ok_or_else(|| ctx.err(&key, "missing key"))?;
                if v <= 0.0 {
                    return Err(ctx.err(&key, format!("must be > 0, got {v}")));
                }
                *slot = v;
            }
            Ok(SensorDriver::Rdt {
                address,
                counts_per_n: counts[0],
                counts_per_nm: counts[1],
            })
        }
        other => Err(ctx.err(
            "drivers.sensor.kind",
            format!("must be \"sim\" or \"rdt\", got {other:?}"),
        )),
    }
}

impl SensorDriverToml {
    /// The RDT sensor's keys, with whether each is given.
    fn rdt_keys(&self) -> [(&'static str, bool); 3] {
        [
            ("address", self.address.is_some()),
            ("counts_per_n", self.counts_per_n.is_some()),
            ("counts_per_nm", self.counts_per_nm.is_some()),
        ]
    }
}

impl AxesDriverToml {
    /// The CANopen drives' keys, with whether each is given.
    fn canopen_keys(&self) -> [(&'static str, bool); 6] {
        [
            ("interface", self.interface.is_some()),
            ("node_ids", self.node_ids.is_some()),
            ("lead_m", self.lead_m.is_some()),
            ("counts_per_turn", self.counts_per_turn.is_some()),
            (
                "quick_stop_decel_mps2",
                self.quick_stop_decel_mps2.is_some(),
            ),
            ("max_torque_permille", self.max_torque_permille.is_some()),
        ]
    }
}

/// Refuses the first key of `given` (`(key, given)`, under `section`) that
/// is given: not a key of `what` (the simulated device, `kind = "sim"`).
fn refuse_given(
    ctx: &Ctx<'_>,
    section: &str,
    what: &str,
    given: &[(&str, bool)],
) -> Result<(), ConfigError> {
    match given.iter().find(|(_, given)| *given) {
        Some((key, _)) => Err(ctx.err(
            &format!("{section}.{key}"),
            format!("not a key of {what} (kind = \"sim\")"),
        )),
        None => Ok(()),
    }
}

/// `[drivers.axes]`: the simulated axes (the default) or CANopen drives.
fn axes_driver(
    ctx: &Ctx<'_>,
    a: Option<&AxesDriverToml>,
    max_accel_mps2: f64,
) -> Result<AxesDriver, ConfigError> {
    let Some(a) = a else {
        return Ok(AxesDriver::Sim);
    };
    match a.kind.as_str() {
        "sim" => refuse_given(
            ctx,
            "drivers.axes",
            "the simulated axes",
            // The quick stop's deceleration is every drive's (drives_motion).
            &a.canopen_keys()
                .map(|(key, given)| (key, given && key != "quick_stop_decel_mps2")),
        )
        .map(|()| AxesDriver::Sim),
        "canopen" => canopen_axes(ctx, a, max_accel_mps2),
        other => Err(ctx.err(
            "drivers.axes.kind",
            format!("must be \"sim\" or \"canopen\", got {other:?}"),
        )),
    }
}

/// `[drivers.axes]` with `kind = "canopen"`: the bus, the nodes, the scale
/// and the drives' own limits (`max_accel_mps2`: the planned moves'
/// acceleration, which the drives' quick stop must at least match).
fn canopen_axes(
    ctx: &Ctx<'_>,
    a: &AxesDriverToml,
    max_accel_mps2: f64,
) -> Result<AxesDriver, ConfigError> {
    let interface = a
        .interface
        .clone()
        .ok_or_else(|| ctx.err("drivers.axes.interface", "missing key"))?;
    if interface.is_empty() || interface.len() > 15 {
        return Err(ctx.err(
            "drivers.axes.interface",
            format!("must be a network interface name of 1 to 15 bytes, got {interface:?}"),
        ));
    }
    let node_ids = canopen_node_ids(ctx, a)?;
    let lead_m = a
        .lead_m
        .ok_or_else(|| ctx.err("drivers.axes.lead_m", "missing key"))?;
    let lead_m = ctx.range_f("drivers.axes.lead_m", lead_m, 1e-5, 1.0, "m")?;
    let cpt = a
        .counts_per_turn
        .ok_or_else(|| ctx.err("drivers.axes.counts_per_turn", "missing key"))?;
    let cpt = ctx.range_i("drivers.axes.counts_per_turn", cpt, 1, i64::from(u32::MAX))?;
    // The drives' own quick stop brakes at least as hard as the
    // planned moves accelerate.
    let quick_stop_decel_mps2 = ctx.range_f(
        "drivers.axes.quick_stop_decel_mps2",
        a.quick_stop_decel_mps2
            .unwrap_or(DEFAULT_QUICK_STOP_DECEL_MPS2),
        max_accel_mps2,
        10.0,
        "m/s^2 (at least [axes] max_accel_mps2)",
    )?;
    let torque = ctx.range_i(
        "drivers.axes.max_torque_permille",
        a.max_torque_permille
            .unwrap_or(i64::from(DEFAULT_MAX_TORQUE_PERMILLE)),
        1,
        3000,
    )?;
    Ok(AxesDriver::Canopen {
        interface,
        node_ids,
        lead_m,
        counts_per_turn: u32::try_from(cpt).unwrap_or(1),
        quick_stop_decel_mps2,
        max_torque_permille: u16::try_from(torque).unwrap_or(DEFAULT_MAX_TORQUE_PERMILLE),
    })
}

/// `drivers.axes.node_ids`: three distinct CANopen node ids (1 to 127),
/// for q1, q2, q3.
fn canopen_node_ids(ctx: &Ctx<'_>, a: &AxesDriverToml) -> Result<[u8; 3], ConfigError> {
    let ids = a
        .node_ids
        .as_ref()
        .ok_or_else(|| ctx.err("drivers.axes.node_ids", "missing key"))?;
    let [q1, q2, q3] = ids.as_slice() else {
        return Err(ctx.err(
            "drivers.axes.node_ids",
            format!("must name 3 nodes (q1, q2, q3), got {}", ids.len()),
        ));
    };
    let mut node_ids = [0u8; 3];
    for (i, (slot, &id)) in node_ids.iter_mut().zip([q1, q2, q3]).enumerate() {
        let id = ctx.range_i(&format!("drivers.axes.node_ids[{i}]"), id, 1, 127)?;
        *slot = u8::try_from(id).unwrap_or(1);
    }
    let [n1, n2, n3] = node_ids;
    if n1 == n2 || n2 == n3 || n1 == n3 {
        return Err(ctx.err(
            "drivers.axes.node_ids",
            format!("the three node ids must differ, got {node_ids:?}"),
        ));
    }
    Ok(node_ids)
}
