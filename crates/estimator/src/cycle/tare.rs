//! The tare: the sensor's bias made such that the mean reading at rest
//! gives zero tip force at this pose and the measured torque the predicted
//! one ([`super::Command::Tare`]). The mean at rest it is taken over
//! ([`TareMean`], a window of new samples since the joints last moved), the
//! tare's age and the drift bound since it (a margin of the guard, and the
//! warning that a tare is due), and why a tare is refused
//! ([`super::TareRefused`]).

use super::Estimator;
use super::input_checks::moved_since;
use super::torque_residual::predicted_torque_nm;
use super::vocabulary::{Bias, CommandRefused, CycleInput, SensorSample, TareRefused, TipOutcome};
use crate::guard::{Axis, Reason};
use crate::{Mat3, Pose, Vec3};
use sar_kinematics::ActiveJoints;

/// The mean reading at rest a tare is taken over ([`super::TareLimits`]): the raw
/// force and torque (sensor frame, before the bias) of the new samples
/// since the joints last moved, and the force's spread. One recursion gives
/// the running mean and population variance of the first `window_samples`
/// samples, and an exponential mean and variance of that length beyond.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TareMean {
    /// New samples in the mean (at most `window_samples`).
    count: u32,
    /// Mean force reading, sensor frame, N.
    force_n: Vec3,
    /// Mean torque reading, sensor frame, N m.
    torque_nm: Vec3,
    /// Variance of the force reading per sensor axis, N^2.
    var_n2: Vec3,
    /// The joints the mean was taken at.
    joints: Option<ActiveJoints>,
}

impl TareMean {
    pub(super) const EMPTY: TareMean = TareMean {
        count: 0,
        force_n: Vec3::new(0.0, 0.0, 0.0),
        torque_nm: Vec3::new(0.0, 0.0, 0.0),
        var_n2: Vec3::new(0.0, 0.0, 0.0),
        joints: None,
    };
}

/// The tare's age and what follows from it ([`Estimator::tare_status`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct TareStatus {
    /// Time since the tare in use, ns.
    pub(super) age_ns: Option<u64>,
    /// The drift bound since the tare, added to the guard's margin, N.
    pub(super) extra_margin_n: f64,
    /// The warning that a tare is due.
    pub(super) due: Option<Reason>,
}

/// ns to s.
fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

impl Estimator {
    /// The tare's age (its clock starts at the first trusted reading), the
    /// drift bound since it, and whether a tare is due.
    pub(super) fn tare_status(&mut self, now_ns: Option<u64>) -> TareStatus {
        if let (Some(now), None) = (now_ns, self.tare_ns) {
            self.tare_ns = Some(now);
        }
        let age_ns = now_ns
            .zip(self.tare_ns)
            .map(|(now, tare)| now.saturating_sub(tare));
        let tare = self.limits.tare;
        let extra_margin_n = age_ns.map_or(0.0, |age| tare.drift_n_per_s * ns_to_s(age));
        let due = match (tare.max_age_ns, age_ns) {
            (Some(max_ns), Some(age_ns)) if age_ns > max_ns => Some(Reason::TareDue {
                age_s: ns_to_s(age_ns),
                max_age_s: ns_to_s(max_ns),
            }),
            _ => None,
        };
        TareStatus {
            age_ns,
            extra_margin_n,
            due,
        }
    }

    /// The tare's mean at rest: one new sample's reading into it; joints
    /// that moved (beyond the joint margin) restart it, and so does a
    /// sample without an estimate (no pose, invalid or stale input).
    pub(super) fn update_tare_mean(&mut self, q: &ActiveJoints, sensor: &SensorSample) {
        let window = self.limits.tare.window_samples.max(1);
        let mean = &mut self.tare_mean;
        if !matches!(self.last.tip, TipOutcome::Estimate(_)) {
            *mean = TareMean::EMPTY;
            return;
        }
        if moved_since(mean.joints, q, self.limits.joint_margin_m) {
            *mean = TareMean {
                joints: Some(*q),
                ..TareMean::EMPTY
            };
        }
        mean.count = mean.count.saturating_add(1).min(window);
        let k = 1.0 / f64::from(mean.count);
        // Welford's recursion with weight k: the population variance of the
        // first `window` samples, an exponential one beyond.
        let d = sensor.force_n - mean.force_n;
        mean.force_n += d * k;
        mean.var_n2 = (mean.var_n2 + d.component_mul(&d) * k) * (1.0 - k);
        mean.torque_nm += (sensor.torque_nm - mean.torque_nm) * k;
    }

