//! The excitation of the dynamic identification run by the loop (issue 26
//! section 3, `sarctl identify --dynamic --live`, [`crate::step::Request::Excite`]):
//! a sine per axis about where the axes rest, faded in and out by a raised
//! cosine so that it starts and ends at rest. The loop computes it
//! analytically each cycle ([`Excitation::at`], no allocation, fixed size)
//! and streams it to the drives one period ahead.
//!
//! A request is judged by [`judge`] before anything moves (issue 33): its
//! parameters finite and in range, each fade at least [`MIN_FADE_PERIODS`]
//! of the loop's periods, each axis's peak speed, acceleration and jerk over
//! the whole faded motion ([`unit_peaks`]: an upper bound, the fades
//! included, so that no client can make the loop stream a step) within
//! `[identify] excitation_max_speed_mps`, `excitation_max_accel_mps2`,
//! `excitation_max_jerk_mps3` (with [`PEAK_ALLOWANCE`]) and the peak speed
//! within the drives' `[axes] max_speed_mps`, and the sweep (`centre +- A`:
//! the fade never exceeds 1) within the travel. `sarctl identify --dynamic`
//! scales its amplitudes with the same [`unit_peaks`], so that what it plans
//! the loop accepts. The peaks are checked again every cycle
//! ([`Excitation::within_limits`]): above the limits the excitation is
//! braked.
//!
//! The estimator is handed its motion as any streamed motion's
//! ([`crate::motion`]: the servo model follows the streamed set points);
//! with ideal drives (no servo model) its analytic velocity and
//! acceleration ([`Excitation::carriage_motion`]).

use crate::motion::{ACCEL_STD_FLOOR_MPS2, ACCEL_STD_FRACTION};
use sar_estimator::Vec3;
use sar_estimator::motion::CarriageMotion;
use sar_hal::motion::AxisState;
use sar_kinematics::Shown;

/// Why an excitation is refused ([`judge`]); its `Display` is the reply's
/// detail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExciteRefusal {
    /// A parameter out of range.
    Bad {
        /// 1, 2 or 3 (q1, q2, q3); 0 for the duration and the fade.
        axis: u8,
        /// The parameter.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A peak speed, acceleration or jerk above a limit.
    AboveLimit {
        /// 1, 2 or 3 (q1, q2, q3).
        axis: u8,
        /// The key, with its section.
        key: &'static str,
        /// The unit: m/s, m/s^2 or m/s^3.
        unit: &'static str,
        /// The peak, m/s, m/s^2 or m/s^3.
        value: f64,
        /// The key's value.
        limit: f64,
    },
    /// The sweep leaves an axis's travel.
    OutsideTravel {
        /// 1, 2 or 3 (q1, q2, q3).
        axis: u8,
        /// The axis position the sweep reaches, m.
        value_m: f64,
        /// The travel, m.
        min_m: f64,
        /// The travel, m.
        max_m: f64,
    },
}

impl core::fmt::Display for ExciteRefusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Bad { axis, field, value } => {
                write!(f, "the excitation's {field}")?;
                if *axis != 0 {
                    write!(f, " of q{axis}")?;
                }
                write!(
                    f,
                    " = {} is out of range (amplitude >= 0, frequency > 0, {} periods of the \
                     loop <= fade, 2 fade <= duration <= {} s)",
                    Shown(*value),
                    MIN_FADE_PERIODS,
                    Shown(MAX_DURATION_S)
                )
            }
            Self::AboveLimit {
                axis,
                key,
                unit,
                value,
                limit,
            } => write!(
                f,
                "the excitation of q{axis} peaks at {} {unit} (its fades included), above {key} = {} {unit}",
                Shown(*value),
                Shown(*limit)
            ),
            Self::OutsideTravel {
                axis,
                value_m,
                min_m,
                max_m,
            } => write!(
                f,
                "the excitation of q{axis} reaches {} m, outside its travel {}..{} m",
                Shown(*value_m),
                Shown(*min_m),
                Shown(*max_m)
            ),
        }
    }
}

