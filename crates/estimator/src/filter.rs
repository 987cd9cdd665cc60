//! A causal low-pass of the tip force, beside the unfiltered estimate: a
//! second-order Butterworth per axis (bilinear transform with the cutoff
//! prewarped), with its own propagated standard deviation.
//!
//! The guard keeps acting on the unfiltered per-cycle estimate; this filter is
//! for display, recording and slow trends (a smoothed force for the operator).
//!
//! Why a Butterworth and not a Kalman filter on a random-walk force model: the
//! Butterworth's frequency response is fixed by one number the user can reason
//! about (the cutoff: DC gain 1, -3 dB exactly at the cutoff, maximally flat
//! below it), and so is its lag (the group delay at low frequency, see
//! [`TipFilter::group_delay_s`]). A random-walk Kalman filter's bandwidth is set
//! by the ratio of a process noise nobody measures to the measurement noise, and
//! since the tip force's deviation changes with the pose (it grows as the support
//! nears the tip) the bandwidth and the lag would change with the pose too.
//!
//! The standard deviation is propagated exactly through the filter's state
//! (a 2x2 covariance per axis, recursively), under the assumption that the
//! noise of successive samples is independent (white; the HEX-6's noise is, at
//! its 500 Hz rate) and that each sample's deviation is the one given with it.
//! At a steady input deviation `sigma` it tends to `sqrt(G) sigma`, where
//! `G = sum h[k]^2` is the filter's white-noise variance gain
//! ([`TipFilter::variance_gain`], computed in closed form at construction from
//! the discrete Lyapunov equation). Right after a (re)start the output is the
//! first sample itself and carries its whole deviation, which then decays to
//! the steady value. A deviation says nothing of the lag: a moving force is
//! followed late by about the group delay, whatever the noise.
//!
//! State is reset by any invalid input (a NaN, an infinity, a negative
//! deviation): the call is refused with a typed error, and the next valid
//! sample restarts the filter at that sample (its state set to the steady state
//! of a constant input equal to it), so no stale state makes a transient.

use crate::Vec3;
use nalgebra::ComplexField;

/// The longest counter gap [`TipFilter::update_counted`] steps over with the
/// new sample held (64 samples: 128 ms at 500 Hz, beyond any accepted input
/// age); a longer one restarts the filter.
pub const MAX_HELD_SAMPLES: u32 = 64;

/// Settings of the tip-force low-pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterConfig {
    /// The -3 dB cutoff, Hz: finite, > 0 and below the Nyquist frequency
    /// `0.5 / sample_period_s`.
    pub cutoff_hz: f64,
    /// The period of the sensor samples the filter is stepped with, s: finite
    /// and > 0 (0.002 s for the HEX-6 at 500 Hz). The filter must be stepped once
    /// per new sample, not once per control cycle.
    pub sample_period_s: f64,
}

/// Why a filter setting or input was refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FilterError {
    /// The cutoff is NaN, infinite or not > 0.
    #[error("cutoff_hz must be finite and > 0, got {cutoff_hz}")]
    InvalidCutoff {
        /// The value given.
        cutoff_hz: f64,
    },
    /// The sample period is NaN, infinite or not > 0.
    #[error("sample_period_s must be finite and > 0, got {sample_period_s}")]
    InvalidSamplePeriod {
        /// The value given.
        sample_period_s: f64,
    },
    /// The cutoff is not below the Nyquist frequency of the sample period.
    #[error("cutoff_hz = {cutoff_hz} is not below the Nyquist frequency {nyquist_hz} Hz")]
    CutoffAboveNyquist {
        /// The value given.
        cutoff_hz: f64,
        /// `0.5 / sample_period_s`.
        nyquist_hz: f64,
    },
    /// The filter's coefficients are not a stable, finite filter (a cutoff so
    /// close to 0 or to Nyquist that the arithmetic breaks down).
    #[error("cutoff_hz = {cutoff_hz} gives no usable filter (variance gain {variance_gain})")]
    Degenerate {
        /// The value given.
        cutoff_hz: f64,
        /// The variance gain computed.
        variance_gain: f64,
    },
    /// An input force component is NaN or infinite. The filter was reset.
    #[error("force_n[{axis}] = {value} is not finite: filter reset")]
    NonFiniteForce {
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// The value given.
        value: f64,
    },
    /// The output overflowed (an input too large for the arithmetic). The
    /// filter was reset.
    #[error("filtered force_n[{axis}] = {value} is not finite: filter reset")]
    Overflow {
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// The value computed.
        value: f64,
    },
    /// An input standard deviation is NaN, infinite or negative. The filter
    /// was reset.
    #[error("std_n[{axis}] = {value} is not a finite value >= 0: filter reset")]
    InvalidStd {
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// The value given.
        value: f64,
    },
}

