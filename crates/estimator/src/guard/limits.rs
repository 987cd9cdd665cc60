//! The guard's limits: as the caller fills them ([`GuardLimits`], with the
//! six force limits of [`ForceLimits`], the one type that holds them), and
//! checked once ([`GuardConfig`]: warn below stop, within their bounds; the
//! ceilings a run-time change of the force limits may not pass; the rise
//! allowance of `Retreat`).

use super::parts::ForcePart;
use crate::SettingError;
use core::fmt;

/// The limits of the guard, as the caller fills them (e.g. from a
/// configuration file). [`GuardConfig::new`] checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardLimits {
    /// The six force limits (warn and stop on the total, axial and lateral
    /// parts), N.
    pub force: ForceLimits,
    /// `Warn` clears only when every part is below its warn limit minus this, N.
    pub hysteresis_n: f64,
    /// The up/down count over new sensor samples at which `Warn` or `Stop` is
    /// entered and `Warn` left (see the module documentation), 1..=100.
    pub debounce_samples: u32,
    /// Largest accepted age of the force sensor reading, measured from the
    /// stamp of the sample whose counter is the current one (a re-stamped
    /// copy of an old sample does not make it younger), ns. Also the longest
    /// accepted interval between two new samples.
    pub max_sensor_age_ns: u64,
    /// Largest accepted age of the joint positions, ns.
    pub max_joints_age_ns: u64,
    /// k: each part is compared with its limits after adding `k |std_n|`
    /// (|std_n| bounds the standard deviation of every part), so that a force
    /// that may be above a limit counts as above it. 0 compares the estimate
    /// itself; 2 stops a force whose estimate is within two standard deviations
    /// below the limit. 0 <= k <= [`MAX_STD_MARGIN`].
    pub std_margin: f64,
}

impl GuardLimits {
    /// Example limits, for tests and examples (a robot's come from its
    /// configuration): total 10/15 N, axial 8/12 N, lateral 6/10 N (the
    /// default configuration's force limits), hysteresis 1 N, debounce 3 new
    /// samples, inputs at most 5 ms old, no margin.
    pub const EXAMPLE: GuardLimits = GuardLimits {
        force: ForceLimits::DEFAULT,
        hysteresis_n: 1.0,
        debounce_samples: 3,
        max_sensor_age_ns: 5_000_000,
        max_joints_age_ns: 5_000_000,
        std_margin: 0.0,
    };
}

/// The six force limits of the guard, the one type that holds them: in the
/// guard's limits ([`GuardLimits::force`]), what an operator may change at
/// run time ([`crate::cycle::Command::SetLimits`], within the ceilings
/// fixed at start, [`GuardConfig::with_ceiling`]), and, through
/// [`ForceLimits::to_array`] and [`ForceLimits::NAMES`], the wire's six
/// numbers and every name they are shown under (configuration keys, JSON
/// fields, the command line's options, the log).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    /// Warn limit on the total tip force |F_tip|, N.
    pub warn_total_n: f64,
    /// Stop limit on the total tip force |F_tip|, N.
    pub stop_total_n: f64,
    /// Warn limit on the axial part |F_tip . u|, N.
    pub warn_axial_n: f64,
    /// Stop limit on the axial part |F_tip . u|, N.
    pub stop_axial_n: f64,
    /// Warn limit on the lateral part |F_tip - (F_tip . u) u|, N.
    pub warn_lateral_n: f64,
    /// Stop limit on the lateral part |F_tip - (F_tip . u) u|, N.
    pub stop_lateral_n: f64,
}

impl ForceLimits {
    /// The default limits, the one place they are written (the
    /// configuration's `[guard]` defaults and [`GuardLimits::EXAMPLE`]):
    /// total 10/15 N, axial 8/12 N, lateral 6/10 N.
    pub const DEFAULT: ForceLimits = ForceLimits {
        warn_total_n: 10.0,
        stop_total_n: 15.0,
        warn_axial_n: 8.0,
        stop_axial_n: 12.0,
        warn_lateral_n: 6.0,
        stop_lateral_n: 10.0,
    };

    /// The six limits' names, in the order of [`ForceLimits::to_array`]
    /// (the wire's): (warn, stop) for total, axial, lateral. They are the
    /// keys of the configuration's `[guard]`, the fields of `sarctl`'s
    /// JSON, and (without `_n`, `-` for `_`) its options.
    pub const NAMES: [&'static str; 6] = [
        "warn_total_n",
        "stop_total_n",
        "warn_axial_n",
        "stop_axial_n",
        "warn_lateral_n",
        "stop_lateral_n",
    ];

    /// The names of the (warn, stop) limits of each part, in
    /// [`ForcePart::ALL`] order (from [`ForceLimits::NAMES`]).
    pub const fn pair_names() -> [(&'static str, &'static str); 3] {
        let [wt, st, wa, sa, wl, sl] = Self::NAMES;
        [(wt, st), (wa, sa), (wl, sl)]
    }

