//! `sard`, the SAR daemon: the fixed-rate control loop on the robot named by
//! the configuration, or on the simulated robot (`--sim`).

use clap::Parser;
use sar_config as config;
use sar_daemon::{devices, sim};
use sar_estimator::Vec3;
use sar_estimator::cycle::Bias;
use sar_hal::{AxisDrives, Clock, ForceSensor, MonotonicClock, SimClock};
use sar_loop::control::{Controller, DrivesCycle, Operator};
use sar_loop::notify::{Notifier, Watchdog};
use sar_loop::publish::SimTruthFn;
use sar_loop::runloop::{self, Edges, RunLimits};
use sar_loop::stats::LoopStats;
use sar_loop::time::{LoopClock, RealTime, SimulatedTime, Speed};
use sar_loop::{logq, rt};
use sar_rdt::RdtSensor;
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
    /// With --sim: run in simulated time, N times as fast as real time
    /// (0 < N <= 1000) or as fast as the machine allows (`max`); a cycle
    /// then takes no simulated time, so a run is the same whatever the
    /// host's load. Default: real time.
    #[arg(long, value_name = "N|max", requires = "sim", value_parser = Speed::parse)]
    speed: Option<Speed>,
    /// Stop after this many cycles (tests and benchmarks).
    #[arg(long, hide = true)]
    max_cycles: Option<u64>,
    /// Stall the loop on purpose after this many cycles (watchdog test).
    #[arg(long, hide = true)]
    stall_after_cycles: Option<u64>,
}

/// The simulated parts on the simulator's clock `C` (the monotonic clock in
/// real time, the loop's simulated clock with `--speed`).
type Simulated<C> = sim::Simulated<C>;

/// Where simulated time (`--speed`) starts, ns: one second, so that no
/// stamp is 0.
const SIMULATED_EPOCH_NS: u64 = 1_000_000_000;

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

/// The daemon: the configuration and its devices, the shared memory and
/// the recording, then the loop on the devices the configuration names.
fn run(args: &Args) -> Result<(), String> {
    if let Some(path) = &args.check_config {
        return check_config(path);
    }
    let cfg = configuration(args)?;
    let (rdt, canopen) = chosen_devices(args, &cfg)?;
    match args.speed {
        None => {
            let clock = MonotonicClock::new().map_err(|e| e.to_string())?;
            run_on_clock(args, &cfg, (rdt, canopen), clock, &RealTime)
        }
        Some(speed) => {
            // Simulated time starts at a fixed time, not the host's: two
            // runs of a scenario are the same run, stamps included.
            let clock = SimClock::new(SIMULATED_EPOCH_NS);
            let time = SimulatedTime::new(clock.clone(), speed);
            run_on_clock(args, &cfg, (rdt, canopen), clock, &time)
        }
    }
}

