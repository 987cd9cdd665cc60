//! The file's shape as serde reads it. Every table refuses unknown keys, so a
//! typo is an error, never a silently ignored value. Values are checked later
//! (`super::build`), where each check names its key.

use serde::Deserialize;

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FileToml {
    pub name: String,
    #[serde(default)]
    pub description: Option<String>,
    pub seed: u64,
    #[serde(default)]
    pub physics_step_s: Option<f64>,
    pub robot: RobotToml,
    pub manipulator: ManipulatorToml,
    #[serde(default)]
    pub support: Option<SupportToml>,
    #[serde(default)]
    pub axes: Option<AxesToml>,
    #[serde(default)]
    pub sensor: Option<SensorToml>,
    #[serde(default)]
    pub motion: Vec<MotionToml>,
    #[serde(default)]
    pub random_motion: Option<RandomMotionToml>,
    #[serde(default)]
    pub contact: Vec<ContactToml>,
    #[serde(default)]
    pub tissue: Vec<TissueToml>,
    #[serde(default)]
    pub tip_mass: Option<TipMassToml>,
    #[serde(default)]
    pub fault: Vec<FaultToml>,
    #[serde(default)]
    pub support_shift: Vec<SupportShiftToml>,
}

/// `[robot]`: the true geometry, with the keys of INTERFACES.md 2 `[geometry]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RobotToml {
    #[serde(deserialize_with = "crate::exact::array")]
    pub gravity: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub support: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub p_home: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub ujoint_offset: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub sensor_offset: [f64; 3],
    #[serde(deserialize_with = "crate::exact::rows")]
    pub sensor_rotation: [[f64; 3]; 3],
}

/// `[manipulator]`: the true manipulator.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ManipulatorToml {
    #[serde(default)]
    pub name: Option<String>,
    pub length_m: f64,
    pub offset_m: f64,
    pub mass_kg: f64,
    pub com_m: f64,
    pub inertia_perp_kgm2: Option<f64>,
    pub inertia_axial_kgm2: Option<f64>,
}

/// `[support]`: the support's friction.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SupportToml {
    pub friction_n: f64,
}

/// `[axes]`: every key optional (defaults: the article's axes).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct AxesToml {
    pub max_speed_mps: Option<f64>,
    pub max_accel_mps2: Option<f64>,
    pub lead_m_per_turn: Option<f64>,
    pub counts_per_turn: Option<u32>,
    pub position_rate_hz: Option<f64>,
    #[serde(default, deserialize_with = "crate::exact::option_rows")]
    pub travel_m: Option<[[f64; 2]; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub start: Option<[f64; 3]>,
    pub servo_bandwidth_hz: Option<f64>,
    pub servo_damping: Option<f64>,
    pub servo_max_accel_mps2: Option<f64>,
    pub servo_delay_s: Option<f64>,
    pub servo_inner_loop_hz: Option<f64>,
    pub quick_stop_decel_mps2: Option<f64>,
}

/// `[sensor]`: every key optional (defaults: the HEX-6 of the article).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SensorToml {
    pub rate_hz: Option<f64>,
    pub latency_s: Option<f64>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub noise_n: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub noise_nm: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub bias_n: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub bias_nm: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub drift_n_per_s: Option<[f64; 3]>,
    pub has_tare: Option<bool>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub range_n: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub range_nm: Option<[f64; 3]>,
    pub adapter_mass_kg: Option<f64>,
    pub counts_per_n: Option<f64>,
    pub counts_per_nm: Option<f64>,
}

/// `[[motion]]`: one step; exactly one target.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MotionToml {
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub joints: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub ujoint: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub tip: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub rod_dir: Option<[f64; 3]>,
    pub support_distance_m: Option<f64>,
    pub hold_s: Option<f64>,
}

/// `[random_motion]`: random tip targets after the `[[motion]]` steps.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RandomMotionToml {
    pub count: u32,
    pub max_angle_deg: f64,
    #[serde(deserialize_with = "crate::exact::array")]
    pub beyond_m: [f64; 2],
    pub hold_s: f64,
}

/// `[[contact]]`: one keyframe of the tip force.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ContactToml {
    pub t_s: f64,
    #[serde(deserialize_with = "crate::exact::array")]
    pub force_n: [f64; 3],
}

/// The spring law of a `[[tissue]]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum TissueModelName {
    Linear,
    Exponential,
}

/// `[[support_shift]]`: the true support point moving (issue 26).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SupportShiftToml {
    pub t_s: f64,
    #[serde(deserialize_with = "crate::exact::array")]
    pub shift_m: [f64; 3],
    #[serde(default)]
    pub duration_s: f64,
}

/// `[[tissue.shift]]`: a sudden shift of the tissue's rest point.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ShiftToml {
    pub t_s: f64,
    pub offset_m: f64,
}

/// `[[tissue]]`: a tissue that pushes back on the tip.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TissueToml {
    #[serde(deserialize_with = "crate::exact::array")]
    pub direction: [f64; 3],
    #[serde(deserialize_with = "crate::exact::array")]
    pub rest_m: [f64; 3],
    pub model: Option<TissueModelName>,
    pub stiffness_n_per_m: f64,
    pub beta_per_m: Option<f64>,
    pub damping_n_s_per_m: Option<f64>,
    pub breathing_amplitude_m: Option<f64>,
    pub breathing_hz: Option<f64>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub breathing_direction: Option<[f64; 3]>,
    #[serde(default)]
    pub shift: Vec<ShiftToml>,
}

/// `[tip_mass]`: a known mass hung at the tip.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TipMassToml {
    pub mass_kg: f64,
}

/// The kinds of `[[fault]]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum FaultKind {
    SensorSilent,
    NanSample,
    EncoderJump,
    DriveFault,
    SensorFrozen,
    SensorSaturated,
    SensorSpike,
    SensorDrift,
    SensorScale,
    EncoderFrozen,
    EncoderCountLoss,
    DriveHeartbeatLoss,
    DriveEmcy,
}

/// A channel of the force/torque sensor by its name (sensor frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum ChannelName {
    Fx,
    Fy,
    Fz,
    Tx,
    Ty,
    Tz,
}

/// An end of the measuring range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum RailName {
    Positive,
    Negative,
}

/// An axis by its joint name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum AxisName {
    Q1,
    Q2,
    Q3,
}

/// `[[fault]]`: one fault; which keys it takes depends on `kind` (checked later,
/// so that the error names the key).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FaultToml {
    pub kind: FaultKind,
    pub from_s: Option<f64>,
    pub until_s: Option<f64>,
    pub at_s: Option<f64>,
    pub axis: Option<AxisName>,
    pub jump_m: Option<f64>,
    pub code: Option<u16>,
    pub axes: Option<Vec<ChannelName>>,
    pub rail: Option<RailName>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub force_n: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub torque_nm: Option<[f64; 3]>,
    pub samples: Option<u32>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub drift_n_per_s: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "crate::exact::option_array")]
    pub drift_nm_per_s: Option<[f64; 3]>,
    pub factor: Option<f64>,
    pub counts: Option<i32>,
}
