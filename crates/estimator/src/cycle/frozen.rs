//! The frozen-sensor (stuck-at) check's statistics: how likely a live
//! sensor at rest repeats its previous sample bit for bit on every channel,
//! and the smallest count of repeats in a row ([`super::FrozenCheck`]) with
//! fewer than one expected false alarm in ten years of 1 kHz operation.

use super::plausibility::FrozenCheck;
use crate::Vec3;

/// The fraction of the configured noise assumed for the difference of two
/// consecutive samples in [`frozen_repeat_probability`]: a device's internal
/// low-pass correlates consecutive samples (the difference of two samples
/// with correlation rho has std sigma sqrt(2 (1 - rho))); 1/4 is rho ~ 0.97,
/// and also covers a sensor quieter than configured.
pub const FROZEN_NOISE_FRACTION: f64 = 0.25;

/// New samples in ten years of 1 kHz operation: the false-alarm budget of
/// [`frozen_repeats`] is less than one alarm in that many samples.
pub const SAMPLES_IN_TEN_YEARS_1KHZ: f64 = 1000.0 * 3600.0 * 24.0 * 365.25 * 10.0;

/// The probability that one new sample repeats the previous one bit for bit
/// on every channel, for a live sensor at rest. Per channel with noise
/// sigma and resolution r (one count; 0 for a continuous reading, as the
/// simulator's), the difference of two samples has std
/// `sd = FROZEN_NOISE_FRACTION * sqrt(2) * sigma` and rounds to zero counts
/// with probability about `r / (sqrt(2 pi) sd)` (its density at 0 times one
/// count; capped at 1, and 1 when `sd < r / 2`); the channels are
/// independent, so the probabilities multiply. `noise_nm` `None` (no torque
/// channels configured) uses the three force channels only.
pub fn frozen_repeat_probability(
    noise_n: &Vec3,
    noise_nm: Option<&Vec3>,
    resolution_n: f64,
    resolution_nm: f64,
) -> f64 {
    let channel = |sigma: f64, resolution: f64| -> f64 {
        if resolution <= 0.0 {
            return 0.0;
        }
        let sd = FROZEN_NOISE_FRACTION * core::f64::consts::SQRT_2 * sigma;
        if sd.is_nan() || sd < resolution / 2.0 {
            return 1.0;
        }
        let density = 1.0 / (libm::sqrt(2.0 * core::f64::consts::PI) * sd);
        (density * resolution).min(1.0)
    };
    let mut p = 1.0;
    for sigma in noise_n.iter() {
        p *= channel(*sigma, resolution_n);
    }
    if let Some(nm) = noise_nm {
        for sigma in nm.iter() {
            p *= channel(*sigma, resolution_nm);
        }
    }
    p
}

/// Expected false alarms of the frozen check with N = `repeats` over ten
/// years of 1 kHz operation: `SAMPLES_IN_TEN_YEARS_1KHZ * p^repeats` for the
/// per-sample repeat probability `p` ([`frozen_repeat_probability`]).
pub fn frozen_false_alarms_in_ten_years(p: f64, repeats: u32) -> f64 {
    SAMPLES_IN_TEN_YEARS_1KHZ * libm::pow(p, f64::from(repeats))
}

/// N for the frozen check: the smallest N >= [`FrozenCheck::DEFAULT_REPEATS`]
/// with fewer than one expected false alarm in ten years of 1 kHz operation
/// ([`frozen_false_alarms_in_ten_years`] < 1); `None` when no N up to
/// [`FrozenCheck::MAX_REPEATS`] does (a sensor that repeats by itself: the
/// check cannot work and must be switched off explicitly).
///
/// Example, the HEX-6 over RDT (noise 0.2/0.2/0.8 N, 0.01/0.01/0.002 N m;
/// resolution 1e-4 N, 1e-5 N m, i.e. 10000 counts/N and 100000 counts/N m):
/// per channel 8e-4, 8e-4, 2e-4, 1.6e-3, 1.6e-3, 8e-3; p = 2.6e-18; with
/// N = 3 the expected false alarms in ten years are 5e-42.
pub fn frozen_repeats(
    noise_n: &Vec3,
    noise_nm: Option<&Vec3>,
    resolution_n: f64,
    resolution_nm: f64,
) -> Option<u32> {
    let p = frozen_repeat_probability(noise_n, noise_nm, resolution_n, resolution_nm);
    (FrozenCheck::DEFAULT_REPEATS..=FrozenCheck::MAX_REPEATS)
        .find(|n| frozen_false_alarms_in_ten_years(p, *n) < 1.0)
}
