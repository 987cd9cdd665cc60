//! The simulated robot of `sard --sim`: the built-in demo scenario, and the
//! simulator made from a scenario on a given clock (the host's monotonic
//! clock for a real-time run, so that the simulated world advances with real
//! time; a `SimClock` in tests).

use sar_config::ConfigError;
use sar_config::scenario::{self, Scenario};
use sar_estimator::cycle::Bias;
use sar_hal::Clock;
use sar_sim::{SimDrives, SimError, SimSensor, Simulator};

/// The built-in demo scenario (a tip contact rising into Warn).
pub const DEMO_SCENARIO_TOML: &str = include_str!("demo_scenario.toml");

/// The built-in demo scenario, checked.
pub fn demo_scenario() -> Result<Scenario, ConfigError> {
    scenario::parse(DEMO_SCENARIO_TOML, "(built-in demo scenario)")
}

/// The simulator, its sensor and drives, and the starting bias.
pub type Simulated<C> = (Simulator<C>, SimSensor<C>, SimDrives<C>, Bias);

/// The simulated sensor and drives of `scenario` on `clock`, and the bias the
/// estimator starts with: the simulated sensor's initial bias, as if it had
/// been measured beforehand with the rod detached.
pub fn simulated<C: Clock + Clone>(
    scenario: &Scenario,
    clock: C,
) -> Result<Simulated<C>, SimError> {
    let sim = Simulator::new(scenario.spec.clone(), clock)?;
    let bias = Bias {
        force_n: scenario.spec.sensor.bias_n,
        torque_nm: scenario.spec.sensor.bias_nm,
    };
    let sensor = sim.sensor();
    let drives = sim.drives();
    Ok((sim, sensor, drives, bias))
}
