//! `[axes]` and `[sensor]`: every key optional, defaults the article's axes
//! and the HEX-6 of MODEL.md 7; each value checked under its own key.

use super::raw::{AxesToml, SensorToml};
use super::{
    ConfigError, DEFAULT_COUNTS_PER_TURN, DEFAULT_LEAD_M_PER_TURN, DEFAULT_MAX_ACCEL_MPS2,
    DEFAULT_MAX_SPEED_MPS, DEFAULT_NOISE_N, DEFAULT_NOISE_NM, DEFAULT_POSITION_RATE_HZ,
    DEFAULT_RANGE_N, DEFAULT_RANGE_NM, DEFAULT_SENSOR_LATENCY_S, DEFAULT_SENSOR_RATE_HZ,
    DEFAULT_TRAVEL_M,
};
use crate::toml_file::Ctx;
use sar_hal::Vec3;
use sar_kinematics::ActiveJoints;
use sar_sim::{AxesSpec, SensorSpec};

/// `[axes]`, checked (the start is checked later, against the kinematics).
pub(super) struct Axes {
    pub max_speed_mps: f64,
    pub max_accel_mps2: f64,
    pub lead_m_per_turn: f64,
    pub counts_per_turn: u32,
    pub position_period_ns: u64,
    pub travel_m: [(f64, f64); 3],
    pub start: Option<[f64; 3]>,
}

impl Axes {
    /// One encoder count, m.
    pub fn count_m(&self) -> f64 {
        self.lead_m_per_turn / f64::from(self.counts_per_turn)
    }

    /// The simulator's axes, starting at `start`.
    pub fn spec(&self, start: ActiveJoints) -> AxesSpec {
        AxesSpec {
            max_speed_mps: self.max_speed_mps,
            drive_max_speed_mps: None,
            max_accel_mps2: self.max_accel_mps2,
            lead_m_per_turn: self.lead_m_per_turn,
            counts_per_turn: self.counts_per_turn,
            position_period_ns: self.position_period_ns,
            travel_m: self.travel_m,
            start,
        }
    }
}

/// `[axes]` with its defaults.
pub(super) fn axes(ctx: &Ctx<'_>, axes: &AxesToml) -> Result<Axes, ConfigError> {
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
    Ok(Axes {
        max_speed_mps,
        max_accel_mps2,
        lead_m_per_turn,
        counts_per_turn,
        position_period_ns,
        travel_m,
        start: axes.start,
    })
}

/// `[sensor]` with its defaults.
pub(super) fn sensor(ctx: &Ctx<'_>, sensor: &SensorToml) -> Result<SensorSpec, ConfigError> {
    let period_ns = ctx.period_ns(
        "sensor.rate_hz",
        sensor.rate_hz.unwrap_or(DEFAULT_SENSOR_RATE_HZ),
    )?;
    let latency_ns = ctx.time_ns(
        "sensor.latency_s",
        sensor.latency_s.unwrap_or(DEFAULT_SENSOR_LATENCY_S),
    )?;
    Ok(SensorSpec {
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
        range_n: positive3(
            ctx,
            "sensor.range_n",
            sensor.range_n.unwrap_or(DEFAULT_RANGE_N),
            "N",
        )?,
        range_nm: positive3(
            ctx,
            "sensor.range_nm",
            sensor.range_nm.unwrap_or(DEFAULT_RANGE_NM),
            "N m",
        )?,
        counts_per_n: match sensor.counts_per_n {
            Some(v) => ctx.positive("sensor.counts_per_n", v, "counts/N")?,
            None => 0.0,
        },
        counts_per_nm: match sensor.counts_per_nm {
            Some(v) => ctx.positive("sensor.counts_per_nm", v, "counts/(N m)")?,
            None => 0.0,
        },
    })
}

fn positive3(ctx: &Ctx<'_>, key: &str, v: [f64; 3], unit: &str) -> Result<Vec3, ConfigError> {
    for (i, x) in v.iter().enumerate() {
        ctx.positive(&format!("{key}[{i}]"), *x, unit)?;
    }
    Ok(Vec3::from(v))
}
