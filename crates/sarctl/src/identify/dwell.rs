//! The static dwells of a recording: stretches where the active joints stay
//! still (every joint within `still_tolerance_m` of the stretch's range) for
//! at least `settle_s + min_dwell_s`. The first `settle_s` of each stretch is
//! discarded (the transient after the move); the rest is the dwell's window,
//! over which the joints and the sensor's force are averaged.
//!
//! Streaming and bounded: [`DwellFinder`] takes the joint samples in stamp
//! order and keeps one stretch's sums; [`SensorAverager`] then adds each
//! sensor sample to the dwell whose window holds its stamp. Memory grows with
//! the number of dwells only, never with the recording's length.

use sar_kinematics::slide::{SlideSign, SlideTracker};
use sar_kinematics::{ActiveJoints, Calibration};

/// How dwells are found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DwellOptions {
    /// Largest range (max - min) of each joint within a dwell, m. Default
    /// 20 um: 16 encoder counts of the article's axes (1.2 um per count), far
    /// below any move between poses.
    pub still_tolerance_m: f64,
    /// Time discarded at the start of each still stretch (the transient after
    /// the move: the axes' settling, the sensor's filter and latency), s.
    /// Default 0.1 s.
    pub settle_s: f64,
    /// Shortest window kept after the settle time, s. Default 0.3 s (150
    /// samples of a 500 Hz sensor): a turnaround or a pause in a move is not a
    /// pose.
    pub min_dwell_s: f64,
}

impl Default for DwellOptions {
    fn default() -> Self {
        Self {
            still_tolerance_m: 20e-6,
            settle_s: 0.1,
            min_dwell_s: 0.3,
        }
    }
}

impl DwellOptions {
    /// Checks the values: tolerance finite and > 0, times finite and >= 0
    /// (`min_dwell_s` > 0).
    pub fn check(&self) -> Result<(), String> {
        if !(self.still_tolerance_m.is_finite() && self.still_tolerance_m > 0.0) {
            return Err(format!(
                "still tolerance must be > 0 m, got {}",
                self.still_tolerance_m
            ));
        }
        if !(self.settle_s.is_finite() && self.settle_s >= 0.0) {
            return Err(format!("settle time must be >= 0 s, got {}", self.settle_s));
        }
        if !(self.min_dwell_s.is_finite() && self.min_dwell_s > 0.0) {
            return Err(format!(
                "minimum dwell must be > 0 s, got {}",
                self.min_dwell_s
            ));
        }
        Ok(())
    }

    fn settle_ns(&self) -> u64 {
        (self.settle_s * 1e9).round() as u64
    }

    fn min_dwell_ns(&self) -> u64 {
        (self.min_dwell_s * 1e9).round() as u64
    }
}

/// One static dwell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dwell {
    /// Start of the still stretch (the first still joint sample), ns.
    pub still_from_ns: u64,
    /// Start of the averaging window (after the settle time), ns, inclusive.
    pub start_ns: u64,
    /// End of the window (the last still joint sample), ns, inclusive.
    pub end_ns: u64,
    /// Mean active joints over the window, m.
    pub joints: ActiveJoints,
    /// Joint samples averaged.
    pub joint_samples: u32,
    /// The sign of the last slide of the rod in the support as the window
    /// starts (from the joints and the configured support; unknown before any
    /// slide).
    pub slide_sign: SlideSign,
    /// Sum of the sensor's force readings in the window (sensor frame), N.
    pub force_sum_n: [f64; 3],
    /// Sensor samples summed.
    pub sensor_samples: u32,
}

impl Dwell {
    /// The mean force reading, sensor frame, N (None without samples).
    pub fn mean_force_n(&self) -> Option<[f64; 3]> {
        (self.sensor_samples > 0).then(|| {
            let k = f64::from(self.sensor_samples);
            self.force_sum_n.map(|s| s / k)
        })
    }
}

/// One still stretch being followed.
#[derive(Debug, Clone, Copy)]
struct Stretch {
    first_ns: u64,
    last_ns: u64,
    lo: [f64; 3],
    hi: [f64; 3],
    sum: [f64; 3],
    n: u32,
    /// The slide sign when the window started (the move before it done).
    sign: SlideSign,
}

impl Stretch {
    fn start(stamp_ns: u64, q: [f64; 3]) -> Self {
        Self {
            first_ns: stamp_ns,
            last_ns: stamp_ns,
            lo: q,
            hi: q,
            sum: [0.0; 3],
            n: 0,
            sign: SlideSign::Unknown,
        }
    }
}

