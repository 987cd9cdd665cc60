//! `sard`, the SAR daemon: the fixed-rate control loop on the robot named by
//! the configuration, or on the simulated robot (`--sim`).

use clap::Parser;
use sar_config as config;
use sar_daemon::{devices, sim};
use sar_drivers::{AxisDrives, ForceSensor, MonotonicClock};
use sar_estimator::Vec3;
use sar_estimator::cycle::Bias;
use sar_loop::control::{Controller, DrivesCycle, Operator};
use sar_loop::notify::{Notifier, Watchdog};
use sar_loop::publish::SimTruthFn;
use sar_loop::runloop::{self, Edges, RunLimits};
use sar_loop::stats::LoopStats;
use sar_loop::{logq, rt};
use sar_record::SceneOptions;
use sar_record::live::{LiveRecorder, RecordManager, RecordSwitch};
use sar_shm::{DaemonShm, RecordCommands};
use std::io::Write as _;
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
    /// The robot's configuration (TOML, INTERFACES.md 2): runs on the devices
    /// its [drivers] name. With --sim, the built-in configuration when absent.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Run on the simulated robot, in real time (whatever [drivers] names).
    #[arg(long)]
    sim: bool,
    /// The scenario of the simulated parts (with --sim, or the parts the
    /// configuration leaves "sim"; default: the built-in demo, a tip contact
    /// rising into Warn).
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// Check a configuration file and exit (0 when valid).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["sim", "config", "scenario"])]
    check_config: Option<PathBuf>,
    /// Prefix of the shared-memory service names (one daemon per prefix).
    #[arg(long, env = "SAR_SERVICE_PREFIX", default_value = sar_shm::DEFAULT_PREFIX)]
    prefix: String,
    /// Stop after this many cycles (tests and benchmarks).
    #[arg(long, hide = true)]
    max_cycles: Option<u64>,
    /// Stall the loop on purpose after this many cycles (watchdog test).
    #[arg(long, hide = true)]
    stall_after_cycles: Option<u64>,
}

/// A real sensor must send its first sample within this at start, ns.
const FIRST_SAMPLE_TIMEOUT_NS: u64 = 2_000_000_000;

