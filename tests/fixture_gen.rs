//! The replay fixtures (`tests/fixtures/replay/`), made from the simulator's
//! scenarios, deterministically (seeded simulator, `SimClock`): the same
//! code gives the same bytes. Regenerate them with
//!
//! ```text
//! SAR_REGEN_FIXTURES=1 cargo test -p sar-tests --test replay regenerate_fixtures -- --ignored
//! ```
//!
//! - [`daemon_recording`]: the daemon's real `Controller` over the simulator
//!   (automatic reset as in `sard --sim`), one cycle per period, every
//!   message of the daemon's recorder (`convert::cycle_record`) plus the
//!   simulator's truth `/sar/sim/tip_wrench_truth` at each new sample.
//! - [`inputs_recording`]: the scenario's motion script run by the drivers'
//!   runner: only `/sar/sensor/wrench` and `/sar/joints` (as another
//!   program would record them) and the truth at each sample's measure time.

use sar_config as config;
use sar_daemon::sim;
use sar_estimator::Vec3;
use sar_hal::SimClock;
use sar_loop::control::{Envelope, Operator, Request};
use sar_loop::logq;
use sar_msgs::msgs::{Outgoing, RecorderDrops, WrenchStamped};
use sar_record::convert;
use sar_record::{FileOptions, RotatingWriter};
use sar_sim::{Simulator, Truth};
use sar_test_support::rig::controller;
use sar_test_support::truth::run_tapped;
use std::path::Path;

/// The simulated host clock's start, ns.
pub const HOST_START_NS: u64 = 1_000_000_000;
/// The loop's period, ns.
pub const PERIOD_NS: u64 = 1_000_000;