/// The filtered tip force and its standard deviation, per axis of {0}, N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filtered {
    /// Low-passed F_tip, {0}, N.
    pub force_n: Vec3,
    /// Its standard deviation per axis from the input noise alone, N (not the
    /// lag; see the module documentation).
    pub std_n: Vec3,
}

/// Second-order coefficients in the state-space form of the transposed direct
/// form II: `y = b0 x + s1; s1' = k1 x - a1 s1 + s2; s2' = k2 x - a2 s1`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Biquad {
    b0: f64,
    a1: f64,
    a2: f64,
    /// Input weights into the two states: `b1 - a1 b0`, `b2 - a2 b0`.
    k1: f64,
    k2: f64,
    /// Steady state per unit constant input: s1 = 1 - b0, s2 = b2 - a2.
    ss1: f64,
    ss2: f64,
}

/// The filter's running state, per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
struct State {
    s1: Vec3,
    s2: Vec3,
    /// Covariance of the states (p11, p12, p22), N^2.
    p11: Vec3,
    p12: Vec3,
    p22: Vec3,
    last: Filtered,
    /// The counter of the last sample stepped with `update_counted`.
    counter: Option<u32>,
}

/// A causal second-order Butterworth low-pass of the tip force, per axis of
/// {0}, with its propagated standard deviation. Fixed-size; no allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipFilter {
    config: FilterConfig,
    coef: Biquad,
    variance_gain: f64,
    state: Option<State>,
}

