//! Criterion benchmark of `sarctl identify`'s work on a one-hour recording
//! (synthesised once, written with the recorder's library to a temporary
//! file and read into memory): a 1 kHz sensor and 1 kHz joints, the cone
//! set's 20 poses (MODEL.md 5.1) held 170 s each with 10 s moves between
//! them, readings from the model of MODEL.md 5.1 with the HEX-6 noise.
//! Beside it, the baselines measured in the same run: reading every message
//! of the file (decompression and CRC only), and decoding both topics.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sar_msgs::msgs::{ActiveJointState, RecorderDrops, WrenchStamped};
use sar_record::McapReader;
use sar_record::{FileOptions, Outgoing, RotatingWriter};
use sarctl::identify::{self, IdentifyOptions};
use std::hint::black_box;
use std::time::Duration;

type V = nalgebra::Vector3<f64>;

const HOUR_S: u64 = 3600;
const HOLD_S: u64 = 170;
const MOVE_S: u64 = 10;
const RATE_HZ: u64 = 1000;
const B: [f64; 3] = [0.45, 0.20, 0.0];
const MASS_KG: f64 = 2.593;
const COM_M: f64 = 0.103;
const FRICTION_N: f64 = 0.3;

const CONFIG: &str = r#"
[geometry]
gravity = [0.0, -9.80665, 0.0]
support = [0.45, 0.20, 0.0]
p_home = [0.0, 0.0, 0.0]
ujoint_offset = [0.0, -0.08, 0.0]
sensor_offset = [0.0, -0.03, 0.0]
sensor_rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

[manipulator]
name = "bench"
length_m = 0.35
offset_m = 0.0
mass_kg = 2.0
com_m = 0.1

[sensor]
noise_n = [0.2, 0.2, 0.8]
"#;

/// The cone set: 4 directions at 35 degrees around X0, 5 distances, swept
/// alternately outward and inward. U-joint centres A.
fn cone_poses() -> Vec<V> {
    let (s, c) = 35f64.to_radians().sin_cos();
    let dirs = [
        V::new(c, s, 0.0),
        V::new(c, 0.0, s),
        V::new(c, -s, 0.0),
        V::new(c, 0.0, -s),
    ];
    let dists = [0.04, 0.07, 0.12, 0.20, 0.30];
    let b = V::from(B);
    let mut out = Vec::new();
    for (k, u) in dirs.iter().enumerate() {
        let order: Vec<f64> = if k % 2 == 0 {
            dists.to_vec()
        } else {
            dists.iter().rev().copied().collect()
        };
        out.extend(order.iter().map(|a| b - u * *a));
    }
    out
}

/// F_A of MODEL.md 5.1 at A with slide sign sigma.
fn force_at(a_pt: &V, sigma: f64) -> V {
    let g = V::new(0.0, -9.80665, 0.0);
    let r = V::from(B) - a_pt;
    let a = r.norm();
    let u = r / a;
    -g * MASS_KG + (g - u * g.dot(&u)) * (MASS_KG * COM_M / a) + u * (sigma * FRICTION_N)
}

/// The joints of a U-joint centre A (P_home = 0, a_off = (0, -0.08, 0)).
fn joints_of(a_pt: &V) -> [f64; 3] {
    let d = a_pt - V::new(0.0, -0.08, 0.0);
    [d.z, d.y, d.x]
}

/// Writes the hour into `dir` and returns the file's bytes.
fn synthesise(dir: &std::path::Path) -> Vec<u8> {
    let poses = cone_poses();
    let mut rng = ChaCha8Rng::seed_from_u64(4242);
    let noise = [0.2, 0.2, 0.8].map(|s| Normal::new(0.0, s).unwrap());
    let mut writer = RotatingWriter::new(FileOptions::new(dir, "hour")).unwrap();
    let status = RecorderDrops::default();
    let period_ns = 1_000_000_000 / RATE_HZ;
    let start_ns = 1_000_000_000u64;
    let per_pose_s = HOLD_S + MOVE_S;
    let mut sigma = -1.0;
    for i in 0..(HOUR_S * RATE_HZ) {
        let t_ns = start_ns + i * period_ns;
        let t_s = i as f64 / RATE_HZ as f64;
        let k = ((t_s as u64) / per_pose_s) as usize % poses.len();
        let in_pose_s = t_s - ((t_s as u64) / per_pose_s * per_pose_s) as f64;
        let a_pt = if in_pose_s < MOVE_S as f64 {
            let from = poses[(k + poses.len() - 1) % poses.len()];
            let to = poses[k];
            let x = in_pose_s / MOVE_S as f64;
            // The slide sign of the move: A towards B is inserting (+1).
            let u = (V::from(B) - to).normalize();
            sigma = if u.dot(&(to - from)) > 0.0 { 1.0 } else { -1.0 };
            from + (to - from) * x
        } else {
            poses[k]
        };
        let f_a = force_at(&a_pt, sigma);
        // Sensor reading: -R_0s^T F_A with R_0s = I, no bias, plus noise.
        let reading = [
            -f_a.x + noise[0].sample(&mut rng),
            -f_a.y + noise[1].sample(&mut rng),
            -f_a.z + noise[2].sample(&mut rng),
        ];
        let msgs = [
            Outgoing::SensorWrench(WrenchStamped::sensor(t_ns, reading, [0.0; 3])),
            Outgoing::Joints(ActiveJointState {
                stamp_ns: t_ns,
                q_m: joints_of(&a_pt),
            }),
        ];
        for m in &msgs {
            writer.write(m, &status).unwrap();
        }
    }
    writer.close(&status).unwrap();
    std::fs::read(&writer.files()[0]).unwrap()
}

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("sar-bench-identify-{}", std::process::id()));
    let bytes = synthesise(&dir);
    std::fs::remove_dir_all(&dir).unwrap();
    let config = sar_config::parse(CONFIG, "bench").unwrap();
    let options = IdentifyOptions::default();
    // The result must be right before its time means anything.
    let r = identify::identify(&bytes, &config, &options).unwrap();
    assert_eq!(r.poses, 20);
    assert!(
        (r.mass_kg - MASS_KG).abs() < 1e-3 * MASS_KG,
        "{}",
        r.mass_kg
    );
    assert!((r.com_m - COM_M).abs() < 1e-3 * COM_M, "{}", r.com_m);
    eprintln!(
        "one hour: {} MB on disk, m = {:.4} kg, c = {:.5} m, {} poses",
        bytes.len() / 1_000_000,
        r.mass_kg,
        r.com_m,
        r.poses
    );

    let messages = 2 * HOUR_S * RATE_HZ;
    let mut g = c.benchmark_group("identify_one_hour");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(20));
    g.throughput(Throughput::Elements(messages));
    g.bench_function("baseline_read_raw", |b| {
        b.iter(|| {
            let n: usize = McapReader::new(&bytes)
                .unwrap()
                .map(|m| m.unwrap().data.len())
                .sum();
            black_box(n)
        })
    });
    g.bench_function("baseline_decode_both_topics", |b| {
        b.iter(|| {
            let w = McapReader::new(&bytes)
                .unwrap()
                .typed::<WrenchStamped>("/sar/sensor/wrench")
                .map(|m| m.unwrap().1.force_n[0])
                .sum::<f64>();
            let j = McapReader::new(&bytes)
                .unwrap()
                .typed::<ActiveJointState>("/sar/joints")
                .map(|m| m.unwrap().1.q_m[0])
                .sum::<f64>();
            black_box(w + j)
        })
    });
    g.bench_function("identify", |b| {
        b.iter(|| black_box(identify::identify(&bytes, &config, &options).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
