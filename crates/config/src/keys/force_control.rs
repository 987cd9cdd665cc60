//! `[force_control]` (FORCE_CONTROL.md): the admittance law's settings,
//! with the sensor's and the loop's rates and the axes' servo, checked for
//! stability at the stiffest tissue over the plant's range (issue 34: the
//! servo and the rod as they may be, not as configured; a refusal names the
//! key to change).

use crate::ConfigError;
use crate::decl::{num, setting_error};
use crate::keys::{File, axes};
use crate::toml_file::Ctx;
use sar_estimator::SettingError;
use sar_estimator::force_control::{
    Admittance, DEFAULT_RANGE, ForceControlConfig, ForceControlLimits, PlantRange, TipInertia,
};
use sar_estimator::inertial::RodInertia;
use sar_kinematics::Profile;

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
    /// the slowest servo the margin must hold on, a fraction of axes.servo_bandwidth_hz
    servo_bandwidth_min_ratio: f64 = value(DEFAULT_RANGE.servo_bandwidth_min_ratio),
        num(0.05, 1.0, "(ratio)") => [PlantRange.servo_bandwidth_min_ratio];
    /// the fastest servo, a fraction of axes.servo_bandwidth_hz (0: up to ideal drives)
    servo_bandwidth_max_ratio: f64 = value(DEFAULT_RANGE.servo_bandwidth_max_ratio),
        num(0.0, 100.0, "(ratio)").also("0, or at least 1")
        => [PlantRange.servo_bandwidth_max_ratio];
    /// the least damped servo the margin must hold on
    servo_damping_min: f64 = value(DEFAULT_RANGE.servo_damping_min),
        num(0.05, 2.0, "(ratio)") => [PlantRange.servo_damping_min];
    /// the most damped servo
    servo_damping_max: f64 = value(DEFAULT_RANGE.servo_damping_max),
        num(0.05, 2.0, "(ratio)").also("at least servo_damping_min")
        => [PlantRange.servo_damping_max];
    /// the longest pure delay a servo may add to its reference
    servo_delay_max_s: f64 = value(DEFAULT_RANGE.servo_delay_max_s),
        num(0.0, 0.05, "s") => [PlantRange.servo_delay_max_s];
    /// the lightest rod: I_perp as a fraction of the configured
    inertia_perp_ratio_min: f64 = value(DEFAULT_RANGE.inertia_perp_ratio_min),
        num(0.05, 1.0, "(ratio)") => [PlantRange.inertia_perp_ratio_min];
    /// the heaviest rod: I_perp as a fraction of the configured
    inertia_perp_ratio_max: f64 = value(DEFAULT_RANGE.inertia_perp_ratio_max),
        num(1.0, 20.0, "(ratio)") => [PlantRange.inertia_perp_ratio_max];
    /// the shallowest tip the margin must hold at: its distance past the support (b)
    min_tip_depth_m: f64 = value(DEFAULT_MIN_TIP_DEPTH_M),
        num(0.005, 1.5, "m").also("below manipulator.length_m")
        => [TipInertia];
}

/// The shallowest tip the range is checked at by default, m: the demo's
/// (manipulator 2 at its start, 0.15 m past the support).
pub const DEFAULT_MIN_TIP_DEPTH_M: f64 = 0.15;

/// The rod's inertia at the tip as the estimator compensates it, at the
/// tip `b` = `min_tip_depth_m` past the support (FORCE_CONTROL.md): along
/// the rod `m + m_s`; across it `J_B / b^2` with `J_B = I_perp + m (a - c)^2`
/// and `a = L - b`, of which `I_perp / b^2` is I_perp's.
fn tip_inertia(
    ctx: &Ctx<'_>,
    f: &File,
    (profile, rod): (&Profile, &RodInertia),
) -> Result<TipInertia, ConfigError> {
    let b = f.force_control.min_tip_depth_m;
    let (l, m, c) = (profile.length_m(), profile.mass_kg(), profile.com_m());
    if b >= l {
        return Err(ctx.err(
            KEY.min_tip_depth_m.key,
            format!("must be below [manipulator] length_m ({l} m), got {b} m"),
        ));
    }
    let a = l - b;
    let i = rod.inertia_perp_kgm2;
    Ok(TipInertia {
        axial_kg: m + rod.adapter_mass_kg,
        lateral_kg: (i + m * (a - c) * (a - c)) / (b * b),
        inertia_perp_kg: i / (b * b),
    })
}

/// The law's settings with the sensor's and the loop's rates, the axes'
/// servo and the rod; refused (naming the key) when not stable at
/// `max_stiffness_n_per_m` with `min_phase_margin_deg`, at the configured
/// plant and over the range the `servo_*`, `inertia_perp_ratio_*` and
/// `min_tip_depth_m` keys state (issue 34).
pub(crate) fn build(
    ctx: &Ctx<'_>,
    f: &File,
    (sample_rate_hz, rate_hz): (f64, f64),
    rod: (&Profile, &RodInertia),
) -> Result<ForceControlConfig, ConfigError> {
    let t = &f.force_control;
    let tip_inertia = tip_inertia(ctx, f, rod)?;
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
    let range = PlantRange {
        servo_bandwidth_min_ratio: t.servo_bandwidth_min_ratio,
        servo_bandwidth_max_ratio: t.servo_bandwidth_max_ratio,
        servo_damping_min: t.servo_damping_min,
        servo_damping_max: t.servo_damping_max,
        servo_delay_max_s: t.servo_delay_max_s,
        inertia_perp_ratio_min: t.inertia_perp_ratio_min,
        inertia_perp_ratio_max: t.inertia_perp_ratio_max,
    };
    ForceControlConfig::over_range(limits, &range, &tip_inertia).map_err(|e| match e {
        SettingError::Filter(_) => ctx.err(KEY.filter_cutoff_hz.key, e.to_string()),
        SettingError::NotStableOverRange { field, .. } => {
            let key = crate::decl::key_of_field(&[KEYS], field).map_or(SECTION, |d| d.key);
            ctx.err(key, e.to_string())
        }
        _ => setting_error(ctx, &[KEYS, axes::KEYS], &e),
    })
}
