//! `[force_control]` (FORCE_CONTROL.md): the admittance law's settings,
//! with the sensor's and the loop's rates and the axes' servo, checked for
//! stability at the stiffest tissue (a refusal names the key to change).

use crate::ConfigError;
use crate::decl::{num, setting_error};
use crate::keys::{File, axes};
use crate::toml_file::Ctx;
use sar_estimator::SettingError;
use sar_estimator::force_control::{Admittance, ForceControlConfig, ForceControlLimits};

crate::section! {
    /// Force control (FORCE_CONTROL.md): sarctl hold / push; checked for stability.
    section "force_control";
    /// D along the rod
    axial_damping_n_s_per_m: f64 = value(ForceControlLimits::default().axial.damping_n_s_per_m),
        num(1.0, 1e5, "N s/m") => [ForceControlLimits.axial.damping_n_s_per_m];
    /// M along the rod
    axial_mass_kg: f64 = value(ForceControlLimits::default().axial.mass_kg),
        num(1e-3, 100.0, "kg") => [ForceControlLimits.axial.mass_kg];
    /// D across the rod
    lateral_damping_n_s_per_m: f64 = value(ForceControlLimits::default().lateral.damping_n_s_per_m),
        num(1.0, 1e5, "N s/m") => [ForceControlLimits.lateral.damping_n_s_per_m];
    /// M across the rod
    lateral_mass_kg: f64 = value(ForceControlLimits::default().lateral.mass_kg),
        num(1e-3, 100.0, "kg") => [ForceControlLimits.lateral.mass_kg];
    /// the hold's return stiffness (>= 0)
    hold_return_n_per_m: f64 = value(ForceControlLimits::default().hold_return_n_per_m),
        num(0.0, 1e5, "N/m") => [ForceControlLimits.hold_return_n_per_m];
    /// speed of the commanded tip
    max_speed_mps: f64 = value(ForceControlLimits::default().max_speed_mps),
        num(1e-5, 0.1, "m/s") => [ForceControlLimits.max_speed_mps];
    /// acceleration of the commanded tip
    max_accel_mps2: f64 = value(ForceControlLimits::default().max_accel_mps2),
        num(1e-4, 10.0, "m/s^2") => [ForceControlLimits.max_accel_mps2];
    /// largest excursion of the tip from where the mode started
    max_excursion_m: f64 = value(ForceControlLimits::default().max_excursion_m),
        num(1e-4, 0.2, "m") => [ForceControlLimits.max_excursion_m];
    /// the law's own low-pass of the tip force
    filter_cutoff_hz: f64 = value(ForceControlLimits::default().filter_cutoff_hz),
        num(0.01, 50_000.0, "Hz").also("below half of tip.sample_rate_hz")
        => [ForceControlLimits.filter_cutoff_hz];
    /// delays besides the filter's and the servo's (sensor, drives)
    other_delay_s: f64 = value(ForceControlLimits::default().other_delay_s),
        num(0.0, 1.0, "s") => [ForceControlLimits.other_delay_s];
    /// the stiffest tissue it must stay stable on
    max_stiffness_n_per_m: f64 = value(ForceControlLimits::default().max_stiffness_n_per_m),
        num(1.0, 1e6, "N/m") => [ForceControlLimits.max_stiffness_n_per_m];
    /// the stability bound at that stiffness
    min_phase_margin_deg: f64 = value(ForceControlLimits::default().min_phase_margin_deg),
        num(0.0, 90.0, "deg").also("below 90") => [ForceControlLimits.min_phase_margin_deg];
}

/// The law's settings with the sensor's and the loop's rates and the axes'
/// servo; refused (naming the key) when not stable at
/// `max_stiffness_n_per_m` with `min_phase_margin_deg`.
pub(crate) fn build(
    ctx: &Ctx<'_>,
    f: &File,
    (sample_rate_hz, rate_hz): (f64, f64),
) -> Result<ForceControlConfig, ConfigError> {
    let t = &f.force_control;
    let limits = ForceControlLimits {
        axial: Admittance {
            mass_kg: t.axial_mass_kg,
            damping_n_s_per_m: t.axial_damping_n_s_per_m,
        },
        lateral: Admittance {
            mass_kg: t.lateral_mass_kg,
            damping_n_s_per_m: t.lateral_damping_n_s_per_m,
        },
        max_speed_mps: t.max_speed_mps,
        max_accel_mps2: t.max_accel_mps2,
        max_excursion_m: t.max_excursion_m,
        hold_return_n_per_m: t.hold_return_n_per_m,
        filter_cutoff_hz: t.filter_cutoff_hz,
        sample_period_s: 1.0 / sample_rate_hz,
        period_s: 1.0 / rate_hz,
        other_delay_s: t.other_delay_s,
        max_stiffness_n_per_m: t.max_stiffness_n_per_m,
        min_phase_margin_deg: t.min_phase_margin_deg,
        servo_bandwidth_hz: f.axes.servo_bandwidth_hz,
        servo_damping: f.axes.servo_damping,
    };
    ForceControlConfig::new(limits).map_err(|e| match e {
        SettingError::Filter(_) => ctx.err(KEY.filter_cutoff_hz.key, e.to_string()),
        _ => setting_error(ctx, &[KEYS, axes::KEYS], &e),
    })
}
