//! The servo observer (issue 34): the drives as measured, not only as
//! modelled. Per axis a Kalman filter on `[x, v, d]` whose process is the
//! loop's servo model (`sar_hal::servo::ServoAxis`, `x'' = wn^2 (r - x) -
//! 2 zeta wn x' + d`) and whose measurement is the encoders (the cycle's
//! joint sample, quantised to a count). `d` is an acceleration the model
//! does not explain (a servo slower, less damped, delayed or stiffer than
//! the model: what the configuration gets wrong), a random walk whose rate
//! is set from the servo mismatch the daemon must absorb
//! ([`disturbance_psd`]). The filter is predicted on the model's grid
//! (`sar_loop::motion::MODEL_STEP_NS`) and corrected there by each joint
//! sample whose stamp falls in the step ([`AxisFilter::correct`]); so the
//! acceleration handed to the estimator is the model's plus `d`'s estimate,
//! and its standard deviation is the filter's ([`AxisFilter::accel_var`]),
//! what the observer knows. Never the encoders differentiated twice alone.
//!
//! How far the axes follow the model ([`ServoFit`]): the innovations'
//! mean square against the one the filter expects, over the last
//! [`FIT_WINDOW_S`] of motion. Beyond [`FIT_NAME_RATIO`] the servo is
//! named (the model does not describe the drives: run `sarctl identify
//! --servo`), once, and stays named until the drives are released.
//!
//! Fixed-size state; no allocation, no panic; a pure function of the
//! recorded joint samples and the trajectory.

use nalgebra::{Matrix3, Vector3};
use sar_hal::servo::ServoAxis;

/// The standard deviation of the disturbance before any encoder sample
/// (the model's own acceleration is all the filter knows then), m/s^2.
pub const INITIAL_DISTURBANCE_STD_MPS2: f64 = 0.05;

/// The disturbance's rate, as a fraction of the model's own peak jerk on
/// the planned acceleration (`2 zeta wn a_max`; [`disturbance_psd`]).
pub const DISTURBANCE_JERK_FRACTION: f64 = 0.03;

/// The weight of a sample in the innovations' average ([`AxisFilter::nis`]):
/// about the last 1 / weight samples (10 ms at 1 kHz).
pub const NIS_WEIGHT: f64 = 0.1;

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

/// The innovations' RMS, as a multiple of the one the filter expects,
/// beyond which the servo is named (1 for a model that describes the
/// drives; quantisation alone gives 1).
pub const FIT_NAME_RATIO: f64 = 3.0;

/// The fit's window must have seen this much motion before it names
/// anything, s.
pub const FIT_MIN_MOTION_S: f64 = 0.1;

/// The observer's noises (from the configuration: the encoders' count and
/// the planned acceleration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverNoise {
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
            encoder_var_m2: count_m * count_m / 12.0,
            disturbance_psd: disturbance_psd(wn_rad_s, damping, max_accel_mps2),
        }
    }
}

