//! `[guard]`: the force limits (their keys are [`ForceLimits::NAMES`], the
//! names the wire, `sarctl` and the log use), the guard's timing and margin,
//! the ceilings of run-time limit changes and the retreat's rise allowance,
//! through the guard's own checks (warn below stop, ...).

use crate::ConfigError;
use crate::decl::{int, num, setting_error};
use crate::keys::{ns, u32_of};
use crate::toml_file::Ctx;
use sar_estimator::guard::{
    DEFAULT_RETREAT_RISE_N, ForceLimits, GuardConfig, GuardLimits, MAX_DEBOUNCE_SAMPLES,
    MAX_STD_MARGIN,
};

crate::section! {
    /// The guard: warn and stop limits on the tip force's total, axial and lateral parts.
    section "guard";
    const BELOW_RANGE: &str = "at most the smallest of sensor.range_n";
    /// Warn above this total tip force |F|, N
    warn_total_n: f64 = value(ForceLimits::DEFAULT.warn_total_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.warn_total_n];
    /// Stop above this total tip force |F|, N
    stop_total_n: f64 = value(ForceLimits::DEFAULT.stop_total_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.stop_total_n];
    /// Warn above this axial part |F . u|, N
    warn_axial_n: f64 = value(ForceLimits::DEFAULT.warn_axial_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.warn_axial_n];
    /// Stop above this axial part |F . u|, N
    stop_axial_n: f64 = value(ForceLimits::DEFAULT.stop_axial_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.stop_axial_n];
    /// Warn above this lateral part |F - (F . u) u|, N
    warn_lateral_n: f64 = value(ForceLimits::DEFAULT.warn_lateral_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.warn_lateral_n];
    /// Stop above this lateral part |F - (F . u) u|, N
    stop_lateral_n: f64 = value(ForceLimits::DEFAULT.stop_lateral_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardLimits.force.stop_lateral_n];
    /// Warn clears only below every warn limit less this, N
    hysteresis_n: f64 = value(1.0),
        num(0.0, 10.0, "N").also("below every warn limit") => [GuardLimits.hysteresis_n];
    /// new samples in a row (up/down count) to enter Warn or Stop, or leave Warn
    debounce_samples: i64 = value(3),
        int(1, MAX_DEBOUNCE_SAMPLES as i64, "samples") => [GuardLimits.debounce_samples];
    /// a sensor sample older than this: Fault
    max_sensor_age_s: f64 = value(0.01), num(1e-4, 1.0, "s") => [GuardLimits.max_sensor_age_ns];
    /// joint positions older than this: Fault
    max_joints_age_s: f64 = value(0.01), num(1e-4, 1.0, "s") => [GuardLimits.max_joints_age_ns];
    /// each part is compared with its limits after adding this many standard deviations
    std_margin: f64 = value(2.0),
        num(0.0, MAX_STD_MARGIN, "(standard deviations)") => [GuardLimits.std_margin];
    /// the ceiling `sarctl limits --set` may raise stop_total_n to
    max_stop_total_n: f64 = absent("the stop limit: limits can only be lowered at run time", ForceLimits::DEFAULT.stop_total_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardConfig::with_ceiling];
    /// the ceiling `sarctl limits --set` may raise stop_axial_n to
    max_stop_axial_n: f64 = absent("the stop limit: limits can only be lowered at run time", ForceLimits::DEFAULT.stop_axial_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardConfig::with_ceiling];
    /// the ceiling `sarctl limits --set` may raise stop_lateral_n to
    max_stop_lateral_n: f64 = absent("the stop limit: limits can only be lowered at run time", ForceLimits::DEFAULT.stop_lateral_n),
        num(0.1, 100.0, "N").also(BELOW_RANGE) => [GuardConfig::with_ceiling];
    /// Retreat: Stop when the filtered force rises this much
    retreat_rise_n: f64 = value(DEFAULT_RETREAT_RISE_N),
        num(0.0, 100.0, "N").also("below every stop limit") => [GuardConfig::with_retreat_rise_n];
}

/// The six force limits, the only place they leave the keys.
fn force_limits(g: &Section) -> ForceLimits {
    ForceLimits {
        warn_total_n: g.warn_total_n,
        stop_total_n: g.stop_total_n,
        warn_axial_n: g.warn_axial_n,
        stop_axial_n: g.stop_axial_n,
        warn_lateral_n: g.warn_lateral_n,
        stop_lateral_n: g.stop_lateral_n,
    }
}

/// The guard, through its own checks (each error under its key).
pub(crate) fn build(ctx: &Ctx<'_>, g: &Section) -> Result<GuardConfig, ConfigError> {
    let force = force_limits(g);
    let limits = GuardLimits {
        force,
        hysteresis_n: g.hysteresis_n,
        debounce_samples: u32_of(g.debounce_samples),
        max_sensor_age_ns: ns(g.max_sensor_age_s),
        max_joints_age_ns: ns(g.max_joints_age_s),
        std_margin: g.std_margin,
    };
    let err = |e| setting_error(ctx, &[KEYS], &e);
    let [total_n, axial_n, lateral_n] = force.stop_n();
    GuardConfig::new(limits)
        .map_err(err)?
        .with_ceiling([
            g.max_stop_total_n.unwrap_or(total_n),
            g.max_stop_axial_n.unwrap_or(axial_n),
            g.max_stop_lateral_n.unwrap_or(lateral_n),
        ])
        .map_err(err)?
        .with_retreat_rise_n(g.retreat_rise_n)
        .map_err(err)
}
