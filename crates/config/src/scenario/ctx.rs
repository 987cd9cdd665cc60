//! The checks that the keys of a scenario file share (>= 0, > 0, a time, a
//! rate), on the file being checked ([`Ctx`]): each error names the file,
//! the dotted key and, where the file writes it, the line.

use super::MAX_TIME_S;
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_hal::Vec3;
use sar_sim::scenario::seconds_to_ns_saturating;

/// The scenario loader's checks of a value.
impl Ctx<'_> {
    pub(super) fn non_negative(
        &self,
        key: &str,
        value: f64,
        unit: &str,
    ) -> Result<f64, ConfigError> {
        if value >= 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be >= 0, got {value} {unit}")))
        }
    }

    pub(super) fn positive(&self, key: &str, value: f64, unit: &str) -> Result<f64, ConfigError> {
        if value > 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be > 0, got {value} {unit}")))
        }
    }

    pub(super) fn non_negative3(
        &self,
        key: &str,
        v: [f64; 3],
        unit: &str,
    ) -> Result<Vec3, ConfigError> {
        for (i, x) in v.iter().enumerate() {
            self.non_negative(&format!("{key}[{i}]"), *x, unit)?;
        }
        Ok(Vec3::from(v))
    }

    /// A time in seconds (>= 0, at most [`MAX_TIME_S`]) as ns.
    pub(super) fn time_ns(&self, key: &str, s: f64) -> Result<u64, ConfigError> {
        if s < 0.0 {
            return Err(self.err(key, format!("must be >= 0, got {s} s")));
        }
        if s > MAX_TIME_S {
            return Err(self.err(key, format!("must be at most {MAX_TIME_S} s, got {s} s")));
        }
        Ok(seconds_to_ns_saturating(s))
    }

    /// A rate in Hz as a period in ns (>= 1 us).
    pub(super) fn period_ns(&self, key: &str, rate_hz: f64) -> Result<u64, ConfigError> {
        if !(rate_hz > 0.0 && rate_hz <= 1e6) {
            return Err(self.err(key, format!("must be in (0, 1e6] Hz, got {rate_hz} Hz")));
        }
        Ok(seconds_to_ns_saturating(1.0 / rate_hz).max(1))
    }
}
