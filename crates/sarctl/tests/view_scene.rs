//! The 3D scene as a pure function (no processes): the rod's ends against
//! `sar_kinematics::forward` also with a rod offset d != 0, the arrow along
//! the force in every direction and |F_tip| x the scale long, a state
//! without a pose sends the rod, tip, force and limits as DELETE (and no
//! NaN anywhere), the colours follow the guard, the static frame shows Y0
//! up, and the MarkerArray decodes to what was drawn.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_kinematics::{ActiveJoints, Profile, ProfileSpec, forward};
use sar_msgs::msgs::RosMessage;
use sar_msgs::viz::{Marker, MarkerArray, TfMessage, marker_action};
use sar_msgs::wire::{StateMsg, flags, guard_code};
use sar_scene::draw::{self as scene, ids};
use sar_scene::geometry::SceneGeometry;

type V3 = [f64; 3];

fn arr(v: sar_estimator::Vec3) -> V3 {
    [v.x, v.y, v.z]
}

fn close(a: V3, b: V3, tol: f64) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

fn marker(s: &MarkerArray, ns: &str, id: i32) -> Marker {
    *s.markers
        .as_slice()
        .iter()
        .find(|m| m.ns.as_str() == ns && m.id == id)
        .unwrap_or_else(|| panic!("no marker {ns} {id}"))
}

fn drawn(s: &StateMsg, g: &SceneGeometry) -> MarkerArray {
    let mut out = MarkerArray::default();
    scene::scene(s, g, &mut out);
    out
}

/// The built-in configuration with the rod offset `d`.
fn config(d: f64) -> sar_estimator::cycle::EstimatorConfig {
    let mut cfg = sar_config::builtin().unwrap().estimator;
    cfg.profile = Profile::new(&ProfileSpec {
        offset_m: d,
        ..cfg.profile.spec()
    })
    .unwrap();
    cfg
}

/// A state as the daemon publishes it for joints `q` and tip force `f`.
fn state(cfg: &sar_estimator::cycle::EstimatorConfig, q: V3, f: V3, guard: u32) -> StateMsg {
    let joints = ActiveJoints {
        q1_m: q[0],
        q2_m: q[1],
        q3_m: q[2],
    };
    let pose = forward(&cfg.calibration, &cfg.profile, &joints).unwrap();
    StateMsg {
        cycle: 42,
        now_ns: 1_234_567_890_123,
        q_m: q,
        q45_rad: [pose.q4_rad(), pose.q5_rad()],
        ujoint_m: arr(pose.ujoint_m),
        tip_m: arr(pose.tip_m),
        support_distance_m: pose.support_distance_m,
        tip_force_n: f,
        flags: flags::POSE | flags::ESTIMATE | flags::OBSERVABLE,
        guard_state: guard,
        limits_n: [10.0, 15.0, 8.0, 12.0, 6.0, 10.0],
        ..StateMsg::default()
    }
}

const POSES: [V3; 4] = [
    [0.02, 0.25, 0.30],
    [-0.05, 0.22, 0.25],
    [0.0, 0.31, 0.33],
    [0.06, 0.15, 0.20],
];

#[test]
fn rod_ends_are_the_kinematics_with_and_without_offset() {
    for d in [0.0, 0.012, -0.02] {
        let cfg = config(d);
        let g = SceneGeometry::from_config(&cfg);
        for q in POSES {
            let s = state(&cfg, q, [1.0, 2.0, -0.5], guard_code::OK);
            let update = drawn(&s, &g);
            let joints = ActiveJoints {
                q1_m: q[0],
                q2_m: q[1],
                q3_m: q[2],
            };
            let pose = forward(&cfg.calibration, &cfg.profile, &joints).unwrap();
            let rod = marker(&update, ids::ROD, 0);
            let (near, far) = (rod.points_m.as_slice()[0], rod.points_m.as_slice()[1]);
            let a = arr(pose.ujoint_m);
            let w = arr(pose.rod_normal);
            let foot: V3 = std::array::from_fn(|k| a[k] + d * w[k]);
            assert!(close(near, foot, 1e-12), "d {d} q {q:?}: {near:?} {foot:?}");
            assert!(close(far, arr(pose.tip_m), 1e-12), "d {d} q {q:?}");
            // The carriage P = P_home + (q3, q2, q1).
            let cube = marker(&update, ids::CARRIAGE, 0);
            let home = arr(cfg.calibration.p_home_m());
            let p_expected = [home[0] + q[2], home[1] + q[1], home[2] + q[0]];
            assert!(close(cube.pose.position_m, p_expected, 1e-12));
            assert!(close(arr(pose.carriage_m), p_expected, 1e-12));
        }
    }
}

