//! `[tip]`: the tip-force estimate's observability limit, the filtered tip
//! force beside it, the sensor's rate and latency.

use crate::ConfigError;
use crate::decl::num;
use crate::toml_file::Ctx;
use sar_estimator::filter::{FilterConfig, TipFilter};
use sar_estimator::tip_force::TipForceConfig;
use sar_loop::motion::MotionConfig;

crate::section! {
    /// The tip force: its observability limit and the filtered tip force beside the estimate.
    section "tip";
    /// observability limit: a larger std of any axis of the estimate is not observable, N
    max_std_n: f64 = value(TipForceConfig::DEFAULT_MAX_STD_N),
        num(1e-3, 20.0, "N") => [TipForceConfig.max_std_n];
    /// filtered tip force beside the estimate, Hz (0: off)
    filter_cutoff_hz: f64 = value(5.0),
        num(0.0, 50_000.0, "Hz").also("below half of sample_rate_hz") => [FilterConfig.cutoff_hz];
    /// the sensor's sample rate, Hz (the filter's step)
    sample_rate_hz: f64 = value(500.0), num(1.0, 100_000.0, "Hz") => [FilterConfig.sample_period_s];
    /// from measurement to the sample's stamp (the motion is evaluated there)
    sensor_latency_s: f64 = value(0.001), num(0.0, 0.05, "s") => [MotionConfig.sensor_latency_ns];
}

/// `[tip]` checked: the observability limit, the sensor's rate and the filter.
pub(crate) struct Tip {
    pub max_std_n: f64,
    pub sample_rate_hz: f64,
    pub filter: Option<FilterConfig>,
}

/// The sensor's sample period, ns.
pub(crate) fn sample_period_ns(t: &Section) -> u64 {
    (1e9 / t.sample_rate_hz).round() as u64
}

/// `[tip]`, the filter through its own check (below Nyquist).
pub(crate) fn build(ctx: &Ctx<'_>, t: &Section) -> Result<Tip, ConfigError> {
    let filter = if t.filter_cutoff_hz == 0.0 {
        None
    } else {
        let filter = FilterConfig {
            cutoff_hz: t.filter_cutoff_hz,
            sample_period_s: 1.0 / t.sample_rate_hz,
        };
        // Checked here so that the error names the key.
        TipFilter::new(filter).map_err(|e| ctx.err(KEY.filter_cutoff_hz.key, e.to_string()))?;
        Some(filter)
    };
    Ok(Tip {
        max_std_n: t.max_std_n,
        sample_rate_hz: t.sample_rate_hz,
        filter,
    })
}