/// Finds the dwells in a stream of joint samples (stamp order).
#[derive(Debug, Clone)]
pub struct DwellFinder {
    options: DwellOptions,
    tracker: SlideTracker,
    current: Option<Stretch>,
    last_stamp_ns: Option<u64>,
    dwells: Vec<Dwell>,
    /// Joint samples left out (non-finite or stamped before the previous one).
    pub skipped: u64,
    /// Joint samples seen.
    pub seen: u64,
}

impl DwellFinder {
    /// A finder for the geometry `calibration` (its support follows the slides).
    pub fn new(calibration: &Calibration, options: DwellOptions) -> Self {
        Self {
            options,
            tracker: SlideTracker::new(calibration),
            current: None,
            last_stamp_ns: None,
            dwells: Vec::new(),
            skipped: 0,
            seen: 0,
        }
    }

    /// Takes the next joint sample (q1, q2, q3 in m).
    pub fn push(&mut self, stamp_ns: u64, q: [f64; 3]) {
        self.seen += 1;
        let backwards = self.last_stamp_ns.is_some_and(|t| stamp_ns < t);
        if backwards || !q.iter().all(|x| x.is_finite()) {
            // Whatever it was, the stretch cannot be trusted across it.
            self.skipped += 1;
            self.close();
            return;
        }
        self.last_stamp_ns = Some(stamp_ns);
        let tol = self.options.still_tolerance_m;
        let still = self.current.as_ref().is_some_and(|s| {
            (0..3).all(|k| {
                let (lo, hi, x) = (
                    s.lo.get(k).copied().unwrap_or(0.0),
                    s.hi.get(k).copied().unwrap_or(0.0),
                    q.get(k).copied().unwrap_or(0.0),
                );
                hi.max(x) - lo.min(x) <= tol
            })
        });
        if !still {
            self.close();
            self.current = Some(Stretch::start(stamp_ns, q));
        }
        let [q1_m, q2_m, q3_m] = q;
        self.tracker.update(&ActiveJoints { q1_m, q2_m, q3_m });
        let sign = self.tracker.sign();
        let settle_ns = self.options.settle_ns();
        if let Some(s) = self.current.as_mut() {
            s.last_ns = stamp_ns;
            for ((lo, hi), x) in s.lo.iter_mut().zip(s.hi.iter_mut()).zip(q) {
                *lo = lo.min(x);
                *hi = hi.max(x);
            }
            if stamp_ns >= s.first_ns.saturating_add(settle_ns) {
                if s.n == 0 {
                    // The sign as of the window's start: the next move may
                    // begin within the tolerance (a slow start) and slide
                    // the rod before the stretch ends.
                    s.sign = sign;
                }
                for (sum, x) in s.sum.iter_mut().zip(q) {
                    *sum += x;
                }
                s.n += 1;
            }
        }
    }

    /// Ends the current stretch; keeps it as a dwell when long enough.
    fn close(&mut self) {
        let Some(s) = self.current.take() else {
            return;
        };
        let start_ns = s.first_ns.saturating_add(self.options.settle_ns());
        if s.n == 0 || s.last_ns < start_ns || s.last_ns - start_ns < self.options.min_dwell_ns() {
            return;
        }
        let k = f64::from(s.n);
        let [q1, q2, q3] = s.sum.map(|x| x / k);
        self.dwells.push(Dwell {
            still_from_ns: s.first_ns,
            start_ns,
            end_ns: s.last_ns,
            joints: ActiveJoints {
                q1_m: q1,
                q2_m: q2,
                q3_m: q3,
            },
            joint_samples: s.n,
            slide_sign: s.sign,
            force_sum_n: [0.0; 3],
            sensor_samples: 0,
        });
    }

    /// Ends the stream: the dwells found, in time order.
    pub fn finish(mut self) -> Vec<Dwell> {
        self.close();
        self.dwells
    }
}

/// Adds sensor samples to the dwells whose window holds their stamp.
#[derive(Debug)]
pub struct SensorAverager {
    dwells: Vec<Dwell>,
    /// Sensor samples seen.
    pub seen: u64,
    /// Non-finite force readings inside a window, left out.
    pub skipped: u64,
}

impl SensorAverager {
    /// Starts with the dwells of [`DwellFinder::finish`] (time order, disjoint).
    pub fn new(dwells: Vec<Dwell>) -> Self {
        Self {
            dwells,
            seen: 0,
            skipped: 0,
        }
    }