#[test]
fn arrow_points_along_the_force_in_every_direction() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let forces = [
        [-3.0, 0.0, 0.0],
        [3.0, 0.0, 0.0],
        [0.0, -7.0, 0.0],
        [0.0, 0.0, 2.0],
        [1.0, -1.0, 1.0],
    ];
    for f in forces {
        let s = state(&cfg, POSES[0], f, guard_code::WARN);
        let arrow = marker(&drawn(&s, &g), ids::TIP_FORCE, 0);
        let p = arrow.points_m.as_slice();
        assert!(close(p[0], s.tip_m, 0.0));
        let v: V3 = std::array::from_fn(|k| p[1][k] - p[0][k]);
        assert!(
            close(v, f.map(|x| x * g.force_scale_m_per_n), 1e-15),
            "{f:?}: {v:?}"
        );
        assert!(arrow.scale_m.iter().all(|x| *x > 0.0));
        assert_eq!(arrow.color, scene::guard_color(guard_code::WARN));
    }
}

#[test]
fn guard_colours_differ() {
    let codes = [
        guard_code::OK,
        guard_code::WARN,
        guard_code::STOP,
        guard_code::FAULT,
    ];
    for (i, a) in codes.iter().enumerate() {
        for b in &codes[i + 1..] {
            assert_ne!(scene::guard_color(*a), scene::guard_color(*b));
        }
    }
}

fn all_finite(update: &MarkerArray) -> bool {
    let bytes = format!("{update:?}");
    !bytes.contains("NaN") && !bytes.contains("inf")
}

#[test]
fn a_state_without_pose_or_estimate_deletes_the_rod_and_the_arrow() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let mut s = state(&cfg, POSES[1], [2.0, 0.0, 0.0], guard_code::FAULT);
    s.flags = 0;
    s.ujoint_m = [f64::NAN; 3];
    s.tip_m = [f64::NAN; 3];
    s.q45_rad = [f64::NAN; 2];
    s.tip_force_n = [f64::NAN; 3];
    let update = drawn(&s, &g);
    for ns in [ids::UJOINT, ids::ROD, ids::TIP_FORCE, ids::FORCE_LIMITS] {
        assert_eq!(marker(&update, ns, 0).action, marker_action::DELETE, "{ns}");
    }
    for (ns, id) in [(ids::BASE_FRAME, 0), (ids::SUPPORT, 0), (ids::CARRIAGE, 0)] {
        assert_eq!(marker(&update, ns, id).action, marker_action::ADD, "{ns}");
    }
    assert!(all_finite(&update), "{update:?}");

    // A pose but no estimate: the rod, no arrow.
    let mut s = state(&cfg, POSES[1], [2.0, 0.0, 0.0], guard_code::FAULT);
    s.flags = flags::POSE;
    let update = drawn(&s, &g);
    assert_eq!(marker(&update, ids::ROD, 0).action, marker_action::ADD);
    assert_eq!(
        marker(&update, ids::TIP_FORCE, 0).action,
        marker_action::DELETE
    );
    assert!(all_finite(&update));
}

#[test]
fn support_ring_is_around_b_across_the_rod() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[2], [0.0; 3], guard_code::OK);
    let ring = marker(&drawn(&s, &g), ids::SUPPORT, 0);
    let b = arr(cfg.calibration.support_m());
    let (u, _) = sar_kinematics::rod_frame(s.q45_rad[0], s.q45_rad[1]);
    let points = ring.points_m.as_slice();
    assert!(points.len() >= 16);
    assert_eq!(points.first(), points.last(), "closed");
    for p in points {
        let r = [p[0] - b[0], p[1] - b[1], p[2] - b[2]];
        let radius = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((radius - g.support_radius_m).abs() < 1e-12);
        assert!((r[0] * u.x + r[1] * u.y + r[2] * u.z).abs() < 1e-12);
    }
}

#[test]
fn the_scene_and_its_frames_decode_to_what_was_drawn() {
    let cfg = config(0.01);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[3], [1.0, -2.0, 0.5], guard_code::STOP);
    let update = drawn(&s, &g);
    let mut buf = Vec::new();
    update.encode(&mut buf).unwrap();
    assert_eq!(MarkerArray::decode(&buf).unwrap(), update);
    let tf = scene::static_transforms(s.now_ns);
    tf.encode(&mut buf).unwrap();
    let back = TfMessage::decode(&buf).unwrap();
    assert_eq!(back, tf);
    // world -> base: Y0 shows up (world's Z), Z0 towards the viewer.
    let t = back.transforms.as_slice()[0];
    assert!(close(
        scene::rotate(&t.rotation, [0.0, 1.0, 0.0]),
        [0.0, 0.0, 1.0],
        1e-15
    ));
    let moving = scene::moving_transforms(&s, &g);
    let tip = moving.transforms.as_slice()[1];
    assert_eq!(tip.child_frame_id.as_str(), scene::FRAME_TIP);
    assert!(close(tip.translation_m, s.tip_m, 0.0));
}

/// Every string of the layout that names a topic.
fn topic_paths(v: &serde_json::Value, out: &mut Vec<String>) {
    match v {
        serde_json::Value::String(s) if s.starts_with("/sar/") || s.starts_with("/tf") => {
            out.push(s.clone())
        }
        serde_json::Value::Array(a) => a.iter().for_each(|x| topic_paths(x, out)),
        serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| {
            if k.starts_with("/sar/") || k.starts_with("/tf") {
                out.push(k.clone());
            }
            topic_paths(x, out)
        }),
        _ => {}
    }
}

