//! `sard`, the SAR daemon: the fixed-rate control loop on the robot named by
//! the configuration, or on the simulated robot (`--sim`).

use clap::Parser;
use sar_daemon::control::{Controller, Operator};
use sar_daemon::notify::{Notifier, Watchdog};
use sar_daemon::runloop::{self, RunLimits};
use sar_daemon::shm::DaemonShm;
use sar_daemon::stats::LoopStats;
use sar_daemon::wire::limits_array;
use sar_daemon::{config, logq, rt, sim};
use sar_drivers::MonotonicClock;
use std::path::PathBuf;
use std::process::ExitCode;

/// The SAR daemon.
#[derive(Debug, Parser)]
#[command(
    name = "sard",
    version,
    about = "The SAR daemon: fixed-rate tip-force loop with the force-limit guard"
)]
struct Args {
    /// The robot's configuration (TOML, INTERFACES.md 2). With --sim, the
    /// built-in configuration when absent.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Run on the simulated robot, in real time.
    #[arg(long)]
    sim: bool,
    /// With --sim: the scenario to simulate (default: the built-in demo, a
    /// tip contact rising into Warn).
    #[arg(long, value_name = "FILE", requires = "sim")]
    scenario: Option<PathBuf>,
    /// Check a configuration file and exit (0 when valid).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["sim", "config", "scenario"])]
    check_config: Option<PathBuf>,
    /// Prefix of the shared-memory service names (one daemon per prefix).
    #[arg(long, env = "SAR_SERVICE_PREFIX", default_value = sar_daemon::shm::DEFAULT_PREFIX)]
    prefix: String,
    /// Stop after this many cycles (tests and benchmarks).
    #[arg(long, hide = true)]
    max_cycles: Option<u64>,
    /// Stall the loop on purpose after this many cycles (watchdog test).
    #[arg(long, hide = true)]
    stall_after_cycles: Option<u64>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // iceoryx2's own log (e.g. "no config file was loaded") only for errors.
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("sard: {message}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    if let Some(path) = &args.check_config {
        let c = config::load(path).map_err(|e| e.to_string())?;
        println!(
            "{}: valid ({}, {} Hz)",
            path.display(),
            c.manipulator_name,
            c.loop_.rate_hz
        );
        return Ok(());
    }
    let cfg = match &args.config {
        Some(path) => config::load(path).map_err(|e| e.to_string())?,
        None if args.sim => config::builtin().map_err(|e| e.to_string())?,
        None => return Err("give --config FILE, or --sim for the simulated robot".to_owned()),
    };
    if !args.sim {
        return Err(format!(
            "{}: real devices ({:?} sensor, {:?} axes) are not supported by this build yet; run with --sim",
            cfg.origin, cfg.sensor_driver, cfg.axes_driver
        ));
    }
    let scenario = match &args.scenario {
        Some(path) => sar_drivers::scenario::load(path).map_err(|e| e.to_string())?,
        None => sim::demo_scenario().map_err(|e| e.to_string())?,
    };
    rt::install_stop_handler().map_err(|e| format!("cannot install the signal handler: {e}"))?;

    // Real-time settings: said once, here, when they cannot be applied.
    if let Err(e) = rt::lock_memory() {
        tracing::warn!("{e}; running without locked memory");
    }
    if let Err(e) = rt::set_fifo(cfg.loop_.priority) {
        tracing::warn!("{e}; running at normal priority");
    }
    if let Some(cpu) = cfg.loop_.cpu
        && let Err(e) = rt::pin_to_cpu(cpu)
    {
        tracing::warn!("{e}; running unpinned");
    }

    let clock = MonotonicClock::new().map_err(|e| e.to_string())?;
    let (simulator, sensor, drives, bias) =
        sim::simulated(&scenario, clock).map_err(|e| format!("{}: {e}", scenario.origin))?;
    let operator = Operator::new();
    let truth_sim = simulator.clone();
    let mut shm = DaemonShm::create(
        &args.prefix,
        operator.clone(),
        limits_array(&cfg.estimator.guard.limits()),
        Some(Box::new(move || {
            truth_sim.truth().ok().map(|t| t.tip_force_n)
        })),
    )?;
    let (log, log_thread, _queue) = logq::channel(true);
    let mut controller = Controller::new(
        &cfg.estimator,
        bias,
        cfg.axes.travel_m,
        sensor,
        drives,
        operator,
        log.clone(),
        true,
    )
    .map_err(|e| format!("{}: {e}", cfg.origin))?;
    // Ping systemd's watchdog ten times a second from the loop.
    let every = (cfg.loop_.rate_hz / 10.0).round().max(1.0) as u64;
    let mut watchdog = Watchdog::new(Notifier::from_env(), every);
    let mut stats = LoopStats::default();
    tracing::info!(
        "sard: simulating {:?} ({}) at {} Hz with {} ({})",
        scenario.name,
        scenario.origin,
        cfg.loop_.rate_hz,
        cfg.manipulator_name,
        cfg.origin
    );
    runloop::run(
        &mut controller,
        &cfg.loop_,
        RunLimits {
            max_cycles: args.max_cycles,
            stall_after_cycles: args.stall_after_cycles,
        },
        &mut stats,
        &mut shm,
        &mut watchdog,
        &log,
    );
    if let Some(t) = log_thread {
        t.finish();
    }
    let out = controller.output();
    tracing::info!(
        "sard: stopped after {} cycles, drives halted; guard {} ({}); wake-up latency p50 {} us p99 {} us max {} us; compute p99 {} us; {} overruns; {} quick stops",
        stats.cycles,
        out.guard_state,
        out.guard_reason,
        stats.wakeup.quantile_ns(0.5) / 1000,
        stats.wakeup.quantile_ns(0.99) / 1000,
        stats.wakeup.max_ns() / 1000,
        stats.compute.quantile_ns(0.99) / 1000,
        stats.overruns,
        controller.counts().quick_stops,
    );
    Ok(())
}