/// The daemon on its clocks: the simulator's `sim_clock`, the loop's
/// `loop_clock` (the host's in real time; one simulated clock with
/// `--speed`).
fn run_on_clock<C: Clock + Clone + 'static, L: LoopClock>(
    args: &Args,
    cfg: &config::Config,
    (rdt, canopen): RealDevices,
    sim_clock: C,
    loop_clock: &L,
) -> Result<(), String> {
    rt::install_stop_handler().map_err(|e| format!("cannot install the signal handler: {e}"))?;
    // A shared-memory file truncated under sard (by a member of the
    // operators' group) stops it cleanly instead of killing it (SIGBUS).
    rt::install_bus_guard().map_err(|e| format!("cannot install the SIGBUS handler: {e}"))?;
    // The sensor first (no thread of its own: the loop reads its socket;
    // the kernel's receive buffer keeps its packets meanwhile).
    let real_sensor = rdt.map(connect_sensor).transpose()?;
    let (simulated, scenario_name) =
        simulator(args, cfg, real_sensor.is_some(), &canopen, sim_clock)?;
    let (bias, truth) = start_bias(real_sensor.is_some(), simulated.as_ref());
    let operator = Operator::new();
    let Some(shm) = start_shm(args, cfg, &operator)? else {
        return Ok(());
    };
    let (recording, recorder, switch) = start_recording(cfg, simulated.as_ref(), bias)?;
    let shm = shm.with_record_commands(std::sync::Arc::new(SwitchCommands(switch)));
    // The logging thread before the real-time settings, so that it keeps the
    // normal priority (it writes to stderr: never at the loop's priority).
    let (log, log_thread, _queue) = logq::channel(true);
    // The publishing thread wakes the logging thread when the loop queued
    // events (the loop wakes nobody).
    if let Some(waker) = log_thread.as_ref().and_then(logq::LogThread::waker) {
        shm.wake_log(waker);
    }
    let _latency = if loop_clock.simulated() {
        tracing::info!(
            "sard: simulated time ({:?}): no real-time settings (a cycle takes no simulated time)",
            args.speed.unwrap_or(Speed::Max)
        );
        None
    } else {
        real_time(cfg)
    };
    // Once the devices are up: a refusal at start stays one line.
    say_inertia(cfg);
    let run = Run {
        args,
        cfg,
        operator,
        shm,
        recorder,
        truth,
        recording,
        bias,
        auto_reset: args.sim,
        log,
        log_thread,
    };
    let sensor_what = match &real_sensor {
        Some(s) => format!("the RDT sensor at {}", s.config().address),
        None => format!("the simulated sensor of {scenario_name:?}"),
    };
    run_on(
        run,
        real_sensor,
        canopen,
        simulated,
        &sensor_what,
        loop_clock,
    )
}

/// The RDT sensor, connected and streaming (its first sample came in time).
fn connect_sensor(config: sar_rdt::RdtConfig) -> Result<RdtSensor, String> {
    let mut sensor = devices::connect_rdt(config)?;
    devices::first_sample(&mut sensor, FIRST_SAMPLE_TIMEOUT_NS)?;
    Ok(sensor)
}

/// The simulator for the parts that are simulated (none on the real robot:
/// a `--scenario` is then refused), and its scenario's name.
fn simulator<C: Clock + Clone>(
    args: &Args,
    cfg: &config::Config,
    real_sensor: bool,
    canopen: &Option<(String, sar_canopen::CanOpenConfig)>,
    clock: C,
) -> Result<(Option<Simulated<C>>, String), String> {
    if real_sensor && canopen.is_some() {
        if let Some(path) = &args.scenario {
            return Err(format!(
                "--scenario {}: nothing is simulated ({} names a real sensor and real axes)",
                path.display(),
                cfg.origin
            ));
        }
        return Ok((None, String::new()));
    }
    let scenario = scenario(args, cfg)?;
    let simulated =
        sim::simulated(&scenario, clock).map_err(|e| format!("{}: {e}", scenario.origin))?;
    Ok((Some(simulated), scenario.name))
}

/// The start bias, decided once for the estimator and the recordings (a
/// real sensor starts with none, the operator tares; the simulated one with
/// the scenario's, as if measured beforehand), and the simulator's true tip
/// force where the sensor is simulated.
fn start_bias<C: Clock + Clone + 'static>(
    real_sensor: bool,
    simulated: Option<&Simulated<C>>,
) -> (Bias, Option<SimTruthFn>) {
    match simulated {
        Some((simulator, _, _, sim_bias)) if !real_sensor => {
            (*sim_bias, Some(truth_of(simulator.clone())))
        }
        _ => (Bias::force_only(Vec3::zeros()), None),
    }
}

/// The shared memory in the runtime directory (`SAR_RUNTIME_DIR`, default
/// /run/sar: the access model, README "Access"); `None` when a SIGTERM
/// came while iceoryx2 was stuck on a damaged file (sard then ends).
fn start_shm(
    args: &Args,
    cfg: &config::Config,
    operator: &Operator,
) -> Result<Option<DaemonShm>, String> {
    let dir = sar_shm::runtime_dir().map_err(|e| e.to_string())?;
    match DaemonShm::create_in(
        &dir,
        &args.prefix,
        operator.clone(),
        cfg.estimator.guard.force_limits().to_array(),
        &rt::stop_requested,
    ) {
        Ok(shm) => Ok(Some(shm)),
        Err(sar_shm::ShmError::Stopped) => {
            tracing::info!(
                "sard: stopped while creating the shared-memory services (the loop never ran)"
            );
            Ok(None)
        }
        Err(e) => Err(e.to_string()),
    }
}

