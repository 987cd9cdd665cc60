//! `sarctl identify --servo` (issue 34 section 1): the drives' position
//! loop as measured. From the recorded cycle inputs (`/sar/cycle/input`,
//! full or lean recordings) it takes what the drives were told (the
//! trajectory at each joint sample, `target_q_m`, or, while streaming, the
//! set points `setpoint_q_m`, each reached one period after it was sent, as
//! the drives interpolate them) and what the encoders saw (`joints_q_m` at
//! their stamps), and fits the loop's one servo model (`sar_hal::servo`:
//! `x'' = wn^2 (r(t - d) - x) - 2 zeta wn x'`, sampled every
//! [`MODEL_STEP_NS`], the model `sar_loop::motion` and the simulator run)
//! to the encoders: bandwidth, damping and a pure delay of the reference,
//! each with its standard deviation, per axis and shared by the axes that
//! moved (the configuration has one servo for the three: the shared fit is
//! what is written back as `[axes] servo_bandwidth_hz`, `servo_damping`,
//! `servo_delay_s`).
//!
//! The fit is Levenberg-Marquardt on the encoder residuals (each axis's
//! constant offset from the reference fitted too: the encoders' count)
//! from the best of a coarse grid; the Jacobian by central differences.
//! The covariance is not `s^2 (J^T J)^-1`: the residuals are not white
//! (the encoders' quantisation holds its error while the axis stays within
//! a count, over tens of samples), and that formula's standard deviations
//! were up to 9 times smaller than the true error. It is the sandwich
//! `(J^T J)^-1 S (J^T J)^-1` whose middle `S` sums the scores `j_t r_t`
//! and their cross products up to a lag (Newey and West 1987, Bartlett
//! weights), each series (an axis over a segment) on its own; the lag is
//! read off the residuals (Sokal's window: the least M with M >= 5 times
//! their integrated autocorrelation time up to M), see [`hac_lags`].

use nalgebra::{Matrix3, Vector3};
use sar_loop::motion::{MODEL_STEP_NS, ServoAxis};
use sar_msgs::msgs::{CycleInput, DriveActionCode, DriveStateCode, Topic};
use sar_record::{McapReader, ReadError};
use serde_json::json;

/// The least range of an axis's reference that counts as motion, m.
pub const MIN_MOTION_M: f64 = 0.5e-3;

/// The fewest encoder samples fitted (over the axes that moved).
pub const MIN_SAMPLES: usize = 300;

/// Why the servo cannot be identified (the CLI prints it on one line).
#[derive(Debug, thiserror::Error)]
pub enum ServoFitError {
    /// The recording could not be read.
    #[error("the recording cannot be read: {0}")]
    Read(#[from] ReadError),
    /// A lean recording's batches cannot be read.
    #[error("the recording cannot be read: {0}")]
    Lean(#[from] sar_record::lean::LeanReadError),
    /// No cycle inputs.
    #[error(
        "the recording has no /sar/cycle/input messages: identify --servo needs what the drives were told (record with sarctl record start/stop or sard --record)"
    )]
    NoCycleInput,
    /// Nothing moved.
    #[error(
        "no axis moved {MIN_MOTION_M} m or more with the drives enabled: identify --servo needs motion (sarctl identify --servo --live commands its own)"
    )]
    NoMotion,
    /// Too few samples.
    #[error("too short: {samples} encoder samples of motion, at least {MIN_SAMPLES} are needed")]
    TooShort {
        /// The samples there were.
        samples: usize,
    },
    /// The motion does not determine the parameters.
    #[error(
        "the motion does not determine bandwidth, damping and delay (singular fit): move each axis from rest to rest"
    )]
    Singular,
}

/// A point of the drives' reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knot {
    /// When, ns.
    pub t_ns: u64,
    /// The reference then, q1..q3, m.
    pub q_m: [f64; 3],
    /// A sample of a planned trajectory (smooth: quadratic between its
    /// breakpoints), not a streamed set point (the drives go linearly from
    /// one to the next).
    pub planned: bool,
}

