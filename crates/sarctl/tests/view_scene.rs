//! The live view's scene as a pure function (no processes): the rod's ends
//! against `sar_kinematics::forward` also with a rod offset d != 0, the
//! arrow's direction for a force opposite to the arrow's own axis (the
//! half-turn case), a state without a pose draws no rod, tip, force nor
//! limits (and no NaN anywhere), the colours follow the guard, and the
//! scene written to an MCAP file with [`scene::schema`] and
//! [`scene::encode`] reads back (the recorder's future scene topic).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use foxglove::Decode;
use foxglove::messages::{SceneEntity, SceneUpdate};
use sar_kinematics::{ActiveJoints, Profile, ProfileSpec, forward};
use sar_msgs::wire::{StateMsg, flags, guard_code};
use sar_scene::draw::{self as scene, ids};
use sar_scene::geometry::SceneGeometry;
use std::collections::BTreeMap;

type V3 = [f64; 3];

fn arr(v: sar_estimator::Vec3) -> V3 {
    [v.x, v.y, v.z]
}

fn close(a: V3, b: V3, tol: f64) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

fn v3(v: &foxglove::messages::Vector3) -> V3 {
    [v.x, v.y, v.z]
}

fn entity<'a>(s: &'a SceneUpdate, id: &str) -> &'a SceneEntity {
    s.entities.iter().find(|e| e.id == id).unwrap()
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
            let update = scene::scene(&s, &g);
            let joints = ActiveJoints {
                q1_m: q[0],
                q2_m: q[1],
                q3_m: q[2],
            };
            let pose = forward(&cfg.calibration, &cfg.profile, &joints).unwrap();
            let rod = &entity(&update, ids::ROD).cylinders[0];
            let (p, size) = (rod.pose.unwrap(), rod.size.unwrap());
            let axis = scene::rotate(&p.orientation.unwrap(), [0.0, 0.0, 1.0]);
            let c = v3(&p.position.unwrap());
            let near: V3 = std::array::from_fn(|k| c[k] - 0.5 * size.z * axis[k]);
            let far: V3 = std::array::from_fn(|k| c[k] + 0.5 * size.z * axis[k]);
            let a = arr(pose.ujoint_m);
            let w = arr(pose.rod_normal);
            let foot: V3 = std::array::from_fn(|k| a[k] + d * w[k]);
            assert!(close(near, foot, 1e-12), "d {d} q {q:?}: {near:?} {foot:?}");
            assert!(close(far, arr(pose.tip_m), 1e-12), "d {d} q {q:?}");
            // The carriage P = P_home + (q3, q2, q1).
            let cube = &entity(&update, ids::CARRIAGE).cubes[0];
            let home = arr(cfg.calibration.p_home_m());
            let p_expected = [home[0] + q[2], home[1] + q[1], home[2] + q[0]];
            assert!(close(
                v3(&cube.pose.unwrap().position.unwrap()),
                p_expected,
                1e-12
            ));
            assert!(close(arr(pose.carriage_m), p_expected, 1e-12));
        }
    }
}

#[test]
fn arrow_points_along_the_force_in_every_direction() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let forces = [
        [-3.0, 0.0, 0.0], // opposite to the arrow's own +x
        [3.0, 0.0, 0.0],
        [0.0, -7.0, 0.0],
        [0.0, 0.0, 2.0],
        [1.0, -1.0, 1.0],
    ];
    for f in forces {
        let s = state(&cfg, POSES[0], f, guard_code::WARN);
        let update = scene::scene(&s, &g);
        let arrow = &entity(&update, ids::TIP_FORCE).arrows[0];
        let dir = scene::rotate(&arrow.pose.unwrap().orientation.unwrap(), [1.0, 0.0, 0.0]);
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!(
            close(dir, [f[0] / n, f[1] / n, f[2] / n], 1e-12),
            "{f:?}: {dir:?}"
        );
        assert!((arrow.shaft_length + arrow.head_length - n * g.force_scale_m_per_n).abs() < 1e-12);
        assert!(arrow.shaft_length > 0.0);
        let c = arrow.color.unwrap();
        assert_eq!((c.r, c.g, c.b), scene::guard_color(guard_code::WARN));
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

fn all_finite(update: &SceneUpdate) -> bool {
    let bytes = format!("{update:?}");
    !bytes.contains("NaN") && !bytes.contains("inf")
}

#[test]
fn a_state_without_pose_or_estimate_draws_no_rod_and_no_arrow() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let mut s = state(&cfg, POSES[1], [2.0, 0.0, 0.0], guard_code::FAULT);
    s.flags = 0;
    s.ujoint_m = [f64::NAN; 3];
    s.tip_m = [f64::NAN; 3];
    s.q45_rad = [f64::NAN; 2];
    s.tip_force_n = [f64::NAN; 3];
    let update = scene::scene(&s, &g);
    let got: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(got, ids::ALL);
    for id in [ids::UJOINT, ids::ROD, ids::TIP_FORCE, ids::FORCE_LIMITS] {
        let e = entity(&update, id);
        assert!(
            e.arrows.is_empty() && e.cylinders.is_empty() && e.spheres.is_empty(),
            "{id}"
        );
    }
    assert_eq!(entity(&update, ids::BASE_FRAME).arrows.len(), 3);
    assert_eq!(entity(&update, ids::SUPPORT).lines.len(), 1);
    assert!(all_finite(&update), "{update:?}");

    // A pose but no estimate: the rod, no arrow.
    let mut s = state(&cfg, POSES[1], [2.0, 0.0, 0.0], guard_code::FAULT);
    s.flags = flags::POSE;
    let update = scene::scene(&s, &g);
    assert_eq!(entity(&update, ids::ROD).cylinders.len(), 1);
    assert!(entity(&update, ids::TIP_FORCE).arrows.is_empty());
    assert!(all_finite(&update));
}

