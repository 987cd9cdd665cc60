//! The 3D scene in recordings: `sarctl replay --output OUT.mcap` (and the
//! daemon's recorder, which shares the writer) writes `/sar/scene`
//! (`visualization_msgs/msg/MarkerArray`), `/tf` and `/tf_static`
//! (`tf2_msgs/msg/TFMessage`) into the `ros2` file itself (every channel
//! `cdr` with a `ros2msg` schema and `offered_qos_profiles`; `/tf_static`
//! transient local), at 30 Hz of log time, each scene drawn from the cycle
//! it is stamped with: the U-joint where the cycle's recorded state puts it,
//! the rod from A's foot to the tip, the force arrow |F_tip| x scale long in
//! the guard's colour. The topics themselves still replay bit for bit.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_msgs::msgs::{EstimatorState, RosMessage};
use sar_msgs::scene::{MarkerArray, TfMessage, action};
use sar_record::replay::{ReplayOptions, replay_file};
use sar_scene::draw::{FRAME_BASE, FRAME_WORLD, guard_color, ids};
use sar_scene::geometry::SceneGeometry;
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
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "ros2msg", "{}", m.channel.topic);
        let qos = m
            .channel
            .metadata
            .get("offered_qos_profiles")
            .map(String::as_str);
        let expected_qos = if m.channel.topic == "/tf_static" {
            sar_record::OFFERED_QOS_PROFILES_LATCHED
        } else {
            sar_record::OFFERED_QOS_PROFILES
        };
        assert_eq!(qos, Some(expected_qos), "{}", m.channel.topic);
        match m.channel.topic.as_str() {
            "/sar/estimate/state" => {
                states.insert(m.log_time, EstimatorState::decode(&m.data).unwrap());
            }
            "/sar/scene" => {
                assert_eq!(schema.name, "visualization_msgs/msg/MarkerArray");
                scenes.push((m.log_time, MarkerArray::decode(&m.data).unwrap()));
            }
            "/tf" => {
                assert_eq!(schema.name, "tf2_msgs/msg/TFMessage");
                TfMessage::decode(&m.data).unwrap();
                tf += 1;
            }
            "/tf_static" => tf_static.push((m.log_time, TfMessage::decode(&m.data).unwrap())),
            _ => {}
        }
    }
    assert!(!dir.join("out.scene.mcap").exists(), "no companion file");
    let first = *states.keys().next().unwrap();
    let last = *states.keys().last().unwrap();
    let expected = (last - first) as f64 / 33_333_333.0;
    assert!(
        (scenes.len() as f64 - expected).abs() <= 2.0,
        "{} scenes over {expected:.1} periods",
        scenes.len()
    );
    assert_eq!(tf, scenes.len());
    // The fixed frame once, before the first scene: world -> base.
    assert_eq!(tf_static.len(), 1);
    assert!(tf_static[0].0 <= scenes[0].0);
    let fixed = &tf_static[0].1.transforms[0];
    assert_eq!(
        (fixed.parent.as_str(), fixed.child.as_str()),
        (FRAME_WORLD, FRAME_BASE)
    );
    let g = SceneGeometry::from_config(&cfg.estimator);
    let mut colours = std::collections::BTreeSet::new();
    for (t, scene) in &scenes {
        let state = states.get(t).expect("a scene at a cycle's stamp");
        let marker = |ns: &str, id: i32| {
            scene
                .markers
                .iter()
                .find(|m| m.ns == ns && m.id == id)
                .unwrap()
        };
        let ujoint = marker(ids::UJOINT, 0);
        let rod = marker(ids::ROD, 0);
        if state.flags & sar_msgs::msgs::flags::POSE_VALID != 0 {
            assert_eq!(ujoint.action, action::ADD);
            for (a, b) in ujoint.position_m.iter().zip(state.ujoint_m) {
                assert!((a - b).abs() < 1e-12, "at {t}: {a} vs {b}");
            }
            // The rod: a cylinder L long, centred between A's foot (A here:
            // d = 0) and the tip.
            assert_eq!(rod.scale_m[2], g.length_m);
            for k in 0..3 {
                let mid = 0.5 * (state.ujoint_m[k] + state.tip_m[k]);
                assert!((rod.position_m[k] - mid).abs() < 1e-9, "at {t}");
            }
        } else {
            assert_eq!(ujoint.action, action::DELETE);
        }
        let arrow = marker(ids::TIP_FORCE, 0);
        if arrow.action == action::ADD {
            assert_eq!(
                arrow.color,
                guard_color(u32::from(state.guard_state.code())),
                "at {t}"
            );
            let [from, to] = [arrow.points_m[0], arrow.points_m[1]];
            let length_m = (0..3)
                .map(|k| (to[k] - from[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let f = state.tip_force_n;
            let force_n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            assert!(
                (length_m - force_n * g.force_scale_m_per_n).abs() < 1e-12,
                "at {t}"
            );
            colours.insert(state.guard_state.code());
        }
    }
    // The fixture goes through Ok, Warn and Stop: the arrow's colour follows.
    assert!(colours.len() >= 2, "{colours:?}");
}
