//! Criterion benchmarks of the 3D scene on the recorder's thread: `draw`
//! draws one scene (the `MarkerArray`), `draw_encode` draws and encodes all
//! that a scene writes (markers, `/tf`, `/sar/scene/status`) into reused
//! buffers, and the baseline `estimator_state_encode` encodes the one
//! `/sar/estimate/state` message every cycle writes.
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use sar_msgs::msgs::RosMessage;
use sar_msgs::wire::{StateMsg, flags, guard_code};
use sar_scene::draw;
use sar_scene::geometry::SceneGeometry;
use sar_scene::topics;
use std::hint::black_box;

/// The demo's geometry and a state with a pose and an estimate.
fn inputs() -> (StateMsg, SceneGeometry) {
    let g = SceneGeometry {
        p_home_m: [0.0; 3],
        support_m: [0.45, 0.2, 0.0],
        length_m: 0.35,
        offset_m: 0.0,
        force_scale_m_per_n: 0.01,
        rod_diameter_m: 0.008,
        support_radius_m: 0.012,
        axis_length_m: 0.1,
    };
    let s = StateMsg {
        cycle: 42,
        now_ns: 1_234_567_890_123,
        q_m: [0.0, 0.12, 0.25],
        q45_rad: [1.4, 0.05],
        ujoint_m: [0.25, 0.2, 0.0],
        tip_m: [0.6, 0.21, 0.003],
        tip_force_n: [1.0, -2.0, 0.5],
        tip_axial_lateral_n: [1.0, 2.06],
        flags: flags::POSE | flags::ESTIMATE | flags::OBSERVABLE,
        guard_state: guard_code::WARN,
        limits_n: [10.0, 15.0, 8.0, 12.0, 6.0, 10.0],
        ..StateMsg::default()
    };
    (s, g)
}

fn bench(c: &mut Criterion) {
    let (s, g) = inputs();
    let mut g_ = c.benchmark_group("scene");
    g_.bench_function("draw", |b| {
        b.iter(|| black_box(draw::scene(black_box(&s), &g)))
    });
    let mut buf = Vec::with_capacity(8192);
    g_.bench_function("draw_encode", |b| {
        b.iter(|| {
            draw::scene(black_box(&s), &g).encode(&mut buf).unwrap();
            draw::moving_frames(&s, &g).encode(&mut buf).unwrap();
            topics::scene_status(&s).encode(&mut buf).unwrap();
            black_box(buf.len())
        })
    });
    let state = topics::estimator_state(&s);
    g_.bench_function("estimator_state_encode", |b| {
        b.iter(|| black_box(&state).encode(&mut buf).unwrap())
    });
    g_.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
