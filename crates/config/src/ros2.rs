//! `[ros2]`: the ROS 2 bridge's settings (`sar-ros2`, a separate read-only
//! process; `sard` reads and checks the section but nothing of it): the DDS
//! domain, the local addresses DDS may use, and each topic's rate.
//!
//! ```toml
//! [ros2]
//! domain_id = 0                  # absent: ROS_DOMAIN_ID, else 0 (0..=232)
//! interfaces = ["127.0.0.1"]     # absent: every interface
//! estimate_hz = 100.0            # /sar/estimate/state at most 100 Hz
//! scene_hz = 30.0                # absent: [record] scene_hz
//! ```
//!
//! A topic's rate (`*_hz`, Hz, 0..=100000): absent, every message (the
//! loop's rate for the estimate); 0, not published; else at most that many
//! messages a second, decimated by the cycles' stamps. The guard's events
//! are never decimated; `/tf_static` is published once (transient local).

use crate::ConfigError;
use crate::toml_file::Ctx;
use serde::Deserialize;
use std::net::IpAddr;

/// `[ros2]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(crate) struct Ros2Toml {
    domain_id: Option<i64>,
    interfaces: Option<Vec<String>>,
    sensor_wrench_hz: Option<f64>,
    joints_hz: Option<f64>,
    estimate_hz: Option<f64>,
    tip_wrench_hz: Option<f64>,
    tip_wrench_filtered_hz: Option<f64>,
    passive_joints_hz: Option<f64>,
    sim_truth_hz: Option<f64>,
    scene_hz: Option<f64>,
}

/// Largest DDS domain id a ROS 2 participant can use (RTPS's port mapping
/// with ROS 2's participant limit).
pub const MAX_DOMAIN_ID: u16 = 232;

/// How often a topic is published.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TopicRate {
    /// Every message (the loop's rate for the per-cycle topics).
    Every,
    /// At most one message per this many ns, decimated by the cycles'
    /// stamps.
    PeriodNs(u64),
    /// Not published.
    Off,
}

impl TopicRate {
    fn of(ctx: &Ctx<'_>, key: &str, hz: Option<f64>) -> Result<Self, ConfigError> {
        let Some(hz) = hz else {
            return Ok(Self::Every);
        };
        if !(hz.is_finite() && (0.0..=100_000.0).contains(&hz)) {
            return Err(ctx.err(
                key,
                format!("must be within 0..=100000 Hz (0: not published), got {hz}"),
            ));
        }
        Ok(if hz == 0.0 {
            Self::Off
        } else {
            Self::PeriodNs((1e9 / hz).round() as u64)
        })
    }
}

/// Each topic's rate (`[ros2] *_hz`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ros2Rates {
    /// `/sar/sensor/wrench` (`sensor_wrench_hz`).
    pub sensor_wrench: TopicRate,
    /// `/sar/joints` (`joints_hz`).
    pub joints: TopicRate,
    /// `/sar/estimate/state` (`estimate_hz`).
    pub estimate: TopicRate,
    /// `/sar/estimate/tip_wrench` (`tip_wrench_hz`).
    pub tip_wrench: TopicRate,
    /// `/sar/estimate/tip_wrench_filtered` (`tip_wrench_filtered_hz`).
    pub tip_wrench_filtered: TopicRate,
    /// `/sar/estimate/passive_joints` (`passive_joints_hz`).
    pub passive_joints: TopicRate,
    /// `/sar/sim/tip_wrench_truth` (`sim_truth_hz`).
    pub sim_truth: TopicRate,
}

impl Default for Ros2Rates {
    fn default() -> Self {
        Self {
            sensor_wrench: TopicRate::Every,
            joints: TopicRate::Every,
            estimate: TopicRate::Every,
            tip_wrench: TopicRate::Every,
            tip_wrench_filtered: TopicRate::Every,
            passive_joints: TopicRate::Every,
            sim_truth: TopicRate::Every,
        }
    }
}

/// The bridge's settings (`[ros2]`), checked.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Ros2Settings {
    /// The DDS domain (`domain_id`); `None`: `ROS_DOMAIN_ID`, else 0.
    pub domain_id: Option<u16>,
    /// The local addresses DDS uses (`interfaces`); `None`: every
    /// interface.
    pub interfaces: Option<Vec<IpAddr>>,
    /// The per-cycle topics' rates.
    pub rates: Ros2Rates,
    /// The 3D scene (`/sar/scene`, `/sar/scene/status`, `/tf`) at most one
    /// per this many ns (`scene_hz`, default `[record] scene_hz`); `None`:
    /// none.
    pub scene_period_ns: Option<u64>,
}

/// Checks `[ros2]` (each error names its key); `record_scene_period_ns` is
/// `[record] scene_hz`'s period, the scene's default.
pub(crate) fn ros2(
    ctx: &Ctx<'_>,
    t: &Ros2Toml,
    record_scene_period_ns: Option<u64>,
) -> Result<Ros2Settings, ConfigError> {
    let domain_id = t
        .domain_id
        .map(|d| {
            u16::try_from(d)
                .ok()
                .filter(|d| *d <= MAX_DOMAIN_ID)
                .ok_or_else(|| {
                    ctx.err(
                        "ros2.domain_id",
                        format!("must be within 0..={MAX_DOMAIN_ID}, got {d}"),
                    )
                })
        })
        .transpose()?;
    let interfaces = t
        .interfaces
        .as_ref()
        .map(|list| {
            if list.is_empty() {
                return Err(ctx.err(
                    "ros2.interfaces",
                    "must name at least one local address (leave the key out for every interface)",
                ));
            }
            list.iter()
                .map(|a| {
                    a.parse::<IpAddr>().map_err(|_| {
                        ctx.err(
                            "ros2.interfaces",
                            format!("{a:?} is not an IP address (e.g. \"127.0.0.1\")"),
                        )
                    })
                })
                .collect::<Result<Vec<_>, _>>()
        })
        .transpose()?;
    let rates = Ros2Rates {
        sensor_wrench: TopicRate::of(ctx, "ros2.sensor_wrench_hz", t.sensor_wrench_hz)?,
        joints: TopicRate::of(ctx, "ros2.joints_hz", t.joints_hz)?,
        estimate: TopicRate::of(ctx, "ros2.estimate_hz", t.estimate_hz)?,
        tip_wrench: TopicRate::of(ctx, "ros2.tip_wrench_hz", t.tip_wrench_hz)?,
        tip_wrench_filtered: TopicRate::of(
            ctx,
            "ros2.tip_wrench_filtered_hz",
            t.tip_wrench_filtered_hz,
        )?,
        passive_joints: TopicRate::of(ctx, "ros2.passive_joints_hz", t.passive_joints_hz)?,
        sim_truth: TopicRate::of(ctx, "ros2.sim_truth_hz", t.sim_truth_hz)?,
    };
    let scene_period_ns = match t.scene_hz {
        None => record_scene_period_ns,
        Some(hz) => {
            let hz = ctx.range_f("ros2.scene_hz", hz, 0.0, 1000.0, "Hz")?;
            (hz > 0.0).then(|| (1e9 / hz).round() as u64)
        }
    };
    Ok(Ros2Settings {
        domain_id,
        interfaces,
        rates,
        scene_period_ns,
    })
}