#[test]
fn support_ring_is_around_b_across_the_rod() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[2], [0.0; 3], guard_code::OK);
    let update = scene::scene(&s, &g);
    let ring = &entity(&update, ids::SUPPORT).lines[0];
    let b = arr(cfg.calibration.support_m());
    let (u, _) = sar_kinematics::rod_frame(s.q45_rad[0], s.q45_rad[1]);
    assert!(ring.points.len() >= 16);
    for p in &ring.points {
        let r = [p.x - b[0], p.y - b[1], p.z - b[2]];
        let radius = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((radius - g.support_radius_m).abs() < 1e-12);
        assert!((r[0] * u.x + r[1] * u.y + r[2] * u.z).abs() < 1e-12);
    }
}

#[test]
fn the_scene_goes_into_an_mcap_file_and_back() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[0], [4.0, 1.0, 0.0], guard_code::OK);
    let update = scene::scene(&s, &g);
    let schema = scene::schema();
    assert_eq!(schema.name, "foxglove.SceneUpdate");
    assert_eq!(schema.encoding, "protobuf");
    assert_eq!(schema.message_encoding, "protobuf");
    assert!(!schema.data.is_empty());

    let mut file = Vec::new();
    {
        let mut w = mcap::Writer::new(std::io::Cursor::new(&mut file)).unwrap();
        let id = w
            .add_schema(&schema.name, &schema.encoding, &schema.data)
            .unwrap();
        let ch = w
            .add_channel(
                id,
                sar_scene::SCENE_TOPIC,
                &schema.message_encoding,
                &BTreeMap::new(),
            )
            .unwrap();
        let mut buf = Vec::new();
        scene::encode(&update, &mut buf).unwrap();
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: s.now_ns,
                publish_time: s.now_ns,
            },
            &buf,
        )
        .unwrap();
        w.finish().unwrap();
    }
    let msgs: Vec<_> = mcap::MessageStream::new(&file)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(msgs.len(), 1);
    let m = &msgs[0];
    assert_eq!(m.channel.topic, sar_scene::SCENE_TOPIC);
    assert_eq!(m.log_time, s.now_ns);
    let schema_back = m.channel.schema.as_ref().unwrap();
    assert_eq!(schema_back.name, "foxglove.SceneUpdate");
    assert_eq!(SceneUpdate::decode(&m.data[..]).unwrap(), update);
    assert_eq!(
        entity(&update, ids::ROD).timestamp.unwrap().total_nanos(),
        s.now_ns
    );
}

/// Every string of the layout that names a topic.
fn topic_paths(v: &serde_json::Value, out: &mut Vec<String>) {
    match v {
        serde_json::Value::String(s) if s.starts_with("/sar/") => out.push(s.clone()),
        serde_json::Value::Array(a) => a.iter().for_each(|x| topic_paths(x, out)),
        serde_json::Value::Object(o) => o.iter().for_each(|(k, x)| {
            if k.starts_with("/sar/") {
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
        assert_eq!(scene::scene(&back, &g), scene::scene(&s, &g), "pose {k}");
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
