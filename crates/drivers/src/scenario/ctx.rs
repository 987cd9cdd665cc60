//! The file being checked ([`Ctx`]): every error of the loader names the
//! file, the dotted key and, where the file writes it, the line; and the
//! checks that each key's value shares (>= 0, > 0, a time, a rate).

use super::locate::Locator;
use super::{MAX_TIME_S, ScenarioError};
use crate::Vec3;

/// The file being checked: makes errors that name it, the key and the line.
pub(super) struct Ctx<'a> {
    pub origin: &'a str,
    pub locator: Locator<'a>,
}

impl Ctx<'_> {
    pub fn err(&self, key: &str, problem: impl Into<String>) -> ScenarioError {
        ScenarioError::Invalid {
            origin: self.origin.to_owned(),
            key: key.to_owned(),
            line: self.locator.line_near(key),
            problem: problem.into(),
        }
    }

    pub fn serde_error(&self, e: &toml::de::Error) -> ScenarioError {
        let (key, line, problem) = self.locator.serde_problem(e);
        ScenarioError::Invalid {
            origin: self.origin.to_owned(),
            key,
            line,
            problem,
        }
    }

    pub fn non_negative(&self, key: &str, value: f64, unit: &str) -> Result<f64, ScenarioError> {
        if value >= 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be >= 0, got {value} {unit}")))
        }
    }

    pub fn positive(&self, key: &str, value: f64, unit: &str) -> Result<f64, ScenarioError> {
        if value > 0.0 {
            Ok(value)
        } else {
            Err(self.err(key, format!("must be > 0, got {value} {unit}")))
        }
    }

    pub fn non_negative3(&self, key: &str, v: [f64; 3], unit: &str) -> Result<Vec3, ScenarioError> {
        for (i, x) in v.iter().enumerate() {
            self.non_negative(&format!("{key}[{i}]"), *x, unit)?;
        }
        Ok(Vec3::from(v))
    }

    /// A time in seconds (>= 0, at most [`MAX_TIME_S`]) as ns.
    pub fn time_ns(&self, key: &str, s: f64) -> Result<u64, ScenarioError> {
        if s < 0.0 {
            return Err(self.err(key, format!("must be >= 0, got {s} s")));
        }
        if s > MAX_TIME_S {
            return Err(self.err(key, format!("must be at most {MAX_TIME_S} s, got {s} s")));
        }
        Ok(seconds_to_ns_saturating(s))
    }

    /// A rate in Hz as a period in ns (>= 1 us).
    pub fn period_ns(&self, key: &str, rate_hz: f64) -> Result<u64, ScenarioError> {
        if !(rate_hz > 0.0 && rate_hz <= 1e6) {
            return Err(self.err(key, format!("must be in (0, 1e6] Hz, got {rate_hz} Hz")));
        }
        Ok(seconds_to_ns_saturating(1.0 / rate_hz).max(1))
    }
}

pub(super) fn seconds_to_ns_saturating(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        // Saturating float-to-int cast; times here are far below u64::MAX ns.
        (s * 1e9).round() as u64
    } else {
        0
    }
}