fn main() -> ExitCode {
    let args = Args::parse();
    // iceoryx2's own log (e.g. "no config file was loaded") only for errors.
    sar_shm::log_errors_only();
    // Colours only on a terminal: journald and log files get plain text.
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .init();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            // Not `eprintln!`: a closed stderr (SIGPIPE is ignored) must
            // not turn a one-line refusal into a panic.
            let _ = writeln!(std::io::stderr(), "sard: {message}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    if let Some(path) = &args.check_config {
        return check_config(path);
    }
    let cfg = configuration(args)?;
    let (rdt, canopen) = chosen_devices(args, &cfg)?;
    rt::install_stop_handler().map_err(|e| format!("cannot install the signal handler: {e}"))?;

    // The sensor first: its receive thread keeps the normal priority.
    let real_sensor = match rdt {
        Some(c) => {
            let mut sensor = devices::connect_rdt(c)?;
            devices::first_sample(&mut sensor, FIRST_SAMPLE_TIMEOUT_NS)?;
            Some(sensor)
        }
        None => None,
    };
    // The simulator only for the parts that are simulated (none on the
    // real robot).
    let mut scenario_name = String::new();
    let simulated = if real_sensor.is_some() && canopen.is_some() {
        if let Some(path) = &args.scenario {
            return Err(format!(
                "--scenario {}: nothing is simulated ({} names a real sensor and real axes)",
                path.display(),
                cfg.origin
            ));
        }
        None
    } else {
        let scenario = scenario(args, &cfg)?;
        scenario_name = scenario.name.clone();
        let clock = MonotonicClock::new().map_err(|e| e.to_string())?;
        Some(sim::simulated(&scenario, clock).map_err(|e| format!("{}: {e}", scenario.origin))?)
    };
    // The start bias, decided once for the estimator and the recordings: a
    // real sensor starts with none (the operator tares), the simulated one
    // with the scenario's, as if measured beforehand.
    let bias = match (&real_sensor, &simulated) {
        (None, Some((_, _, _, sim_bias))) => *sim_bias,
        _ => Bias::force_only(Vec3::zeros()),
    };
    // The simulator's true tip force only where the sensor is simulated.
    let truth = match (&real_sensor, &simulated) {
        (None, Some((simulator, ..))) => Some(truth_of(simulator.clone())),
        _ => None,
    };
    let operator = Operator::new();
    // The shared memory in the runtime directory (`SAR_RUNTIME_DIR`, default
    // /run/sar: the access model, README "Access"); a SIGTERM while iceoryx2
    // is stuck on a damaged file still ends sard.
    let shm = match DaemonShm::create_in(
        &sar_shm::runtime_dir(),
        &args.prefix,
        operator.clone(),
        cfg.estimator.guard.force_limits().to_array(),
        &rt::stop_requested,
    ) {
        Ok(shm) => shm,
        Err(sar_shm::ShmError::Stopped) => {
            tracing::info!(
                "sard: stopped while creating the shared-memory services (the loop never ran)"
            );
            return Ok(());
        }
        Err(e) => return Err(e.to_string()),
    };
    // Recording (`[record]`, `sarctl record start|stop`): its manager thread
    // (which opens and closes the files, never the loop) starts here, before
    // the real-time settings, so that it and the writer threads it starts
    // keep the normal priority and every CPU.
    tracing::info!(
        "recordings go to {} ([record] directory)",
        cfg.record.directory.display()
    );
    let switch = std::sync::Arc::new(RecordSwitch::new(cfg.loop_.period_ns));
    let (recording, recorder) = RecordManager::start(
        cfg.record.clone(),
        SceneOptions::from_config(&cfg),
        bias,
        std::sync::Arc::clone(&switch),
    )?;
    let shm = shm.with_record_commands(std::sync::Arc::new(SwitchCommands(switch)));
    real_time(&cfg);
    let run = Run {
        args,
        cfg: &cfg,
        operator,
        shm,
        recorder,
        truth,
        recording,
        bias,
        auto_reset: args.sim,
    };
    let sensor_what = match (&real_sensor, &simulated) {
        (Some(s), _) => format!("the RDT sensor at {}", s.config().address),
        _ => format!("the simulated sensor of {scenario_name:?}"),
    };
    match (real_sensor, canopen, simulated) {
        (None, None, Some((_, sensor, drives, _))) => run.run(
            sensor,
            drives,
            None,
            &format!("{sensor_what} and the simulated axes"),
        ),
        (Some(sensor), None, Some((_, _, drives, _))) => run.run(
            sensor,
            drives,
            None,
            &format!("{sensor_what} and the simulated axes"),
        ),
        #[cfg(all(feature = "socketcan", target_os = "linux"))]
        (sensor, Some((interface, c)), simulated) => {
            let drives = start_canopen(&interface, c)?;
            let axes_what = format!("the CANopen drives on {interface}");
            let what = format!("{sensor_what} and {axes_what}");
            match (sensor, simulated) {
                (Some(sensor), _) => run.run(sensor, drives, Some(devices::canopen_cycle), &what),
                (None, Some((_, sensor, _, _))) => {
                    run.run(sensor, drives, Some(devices::canopen_cycle), &what)
                }
                (None, None) => Err(NO_SIMULATOR.to_owned()),
            }
        }
        #[cfg(not(all(feature = "socketcan", target_os = "linux")))]
        (_, Some((interface, _)), _) => Err(format!(
            "{}: CANopen drives on {interface} need the `socketcan` feature",
            cfg.origin
        )),
        (_, None, None) => Err(NO_SIMULATOR.to_owned()),
    }
}

/// A combination of devices that needs the simulator found none (a bug:
/// the simulator is made whenever a part is simulated).
const NO_SIMULATOR: &str = "internal error: a simulated part without the simulator";

/// `sard --check-config FILE`.
fn check_config(path: &std::path::Path) -> Result<(), String> {
    let c = config::load(path).map_err(|e| e.to_string())?;
    println!(
        "{}: valid ({}, {} Hz)",
        path.display(),
        c.manipulator_name,
        c.loop_.rate_hz
    );
    Ok(())
}