/// One stretch of the drives enabled with a known reference.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Segment {
    /// The drives' reference, held before the first knot and after the
    /// last; between knots: linear where a streamed set point is at
    /// either end, else the cubic through the four planned knots around
    /// (exact on a trajectory's quadratic pieces: linear interpolation of
    /// 1 ms samples of a 1 m/s^2 ramp is a T^2 a / 8 = 0.12 um chord,
    /// which read as +22 us of delay and +0.16 % of bandwidth on a 30 Hz
    /// servo), see [`Reference`].
    pub knots: Vec<Knot>,
    /// The encoders (stamp ns, q1..q3 m), in time order.
    pub joints: Vec<(u64, [f64; 3])>,
}

/// The recorded cycles cut into [`Segment`]s; `period_ns` the loop's
/// period (a streamed set point is reached that long after it was sent).
pub fn segments(cycles: &[CycleInput], period_ns: u64) -> Vec<Segment> {
    let mut out = Vec::new();
    let mut seg = Segment::default();
    let mut close = |seg: &mut Segment| {
        let s = std::mem::take(seg);
        if s.joints.len() >= 2 && !s.knots.is_empty() {
            out.push(s);
        }
    };
    for c in cycles {
        // A non-finite value (a damaged or crafted recording) cuts the
        // segment like a cycle without drives: it never reaches the fit.
        let finite = |q: &[f64; 3]| q.iter().all(|v| v.is_finite());
        let enabled = c.drive_state == DriveStateCode::Enabled
            && c.joints_valid
            && finite(&c.joints_q_m)
            && finite(&c.target_q_m)
            && finite(&c.setpoint_q_m);
        let streamed = c.drive_action == DriveActionCode::Stream;
        if !enabled || !(c.target_valid || streamed) {
            close(&mut seg);
            continue;
        }
        if streamed {
            let before = seg.knots.last().map(|k| k.q_m).unwrap_or(c.target_q_m);
            if seg.knots.last().is_none_or(|k| k.t_ns < c.now_ns) {
                seg.knots.push(Knot {
                    t_ns: c.now_ns,
                    q_m: before,
                    planned: false,
                });
            }
            seg.knots.push(Knot {
                t_ns: c.now_ns + period_ns,
                q_m: c.setpoint_q_m,
                planned: false,
            });
        } else if seg.knots.last().is_none_or(|k| k.t_ns < c.joints_stamp_ns) {
            seg.knots.push(Knot {
                t_ns: c.joints_stamp_ns,
                q_m: c.target_q_m,
                planned: true,
            });
        }
        if seg.joints.last().is_none_or(|j| j.0 < c.joints_stamp_ns) {
            seg.joints.push((c.joints_stamp_ns, c.joints_q_m));
        }
    }
    close(&mut seg);
    out
}

/// Reads the cycle inputs of a recording file (full or lean).
pub fn read_cycles(path: &std::path::Path) -> Result<Vec<CycleInput>, ServoFitError> {
    let open = || McapReader::open(path);
    let mut out = Vec::new();
    if sar_record::lean::is_lean(open()?) {
        for c in sar_record::lean::cycles(open()?) {
            out.push(c?.input);
        }
    } else {
        for item in open()?.typed::<CycleInput>(Topic::CycleInput.name()) {
            out.push(item?.1);
        }
    }
    if out.is_empty() {
        return Err(ServoFitError::NoCycleInput);
    }
    Ok(out)
}

/// The loop's period of a recording: the median spacing of its cycles, ns.
pub fn period_of(cycles: &[CycleInput]) -> u64 {
    let mut d: Vec<u64> = cycles
        .windows(2)
        .filter_map(|w| match w {
            [a, b] => b.now_ns.checked_sub(a.now_ns),
            _ => None,
        })
        .filter(|&d| d > 0)
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(1_000_000)
}

/// Servo parameters: bandwidth Hz, damping ratio, delay s.
pub type Params = [f64; 3];

/// The parameters' bounds during the fit.
const LOWER: Params = [0.5, 0.05, -0.01];
const UPPER: Params = [300.0, 3.0, 0.02];

/// One axis's reference with a cursor (times only go forward).
struct Reference<'a> {
    knots: &'a [Knot],
    axis: usize,
    i: usize,
}