    /// Takes one sensor sample (any order).
    pub fn push(&mut self, stamp_ns: u64, force_n: [f64; 3]) {
        self.seen += 1;
        let i = self.dwells.partition_point(|d| d.end_ns < stamp_ns);
        let Some(d) = self.dwells.get_mut(i) else {
            return;
        };
        if stamp_ns < d.start_ns {
            return;
        }
        if !force_n.iter().all(|x| x.is_finite()) {
            self.skipped += 1;
            return;
        }
        for (sum, f) in d.force_sum_n.iter_mut().zip(force_n) {
            *sum += f;
        }
        d.sensor_samples += 1;
    }

    /// The dwells with their sums.
    pub fn finish(self) -> Vec<Dwell> {
        self.dwells
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use sar_kinematics::{CalibrationSpec, Mat3, Vec3};

    fn cal() -> Calibration {
        Calibration::new(&CalibrationSpec {
            p_home_m: Vec3::zeros(),
            ujoint_offset_m: Vec3::new(0.0, -0.08, 0.0),
            sensor_offset_m: Vec3::new(0.0, -0.03, 0.0),
            sensor_rotation: Mat3::identity(),
            support_m: Vec3::new(0.45, 0.20, 0.0),
            gravity_mps2: Vec3::new(0.0, -9.80665, 0.0),
        })
        .unwrap()
    }

    /// 1 kHz joints: still at x = 0.40 for 0.5 s, a move, still at 0.30 for
    /// 0.35 s (too short after the settle), a move, still at 0.2 for 1 s.
    #[test]
    fn finds_long_still_stretches_and_drops_the_settle_time() {
        let mut f = DwellFinder::new(&cal(), DwellOptions::default());
        let mut t = 0u64;
        let mut push = |f: &mut DwellFinder, x: f64, n: u32| {
            for _ in 0..n {
                f.push(t, [0.0, 0.28, x]);
                t += 1_000_000;
            }
        };
        push(&mut f, 0.40, 500);
        for k in 1..100 {
            push(&mut f, 0.40 - 0.001 * f64::from(k), 1);
        }
        push(&mut f, 0.30, 350);
        for k in 1..100 {
            push(&mut f, 0.30 - 0.001 * f64::from(k), 1);
        }
        push(&mut f, 0.20, 1000);
        let dwells = f.finish();
        assert_eq!(dwells.len(), 2, "{dwells:?}");
        assert_eq!(dwells[0].start_ns, 100_000_000);
        assert_eq!(dwells[0].joint_samples, 400);
        assert!((dwells[1].joints.q3_m - 0.20).abs() < 1e-12);
        // q3 decreasing moves A away from B (B_x = 0.45): retracting.
        assert_eq!(dwells[1].slide_sign, SlideSign::Retracting);
        assert_eq!(dwells[0].slide_sign, SlideSign::Unknown);
        let mut avg = SensorAverager::new(dwells);
        for k in 0..3000u64 {
            avg.push(k * 1_000_000, [1.0, 2.0, 3.0]);
        }
        let d = avg.finish();
        assert_eq!(d[0].sensor_samples, 400);
        assert_eq!(d[0].mean_force_n(), Some([1.0, 2.0, 3.0]));
    }

    /// A dwell reached retracting, then a slow start towards B (3 um per
    /// sample: the first 6 samples stay within the 20 um tolerance but slide
    /// the rod by more than the 5 um threshold): the dwell keeps the sign of
    /// the move that led to it.
    #[test]
    fn a_slow_start_of_the_next_move_leaves_the_dwell_sign() {
        let mut f = DwellFinder::new(&cal(), DwellOptions::default());
        let mut t = 0u64;
        let mut push = |f: &mut DwellFinder, x: f64| {
            f.push(t, [0.0, 0.28, x]);
            t += 1_000_000;
        };
        for k in 0..100 {
            push(&mut f, 0.41 - 1e-4 * f64::from(k));
        }
        for _ in 0..500 {
            push(&mut f, 0.40);
        }
        for k in 1..100 {
            push(&mut f, 0.40 + 3e-6 * f64::from(k));
        }
        let dwells = f.finish();
        assert_eq!(dwells.len(), 1);
        assert_eq!(dwells[0].slide_sign, SlideSign::Retracting);
    }

    #[test]
    fn a_nan_or_backwards_stamp_breaks_a_stretch() {
        let mut f = DwellFinder::new(&cal(), DwellOptions::default());
        for k in 0..300u64 {
            f.push(k * 1_000_000, [0.0, 0.28, 0.4]);
        }
        f.push(300_000_000, [f64::NAN, 0.28, 0.4]);
        for k in 301..600u64 {
            f.push(k * 1_000_000, [0.0, 0.28, 0.4]);
        }
        assert_eq!(f.skipped, 1);
        // Each half is 0.3 s: 0.2 s after the settle, below 0.3 s.
        assert!(f.finish().is_empty());
    }
}