/// The disturbance's power spectral density, (m/s^3)^2 s: a servo of 0.4x
/// the modelled bandwidth up to ideal drives makes the acceleration the
/// model misses change at up to the model's own peak jerk on a step of the
/// acceleration, `2 zeta wn a_max` (the model's acceleration response
/// starts with that slope); [`DISTURBANCE_JERK_FRACTION`] of it, correlated
/// over [`DISTURBANCE_CORRELATION_S`]: the random walk's increments over
/// that time have the standard deviation of that jerk times that time.
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
    /// last samples ([`NIS_WEIGHT`]): about 1 while the model describes the
    /// axis.
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
    /// model's own is known), (m/s^2)^2.
    pub fn accel_var(&self) -> f64 {
        self.p.m33.max(0.0)
    }

    /// One model step `dt_s` on, the model's acceleration
    /// `model_accel_mps2` held over it (`ServoAxis::step`), the
    /// disturbance's random walk added to the covariance.
    pub fn predict(&mut self, dt_s: f64, model_accel_mps2: f64, noise: &ObserverNoise) {
        let next = self.axis(model_accel_mps2).after_s(dt_s);
        (self.x_m, self.v_mps) = (next.x_m, next.v_mps);
        let f = transition(dt_s);
        let mut p = f * self.p * f.transpose();
        p.m33 += noise.disturbance_psd * dt_s;
        self.p = p;
    }

    /// Corrected by an encoder reading `z_m` taken `tau_s` after the last
    /// sample (the model's acceleration `model_accel_mps2` held). Returns
    /// the innovation and its expected variance (m, m^2), `None` when the
    /// update is not finite (the filter unchanged).
    pub fn correct(
        &mut self,
        z_m: f64,
        tau_s: f64,
        model_accel_mps2: f64,
        noise: &ObserverNoise,
    ) -> Option<(f64, f64)> {
        let h = Vector3::new(1.0, tau_s, 0.5 * tau_s * tau_s);
        let predicted = self.axis(model_accel_mps2).after_s(tau_s).x_m;
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

/// Held-acceleration motion over a signed time.
trait AfterS {
    fn after_s(&self, dt_s: f64) -> ServoAxis;
}

impl AfterS for ServoAxis {
    fn after_s(&self, dt_s: f64) -> ServoAxis {
        ServoAxis {
            x_m: self.x_m + self.v_mps * dt_s + 0.5 * self.a_mps2 * dt_s * dt_s,
            v_mps: self.v_mps + self.a_mps2 * dt_s,
            a_mps2: self.a_mps2,
        }
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

/// How far the axes follow the model: the innovations against what the
/// filter expects, over the last [`FIT_WINDOW_S`] of motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoFit {
    /// The innovations' mean square (the worst axis's), m^2.
    pub innovation_ms_m2: [f64; 3],
    /// The expected mean square, m^2.
    pub expected_ms_m2: [f64; 3],
    /// Motion seen in the window so far, s (at most the window).
    pub motion_s: f64,
    /// The stamp of the last sample added, ns.
    pub last_ns: u64,
    /// Named: the axes do not follow the model (latched until the drives
    /// are released).
    pub named: bool,
}

impl ServoFit {
    /// One innovation `nu_m` of `axis` with its expected variance `s_m2`,
    /// of the sample stamped `at_ns`, the axes moving or not.
    pub fn add(&mut self, axis: usize, nu_m: f64, s_m2: f64, at_ns: u64, moving: bool) {
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
        if let (Some(i), Some(e)) = (
            self.innovation_ms_m2.get_mut(axis),
            self.expected_ms_m2.get_mut(axis),
        ) {
            *i += w * (nu_m * nu_m - *i);
            *e += w * (s_m2 - *e);
        }
        if axis == 0 {
            self.motion_s = (self.motion_s + dt_s).min(FIT_WINDOW_S);
        }
        if self.motion_s >= FIT_MIN_MOTION_S && self.ratio() > FIT_NAME_RATIO {
            self.named = true;
        }
    }

    /// The worst axis's innovation RMS over its expected RMS (0 before any
    /// motion).
    pub fn ratio(&self) -> f64 {
        self.innovation_ms_m2
            .iter()
            .zip(self.expected_ms_m2)
            .fold(
                0.0,
                |m: f64, (i, e)| {
                    if e > 0.0 { m.max((i / e).sqrt()) } else { m }
                },
            )
    }

    /// The worst axis's innovation RMS, m.
    pub fn rms_m(&self) -> f64 {
        self.innovation_ms_m2
            .iter()
            .fold(0.0, |m: f64, i| m.max(i.sqrt()))
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
    innovation_ms_m2,
    expected_ms_m2,
    motion_s,
    last_ns,
    named
});
sar_snapshot::config_struct!(ObserverNoise {
    encoder_var_m2,
    disturbance_psd,
});