    /// In the order (warn, stop) total, axial, lateral (the wire's order,
    /// [`ForceLimits::NAMES`]).
    pub fn to_array(&self) -> [f64; 6] {
        let Self {
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        } = *self;
        [
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        ]
    }

    /// From (warn, stop) total, axial, lateral (the order of
    /// [`ForceLimits::to_array`]).
    pub fn from_array(v: [f64; 6]) -> Self {
        let [
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        ] = v;
        Self {
            warn_total_n,
            stop_total_n,
            warn_axial_n,
            stop_axial_n,
            warn_lateral_n,
            stop_lateral_n,
        }
    }

    /// The warn limits in [`ForcePart::ALL`] order, N.
    pub fn warn_n(&self) -> [f64; 3] {
        [self.warn_total_n, self.warn_axial_n, self.warn_lateral_n]
    }

    /// The stop limits in [`ForcePart::ALL`] order, N.
    pub fn stop_n(&self) -> [f64; 3] {
        [self.stop_total_n, self.stop_axial_n, self.stop_lateral_n]
    }
}

/// As the log and `sarctl limits` print them: `warn/stop total 9/17 N,
/// axial 8/14 N, lateral 3/6 N`.
impl fmt::Display for ForceLimits {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("warn/stop")?;
        let parts = ForcePart::ALL.iter().zip(self.warn_n()).zip(self.stop_n());
        for (i, ((part, warn), stop)) in parts.enumerate() {
            let sep = if i == 0 { " " } else { ", " };
            write!(f, "{sep}{part} {warn}/{stop} N")?;
        }
        Ok(())
    }
}

/// Largest accepted `debounce_samples` (0.2 s at 500 Hz): a larger debounce
/// would in effect disable Stop.
pub const MAX_DEBOUNCE_SAMPLES: u32 = 100;

/// Largest accepted `std_margin`.
pub const MAX_STD_MARGIN: f64 = 10.0;

/// Checked guard limits. Exists only if valid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardConfig {
    pub(super) limits: GuardLimits,
    /// Warn limits in [`ForcePart::ALL`] order, N: a cache, derived from
    /// `limits.force` ([`ForceLimits::warn_n`]) whenever it is set.
    pub(super) warn_n: [f64; 3],
    /// Stop limits in [`ForcePart::ALL`] order, N: a cache, derived from
    /// `limits.force` ([`ForceLimits::stop_n`]).
    pub(super) stop_n: [f64; 3],
    /// Warn limits minus the hysteresis, in [`ForcePart::ALL`] order, N: a
    /// cache, derived from `limits` too.
    pub(super) clear_n: [f64; 3],
    /// The largest stop limit a run-time change may set, in
    /// [`ForcePart::ALL`] order, N (default: the configured stop limits, so
    /// that limits can only be lowered).
    ceiling_n: [f64; 3],
    /// In `Retreat`, how far a part's filtered value may rise above the
    /// lowest value it had since the retreat began before the guard stops
    /// again, N ([`GuardConfig::with_retreat_rise_n`]).
    pub(super) retreat_rise_n: f64,
}

/// Default rise allowance in `Retreat`, N: well above the excursions of the
/// filtered tip force's noise (its standard deviation is about 0.1-0.3 N with
/// the HEX-6 and a 5 Hz filter at the nominal pose), so that a still, noisy
/// retreat never stops by itself, and well below any stop limit.
pub const DEFAULT_RETREAT_RISE_N: f64 = 2.0;

fn invalid(field: &'static str, value: f64, why: &'static str) -> SettingError {
    SettingError::Invalid { field, value, why }
}

impl GuardConfig {
    /// Checks the limits: all finite; for each of total, axial and lateral
    /// 0 < warn < stop; 0 <= hysteresis < every warn limit; both maximum ages
    /// > 0; 1 <= debounce <= 100; 0 <= std_margin <= 10.
    pub fn new(limits: GuardLimits) -> Result<Self, SettingError> {
        let force = &limits.force;
        let (warn_n, stop_n) = (force.warn_n(), force.stop_n());
        let names = ForceLimits::pair_names();
        for (((warn_field, stop_field), warn), stop) in names.into_iter().zip(warn_n).zip(stop_n) {
            if !(warn.is_finite() && warn > 0.0) {
                return Err(invalid(warn_field, warn, "must be finite and > 0"));
            }
            if !(stop.is_finite() && stop > warn) {
                return Err(invalid(
                    stop_field,
                    stop,
                    "must be finite and > its warn limit",
                ));
            }
        }
        let h = limits.hysteresis_n;
        let min_warn = force
            .warn_total_n
            .min(force.warn_axial_n)
            .min(force.warn_lateral_n);
        if !(h.is_finite() && h >= 0.0 && h < min_warn) {
            return Err(invalid(
                "hysteresis_n",
                h,
                "must be finite, >= 0 and < every warn limit",
            ));
        }
        if !(1..=MAX_DEBOUNCE_SAMPLES).contains(&limits.debounce_samples) {
            return Err(invalid(
                "debounce_samples",
                f64::from(limits.debounce_samples),
                "must be >= 1 and <= 100",
            ));
        }
        let k = limits.std_margin;
        if !(k.is_finite() && (0.0..=MAX_STD_MARGIN).contains(&k)) {
            return Err(invalid("std_margin", k, "must be finite, >= 0 and <= 10"));
        }
        if limits.max_sensor_age_ns == 0 {
            return Err(invalid("max_sensor_age_ns", 0.0, "must be > 0"));
        }
        if limits.max_joints_age_ns == 0 {
            return Err(invalid("max_joints_age_ns", 0.0, "must be > 0"));
        }
        let clear_n = warn_n.map(|w| w - h);
        Ok(Self {
            limits,
            warn_n,
            stop_n,
            clear_n,
            ceiling_n: stop_n,
            retreat_rise_n: DEFAULT_RETREAT_RISE_N,
        })
    }