/// Recording (`[record]`, `sarctl record start|stop`): its manager thread
/// (which opens and closes the files, never the loop) starts here, before
/// the real-time settings, so that it and the writer threads it starts keep
/// the normal priority and every CPU.
fn start_recording<C: Clock + Clone>(
    cfg: &config::Config,
    simulated: Option<&Simulated<C>>,
    bias: Bias,
) -> Result<(RecordManager, LiveRecorder, std::sync::Arc<RecordSwitch>), String> {
    tracing::info!(
        "recordings go to {} ([record] directory, mode {:?})",
        cfg.record.directory.display(),
        cfg.record.mode.name()
    );
    let mut settings = cfg.record.clone();
    // The simulated encoders' counts, for the lean mode (the simulator
    // reports q = round(x / m) * m, m = lead / counts per turn).
    if let (config::AxesDriver::Sim, Some((sim, ..))) = (&cfg.axes_driver, simulated) {
        settings.scales.joint_m_per_count = sim.encoder_m_per_count().map_err(|e| e.to_string())?;
    }
    // And the simulated sensor's counts (the demo's: the HEX-E's).
    if let (config::SensorDriver::Sim, Some((sim, ..))) = (&cfg.sensor_driver, simulated) {
        let (per_n, per_nm) = sim.sensor_counts().map_err(|e| e.to_string())?;
        settings.scales.force_counts_per_n = per_n;
        settings.scales.torque_counts_per_nm = per_nm;
    }
    let switch = std::sync::Arc::new(RecordSwitch::new(cfg.loop_.period_ns));
    let (recording, recorder) = RecordManager::start(
        settings,
        SceneOptions::from_config(cfg),
        bias,
        std::sync::Arc::clone(&switch),
    )?;
    Ok((recording, recorder, switch))
}

