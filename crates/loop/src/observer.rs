//! The servo observer (issue 34): the drives as measured, not only as
//! modelled. Per axis a Kalman filter on `[x, v, d]` whose process is the
//! loop's servo model (`sar_hal::servo::ServoAxis`, `x'' = wn^2 (r - x) -
//! 2 zeta wn x' + d`) and whose measurement is the encoders (the cycle's
//! joint sample, quantised to a count). `d` is an acceleration the model
//! does not explain (a servo slower, less damped, delayed or stiffer than
//! the model: what the configuration gets wrong), a random walk at the
//! rate such a servo asks for ([`disturbance_psd`]). The filter always
//! runs; what it hands on depends on the evidence (below), and its
//! acceleration's variance is inflated while its innovations are larger
//! than it expects ([`AxisFilter::accel_var`]: covariance matching). It is
//! predicted on the model's grid
//! (`sar_loop::motion::MODEL_STEP_NS`) and corrected there by each joint
//! sample whose stamp falls in the step ([`AxisFilter::correct`]). Never the
//! encoders differentiated twice alone.
//!
//! What the loop hands the estimator ([`ServoFit::engaged`]): the model's
//! motion as it is while the encoders agree with the model's position to
//! within [`ENGAGE_COUNTS`] counts in motion (then `d` is indistinguishable from 0
//! and the model's acceleration is the best estimate: a plant that matches
//! the model gets exactly today's motion); once an axis's encoder has
//! left the model by more, the filter's (its position and velocity, the
//! model's acceleration plus `d`), with the standard deviation of `d`
//! ([`AxisFilter::accel_var`]), what the observer knows.
//!
//! How far the axes follow the model ([`ServoFit`]): the encoders less the
//! model's position, RMS per axis over the last [`FIT_WINDOW_S`] of motion.
//! Beyond [`FIT_NAME_COUNTS`] counts the servo is named (the model does not
//! describe the drives: run `sarctl identify --servo`), once, and stays
//! named until the drives are released.
//!
//! Fixed-size state; no allocation, no panic; a pure function of the
//! recorded joint samples and the trajectory.

use nalgebra::{Matrix3, Vector3};
use sar_hal::servo::ServoAxis;

/// The standard deviation of the disturbance before any encoder sample,
/// m/s^2.
pub const INITIAL_DISTURBANCE_STD_MPS2: f64 = 0.01;

/// The disturbance's rate, as a fraction of the model's own peak jerk on
/// the hardest acceleration the drives are told (`2 zeta wn a_max`;
/// [`disturbance_psd`]): what a servo of 0.4x the modelled bandwidth up to
/// ideal drives asks of the filter to follow its acceleration.
pub const DISTURBANCE_JERK_FRACTION: f64 = 0.03;

/// The most the acceleration's variance is inflated by the innovations
/// ([`AxisFilter::accel_var`]): its standard deviation at most tripled.
pub const MAX_INFLATION: f64 = 9.0;

/// The weight of a sample in the innovations' average ([`AxisFilter::nis`]):
/// about the last 1 / weight samples (5 ms at 1 kHz).
pub const NIS_WEIGHT: f64 = 0.2;

/// The time over which the disturbance's rate holds, s (a joint sample's
/// period).
pub const DISTURBANCE_CORRELATION_S: f64 = 0.001;

/// Above this speed (the model's, any axis) the axes are moving for the
/// fit, m/s.
pub const FIT_MOVING_MPS: f64 = 1e-3;

/// The encoders' samples kept until the model reaches their stamp.
pub const PENDING: usize = 4;

/// The window of the fit's mean squares, s (an exponential average over
/// the cycles in motion).
pub const FIT_WINDOW_S: f64 = 0.25;

/// The encoders less the model's position, RMS in counts, beyond which the
/// servo is named (a model that describes the drives: the quantisation,
/// 0.29 counts).
pub const FIT_NAME_COUNTS: f64 = 8.0;

/// The fit's window must have seen this much motion before it names
/// anything, s.
pub const FIT_MIN_MOTION_S: f64 = 0.1;

