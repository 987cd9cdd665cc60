//! The 3D scene inside recordings: `sarctl replay --output OUT.mcap` (and
//! the daemon's recorder, which shares the writer) writes `/sar/scene`
//! (`visualization_msgs/msg/MarkerArray`), `/tf` and `/tf_static`
//! (`tf2_msgs/msg/TFMessage`) into the `ros2` file itself (every channel
//! `cdr` with a `ros2msg` schema and `offered_qos_profiles`; `/tf_static`
//! transient_local, once at the file's start), at 30 Hz of log time, each
//! scene drawn from the cycle it is stamped with: the U-joint where the
//! cycle's recorded state puts it, the rod from A's foot to the tip D, the
//! force arrow |F_tip| x the scale long in the guard's colour. The topics
//! themselves still replay bit for bit.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_msgs::msgs::{EstimatorState, RosMessage};
use sar_msgs::viz::{MarkerArray, TfMessage, marker_action};
use sar_record::replay::{ReplayOptions, replay_file};
use sar_scene::draw::{guard_color, ids};
use std::collections::BTreeMap;
use std::path::PathBuf;

#[test]
fn replay_outputs_carry_the_scene_of_their_cycles() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cfg = sar_config::load(&root.join("tests/fixtures/replay/config.toml")).unwrap();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("record_scene");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out.mcap");
    let mut options = ReplayOptions::from_config(&cfg);
    options.output = Some(out.clone());
    let report = replay_file(
        &root.join("tests/fixtures/replay/contact_daemon.mcap"),
        &options,
    )
    .unwrap();
    assert!(report.first_difference.is_none(), "{report:?}");

    let bytes = std::fs::read(&out).unwrap();
    let mut states: BTreeMap<u64, EstimatorState> = BTreeMap::new();
    let mut scenes: Vec<(u64, MarkerArray)> = Vec::new();
    let (mut tf, mut tf_static) = (0, Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        // The `ros2` file: CDR only, every channel with its QoS.
        assert_eq!(m.channel.message_encoding, "cdr", "{}", m.channel.topic);
        assert_eq!(
            m.channel.schema.as_ref().unwrap().encoding,
            "ros2msg",
            "{}",
            m.channel.topic
        );
        let qos = if m.channel.topic == "/tf_static" {
            sar_record::OFFERED_QOS_PROFILES_STATIC
        } else {
            sar_record::OFFERED_QOS_PROFILES
        };
        assert_eq!(
            m.channel
                .metadata
                .get("offered_qos_profiles")
                .map(String::as_str),
            Some(qos),
            "{}",
            m.channel.topic
        );
        match m.channel.topic.as_str() {
            "/sar/estimate/state" => {
                states.insert(m.log_time, EstimatorState::decode(&m.data).unwrap());
            }
            "/sar/scene" => {
                let schema = m.channel.schema.as_ref().unwrap();
                assert_eq!(schema.name, "visualization_msgs/msg/MarkerArray");
                scenes.push((m.log_time, MarkerArray::decode(&m.data).unwrap()));
            }
            "/tf" => tf += 1,
            "/tf_static" => tf_static.push((m.log_time, TfMessage::decode(&m.data).unwrap())),
            _ => {}
        }
    }
    // No companion file.
    assert!(!dir.join("out.scene.mcap").exists());
    // The fixed frames once, at the file's start: world -> base.
    assert_eq!(tf_static.len(), 1, "{tf_static:?}");
    let t = tf_static[0].1.transforms.as_slice()[0];
    assert_eq!(
        (t.frame_id.as_str(), t.child_frame_id.as_str()),
        ("world", "base")
    );
    assert!(tf_static[0].0 <= *states.keys().next().unwrap());
    let first = *states.keys().next().unwrap();
    let last = *states.keys().last().unwrap();
    let expected = (last - first) as f64 / 33_333_333.0;
    assert!(
        (scenes.len() as f64 - expected).abs() <= 2.0,
        "{} scenes over {expected:.1} periods",
        scenes.len()
    );
    assert_eq!(tf, scenes.len());
    let scale_m_per_n =
        sar_scene::geometry::SceneGeometry::from_config(&cfg.estimator).force_scale_m_per_n;
    let mut colours = std::collections::BTreeSet::new();
    let near = |a: [f64; 3], b: [f64; 3], tol: f64| (0..3).all(|i| (a[i] - b[i]).abs() < tol);
    for (t, scene) in &scenes {
        let state = states.get(t).expect("a scene at a cycle's stamp");
        let marker = |ns: &str, id: i32| {
            *scene
                .markers
                .as_slice()
                .iter()
                .find(|m| m.ns.as_str() == ns && m.id == id)
                .unwrap()
        };
        let ujoint = marker(ids::UJOINT, 0);
        let rod = marker(ids::ROD, 0);
        if state.flags & sar_msgs::msgs::flags::POSE_VALID != 0 {
            assert!(
                near(ujoint.pose.position_m, state.ujoint_m, 1e-12),
                "at {t}"
            );
            // The rod: from A's foot on the rod axis (d from A) to D.
            let p = rod.points_m.as_slice();
            assert!(
                near(p[1], state.tip_m, 1e-9),
                "at {t}: {p:?} vs {:?}",
                state.tip_m
            );
            let offset = (0..3)
                .map(|i| (p[0][i] - state.ujoint_m[i]).powi(2))
                .sum::<f64>();
            assert!((offset.sqrt() - cfg.estimator.profile.offset_m().abs()).abs() < 1e-9);
        } else {
            assert_eq!(rod.action, marker_action::DELETE, "at {t}");
        }
        let arrow = marker(ids::TIP_FORCE, 0);
        if arrow.action == marker_action::ADD {
            let c = arrow.color;
            assert_eq!(
                c,
                guard_color(u32::from(state.guard_state.code())),
                "at {t}"
            );
            colours.insert(state.guard_state.code());
            // From the tip, |F_tip| x the scale long, along F_tip.
            let p = arrow.points_m.as_slice();
            assert!(near(p[0], state.tip_m, 1e-12));
            let f = state.tip_force_n;
            let head: Vec<f64> = (0..3)
                .map(|i| state.tip_m[i] + f[i] * scale_m_per_n)
                .collect();
            assert!(near(p[1], [head[0], head[1], head[2]], 1e-12), "at {t}");
        }
    }
    // The fixture goes through Ok, Warn and Stop: the arrow's colour follows.
    assert!(colours.len() >= 2, "{colours:?}");
}
