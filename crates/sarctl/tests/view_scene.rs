//! The 3D scene as a pure function (no processes): the rod's ends against
//! `sar_kinematics::forward` also with a rod offset d != 0, the arrow from
//! the tip along the force, |F_tip| x scale long, a state without a pose
//! deletes the rod, tip, force and limits (and no NaN anywhere), the colours
//! follow the guard, the frames (`/tf`: carriage, rod, tip) agree with the
//! markers, and the layout names only what a recording and the view carry.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_kinematics::{ActiveJoints, Profile, ProfileSpec, forward};
use sar_msgs::scene::{Marker, MarkerArray, action, kind};
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

fn marker<'a>(s: &'a MarkerArray, ns: &str, id: i32) -> &'a Marker {
    s.markers.iter().find(|m| m.ns == ns && m.id == id).unwrap()
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
            let rod = marker(&update, ids::ROD, 0);
            assert_eq!((rod.kind, rod.action), (kind::CYLINDER, action::ADD));
            let axis = scene::rotate(rod.orientation, [0.0, 0.0, 1.0]);
            let (c, height) = (rod.position_m, rod.scale_m[2]);
            let near: V3 = std::array::from_fn(|k| c[k] - 0.5 * height * axis[k]);
            let far: V3 = std::array::from_fn(|k| c[k] + 0.5 * height * axis[k]);
            let a = arr(pose.ujoint_m);
            let w = arr(pose.rod_normal);
            let foot: V3 = std::array::from_fn(|k| a[k] + d * w[k]);
            assert!(close(near, foot, 1e-12), "d {d} q {q:?}: {near:?} {foot:?}");
            assert!(close(far, arr(pose.tip_m), 1e-12), "d {d} q {q:?}");
            // The carriage P = P_home + (q3, q2, q1).
            let cube = marker(&update, ids::CARRIAGE, 0);
            let home = arr(cfg.calibration.p_home_m());
            let p_expected = [home[0] + q[2], home[1] + q[1], home[2] + q[0]];
            assert!(close(cube.position_m, p_expected, 1e-12));
            assert!(close(arr(pose.carriage_m), p_expected, 1e-12));
            // The frames: base -> carriage at P, base -> rod at A's foot with
            // x along u, rod -> tip L along x: the tip where the markers put it.
            let tf = scene::moving_frames(&s, &g);
            let names: Vec<_> = tf.transforms.iter().map(|t| t.child.as_str()).collect();
            assert_eq!(names, ["carriage", "rod", "tip"]);
            assert!(close(tf.transforms[0].translation_m, p_expected, 1e-12));
            let rod_frame = &tf.transforms[1];
            assert!(close(rod_frame.translation_m, foot, 1e-12));
            let along = scene::rotate(rod_frame.rotation, [g.length_m, 0.0, 0.0]);
            let tip: V3 = std::array::from_fn(|k| rod_frame.translation_m[k] + along[k]);
            assert!(close(tip, arr(pose.tip_m), 1e-12));
            assert_eq!(tf.transforms[2].translation_m, [g.length_m, 0.0, 0.0]);
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
        let arrow = marker(&update, ids::TIP_FORCE, 0);
        assert_eq!((arrow.kind, arrow.action), (kind::ARROW, action::ADD));
        let [from, to] = [arrow.points_m[0], arrow.points_m[1]];
        assert_eq!(from, s.tip_m);
        let d: V3 = std::array::from_fn(|k| to[k] - from[k]);
        let length = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let dir: V3 = std::array::from_fn(|k| d[k] / length);
        assert!(
            close(dir, [f[0] / n, f[1] / n, f[2] / n], 1e-12),
            "{f:?}: {dir:?}"
        );
        assert!((length - n * g.force_scale_m_per_n).abs() < 1e-12);
        // The head is shorter than the arrow.
        assert!(arrow.scale_m[2] > 0.0 && arrow.scale_m[2] < length);
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
    // Every marker every time, in the namespaces' order.
    assert_eq!(update.markers.len(), scene::MARKERS);
    let mut namespaces: Vec<&str> = update.markers.iter().map(|m| m.ns.as_str()).collect();
    namespaces.dedup();
    assert_eq!(namespaces, ids::ALL);
    for m in &update.markers {
        let shown = m.action == action::ADD;
        match m.ns.as_str() {
            ns if ns == ids::BASE_FRAME || ns == ids::SUPPORT => assert!(shown, "{m:?}"),
            // The carriage cube (its joints are valid), not its bracket to A.
            ns if ns == ids::CARRIAGE => assert_eq!(shown, m.id == 0, "{m:?}"),
            _ => assert_eq!(m.action, action::DELETE, "{m:?}"),
        }
    }
    assert!(all_finite(&update), "{update:?}");
    // No frames of the rod or the tip without a pose.
    assert_eq!(scene::moving_frames(&s, &g).transforms.len(), 1);

    // A pose but no estimate: the rod, no arrow.
    let mut s = state(&cfg, POSES[1], [2.0, 0.0, 0.0], guard_code::FAULT);
    s.flags = flags::POSE;
    let update = scene::scene(&s, &g);
    assert_eq!(marker(&update, ids::ROD, 0).action, action::ADD);
    assert_eq!(marker(&update, ids::TIP_FORCE, 0).action, action::DELETE);
    assert!(all_finite(&update));
}

