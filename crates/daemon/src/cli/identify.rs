//! `sarctl identify --config FILE --input REC.mcap [--dry-run] [--format json]
//! [--plot FILE.svg]` (INTERFACES.md 3): identifies m and c (and calibrates
//! the support B) from a recording of the identification procedure, prints
//! the result, and unless `--dry-run` writes `mass_kg`, `com_m` and
//! `[geometry] support` back into FILE, keeping the rest of it as it was.
//! The work is in [`crate::identify`]; this is the shell (files, output).

use crate::identify::dwell::DwellOptions;
use crate::identify::{self, IdentifyOptions, plot, writeback};
use std::path::{Path, PathBuf};

/// The arguments of `sarctl identify` (besides the global `--config` and `--format`).
#[derive(Debug, Clone, clap::Args)]
pub struct IdentifyArgs {
    /// The recording of the procedure (MCAP with /sar/sensor/wrench and /sar/joints).
    #[arg(long, value_name = "REC.mcap")]
    pub input: PathBuf,
    /// Print the result, write nothing back.
    #[arg(long)]
    pub dry_run: bool,
    /// Draw the vertical force against 1/a with the fitted line and the residuals.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// The sensor's force bias measured with the rod detached, sensor frame,
    /// N (FX,FY,FZ). Default 0: the device was tared with the rod detached.
    #[arg(
        long,
        value_name = "FX,FY,FZ",
        value_delimiter = ',',
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

/// Runs `sarctl identify`; the error is the one-line reason.
pub fn run(config_path: Option<&Path>, json: bool, args: &IdentifyArgs) -> Result<(), String> {
    let config_path =
        config_path.ok_or("identify needs --config FILE (the configuration to identify for)")?;
    let text = std::fs::read_to_string(config_path)
        .map_err(|e| format!("{}: {e}", config_path.display()))?;
    let config = crate::config::parse(&text, &config_path.display().to_string())
        .map_err(|e| e.to_string())?;
    let options = args.options()?;
    let bytes = crate::record::read_file(&args.input).map_err(|e| e.to_string())?;
    let result = identify::identify(&bytes, &config, &options)
        .map_err(|e| format!("{}: {e}", args.input.display()))?;
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
