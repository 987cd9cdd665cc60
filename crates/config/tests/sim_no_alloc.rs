//! The simulator allocates nothing once made, with every fault on demand and
//! tissues acting: `sard --sim` runs it on the loop's path, so its sensor and
//! drives calls are counted under a counting global allocator (the daemon's
//! no-alloc tests run the demo scenario; this one runs every failure mode
//! and a breathing, shifting, damped tissue, then the plant in motion: the
//! rod's inertia, the servos and the quick stop). One test in this binary, so
//! that no other test's allocations count. (Here, beside the scenario
//! loader, since `sar-sim` reads no scenario file.)
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use sar_hal::{AxisDrives, DriveState, ForceSensor, SimClock, Vec3, WrenchSample};
use sar_kinematics::ActiveJoints;
use sar_sim::{
    Breathing, Fault, PlantSpec, RodInertia, ServoSpec, Simulator, Tissue, TissueModel, TissueShift,
};
use sar_test_support::counting::{Counting, thread_allocations};
use std::path::Path;

#[global_allocator]
static GLOBAL: Counting = Counting;

const MS: u64 = 1_000_000;

#[test]
fn the_simulator_with_every_fault_and_a_tissue_allocates_nothing_per_cycle() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/tissue_breathing.toml");
    let scenario = sar_config::scenario::load(&path).unwrap();
    let mut spec = scenario.spec;
    // A second, exponential tissue across the rod.
    spec.tissue.push(Tissue {
        direction: Vec3::new(0.0, 0.0, -1.0),
        rest_m: Vec3::new(0.6, 0.2, 0.002),
        model: TissueModel::Exponential {
            stiffness_n_per_m: 1000.0,
            beta_per_m: 50.0,
        },
        damping_n_s_per_m: 10.0,
        breathing: Some(Breathing {
            amplitude_m: 0.003,
            hz: 0.3,
            direction: Vec3::new(0.0, 0.0, 1.0),
        }),
        shifts: vec![TissueShift {
            t_ns: 300 * MS,
            offset_m: 0.001,
        }],
    });
    let channels = [true, false, true, false, false, true];
    spec.faults = vec![
        Fault::SensorFrozen {
            from_ns: 100 * MS,
            until_ns: Some(150 * MS),
        },
        Fault::SensorSaturated {
            from_ns: 160 * MS,
            until_ns: Some(200 * MS),
            channels,
            rail: None,
        },
        Fault::SensorSpike {
            at_ns: 210 * MS,
            force_n: Vec3::new(0.0, 0.0, 30.0),
            torque_nm: Vec3::zeros(),
            samples: 3,
        },
        Fault::SensorDrift {
            from_ns: 220 * MS,
            drift_n_per_s: Vec3::new(0.0, 0.0, 1.0),
            drift_nm_per_s: Vec3::new(0.01, 0.0, 0.0),
        },
        Fault::SensorScale {
            from_ns: 240 * MS,
            factor: 1.1,
        },
        Fault::SensorSilent {
            from_ns: 260 * MS,
            until_ns: Some(270 * MS),
        },
        Fault::NanSample { at_ns: 280 * MS },
        Fault::EncoderFrozen {
            at_ns: 50 * MS,
            axis: 2,
            until_ns: Some(90 * MS),
        },
        Fault::EncoderCountLoss {
            at_ns: 120 * MS,
            axis: 0,
            counts: 50,
        },
        Fault::EncoderJump {
            at_ns: 130 * MS,
            axis: 1,
            jump_m: 0.001,
        },
        Fault::DriveEmcy {
            at_ns: 350 * MS,
            axis: 2,
            code: 0x4310,
        },
        Fault::DriveHeartbeatLoss {
            at_ns: 420 * MS,
            axis: 1,
        },
    ];
    let clock = SimClock::new(1_000_000_000);
    let sim = Simulator::new(spec, clock.clone()).unwrap();
    let mut sensor = sim.sensor();
    let mut drives = sim.drives();
    let mut buffer = [WrenchSample {
        force_n: Vec3::zeros(),
        torque_nm: Vec3::zeros(),
        counter: 0,
        status: Default::default(),
        received_ns: 0,
    }; 64];
    let start = scenario.script.start;
    let deeper = ActiveJoints {
        q3_m: start.q3_m + 0.004,
        ..start
    };
    // Warm up outside the count (nothing here allocates either, but the
    // count is about the cycles).
    drives.enable().unwrap();
    let before = thread_allocations();
    let mut samples = 0u64;
    let mut faults_seen = 0u64;
    let mut drive_faults = 0u64;
    for cycle in 0..500u64 {
        clock.advance_ns(MS);
        if let Some(s) = sensor.poll().unwrap() {
            samples += 1;
            if !s.is_valid() {
                faults_seen += 1;
            }
        }
        let _ = sensor.drain(&mut buffer).unwrap();
        let _ = drives.positions().unwrap();
        if matches!(drives.state().unwrap(), DriveState::Fault { .. }) {
            drive_faults += 1;
        }
        match cycle {
            10 => drives.set_targets(deeper).unwrap(),
            200 => sensor.tare().unwrap(),
            400 | 460 => {
                let _ = drives.quick_stop();
                let _ = drives.fault_reset();
                let _ = drives.disable();
                let _ = drives.enable();
            }
            _ => {}
        }
    }
    let allocations = thread_allocations() - before;
    assert_eq!(allocations, 0, "{allocations} allocations in 500 cycles");
    // The run did what it says: samples came, the NaN sample was among
    // them, the drives faulted, the tip is in the tissue.
    assert!(samples > 200, "{samples}");
    assert!(faults_seen >= 1);
    assert!(drive_faults > 0);
    assert!(sim.truth().unwrap().tissue_force_n.x > 0.0);
    plant_in_motion_allocates_nothing(&path);
}