fn arr(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// The tip force the estimator can see: the contact force less the support's
/// friction along the rod (the model has no friction term).
fn visible_truth(t: &Truth) -> Vec3 {
    t.tip_force_n - t.friction_force_n
}

fn writer(
    path: &Path,
    bias: &sar_estimator::cycle::Bias,
    zstd_level: u32,
) -> Result<RotatingWriter, String> {
    let mut o = FileOptions::single(path);
    o.zstd_level = zstd_level;
    o.metadata = vec![convert::replay_metadata(bias, true)];
    RotatingWriter::new(o).map_err(|e| e.to_string())
}

/// The operator requests of the contact fixture: a tare before the contact,
/// a small move (set points, the trajectory the joints are checked
/// against), and limits set to the configured ones.
pub fn contact_requests() -> Vec<(u64, Request)> {
    let limits = sar_estimator::guard::ForceLimits::from_array([10.0, 15.0, 8.0, 12.0, 6.0, 10.0]);
    vec![
        (100, Request::Tare),
        (
            1000,
            Request::MoveTip {
                tip_m: Vec3::new(0.6, 0.2, 0.002),
            },
        ),
        (3000, Request::SetLimits(limits)),
    ]
}

/// Records `cycles` cycles of the daemon's controller over `scenario`, one
/// every `period_ns`, with the operator `requests` (cycle, request), into
/// `path` (see the module documentation).
pub fn daemon_recording(
    scenario: &Path,
    cycles: u64,
    period_ns: u64,
    requests: &[(u64, Request)],
    path: &Path,
) -> Result<u64, String> {
    daemon_recording_at_level(scenario, cycles, period_ns, requests, path, 19)
}

/// [`daemon_recording`] with zstd at `zstd_level` (19 for the committed
/// fixtures; the recorder's default, 0, for long recordings made by tests).
pub fn daemon_recording_at_level(
    scenario: &Path,
    cycles: u64,
    period_ns: u64,
    requests: &[(u64, Request)],
    path: &Path,
    zstd_level: u32,
) -> Result<u64, String> {
    let cfg = config::builtin().map_err(|e| e.to_string())?;
    let mut scenario = sar_config::scenario::load(scenario).map_err(|e| e.to_string())?;
    // As `sard --sim`: the simulated drives run the configured profile.
    scenario.spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
    scenario.spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
    let clock = SimClock::new(HOST_START_NS);
    let (simulator, sensor, drives, bias) =
        sim::simulated(&scenario, clock.clone()).map_err(|e| e.to_string())?;
    let (log, _thread, _queue) = logq::channel(false);
    let operator = Operator::new();
    let mut c =
        controller(&cfg, bias, sensor, drives, operator.clone(), log).map_err(|e| e.to_string())?;
    let mut w = writer(path, &bias, zstd_level)?;
    let mut status = RecorderDrops::default();
    let mut last_joints: Option<u64> = None;
    let mut error = None;
    for cycle in 1..=cycles {
        clock.advance_ns(period_ns);
        for (_, request) in requests.iter().filter(|(k, _)| *k == cycle) {
            operator
                .requests
                .push(Envelope {
                    id: cycle,
                    request: *request,
                })
                .map_err(|_| "the request queue is full".to_owned())?;
        }
        while operator.replies.pop().is_some() {}
        let out = *c.step(cycle, || Some(clock.now_ns()));
        let (input, decision) = (*c.loop_input(), *c.decision());
        let joints_new = last_joints != Some(input.joints.stamp_ns);
        last_joints = Some(input.joints.stamp_ns);
        convert::cycle_record(&input, &decision, joints_new, |m| {
            status.stamp_ns = m.stamp_ns();
            if let Err(e) = w.write(&m, &status) {
                error.get_or_insert(e.to_string());
            }
        });
        if out.new_sample
            && let Ok(t) = simulator.truth()
        {
            let m = Outgoing::SimTruth(WrenchStamped::base_force(
                clock.now_ns(),
                arr(&visible_truth(&t)),
            ));
            if let Err(e) = w.write(&m, &status) {
                error.get_or_insert(e.to_string());
            }
        }
        if let Some(e) = error {
            return Err(e);
        }
    }
    w.close(&status).map_err(|e| e.to_string())?;
    Ok(cycles)
}

/// Runs `scenario`'s motion script and records its inputs alone into `path`
/// (see the module documentation); returns the sensor samples written.
pub fn inputs_recording(scenario: &Path, path: &Path) -> Result<u64, String> {
    let s = sar_config::scenario::load(scenario).map_err(|e| e.to_string())?;
    let clock = SimClock::new(HOST_START_NS);
    let sim = Simulator::new(s.spec.clone(), clock.clone()).map_err(|e| e.to_string())?;
    let (r, truths) = run_tapped(&s.script, &sim, &clock, PERIOD_NS).map_err(|e| e.to_string())?;
    let bias = sar_estimator::cycle::Bias {
        force_n: s.spec.sensor.bias_n,
        torque_nm: s.spec.sensor.bias_nm,
    };
    // Every message by its stamp (joints before a sensor sample of the same
    // stamp, the truth after it).
    let mut msgs: Vec<(u64, u8, Outgoing)> = Vec::new();
    for p in &r.positions {
        if p.valid {
            msgs.push((
                p.stamp_ns,
                0,
                Outgoing::Joints(sar_msgs::msgs::ActiveJointState {
                    stamp_ns: p.stamp_ns,
                    q_m: [p.joints.q1_m, p.joints.q2_m, p.joints.q3_m],
                }),
            ));
        }
    }
    let latency_ns = s.spec.sensor.latency_ns;
    for sample in &r.sensor_samples {
        msgs.push((
            sample.received_ns,
            1,
            Outgoing::SensorWrench(WrenchStamped::sensor(
                sample.received_ns,
                arr(&sample.force_n),
                arr(&sample.torque_nm),
            )),
        ));
        let elapsed = sample
            .received_ns
            .saturating_sub(latency_ns)
            .saturating_sub(HOST_START_NS);
        let i = truths.partition_point(|t| t.elapsed_ns <= elapsed);
        if let Some(t) = i.checked_sub(1).and_then(|i| truths.get(i)) {
            msgs.push((
                sample.received_ns,
                2,
                Outgoing::SimTruth(WrenchStamped::base_force(
                    sample.received_ns,
                    arr(&visible_truth(t)),
                )),
            ));
        }
    }
    msgs.sort_by_key(|(t, k, _)| (*t, *k));
    let mut w = writer(path, &bias, 19)?;
    let mut status = RecorderDrops::default();
    for (t, _, m) in &msgs {
        status.stamp_ns = *t;
        w.write(m, &status).map_err(|e| e.to_string())?;
    }
    w.close(&status).map_err(|e| e.to_string())?;
    Ok(r.sensor_samples.len() as u64)
}
