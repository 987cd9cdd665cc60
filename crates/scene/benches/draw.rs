//! Criterion benchmark of the 3D scene's cost on the recorder's thread: one
//! scene drawn (`draw::scene`), drawn and encoded as the recording's
//! `MarkerArray` with the frames' `TFMessage`, beside the baseline of one
//! recorded message of the same cycle encoded (`/sar/estimate/state`).
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use sar_msgs::msgs::{EstimatorState, RosMessage};
use sar_msgs::viz::MarkerArray;
use sar_msgs::wire::{StateMsg, flags, guard_code};
use sar_scene::draw;
use sar_scene::geometry::SceneGeometry;
use std::hint::black_box;

fn state() -> StateMsg {
    StateMsg {
        cycle: 42,
        now_ns: 1_234_567_890_123,
        q_m: [0.02, 0.25, 0.30],
        q45_rad: [0.3, -0.2],
        ujoint_m: [0.3, 0.2, 0.1],
        tip_m: [0.7, 0.05, 0.12],
        tip_force_n: [1.0, -2.0, 0.5],
        flags: flags::POSE | flags::ESTIMATE | flags::OBSERVABLE,
        guard_state: guard_code::WARN,
        limits_n: [10.0, 15.0, 8.0, 12.0, 6.0, 10.0],
        ..StateMsg::default()
    }
}

fn scene(c: &mut Criterion) {
    let g = SceneGeometry {
        p_home_m: [0.1, 0.2, 0.3],
        support_m: [0.5, 0.1, 0.1],
        length_m: 0.4,
        offset_m: 0.01,
        force_scale_m_per_n: 0.01,
        rod_diameter_m: 0.008,
        support_radius_m: 0.012,
        axis_length_m: 0.1,
    };
    let s = state();
    let mut out = Box::<MarkerArray>::default();
    let mut buf = Vec::with_capacity(16384);
    let mut grp = c.benchmark_group("scene");
    grp.bench_function("baseline_encode_estimator_state", |b| {
        let est = sar_scene::topics::estimator_state(&s);
        b.iter(|| {
            black_box(&est).encode(&mut buf).unwrap();
            black_box(&buf);
        })
    });
    grp.bench_function("draw", |b| {
        b.iter(|| draw::scene(black_box(&s), &g, &mut out))
    });
    grp.bench_function("draw_and_encode_with_tf", |b| {
        b.iter(|| {
            draw::scene(black_box(&s), &g, &mut out);
            out.encode(&mut buf).unwrap();
            draw::moving_transforms(&s, &g).encode(&mut buf).unwrap();
            black_box(&buf);
        })
    });
    grp.finish();
    draw::scene(&s, &g, &mut out);
    out.encode(&mut buf).unwrap();
    println!("one /sar/scene MarkerArray: {} bytes of CDR", buf.len());
    let est: EstimatorState = sar_scene::topics::estimator_state(&s);
    est.encode(&mut buf).unwrap();
    println!("one /sar/estimate/state: {} bytes of CDR", buf.len());
}

criterion_group!(benches, scene);
criterion_main!(benches);