/// The configuration `--config` names, or the built-in one with `--sim`.
fn configuration(args: &Args) -> Result<config::Config, String> {
    let mut cfg = match &args.config {
        Some(path) => config::load(path).map_err(|e| e.to_string())?,
        None if args.sim => config::builtin().map_err(|e| e.to_string())?,
        None => return Err("give --config FILE, or --sim for the simulated robot".to_owned()),
    };
    // `[record] directory`: a relative one is resolved once, here, against
    // the working directory the daemon starts in, and said in the log once
    // the devices are up (a refusal at start stays one line).
    if cfg.record.directory.is_relative() {
        let cwd = std::env::current_dir()
            .map_err(|e| format!("cannot read the working directory: {e}"))?;
        cfg.record.directory = cwd.join(&cfg.record.directory);
    }
    Ok(cfg)
}

/// The real sensor and drives a configuration names (`None`: simulated).
type RealDevices = (
    Option<sar_drivers::rdt::RdtConfig>,
    Option<(String, sar_drivers::canopen::CanOpenConfig)>,
);

/// The real devices to run: with --sim none; otherwise those the file names
/// (a part it leaves "sim" is simulated: a bench set-up).
fn chosen_devices(args: &Args, cfg: &config::Config) -> Result<RealDevices, String> {
    if args.sim {
        return Ok((None, None));
    }
    let canopen = devices::canopen_config(cfg);
    if let Some((interface, _)) = &canopen
        && !cfg!(all(feature = "socketcan", target_os = "linux"))
    {
        return Err(format!(
            "{}: drivers.axes.kind = \"canopen\" (interface {interface}) needs sard built with the `socketcan` feature (Linux); this build has no SocketCAN",
            cfg.origin
        ));
    }
    Ok((devices::rdt_config(cfg), canopen))
}

/// The scenario of the simulated parts, its drives running the configured
/// profile as configured drives would (the loop's plan is then the
/// trajectory they follow).
fn scenario(args: &Args, cfg: &config::Config) -> Result<config::scenario::Scenario, String> {
    let mut scenario = match &args.scenario {
        Some(path) => config::scenario::load(path).map_err(|e| e.to_string())?,
        None => sim::demo_scenario().map_err(|e| e.to_string())?,
    };
    scenario.spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
    scenario.spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
    Ok(scenario)
}

/// The simulator's truth, asked once per cycle by the loop.
fn truth_of(simulator: sar_drivers::sim::Simulator<MonotonicClock>) -> SimTruthFn {
    Box::new(move || {
        simulator.truth().ok().map(|t| sar_loop::publish::SimTruth {
            tip_force_n: t.tip_force_n,
            friction_force_n: t.friction_force_n,
            elapsed_ns: t.elapsed_ns,
        })
    })
}

/// Real-time settings: said once, here, when they cannot be applied. After
/// the publishing and recording threads have started, so that they keep the
/// normal priority and every CPU.
fn real_time(cfg: &config::Config) {
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
}

/// Opens the CAN interface, starts the drives and brings them to `Ready`.
#[cfg(all(feature = "socketcan", target_os = "linux"))]
fn start_canopen(
    interface: &str,
    config: sar_drivers::canopen::CanOpenConfig,
) -> Result<
    sar_drivers::canopen::CanOpenDrives<sar_drivers::canopen::socketcan::CanSocket, MonotonicClock>,
    String,
> {
    let socket = sar_drivers::canopen::socketcan::open(interface).map_err(|e| e.to_string())?;
    let clock = MonotonicClock::new().map_err(|e| e.to_string())?;
    let period_ns = config.sync_period_ns;
    let mut drives = sar_drivers::canopen::CanOpenDrives::start(socket, clock, config)
        .map_err(|e| format!("CANopen drives on {interface}: {e}"))?;
    let mut next_ns = rt::monotonic_ns().unwrap_or(0);
    devices::bring_up(&mut drives, interface, 200, || {
        next_ns = next_ns.saturating_add(period_ns);
        rt::sleep_until_ns(next_ns);
    })?;
    Ok(drives)
}