impl Reference<'_> {
    /// The reference at `t_ns` (fractional): see [`Segment::knots`].
    fn at(&mut self, t_ns: f64) -> f64 {
        while self
            .knots
            .get(self.i + 1)
            .is_some_and(|k| (k.t_ns as f64) <= t_ns)
        {
            self.i += 1;
        }
        let x = |k: &Knot| k.q_m.get(self.axis).copied().unwrap_or(0.0);
        let i = self.i;
        let (Some(a), next) = (self.knots.get(i), self.knots.get(i + 1)) else {
            return 0.0;
        };
        let Some(b) = next.filter(|_| (a.t_ns as f64) <= t_ns) else {
            return x(a);
        };
        let around = i
            .checked_sub(1)
            .and_then(|first| self.knots.get(first..first + 4));
        if let Some(four) = around.filter(|k| k.iter().all(|k| k.planned)) {
            return lagrange(four, t_ns, x);
        }
        let f = (t_ns - a.t_ns as f64) / (b.t_ns - a.t_ns) as f64;
        x(a) + f * (x(b) - x(a))
    }
}

/// The polynomial through `knots` (distinct times) at `t_ns`.
fn lagrange(knots: &[Knot], t_ns: f64, x: impl Fn(&Knot) -> f64) -> f64 {
    knots
        .iter()
        .enumerate()
        .map(|(j, kj)| {
            let weight: f64 = knots
                .iter()
                .enumerate()
                .filter(|(m, _)| *m != j)
                .map(|(_, km)| (t_ns - km.t_ns as f64) / (kj.t_ns as f64 - km.t_ns as f64))
                .product();
            weight * x(kj)
        })
        .sum()
}

/// The model's position at every encoder sample of `seg` on `axis`,
/// appended to `out`: from rest on the (delayed) reference at the first
/// sample, stepped every [`MODEL_STEP_NS`].
fn simulate(seg: &Segment, axis: usize, p: &Params, out: &mut Vec<f64>) {
    let [f_hz, zeta, delay_s] = *p;
    let wn = core::f64::consts::TAU * f_hz;
    let delay_ns = delay_s * 1e9;
    let Some(&(t0, _)) = seg.joints.first() else {
        return;
    };
    let mut r = Reference {
        knots: &seg.knots,
        axis,
        i: 0,
    };
    let mut x = ServoAxis::rest(r.at(t0 as f64 - delay_ns));
    let mut t = t0;
    for &(stamp, _) in &seg.joints {
        while t + MODEL_STEP_NS <= stamp {
            t += MODEL_STEP_NS;
            x.step(MODEL_STEP_NS, r.at(t as f64 - delay_ns), wn, zeta, None);
        }
        out.push(x.after(stamp - t).x_m);
    }
}

/// The encoders less the model over `axes` of every segment, each axis's
/// mean removed (an encoder's constant offset from the reference, up to a
/// count, would read as a delay on every ramp: it is fitted, as the mean).
pub fn residuals(segs: &[Segment], axes: &[usize], p: &Params) -> Vec<f64> {
    let mut model = Vec::new();
    let mut out = Vec::new();
    for &axis in axes {
        let first = out.len();
        for seg in segs {
            model.clear();
            simulate(seg, axis, p, &mut model);
            for (m, (_, q)) in model.iter().zip(&seg.joints) {
                out.push(q.get(axis).copied().unwrap_or(0.0) - m);
            }
        }
        let Some(axis_residuals) = out.get_mut(first..) else {
            continue;
        };
        let mean = axis_residuals.iter().sum::<f64>() / axis_residuals.len().max(1) as f64;
        axis_residuals.iter_mut().for_each(|r| *r -= mean);
    }
    out
}

fn sum_sq(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// A fit: the parameters, their standard deviations, the residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoFit {
    /// Bandwidth Hz, damping, delay s.
    pub params: Params,
    /// Their standard deviations.
    pub std: Params,
    /// The encoders' RMS residual, m.
    pub rms_m: f64,
    /// The samples fitted.
    pub samples: usize,
}

/// The Jacobian of the model (central differences) and the residuals at `p`.
fn jacobian(segs: &[Segment], axes: &[usize], p: &Params) -> (Vec<[f64; 3]>, Vec<f64>) {
    let r0 = residuals(segs, axes, p);
    let [f_hz, _, _] = *p;
    let h = [1e-4 * f_hz, 1e-4, 2e-6];
    let columns = h
        .iter()
        .enumerate()
        .map(|(k, &hk)| {
            let shifted = |by: f64| {
                let mut q = *p;
                q.iter_mut()
                    .enumerate()
                    .filter(|(i, _)| *i == k)
                    .for_each(|(_, v)| *v += by);
                residuals(segs, axes, &q)
            };
            let (ru, rd) = (shifted(hk), shifted(-hk));
            // d(model)/dp = -d(residual)/dp.
            ru.iter()
                .zip(rd)
                .map(|(u, d)| (d - u) / (2.0 * hk))
                .collect::<Vec<f64>>()
        })
        .collect::<Vec<_>>();
    let jac = match columns.as_slice() {
        [a, b, c] => a
            .iter()
            .zip(b)
            .zip(c)
            .map(|((a, b), c)| [*a, *b, *c])
            .collect(),
        _ => Vec::new(),
    };
    (jac, r0)
}