/// The loop's limits of an excitation (`[identify]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteLimits {
    /// The largest joint speed, m/s.
    pub max_speed_mps: f64,
    /// The largest joint acceleration, m/s^2.
    pub max_accel_mps2: f64,
    /// The largest joint jerk, m/s^3.
    pub max_jerk_mps3: f64,
    /// The drives' speed limit (`[axes] max_speed_mps`: a streamed set
    /// point further than this over a period is refused by them), m/s.
    pub axes_max_speed_mps: f64,
    /// The loop's period, ns: a fade is at least [`MIN_FADE_PERIODS`] of
    /// them.
    pub period_ns: u64,
}

/// The shortest fade, in the loop's periods: the fade is the excitation's
/// own ramp from rest; shorter, it is a step however small the limits
/// judge it (the peaks below judge how fast it may be).
pub const MIN_FADE_PERIODS: u32 = 100;

/// The fade's phases [`unit_peaks`] evaluates the envelope at (0..=pi).
const FADE_SAMPLES: u32 = 1024;

/// The peak speed, acceleration and jerk of one axis of unit amplitude at
/// `freq_hz` faded in and out over `fade_s` (the raised cosine of
/// [`fade`]), over the whole excitation: an upper bound, exact where the
/// sine runs through its phases within the fade. With `x = e(t) sin(w t)`,
/// each derivative is `alpha sin + beta cos` of the fade's value and
/// derivatives, so at most `sqrt(alpha^2 + beta^2)`, taken over the fade's
/// phase (the fade out mirrors the fade in: the same magnitudes) and the
/// middle part (`w`, `w^2`, `w^3`). No allocation; [`FADE_SAMPLES`] phases.
pub fn unit_peaks(freq_hz: f64, fade_s: f64) -> [f64; 3] {
    let w = core::f64::consts::TAU * freq_hz;
    let k = core::f64::consts::PI / fade_s;
    let hyp = |a: f64, b: f64| (a * a + b * b).sqrt();
    let mut peaks = [w, w * w, w * w * w];
    for i in 0..=FADE_SAMPLES {
        let phase = core::f64::consts::PI * f64::from(i) / f64::from(FADE_SAMPLES);
        let (sin, cos) = phase.sin_cos();
        let e = 0.5 * (1.0 - cos);
        let e1 = 0.5 * k * sin;
        let e2 = 0.5 * k * k * cos;
        let e3 = -0.5 * k * k * k * sin;
        let now = [
            hyp(e1, e * w),
            hyp(e2 - e * w * w, 2.0 * e1 * w),
            hyp(e3 - 3.0 * e1 * w * w, 3.0 * e2 * w - e * w * w * w),
        ];
        for (p, n) in peaks.iter_mut().zip(now) {
            *p = p.max(n);
        }
    }
    peaks
}

/// The relative allowance over the limits: for the rounding of a planner
/// that scales its amplitudes to the limits by [`unit_peaks`], whose
/// envelope found on [`FADE_SAMPLES`] phases is below its true peak by far
/// less (the phase step is 0.003 rad).
pub const PEAK_ALLOWANCE: f64 = 1e-3;

/// The longest excitation a request may ask for, s.
pub const MAX_DURATION_S: f64 = 600.0;

/// An excitation as requested: the command table's (`sar_msgs::command`).
pub use sar_msgs::command::ExciteRequest;

/// An excitation under way: the request, where the axes rested when it
/// started (its centre) and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excitation {
    /// The request.
    pub request: ExciteRequest,
    /// The centre, q1, q2, q3, m.
    pub centre_m: [f64; 3],
    /// The start, ns (the loop's clock).
    pub start_ns: u64,
}

