//! The bridge's messages are the recording's: one run of the simulated rig
//! (a reset, a tare, a move, a 20 N push along the rod that stops the
//! guard, a reset, new limits; the simulator's truth as `sard --sim` hands
//! it) goes to the daemon's recorder and, through the state the daemon
//! publishes (`sar_loop::publish::state_msg`, the publisher sink's own
//! call), to the bridge's plan. Every topic the bridge publishes holds the
//! recorded messages, byte for byte, in order, with the recorded log
//! times; the 3D scene and `/tf_static` too (both start at the first
//! cycle, so their phases agree). Decimated topics keep a subset at the
//! configured rate, and a rate of 0 publishes nothing.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config as config;
use sar_config::{RecordMode, RecordSettings, Ros2Settings, Rotation, TopicRate};
use sar_estimator::Vec3;
use sar_loop::control::{Envelope, Request};
use sar_loop::publish::{SimTruth, StateParts, state_msg};
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_loop::stats::LoopStats;
use sar_msgs::msgs::Topic;
use sar_record::live::{LiveRecorder, RecordManager, RecordSwitch};
use sar_record::{McapReader, read_file};
use sar_ros2::plan::{Plan, PlanOptions};
use sar_ros2::topics::{ALL, Published};
use sar_scene::geometry::SceneGeometry;
use sar_test_support::messages::rod_push_20n;
use sar_test_support::rig::{RigBuilder, SimRig};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

/// Messages by topic: (log time, bytes).
type Messages = BTreeMap<String, Vec<(u64, Vec<u8>)>>;

const SCENE_PERIOD_NS: u64 = 33_333_333;

fn recorder(dir: &Path, bias: sar_estimator::cycle::Bias) -> (RecordManager, LiveRecorder) {
    let switch = Arc::new(RecordSwitch::default());
    let mut scene = sar_record::SceneOptions::from_config(&config::builtin().unwrap()).unwrap();
    scene.period_ns = SCENE_PERIOD_NS;
    RecordManager::start(
        RecordSettings {
            enabled: true,
            directory: dir.to_path_buf(),
            rotation: Rotation::default(),
            queue_capacity: 1 << 20,
            scene_period_ns: Some(SCENE_PERIOD_NS),
            snapshot_period_ns: 1_000_000_000,
            config_source: None,
            mode: RecordMode::Full,
            scales: config::DeviceScales::default(),
        },
        Some(scene),
        bias,
        switch,
    )
    .unwrap()
}

/// The run recorded into `dir` and bridged through plans of each of
/// `settings`: the recording's messages and each plan's.
fn run(name: &str, settings: &[Ros2Settings]) -> (Messages, Vec<Messages>) {
    let dir = sar_test_support::scratch!(name);
    let SimRig {
        mut c,
        sim,
        clock,
        operator,
        queue,
        bias,
        cfg,
        ..
    } = RigBuilder::demo(rod_push_20n([
        2_000_000_000,
        2_300_000_000,
        2_600_000_000,
        2_900_000_000,
    ]))
    .build();
    let (manager, mut rec) = recorder(&dir, bias);
    let mut plans: Vec<Plan> = settings
        .iter()
        .map(|s| {
            Plan::new(PlanOptions::of(
                s,
                SceneGeometry::from_config(&cfg.estimator),
                cfg.estimator.guard.force_limits().to_array(),
            ))
        })
        .collect();
    let mut bridged = vec![Messages::new(); plans.len()];
    let stats = LoopStats::default();
    let configured = cfg.estimator.guard.force_limits();
    let lower = sar_estimator::guard::ForceLimits {
        warn_total_n: configured.warn_total_n - 0.5,
        ..configured
    };
    for cycle in 1..=4000u64 {
        clock.advance_ns(1_000_000);
        let request = match cycle {
            100 | 3200 => Some(Request::Reset),
            300 => Some(Request::Tare),
            500 => Some(Request::MoveTip {
                tip_m: Vec3::new(0.6, 0.2, 0.002),
            }),
            3500 => Some(Request::SetLimits(lower)),
            _ => None,
        };
        if let Some(request) = request {
            operator
                .requests
                .push(Envelope { id: cycle, request })
                .unwrap();
        }
        rec.before_cycle();
        c.step(cycle, || Some(clock.now_ns()));
        let truth = sim.truth().ok().map(|t| SimTruth {
            tip_force_n: t.tip_force_n,
            friction_force_n: t.friction_force_n,
            elapsed_ns: t.elapsed_ns,
        });
        let mut health = SinkHealth::default();
        let cyc = Cycle::of(&c, &stats, truth);
        rec.cycle(&cyc, &mut health);
        // The state as the publisher sink makes it.
        let state = state_msg(&StateParts {
            input: cyc.loop_input,
            decision: cyc.decision,
            stats: cyc.stats,
            quick_stops: cyc.quick_stops,
            recorder_drops: health.recorder_drops,
            recording: health.recording,
            truth: cyc.truth,
            sensor_samples: cyc.sensor_samples,
        });
        for (plan, out) in plans.iter_mut().zip(&mut bridged) {
            plan.on_state(&state, |topic, stamp_ns, cdr| {
                out.entry(topic.name().to_owned())
                    .or_default()
                    .push((stamp_ns, cdr.to_vec()));
            });
        }
        while queue.pop().is_some() {}
        while operator.replies.pop().is_some() {}
    }
    rec.release();
    manager.finish();
    let files = sar_test_support::files::recordings(&dir);
    assert_eq!(files.len(), 1, "{files:?}");
    let bytes = read_file(&files[0]).unwrap();
    let mut reader = McapReader::new(&bytes).unwrap();
    let mut recorded = Messages::new();
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        let topic = reader.channels()[&m.channel_id].topic.clone();
        recorded
            .entry(topic)
            .or_default()
            .push((m.log_time_ns, m.data));
    }
    (recorded, bridged)
}

