//! `sarctl identify --config FILE --input REC.mcap [--dry-run] [--format json]
//! [--plot FILE.svg]` (INTERFACES.md 3): identifies m and c (and calibrates
//! the support B) from a recording of the identification procedure, prints
//! the result, and unless `--dry-run` writes `mass_kg`, `com_m` and
//! `[geometry] support` back into FILE, keeping the rest of it as it was.
//! The work is in [`crate::identify`]; this is the shell (files, output).
//!
//! `--live` drives a running `sard` instead (iceoryx2 client): after the
//! operator confirms that the sensor was tared with the rod detached
//! (`--yes` for tests), it moves the tip through the cone set of MODEL.md 5.1
//! shrunk to the configured travel ([`crate::identify::poses`]) with
//! move-tip, holds each pose, and feeds the published state to the same
//! dwell finder as a recording: the joints and, as the sensor reading with
//! the daemon's bias removed, `-R_0s^T F_A` (F_A = -R_0s (f_s - b) is
//! published with every estimate). It refuses at once a guard that is not
//! Ok or a tip force at half the warn limit (a contact: the built-in demo of
//! `sard --sim`), asks again a move the guard's Warn braked near the
//! support (the estimate's noise grows as L/a there), and says on stderr
//! which pose it is at and about how long is left.
//!
//! `--servo` identifies the drives' position loop instead
//! ([`super::identify_servo`], [`crate::identify::servo`]).

use crate::identify::dwell::DwellOptions;
use crate::identify::dynamic::DynamicOptions;
use crate::identify::smooth::SmootherSpec;
use crate::identify::{self, IdentifyOptions, excitation, plot, plot_dynamic, writeback};
use sar_record::output::{PendingFile, check_outputs};
use std::path::{Path, PathBuf};