/// The raised-cosine fade's value and its first and second time
/// derivatives at `t_s` into an excitation of `duration_s`.
pub fn fade(t_s: f64, duration_s: f64, fade_s: f64) -> (f64, f64, f64) {
    let k = core::f64::consts::PI / fade_s;
    let rise = |x: f64| {
        let (s, c) = (k * x).sin_cos();
        (0.5 * (1.0 - c), 0.5 * k * s, 0.5 * k * k * c)
    };
    if t_s <= 0.0 || t_s >= duration_s {
        (0.0, 0.0, 0.0)
    } else if t_s < fade_s {
        rise(t_s)
    } else if t_s > duration_s - fade_s {
        let (e, e1, e2) = rise(duration_s - t_s);
        (e, -e1, e2)
    } else {
        (1.0, 0.0, 0.0)
    }
}

/// One axis of unit amplitude at `t_s`: its offset, speed and
/// acceleration (the faded sine `e(t) sin(w t)` and its derivatives).
pub fn unit_axis(t_s: f64, freq_hz: f64, duration_s: f64, fade_s: f64) -> (f64, f64, f64) {
    let w = 2.0 * core::f64::consts::PI * freq_hz;
    let (s, c) = (w * t_s).sin_cos();
    let (e, e1, e2) = fade(t_s, duration_s, fade_s);
    (
        e * s,
        e1 * s + e * w * c,
        e2 * s + 2.0 * e1 * w * c - e * w * w * s,
    )
}

impl Excitation {
    /// The end, ns (saturating).
    pub fn end_ns(&self) -> u64 {
        // Saturating float-to-int; the duration was checked finite.
        self.start_ns
            .saturating_add((self.request.duration_s * 1e9).ceil() as u64)
    }

    /// Each axis's position and velocity at `t_ns` (the centre at rest
    /// before the start and after the end), and its acceleration, m/s^2.
    pub fn at(&self, t_ns: u64) -> ([AxisState; 3], [f64; 3]) {
        let t_s = t_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        let r = &self.request;
        let mut states = [AxisState {
            x_m: 0.0,
            v_mps: 0.0,
        }; 3];
        let mut accel_mps2 = [0.0; 3];
        for (i, (state, accel)) in states.iter_mut().zip(accel_mps2.iter_mut()).enumerate() {
            let (a_m, f_hz, c_m) = (
                r.amplitude_m.get(i).copied().unwrap_or(0.0),
                r.freq_hz.get(i).copied().unwrap_or(0.0),
                self.centre_m.get(i).copied().unwrap_or(0.0),
            );
            let (x, v, a) = unit_axis(t_s, f_hz, r.duration_s, r.fade_s);
            *state = AxisState {
                x_m: c_m + a_m * x,
                v_mps: a_m * v,
            };
            *accel = a_m * a;
        }
        (states, accel_mps2)
    }

    /// The carriage's motion at `t_ns` as commanded (A' = (q3', q2', q1')),
    /// with the standard deviation of [`crate::motion`]'s known motions: for
    /// ideal drives, which follow the streamed set points exactly.
    pub fn carriage_motion(&self, t_ns: u64) -> CarriageMotion {
        let ([q1, q2, q3], [a1, a2, a3]) = self.at(t_ns);
        let accel_mps2 = Vec3::new(a3, a2, a1);
        let velocity_mps = Vec3::new(q3.v_mps, q2.v_mps, q1.v_mps);
        let moving = velocity_mps.norm() > 0.0 || accel_mps2.norm() > 0.0;
        let floor = if moving { ACCEL_STD_FLOOR_MPS2 } else { 0.0 };
        CarriageMotion {
            velocity_mps,
            accel_mps2,
            accel_std_mps2: ACCEL_STD_FRACTION * accel_mps2.norm() + floor,
        }
    }

    /// Whether the excitation at `t_ns` is within the limits (with
    /// [`PEAK_ALLOWANCE`]).
    pub fn within_limits(&self, t_ns: u64, limits: &ExciteLimits) -> bool {
        let (states, accel_mps2) = self.at(t_ns);
        let k = 1.0 + PEAK_ALLOWANCE;
        let max_speed_mps = limits.max_speed_mps.min(limits.axes_max_speed_mps);
        states.iter().all(|s| s.v_mps.abs() <= k * max_speed_mps)
            && accel_mps2
                .iter()
                .all(|a| a.abs() <= k * limits.max_accel_mps2)
    }
}