#[test]
fn support_ring_is_around_b_across_the_rod() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[2], [0.0; 3], guard_code::OK);
    let update = scene::scene(&s, &g);
    let ring = marker(&update, ids::SUPPORT, 0);
    let b = arr(cfg.calibration.support_m());
    let (u, _) = sar_kinematics::rod_frame(s.q45_rad[0], s.q45_rad[1]);
    assert!(ring.points_m.len() >= 16);
    // Closed: the last point is the first.
    assert_eq!(ring.points_m.first(), ring.points_m.last());
    for p in &ring.points_m {
        let r = [p[0] - b[0], p[1] - b[1], p[2] - b[2]];
        let radius = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((radius - g.support_radius_m).abs() < 1e-12);
        assert!((r[0] * u.x + r[1] * u.y + r[2] * u.z).abs() < 1e-12);
    }
}

#[test]
fn the_scene_encodes_and_decodes_as_drawn() {
    let cfg = config(0.0);
    let g = SceneGeometry::from_config(&cfg);
    let s = state(&cfg, POSES[0], [4.0, 1.0, 0.0], guard_code::OK);
    let update = scene::scene(&s, &g);
    let mut buf = Vec::new();
    update.encode(&mut buf).unwrap();
    assert_eq!(MarkerArray::decode(&buf).unwrap(), update);
    for m in &update.markers {
        assert_eq!((m.stamp_ns, m.frame_id.as_str()), (s.now_ns, "base"));
    }
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
        use sar_msgs::msgs::RosMessage;
        use sar_msgs::msgs::Topic;
        match Topic::from_name(topic) {
            Some(t) => t.schema(),
            None if topic == sarctl::view::STATUS_TOPIC => sarctl::view::STATUS_SCHEMA,
            None if topic == sar_scene::SCENE_STATUS_TOPIC => sar_msgs::msgs::SceneStatus::SCHEMA,
            None if topic == sar_scene::SCENE_TOPIC => MarkerArray::SCHEMA,
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
        "/sar/scene/status.stop_total_n",
        "/sar/scene/status.guard_state",
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
fn topics_of_a_state_are_the_recorders_messages_of_its_cycle() {
    use sar_estimator::guard::{ForcePart, Reason};
    use sar_msgs::msgs::{GuardStateCode, Outgoing, TipOutcomeCode, Topic};
    use sar_msgs::wire::reason_bytes;
    use sar_scene::topics;
    let cfg = config(0.0);
    let mut ok = state(&cfg, POSES[0], [1.0, 0.0, 0.0], guard_code::OK);
    ok.flags |= flags::NOW | flags::SENSOR_VALID | flags::JOINTS_VALID;
    ok.joints_stamp_ns = ok.now_ns - 100_000;
    let mut out = Vec::new();
    let names = |out: &[Outgoing]| out.iter().map(|m| m.topic()).collect::<Vec<_>>();

    // The recorder's order; the joints when their sample is new.
    topics::messages(&ok, None, &mut out);
    assert_eq!(
        names(&out),
        [
            Topic::Joints,
            Topic::EstimatorState,
            Topic::TipWrench,
            Topic::PassiveJoints
        ]
    );
    topics::messages(&ok, Some(&ok), &mut out);
    assert_eq!(
        names(&out),
        [
            Topic::EstimatorState,
            Topic::TipWrench,
            Topic::PassiveJoints
        ]
    );

    // The loop's own transition, with its reason whole (the recording's
    // sentence, not only its name).
    let reason = Reason::AboveWarn {
        part: ForcePart::Axial,
        force_n: 8.25,
        limit_n: 8.0,
    };
    let mut warn = ok;
    warn.cycle += 1;
    warn.now_ns += 1_000_000;
    warn.guard_state = guard_code::WARN;
    warn.guard_reason = 22;
    warn.guard_reason_bytes = reason_bytes(&reason);
    warn.flags |= flags::TRANSITION;
    warn.transition_cycle = warn.cycle;
    warn.transition_from = guard_code::OK;
    warn.transition_to = guard_code::WARN;
    warn.transition_reason_bytes = reason_bytes(&reason);
    topics::messages(&warn, Some(&ok), &mut out);
    let Some(Outgoing::GuardEvent(e)) = out.last() else {
        panic!("{out:?}")
    };
    assert_eq!(
        (e.from_state, e.to_state, e.reason_code, e.cycle, e.stamp_ns),
        (
            GuardStateCode::Ok,
            GuardStateCode::Warn,
            22,
            warn.cycle,
            warn.now_ns
        )
    );
    assert_eq!(e.reason_text.as_str(), reason.to_string());
    let Some(Outgoing::EstimatorState(st)) = out.first() else {
        panic!("{out:?}")
    };
    assert_eq!(st.guard_reason_text.as_str(), reason.to_string());
    // A state that differs from the one before without the loop's
    // transition (states lost between them): no event is made up.
    let mut later = warn;
    later.cycle += 5;
    later.guard_state = guard_code::STOP;
    later.flags &= !flags::TRANSITION;
    topics::messages(&later, Some(&ok), &mut out);
    assert!(!names(&out).contains(&Topic::GuardEvents));

    // No pose, no estimate: the state alone, with the outcome the loop
    // recorded; each sensor sample received first, in order.
    let mut none = ok;
    none.flags = flags::NOW;
    none.tip_outcome = u32::from(TipOutcomeCode::SensorInvalid.code());
    none.sensor_samples = 2;
    none.sensor_received_ns[0] = 7;
    none.sensor_received_ns[1] = 8;
    topics::messages(&none, Some(&ok), &mut out);
    assert_eq!(
        names(&out),
        [
            Topic::SensorWrench,
            Topic::SensorWrench,
            Topic::EstimatorState
        ]
    );
    assert_eq!(out[1].stamp_ns(), 8);
    let Some(Outgoing::EstimatorState(st)) = out.last() else {
        panic!()
    };
    assert_eq!(st.tip_outcome, TipOutcomeCode::SensorInvalid);
}