/// The arguments of `sarctl identify` (besides the global `--config` and `--format`).
#[derive(Debug, Clone, clap::Args)]
pub struct IdentifyArgs {
    /// Identify the rod's inertia I_perp (with m and c) from an excitation
    /// motion instead of m, c and B from static poses (MODEL.md 10).
    #[arg(long)]
    pub dynamic: bool,
    /// Identify the drives' position loop (bandwidth, damping, delay) from
    /// moves of each axis instead (issue 34): `--live` makes them, or
    /// `--input` a recording of them; writes `[axes] servo_bandwidth_hz`,
    /// `servo_damping`, `servo_delay_s` back.
    #[arg(long, conflicts_with_all = ["dynamic", "plot", "tare_n", "keep_support"])]
    pub servo: bool,
    /// With --dynamic: the order of the encoders' centred smoothing polynomial.
    #[arg(long, default_value_t = SmootherSpec::default().order, value_name = "N", requires = "dynamic")]
    pub smoother_order: usize,
    /// With --dynamic: the span of the smoothing window, s.
    #[arg(long, default_value_t = SmootherSpec::default().span_s, value_name = "S", requires = "dynamic")]
    pub smoother_span_s: f64,
    /// With --dynamic: the sensor's latency (a sample's stamp less this is
    /// when it was measured), s.
    #[arg(long, default_value_t = 0.0, value_name = "S", requires = "dynamic")]
    pub sensor_latency_s: f64,
    /// With --dynamic: the mass between the sensor and the U-joint, kg, held
    /// there (default: estimated with I_perp, from the configuration's
    /// `[sensor] adapter_mass_kg`, and written back).
    #[arg(long, value_name = "KG", requires = "dynamic")]
    pub adapter_mass_kg: Option<f64>,
    /// With --dynamic: print the excitation of `[identify]`'s limits, its
    /// condition number and the accuracy it promises, and move nothing.
    #[arg(long, requires = "dynamic", conflicts_with_all = ["input", "live"])]
    pub plan: bool,
    /// With --dynamic --plan or --live: the excitation's centre, joints
    /// Q1,Q2,Q3, m (default: the U-joint 0.2 m behind the support along X0).
    #[arg(
        long,
        value_name = "Q1,Q2,Q3",
        value_delimiter = ',',
        requires = "dynamic",
        allow_hyphen_values = true
    )]
    pub centre_m: Option<Vec<f64>>,
    /// With --dynamic --plan or --live: the sensor's sample rate, Hz (for
    /// the plan's expected accuracy).
    #[arg(long, default_value_t = 500.0, value_name = "HZ", requires = "dynamic")]
    pub sensor_rate_hz: f64,
    /// Do not estimate the support's friction (assume a frictionless support).
    #[arg(long)]
    pub no_friction: bool,
    /// The recording of the procedure (MCAP with /sar/sensor/wrench and /sar/joints).
    #[arg(
        long,
        value_name = "REC.mcap",
        required_unless_present_any = ["live", "plan"],
        conflicts_with = "live"
    )]
    pub input: Option<PathBuf>,
    /// Drive the running daemon through the procedure instead of reading a recording.
    #[arg(long)]
    pub live: bool,
    /// With --live: do not ask whether the sensor was tared with the rod detached.
    #[arg(long, requires = "live")]
    pub yes: bool,
    /// With --live: how long each pose is held, s (more than settle + minimum dwell).
    #[arg(long, default_value_t = 0.8, value_name = "S")]
    pub hold_s: f64,
    /// Print the result, write nothing back.
    #[arg(long)]
    pub dry_run: bool,
    /// Draw the vertical force against 1/a with the fitted line and the residuals.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// The sensor's force bias measured with the rod detached, sensor frame,
    /// N (FX,FY,FZ). Default 0: the device was tared with the rod detached.
    /// Not with --live (the daemon's bias is removed from what it publishes).
    #[arg(
        long,
        value_name = "FX,FY,FZ",
        value_delimiter = ',',
        conflicts_with = "live",
        allow_hyphen_values = true
    )]
    pub tare_n: Option<Vec<f64>>,
    /// A dwell: every joint within this range, m.
    #[arg(long, default_value_t = DwellOptions::default().still_tolerance_m, value_name = "M")]
    pub still_tolerance_m: f64,
    /// Time discarded after each move, s.
    #[arg(long, default_value_t = DwellOptions::default().settle_s, value_name = "S")]
    pub settle_s: f64,
    /// Shortest dwell kept after the settle time, s.
    #[arg(long, default_value_t = DwellOptions::default().min_dwell_s, value_name = "S")]
    pub min_dwell_s: f64,
    /// Keep the configured support B (do not calibrate it).
    #[arg(long)]
    pub keep_support: bool,
    /// Largest accepted chi-square per degree of freedom.
    #[arg(long, default_value_t = IdentifyOptions::default().max_chi2_dof, value_name = "X")]
    pub max_chi2_dof: f64,
    /// Largest accepted condition number.
    #[arg(long, default_value_t = identify::DEFAULT_MAX_CONDITION, value_name = "X")]
    pub max_condition: f64,
}

