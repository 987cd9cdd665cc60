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
//! published with every estimate).

use crate::identify::dwell::DwellOptions;
use crate::identify::{self, IdentifyOptions, plot, writeback};
use std::path::{Path, PathBuf};

/// The arguments of `sarctl identify` (besides the global `--config` and `--format`).
#[derive(Debug, Clone, clap::Args)]
pub struct IdentifyArgs {
    /// The recording of the procedure (MCAP with /sar/sensor/wrench and /sar/joints).
    #[arg(
        long,
        value_name = "REC.mcap",
        required_unless_present = "live",
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

impl IdentifyArgs {
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
            max_chi2_dof: self.max_chi2_dof,
            max_condition: self.max_condition,
            ..IdentifyOptions::default()
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
    let config_path =
        config_path.ok_or("identify needs --config FILE (the configuration to identify for)")?;
    let text = std::fs::read_to_string(config_path)
        .map_err(|e| format!("{}: {e}", config_path.display()))?;
    let config = crate::config::parse(&text, &config_path.display().to_string())
        .map_err(|e| e.to_string())?;
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
        let svg = plot::svg(&result)?;
        std::fs::write(path, svg).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    let written = if args.dry_run {
        None
    } else {
        let new = writeback::write_back(&text, result.mass_kg, result.com_m, result.support_m)
            .map_err(|e| format!("{}: {e}", config_path.display()))?;
        // The new text must still be a valid configuration before it replaces the old.
        crate::config::parse(&new, &config_path.display().to_string())
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

/// The live procedure against a running daemon.
mod live {
    use super::IdentifyArgs;
    use crate::config::Config;
    use crate::identify::IdentifyOptions;
    use crate::identify::dwell::{Dwell, DwellFinder, SensorAverager};
    use crate::identify::poses::{self, PoseTarget};
    use crate::shm::{Client, StateSubscription};
    use crate::wire::{CommandMsg, StateMsg, command_kind, flags, guard_code};
    use sar_kinematics::{Mat3, Vec3};
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
                            crate::wire::guard_state_name(s.guard_state),
                            crate::wire::reason_name(s.guard_reason)
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
        let client = Client::new(prefix)?;
        let sub = client.subscribe()?;
        confirm(args)?;
        let cal = &config.estimator.calibration;
        let mut c = Collector {
            finder: DwellFinder::new(cal, options.dwell),
            sensor: Vec::new(),
            rotation_t: cal.sensor_rotation().transpose(),
            last_joints_ns: None,
            last_sensor_ns: None,
            latest: None,
        };
        let speed = config.axes.max_speed_mps;
        for (i, t) in targets.iter().enumerate() {
            let reply = client.command(
                CommandMsg {
                    kind: command_kind::MOVE_TIP,
                    reserved: 0,
                    id: u64::from(std::process::id()),
                    tip_m: t.tip_m.into(),
                    limits_n: [0.0; 6],
                },
                Duration::from_secs(2),
            )?;
            if reply.status != 0 {
                return Err(format!(
                    "the daemon refused the move to pose {} of {} (tip {:?} m): status {}, reason {}",
                    i + 1,
                    targets.len(),
                    t.tip_m.as_slice(),
                    reply.status,
                    crate::wire::reason_name(reply.reason)
                ));
            }
            // Generous: the longest axis move at the planned speed, twice, plus 5 s.
            let distance = c.latest.map_or(1.0, |s| {
                s.q_m
                    .iter()
                    .zip([t.joints.q1_m, t.joints.q2_m, t.joints.q3_m])
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max)
            });
            let timeout = Duration::from_secs_f64(2.0 * distance / speed + 5.0);
            if !c.follow(&sub, timeout, |s| arrived(s, t))? {
                return Err(format!(
                    "pose {} of {} (tip {:?} m) not reached within {:.0} s",
                    i + 1,
                    targets.len(),
                    t.tip_m.as_slice(),
                    timeout.as_secs_f64()
                ));
            }
            if !t.turnaround {
                c.follow(&sub, Duration::from_secs_f64(hold_s), |_| false)?;
            }
        }
        // One more move would end the last stretch; the finder closes it.
        let mut averager = SensorAverager::new(c.finder.finish());
        for (stamp, f) in &c.sensor {
            averager.push(*stamp, *f);
        }
        Ok(averager.finish())
    }
}
