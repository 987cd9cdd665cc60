//! The RDT device emulator on a loopback UDP port, streaming what the
//! simulated demo robot's sensor reads at rest (without its bias, with the
//! HEX-E's noise), as `crates/daemon/tests/deploy.rs` starts it; for
//! `scripts/sard-footprint.sh --rdt`.
//!
//! `cargo run --release -p sar-daemon --example rdt_emulator -- CONFIG [PERIOD_US]`
//! writes to CONFIG the built-in configuration with `[drivers.sensor]` on the
//! emulator (the axes simulated), prints the emulator's address, and streams
//! until it is killed: without PERIOD_US, at the rate the driver asks
//! (OnRobot's rate command: 500 Hz); with it, one packet every PERIOD_US
//! whatever the driver asks (the emulator then speaks ATI's dialect, whose
//! rate is set on the device, e.g. 143 for ATI's 7 kHz).

use sar_daemon::sim;
use sar_rdt::emulator::{Emulator, EmulatorConfig, Pacing, counts_for};

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let config = args
        .next()
        .ok_or("usage: rdt_emulator CONFIG [PERIOD_US]")?;
    let fixed_period_us: Option<u64> = match args.next() {
        Some(p) => Some(p.parse().map_err(|e| format!("PERIOD_US {p:?}: {e}"))?),
        None => None,
    };
    let mut scenario = sim::demo_scenario().map_err(|e| e.to_string())?;
    // The reading without noise: the emulator adds its own.
    scenario.spec.sensor.noise_n = sar_estimator::Vec3::zeros();
    scenario.spec.sensor.noise_nm = sar_estimator::Vec3::zeros();
    let (_sim, mut sensor, _drives, bias) =
        sim::simulated(&scenario, sar_hal::SimClock::new(1_000_000_000))
            .map_err(|e| e.to_string())?;
    let s = sar_hal::ForceSensor::wait(&mut sensor, 1_000_000_000).map_err(|e| e.to_string())?;
    let (f, t) = (s.force_n - bias.force_n, s.torque_nm - bias.torque_nm);
    let mut emu = EmulatorConfig::new(Pacing::Periodic {
        period_ns: fixed_period_us.unwrap_or(1000).saturating_mul(1000),
    });
    if fixed_period_us.is_some() {
        // ATI's dialect ignores the driver's rate command: the period stays.
        emu.flavour = sar_rdt::Flavour::Ati;
    }
    emu.counts = counts_for([f.x, f.y, f.z], [t.x, t.y, t.z], 10_000.0, 100_000.0);
    emu.noise_counts = [2000.0, 2000.0, 8000.0, 1000.0, 1000.0, 200.0];
    emu.seed = 0x5afe;
    let emulator = Emulator::start(emu).map_err(|e| e.to_string())?;
    let toml = sar_config::DEFAULT_TOML.replace(
        "[drivers.sensor]\nkind = \"sim\"",
        &format!(
            "[drivers.sensor]\nkind = \"rdt\"\naddress = \"{}\"\ncounts_per_n = 10000.0\ncounts_per_nm = 100000.0\n",
            emulator.address()
        ),
    );
    if toml == sar_config::DEFAULT_TOML {
        return Err("the built-in configuration's [drivers.sensor] section moved".to_owned());
    }
    std::fs::write(&config, toml).map_err(|e| format!("{config}: {e}"))?;
    println!("{}", emulator.address());
    loop {
        std::thread::park();
    }
}