/// An encoder this many counts from the model's position while the axes
/// move engages the observer on its axis ([`ServoFit::engaged`]): the
/// quantisation is half a count; the simulated servo the model describes
/// stays within 2.8 counts of it (the decision recordings of
/// `tests/decisions.rs` on the demo plant).
pub const ENGAGE_COUNTS: f64 = 4.0;

/// The observer's noises (from the configuration: the encoders' count and
/// the planned acceleration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverNoise {
    /// One count of the encoders, m.
    pub count_m: f64,
    /// The encoders' quantisation: one count's variance, `count^2 / 12`,
    /// m^2.
    pub encoder_var_m2: f64,
    /// The disturbance's random walk: the power spectral density of its
    /// rate, (m/s^3)^2 s.
    pub disturbance_psd: f64,
}

impl ObserverNoise {
    /// From one encoder count `count_m`, the servo's natural frequency and
    /// damping and the hardest acceleration the drives are told.
    pub fn new(count_m: f64, wn_rad_s: f64, damping: f64, max_accel_mps2: f64) -> Self {
        Self {
            count_m,
            encoder_var_m2: count_m * count_m / 12.0,
            disturbance_psd: disturbance_psd(wn_rad_s, damping, max_accel_mps2),
        }
    }
}

/// The disturbance's power spectral density, (m/s^3)^2 s:
/// [`DISTURBANCE_JERK_FRACTION`] of the model's own peak jerk on a step of
/// the acceleration, `2 zeta wn a_max`, correlated over
/// [`DISTURBANCE_CORRELATION_S`].
pub fn disturbance_psd(wn_rad_s: f64, damping: f64, max_accel_mps2: f64) -> f64 {
    let jerk = DISTURBANCE_JERK_FRACTION * 2.0 * damping * wn_rad_s * max_accel_mps2;
    jerk * jerk * DISTURBANCE_CORRELATION_S
}

/// One axis's filter on `[x, v, d]`: the axis driven by the model's
/// acceleration plus the disturbance `d`, with their covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisFilter {
    /// The position at the model's last sample, m.
    pub x_m: f64,
    /// The velocity there, m/s.
    pub v_mps: f64,
    /// The acceleration the model misses, m/s^2.
    pub d_mps2: f64,
    /// The covariance of `[x, v, d]` (m, m/s, m/s^2).
    pub p: Matrix3<f64>,
    /// The innovations' normalised square `nu^2 / S`, averaged over the
    /// last samples ([`NIS_WEIGHT`]): about 1 while the filter describes
    /// the axis.
    pub nis: f64,
}

/// How `[x, v, d]` carry over `dt_s` under a held acceleration.
fn transition(dt_s: f64) -> Matrix3<f64> {
    #[rustfmt::skip]
    let f = Matrix3::new(
        1.0, dt_s, 0.5 * dt_s * dt_s,
        0.0, 1.0, dt_s,
        0.0, 0.0, 1.0,
    );
    f
}

impl AxisFilter {
    /// Restarted on the model's `axis`: no disturbance known, the position
    /// one count's quantisation, the velocity as the model has it.
    pub fn new(axis: &ServoAxis, noise: &ObserverNoise) -> Self {
        let d0 = INITIAL_DISTURBANCE_STD_MPS2;
        Self {
            x_m: axis.x_m,
            v_mps: axis.v_mps,
            d_mps2: 0.0,
            p: Matrix3::from_diagonal(&Vector3::new(noise.encoder_var_m2, 0.0, d0 * d0)),
            nis: 1.0,
        }
    }

    /// The axis as observed: its acceleration the model's `model_accel_mps2`
    /// plus the disturbance, held from the last sample.
    pub fn axis(&self, model_accel_mps2: f64) -> ServoAxis {
        ServoAxis {
            x_m: self.x_m,
            v_mps: self.v_mps,
            a_mps2: model_accel_mps2 + self.d_mps2,
        }
    }

