//! What the daemon's benchmarks share: the loop's controller over the
//! simulator of a scenario, as `sard --sim` builds it.
#![allow(dead_code)]

use sar_config::Config;
use sar_config::scenario::Scenario;
use sar_daemon::sim;
use sar_estimator::cycle::Bias;
use sar_hal::Clock;
use sar_loop::control::{Controller, Operator};
use sar_loop::logq::LogSender;
use sar_sim::{SimDrives, SimSensor, Simulator};

/// The controller of the simulated robot.
pub type SimController<C> = Controller<SimSensor<C>, SimDrives<C>>;

/// The simulator of `scenario` on `clock` (keep it while the controller
/// runs), the controller of `cfg` over its sensor and drives (automatic
/// first reset on), and the bias it starts with.
pub fn sim_controller<C: Clock + Clone>(
    cfg: &Config,
    scenario: &Scenario,
    clock: C,
    operator: Operator,
    log: LogSender,
) -> (Simulator<C>, SimController<C>, Bias) {
    let (sim, sensor, drives, bias) = sim::simulated(scenario, clock).unwrap();
    let controller =
        sar_test_support::rig::controller(cfg, bias, sensor, drives, operator, log).unwrap();
    (sim, controller, bias)
}
