//! `sarctl`, the operator's tool of the SAR daemon. This file parses the
//! command line (clap) and dispatches; each subcommand's body is in
//! `sarctl::cli::NAME` (`view`: `sarctl::view`). The subcommands:
//!
//! - `status`: the daemon's latest state, one line or one JSON object.
//! - `monitor`: the live state, one line per sample (on a terminal, a view).
//! - `reset`: leave Stop or Fault (faulted drives reset first).
//! - `retreat`: the way back from a Stop: reset, drives, back out along the rod.
//! - `tare`: the model-based tare of the force sensor.
//! - `hold`: force control, the tip held while |F_tip| is below N.
//! - `push`: force control, the force along the rod regulated to N.
//! - `position`: the end of force control (the tip holds where it is).
//! - `move-tip`: move the tip to (X, Y, Z); guarded with `--max-force`.
//! - `limits`: the guard's force limits, shown or set.
//! - `view`: the live view, served to Foxglove over a WebSocket.
//! - `identify`: m and c (and the support) from a recording or live.
//! - `replay`: the estimator over a recording's inputs, outputs compared.
//! - `export`: a rosbag2 directory of a recording.
//! - `recover`: a recording cut short rewritten with its summary and index.
//! - `workspace`: the reachable region (read-only).
//! - `completions`: shell completions for bash, zsh or fish.
//! - `record`: start or stop the daemon's recording.
//! - `support`: the support point's shift: status, a check's pose sequence, confirm.
//!
//! The requests to the daemon and its state go over iceoryx2 (`sar-shm`):
//! every one fails with a one-line reason when no daemon runs. The
//! recording tools (`replay`, `export`, `recover`) need no daemon.

use clap::{Parser, Subcommand, ValueEnum};
use sar_shm::{Client, DEFAULT_PREFIX};
use sarctl::cli::completions::CompletionShell;
use sarctl::cli::limits::LimitOptions;
use sarctl::cli::request::{self, Daemon};
use sarctl::cli::{self, OUTPUT_CLOSED};
use std::process::ExitCode;

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
        /// Stop after this many samples, at least 1 (default: until
        /// interrupted).
        #[arg(long, value_parser = sarctl::cli::monitor::parse_count)]
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
    /// The support point B (issue 34): `status` (the shift the daemon
    /// estimates, per axis with its standard error), `check` (a short pose
    /// sequence about the tip, the tip free, then the estimate; non-zero
    /// exit when shifted beyond `[support] max_shift_m` or when it could
    /// not run), `confirm` (the support is as it is: force control no longer
    /// refused for a named shift).
    Support {
        /// What to do.
        #[arg(value_enum)]
        action: sarctl::cli::support::SupportAction,
    },
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum RecordAction {
    Start,
    Stop,
}

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

/// Runs the subcommand.
fn run(args: &Args) -> Result<(), String> {
    let json = args.format == Format::Json;
    let config = args.config.as_deref();
    match &args.command {
        Cmd::Replay {
            input,
            output,
            compare,
            plot,
            from,
            to,
        } => cli::replay::run(&cli::replay::Args {
            config,
            input,
            output: output.as_deref(),
            compare: compare.as_deref(),
            json,
            plot: plot.as_deref(),
            from_s: *from,
            to_s: *to,
        }),
        Cmd::Recover { file, output } => cli::recover::run(file, output.as_deref(), json),
        Cmd::Export {
            rosbag2,
            recordings,
        } => cli::export::run(rosbag2, recordings, json),
        Cmd::Completions { shell } => {
            check_config(args)?;
            cli::completions::run(<Args as clap::CommandFactory>::command(), *shell)
        }
        Cmd::Workspace => {
            check_config(args)?;
            cli::workspace::run(config, &args.prefix, json)
        }
        Cmd::Identify(a) => {
            // Every number in range before anything is read or asked.
            a.check_ranges()?;
            check_config(args)?;
            cli::identify::run(config, json, &args.prefix, a)
        }
        Cmd::View { bind, scene_hz } => {
            // Refused as every daemon command when no client can be made.
            let _client = connect(args)?;
            sarctl::view::run_cli(&args.prefix, config, bind, *scene_hz)
        }
        Cmd::Status => cli::status::run(&connect(args)?, json),
        Cmd::Monitor { count } => cli::monitor::run(&connect(args)?, json, *count),
        Cmd::Record { action } => {
            cli::record::run(&connect(args)?, *action == RecordAction::Start, json)
        }
        Cmd::Reset => with_daemon(args, cli::reset::run),
        Cmd::Retreat { distance } => with_daemon(args, |d| cli::retreat::run(d, *distance)),
        Cmd::Tare => with_daemon(args, request::tare),
        Cmd::Hold { max_force } => with_daemon(args, |d| request::hold(d, *max_force)),
        Cmd::Push { axial } => with_daemon(args, |d| request::push(d, *axial)),
        Cmd::Position => with_daemon(args, request::position),
        Cmd::MoveTip { x, y, z, max_force } => {
            with_daemon(args, |d| request::move_tip(d, [*x, *y, *z], *max_force))
        }
        Cmd::Limits { set } => with_daemon(args, |d| cli::limits::run(d, set)),
        Cmd::Support { action } => with_daemon(args, |d| cli::support::run(d, *action)),
    }
}

/// The configuration given with `--config` must load (checked even where
/// the subcommand does not use it).
fn check_config(args: &Args) -> Result<(), String> {
    if let Some(path) = &args.config {
        sar_config::load(path).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The client of the daemon (after the configuration's check).
fn connect(args: &Args) -> Result<Client, String> {
    check_config(args)?;
    Client::new(&args.prefix).map_err(|e| e.to_string())
}

/// Runs `f` with the daemon's command service.
fn with_daemon(
    args: &Args,
    f: impl FnOnce(&Daemon<'_>) -> Result<(), String>,
) -> Result<(), String> {
    let client = connect(args)?;
    f(&Daemon {
        client: &client,
        json: args.format == Format::Json,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use sar_estimator::guard::ForceLimits;

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
    #[allow(clippy::unwrap_used)]
    fn the_header_names_every_subcommand() {
        let header: String = include_str!("main.rs")
            .lines()
            .take_while(|l| l.starts_with("//!"))
            .collect::<Vec<_>>()
            .join("\n");
        let cmd = <Args as clap::CommandFactory>::command();
        let names: Vec<&str> = cmd.get_subcommands().map(|c| c.get_name()).collect();
        assert_eq!(names.len(), 19, "{names:?}");
        for name in names {
            assert!(header.contains(&format!("//! - `{name}`: ")), "{name}");
        }
    }
}
