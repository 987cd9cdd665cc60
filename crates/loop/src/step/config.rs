//! The loop's settings beyond the estimator's ([`StepConfig`], checked by
//! [`LoopStep::new`](super::LoopStep::new)) and the step's fixed constants.

use crate::excite::ExciteLimits;
use crate::motion::MotionConfig;
use sar_estimator::SettingError;
use sar_estimator::filter::{FilterConfig, TipFilter};
use sar_estimator::force_control::ForceControlConfig;
use sar_estimator::inertia_watch::InertiaWatchConfig;
use sar_estimator::support::SupportWatchConfig;
use sar_hal::motion::Limits;

/// Below this speed (on every axis, between two joint samples) the axes are
/// at rest for a reset, m/s (well above the encoders' quantisation over one
/// period, well below any planned move).
pub const REST_SPEED_MPS: f64 = 0.002;

/// The guarded force's rate is low-passed over this fraction of the
/// filter's lag.
pub const RATE_LAG_FRACTION: f64 = 0.125;

/// The longest back-out a single request may ask for, m.
pub const MAX_BACK_OUT_M: f64 = 0.1;

/// The significance, in standard deviations, at which a guarded move's
/// force along its way says that it is in contact, and its anticipated rise
/// counts (issue 33 section 3; `in_contact` in `step/guarded.rs`).
pub const GUARDED_CONTACT_SIGMA: f64 = 6.0;

/// The loop's settings beyond the estimator's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepConfig {
    /// (min, max) of q1, q2, q3, m.
    pub travel_m: [(f64, f64); 3],
    /// Speed and acceleration of the moves the loop plans.
    pub axis_limits: Limits,
    /// The accepted following error per axis, m.
    pub following_tolerance_m: f64,
    /// The speed of moves in Retreat, m/s (> 0, at most the axes' speed).
    pub retreat_speed_mps: f64,
    /// The loop's period, ns: streamed set points are one period ahead.
    pub period_ns: u64,
    /// The publishing thread without progress for longer than this is a
    /// Fault, ns.
    pub publisher_stall_ns: u64,
    /// Force control's settings (`[force_control]`).
    pub force_control: ForceControlConfig,
    /// The drives as the loop models them: their servo, quick stop, and a
    /// guarded move's brake ([`crate::motion`]).
    pub motion: MotionConfig,
    /// An excitation's limits (`[identify]`, issue 26).
    pub excite: ExciteLimits,
    /// The inertia watch's limits (`[manipulator] inertia_watch_*`, issue 34).
    pub inertia_watch: InertiaWatchConfig,
    /// The support watch (`[support]`, issue 34 section 3).
    pub support: SupportWatchConfig,
}

/// Why a [`StepConfig`] cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum StepConfigError {
    /// The estimator refused its configuration.
    #[error(transparent)]
    Estimator(#[from] SettingError),
    /// A loop setting is out of range.
    #[error("{field} = {value}: {why}")]
    Invalid {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        why: &'static str,
    },
}

impl StepConfig {
    /// The loop's settings checked one by one (the first out of range is
    /// the error).
    pub(super) fn check(&self) -> Result<(), StepConfigError> {
        let invalid = |field, value, why| StepConfigError::Invalid { field, value, why };
        let l = self.axis_limits;
        if !(l.max_speed_mps.is_finite() && l.max_speed_mps > 0.0) {
            return Err(invalid(
                "max_speed_mps",
                l.max_speed_mps,
                "must be finite and > 0",
            ));
        }
        if !(l.max_accel_mps2.is_finite() && l.max_accel_mps2 > 0.0) {
            return Err(invalid(
                "max_accel_mps2",
                l.max_accel_mps2,
                "must be finite and > 0",
            ));
        }
        let t = self.following_tolerance_m;
        if !(t.is_finite() && t > 0.0) {
            return Err(invalid(
                "following_tolerance_m",
                t,
                "must be finite and > 0",
            ));
        }
        for &(lo, hi) in &self.travel_m {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid("travel_m", lo, "must be finite with min < max"));
            }
        }
        let r = self.retreat_speed_mps;
        if !(r.is_finite() && r > 0.0 && r <= l.max_speed_mps) {
            return Err(invalid(
                "retreat_speed_mps",
                r,
                "must be finite, > 0 and at most max_speed_mps",
            ));
        }
        if self.period_ns == 0 {
            return Err(invalid("period_ns", 0.0, "must be > 0"));
        }
        if self.publisher_stall_ns == 0 {
            return Err(invalid("publisher_stall_ns", 0.0, "must be > 0"));
        }
        self.inertia_watch.check()?;
        self.motion
            .check(l.max_accel_mps2)
            .map_err(|(field, value, why)| invalid(field, value, why))
    }
}

/// The guarded force's filter: its group delay and sample period, s. The
/// estimator has checked the filter; refused here the same way. No filter:
/// the guarded force is the estimate, whose rate is its noise; no
/// anticipation (a period of 0 marks it).
pub(super) fn guarded_filter(filter: Option<FilterConfig>) -> Result<(f64, f64), StepConfigError> {
    let Some(f) = filter else {
        return Ok((0.0, 0.0));
    };
    match TipFilter::new(f) {
        Ok(t) => Ok((t.group_delay_s(), f.sample_period_s)),
        Err(_) => Err(StepConfigError::Invalid {
            field: "filter_cutoff_hz",
            value: f.cutoff_hz,
            why: "not a valid filter of the sensor's samples",
        }),
    }
}
