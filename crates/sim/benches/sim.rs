//! The simulator's cost per 1 ms cycle as `sard --sim` calls it on the
//! loop's path (the clock advanced 1 ms, the sensor polled, the positions
//! read: ten 100 us physics steps, a sensor sample every other cycle, a
//! position report), while the axes move back and forth, for the plant of
//! before issue 26 (the baseline, in the same run) beside the plant in
//! motion: the rod's Newton-Euler wrench, then with the servos as well.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing
)]

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3, Vector3};
use sar_hal::{AxisDrives, ForceSensor, SimClock};
use sar_kinematics::{ActiveJoints, Calibration, CalibrationSpec, Profile, ProfileSpec};
use sar_sim::{AxesSpec, PlantSpec, RodInertia, SensorSpec, ServoSpec, SimSpec, Simulator};
use std::hint::black_box;

const MS: u64 = 1_000_000;

fn start() -> ActiveJoints {
    ActiveJoints {
        q1_m: 0.0,
        q2_m: 0.28,
        q3_m: 0.25,
    }
}

fn spec(plant: PlantSpec) -> SimSpec {
    SimSpec {
        seed: 1,
        calibration: Calibration::new(&CalibrationSpec {
            p_home_m: Vector3::zeros(),
            ujoint_offset_m: Vector3::new(0.0, -0.08, 0.0),
            sensor_offset_m: Vector3::new(0.0, -0.03, 0.0),
            sensor_rotation: Matrix3::identity(),
            support_m: Vector3::new(0.45, 0.2, 0.0),
            gravity_mps2: Vector3::new(0.0, -9.80665, 0.0),
        })
        .unwrap(),
        profile: Profile::new(&ProfileSpec {
            length_m: 0.35,
            offset_m: 0.0,
            mass_kg: 2.593,
            com_m: 0.103,
        })
        .unwrap(),
        friction_n: 0.3,
        axes: AxesSpec {
            max_speed_mps: 0.05,
            drive_max_speed_mps: None,
            max_accel_mps2: 0.5,
            lead_m_per_turn: 0.005,
            counts_per_turn: 4096,
            position_period_ns: MS,
            travel_m: [(-0.3, 0.3), (0.0, 0.6), (0.0, 0.6)],
            start: start(),
        },
        sensor: SensorSpec {
            period_ns: 2 * MS,
            latency_ns: MS,
            noise_n: Vector3::new(0.2, 0.2, 0.8),
            noise_nm: Vector3::new(0.01, 0.01, 0.002),
            bias_n: Vector3::zeros(),
            bias_nm: Vector3::zeros(),
            drift_n_per_s: Vector3::zeros(),
            has_tare: true,
            range_n: Vector3::new(200.0, 200.0, 200.0),
            range_nm: Vector3::new(10.0, 10.0, 13.0),
            counts_per_n: 0.0,
            counts_per_nm: 0.0,
        },
        contact: Vec::new(),
        tissue: Vec::new(),
        tip_mass_kg: 0.0,
        faults: Vec::new(),
        physics_step_ns: 100_000,
        plant,
        support_shifts: Vec::new(),
    }
}

fn per_cycle(c: &mut Criterion) {
    let inertia = RodInertia {
        inertia_perp_kgm2: 0.0265,
        inertia_axial_kgm2: 0.0,
        adapter_mass_kg: 0.2,
    };
    let servo = ServoSpec {
        bandwidth_hz: 30.0,
        damping: 0.7,
        max_accel_mps2: 5.0,
        delay_ns: 0,
        inner_loop_hz: 0.0,
    };
    let plants = [
        ("statics, ideal axes (baseline)", PlantSpec::default()),
        (
            "Newton-Euler, ideal axes",
            PlantSpec {
                inertia: Some(inertia),
                ..PlantSpec::default()
            },
        ),
        (
            "Newton-Euler, servos",
            PlantSpec {
                inertia: Some(inertia),
                servo: Some(servo),
                quick_stop_decel_mps2: Some(2.0),
            },
        ),
    ];
    let mut g = c.benchmark_group("sim cycle (1 ms)");
    for (name, plant) in plants {
        let clock = SimClock::new(MS);
        let sim = Simulator::new(spec(plant), clock.clone()).unwrap();
        let (mut sensor, mut drives) = (sim.sensor(), sim.drives());
        drives.enable().unwrap();
        let mut cycle = 0u64;
        g.bench_function(name, |b| {
            b.iter(|| {
                // Back and forth by 10 mm every second: moving most of the time.
                if cycle.is_multiple_of(1000) {
                    let forth = (cycle / 1000).is_multiple_of(2);
                    let q3_m = start().q3_m + if forth { 0.01 } else { 0.0 };
                    drives
                        .set_targets(ActiveJoints { q3_m, ..start() })
                        .unwrap();
                }
                cycle += 1;
                clock.advance_ns(MS);
                black_box(sensor.poll().unwrap());
                black_box(drives.positions().unwrap());
            });
        });
    }
    g.finish();
}

criterion_group!(benches, per_cycle);
criterion_main!(benches);