/// The plant in motion (issue 26): the Newton-Euler wrench with every
/// inertia, the servos (planned moves, streamed set points) and the drives'
/// own braking ramp, under the same count.
fn plant_in_motion_allocates_nothing(path: &Path) {
    let scenario = sar_config::scenario::load(path).unwrap();
    let mut spec = scenario.spec;
    spec.plant = PlantSpec {
        inertia: Some(RodInertia {
            inertia_perp_kgm2: 0.03,
            inertia_axial_kgm2: 0.001,
            adapter_mass_kg: 0.2,
        }),
        servo: Some(ServoSpec {
            bandwidth_hz: 30.0,
            damping: 0.7,
            max_accel_mps2: 5.0,
            delay_ns: 0,
            inner_loop_hz: 0.0,
        }),
        quick_stop_decel_mps2: Some(2.0),
    };
    // The support moving under it (issue 26), ramped over the moves.
    spec.support_shifts = vec![sar_sim::SupportShift {
        t_ns: 50_000_000,
        shift_m: sar_hal::Vec3::new(0.0, 0.005, -0.002),
        duration_ns: 200_000_000,
    }];
    let clock = SimClock::new(1_000_000_000);
    let sim = Simulator::new(spec, clock.clone()).unwrap();
    let (mut sensor, mut drives) = (sim.sensor(), sim.drives());
    let start = scenario.script.start;
    drives.enable().unwrap();
    let before = thread_allocations();
    let mut moving_accel = 0.0f64;
    for cycle in 0..400u64 {
        clock.advance_ns(MS);
        let _ = sensor.poll().unwrap();
        let _ = drives.positions().unwrap();
        let t = sim.truth().unwrap();
        moving_accel = moving_accel.max(t.joint_accels_mps2[2].abs());
        match cycle {
            10 => drives
                .set_targets(ActiveJoints {
                    q3_m: start.q3_m + 0.004,
                    ..start
                })
                .unwrap(),
            // Streamed set points from where the planned move ended.
            200..=299 => {
                let q = ActiveJoints {
                    q3_m: start.q3_m + 0.004 + 4e-5 * (cycle - 199) as f64,
                    ..start
                };
                drives.stream(q, MS).unwrap();
            }
            300 => drives.quick_stop().unwrap(),
            _ => {}
        }
    }
    let allocations = thread_allocations() - before;
    assert_eq!(
        allocations, 0,
        "{allocations} allocations in 400 cycles in motion"
    );
    assert!(moving_accel > 0.1, "{moving_accel}");
}