    /// Sets the rise allowance of `Retreat` (finite, >= 0, below the smallest
    /// stop limit).
    pub fn with_retreat_rise_n(mut self, rise_n: f64) -> Result<Self, SettingError> {
        let smallest_stop_n = self.stop_n.iter().fold(f64::INFINITY, |a, b| a.min(*b));
        if !(rise_n.is_finite() && rise_n >= 0.0 && rise_n < smallest_stop_n) {
            return Err(invalid(
                "retreat_rise_n",
                rise_n,
                "must be finite, >= 0 and below every stop limit",
            ));
        }
        self.retreat_rise_n = rise_n;
        Ok(self)
    }

    /// The rise allowance of `Retreat`, N.
    pub fn retreat_rise_n(&self) -> f64 {
        self.retreat_rise_n
    }

    /// The checked limits.
    pub fn limits(&self) -> GuardLimits {
        self.limits
    }

    /// The six force limits in use.
    pub fn force_limits(&self) -> ForceLimits {
        self.limits.force
    }

    /// The ceilings of the stop limits (total, axial, lateral), N.
    pub fn ceiling_n(&self) -> [f64; 3] {
        self.ceiling_n
    }

    /// Sets the ceilings of the stop limits that a run-time change may set
    /// (total, axial, lateral), N: each finite and at least the configured
    /// stop limit.
    pub fn with_ceiling(mut self, ceiling_n: [f64; 3]) -> Result<Self, SettingError> {
        let fields = ["max_stop_total_n", "max_stop_axial_n", "max_stop_lateral_n"];
        for ((field, c), stop) in fields.into_iter().zip(ceiling_n).zip(self.stop_n) {
            if !(c.is_finite() && c >= stop) {
                return Err(invalid(
                    field,
                    c,
                    "must be finite and >= the configured stop limit",
                ));
            }
        }
        self.ceiling_n = ceiling_n;
        Ok(self)
    }

    /// This configuration with other force limits, checked as
    /// [`GuardConfig::new`] checks them and each stop limit at most its
    /// ceiling; the other settings (hysteresis, debounce, ages, margin) and
    /// the ceilings are kept.
    pub fn with_force_limits(&self, force: &ForceLimits) -> Result<Self, SettingError> {
        let limits = GuardLimits {
            force: *force,
            ..self.limits
        };
        let next = Self::new(limits)?;
        let fields = ForceLimits::pair_names().map(|(_, stop)| stop);
        for ((field, stop), ceiling) in fields.into_iter().zip(next.stop_n).zip(self.ceiling_n) {
            if stop > ceiling {
                return Err(invalid(
                    field,
                    stop,
                    "must be at most its configured ceiling",
                ));
            }
        }
        Ok(Self {
            ceiling_n: self.ceiling_n,
            retreat_rise_n: self.retreat_rise_n,
            ..next
        })
    }

    /// Worst-case time from the first new sample of a force continuously at
    /// or above a stop limit to `Stop`, ns: `debounce_samples` new samples,
    /// each at most `max_sensor_age_ns` after the previous one (a longer gap
    /// is a Fault). Saturates at `u64::MAX`. The sensor's latency comes on top.
    pub fn stop_within_ns(&self) -> u64 {
        u64::from(self.limits.debounce_samples).saturating_mul(self.limits.max_sensor_age_ns)
    }
}

// `GuardLimits` stores its `ForceLimits` first: the same bytes as when
// the six were its own first fields.

sar_snapshot::snap_struct!(GuardLimits {
    force,
    hysteresis_n,
    debounce_samples,
    max_sensor_age_ns,
    max_joints_age_ns,
    std_margin,
});

sar_snapshot::snap_struct!(GuardConfig {
    limits,
    warn_n,
    stop_n,
    clear_n,
    ceiling_n,
    retreat_rise_n,
});

sar_snapshot::snap_struct!(ForceLimits {
    warn_total_n,
    stop_total_n,
    warn_axial_n,
    stop_axial_n,
    warn_lateral_n,
    stop_lateral_n,
});
