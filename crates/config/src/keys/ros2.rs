//! `[ros2]`: the ROS 2 bridge's settings (`sar-ros2`, a separate read-only
//! process; `sard` reads and checks the section but nothing of it): the DDS
//! domain, the local addresses DDS may use, and each topic's rate.
//!
//! A topic's rate (`*_hz`): absent, every message (the loop's rate for the
//! estimate); 0, not published; else at most that many messages a second,
//! decimated by the cycles' stamps. The guard's events are never
//! decimated; `/tf_static` is published once (transient local).

use crate::ConfigError;
use crate::decl::{int, num, text};
use crate::toml_file::Ctx;
use std::net::IpAddr;

/// Largest DDS domain id a ROS 2 participant can use (RTPS's port mapping
/// with ROS 2's participant limit).
pub const MAX_DOMAIN_ID: u16 = 232;

/// A topic's rate: absent, every message; 0, not published.
const TOPIC_HZ: crate::decl::Range = num(0.0, 100_000.0, "Hz");

crate::section! {
    /// The ROS 2 bridge (sar-ros2; sard only checks it): the DDS domain, the addresses, each topic's rate.
    section "ros2";
    /// the DDS domain
    domain_id: i64 = absent("ROS_DOMAIN_ID, else 0", 0),
        int(0, MAX_DOMAIN_ID as i64, "") => [Ros2Settings.domain_id];
    /// the local addresses DDS uses
    interfaces: Vec<String> = absent("every interface", ["127.0.0.1"]),
        text("IP addresses, at least one") => [Ros2Settings.interfaces];
    /// /sar/sensor/wrench at most this often (0: not published)
    sensor_wrench_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.sensor_wrench];
    /// /sar/joints at most this often (0: not published)
    joints_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.joints];
    /// /sar/estimate/state at most this often (0: not published)
    estimate_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.estimate];
    /// /sar/estimate/tip_wrench at most this often (0: not published)
    tip_wrench_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.tip_wrench];
    /// /sar/estimate/tip_wrench_filtered at most this often (0: not published)
    tip_wrench_filtered_hz: f64 = absent("every message", 100.0),
        TOPIC_HZ => [Ros2Rates.tip_wrench_filtered];
    /// /sar/estimate/passive_joints at most this often (0: not published)
    passive_joints_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.passive_joints];
    /// /sar/sim/tip_wrench_truth at most this often (0: not published)
    sim_truth_hz: f64 = absent("every message", 100.0), TOPIC_HZ => [Ros2Rates.sim_truth];
    /// the 3D scene (/sar/scene, /sar/scene/status, /tf) at most this often (0: none)
    scene_hz: f64 = absent("[record] scene_hz", 30.0),
        num(0.0, 1000.0, "Hz") => [Ros2Settings.scene_period_ns];
}

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
    /// The rate of a `*_hz` key (within its range).
    fn of(hz: Option<f64>) -> Self {
        match hz {
            None => Self::Every,
            Some(hz) => {
                if hz == 0.0 {
                    Self::Off
                } else {
                    Self::PeriodNs((1e9 / hz).round() as u64)
                }
            }
        }
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

/// `[ros2]` (the addresses checked, each error under its key);
/// `record_scene_period_ns` is `[record] scene_hz`'s period, the scene's
/// default.
pub(crate) fn build(
    ctx: &Ctx<'_>,
    t: &Section,
    record_scene_period_ns: Option<u64>,
) -> Result<Ros2Settings, ConfigError> {
    let key = KEY.interfaces.key;
    let interfaces = t
        .interfaces
        .as_ref()
        .map(|list| {
            if list.is_empty() {
                return Err(ctx.err(
                    key,
                    "must name at least one local address (leave the key out for every interface)",
                ));
            }
            list.iter()
                .map(|a| {
                    a.parse::<IpAddr>().map_err(|_| {
                        ctx.err(
                            key,
                            format!("{a:?} is not an IP address (e.g. \"127.0.0.1\")"),
                        )
                    })
                })
                .collect::<Result<Vec<_>, _>>()
        })
        .transpose()?;
    Ok(Ros2Settings {
        domain_id: t.domain_id.and_then(|d| u16::try_from(d).ok()),
        interfaces,
        rates: Ros2Rates {
            sensor_wrench: TopicRate::of(t.sensor_wrench_hz),
            joints: TopicRate::of(t.joints_hz),
            estimate: TopicRate::of(t.estimate_hz),
            tip_wrench: TopicRate::of(t.tip_wrench_hz),
            tip_wrench_filtered: TopicRate::of(t.tip_wrench_filtered_hz),
            passive_joints: TopicRate::of(t.passive_joints_hz),
            sim_truth: TopicRate::of(t.sim_truth_hz),
        },
        scene_period_ns: match t.scene_hz {
            None => record_scene_period_ns,
            Some(hz) => (hz > 0.0).then(|| (1e9 / hz).round() as u64),
        },
    })
}