    /// The variance of the axis's acceleration (the disturbance's: the
    /// model's own is known), (m/s^2)^2, inflated by the innovations'
    /// averaged normalised square when above 1 (the filter's covariance is
    /// then too optimistic by that much), at most [`MAX_INFLATION`].
    pub fn accel_var(&self) -> f64 {
        self.p.m33.max(0.0) * self.nis.clamp(1.0, MAX_INFLATION)
    }

    /// One model step `dt_s` on, the model's acceleration
    /// `model_accel_mps2` held over it (`ServoAxis::step`), the
    /// disturbance's random walk added to the covariance.
    pub fn predict(&mut self, dt_s: f64, model_accel_mps2: f64, noise: &ObserverNoise) {
        let next = after_s(&self.axis(model_accel_mps2), dt_s);
        (self.x_m, self.v_mps) = (next.x_m, next.v_mps);
        let f = transition(dt_s);
        let mut p = f * self.p * f.transpose();
        p.m33 += noise.disturbance_psd * dt_s;
        self.p = p;
    }

    /// Corrected by an encoder reading `z_m` taken `tau_s` after the last
    /// sample (the model's acceleration `model_accel_mps2` held). Returns the
    /// innovation and its expected variance (m, m^2), `None` when the
    /// update is not finite (the filter unchanged).
    pub fn correct(
        &mut self,
        z_m: f64,
        tau_s: f64,
        model_accel_mps2: f64,
        noise: &ObserverNoise,
    ) -> Option<(f64, f64)> {
        let h = Vector3::new(1.0, tau_s, 0.5 * tau_s * tau_s);
        let predicted = after_s(&self.axis(model_accel_mps2), tau_s).x_m;
        let innovation = z_m - predicted;
        let ph = self.p * h;
        let s = h.dot(&ph) + noise.encoder_var_m2;
        if !(s.is_finite() && s > 0.0 && innovation.is_finite()) {
            return None;
        }
        self.nis += NIS_WEIGHT * (innovation * innovation / s - self.nis);
        let k = ph / s;
        self.x_m += k.x * innovation;
        self.v_mps += k.y * innovation;
        self.d_mps2 += k.z * innovation;
        // P - K (P h)^T, kept symmetric.
        let p = self.p - k * ph.transpose();
        self.p = 0.5 * (p + p.transpose());
        Some((innovation, s))
    }
}

/// Held-acceleration motion over a signed time `dt_s`.
pub fn after_s(a: &ServoAxis, dt_s: f64) -> ServoAxis {
    ServoAxis {
        x_m: a.x_m + a.v_mps * dt_s + 0.5 * a.a_mps2 * dt_s * dt_s,
        v_mps: a.v_mps + a.a_mps2 * dt_s,
        a_mps2: a.a_mps2,
    }
}

/// The encoders' samples not yet reached by the model (their stamps ahead
/// of its last sample), oldest first.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pending {
    /// Each sample's stamp, ns (`len` used).
    pub at_ns: [u64; PENDING],
    /// Each sample, q1, q2, q3, m.
    pub q_m: [[f64; 3]; PENDING],
    /// How many are kept.
    pub len: u8,
    /// The newest stamp taken (a sample seen again is not taken twice), ns.
    pub last_ns: u64,
}

impl Pending {
    /// A joint sample: kept when newer than the last taken (the oldest
    /// dropped when full).
    pub fn push(&mut self, at_ns: u64, q_m: [f64; 3]) {
        if at_ns <= self.last_ns || !q_m.iter().all(|q| q.is_finite()) {
            return;
        }
        self.last_ns = at_ns;
        let n = usize::from(self.len).min(PENDING);
        if n == PENDING {
            self.at_ns.rotate_left(1);
            self.q_m.rotate_left(1);
        }
        let last = n.min(PENDING - 1);
        if let (Some(at), Some(q)) = (self.at_ns.get_mut(last), self.q_m.get_mut(last)) {
            *at = at_ns;
            *q = q_m;
        }
        self.len = u8::try_from(last + 1).unwrap_or(0);
    }