/// `sarctl record start|stop`, from the transport to the recording's switch.
#[derive(Debug)]
struct SwitchCommands(std::sync::Arc<RecordSwitch>);

impl RecordCommands for SwitchCommands {
    fn start(&self) -> u64 {
        self.0.request_start()
    }
    fn stop(&self) -> u64 {
        self.0.request_stop()
    }
    fn answer(&self, ticket: u64) -> Option<Result<String, String>> {
        self.0.answer(ticket)
    }
}

/// What every combination of devices runs with.
struct Run<'a> {
    args: &'a Args,
    cfg: &'a config::Config,
    operator: Operator,
    shm: DaemonShm,
    recorder: LiveRecorder,
    truth: Option<SimTruthFn>,
    recording: RecordManager,
    /// The start bias (decided once in `run`).
    bias: Bias,
    auto_reset: bool,
}

impl Run<'_> {
    fn run<S: ForceSensor, D: AxisDrives>(
        mut self,
        sensor: S,
        drives: D,
        drives_cycle: Option<DrivesCycle<D>>,
        what: &str,
    ) -> Result<(), String> {
        let cfg = self.cfg;
        let (log, log_thread, _queue) = logq::channel(true);
        let mut controller = Controller::new(
            &cfg.estimator,
            self.bias,
            cfg.step_config(),
            sensor,
            drives,
            self.operator,
            log.clone(),
            self.auto_reset,
        )
        .map_err(|e| format!("{}: {e}", cfg.origin))?;
        if let Some(hook) = drives_cycle {
            controller = controller.with_drives_cycle(hook);
        }
        // Ping systemd's watchdog ten times a second from the loop.
        let every = (cfg.loop_.rate_hz / 10.0).round().max(1.0) as u64;
        let mut watchdog = Watchdog::new(Notifier::from_env(), every);
        let mut stats = LoopStats::default();
        tracing::info!(
            "sard: running {} ({}) at {} Hz with {what}",
            cfg.manipulator_name,
            cfg.origin,
            cfg.loop_.rate_hz,
        );
        // The sinks' last counters: said in the stop line below.
        let health = runloop::run(
            &mut controller,
            &cfg.loop_,
            RunLimits {
                max_cycles: self.args.max_cycles,
                stall_after_cycles: self.args.stall_after_cycles,
            },
            &mut stats,
            Edges {
                // The recorder first: the publisher puts its counters in
                // the published state.
                sinks: (&mut self.recorder, &mut self.shm),
                truth: self.truth.take(),
                watchdog: &mut watchdog,
                log: &log,
            },
        );
        // Which signal ended the loop (SIGTERM, SIGHUP, ...: the same clean
        // stop for each), said before the recording is closed.
        let by = match rt::stop_signal() {
            Some(sig) => {
                let name = rt::signal_name(sig);
                tracing::info!("sard: {name} received: stopping (drives halted, recording closed)");
                format!(" on {name}")
            }
            None => String::new(),
        };
        // The last recording closed (its writer drains the queue first).
        self.recorder.release();
        self.recording.finish();
        if let Some(t) = log_thread {
            t.finish();
        }
        let out = controller.output();
        tracing::info!(
            "sard: stopped after {} cycles{by}, drives halted; guard {} ({}); wake-up latency p50 {} us p99 {} us max {} us; compute p99 {} us; {} overruns ({} periods skipped); {} quick stops; {} states dropped by the publisher's queue; {} messages dropped by the recorder",
            stats.cycles,
            out.guard_state,
            out.guard_reason,
            stats.wakeup.quantile_ns(0.5) / 1000,
            stats.wakeup.quantile_ns(0.99) / 1000,
            stats.wakeup.max_ns() / 1000,
            stats.compute.quantile_ns(0.99) / 1000,
            stats.overruns,
            stats.skipped_periods,
            controller.counts().quick_stops,
            health.publish_queue_drops,
            health.recorder_drops,
        );
        Ok(())
    }
}
