//! `sar-ros2`: the daemon's outputs on a ROS 2 network, read-only, in a
//! process of its own. It subscribes to the daemon's state over iceoryx2
//! like `sarctl monitor` (a member of the operators' group; a slow or
//! stalled bridge loses states, never makes the loop wait) and publishes on
//! a DDS domain with ROS 2's conventions: the topics of a full recording
//! and the 3D scene, with the recordings' types and CDR, values equal to a
//! recording of the same cycle.
//!
//! - [`names`]: ROS 2's names on DDS (`rt/` topics, `pkg::msg::dds_::Type_`).
//! - [`topics`]: what is published and with which QoS.
//! - [`plan`]: what each state gives (pure, no DDS): the recording's
//!   messages (`sar_scene::topics::messages`), decimated per topic, and the
//!   scene drawn as the recorder draws it.
//! - [`dds`]: the DDS participant and writers (RustDDS, pure Rust).
//! - [`run`]: the process: domain, subscription, summary.
//!
//! Read-only by construction: it holds a state subscription and DDS
//! writers, no DDS reader and no command port (the daemon's command service
//! is never opened; a test checks the sources). `sard` does not link it.

pub mod dds;
pub mod names;
pub mod plan;
pub mod run;
pub mod topics;

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    /// Read-only by construction: no source of the bridge sends a command
    /// to the daemon or reads anything from DDS. (The needles are built at
    /// run time so that this test's own text does not hold them.)
    #[test]
    fn the_bridge_never_commands_the_daemon_nor_reads_dds() {
        let needles: Vec<String> = [
            ("Client::", "command"),
            (".command", "("),
            ("Command", "Msg"),
            ("request_", "response"),
            ("create_data", "reader"),
            ("create_sub", "scriber"),
        ]
        .iter()
        .map(|(a, b)| format!("{a}{b}"))
        .collect();
        let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut files = 0;
        for entry in std::fs::read_dir(src).unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap();
            files += 1;
            for n in &needles {
                assert!(!text.contains(n.as_str()), "{} holds {n}", path.display());
            }
        }
        assert!(files >= 6, "{files} sources");
    }
}
