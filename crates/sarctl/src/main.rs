//! `sarctl`, the operator's tool: the daemon's state (`status`, `monitor`)
//! and its commands (`reset`, `tare`, `move-tip`, `limits`), over iceoryx2;
//! `workspace` (the reachable region) and `completions` (shell completions).
//! Every command fails with a one-line reason when no daemon runs.

use clap::{Parser, Subcommand, ValueEnum};
use sar_estimator::guard::ForceLimits;
use sar_msgs::wire::{
    self, CommandMsg, ReplyMsg, StateMsg, command_kind, flags, guard_state_name, reason_name,
    recording_code, status_name,
};
use sar_shm::{Client, DEFAULT_PREFIX};
use serde_json::json;
use std::io::{IsTerminal, Write};
use std::process::ExitCode;
use std::time::Duration;

/// The SAR operator's tool.
#[derive(Debug, Parser)]
#[command(name = "sarctl", version, about = "Operator's tool of the SAR daemon")]
struct Args {
    /// Prefix of the daemon's shared-memory services.
    #[arg(long, global = true, env = "SAR_SERVICE_PREFIX", default_value = DEFAULT_PREFIX)]
    prefix: String,
    /// Output format.
    #[arg(long, global = true, value_enum, default_value_t = Format::Text)]
    format: Format,
    /// The robot's configuration (checked when given).
    #[arg(long, global = true, value_name = "FILE")]
    config: Option<std::path::PathBuf>,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Format {
    Text,
    Json,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// The daemon's latest state.
    Status,
    /// The live state (`--format json`: one JSON line per sample).
    Monitor {
        /// Stop after this many samples (default: until interrupted).
        #[arg(long)]
        count: Option<u64>,
    },
    /// Leave Stop or Fault (refused while a fault persists; with a force
    /// still above the stop limit it enters Retreat: only motions that
    /// reduce the force).
    Reset,
    /// The way back from a Stop: reset (into Retreat while the force
    /// persists), wait for the drives, then back the tip out along the rod
    /// at the retreat speed.
    Retreat {
        /// How far to back out along the rod, m (0 < d <= 0.1).
        #[arg(long, default_value_t = 0.01)]
        distance: f64,
    },
    /// Model-based tare of the force sensor.
    Tare,
    /// Force control: hold the tip while |F_tip| is below N; above, yield
    /// along the force so that it stays near N (FORCE_CONTROL.md).
    Hold {
        /// N (0 < N < the total warn limit).
        #[arg(long, value_name = "N")]
        max_force: f64,
    },
    /// Force control: regulate the force along the rod to N, the lateral
    /// position held.
    Push {
        /// N (0 < N < the axial warn limit).
        #[arg(long, value_name = "N")]
        axial: f64,
    },
    /// End force control: the tip holds where it is (position control).
    Position,
    /// Move the tip to (X, Y, Z), base frame, m.
    MoveTip {
        /// X, m.
        #[arg(allow_hyphen_values = true)]
        x: f64,
        /// Y, m.
        #[arg(allow_hyphen_values = true)]
        y: f64,
        /// Z, m.
        #[arg(allow_hyphen_values = true)]
        z: f64,
        /// A guarded move: braked when |F_tip| (filtered) is anticipated to
        /// reach this (its rise over the filter lag and the braking), N
        /// (0 < N <= the total stop limit); where and at what force shows
        /// in `sarctl status` and the daemon's log.
        #[arg(long, value_name = "N")]
        max_force: Option<f64>,
    },
    /// The guard's force limits; with any `--warn-*`/`--stop-*` option, sets
    /// them (the others kept; within the ceilings of the configuration).
    Limits {
        #[command(flatten)]
        set: LimitOptions,
    },
    /// The live view: serves the state to Foxglove (WebSocket) until stopped.
    View {
        /// Address to serve on, ADDR:PORT (port 0: any free port).
        #[arg(long, default_value = sarctl::view::DEFAULT_BIND)]
        bind: String,
        /// Rate of the 3D scene, Hz.
        #[arg(long, default_value_t = sarctl::view::DEFAULT_SCENE_HZ)]
        scene_hz: f64,
    },
    /// Identify m and c (and calibrate the support) from a recording or live.
    Identify(sarctl::cli::identify::IdentifyArgs),
    /// Run the estimator over a recording's inputs, write and compare the outputs.
    Replay {
        /// The recording: a file, the files of a rotated set in order
        /// (--input A --input B ...), or a directory of them (by name).
        #[arg(long, value_name = "REC.mcap|DIR", required = true)]
        input: Vec<std::path::PathBuf>,
        /// Where to write the outputs.
        #[arg(long, value_name = "OUT.mcap")]
        output: Option<std::path::PathBuf>,
        /// A reference topic (WrenchStamped, e.g. /sar/sim/tip_wrench_truth): error figures.
        #[arg(long, value_name = "TOPIC")]
        compare: Option<String>,
        /// Draw the tip force over time (with the reference) into an SVG.
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<std::path::PathBuf>,
        /// Replay from this time on, s after the recording's first cycle
        /// (from the snapshot before it).
        #[arg(long, value_name = "S")]
        from: Option<f64>,
        /// Stop after this time, s after the recording's first cycle.
        #[arg(long, value_name = "S")]
        to: Option<f64>,
    },
    /// Write a rosbag2 directory (metadata.yaml beside the files) that ROS 2
    /// tools and Python rosbags open.
    Export {
        /// The directory to create (absent or empty).
        #[arg(long, value_name = "DIR")]
        rosbag2: std::path::PathBuf,
        /// The recording's files (a rotation's -0000.mcap, -0001.mcap, ... in order).
        #[arg(required = true, value_name = "REC.mcap")]
        recordings: Vec<std::path::PathBuf>,
    },
    /// Rewrite a recording cut short with its summary and index.
    Recover {
        /// The recording.
        file: std::path::PathBuf,
        /// The output (default: FILE.recovered.mcap; never the input).
        #[arg(long, value_name = "OUT")]
        output: Option<std::path::PathBuf>,
    },
    /// The reachable region (read-only): the axes' travel of the
    /// configuration (--config FILE, else the built-in one of `sard --sim`)
    /// and, from the daemon's present pose, the tip's range along base x, y,
    /// z when one axis at a time moves through its travel.
    Workspace,
    /// Shell completions for bash, zsh or fish, on stdout.
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: CompletionShell,
    },
    /// Start or stop the daemon's recording.
    Record {
        /// start or stop.
        #[arg(value_enum)]
        action: RecordAction,
    },
}