/// One numeric argument's range: (option, value, least, most, unit, what
/// it is). The bounds are inclusive; NaN is never in range.
type Range = (&'static str, f64, f64, f64, &'static str, &'static str);

/// `value` against `[lo, hi]`, or the one-line reason.
fn in_range((option, value, lo, hi, unit, what): Range) -> Result<(), String> {
    use sar_kinematics::Shown;
    if value >= lo && value <= hi {
        return Ok(());
    }
    Err(format!(
        "{option} {} is out of range: {what} must be {} to {}{unit}",
        if value.is_nan() {
            "NaN".to_owned()
        } else {
            Shown(value).to_string()
        },
        Shown(lo),
        Shown(hi)
    ))
}

/// The ranges of the numeric arguments every run checks, in the order of
/// [`IdentifyArgs::check_ranges`]'s values: (option, least, most, unit,
/// what it is).
const RANGES: [(&str, f64, f64, &str, &str); 9] = [
    (
        "--smoother-order",
        2.0,
        12.0,
        "",
        "the smoothing polynomial's order",
    ),
    (
        "--smoother-span-s",
        0.01,
        4.0,
        " s",
        "the smoothing window's span",
    ),
    ("--sensor-latency-s", 0.0, 0.1, " s", "the sensor's latency"),
    (
        "--sensor-rate-hz",
        1.0,
        MAX_SENSOR_RATE_HZ,
        " Hz",
        "the sensor's sample rate",
    ),
    (
        "--still-tolerance-m",
        1e-7,
        0.01,
        " m",
        "a dwell's joint range",
    ),
    (
        "--settle-s",
        0.0,
        60.0,
        " s",
        "the time discarded after each move",
    ),
    ("--min-dwell-s", 0.001, 600.0, " s", "the shortest dwell"),
    (
        "--max-chi2-dof",
        1e-3,
        1e6,
        "",
        "the chi-square per degree of freedom accepted",
    ),
    (
        "--max-condition",
        1.0,
        1e15,
        "",
        "the condition number accepted",
    ),
];

/// Largest sensor rate accepted, Hz (ATI's Net F/T streams 7 kHz; the time
/// the plan's promise takes is linear in it).
pub const MAX_SENSOR_RATE_HZ: f64 = 10_000.0;

/// Longest hold of a pose of `--live`, s.
pub const MAX_HOLD_S: f64 = 600.0;

impl IdentifyArgs {
    /// Every numeric argument against its range, before anything runs
    /// (nothing read, nothing asked of the daemon): the first out of range
    /// is the one-line reason. NaN and infinities are out of every range.
    pub fn check_ranges(&self) -> Result<(), String> {
        let fixed = [
            self.smoother_order as f64,
            self.smoother_span_s,
            self.sensor_latency_s,
            self.sensor_rate_hz,
            self.still_tolerance_m,
            self.settle_s,
            self.min_dwell_s,
            self.max_chi2_dof,
            self.max_condition,
        ];
        for ((option, lo, hi, unit, what), value) in RANGES.into_iter().zip(fixed) {
            in_range((option, value, lo, hi, unit, what))?;
        }
        if let Some(m) = self.adapter_mass_kg {
            in_range((
                "--adapter-mass-kg",
                m,
                0.0,
                5.0,
                " kg",
                "the adapter's mass",
            ))?;
        }
        for v in self.tare_n.iter().flatten() {
            in_range((
                "--tare-n",
                *v,
                -1000.0,
                1000.0,
                " N",
                "each component of the tare",
            ))?;
        }
        for v in self.centre_m.iter().flatten() {
            in_range((
                "--centre-m",
                *v,
                -2.0,
                2.0,
                " m",
                "each joint of the excitation's centre",
            ))?;
        }
        // Only with --live: the pose's hold (its default is checked too).
        if self.live && !self.dynamic && !self.servo {
            let least = self.settle_s + self.min_dwell_s;
            let what = "each pose's hold (more than --settle-s + --min-dwell-s)";
            in_range(("--hold-s", self.hold_s, least, MAX_HOLD_S, " s", what))?;
            if self.hold_s <= least {
                return Err(format!(
                    "--hold-s {} must exceed --settle-s + --min-dwell-s ({} s)",
                    sar_kinematics::Shown(self.hold_s),
                    sar_kinematics::Shown(least)
                ));
            }
        }
        Ok(())
    }

    /// The options these arguments give.
    pub fn options(&self) -> Result<IdentifyOptions, String> {
        let tare_n = match self.tare_n.as_deref() {
            None => [0.0; 3],
            Some(&[x, y, z]) => [x, y, z],
            Some(other) => {
                return Err(format!(
                    "--tare-n needs 3 values FX,FY,FZ, got {}",
                    other.len()
                ));
            }
        };
        Ok(IdentifyOptions {
            dwell: DwellOptions {
                still_tolerance_m: self.still_tolerance_m,
                settle_s: self.settle_s,
                min_dwell_s: self.min_dwell_s,
            },
            tare_n,
            calibrate_support: !self.keep_support,
            friction: !self.no_friction,
            max_chi2_dof: self.max_chi2_dof,
            max_condition: self.max_condition,
        })
    }

    /// The options of `--dynamic` these arguments give.
    /// `config_adapter_mass_kg`: the configuration's `[sensor]
    /// adapter_mass_kg`, used unless `--adapter-mass-kg` is given.
    pub fn dynamic_options(&self, config_adapter_mass_kg: f64) -> Result<DynamicOptions, String> {
        let static_options = self.options()?;
        Ok(DynamicOptions {
            tare_n: static_options.tare_n,
            smoother: SmootherSpec {
                order: self.smoother_order,
                span_s: self.smoother_span_s,
            },
            sensor_latency_s: self.sensor_latency_s,
            adapter_mass_kg: self.adapter_mass_kg.unwrap_or(config_adapter_mass_kg),
            estimate_adapter: self.adapter_mass_kg.is_none(),
            friction: !self.no_friction,
            max_condition: self.max_condition,
            max_chi2_dof: self.max_chi2_dof,
            ..DynamicOptions::default()
        })
    }
}

/// Runs `sarctl identify`; the error is the one-line reason. `prefix` names
/// the daemon's services (for `--live`).
pub fn run(
    config_path: Option<&Path>,
    json: bool,
    prefix: &str,
    args: &IdentifyArgs,
) -> Result<(), String> {
    args.check_ranges()?;
    let config_path =
        config_path.ok_or("identify needs --config FILE (the configuration to identify for)")?;
    check_plot(config_path, args)?;
    let text = sar_config::read_text(config_path).map_err(|e| e.to_string())?;
    let config =
        sar_config::parse(&text, &config_path.display().to_string()).map_err(|e| e.to_string())?;
    if args.dynamic {
        return run_dynamic(config_path, &text, &config, json, (prefix, args));
    }
    if args.servo {
        return run_servo(config_path, &text, &config, json, (prefix, args));
    }
    let options = args.options()?;
    let result = match &args.input {
        Some(input) => identify::identify_file(input, &config, &options)
            .map_err(|e| format!("{}: {e}", input.display()))?,
        None => {
            let dwells = live::collect(&config, &options, prefix, args)?;
            identify::identify_dwells(&dwells, &config, &options)
                .map_err(|e| format!("live: {e}"))?
        }
    };
    if let Some(path) = &args.plot {
        write_whole(path, plot::svg(&result)?.as_bytes())?;
    }
    let written = if args.dry_run {
        None
    } else {
        let new = writeback::write_back(&text, result.mass_kg, result.com_m, result.support_m)
            .map_err(|e| format!("{}: {e}", config_path.display()))?;
        // The new text must still be a valid configuration before it replaces the old.
        sar_config::parse(&new, &config_path.display().to_string())
            .map_err(|e| format!("the written configuration would be refused: {e}"))?;
        let tmp = config_path.with_extension("toml.identify-tmp");
        std::fs::write(&tmp, &new).map_err(|e| format!("{}: {e}", tmp.display()))?;
        std::fs::rename(&tmp, config_path)
            .map_err(|e| format!("{}: {e}", config_path.display()))?;
        Some(config_path.display().to_string())
    };
    let out = if json {
        result.to_json(written.as_deref()).to_string()
    } else {
        result.to_text(written.as_deref())
    };
    println!("{out}");
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file beside it, renamed
/// over it once whole (never a file cut in place).
fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let pending = PendingFile::new(path).map_err(|e| err(&e))?;
    std::fs::write(pending.tmp_path(), bytes).map_err(|e| err(&e))?;
    pending.commit().map_err(|e| err(&e))?;
    Ok(())
}

/// `--plot` is neither the configuration nor the recording (compared as
/// files: a hard or symbolic link is the file).
fn check_plot(config_path: &Path, args: &IdentifyArgs) -> Result<(), String> {
    if let Some(plot) = &args.plot {
        let mut read = vec![config_path];
        read.extend(args.input.as_deref());
        check_outputs(&[plot], &read).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Writes `new` over the configuration at `path` once it parses (through
/// a temporary file and a rename); returns the path written.
fn replace_config(path: &Path, new: &str) -> Result<String, String> {
    // The new text must still be a valid configuration before it replaces the old.
    sar_config::parse(new, &path.display().to_string())
        .map_err(|e| format!("the written configuration would be refused: {e}"))?;
    let tmp = path.with_extension("toml.identify-tmp");
    std::fs::write(&tmp, new).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path.display().to_string())
}

/// `sarctl identify --dynamic`: I_perp, m and c from a recording of an
/// excitation (`--input`), printed, drawn (`--plot`) and, unless
/// `--dry-run`, written back as `[manipulator] inertia_perp_kgm2` and
/// `inertia_perp_std_kgm2`.
fn run_dynamic(
    config_path: &Path,
    text: &str,
    config: &sar_config::Config,
    json: bool,
    (prefix, args): (&str, &IdentifyArgs),
) -> Result<(), String> {
    if args.plan {
        return print_plan(config, json, args);
    }
    let options = args.dynamic_options(config.estimator.inertia.adapter_mass_kg)?;
    let input = match &args.input {
        Some(input) => input.clone(),
        None => super::identify_excite::record_excitation(
            config,
            prefix,
            centre_of(config, args)?,
            args.sensor_rate_hz,
        )?,
    };
    let input = &input;
    let result = identify::dynamic::identify_file(input, config, &options)
        .map_err(|e| format!("{}: {e}", input.display()))?;
    if let Some(path) = &args.plot {
        let svg = plot_dynamic::svg(&result, config.estimator.calibration.gravity_mps2().into())?;
        write_whole(path, svg.as_bytes())?;
    }
    let written = if args.dry_run {
        None
    } else {
        let f = &result.fit;
        let mut new = writeback::write_inertia(text, f.inertia_perp_kgm2, f.inertia_perp_std_kgm2)
            .map_err(|e| format!("{}: {e}", config_path.display()))?;
        if f.adapter_mass_std_kg.is_some() {
            new = writeback::write_adapter(&new, f.adapter_mass_kg.max(0.0))
                .map_err(|e| format!("{}: {e}", config_path.display()))?;
        }
        Some(replace_config(config_path, &new)?)
    };
    let out = if json {
        result.to_json(written.as_deref()).to_string()
    } else {
        result.to_text(written.as_deref())
    };
    println!("{out}");
    Ok(())
}

/// `sarctl identify --servo`: bandwidth, damping and delay from the moves
/// of `--input` (or made `--live`), printed and, unless `--dry-run`,
/// written back as `[axes] servo_bandwidth_hz`, `servo_damping`,
/// `servo_delay_s` (the shared fit; a delay below 0 as 0).
fn run_servo(
    config_path: &Path,
    text: &str,
    config: &sar_config::Config,
    json: bool,
    (prefix, args): (&str, &IdentifyArgs),
) -> Result<(), String> {
    let result = super::identify_servo::identify(config, prefix, args.input.as_deref())?;
    let written = if args.dry_run {
        None
    } else {
        let [bw, z, d] = result.shared.params;
        let new = writeback::write_servo(text, bw, z, identify::servo::written_delay_s(d))
            .map_err(|e| format!("{}: {e}", config_path.display()))?;
        Some(replace_config(config_path, &new).map_err(|e| {
            format!(
                "the servo found ({bw:.3} Hz, damping {z:.4}, delay {:.3} ms) was not written: {e}",
                d * 1e3
            )
        })?)
    };
    let out = if json {
        result.to_json(written.as_deref()).to_string()
    } else {
        result.to_text(written.as_deref())
    };
    println!("{out}");
    Ok(())
}

/// `sarctl identify --dynamic --plan`: the excitation and its promise.
fn print_plan(config: &sar_config::Config, json: bool, args: &IdentifyArgs) -> Result<(), String> {
    let centre_m = centre_of(config, args)?;
    let plan = excitation::Plan::new(config, centre_m, args.sensor_rate_hz)?;
    if json {
        println!("{}", plan.to_json());
    } else {
        println!("{}", plan.to_text());
    }
    Ok(())
}

/// The excitation's centre: `--centre-m`, else the default.
fn centre_of(config: &sar_config::Config, args: &IdentifyArgs) -> Result<[f64; 3], String> {
    match args.centre_m.as_deref() {
        None => excitation::default_centre_m(config),
        Some(&[q1, q2, q3]) => Ok([q1, q2, q3]),
        Some(other) => Err(format!(
            "--centre-m needs 3 values Q1,Q2,Q3, got {}",
            other.len()
        )),
    }
}

/// The live procedure against a running daemon.
mod live {
    use super::IdentifyArgs;
    use crate::cli::request::command_msg;
    use crate::identify::IdentifyOptions;
    use crate::identify::dwell::{Dwell, DwellFinder, SensorAverager};
    use crate::identify::poses::{self, PoseTarget};
    use sar_config::Config;
    use sar_kinematics::{Mat3, Vec3};
    use sar_msgs::command::Request;
    use sar_msgs::wire::{StateMsg, flags, guard_code};
    use sar_shm::{Client, StateSubscription};
    use std::io::{BufRead, Write};
    use std::time::{Duration, Instant};

    /// Joints within this of a target count as arrived, m.
    const ARRIVED_M: f64 = 20e-6;

    /// What the published state gave so far.
    struct Collector {
        finder: DwellFinder,
        sensor: Vec<(u64, [f64; 3])>,
        rotation_t: Mat3,
        last_joints_ns: Option<u64>,
        last_sensor_ns: Option<u64>,
        latest: Option<StateMsg>,
    }

    impl Collector {
        fn take(&mut self, s: &StateMsg) {
            if self.last_joints_ns != Some(s.joints_stamp_ns) {
                self.last_joints_ns = Some(s.joints_stamp_ns);
                self.finder.push(s.joints_stamp_ns, s.q_m);
            }
            if s.flags & flags::ESTIMATE != 0 && self.last_sensor_ns != Some(s.sensor_stamp_ns) {
                self.last_sensor_ns = Some(s.sensor_stamp_ns);
                // f_s - b = -R_0s^T F_A.
                let reading = -(self.rotation_t * Vec3::from(s.ujoint_force_n));
                self.sensor.push((s.sensor_stamp_ns, reading.into()));
            }
            self.latest = Some(*s);
        }

        /// Reads the state for `duration` or until `done` holds; refuses a
        /// halted guard.
        fn follow(
            &mut self,
            sub: &StateSubscription,
            duration: Duration,
            done: impl Fn(&StateMsg) -> bool,
        ) -> Result<bool, String> {
            let start = Instant::now();
            while start.elapsed() < duration {
                let mut batch = Vec::new();
                sub.wait(Duration::from_millis(20), |s| batch.push(*s));
                for s in &batch {
                    self.take(s);
                    if s.guard_state == guard_code::STOP || s.guard_state == guard_code::FAULT {
                        return Err(format!(
                            "the guard halted the robot (state {}, reason {}): the procedure stopped; reset, then run it again",
                            sar_msgs::wire::guard_state_name(s.guard_state),
                            sar_msgs::wire::reason_name(s.guard_reason)
                        ));
                    }
                }
                if self.latest.as_ref().is_some_and(&done) {
                    return Ok(true);
                }
            }
            Ok(false)
        }
    }

    fn confirm(args: &IdentifyArgs) -> Result<(), String> {
        if args.yes {
            return Ok(());
        }
        eprint!(
            "Was the force sensor tared with the rod detached (no manipulator in the U-joint)? [y/N] "
        );
        let _ = std::io::stderr().flush();
        let mut line = String::new();
        std::io::stdin()
            .lock()
            .read_line(&mut line)
            .map_err(|e| format!("cannot read the answer: {e}"))?;
        if matches!(line.trim(), "y" | "Y" | "yes") {
            Ok(())
        } else {
            Err("not confirmed: tare the sensor with the rod detached first (MODEL.md 5), then run identify --live again".into())
        }
    }

    fn arrived(s: &StateMsg, t: &PoseTarget) -> bool {
        let q = [t.joints.q1_m, t.joints.q2_m, t.joints.q3_m];
        s.q_m.iter().zip(q).all(|(a, b)| (a - b).abs() <= ARRIVED_M)
    }

    /// The largest joint distance from `q` to `t`, m.
    fn distance_m(q: &[f64; 3], t: &PoseTarget) -> f64 {
        q.iter()
            .zip([t.joints.q1_m, t.joints.q2_m, t.joints.q3_m])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }

    /// The time a move of `distance_m` takes at `speed_mps`, with some
    /// allowance for accelerating and braking, s.
    fn move_s(distance_m: f64, speed_mps: f64) -> f64 {
        1.2 * distance_m / speed_mps + 0.5
    }

    /// The recipe a refusal names.
    const RECIPE: &str = "identification needs a free tip at rest, nothing touching it \
        (with sard --sim, the built-in demo presses on the tip from 2 s: run \
        sard --sim --scenario scenarios/identify_cone_manipulator_2.toml; README, Recording, replay, identification)";

    /// Refuses at once what cannot be identified: no state, a guard that is
    /// not Ok, or a tip force already at half the total warn limit.
    fn check_start(sub: &StateSubscription) -> Result<StateMsg, String> {
        let s = sub
            .latest(Duration::from_secs(2))
            .ok_or("no state from the daemon within 2 s: is sard running (with this --prefix)?")?;
        if s.guard_state != guard_code::OK {
            return Err(format!(
                "the guard is {} ({}): {RECIPE}",
                sar_msgs::wire::guard_state_name(s.guard_state),
                sar_msgs::wire::reason_name(s.guard_reason)
            ));
        }
        let f = s.tip_force_n;
        let total = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let warn_total = s.limits_n[0];
        if s.flags & flags::ESTIMATE != 0 && total >= 0.5 * warn_total {
            return Err(format!(
                "the tip force is {total:.1} N at rest, half the total warn limit {warn_total:.1} N or more: {RECIPE}"
            ));
        }
        Ok(s)
    }

    /// Moves to `t` and waits until the joints arrive. A move the guard's
    /// Warn braked (the joints at rest short of the target, the guard Ok
    /// again) or refused (in Warn) is asked again, up to [`MAX_RETRIES`]
    /// times: near the support the estimate's noise, amplified by L/a,
    /// crosses the lateral warn limit for a few ms now and then. A Warn
    /// that lasts [`WARN_LIMIT`] is a contact: refused.
    fn reach(
        c: &mut Collector,
        client: &Client,
        sub: &StateSubscription,
        t: &PoseTarget,
        what: &str,
        speed: f64,
    ) -> Result<(), String> {
        let q0 = c.latest.map_or([0.0; 3], |s| s.q_m);
        let deadline =
            Instant::now() + Duration::from_secs_f64(2.0 * move_s(distance_m(&q0, t), speed) + 5.0);
        let mut retries = 0u32;
        let mut warn_since: Option<Instant> = None;
        loop {
            ask_move(c, client, t, what)?;
            let watch = MoveWatch {
                t,
                what,
                deadline,
                retries,
            };
            if follow_move(c, sub, &watch, &mut warn_since)? == MoveEnd::Arrived {
                return Ok(());
            }
            retries += 1;
            if retries > MAX_RETRIES {
                return Err(format!(
                    "{what} (tip {} m) not reached: the guard's Warn braked the move {MAX_RETRIES} times",
                    sar_kinematics::ShownAll(t.tip_m.as_slice())
                ));
            }
        }
    }

    /// Asks the daemon to move the tip to `t`. A refusal is an error, unless
    /// the guard is in Warn (the move is then asked again after it).
    fn ask_move(c: &Collector, client: &Client, t: &PoseTarget, what: &str) -> Result<(), String> {
        let reply = client
            .command(
                command_msg(Request::MoveTip { tip_m: t.tip_m }),
                Duration::from_secs(2),
            )
            .map_err(|e| e.to_string())?;
        let in_warn = c.latest.is_some_and(|s| s.guard_state == guard_code::WARN);
        if reply.status != 0 && !in_warn {
            return Err(format!(
                "the daemon refused the move to {what} (tip {} m): status {}, reason {}",
                sar_kinematics::ShownAll(t.tip_m.as_slice()),
                reply.status,
                sar_msgs::wire::reason_name(reply.reason)
            ));
        }
        Ok(())
    }

    /// One move being followed: to `t` (named `what`) by `deadline`, after
    /// `retries` moves asked again.
    struct MoveWatch<'a> {
        t: &'a PoseTarget,
        what: &'a str,
        deadline: Instant,
        retries: u32,
    }

    /// How a followed move ended.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum MoveEnd {
        /// The joints are at the target.
        Arrived,
        /// The joints rest short of it (the guard's Warn braked the move).
        AtRest,
    }

    /// Follows the state until the joints arrive, or rest short of the
    /// target (0.3 s without 2 um of motion); the deadline passed, or a Warn
    /// that lasts [`WARN_LIMIT`] (since `warn_since`), is an error.
    fn follow_move(
        c: &mut Collector,
        sub: &StateSubscription,
        m: &MoveWatch<'_>,
        warn_since: &mut Option<Instant>,
    ) -> Result<MoveEnd, String> {
        let (t, what) = (m.t, m.what);
        let mut rest: Option<([f64; 3], Instant)> = None;
        loop {
            if Instant::now() >= m.deadline {
                return Err(format!(
                    "{what} (tip {} m) not reached in time ({} moves asked again after the guard's Warn braked them)",
                    sar_kinematics::ShownAll(t.tip_m.as_slice()),
                    m.retries
                ));
            }
            c.follow(sub, Duration::from_millis(50), |_| true)?;
            let Some(s) = c.latest else { continue };
            if arrived(&s, t) {
                return Ok(MoveEnd::Arrived);
            }
            if s.guard_state == guard_code::WARN {
                let since = *warn_since.get_or_insert_with(Instant::now);
                if since.elapsed() >= WARN_LIMIT {
                    return Err(format!(
                        "the guard stayed in Warn for {:.0} s on the way to {what} ({}): something touches the tip; {RECIPE}",
                        WARN_LIMIT.as_secs_f64(),
                        sar_msgs::wire::reason_name(s.guard_reason)
                    ));
                }
                continue;
            }
            *warn_since = None;
            match rest {
                Some((q, at)) if s.q_m.iter().zip(q).all(|(a, b)| (a - b).abs() < 2e-6) => {
                    if at.elapsed() >= Duration::from_millis(300) {
                        return Ok(MoveEnd::AtRest);
                    }
                }
                _ => rest = Some((s.q_m, Instant::now())),
            }
        }
    }

    /// Moves asked again per pose, at most.
    const MAX_RETRIES: u32 = 50;
    /// A Warn this long during the procedure is a contact.
    const WARN_LIMIT: Duration = Duration::from_secs(2);

    /// Drives the procedure; returns the dwells with their sensor sums.
    pub(super) fn collect(
        config: &Config,
        options: &IdentifyOptions,
        prefix: &str,
        args: &IdentifyArgs,
    ) -> Result<Vec<Dwell>, String> {
        let hold_s = args.hold_s;
        let needed_s = options.dwell.settle_s + options.dwell.min_dwell_s;
        if !(hold_s.is_finite() && hold_s > needed_s) {
            return Err(format!(
                "--hold-s {hold_s} must exceed settle + minimum dwell ({needed_s} s)"
            ));
        }
        let targets = poses::cone_set(config)?;
        let client = Client::new(prefix).map_err(|e| e.to_string())?;
        let sub = client.subscribe().map_err(|e| e.to_string())?;
        let first = check_start(&sub)?;
        confirm(args)?;
        let cal = &config.estimator.calibration;
        let mut c = Collector {
            finder: DwellFinder::new(cal, options.dwell),
            sensor: Vec::new(),
            rotation_t: cal.sensor_rotation().transpose(),
            last_joints_ns: None,
            last_sensor_ns: None,
            latest: Some(first),
        };
        let speed = config.axes.max_speed_mps;
        let n = targets.len();
        // What is left: every remaining move and hold, s.
        let left_s = |from: [f64; 3], k: usize| -> f64 {
            let mut q = from;
            let mut total = 0.0;
            for t in targets.iter().skip(k) {
                total += move_s(distance_m(&q, t), speed) + if t.turnaround { 0.0 } else { hold_s };
                q = [t.joints.q1_m, t.joints.q2_m, t.joints.q3_m];
            }
            total
        };
        eprintln!(
            "identify --live: {n} poses (the cone set of MODEL.md 5.1 in the travel), about {:.0} s",
            left_s(first.q_m, 0)
        );
        for (i, t) in targets.iter().enumerate() {
            let q = c.latest.map_or(first.q_m, |s| s.q_m);
            let what = format!("pose {} of {n}", i + 1);
            eprintln!(
                "identify --live: {what}{} (a = {:.3} m), about {:.0} s left",
                if t.turnaround { ", a turnaround" } else { "" },
                t.support_distance_m,
                left_s(q, i)
            );
            reach(&mut c, &client, &sub, t, &what, speed)?;
            if !t.turnaround {
                c.follow(&sub, Duration::from_secs_f64(hold_s), |_| false)?;
            }
        }
        eprintln!("identify --live: every pose held; identifying");
        // One more move would end the last stretch; the finder closes it.
        let mut averager = SensorAverager::new(c.finder.finish());
        for (stamp, f) in &c.sensor {
            averager.push(*stamp, *f);
        }
        Ok(averager.finish())
    }
}
