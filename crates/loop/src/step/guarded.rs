//! Guarded moves (force control, issue 15) and the one brake: a move
//! under way braked when its force is anticipated to reach its limit (once
//! in contact: [`GUARDED_CONTACT_SIGMA`]) or, under the warn rule, when it
//! pushes further along the force; the guarded force's rate.

use super::LoopStep;
use super::config::{GUARDED_CONTACT_SIGMA, RATE_LAG_FRACTION};
use super::retreat::pushes_along_warned_force;
use super::trajectory::Trajectory;
use super::vocabulary::{GuardedStop, LoopInput};
use sar_estimator::Vec3;
use sar_estimator::cycle::{CycleOutput, TipOutcome};
use sar_hal::motion::AxisPlan;

/// A move braked in this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Brake {
    /// The braked trajectory (a new plan: its end point goes to the drives).
    pub(super) trajectory: Trajectory,
    /// Where and at what force, for a guarded move.
    pub(super) guarded_stop: Option<GuardedStop>,
}

impl LoopStep {
    /// Updates the guarded force's rate, per new sensor sample.
    pub(super) fn update_guarded_rate(&mut self, input: &LoopInput, estimate: &CycleOutput) {
        match guarded_force(estimate).filter(|_| self.sample_period_s > 0.0) {
            Some((f, _)) => {
                let counter = input.sensor.counter;
                let m = f.norm();
                match self.guarded_last {
                    Some((c, last)) if c != counter => {
                        // Low-passed over an eighth of the filter's lag (a
                        // difference of one sample is mostly noise; over the
                        // whole lag, the rate comes too late on a stiff
                        // tissue, whose force rises within that lag).
                        let dt_s = f64::from(counter.wrapping_sub(c)) * self.sample_period_s;
                        let alpha = dt_s / (dt_s + RATE_LAG_FRACTION * self.guarded_lag_s);
                        self.guarded_rate_n_per_s +=
                            alpha * ((m - last) / dt_s - self.guarded_rate_n_per_s);
                        self.guarded_last = Some((counter, m));
                    }
                    Some(_) => {}
                    None => {
                        self.guarded_rate_n_per_s = 0.0;
                        self.guarded_last = Some((counter, m));
                    }
                }
            }
            None => {
                self.guarded_last = None;
                self.guarded_rate_n_per_s = 0.0;
            }
        }
    }

    /// A move under way whose force stops it, braked: a guarded move's
    /// force anticipated to reach its limit, or, under the warn rule, a move
    /// toward a tip further along the force. A guarded move braked either
    /// way records where and at what force.
    pub(super) fn brake_if_due(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
    ) -> Option<Brake> {
        let (Some(t), Some(now_ns), Some(pose)) = (trajectory, input.now_ns, estimate.pose) else {
            return None;
        };
        if now_ns >= t.end_ns {
            return None;
        }
        let guarded = self.guarded_limit_reached(t, now_ns, estimate);
        let force_n = guarded.or_else(|| pushes_along_warned_force(t, &pose.tip_m, estimate))?;
        Some(Brake {
            trajectory: self.braked(t, now_ns, guarded.is_some()),
            guarded_stop: t.max_force_n.map(|max_force_n| GuardedStop {
                cycle: input.cycle,
                tip_m: pose.tip_m,
                force_n,
                max_force_n,
            }),
        })
    }

    /// A guarded move's force, when it is anticipated to reach the move's
    /// limit: the magnitude of the filtered tip force when the filter is on
    /// (the unfiltered one's noise would stop it early at random), plus its
    /// rise over the filter's lag, the drives' lag (`2 zeta / wn`) and the
    /// braking (at `brake_decel_mps2`, v / 2a at the mean speed), once the
    /// move is in contact ([`in_contact`]).
    fn guarded_limit_reached(
        &self,
        t: &Trajectory,
        now_ns: u64,
        estimate: &CycleOutput,
    ) -> Option<Vec3> {
        let max_force_n = t.max_force_n?;
        let (force_n, std_n) = guarded_force(estimate)?;
        let speed_mps = t
            .at(now_ns)
            .iter()
            .fold(0.0, |m: f64, s| m.max(s.v_mps.abs()));
        let drives = &self.config.motion;
        let horizon_s =
            self.guarded_lag_s + drives.servo_lag_s() + speed_mps / (2.0 * drives.brake_decel_mps2);
        let m = force_n.norm();
        let contact = estimate
            .pose
            .zip(t.target_tip_m)
            .is_some_and(|(pose, target)| {
                in_contact(&force_n, &std_n, &(target - pose.tip_m), max_force_n)
            });
        let rise_n = if contact {
            self.guarded_rate_n_per_s.max(0.0) * horizon_s
        } else {
            0.0
        };
        (m + rise_n >= max_force_n).then_some(force_n)
    }

    /// The one brake: the trajectory under way, stopped from where it is at
    /// `now_ns`: `hard` (a guarded move's force) at `[axes]
    /// brake_decel_mps2`, streamed to the drives (their own planner runs the
    /// planned acceleration); else (the warn rule) at the planned
    /// deceleration, streamed if the move was.
    pub(super) fn braked(&self, t: &Trajectory, now_ns: u64, hard: bool) -> Trajectory {
        let mut limits = self.config.axis_limits;
        if hard {
            limits.max_accel_mps2 = self.config.motion.brake_decel_mps2;
        }
        let axes = t.at(now_ns).map(|s| AxisPlan::brake(now_ns, s, limits));
        let mut braked = Trajectory::from_plans(now_ns, axes, None);
        braked.streamed = t.streamed || hard;
        braked
    }
}

/// The tip force a guarded move watches and its standard deviation per
/// axis: the filtered one when the filter is on, else this cycle's
/// estimate; `None` without either.
pub(super) fn guarded_force(estimate: &CycleOutput) -> Option<(Vec3, Vec3)> {
    match (estimate.filtered, estimate.tip) {
        (Some(f), _) => Some((f.force_n, f.std_n)),
        (None, TipOutcome::Estimate(e)) => Some((e.force_n, e.std_n)),
        (None, _) => None,
    }
}

/// Whether a guarded move whose tip still has `to_target_m` to go is in
/// contact: the tip force's component along its way (what a passive tissue
/// it drives into pushes back with: the tip does work on it, `F . v > 0`) at
/// least a quarter of the move's limit and [`GUARDED_CONTACT_SIGMA`] of that
/// component's standard deviation (bounded by `sum |u_i| std_i`, whatever
/// the axes' correlation). Before it, the force's rate (its noise's
/// derivative, amplified by the horizon) anticipates nothing: in free air
/// the component is the filtered noise, a Gaussian process that crosses
/// `z sigma` upwards `f_c exp(-z^2 / 2)` times per second (Rice; for the
/// second-order Butterworth the ratio of the derivative's deviation to the
/// process's is `2 pi f_c`): at the 5 Hz filter and z = 6, 7.6e-8 per
/// second, 2.7e-4 per hour of guarded moves, and a crossing is needed, not
/// sufficient, to brake. The level alone (`|F| >= N`) brakes in any case.
fn in_contact(force_n: &Vec3, std_n: &Vec3, to_target_m: &Vec3, max_force_n: f64) -> bool {
    let distance_m = to_target_m.norm();
    // Arrived (or no finite way): no direction to be in contact along.
    if distance_m.is_nan() || distance_m <= 0.0 {
        return false;
    }
    let way = to_target_m / distance_m;
    let along_n = force_n.dot(&way);
    let std_along_n = way.abs().dot(std_n);
    along_n >= (0.25 * max_force_n).max(GUARDED_CONTACT_SIGMA * std_along_n)
}