impl TipFilter {
    /// Builds the filter. The cutoff must be finite, > 0 and below Nyquist; the
    /// sample period finite and > 0.
    pub fn new(config: FilterConfig) -> Result<Self, FilterError> {
        let FilterConfig {
            cutoff_hz,
            sample_period_s,
        } = config;
        if !(sample_period_s.is_finite() && sample_period_s > 0.0) {
            return Err(FilterError::InvalidSamplePeriod { sample_period_s });
        }
        if !(cutoff_hz.is_finite() && cutoff_hz > 0.0) {
            return Err(FilterError::InvalidCutoff { cutoff_hz });
        }
        let nyquist_hz = 0.5 / sample_period_s;
        if cutoff_hz >= nyquist_hz || !nyquist_hz.is_finite() {
            return Err(FilterError::CutoffAboveNyquist {
                cutoff_hz,
                nyquist_hz,
            });
        }
        // Bilinear transform of 1 / (s^2 + sqrt2 s + 1) with the cutoff
        // prewarped: K = tan(pi fc T).
        let k = ComplexField::tan(core::f64::consts::PI * cutoff_hz * sample_period_s);
        let sqrt2 = core::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + sqrt2 * k + k * k);
        let b0 = k * k * norm;
        let (b1, b2) = (2.0 * b0, b0);
        let a1 = 2.0 * (k * k - 1.0) * norm;
        let a2 = (1.0 - sqrt2 * k + k * k) * norm;
        let coef = Biquad {
            b0,
            a1,
            a2,
            k1: b1 - a1 * b0,
            k2: b2 - a2 * b0,
            ss1: 1.0 - b0,
            ss2: b2 - a2,
        };
        let variance_gain = Self::lyapunov_gain(&coef);
        // Stability (|a2| < 1, |a1| < 1 + a2) and a finite gain in (0, 1].
        let stable = a2.abs() < 1.0 && a1.abs() < 1.0 + a2;
        if !(stable && variance_gain.is_finite() && variance_gain > 0.0 && variance_gain <= 1.0) {
            return Err(FilterError::Degenerate {
                cutoff_hz,
                variance_gain,
            });
        }
        Ok(Self {
            config,
            coef,
            variance_gain,
            state: None,
        })
    }

    /// `G = sum h[k]^2` in closed form: the steady covariance P of the state
    /// solves `P = A P A^T + k k^T` (discrete Lyapunov, 3 unknowns), and
    /// `G = p11 + b0^2`.
    fn lyapunov_gain(c: &Biquad) -> f64 {
        let (a1, a2, k1, k2) = (c.a1, c.a2, c.k1, c.k2);
        // p12 = (a1 a2 p11 + k1 k2) / (1 + a2); p22 = a2^2 p11 + k2^2; and
        // p11 = a1^2 p11 - 2 a1 p12 + p22 + k1^2.
        let lhs = 1.0 - a1 * a1 - a2 * a2 + 2.0 * a1 * a1 * a2 / (1.0 + a2);
        let rhs = k1 * k1 + k2 * k2 - 2.0 * a1 * k1 * k2 / (1.0 + a2);
        rhs / lhs + c.b0 * c.b0
    }

    /// The configuration it was built with.
    pub fn config(&self) -> FilterConfig {
        self.config
    }

    /// The white-noise variance gain `G = sum h[k]^2`: at a steady input
    /// deviation `sigma` the output's deviation tends to `sqrt(G) sigma`.
    pub fn variance_gain(&self) -> f64 {
        self.variance_gain
    }

    /// The group delay at low frequency, s: the lag with which the output
    /// follows a slowly varying force. For H(z) = B(z) / A(z) at z = 1 it is
    /// `sum k b_k / sum b_k - sum k a_k / sum a_k` samples; about
    /// `sqrt(2) / (2 pi cutoff_hz)` when the cutoff is well below Nyquist.
    pub fn group_delay_s(&self) -> f64 {
        let Biquad { a1, a2, .. } = self.coef;
        let samples = 1.0 - (a1 + 2.0 * a2) / (1.0 + a1 + a2);
        samples * self.config.sample_period_s
    }

    /// The coefficients `([b0, b1, b2], [1, a1, a2])` of each axis' filter
    /// `H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)`.
    pub fn coefficients(&self) -> ([f64; 3], [f64; 3]) {
        let Biquad { b0, a1, a2, .. } = self.coef;
        ([b0, 2.0 * b0, b0], [1.0, a1, a2])
    }

    /// Forgets the state: the next valid sample restarts the filter at itself.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Whether the filter holds a state (it has had a valid sample since the
    /// last reset).
    pub fn is_running(&self) -> bool {
        self.state.is_some()
    }

    /// The last output, if the filter is running.
    pub fn last(&self) -> Option<Filtered> {
        self.state.map(|s| s.last)
    }

    /// Steps the filter with one NEW sample: the unfiltered tip force and its
    /// per-axis standard deviation (finite, >= 0). Call once per new sensor
    /// sample, never again for a repeated one (see
    /// [`TipFilter::update_counted`]). An invalid input is refused and resets
    /// the filter.
    pub fn update(&mut self, force_n: &Vec3, std_n: &Vec3) -> Result<Filtered, FilterError> {
        self.step(force_n, std_n, None)
    }

    /// As [`TipFilter::update`], for a loop faster than the sensor: a sample
    /// whose `counter` equals the last one stepped is a repeat, and the last
    /// output is returned without stepping. A gap in the counter (samples the
    /// loop did not see: a late cycle, or lost) of `k` samples, at most
    /// [`MAX_HELD_SAMPLES`], is stepped `k` times with this sample held, each
    /// step with its deviation times `sqrt(k)`: the filter keeps its time
    /// scale and its state (no restart, no jump), and the deviation stays an
    /// upper bound (the held steps' noise is one sample's, whose variance
    /// through the `k` steps is `sigma^2 (sum h)^2 <= k sigma^2 sum h^2`).
    /// A longer gap (or a counter that went back) restarts the filter at
    /// this sample. The caller's plausibility checks judge gaps.
    pub fn update_counted(
        &mut self,
        counter: u32,
        force_n: &Vec3,
        std_n: &Vec3,
    ) -> Result<Filtered, FilterError> {
        let gap = match &self.state {
            Some(state) if state.counter == Some(counter) => return Ok(state.last),
            Some(State {
                counter: Some(last),
                ..
            }) => counter.wrapping_sub(*last),
            _ => 1,
        };
        if gap <= 1 {
            return self.step(force_n, std_n, Some(counter));
        }
        if gap > MAX_HELD_SAMPLES {
            self.reset();
            return self.step(force_n, std_n, Some(counter));
        }
        let held_std_n = std_n * ComplexField::sqrt(f64::from(gap));
        let mut out = self.step(force_n, &held_std_n, Some(counter))?;
        for _ in 1..gap {
            out = self.step(force_n, &held_std_n, Some(counter))?;
        }
        Ok(out)
    }

    /// One step: the sample checked (an invalid one resets the filter), the
    /// next state computed from it, and stored only if its output is
    /// finite (else the filter resets and the overflow is named).
    fn step(
        &mut self,
        force_n: &Vec3,
        std_n: &Vec3,
        counter: Option<u32>,
    ) -> Result<Filtered, FilterError> {
        if let Err(e) = Self::check(force_n, std_n) {
            self.reset();
            return Err(e);
        }
        // A held state was stored only with a finite output (the overflow
        // check below): what the next output builds on.
        debug_assert!(
            self.state.is_none_or(|s| s
                .last
                .force_n
                .iter()
                .chain(s.last.std_n.iter())
                .all(|v| v.is_finite())),
            "a stored filter state with a non-finite output"
        );
        let var_n2 = std_n.component_mul(std_n);
        let state = match self.state {
            None => self.coef.restart(force_n, std_n, &var_n2, counter),
            Some(s) => self.coef.advance(&s, force_n, &var_n2, counter),
        };
        let out = state.last;
        let bad = out
            .force_n
            .iter()
            .chain(out.std_n.iter())
            .enumerate()
            .find(|(_, v)| !v.is_finite());
        if let Some((i, &value)) = bad {
            self.reset();
            return Err(FilterError::Overflow { axis: i % 3, value });
        }
        self.state = Some(state);
        Ok(out)
    }

    fn check(force_n: &Vec3, std_n: &Vec3) -> Result<(), FilterError> {
        for (axis, (&f, &s)) in force_n.iter().zip(std_n.iter()).enumerate() {
            if !f.is_finite() {
                return Err(FilterError::NonFiniteForce { axis, value: f });
            }
            if !(s.is_finite() && s >= 0.0) {
                return Err(FilterError::InvalidStd { axis, value: s });
            }
        }
        Ok(())
    }
}