/// Judges a request about `centre_m` (see the module's doc): the first
/// parameter out of range or limit exceeded is the refusal.
pub fn judge(
    request: &ExciteRequest,
    centre_m: &[f64; 3],
    travel_m: &[(f64, f64); 3],
    limits: &ExciteLimits,
) -> Result<(), ExciteRefusal> {
    let (d, f) = (request.duration_s, request.fade_s);
    let bad = |field, value| ExciteRefusal::Bad {
        axis: 0,
        field,
        value,
    };
    if !(d.is_finite() && d > 0.0 && d <= MAX_DURATION_S) {
        return Err(bad("duration_s", d));
    }
    let min_fade_s = f64::from(MIN_FADE_PERIODS) * limits.period_ns as f64 * 1e-9;
    if !(f.is_finite() && f >= min_fade_s && 2.0 * f <= d) {
        return Err(bad("fade_s", f));
    }
    for (i, (((&a_m, &f_hz), &c_m), &travel)) in request
        .amplitude_m
        .iter()
        .zip(&request.freq_hz)
        .zip(centre_m)
        .zip(travel_m)
        .enumerate()
    {
        let axis = u8::try_from(i + 1).unwrap_or(0);
        judge_axis(axis, (a_m, f_hz, c_m, f), travel, limits)?;
    }
    Ok(())
}

/// One axis of [`judge`]: its amplitude and frequency in range, its peaks
/// (the fades included) within the limits, its sweep within the travel.
fn judge_axis(
    axis: u8,
    (a_m, f_hz, c_m, fade_s): (f64, f64, f64, f64),
    (lo, hi): (f64, f64),
    limits: &ExciteLimits,
) -> Result<(), ExciteRefusal> {
    let bad = |field, value| ExciteRefusal::Bad { axis, field, value };
    if !(a_m.is_finite() && a_m >= 0.0) {
        return Err(bad("amplitude_m", a_m));
    }
    if !(f_hz.is_finite() && f_hz > 0.0) {
        return Err(bad("freq_hz", f_hz));
    }
    let [speed, accel, jerk] = unit_peaks(f_hz, fade_s);
    let k = 1.0 + PEAK_ALLOWANCE;
    let above = |value: f64, limit: f64, key: &'static str| {
        let unit = if key.contains("accel") {
            "m/s^2"
        } else if key.contains("jerk") {
            "m/s^3"
        } else {
            "m/s"
        };
        (value > k * limit).then_some(ExciteRefusal::AboveLimit {
            axis,
            key,
            unit,
            value,
            limit,
        })
    };
    let speed_mps = a_m * speed;
    let speed_key = "[identify] excitation_max_speed_mps";
    let accel_key = "[identify] excitation_max_accel_mps2";
    let jerk_key = "[identify] excitation_max_jerk_mps3";
    if let Some(e) = above(speed_mps, limits.max_speed_mps, speed_key)
        .or_else(|| above(speed_mps, limits.axes_max_speed_mps, "[axes] max_speed_mps"))
        .or_else(|| above(a_m * accel, limits.max_accel_mps2, accel_key))
        .or_else(|| above(a_m * jerk, limits.max_jerk_mps3, jerk_key))
    {
        return Err(e);
    }
    for value_m in [c_m - a_m, c_m + a_m] {
        if !(value_m >= lo && value_m <= hi) {
            return Err(ExciteRefusal::OutsideTravel {
                axis,
                value_m,
                min_m: lo,
                max_m: hi,
            });
        }
    }
    Ok(())
}

sar_snapshot::snap_struct!(Excitation {
    request,
    centre_m,
    start_ns,
});
sar_snapshot::config_struct!(ExciteLimits {
    max_speed_mps,
    max_accel_mps2,
    max_jerk_mps3,
    axes_max_speed_mps,
    period_ns,
});
