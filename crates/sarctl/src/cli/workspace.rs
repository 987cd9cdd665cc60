//! `sarctl workspace`: the reachable region, read-only. It prints the axes'
//! travel (`[axes] travel_m`) of the configuration (`--config FILE`, else the
//! built-in one that `sard --sim` runs), and, when a daemon publishes its
//! state, the tip's range along base x, y and z reached by moving one axis
//! at a time through its whole travel from the present joint positions, the
//! other two held ([`SWEEP_STEPS`] steps per axis; a step where no pose
//! exists is left out). A target inside these ranges may still be out of
//! reach when it needs two or three axes at once: the ranges are a guide,
//! `move-tip` judges.

use sar_config::Config;
use sar_kinematics::{ActiveJoints, forward};
use sar_msgs::wire::flags;
use sar_shm::Client;
use serde_json::json;
use std::path::Path;
use std::time::Duration;

/// Steps of each axis's sweep (ends included).
pub const SWEEP_STEPS: usize = 101;

/// What moving one axis through its travel does to the tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisSweep {
    /// 1, 2 or 3.
    pub axis: u8,
    /// (min, max) of the tip's base x, y, z, m (`None`: no step had a pose).
    pub tip_range_m: Option<[(f64, f64); 3]>,
}

/// Sweeps each axis through its travel from `q_m`, the others held.
pub fn sweep(cfg: &Config, q_m: [f64; 3]) -> [AxisSweep; 3] {
    let cal = &cfg.estimator.calibration;
    let profile = &cfg.estimator.profile;
    let mut out = [1u8, 2, 3].map(|axis| AxisSweep {
        axis,
        tip_range_m: None,
    });
    for (i, (sweep, (lo, hi))) in out.iter_mut().zip(cfg.axes.travel_m).enumerate() {
        for k in 0..SWEEP_STEPS {
            let v = lo + (hi - lo) * k as f64 / (SWEEP_STEPS - 1) as f64;
            let mut q = q_m;
            if let Some(slot) = q.get_mut(i) {
                *slot = v;
            }
            let joints = ActiveJoints {
                q1_m: q[0],
                q2_m: q[1],
                q3_m: q[2],
            };
            let Ok(pose) = forward(cal, profile, &joints) else {
                continue;
            };
            let t = [pose.tip_m.x, pose.tip_m.y, pose.tip_m.z];
            let range = sweep.tip_range_m.get_or_insert(t.map(|c| (c, c)));
            for (r, c) in range.iter_mut().zip(t) {
                *r = (r.0.min(c), r.1.max(c));
            }
        }
    }
    out
}

/// Runs the command: the configuration at `config` (else the built-in one)
/// and the present pose of the daemon with `prefix`, when one answers.
pub fn run(config: Option<&Path>, prefix: &str, json: bool) -> Result<(), String> {
    let cfg = match config {
        Some(path) => sar_config::load(path).map_err(|e| e.to_string())?,
        None => sar_config::builtin().map_err(|e| e.to_string())?,
    };
    let (present, why) = match present_pose(prefix) {
        Ok(p) => (Some(p), String::new()),
        Err(e) => (None, e),
    };
    print(&cfg, present, &why, json)
}

/// The daemon's joint positions and tip now; why not when it has none.
fn present_pose(prefix: &str) -> Result<([f64; 3], [f64; 3]), String> {
    Client::new(prefix)
        .and_then(|c| c.subscribe())
        .map_err(|e| e.to_string())
        .and_then(|sub| {
            sub.latest(Duration::from_secs(2))
                .ok_or_else(|| "the daemon published nothing within 2 s".to_owned())
        })
        .and_then(|s| {
            if s.flags & flags::POSE != 0 {
                Ok((s.q_m, s.tip_m))
            } else {
                Err("the daemon has no pose now".to_owned())
            }
        })
}

/// Prints the region: `present` is the daemon's joint positions and tip
/// (`None` when no daemon answered; `why` then says why).
pub fn print(
    cfg: &Config,
    present: Option<([f64; 3], [f64; 3])>,
    why: &str,
    json: bool,
) -> Result<(), String> {
    let travel = cfg.axes.travel_m;
    let sweeps = present.map(|(q, _)| sweep(cfg, q));
    if json {
        let sweeps_json = sweeps.map(|s| {
            s.iter()
                .map(|a| {
                    json!({"axis": format!("q{}", a.axis),
                       "tip_x_m": a.tip_range_m.map(|r| [r[0].0, r[0].1]),
                       "tip_y_m": a.tip_range_m.map(|r| [r[1].0, r[1].1]),
                       "tip_z_m": a.tip_range_m.map(|r| [r[2].0, r[2].1])})
                })
                .collect::<Vec<_>>()
        });
        println!(
            "{}",
            json!({
                "configuration": cfg.origin,
                "travel_m": {"q1": [travel[0].0, travel[0].1], "q2": [travel[1].0, travel[1].1],
                             "q3": [travel[2].0, travel[2].1]},
                "present_q_m": present.map(|p| p.0),
                "present_tip_m": present.map(|p| p.1),
                "one_axis_at_a_time": sweeps_json,
                "no_daemon": (present.is_none()).then_some(why),
            })
        );
        return Ok(());
    }
    println!(
        "configuration: {}{}",
        cfg.origin,
        if cfg.origin == "the built-in configuration" {
            " (sard --sim's; --config FILE for another)"
        } else {
            ""
        }
    );
    println!(
        "axis travel ([axes] travel_m): q1 {:.4}..{:.4} m (along base Z), q2 {:.4}..{:.4} m \
         (along base Y), q3 {:.4}..{:.4} m (along base X)",
        travel[0].0, travel[0].1, travel[1].0, travel[1].1, travel[2].0, travel[2].1
    );
    match (present, sweeps) {
        (Some((q, tip)), Some(sweeps)) => {
            println!(
                "present: q [{:.4} {:.4} {:.4}] m, tip [{:.4} {:.4} {:.4}] m (base frame)",
                q[0], q[1], q[2], tip[0], tip[1], tip[2]
            );
            println!("tip range moving one axis at a time through its travel (the others held):");
            for s in sweeps {
                match s.tip_range_m {
                    Some(r) => println!(
                        "  q{}: x {:.4}..{:.4} m, y {:.4}..{:.4} m, z {:.4}..{:.4} m",
                        s.axis, r[0].0, r[0].1, r[1].0, r[1].1, r[2].0, r[2].1
                    ),
                    None => println!("  q{}: no pose along its travel", s.axis),
                }
            }
        }
        _ => println!("present pose: not known ({why})"),
    }
    Ok(())
}
