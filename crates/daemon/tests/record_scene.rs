//! The live view's 3D scene beside recordings: `sarctl replay --output
//! OUT.mcap` (and the daemon's recorder, which shares the writer) writes
//! `/sar/scene` (`foxglove.SceneUpdate`) and `/sar/scene/tf` into the companion
//! file `OUT.scene.mcap`, never into the `ros2` file (whose channels stay all
//! `cdr` with `ros2msg` schemas and `offered_qos_profiles`), at 30 Hz
//! of log time, each scene drawn from the cycle it is stamped with: the
//! U-joint where the cycle's recorded state puts it, the force arrow in the
//! guard's colour, the limit spheres of the limits in use. The topics
//! themselves still replay bit for bit.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use foxglove::Decode;
use foxglove::messages::SceneUpdate;
use sar_msgs::msgs::{EstimatorState, RosMessage};
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
    let mut scenes: Vec<(u64, SceneUpdate)> = Vec::new();
    let mut tf = 0;
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
        assert_eq!(
            m.channel
                .metadata
                .get("offered_qos_profiles")
                .map(String::as_str),
            Some(sar_record::OFFERED_QOS_PROFILES),
            "{}",
            m.channel.topic
        );
        if m.channel.topic == "/sar/estimate/state" {
            states.insert(m.log_time, EstimatorState::decode(&m.data).unwrap());
        }
    }
    let scene_file = dir.join("out.scene.mcap");
    assert_eq!(sar_record::scene_path(&out), scene_file);
    let scene_bytes = std::fs::read(&scene_file).unwrap();
    for m in mcap::MessageStream::new(&scene_bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/sar/scene" => {
                let schema = m.channel.schema.as_ref().unwrap();
                assert_eq!(schema.name, "foxglove.SceneUpdate");
                assert_eq!(m.channel.message_encoding, "protobuf");
                scenes.push((m.log_time, SceneUpdate::decode(&m.data[..]).unwrap()));
            }
            "/sar/scene/tf" => tf += 1,
            _ => {}
        }
    }
    let first = *states.keys().next().unwrap();
    let last = *states.keys().last().unwrap();
    let expected = (last - first) as f64 / 33_333_333.0;
    assert!(
        (scenes.len() as f64 - expected).abs() <= 2.0,
        "{} scenes over {expected:.1} periods",
        scenes.len()
    );
    assert_eq!(tf, scenes.len());
    let mut colours = std::collections::BTreeSet::new();
    for (t, scene) in &scenes {
        let state = states.get(t).expect("a scene at a cycle's stamp");
        let entity = |id: &str| scene.entities.iter().find(|e| e.id == id).unwrap();
        let ujoint = entity(ids::UJOINT);
        if state.flags & sar_msgs::msgs::flags::POSE_VALID != 0 {
            let p = ujoint.spheres[0]
                .pose
                .as_ref()
                .unwrap()
                .position
                .as_ref()
                .unwrap();
            for (a, b) in [p.x, p.y, p.z].iter().zip(state.ujoint_m) {
                assert!((a - b).abs() < 1e-12, "at {t}: {a} vs {b}");
            }
        }
        let force = entity(ids::TIP_FORCE);
        if let Some(arrow) = force.arrows.first() {
            let c = arrow.color.as_ref().unwrap();
            let (r, g, b) = guard_color(u32::from(state.guard_state.code()));
            assert_eq!((c.r, c.g, c.b), (r, g, b), "at {t}");
            colours.insert(state.guard_state.code());
        }
    }
    // The fixture goes through Ok, Warn and Stop: the arrow's colour follows.
    assert!(colours.len() >= 2, "{colours:?}");
}