impl Biquad {
    /// The state restarted at this sample: the steady state of a constant
    /// input equal to it, the whole noise of this one sample in the state.
    fn restart(&self, force_n: &Vec3, std_n: &Vec3, var_n2: &Vec3, counter: Option<u32>) -> State {
        let c = self;
        let out = Filtered {
            force_n: *force_n,
            std_n: *std_n,
        };
        State {
            s1: force_n * c.ss1,
            s2: force_n * c.ss2,
            p11: var_n2 * (c.ss1 * c.ss1),
            p12: var_n2 * (c.ss1 * c.ss2),
            p22: var_n2 * (c.ss2 * c.ss2),
            last: out,
            counter,
        }
    }

    /// The state `s` advanced by one sample (transposed direct form II per
    /// axis), with the output's variance propagated beside it.
    fn advance(&self, s: &State, force_n: &Vec3, var_n2: &Vec3, counter: Option<u32>) -> State {
        let c = self;
        // y = b0 x + s1; s1' = k1 x - a1 s1 + s2; s2' = k2 x - a2 s1.
        let y = force_n * c.b0 + s.s1;
        let s1 = force_n * c.k1 - s.s1 * c.a1 + s.s2;
        let s2 = force_n * c.k2 - s.s1 * c.a2;
        // var y = p11 + b0^2 var x (the state holds only past samples,
        // independent of this one); P' = A P A^T + k k^T var x with
        // A = [[-a1, 1], [-a2, 0]].
        let var_y = s.p11 + var_n2 * (c.b0 * c.b0);
        let p11 = s.p11 * (c.a1 * c.a1) - s.p12 * (2.0 * c.a1) + s.p22 + var_n2 * (c.k1 * c.k1);
        let p12 = s.p11 * (c.a1 * c.a2) - s.p12 * c.a2 + var_n2 * (c.k1 * c.k2);
        let p22 = s.p11 * (c.a2 * c.a2) + var_n2 * (c.k2 * c.k2);
        State {
            s1,
            s2,
            p11,
            p12,
            p22,
            last: Filtered {
                force_n: y,
                std_n: var_y.map(|v| ComplexField::sqrt(v.max(0.0))),
            },
            counter,
        }
    }
}

// Snapshots (issue 17): the running state is stored; the settings and the
// coefficients come from the configuration.
sar_snapshot::snap_struct!(Filtered { force_n, std_n });
sar_snapshot::snap_struct!(State {
    s1,
    s2,
    p11,
    p12,
    p22,
    last,
    counter,
});
sar_snapshot::config_struct!(FilterConfig {
    cutoff_hz,
    sample_period_s
});
sar_snapshot::config_struct!(Biquad {
    b0,
    a1,
    a2,
    k1,
    k2,
    ss1,
    ss2
});
sar_snapshot::snap_state!(TipFilter {
    state: [state],
    nested: [],
    config: [config, coef, variance_gain],
    output: [],
});
