//! `[support]`: the support watch (issue 34 section 3, MODEL.md 5.1): the
//! shift of the support point B that free-tip samples at varying poses
//! show while the robot runs, and the limit beyond which it is named and
//! force control refused until `sarctl support confirm`
//! (`sar_estimator::support::SupportWatch`).

use crate::decl::num;
use sar_estimator::support::SupportWatchConfig;

crate::section! {
    /// The support watch: a shift of the support beyond the limit is named, force control refused until confirmed.
    section "support";
    /// a shift of B beyond this on a determined axis is named
    max_shift_m: f64 = value(SupportWatchConfig::DEFAULT.max_shift_m),
        num(5e-4, 0.05, "m") => [SupportWatchConfig.max_shift_m];
    /// the tip is taken as free only while the filtered tip force is below this
    free_tip_max_n: f64 = value(SupportWatchConfig::DEFAULT.free_tip_max_n),
        num(0.1, 20.0, "N") => [SupportWatchConfig.free_tip_max_n];
    /// the forgetting's window (each free sample's weight decays over it)
    window_s: f64 = value(5.0), num(1.0, 600.0, "s") => [SupportWatchConfig.window_samples];
    /// a component whose standard error exceeds this is not determined (not judged)
    max_std_m: f64 = value(SupportWatchConfig::DEFAULT.max_std_m),
        num(1e-5, 0.02, "m") => [SupportWatchConfig.max_std_m];
}

/// `[support]` as the watch's settings, with the sensor's rate (the window
/// in samples).
pub(crate) fn build(s: &Section, sample_rate_hz: f64) -> SupportWatchConfig {
    SupportWatchConfig {
        max_shift_m: s.max_shift_m,
        free_tip_max_n: s.free_tip_max_n,
        window_samples: (s.window_s * sample_rate_hz).max(2.0),
        max_std_m: s.max_std_m,
    }
}
