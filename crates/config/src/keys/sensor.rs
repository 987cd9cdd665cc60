//! `[sensor]`: the force/torque sensor's noise and range, and the tare's
//! limits.

use crate::ConfigError;
use crate::decl::{each, int, num};
use crate::keys::{ns, u32_of, vec3};
use crate::toml_file::Ctx;
use sar_estimator::SensorNoise;
use sar_estimator::cycle::{SensorRange, TareLimits};
use sar_estimator::inertial::RodInertia;

crate::section! {
    /// The force/torque sensor: its noise and range, and the tare.
    section "sensor";
    /// force noise std per sensor axis, N
    noise_n: [f64; 3] = required([0.2, 0.2, 0.8]),
        each(1e-4, 10.0, "N").also("at most a tenth of sensor.range_n") => [SensorNoise::new];
    /// measuring range per axis, N (HEX-6): at or beyond, Fault
    range_n: [f64; 3] = value(<[f64; 3]>::from(SensorRange::HEX6.force_n)),
        each(1.0, 10_000.0, "N") => [SensorRange.force_n];
    /// measuring range per axis, N m (HEX-6)
    range_nm: [f64; 3] = value(<[f64; 3]>::from(SensorRange::HEX6.torque_nm)),
        each(0.01, 1000.0, "N m") => [SensorRange.torque_nm];
    /// bias drift bound since the tare, N/s (added to the margin)
    drift_n_per_s: f64 = value(TareLimits::default().drift_n_per_s),
        num(0.0, 10.0, "N/s") => [TareLimits.drift_n_per_s];
    /// after this long a tare is due (Warn); 0: never
    max_tare_age_s: f64 = value(TareLimits::default().max_age_ns.map_or(0.0, |ns| ns as f64 * 1e-9)),
        num(0.0, 7.0 * 86_400.0, "s") => [TareLimits.max_age_ns];
    /// a tare takes the mean reading of this many samples at rest
    tare_window_samples: i64 = value(i64::from(TareLimits::default().window_samples)),
        int(1, 100_000, "samples") => [TareLimits.window_samples];
    /// refused when the readings' std over it exceeds this x noise_n (not at rest)
    tare_max_spread: f64 = value(TareLimits::default().max_spread),
        num(1.0, 100.0, "(times the noise)") => [TareLimits.max_spread];
    /// at most one accepted tare this often, s (0: no limit)
    tare_min_interval_s: f64 = value(TareLimits::default().min_interval_ns as f64 * 1e-9),
        num(0.0, 3600.0, "s") => [TareLimits.min_interval_ns];
    /// mass between the sensor and the U-joint, kg (MODEL.md 10)
    adapter_mass_kg: f64 = value(0.0), num(0.0, 5.0, "kg") => [RodInertia.adapter_mass_kg];
}

/// The sensor's force noise.
pub(crate) fn noise(ctx: &Ctx<'_>, s: &Section) -> Result<SensorNoise, ConfigError> {
    SensorNoise::new(vec3(s.noise_n)).map_err(|e| ctx.err(KEY.noise_n.key, e.to_string()))
}

/// The sensor's measuring range.
pub(crate) fn range(s: &Section) -> SensorRange {
    SensorRange {
        force_n: vec3(s.range_n),
        torque_nm: vec3(s.range_nm),
    }
}

/// The tare's limits.
pub(crate) fn tare_limits(s: &Section) -> TareLimits {
    TareLimits {
        max_age_ns: (s.max_tare_age_s > 0.0).then(|| ns(s.max_tare_age_s)),
        drift_n_per_s: s.drift_n_per_s,
        window_samples: u32_of(s.tare_window_samples),
        max_spread: s.tare_max_spread,
        min_interval_ns: ns(s.tare_min_interval_s),
    }
}
