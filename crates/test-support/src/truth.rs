//! The simulator's truth at every position read of a run (every tick of the
//! generic runner): the runner stays generic, the test sees the truth.

use crate::drives::{DriveHook, Hooked};
use sar_hal::{AxisDrives, JointPositions, SimClock};
use sar_sim::runner::{Run, RunError, RunOptions, run};
use sar_sim::scenario::MotionScript;
use sar_sim::{SimDrives, SimError, Simulator, Truth};

/// The hook that takes the simulator's truth before each position read.
pub struct TruthTap {
    /// The simulator whose truth is taken.
    pub sim: Simulator<SimClock>,
    /// The truths taken, in time order.
    pub truths: Vec<Truth>,
}

impl DriveHook<SimDrives<SimClock>> for TruthTap {
    fn positions(&mut self, inner: &mut SimDrives<SimClock>) -> Result<JointPositions, SimError> {
        if let Ok(truth) = self.sim.truth() {
            self.truths.push(truth);
        }
        inner.positions()
    }
}

/// `sim`'s drives with the truth taken at every position read.
pub fn tapped(sim: &Simulator<SimClock>) -> Hooked<SimDrives<SimClock>, TruthTap> {
    Hooked::new(
        sim.drives(),
        TruthTap {
            sim: sim.clone(),
            truths: Vec::new(),
        },
    )
}

/// Runs `script` on `sim`'s sensor and tapped drives, polled every
/// `period_ns` of `clock`: the run and the truth at each of its ticks.
pub fn run_tapped(
    script: &MotionScript,
    sim: &Simulator<SimClock>,
    clock: &SimClock,
    period_ns: u64,
) -> Result<(Run, Vec<Truth>), RunError> {
    let mut sensor = sim.sensor();
    let mut drives = tapped(sim);
    let options = RunOptions::for_script(script, period_ns);
    let r = run(script, &mut sensor, &mut drives, clock, &options)?;
    Ok((r, drives.hook.truths))
}

/// The truth taken exactly `elapsed_ns` after the simulator's start, if any.
pub fn truth_at(truths: &[Truth], elapsed_ns: u64) -> Option<&Truth> {
    let i = truths.partition_point(|t| t.elapsed_ns < elapsed_ns);
    truths.get(i).filter(|t| t.elapsed_ns == elapsed_ns)
}