#[test]
fn every_bridged_topic_is_the_recording_byte_for_byte() {
    let (recorded, bridged) = run(
        "bridge_is_recording",
        &[Ros2Settings {
            scene_period_ns: Some(SCENE_PERIOD_NS),
            ..Ros2Settings::default()
        }],
    );
    let bridged = &bridged[0];
    for topic in ALL {
        let name = topic.name();
        let want = recorded.get(name).map_or(&[][..], Vec::as_slice);
        let got = bridged.get(name).map_or(&[][..], Vec::as_slice);
        assert!(!want.is_empty(), "{name}: the recording has none");
        assert_eq!(got.len(), want.len(), "{name}: message count");
        for (i, (a, b)) in want.iter().zip(got).enumerate() {
            assert!(
                a == b,
                "{name}: message {i} differs (log time {} / {})",
                a.0,
                b.0
            );
        }
    }
    // What the run must hold for this to show something: transitions into
    // Stop and back, a filtered estimate, sensor samples, the scene.
    assert!(recorded[Topic::GuardEvents.name()].len() >= 3);
    assert!(recorded[Topic::SensorWrench.name()].len() >= 1900);
    assert!(recorded[sar_scene::SCENE_TOPIC].len() >= 100);
    assert_eq!(recorded[sar_scene::TF_STATIC_TOPIC].len(), 1);
}

#[test]
fn decimated_topics_keep_a_subset_at_their_rate_and_zero_is_off() {
    let rates = config::Ros2Rates {
        estimate: TopicRate::PeriodNs(10_000_000),
        sensor_wrench: TopicRate::PeriodNs(50_000_000),
        joints: TopicRate::Off,
        ..config::Ros2Rates::default()
    };
    let (recorded, bridged) = run(
        "bridge_decimated",
        &[Ros2Settings {
            rates,
            scene_period_ns: None,
            ..Ros2Settings::default()
        }],
    );
    let bridged = &bridged[0];
    for (topic, period_ns, at_least) in [
        (Topic::EstimatorState, 10_000_000, 399),
        (Topic::SensorWrench, 50_000_000, 79),
    ] {
        let got = &bridged[topic.name()];
        let all = &recorded[topic.name()];
        assert!(
            got.len() >= at_least && got.len() <= at_least + 2,
            "{topic:?}: {}",
            got.len()
        );
        // A subset of the recording, in order, at most one per period.
        let mut k = 0;
        for m in got {
            k += all[k..].iter().position(|r| r == m).expect("not recorded") + 1;
        }
        for w in got.windows(2) {
            assert!(w[1].0 - w[0].0 >= period_ns - 1_000_000, "{topic:?}");
        }
    }
    assert!(!bridged.contains_key(Topic::Joints.name()));
    assert!(!bridged.contains_key(sar_scene::SCENE_TOPIC));
    assert!(!bridged.contains_key(sar_scene::TF_STATIC_TOPIC));
    // Never decimated.
    assert_eq!(
        bridged[Topic::GuardEvents.name()],
        recorded[Topic::GuardEvents.name()]
    );
    let _ = Published::Scene;
}

#[test]
fn states_not_received_are_counted_and_a_restart_starts_again() {
    let cfg = config::builtin().unwrap();
    let mut plan = Plan::new(PlanOptions::from_config(&cfg));
    let state = |cycle: u64| sar_msgs::wire::StateMsg {
        cycle,
        now_ns: 1_000_000_000 + cycle * 1_000_000,
        joints_stamp_ns: 1_000_000_000 + cycle * 1_000_000,
        flags: sar_msgs::wire::flags::NOW,
        ..sar_msgs::wire::StateMsg::default()
    };
    let mut joints = 0;
    let mut count = |plan: &mut Plan, cycle: u64| {
        plan.on_state(&state(cycle), |topic, _, _| {
            if topic == Published::Record(Topic::Joints) {
                joints += 1;
            }
        });
    };
    for cycle in [10, 11, 12, 20, 21, 30] {
        count(&mut plan, cycle);
    }
    let c = plan.counts();
    assert_eq!((c.states, c.states_lost, c.encode_errors), (6, 7 + 8, 0));
    // A restarted daemon: its cycles start again; no gap is counted across.
    plan.restart();
    count(&mut plan, 1);
    count(&mut plan, 2);
    assert_eq!(plan.counts().states_lost, 15);
    assert_eq!(joints, 8, "a joint sample per new stamp");
}