#[test]
fn the_foxglove_layout_uses_only_what_the_view_serves() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../deploy/foxglove-layout.json"
    );
    let layout: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut paths = Vec::new();
    topic_paths(&layout, &mut paths);
    assert!(paths.len() > 10, "{paths:?}");
    let served = sarctl::view::served_topics();
    let schema_of = |topic: &str| -> &'static str {
        use sar_msgs::msgs::Topic;
        match Topic::from_name(topic) {
            Some(t) => t.schema(),
            None if topic == sarctl::view::STATUS_TOPIC => sarctl::view::STATUS_SCHEMA,
            None if topic == sar_scene::SCENE_TOPIC => MarkerArray::SCHEMA,
            None if topic.starts_with("/tf") => TfMessage::SCHEMA,
            None => "",
        }
    };
    for p in &paths {
        let (topic, fields) = p.split_once('.').unwrap_or((p, ""));
        assert!(served.contains(&topic), "{p}: {topic} is not served");
        // Each field of a message path is a word of the topic's schema.
        let schema = schema_of(topic);
        for field in fields.split('.').filter(|f| !f.is_empty()) {
            let name = field.split('[').next().unwrap();
            let word = |w: &str| w.trim_matches(|c: char| !c.is_alphanumeric() && c != '_') == name;
            assert!(
                schema.split_whitespace().any(word),
                "{p}: no field {name} in the schema of {topic}"
            );
        }
    }
    // The plot of F_tip per axis, the guard's state and the 3D scene.
    for wanted in [
        "/sar/estimate/tip_wrench.wrench.force.x",
        "/sar/view/status.stop_total_n",
        "/sar/view/status.guard_code",
        sar_scene::SCENE_TOPIC,
        sar_scene::TF_TOPIC,
        sar_scene::TF_STATIC_TOPIC,
    ] {
        assert!(paths.iter().any(|p| p == wanted), "{wanted}");
    }
}

#[test]
fn the_recorded_messages_of_a_cycle_draw_the_same_scene() {
    use sar_msgs::msgs::Outgoing;
    use sar_scene::topics;
    let cfg = config(0.01);
    let g = SceneGeometry::from_config(&cfg);
    for (k, q) in POSES.iter().enumerate() {
        let mut s = state(&cfg, *q, [1.0, -2.0, 0.5], [0, 1, 2, 3][k]);
        s.guard_reason = 21;
        let mut out = Vec::new();
        topics::messages(&s, None, &mut out);
        let (mut est, mut joints, mut passive) = (None, None, None);
        for m in &out {
            match m {
                Outgoing::EstimatorState(e) => est = Some(*e),
                Outgoing::Joints(j) => joints = Some(*j),
                Outgoing::PassiveJoints(p) => passive = Some(*p),
                _ => {}
            }
        }
        let back = topics::state_from_recorded(
            &est.unwrap(),
            &joints.unwrap(),
            passive.as_ref(),
            s.limits_n,
        );
        assert_eq!(drawn(&back, &g), drawn(&s, &g), "pose {k}");
    }
}

#[test]
fn topics_of_a_state_follow_its_flags_and_the_guards_transitions() {
    use sar_msgs::msgs::{GuardStateCode, Outgoing, Topic};
    use sar_scene::topics;
    let cfg = config(0.0);
    let ok = state(&cfg, POSES[0], [1.0, 0.0, 0.0], guard_code::OK);
    let mut warn = ok;
    warn.cycle += 1;
    warn.guard_state = guard_code::WARN;
    warn.guard_reason = 22;
    let mut out = Vec::new();
    let names = |out: &[Outgoing]| out.iter().map(|m| m.topic()).collect::<Vec<_>>();

    topics::messages(&ok, None, &mut out);
    assert_eq!(
        names(&out),
        [
            Topic::Joints,
            Topic::TipWrench,
            Topic::PassiveJoints,
            Topic::EstimatorState
        ]
    );
    topics::messages(&ok, Some(&ok), &mut out);
    assert!(!names(&out).contains(&Topic::GuardEvents));
    topics::messages(&warn, Some(&ok), &mut out);
    let Some(Outgoing::GuardEvent(e)) = out.last() else {
        panic!("{out:?}")
    };
    assert_eq!(
        (e.from_state, e.to_state, e.reason_code, e.cycle),
        (GuardStateCode::Ok, GuardStateCode::Warn, 22, warn.cycle)
    );
    assert_eq!(e.reason_text.as_str(), "above_warn");

    // No pose, no estimate: the joints and the state only.
    let mut none = ok;
    none.flags = 0;
    topics::messages(&none, Some(&ok), &mut out);
    assert_eq!(names(&out), [Topic::Joints, Topic::EstimatorState]);
    let Some(Outgoing::EstimatorState(st)) = out.last() else {
        panic!()
    };
    assert_eq!(st.tip_outcome, sar_msgs::msgs::TipOutcomeCode::PoseInvalid);
}
