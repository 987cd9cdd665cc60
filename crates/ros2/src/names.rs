//! ROS 2's names on DDS (the conventions of `rmw_cyclonedds_cpp` and
//! `rmw_fastrtps_cpp`): a topic `/a/b` is the DDS topic `rt/a/b`, and a
//! message type `pkg/msg/Type` is the DDS type `pkg::msg::dds_::Type_`.

/// Why a name cannot go on DDS as ROS 2 names it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// A topic name that is not absolute, or has an empty part.
    #[error("topic {0:?} is not a ROS 2 topic name (/part/part, each part [A-Za-z0-9_])")]
    Topic(String),
    /// A type name that is not `pkg/msg/Type`.
    #[error("type {0:?} is not a ROS 2 message type (pkg/msg/Type)")]
    Type(String),
}

fn is_part(p: &str) -> bool {
    !p.is_empty()
        && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !p.starts_with(|c: char| c.is_ascii_digit())
}

/// The DDS topic of a ROS 2 topic: `/sar/estimate/state` ->
/// `rt/sar/estimate/state`.
pub fn dds_topic(ros_topic: &str) -> Result<String, NameError> {
    let rest = ros_topic
        .strip_prefix('/')
        .filter(|r| r.split('/').all(is_part))
        .ok_or_else(|| NameError::Topic(ros_topic.to_owned()))?;
    Ok(format!("rt/{rest}"))
}

/// The DDS type of a ROS 2 message type: `sar_msgs/msg/EstimatorState` ->
/// `sar_msgs::msg::dds_::EstimatorState_`.
pub fn dds_type(ros_type: &str) -> Result<String, NameError> {
    let mut parts = ros_type.split('/');
    match (parts.next(), parts.next(), parts.next(), parts.next()) {
        (Some(pkg), Some("msg"), Some(name), None) if is_part(pkg) && is_part(name) => {
            Ok(format!("{pkg}::msg::dds_::{name}_"))
        }
        _ => Err(NameError::Type(ros_type.to_owned())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_and_types_are_mangled_as_ros2_does() {
        assert_eq!(
            dds_topic("/sar/estimate/state").as_deref(),
            Ok("rt/sar/estimate/state")
        );
        assert_eq!(dds_topic("/tf_static").as_deref(), Ok("rt/tf_static"));
        for bad in ["sar/x", "/", "/a//b", "/a/", "/a b", "/9a"] {
            assert!(dds_topic(bad).is_err(), "{bad}");
        }
        assert_eq!(
            dds_type("sar_msgs/msg/EstimatorState").as_deref(),
            Ok("sar_msgs::msg::dds_::EstimatorState_")
        );
        assert_eq!(
            dds_type("geometry_msgs/msg/WrenchStamped").as_deref(),
            Ok("geometry_msgs::msg::dds_::WrenchStamped_")
        );
        assert_eq!(
            dds_type("tf2_msgs/msg/TFMessage").as_deref(),
            Ok("tf2_msgs::msg::dds_::TFMessage_")
        );
        for bad in ["sar_msgs/EstimatorState", "a/srv/B", "a/msg/B/c", "/msg/B"] {
            assert!(dds_type(bad).is_err(), "{bad}");
        }
    }
}