/// Runs the loop on the sensor and the drives: the real ones the
/// configuration names, the simulated ones for the rest.
fn run_on<C: Clock + Clone, L: LoopClock>(
    run: Run<'_>,
    real_sensor: Option<RdtSensor>,
    canopen: Option<(String, sar_canopen::CanOpenConfig)>,
    simulated: Option<Simulated<C>>,
    sensor_what: &str,
    clock: &L,
) -> Result<(), String> {
    match (real_sensor, canopen, simulated) {
        (None, None, Some((_, sensor, drives, _))) => run.run(
            sensor,
            drives,
            None,
            &format!("{sensor_what} and the simulated axes"),
            clock,
        ),
        (Some(sensor), None, Some((_, _, drives, _))) => run.run(
            sensor,
            drives,
            None,
            &format!("{sensor_what} and the simulated axes"),
            clock,
        ),
        #[cfg(all(feature = "socketcan", target_os = "linux"))]
        (sensor, Some((interface, c)), simulated) => {
            let drives = start_canopen(&interface, c)?;
            let axes_what = format!("the CANopen drives on {interface}");
            let what = format!("{sensor_what} and {axes_what}");
            match (sensor, simulated) {
                (Some(sensor), _) => {
                    run.run(sensor, drives, Some(devices::canopen_cycle), &what, clock)
                }
                (None, Some((_, sensor, _, _))) => {
                    run.run(sensor, drives, Some(devices::canopen_cycle), &what, clock)
                }
                (None, None) => Err(NO_SIMULATOR.to_owned()),
            }
        }
        #[cfg(not(all(feature = "socketcan", target_os = "linux")))]
        (_, Some((interface, _)), _) => Err(format!(
            "{}: CANopen drives on {interface} need the `socketcan` feature",
            run.cfg.origin
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

/// The rod's inertia the tip force in motion is compensated with (MODEL.md
/// 10), and whether it was measured or is the slender rod's stated default.
fn say_inertia(cfg: &config::Config) {
    let i = &cfg.estimator.inertia;
    let source = if cfg.inertia_measured {
        "[manipulator] inertia_perp_kgm2"
    } else {
        "DEFAULT m L^2 / 12 of a slender rod, not a measurement: run `sarctl identify --dynamic`"
    };
    tracing::info!(
        "rod inertia: I_perp {:.6} +- {:.6} kg m^2 ({source}), I_axial {} kg m^2, adapter {} kg",
        i.inertia_perp_kgm2,
        i.inertia_perp_std_kgm2,
        i.inertia_axial_kgm2,
        i.adapter_mass_kg,
    );
}

/// The real sensor and drives a configuration names (`None`: simulated).
type RealDevices = (
    Option<sar_rdt::RdtConfig>,
    Option<(String, sar_canopen::CanOpenConfig)>,
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
/// trajectory they follow), and braking in their quick stop at the
/// configured `[drivers.axes] quick_stop_decel_mps2` unless a scenario
/// file sets its own (a drive that does not brake as configured).
fn scenario(args: &Args, cfg: &config::Config) -> Result<config::scenario::Scenario, String> {
    let quick_stop_mps2 = cfg.axes.motion.quick_stop_decel_mps2;
    let mut scenario = match &args.scenario {
        Some(path) => {
            let mut s = config::scenario::load(path).map_err(|e| e.to_string())?;
            s.spec
                .plant
                .quick_stop_decel_mps2
                .get_or_insert(quick_stop_mps2);
            s
        }
        None => {
            let mut s = sim::demo_scenario().map_err(|e| e.to_string())?;
            s.spec.plant.quick_stop_decel_mps2 = Some(quick_stop_mps2);
            s
        }
    };
    scenario.spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
    scenario.spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
    // The velocity limit CANopen drives are written (0x607F): the same
    // margin for the loop's jitter over a stream at the planned speed.
    scenario
        .spec
        .axes
        .drive_max_speed_mps
        .get_or_insert(config::devices::drive_max_speed_mps(cfg, 0.0));
    Ok(scenario)
}

/// The simulator's truth, asked once per cycle by the loop.
fn truth_of<C: Clock + Clone + 'static>(simulator: sar_sim::Simulator<C>) -> SimTruthFn {
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
/// normal priority and every CPU. The returned file holds the CPUs' wake-up
/// latency at 0 us while it is open (keep it for the run).
fn real_time(cfg: &config::Config) -> Option<std::fs::File> {
    let latency = rt::hold_wakeup_latency(0)
        .map_err(|e| tracing::warn!("{e}; the loop wakes up later from idle CPUs"))
        .ok();
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
    latency
}

/// Opens the CAN interface, starts the drives and brings them to `Ready`.
#[cfg(all(feature = "socketcan", target_os = "linux"))]
fn start_canopen(
    interface: &str,
    config: sar_canopen::CanOpenConfig,
) -> Result<sar_canopen::CanOpenDrives<sar_canopen::socketcan::CanSocket, MonotonicClock>, String> {
    let socket = sar_canopen::socketcan::open(interface).map_err(|e| e.to_string())?;
    let clock = MonotonicClock::new().map_err(|e| e.to_string())?;
    let period_ns = config.sync_period_ns;
    let mut drives = sar_canopen::CanOpenDrives::start(socket, clock, config)
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
    /// The loop's side of the log queue.
    log: logq::LogSender,
    /// The logging thread (started before the loop took its priority).
    log_thread: Option<logq::LogThread>,
}

impl Run<'_> {
    /// Runs the loop until its end (a signal, `--max-cycles`), then stops
    /// every thread and says how it went.
    fn run<S: ForceSensor, D: AxisDrives, L: LoopClock>(
        mut self,
        sensor: S,
        drives: D,
        drives_cycle: Option<DrivesCycle<D>>,
        what: &str,
        clock: &L,
    ) -> Result<(), String> {
        let cfg = self.cfg;
        let log = self.log.clone();
        let log_thread = self.log_thread.take();
        let mut controller = self.controller(sensor, drives, drives_cycle, &log)?;
        let mut stats = LoopStats::default();
        tracing::info!(
            "sard: running {} ({}) at {} Hz with {what}",
            cfg.manipulator_name,
            cfg.origin,
            cfg.loop_.rate_hz,
        );
        let health = self.run_loop(&mut controller, &mut stats, &log, clock);
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
        close_recording_and_log(&mut self.recorder, self.recording, log_thread);
        say_stopped(&controller, &stats, &health, &by);
        // The devices (the RDT sensor's stop request), then the
        // publishing and maintenance threads, bounded (a thread stuck on
        // a truncated file is left behind and named below).
        drop(controller);
        drop(self.shm);
        say_left_behind()
    }

    /// The controller on the sensor and the drives, with the operator's
    /// queues and the log.
    fn controller<S: ForceSensor, D: AxisDrives>(
        &mut self,
        sensor: S,
        drives: D,
        drives_cycle: Option<DrivesCycle<D>>,
        log: &logq::LogSender,
    ) -> Result<Controller<S, D>, String> {
        let cfg = self.cfg;
        let controller = Controller::new(
            &cfg.estimator,
            self.bias,
            cfg.step_config(),
            sensor,
            drives,
            self.operator.clone(),
            log.clone(),
            self.auto_reset,
        )
        .map_err(|e| format!("{}: {e}", cfg.origin))?;
        Ok(match drives_cycle {
            Some(hook) => controller.with_drives_cycle(hook),
            None => controller,
        })
    }

    /// The fixed-rate loop with its sinks (the recorder, the shared memory)
    /// and systemd's watchdog: the sinks' last counters.
    fn run_loop<S: ForceSensor, D: AxisDrives, L: LoopClock>(
        &mut self,
        controller: &mut Controller<S, D>,
        stats: &mut LoopStats,
        log: &logq::LogSender,
        clock: &L,
    ) -> sar_loop::sink::SinkHealth {
        let cfg = self.cfg;
        // Ping systemd's watchdog ten times a second from the loop.
        let every = (cfg.loop_.rate_hz / 10.0).round().max(1.0) as u64;
        let mut watchdog = Watchdog::new(Notifier::from_env(), every);
        runloop::run(
            controller,
            clock,
            &cfg.loop_,
            RunLimits {
                max_cycles: self.args.max_cycles,
                stall_after_cycles: self.args.stall_after_cycles,
            },
            stats,
            Edges {
                // The recorder first: the publisher puts its counters in
                // the published state.
                sinks: (&mut self.recorder, &mut self.shm),
                truth: self.truth.take(),
                watchdog: &mut watchdog,
                log,
            },
        )
    }
}

/// The last recording closed (its writer drains the queue first), then
/// the logging thread ended, each waited for within its bound.
fn close_recording_and_log(
    recorder: &mut LiveRecorder,
    recording: RecordManager,
    log_thread: Option<logq::LogThread>,
) {
    recorder.release();
    if !recording.finish() {
        tracing::error!(
            "sard: the recording's thread did not end within {} s: its last file may be cut short (`sarctl recover` rewrites it)",
            sar_record::live::FINISH_WAIT.as_secs()
        );
    }
    if recorder.take_held().is_some() {
        tracing::error!(
            "sard: a recording handed back at the end was never taken by the recording's thread: its file may be cut short"
        );
    }
    if let Some(t) = log_thread
        && !t.finish()
    {
        tracing::error!("sard: the logging thread did not end in time: its last lines may be lost");
    }
}

/// The threads the stop left behind (named), and a stop on SIGBUS (a
/// shared-memory file truncated under `sard`): a failure (exit 1, systemd
/// restarts it), said in one line.
fn say_left_behind() -> Result<(), String> {
    let behind = sar_hal::join::left_behind();
    if !behind.is_empty() {
        tracing::error!(
            "sard: threads left behind at the end: {}",
            behind.join(", ")
        );
    }
    match rt::bus_faults() {
        Some((faults, address)) => Err(format!(
            "stopped on SIGBUS: a shared-memory file of the runtime directory was truncated under sard \
             (first at address {address:#x}; {faults} thread(s) parked there); drives halted, recording closed \
             (a member of the operators' group may write the files the daemon shares with its clients)"
        )),
        None => Ok(()),
    }
}

/// The stop line: cycles, the guard, the wake-up latency and the counters.
fn say_stopped<S: ForceSensor, D: AxisDrives>(
    controller: &Controller<S, D>,
    stats: &LoopStats,
    health: &sar_loop::sink::SinkHealth,
    by: &str,
) {
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
}