/// The shells `sarctl completions` writes for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum CompletionShell {
    Bash,
    Zsh,
    Fish,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum RecordAction {
    Start,
    Stop,
}

/// A write to stdout failed. A reader that went away (`sarctl monitor | head`)
/// ends the command quietly; any other failure is reported.
fn output_error(e: std::io::Error) -> String {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        OUTPUT_CLOSED.to_owned()
    } else {
        format!("cannot write the output: {e}")
    }
}

/// The marker of a closed output (see [`output_error`]).
const OUTPUT_CLOSED: &str = "output closed";

fn main() -> ExitCode {
    // A closed output pipe (`sarctl status | head -0`) ends sarctl quietly
    // by SIGPIPE, as it ends any Unix filter, whatever prints (clap's help,
    // text, JSON): one place instead of an EPIPE check at every print.
    // `sarctl view`, a server, ignores it again (its stop handler).
    let _ = sar_loop::rt::default_sigpipe();
    let args = Args::parse();
    // iceoryx2's own log (e.g. "no config file was loaded") only for errors.
    sar_shm::log_errors_only();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e == OUTPUT_CLOSED => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sarctl: {}", e.replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}

/// The options of `sarctl limits`: one per force limit, named after
/// [`ForceLimits::NAMES`] (without `_n`, `-` for `_`; checked by a test).
#[derive(clap::Args, Debug, Clone, Copy, PartialEq)]
struct LimitOptions {
    /// Warn limit on |F_tip|, N.
    #[arg(long)]
    warn_total: Option<f64>,
    /// Stop limit on |F_tip|, N.
    #[arg(long)]
    stop_total: Option<f64>,
    /// Warn limit on the axial part, N.
    #[arg(long)]
    warn_axial: Option<f64>,
    /// Stop limit on the axial part, N.
    #[arg(long)]
    stop_axial: Option<f64>,
    /// Warn limit on the lateral part, N.
    #[arg(long)]
    warn_lateral: Option<f64>,
    /// Stop limit on the lateral part, N.
    #[arg(long)]
    stop_lateral: Option<f64>,
}

impl LimitOptions {
    /// The wanted limits in the order of [`ForceLimits::to_array`] (the
    /// wire's `limits_n`); `None` keeps the one in force.
    fn wanted(&self) -> [Option<f64>; 6] {
        let Self {
            warn_total,
            stop_total,
            warn_axial,
            stop_axial,
            warn_lateral,
            stop_lateral,
        } = *self;
        [
            warn_total,
            stop_total,
            warn_axial,
            stop_axial,
            warn_lateral,
            stop_lateral,
        ]
    }
}

/// The guard's six force limits by name ([`ForceLimits::NAMES`], the order
/// of `limits_n`).
fn limits_json(l: &[f64; 6]) -> serde_json::Value {
    let fields = ForceLimits::NAMES
        .iter()
        .zip(l)
        .map(|(name, v)| ((*name).to_owned(), json!(v)));
    serde_json::Value::Object(fields.collect())
}

/// One symbol per tenth of a second: |F_tip| against the stop limit, in
/// ninths (`@`: at or above the stop limit).
const HISTORY_GLYPHS: [char; 10] = [' ', '.', ':', '-', '=', '+', '*', '#', '%', '@'];

/// The legend printed above `monitor`'s history line.
const HISTORY_LEGEND: &str = "history: one symbol per 0.1 s, |F_tip| as a share of the stop \
     limit: ' ' under 1/9, then . : - = + * # % in ninths, @ at or above the stop limit";

/// The glyph of |F_tip| = `norm` against the stop limit `stop`.
fn history_glyph(norm: f64, stop: f64) -> char {
    let level = ((norm / stop.max(1e-9)) * 9.0).clamp(0.0, 9.0) as usize;
    HISTORY_GLYPHS.get(level).copied().unwrap_or('@')
}

fn state_json(s: &StateMsg) -> serde_json::Value {
    json!({
        "cycle": s.cycle,
        "now_ns": s.now_ns,
        "sensor_age_ns": (s.sensor_age_ns != u64::MAX).then_some(s.sensor_age_ns),
        "joints_age_ns": (s.joints_age_ns != u64::MAX).then_some(s.joints_age_ns),
        "q_m": s.q_m,
        "q45_rad": (s.flags & flags::POSE != 0).then_some(s.q45_rad),
        "ujoint_m": (s.flags & flags::POSE != 0).then_some(s.ujoint_m),
        "tip_m": (s.flags & flags::POSE != 0).then_some(s.tip_m),
        "support_distance_m": (s.flags & flags::POSE != 0).then_some(s.support_distance_m),
        "ujoint_force_n": (s.flags & flags::ESTIMATE != 0).then_some(s.ujoint_force_n),
        "tip_force_n": (s.flags & flags::ESTIMATE != 0).then_some(s.tip_force_n),
        "tip_std_n": (s.flags & flags::ESTIMATE != 0).then_some(s.tip_std_n),
        "observable": s.flags & flags::OBSERVABLE != 0,
        "truth_tip_force_n": (s.flags & flags::SIM_TRUTH != 0).then_some(s.truth_tip_force_n),
        "sim_elapsed_ns": (s.flags & flags::SIM_TRUTH != 0).then_some(s.truth_elapsed_ns),
        "force_mode": wire::force_mode::name(s.force_mode),
        "force_setpoint_n": (s.force_mode != wire::force_mode::POSITION).then_some(s.force_setpoint_n),
        "guarded_stop": (s.guarded_stop_cycle != 0).then(|| json!({
            "cycle": s.guarded_stop_cycle,
            "tip_m": s.guarded_stop_tip_m,
            "force_n": s.guarded_stop_force_n,
        })),
        "guard": guard_state_name(s.guard_state),
        "reason": reason_name(s.guard_reason),
        "reason_code": s.guard_reason,
        "halted": s.flags & flags::HALTED != 0,
        "drive_state": s.drive_state,
        "drive_state_name": wire::drive_state_name(s.drive_state),
        "limits_n": s.limits_n,
        "limits": limits_json(&s.limits_n),
        "wakeup_ns": {"p50": s.wakeup_ns[0], "p99": s.wakeup_ns[1], "max": s.wakeup_ns[2]},
        "compute_ns": {"p50": s.compute_ns[0], "p99": s.compute_ns[1], "max": s.compute_ns[2]},
        "overruns": s.overruns,
        "quick_stops": s.quick_stops,
        "publish_queue_drops": s.publish_queue_drops,
        "publish_errors": s.publish_errors,
        "recording": recording_code::is_on(s.recording),
        "recording_failed": recording_code::is_failed(s.recording)
            .then(|| sarctl::cli::record::recording_failure(s.recording)),
        "recorder_drops": s.recorder_drops,
    })
}

fn state_line(s: &StateMsg) -> String {
    let f = s.tip_force_n;
    let norm = s.tip_force_norm_n();
    let force = if s.flags & flags::ESTIMATE != 0 {
        format!(
            "F_tip [{:+7.2} {:+7.2} {:+7.2}] N |F| {:6.2} N (std {:.2})",
            f[0],
            f[1],
            f[2],
            norm,
            s.tip_std_n.iter().fold(0.0f64, |a, b| a.max(*b))
        )
    } else {
        "F_tip -- (no estimate)".to_owned()
    };
    format!(
        "cycle {:>8}  {force}  guard {:5} ({})  latency p99 {} us, {} overruns{}",
        s.cycle,
        guard_state_name(s.guard_state),
        reason_name(s.guard_reason),
        s.wakeup_ns[1] / 1000,
        s.overruns,
        if s.recording != 0 || s.recorder_drops != 0 {
            format!(
                ", recording {}, {} dropped",
                match recording_code::state(s.recording) {
                    recording_code::ON => "on".to_owned(),
                    recording_code::FAILED => format!(
                        "FAILED ({}; its file is incomplete)",
                        sarctl::cli::record::recording_failure(s.recording)
                    ),
                    _ => "off".to_owned(),
                },
                s.recorder_drops
            )
        } else {
            String::new()
        }
    )
}

/// A bar of |F| against the stop limit, for the terminal view.
fn bar(s: &StateMsg) -> String {
    let norm = s.tip_force_norm_n();
    let stop = s.limits().stop_total_n.max(1e-9);
    let width = 40usize;
    let filled = ((norm / stop).clamp(0.0, 1.0) * width as f64).round() as usize;
    let warn_at =
        ((s.limits().warn_total_n / stop).clamp(0.0, 1.0) * width as f64).round() as usize;
    (0..width)
        .map(|i| {
            if i < filled {
                '#'
            } else if i == warn_at {
                '|'
            } else {
                '.'
            }
        })
        .collect()
}

fn run(args: &Args) -> Result<(), String> {
    let json = args.format == Format::Json;
    match &args.command {
        Cmd::Replay {
            input,
            output,
            compare,
            plot,
            from,
            to,
        } => {
            return sarctl::cli::replay::run(&sarctl::cli::replay::Args {
                config: args.config.as_deref(),
                input,
                output: output.as_deref(),
                compare: compare.as_deref(),
                json,
                plot: plot.as_deref(),
                from_s: *from,
                to_s: *to,
            });
        }
        Cmd::Recover { file, output } => {
            return sarctl::cli::recover::run(file, output.as_deref(), json);
        }
        Cmd::Export {
            rosbag2,
            recordings,
        } => {
            return sarctl::cli::export::run(rosbag2, recordings, json);
        }
        _ => {}
    }
    if let Some(path) = &args.config {
        sar_config::load(path).map_err(|e| e.to_string())?;
    }
    if let Cmd::Completions { shell } = &args.command {
        let mut cmd = <Args as clap::CommandFactory>::command();
        let shell = match shell {
            CompletionShell::Bash => clap_complete::Shell::Bash,
            CompletionShell::Zsh => clap_complete::Shell::Zsh,
            CompletionShell::Fish => clap_complete::Shell::Fish,
        };
        clap_complete::generate(shell, &mut cmd, "sarctl", &mut std::io::stdout());
        return Ok(());
    }
    if let Cmd::Workspace = &args.command {
        let cfg = match &args.config {
            Some(path) => sar_config::load(path).map_err(|e| e.to_string())?,
            None => sar_config::builtin().map_err(|e| e.to_string())?,
        };
        let present = Client::new(&args.prefix)
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
            });
        let (present, why) = match present {
            Ok(p) => (Some(p), String::new()),
            Err(e) => (None, e),
        };
        return sarctl::cli::workspace::print(&cfg, present, &why, json);
    }
    if let Cmd::Identify(a) = &args.command {
        let json = args.format == Format::Json;
        return sarctl::cli::identify::run(args.config.as_deref(), json, &args.prefix, a);
    }
    let client = Client::new(&args.prefix).map_err(|e| e.to_string())?;
    let command_with = |kind: u32, tip_m: [f64; 3], limits_n: [f64; 6]| {
        client.command(
            CommandMsg {
                kind,
                reserved: 0,
                id: u64::from(std::process::id()),
                tip_m,
                limits_n,
            },
            Duration::from_secs(2),
        )
    };
    let command = |kind: u32, tip_m: [f64; 3]| command_with(kind, tip_m, [0.0; 6]);
    let report = |what: &str, r: &ReplyMsg| -> Result<(), String> {
        let accepted = r.status == 0 || r.status == 1;
        if args.format == Format::Json {
            println!(
                "{}",
                json!({"command": what, "accepted": accepted, "status": status_name(r.status),
                       "status_code": r.status, "reason": reason_name(r.reason),
                       "reason_code": r.reason, "detail": r.detail_text(), "cycle": r.cycle})
            );
        } else if accepted {
            println!("{what}: {} (cycle {})", status_name(r.status), r.cycle);
        }
        if accepted {
            Ok(())
        } else {
            // The daemon's exact cause when it gave one, else the reason's name.
            let detail = match r.detail_text() {
                "" => reason_name(r.reason).to_owned(),
                d => d.to_owned(),
            };
            Err(format!("{what}: {}: {detail}", status_name(r.status)))
        }
    };
    match args.command {
        Cmd::Replay { .. }
        | Cmd::Recover { .. }
        | Cmd::Export { .. }
        | Cmd::Workspace
        | Cmd::Completions { .. } => Ok(()),
        Cmd::Record { action } => {
            sarctl::cli::record::run(&client, action == RecordAction::Start, json)
        }
        Cmd::Status => {
            let sub = client.subscribe().map_err(|e| e.to_string())?;
            let s = sub
                .latest(Duration::from_secs(2))
                .ok_or("the daemon published nothing within 2 s")?;
            if args.format == Format::Json {
                println!("{}", state_json(&s));
            } else {
                println!("{}", state_line(&s));
            }
            Ok(())
        }
        Cmd::Monitor { count } => {
            let sub = client.subscribe().map_err(|e| e.to_string())?;
            let live = args.format == Format::Text && std::io::stdout().is_terminal();
            let mut seen = 0u64;
            let mut history: Vec<char> = Vec::new();
            let mut stdout = std::io::stdout().lock();
            let mut last_print = std::time::Instant::now();
            let mut idle = std::time::Instant::now();
            loop {
                let mut batch: Vec<StateMsg> = Vec::new();
                sub.wait(Duration::from_millis(200), |s| batch.push(*s));
                if batch.is_empty() {
                    if idle.elapsed() > Duration::from_secs(2) {
                        return Err("the daemon stopped publishing".to_owned());
                    }
                    continue;
                }
                idle = std::time::Instant::now();
                for s in &batch {
                    seen += 1;
                    if args.format == Format::Json {
                        writeln!(stdout, "{}", state_json(s)).map_err(output_error)?;
                    } else if !live {
                        writeln!(stdout, "{}", state_line(s)).map_err(output_error)?;
                    }
                    if count.is_some_and(|c| seen >= c) {
                        return Ok(());
                    }
                }
                if live && last_print.elapsed() > Duration::from_millis(100) {
                    last_print = std::time::Instant::now();
                    if let Some(s) = batch.last() {
                        let norm = s.tip_force_norm_n();
                        history.push(history_glyph(norm, s.limits().stop_total_n));
                        if history.len() > 60 {
                            history.remove(0);
                        }
                        let h: String = history.iter().collect();
                        write!(
                            stdout,
                            "\x1b[2J\x1b[H{}\n|F_tip| {:6.2} N [{}] stop {:.1} N\n{HISTORY_LEGEND}\nhistory (10 s) [{h}]\n",
                            state_line(s),
                            norm,
                            bar(s),
                            s.limits().stop_total_n
                        )
                        .map_err(output_error)?;
                        stdout.flush().map_err(output_error)?;
                    }
                }
            }
        }
        Cmd::View { ref bind, scene_hz } => {
            sarctl::view::run_cli(&args.prefix, args.config.as_deref(), bind, scene_hz)
        }
        Cmd::Identify(_) => Ok(()), // run above, without a daemon
        Cmd::Reset => {
            // Faulted drives are reset first: then the guard's reset.
            let mut r = command(command_kind::RESET, [0.0; 3]).map_err(|e| e.to_string())?;
            for _ in 0..10 {
                if r.status != sar_msgs::wire::ReplyStatus::DrivesFaultReset as u32 {
                    break;
                }
                std::thread::sleep(Duration::from_millis(100));
                r = command(command_kind::RESET, [0.0; 3]).map_err(|e| e.to_string())?;
            }
            report("reset", &r)
        }
        Cmd::Retreat { distance } => {
            let sub = client.subscribe().map_err(|e| e.to_string())?;
            let latest = |what: &str| {
                sub.latest(Duration::from_secs(2)).ok_or_else(|| {
                    format!("retreat: the daemon published nothing within 2 s ({what})")
                })
            };
            let s = latest("start")?;
            if s.flags & flags::HALTED != 0 {
                let r = command(command_kind::RESET, [0.0; 3]).map_err(|e| e.to_string())?;
                report("retreat: reset", &r)?;
            }
            // The drives come back within a few cycles after the reset.
            let deadline = std::time::Instant::now() + Duration::from_secs(5);
            let s = loop {
                let s = latest("waiting for the drives")?;
                if s.drives_enabled() && s.flags & flags::HALTED == 0 {
                    break s;
                }
                if std::time::Instant::now() > deadline {
                    return Err(format!(
                        "retreat: the drives are not enabled after 5 s (guard {}: {})",
                        guard_state_name(s.guard_state),
                        reason_name(s.guard_reason)
                    ));
                }
                std::thread::sleep(Duration::from_millis(20));
            };
            if !json {
                println!(
                    "retreat: guard {} ({}), backing out {distance} m along the rod",
                    guard_state_name(s.guard_state),
                    reason_name(s.guard_reason)
                );
            }
            report(
                "retreat: back out",
                &command(command_kind::BACK_OUT, [distance, 0.0, 0.0])
                    .map_err(|e| e.to_string())?,
            )
        }
        Cmd::Tare => report(
            "tare",
            &command(command_kind::TARE, [0.0; 3]).map_err(|e| e.to_string())?,
        ),
        Cmd::Hold { max_force } => report(
            "hold",
            &command_with(
                command_kind::HOLD,
                [0.0; 3],
                [max_force, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .map_err(|e| e.to_string())?,
        ),
        Cmd::Push { axial } => report(
            "push",
            &command_with(
                command_kind::PUSH,
                [0.0; 3],
                [axial, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .map_err(|e| e.to_string())?,
        ),
        Cmd::Position => report(
            "position",
            &command(command_kind::POSITION, [0.0; 3]).map_err(|e| e.to_string())?,
        ),
        Cmd::MoveTip {
            x,
            y,
            z,
            max_force: None,
        } => report(
            "move-tip",
            &command(command_kind::MOVE_TIP, [x, y, z]).map_err(|e| e.to_string())?,
        ),
        Cmd::MoveTip {
            x,
            y,
            z,
            max_force: Some(n),
        } => report(
            "move-tip (guarded)",
            &command_with(
                command_kind::GUARDED_MOVE,
                [x, y, z],
                [n, 0.0, 0.0, 0.0, 0.0, 0.0],
            )
            .map_err(|e| e.to_string())?,
        ),
        Cmd::Limits { set } => {
            let mut r = command(command_kind::LIMITS, [0.0; 3]).map_err(|e| e.to_string())?;
            let wanted = set.wanted();
            if wanted.iter().any(Option::is_some) {
                let mut limits_n = r.limits_n;
                for (slot, value) in limits_n.iter_mut().zip(wanted) {
                    if let Some(v) = value {
                        *slot = v;
                    }
                }
                r = command_with(command_kind::SET_LIMITS, [0.0; 3], limits_n)
                    .map_err(|e| e.to_string())?;
                if r.status != 0 {
                    return Err(format!(
                        "limits: {}: {}",
                        status_name(r.status),
                        r.detail_text()
                    ));
                }
                r = command(command_kind::LIMITS, [0.0; 3]).map_err(|e| e.to_string())?;
            }
            let l = r.limits_n;
            if args.format == Format::Json {
                println!("{}", limits_json(&l));
            } else {
                println!("{}", ForceLimits::from_array(l));
            }
            let _ = wire::guard_code::OK;
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::unwrap_used, clippy::panic, clippy::indexing_slicing)]
    fn the_limit_options_are_the_force_limits_names_in_wire_order() {
        for (i, name) in ForceLimits::NAMES.iter().enumerate() {
            let option = format!("--{}", name.trim_end_matches("_n").replace('_', "-"));
            let value = (i + 1).to_string();
            let cli = Args::try_parse_from(["sarctl", "limits", &option, &value]).unwrap();
            let Cmd::Limits { set } = cli.command else {
                panic!("{option}: not `limits`");
            };
            let mut expected = [None; 6];
            expected[i] = Some((i + 1) as f64);
            assert_eq!(set.wanted(), expected, "{option}");
        }
        // No other option sets a limit.
        let cmd = <Args as clap::CommandFactory>::command();
        let limits = cmd.find_subcommand("limits").unwrap();
        let options: Vec<&str> = limits
            .get_arguments()
            .filter(|a| a.get_id() != "help")
            .filter_map(|a| a.get_long())
            .filter(|l| l.starts_with("warn") || l.starts_with("stop"))
            .collect();
        assert_eq!(options.len(), 6, "{options:?}");
    }

    #[test]
    fn the_limits_json_and_text_name_the_six_in_wire_order() {
        let l = [1.0, 2.0, 3.5, 4.0, 5.0, 6.25];
        assert_eq!(
            limits_json(&l),
            json!({"warn_total_n": 1.0, "stop_total_n": 2.0, "warn_axial_n": 3.5,
                   "stop_axial_n": 4.0, "warn_lateral_n": 5.0, "stop_lateral_n": 6.25})
        );
        assert_eq!(
            ForceLimits::from_array(l).to_string(),
            "warn/stop total 1/2 N, axial 3.5/4 N, lateral 5/6.25 N"
        );
    }

    #[test]
    fn the_history_legend_matches_the_glyphs() {
        // The glyphs between the blank and `@`, in order, then `@`.
        let middle: Vec<String> = HISTORY_GLYPHS[1..9].iter().map(char::to_string).collect();
        assert!(
            HISTORY_LEGEND.contains(&middle.join(" ")),
            "{HISTORY_LEGEND}"
        );
        assert!(HISTORY_LEGEND.contains("@ at or above"), "{HISTORY_LEGEND}");
        assert_eq!(history_glyph(0.0, 15.0), ' ');
        assert_eq!(history_glyph(15.0 / 9.0, 15.0), '.');
        assert_eq!(history_glyph(14.9, 15.0), '%');
        assert_eq!(history_glyph(15.0, 15.0), '@');
        assert_eq!(history_glyph(100.0, 15.0), '@');
    }
}