/// The normal equations J^T J and J^T r.
fn normal(jac: &[[f64; 3]], r: &[f64]) -> (Matrix3<f64>, Vector3<f64>) {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for (row, ri) in jac.iter().zip(r) {
        let j = Vector3::from(*row);
        a += j * j.transpose();
        b += j * *ri;
    }
    (a, b)
}

/// The best start of a coarse grid (delay 0).
fn start(segs: &[Segment], axes: &[usize]) -> Params {
    let mut best = ([30.0, 0.7, 0.0], f64::INFINITY);
    for f in [3.0, 6.0, 12.0, 25.0, 50.0, 100.0] {
        for z in [0.3, 0.6, 1.0, 1.5] {
            let p = [f, z, 0.0];
            let c = sum_sq(&residuals(segs, axes, &p));
            if c < best.1 {
                best = (p, c);
            }
        }
    }
    best.0
}

fn clamp(p: Params) -> Params {
    let mut q = p;
    for ((v, lo), hi) in q.iter_mut().zip(LOWER).zip(UPPER) {
        *v = v.clamp(lo, hi);
    }
    q
}

/// Fits the servo to the encoders of `axes` over `segs`.
pub fn fit(segs: &[Segment], axes: &[usize]) -> Result<ServoFit, ServoFitError> {
    let mut p = start(segs, axes);
    let mut cost = sum_sq(&residuals(segs, axes, &p));
    let mut lambda = 1e-3;
    for _ in 0..60 {
        let (jac, r) = jacobian(segs, axes, &p);
        let (a, b) = normal(&jac, &r);
        let mut improved = false;
        for _ in 0..12 {
            let damped = a + Matrix3::from_diagonal(&a.diagonal()) * lambda;
            let step = damped.try_inverse().ok_or(ServoFitError::Singular)? * b;
            let [p0, p1, p2] = p;
            let q = clamp([p0 + step.x, p1 + step.y, p2 + step.z]);
            let c = sum_sq(&residuals(segs, axes, &q));
            if c < cost {
                let [q0, q1, q2] = q;
                let small = (q0 / p0 - 1.0).abs() < 1e-7
                    && (q1 - p1).abs() < 1e-7
                    && (q2 - p2).abs() < 1e-9;
                (p, cost, lambda, improved) = (q, c, (lambda * 0.1).max(1e-9), !small);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let (jac, r) = jacobian(segs, axes, &p);
    let (a, _) = normal(&jac, &r);
    let n = r.len();
    let runs = series_lengths(segs, axes);
    let lags = hac_lags(&r, &runs);
    let a_inv = a.try_inverse().ok_or(ServoFitError::Singular)?;
    let dof = n as f64 / (n.saturating_sub(3).max(1)) as f64;
    let cov = a_inv * hac_middle(&jac, &r, &runs, lags) * a_inv * dof;
    let d = cov.diagonal();
    let std = [d.x, d.y, d.z].map(|v| v.max(0.0).sqrt());
    Ok(ServoFit {
        params: p,
        std,
        rms_m: (sum_sq(&r) / n.max(1) as f64).sqrt(),
        samples: n,
    })
}

/// The lengths of the residuals' time series, in [`residuals`]' order
/// (each axis over each segment): lags never cross from one to the next.
fn series_lengths(segs: &[Segment], axes: &[usize]) -> Vec<usize> {
    axes.iter()
        .flat_map(|_| segs.iter().map(|s| s.joints.len()))
        .collect()
}

/// The longest lag [`hac_middle`] sums over.
pub const MAX_HAC_LAGS: usize = 2000;

/// The lag for the residuals' correlation: Sokal's automatic window, the
/// least `M` with `M >= 5 tau(M)`, `tau(M) = 1 + 2 sum_{k<=M} rho_k` (the
/// autocorrelations pooled over the series), at least 1 and at most
/// [`MAX_HAC_LAGS`] or a quarter of the longest series.
pub fn hac_lags(r: &[f64], runs: &[usize]) -> usize {
    let longest = runs.iter().copied().max().unwrap_or(0);
    let max_lag = (longest / 4).clamp(1, MAX_HAC_LAGS);
    let c0 = sum_sq(r);
    if c0 <= 0.0 {
        return 1;
    }
    let mut tau = 1.0;
    for lag in 1..=max_lag {
        tau += 2.0 * lagged_sum(r, runs, lag) / c0;
        if lag as f64 >= 5.0 * tau {
            return lag;
        }
    }
    max_lag
}

/// `sum_t x_t x_{t-lag}` over every series of `runs` (lags within a
/// series only).
fn lagged_sum(x: &[f64], runs: &[usize], lag: usize) -> f64 {
    let mut sum = 0.0;
    let mut start = 0;
    for &len in runs {
        if let Some(series) = x.get(start..start + len) {
            sum += series
                .iter()
                .skip(lag)
                .zip(series)
                .map(|(a, b)| a * b)
                .sum::<f64>();
        }
        start += len;
    }
    sum
}

/// The sandwich's middle: `sum_t g_t g_t^T + sum_{l=1..lags} w_l sum_t
/// (g_t g_{t-l}^T + g_{t-l} g_t^T)`, `g_t = j_t r_t`, `w_l = 1 - l / (lags
/// + 1)` (positive semi-definite).
fn hac_middle(jac: &[[f64; 3]], r: &[f64], runs: &[usize], lags: usize) -> Matrix3<f64> {
    let g: Vec<Vector3<f64>> = jac
        .iter()
        .zip(r)
        .map(|(j, ri)| Vector3::from(*j) * *ri)
        .collect();
    let mut s = Matrix3::zeros();
    for gt in &g {
        s += gt * gt.transpose();
    }
    for lag in 1..=lags {
        let w = 1.0 - lag as f64 / (lags + 1) as f64;
        let mut c = Matrix3::zeros();
        let mut start = 0;
        for &len in runs {
            if let Some(series) = g.get(start..start + len) {
                for (now, before) in series.iter().skip(lag).zip(series) {
                    c += now * before.transpose();
                }
            }
            start += len;
        }
        s += (c + c.transpose()) * w;
    }
    s
}

/// The axes whose reference moved at least [`MIN_MOTION_M`].
pub fn moved_axes(segs: &[Segment]) -> Vec<usize> {
    (0..3)
        .filter(|&axis| {
            segs.iter().any(|s| {
                let xs = s
                    .knots
                    .iter()
                    .map(|k| k.q_m.get(axis).copied().unwrap_or(0.0));
                let (lo, hi) = xs.fold((f64::MAX, f64::MIN), |(l, h), x| (l.min(x), h.max(x)));
                hi - lo >= MIN_MOTION_M
            })
        })
        .collect()
}

/// What `identify --servo` found.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoResult {
    /// Each axis that moved: (axis index, its own fit).
    pub per_axis: Vec<(usize, ServoFit)>,
    /// The fit shared by those axes (what is written back).
    pub shared: ServoFit,
}

/// Identifies the servo from recorded cycles.
pub fn identify_cycles(cycles: &[CycleInput]) -> Result<ServoResult, ServoFitError> {
    if cycles.is_empty() {
        return Err(ServoFitError::NoCycleInput);
    }
    let segs = segments(cycles, period_of(cycles));
    let axes = moved_axes(&segs);
    if axes.is_empty() {
        return Err(ServoFitError::NoMotion);
    }
    let samples: usize = segs.iter().map(|s| s.joints.len()).sum();
    if samples < MIN_SAMPLES {
        return Err(ServoFitError::TooShort { samples });
    }
    let per_axis = axes
        .iter()
        .map(|&a| fit(&segs, &[a]).map(|f| (a, f)))
        .collect::<Result<Vec<_>, _>>()?;
    let mut shared = fit(&segs, &axes)?;
    // The axes make the same moves against the same kind of encoder: their
    // errors need not be independent (on the simulator they are equal), so
    // the shared fit is stated no surer than its surest axis.
    for (k, std) in shared.std.iter_mut().enumerate() {
        let surest_axis = per_axis
            .iter()
            .filter_map(|(_, f)| f.std.get(k).copied())
            .fold(f64::INFINITY, f64::min);
        if surest_axis.is_finite() {
            *std = std.max(surest_axis);
        }
    }
    Ok(ServoResult { per_axis, shared })
}

/// Identifies the servo from a recording file.
pub fn identify_file(path: &std::path::Path) -> Result<ServoResult, ServoFitError> {
    identify_cycles(&read_cycles(path)?)
}

/// The value written back for a fitted delay: not below 0 (the key's range).
pub fn written_delay_s(delay_s: f64) -> f64 {
    delay_s.max(0.0)
}

fn fit_json(f: &ServoFit, axis: Option<usize>) -> serde_json::Value {
    json!({
        "axis": axis.map(|a| format!("q{}", a + 1)),
        "bandwidth_hz": f.params[0], "bandwidth_std_hz": f.std[0],
        "damping": f.params[1], "damping_std": f.std[1],
        "delay_s": f.params[2], "delay_std_s": f.std[2],
        "rms_residual_m": f.rms_m, "samples": f.samples,
    })
}

fn fit_text(f: &ServoFit) -> String {
    format!(
        "bandwidth {:.3} ± {:.3} Hz, damping {:.4} ± {:.4}, delay {:.3} ± {:.3} ms (RMS residual {:.2} um, {} samples)",
        f.params[0],
        f.std[0],
        f.params[1],
        f.std[1],
        f.params[2] * 1e3,
        f.std[2] * 1e3,
        f.rms_m * 1e6,
        f.samples
    )
}

impl ServoResult {
    /// The report as JSON (`written`: the configuration written back).
    pub fn to_json(&self, written: Option<&str>) -> serde_json::Value {
        let axes: Vec<_> = self
            .per_axis
            .iter()
            .map(|(a, f)| fit_json(f, Some(*a)))
            .collect();
        json!({ "servo": fit_json(&self.shared, None), "axes": axes, "written": written })
    }

    /// The report for a person.
    pub fn to_text(&self, written: Option<&str>) -> String {
        let mut s = format!("servo (shared): {}\n", fit_text(&self.shared));
        for (a, f) in &self.per_axis {
            s += &format!("  q{}: {}\n", a + 1, fit_text(f));
        }
        s += &match written {
            Some(path) => format!(
                "written to {path}: [axes] servo_bandwidth_hz, servo_damping, servo_delay_s"
            ),
            None => "nothing written (--dry-run)".to_owned(),
        };
        s
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// A trajectory's knots: each axis a rest-to-rest move of 2 mm (1 m/s^2
    /// up, down), then held; samples every ms for 0.5 s.
    fn moves() -> Segment {
        let x = |t_s: f64| {
            let (a, h) = (1.0, 0.0447);
            if t_s < 0.0 {
                0.0
            } else if t_s < h {
                0.5 * a * t_s * t_s
            } else if t_s < 2.0 * h {
                let u = 2.0 * h - t_s;
                a * h * h - 0.5 * a * u * u
            } else {
                a * h * h
            }
        };
        let knots = (0..500u64)
            .map(|k| {
                let t = k as f64 * 1e-3;
                Knot {
                    t_ns: k * 1_000_000,
                    q_m: [x(t - 0.05), x(t - 0.15), x(t - 0.25)],
                    planned: true,
                }
            })
            .collect();
        let joints = (0..500u64).map(|k| (k * 1_000_000, [0.0; 3])).collect();
        Segment { knots, joints }
    }

    /// Encoders made by the model itself (no noise): the fit gives its
    /// parameters back, per axis and shared.
    #[test]
    fn the_fit_gives_back_the_model_that_made_the_encoders() {
        let mut seg = moves();
        let truth = [18.0, 0.55, 0.0015];
        let mut per_axis = Vec::new();
        for axis in 0..3 {
            let mut x = Vec::new();
            simulate(&seg, axis, &truth, &mut x);
            per_axis.push(x);
        }
        for (k, j) in seg.joints.iter_mut().enumerate() {
            j.1 = [per_axis[0][k], per_axis[1][k], per_axis[2][k]];
        }
        let segs = [seg];
        assert_eq!(moved_axes(&segs), vec![0, 1, 2]);
        for axes in [&[1][..], &[0, 1, 2][..]] {
            let f = fit(&segs, axes).unwrap();
            for (p, t) in f.params.iter().zip(truth) {
                assert!((p - t).abs() < 1e-6 * t.max(1.0), "{f:?}");
            }
            assert!(f.rms_m < 1e-10, "{f:?}");
        }
    }

    /// A plant that follows a planned trajectory itself (a rest-to-rest
    /// move of 2 mm at 1 m/s^2, sampled every 0.1 ms, unquantised), the
    /// fit given only the trajectory's 1 ms samples: the planned knots'
    /// cubic gives the 30 Hz plant back within 1e-5 (a linear
    /// interpolation read 30.048 Hz and 22 us of delay).
    #[test]
    fn a_planned_reference_is_interpolated_as_the_trajectory_it_samples() {
        let (accel, speed, step) = (1.0f64, 0.05f64, 0.002f64);
        let t1 = (speed / accel).min((step / accel).sqrt());
        let v = accel * t1;
        let cruise = (step - v * t1) / v;
        let x = |t: f64| -> f64 {
            if t <= 0.0 {
                0.0
            } else if t < t1 {
                0.5 * accel * t * t
            } else if t < t1 + cruise {
                0.5 * accel * t1 * t1 + v * (t - t1)
            } else if t < 2.0 * t1 + cruise {
                let u = 2.0 * t1 + cruise - t;
                step - 0.5 * accel * u * u
            } else {
                step
            }
        };
        let truth = [30.0, 0.7, 0.0];
        let wn = core::f64::consts::TAU * truth[0];
        let mut plant = ServoAxis::rest(0.0);
        let (mut knots, mut joints, mut t) = (Vec::new(), Vec::new(), 0u64);
        for k in 0..400u64 {
            let stamp = k * 1_000_000;
            while t + 100_000 <= stamp {
                t += 100_000;
                plant.step(100_000, x(t as f64 * 1e-9 - 0.05), wn, truth[1], None);
            }
            knots.push(Knot {
                t_ns: stamp,
                q_m: [x(stamp as f64 * 1e-9 - 0.05); 3],
                planned: true,
            });
            joints.push((stamp, [plant.after(stamp - t).x_m; 3]));
        }
        let f = fit(&[Segment { knots, joints }], &[0]).unwrap();
        assert!((f.params[0] / truth[0] - 1.0).abs() < 1e-5, "{f:?}");
        assert!((f.params[1] / truth[1] - 1.0).abs() < 1e-5, "{f:?}");
        assert!(f.params[2].abs() < 1e-7, "{f:?}");
    }

    /// Streamed set points: the reference reaches each one period after
    /// it was sent, held before; cycles without drives enabled cut.
    #[test]
    fn streamed_set_points_are_reached_a_period_later() {
        let cycle = |k: u64, action, sp: f64| CycleInput {
            now_ns: k * 1_000_000,
            joints_stamp_ns: k * 1_000_000,
            joints_valid: true,
            drive_state: DriveStateCode::Enabled,
            target_valid: true,
            target_q_m: [sp; 3],
            drive_action: action,
            setpoint_q_m: [sp; 3],
            ..CycleInput::default()
        };
        let mut cycles = vec![
            cycle(1, DriveActionCode::None, 0.0),
            cycle(2, DriveActionCode::Stream, 0.1),
            cycle(3, DriveActionCode::Stream, 0.2),
        ];
        let mut off = cycle(4, DriveActionCode::None, 0.2);
        off.drive_state = DriveStateCode::QuickStop;
        cycles.push(off);
        cycles.push(cycle(5, DriveActionCode::None, 0.2));
        cycles.push(cycle(6, DriveActionCode::None, 0.2));
        let segs = segments(&cycles, period_of(&cycles));
        assert_eq!(segs.len(), 2);
        // A non-finite encoder value cuts like a cycle without drives.
        let mut damaged = cycles.clone();
        damaged[4].joints_q_m[1] = f64::NAN;
        assert_eq!(segments(&damaged, period_of(&damaged)).len(), 1);
        let knots: Vec<_> = segs[0].knots.iter().map(|k| (k.t_ns, k.q_m[0])).collect();
        assert_eq!(
            knots,
            vec![
                (1_000_000, 0.0),
                (2_000_000, 0.0),
                (3_000_000, 0.1),
                (4_000_000, 0.2)
            ]
        );
        assert_eq!(segs[1].joints.len(), 2);
    }
}