    /// Whether a tare may be taken now: the rate limit, a full mean at
    /// rest, a spread within the noise; the mean reading when it may.
    fn tare_reading(
        &self,
        sensor: &SensorSample,
        now_ns: Option<u64>,
    ) -> Result<SensorSample, TareRefused> {
        let limits = self.limits.tare;
        if let (Some(last), Some(now)) = (self.last_tare_ns, now_ns) {
            let since_ns = now.saturating_sub(last);
            if since_ns < limits.min_interval_ns {
                return Err(TareRefused::TooSoon {
                    since_s: ns_to_s(since_ns),
                    min_interval_s: ns_to_s(limits.min_interval_ns),
                });
            }
        }
        let mean = &self.tare_mean;
        let needed = limits.window_samples.max(1);
        if mean.count < needed {
            return Err(TareRefused::NotAtRest {
                samples: mean.count,
                needed,
            });
        }
        let axes = [Axis::X, Axis::Y, Axis::Z];
        for ((axis, var), noise) in axes.iter().zip(mean.var_n2.iter()).zip(self.noise_n.iter()) {
            let std_n = libm::sqrt(*var);
            let allowed_n = limits.max_spread * noise;
            // NaN counts as beyond.
            if std_n.is_nan() || std_n > allowed_n {
                return Err(TareRefused::NotSteady {
                    axis: *axis,
                    std_n,
                    allowed_n,
                });
            }
        }
        Ok(SensorSample {
            force_n: mean.force_n,
            torque_nm: mean.torque_nm,
            ..*sensor
        })
    }

    /// The tare's bias at `pose` from the reading at rest. Not at rest: the
    /// mean starts again (its spread would otherwise remember the motion for
    /// a few windows), so the next tare needs a fresh window.
    pub(super) fn tare_now(
        &mut self,
        pose: &Pose,
        input: &CycleInput,
        now_ns: Option<u64>,
    ) -> Result<Bias, CommandRefused> {
        let reading = match self.tare_reading(&input.sensor, now_ns) {
            Ok(reading) => reading,
            Err(refused) => {
                if matches!(refused, TareRefused::NotSteady { .. }) {
                    self.tare_mean = TareMean {
                        joints: self.tare_mean.joints,
                        ..TareMean::EMPTY
                    };
                }
                return Err(CommandRefused::Tare(refused));
            }
        };
        let bias = self
            .tare(pose, &reading)
            .ok_or(CommandRefused::Unsolvable)?;
        self.last_tare_ns = now_ns.or(self.last_tare_ns);
        Ok(bias)
    }

    /// The bias for which this reading (the mean at rest) gives zero tip
    /// force at this pose, and the torque bias for which the measured torque
    /// is the predicted one. The estimate is affine in the force bias,
    /// F_tip(b + x) = F_tip(b) + J x: J from three unit steps, then
    /// x = -J^-1 F_tip(b). `None` when J is singular or a result is not
    /// finite.
    fn tare(&self, pose: &Pose, sensor: &SensorSample) -> Option<Bias> {
        let b = self.bias.force_n;
        let reading = &sensor.force_n;
        let estimate = self.tip.estimate(pose, reading, &b).ok()?;
        let column = |unit: Vec3| -> Option<Vec3> {
            let e = self.tip.estimate(pose, reading, &(b + unit)).ok()?;
            Some(e.force_n - estimate.force_n)
        };
        let j = Mat3::from_columns(&[column(Vec3::x())?, column(Vec3::y())?, column(Vec3::z())?]);
        let step = j.try_inverse()? * (-estimate.force_n);
        let force_n = b + step;
        let tared = self.tip.estimate(pose, reading, &force_n).ok()?;
        let torque_nm = sensor.torque_nm
            - predicted_torque_nm(&self.frame, reading, &force_n, tared.torsion_nm, || {
                self.frame.torsion_axis_s(pose)
            });
        let bias = Bias { force_n, torque_nm };
        bias.check().ok()?;
        Some(bias)
    }
}

sar_snapshot::snap_struct!(TareMean {
    count,
    force_n,
    torque_nm,
    var_n2,
    joints,
});