    /// The oldest sample stamped before `before_ns`, removed.
    pub fn pop_before(&mut self, before_ns: u64) -> Option<(u64, [f64; 3])> {
        let n = usize::from(self.len).min(PENDING);
        let at = *self.at_ns.first()?;
        if n == 0 || at >= before_ns {
            return None;
        }
        let q = *self.q_m.first()?;
        self.at_ns.rotate_left(1);
        self.q_m.rotate_left(1);
        self.len = u8::try_from(n - 1).unwrap_or(0);
        Some((at, q))
    }
}

/// How far the axes follow the model: the encoders less the model's
/// position, over the last [`FIT_WINDOW_S`] of motion; which axes the
/// observer is engaged on; whether the servo is named. Kept until the
/// drives are released (the model and its filters restart more often).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoFit {
    /// The encoders less the model's position: mean square per axis, m^2.
    pub follow_ms_m2: [f64; 3],
    /// The acceleration the observer adds to the model's (`d`), per axis,
    /// m/s^2 (its last estimate).
    pub disturbance_mps2: [f64; 3],
    /// Motion seen in the window so far, s (at most the window).
    pub motion_s: f64,
    /// The stamp of the last sample added, ns.
    pub last_ns: u64,
    /// Per axis: the encoder has left the model's position by more than
    /// [`ENGAGE_COUNTS`] while the axes moved: the observer's motion is
    /// handed on, not the model's (latched until the drives are
    /// released).
    pub engaged: [bool; 3],
    /// Named: the axes do not follow the model (latched until the drives
    /// are released).
    pub named: bool,
    /// The stamp of the sample that named it, ns (0: not named).
    pub named_ns: u64,
}

impl ServoFit {
    /// One encoder sample of `axis`, stamped `at_ns`: `deviation_m`, the
    /// encoder less the model's position; `d_mps2`, the observer's
    /// disturbance; `count_m`, one count; the axes moving or not.
    pub fn add(
        &mut self,
        axis: usize,
        deviation_m: f64,
        d_mps2: f64,
        at_ns: u64,
        count_m: f64,
        moving: bool,
    ) {
        if let Some(e) = self.engaged.get_mut(axis) {
            *e |= moving && deviation_m.abs() > ENGAGE_COUNTS * count_m;
        }
        if let Some(d) = self.disturbance_mps2.get_mut(axis) {
            *d = d_mps2;
        }
        let dt_s = if self.last_ns == 0 {
            0.0
        } else {
            (at_ns.saturating_sub(self.last_ns) as f64 * 1e-9).min(FIT_WINDOW_S)
        };
        if axis == 2 {
            self.last_ns = at_ns;
        }
        if !moving {
            return;
        }
        let w = (dt_s / FIT_WINDOW_S).clamp(0.0, 1.0);
        if let Some(f) = self.follow_ms_m2.get_mut(axis) {
            *f += w * (deviation_m * deviation_m - *f);
        }
        if axis == 0 {
            self.motion_s = (self.motion_s + dt_s).min(FIT_WINDOW_S);
        }
        if !self.named
            && self.motion_s >= FIT_MIN_MOTION_S
            && self.follow_rms_m() > FIT_NAME_COUNTS * count_m
        {
            self.named = true;
            self.named_ns = at_ns;
        }
    }

    /// The encoders less the model's position, RMS per axis over the
    /// window, m.
    pub fn follow_rms_per_axis_m(&self) -> [f64; 3] {
        self.follow_ms_m2.map(|m| m.max(0.0).sqrt())
    }

    /// The worst axis's RMS of the encoders less the model's position, m.
    pub fn follow_rms_m(&self) -> f64 {
        self.follow_rms_per_axis_m()
            .iter()
            .fold(0.0, |m: f64, r| m.max(*r))
    }
}

sar_snapshot::snap_struct!(AxisFilter {
    x_m,
    v_mps,
    d_mps2,
    p,
    nis
});
sar_snapshot::snap_struct!(Pending {
    at_ns,
    q_m,
    len,
    last_ns
});
sar_snapshot::snap_struct!(ServoFit {
    follow_ms_m2,
    disturbance_mps2,
    motion_s,
    last_ns,
    engaged,
    named,
    named_ns
});
