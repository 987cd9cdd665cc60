//! What the bridge publishes: the topics of a full recording (section 1 of
//! INTERFACES.md) but the step's input, and the 3D scene, each with its ROS 2
//! type and the QoS a ROS 2 user expects of it ([`Qos`]).

use sar_config::{Ros2Rates, TopicRate};
use sar_msgs::msgs::{RosMessage, SceneStatus, Topic};
use sar_msgs::scene::{MarkerArray, TfMessage};

/// A topic's quality of service, as ROS 2's publishers of its kind offer it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Qos {
    /// rclcpp's `SensorDataQoS`: best effort, keep last 5, volatile. A
    /// slow reader loses samples; nothing waits for it.
    SensorData,
    /// ROS 2's default: reliable, keep last `depth`, volatile (rviz2's
    /// displays and tf2's listener subscribe reliably; a best-effort
    /// subscriber matches it too).
    Reliable {
        /// History depth.
        depth: i32,
    },
    /// Reliable, transient local, keep last `depth`: a subscriber that
    /// joins later gets the last `depth` messages (tf2's
    /// `StaticTransformBroadcaster` offers `/tf_static` so, depth 1).
    Latched {
        /// History depth.
        depth: i32,
    },
}

impl Qos {
    /// The history depth.
    pub fn depth(self) -> i32 {
        match self {
            Qos::SensorData => 5,
            Qos::Reliable { depth } | Qos::Latched { depth } => depth,
        }
    }

    /// `offered_qos_profiles`' reliability: reliable or not.
    pub fn reliable(self) -> bool {
        !matches!(self, Qos::SensorData)
    }

    /// Transient local (a late joiner gets the history).
    pub fn transient_local(self) -> bool {
        matches!(self, Qos::Latched { .. })
    }
}

/// One published topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Published {
    /// A recording's per-cycle topic.
    Record(Topic),
    /// `/sar/scene` (`visualization_msgs/msg/MarkerArray`).
    Scene,
    /// `/sar/scene/status` (`sar_msgs/msg/SceneStatus`).
    SceneStatus,
    /// `/tf` (`tf2_msgs/msg/TFMessage`).
    Tf,
    /// `/tf_static` (`tf2_msgs/msg/TFMessage`), once.
    TfStatic,
}

/// The recordings' topics the bridge publishes (a full recording's but the
/// step's input, the snapshots and the recorder's own account).
pub const RECORD_TOPICS: [Topic; 8] = [
    Topic::SensorWrench,
    Topic::Joints,
    Topic::EstimatorState,
    Topic::TipWrench,
    Topic::TipWrenchFiltered,
    Topic::PassiveJoints,
    Topic::GuardEvents,
    Topic::SimTipWrenchTruth,
];

/// Every published topic, in the order of the bridge's writers.
pub const ALL: [Published; 12] = [
    Published::Record(Topic::SensorWrench),
    Published::Record(Topic::Joints),
    Published::Record(Topic::EstimatorState),
    Published::Record(Topic::TipWrench),
    Published::Record(Topic::TipWrenchFiltered),
    Published::Record(Topic::PassiveJoints),
    Published::Record(Topic::GuardEvents),
    Published::Record(Topic::SimTipWrenchTruth),
    Published::Scene,
    Published::SceneStatus,
    Published::Tf,
    Published::TfStatic,
];

/// Depth of the guard's events kept for a subscriber that joins later
/// (ROS 2's default depth).
pub const GUARD_EVENTS_DEPTH: i32 = 10;

impl Published {
    /// The ROS 2 topic name.
    pub fn name(self) -> &'static str {
        match self {
            Published::Record(t) => t.name(),
            Published::Scene => sar_scene::SCENE_TOPIC,
            Published::SceneStatus => sar_scene::SCENE_STATUS_TOPIC,
            Published::Tf => sar_scene::TF_TOPIC,
            Published::TfStatic => sar_scene::TF_STATIC_TOPIC,
        }
    }

    /// The ROS 2 type, `pkg/msg/Type`.
    pub fn type_name(self) -> &'static str {
        match self {
            Published::Record(t) => t.type_name(),
            Published::Scene => MarkerArray::TYPE_NAME,
            Published::SceneStatus => SceneStatus::TYPE_NAME,
            Published::Tf | Published::TfStatic => TfMessage::TYPE_NAME,
        }
    }

    /// Its QoS: the per-cycle topics as sensor data; the guard's events
    /// reliable and transient local (a late joiner sees the last
    /// transitions); the scene as rviz2 and tf2 subscribe (reliable, `/tf`
    /// keep last 100 as tf2's broadcaster); `/tf_static` latched, depth 1.
    pub fn qos(self) -> Qos {
        match self {
            Published::Record(Topic::GuardEvents) => Qos::Latched {
                depth: GUARD_EVENTS_DEPTH,
            },
            Published::Record(_) => Qos::SensorData,
            Published::Scene | Published::SceneStatus => Qos::Reliable { depth: 5 },
            Published::Tf => Qos::Reliable { depth: 100 },
            Published::TfStatic => Qos::Latched { depth: 1 },
        }
    }

    /// Its place in [`ALL`].
    pub fn index(self) -> usize {
        ALL.iter().position(|p| *p == self).unwrap_or(0)
    }
}

/// A recording topic's configured rate (`[ros2] *_hz`); the guard's events
/// are never decimated.
pub fn rate_of(rates: &Ros2Rates, topic: Topic) -> TopicRate {
    match topic {
        Topic::SensorWrench => rates.sensor_wrench,
        Topic::Joints => rates.joints,
        Topic::EstimatorState => rates.estimate,
        Topic::TipWrench => rates.tip_wrench,
        Topic::TipWrenchFiltered => rates.tip_wrench_filtered,
        Topic::PassiveJoints => rates.passive_joints,
        Topic::SimTipWrenchTruth => rates.sim_truth,
        _ => TopicRate::Every,
    }
}
