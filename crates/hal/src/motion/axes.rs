//! Motion of one axis: a time-optimal profile with a speed and an
//! acceleration limit (accelerate, cruise, brake; a trapezoid or a triangle),
//! planned in closed form from the present position and velocity whenever the
//! target changes, and evaluated exactly at any later time. The simulator's
//! axes move on it; the scenario checks and the runner's timeouts take their
//! move times from it.
//!
//! Planning in closed form (rather than integrating step by step) gives an
//! arrival exactly at the target, without overshoot or chatter, and positions at
//! any instant that do not depend on how often the simulator is polled.

use crate::convert::ns_to_s;

/// One phase of constant acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Phase {
    duration_s: f64,
    accel_mps2: f64,
}

/// A planned motion: phases of constant acceleration from `(x0_m, v0_mps)` at
/// `start_ns`, then a hold at `end_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisPlan {
    start_ns: u64,
    x0_m: f64,
    v0_mps: f64,
    phases: [Phase; 3],
    end_m: f64,
}

/// Position and velocity of an axis at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisState {
    /// m.
    pub x_m: f64,
    /// m/s.
    pub v_mps: f64,
}

/// The limits of an axis (both finite and > 0, checked by the simulator).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// m/s.
    pub max_speed_mps: f64,
    /// m/s^2.
    pub max_accel_mps2: f64,
}

impl AxisPlan {
    /// At rest at `x_m` from `start_ns` on.
    pub fn hold(start_ns: u64, x_m: f64) -> Self {
        Self {
            start_ns,
            x0_m: x_m,
            v0_mps: 0.0,
            phases: [Phase::default(); 3],
            end_m: x_m,
        }
    }

    /// Brake at the acceleration limit from `state` at `start_ns`, then hold.
    pub fn brake(start_ns: u64, state: AxisState, limits: Limits) -> Self {
        let a = limits.max_accel_mps2;
        let v0 = state.v_mps;
        if v0 == 0.0 {
            return Self::hold(start_ns, state.x_m);
        }
        let phase = Phase {
            duration_s: v0.abs() / a,
            accel_mps2: -v0.signum() * a,
        };
        Self {
            start_ns,
            x0_m: state.x_m,
            v0_mps: v0,
            phases: [phase, Phase::default(), Phase::default()],
            end_m: state.x_m + v0 * v0.abs() / (2.0 * a),
        }
    }

    /// One period of cyclic synchronous position (a set point streamed per
    /// period, CiA 402 CSP): from `from_m` at `start_ns` at constant speed
    /// to `to_m` after `period_ns` (> 0), then a hold there until the next
    /// set point. The speed jumps from period to period, as an ideal servo's
    /// interpolated reference does; a set point farther than the axis's
    /// speed allows is the caller's to refuse.
    pub fn segment(start_ns: u64, from_m: f64, to_m: f64, period_ns: u64) -> Self {
        let duration_s = ns_to_s(period_ns.max(1));
        Self {
            start_ns,
            x0_m: from_m,
            v0_mps: (to_m - from_m) / duration_s,
            phases: [
                Phase {
                    duration_s,
                    accel_mps2: 0.0,
                },
                Phase::default(),
                Phase::default(),
            ],
            end_m: to_m,
        }
    }

    /// The time-optimal motion from `state` at `start_ns` to rest at `target_m`.
    ///
    /// When the target lies closer than the stopping distance, the axis brakes,
    /// passes it and comes back (the only possible motion within the limits);
    /// otherwise it never passes the target.
    pub fn to_target(start_ns: u64, state: AxisState, target_m: f64, limits: Limits) -> Self {
        let a = limits.max_accel_mps2;
        let v_max = limits.max_speed_mps;
        let (x0, v0) = (state.x_m, state.v_mps);
        let e = target_m - x0;
        let beyond_stop = e - v0 * v0.abs() / (2.0 * a);
        if beyond_stop == 0.0 {
            if v0 == 0.0 {
                return Self::hold(start_ns, target_m);
            }
            let mut plan = Self::brake(start_ns, state, limits);
            plan.end_m = target_m;
            return plan;
        }
        // Work along the direction s in which the axis must accelerate first.
        let s = beyond_stop.signum();
        let distance = s * e;
        let w0 = (s * v0).min(v_max);
        let peak_sq = a * distance + 0.5 * w0 * w0;
        let peak = peak_sq.max(0.0).sqrt();
        let phases = if peak <= v_max {
            [
                Phase {
                    duration_s: ((peak - w0) / a).max(0.0),
                    accel_mps2: s * a,
                },
                Phase::default(),
                Phase {
                    duration_s: peak / a,
                    accel_mps2: -s * a,
                },
            ]
        } else {
            let accel_m = (v_max * v_max - w0 * w0) / (2.0 * a);
            let brake_m = v_max * v_max / (2.0 * a);
            let cruise_m = (distance - accel_m - brake_m).max(0.0);
            [
                Phase {
                    duration_s: ((v_max - w0) / a).max(0.0),
                    accel_mps2: s * a,
                },
                Phase {
                    duration_s: cruise_m / v_max,
                    accel_mps2: 0.0,
                },
                Phase {
                    duration_s: v_max / a,
                    accel_mps2: -s * a,
                },
            ]
        };
        Self {
            start_ns,
            x0_m: x0,
            v0_mps: v0,
            phases,
            end_m: target_m,
        }
    }

    /// Position and velocity at `t_ns` (>= the plan's start; earlier times
    /// give the start).
    pub fn at(&self, t_ns: u64) -> AxisState {
        self.after_s(ns_to_s(t_ns.saturating_sub(self.start_ns)))
    }

    /// Position and velocity `elapsed_s` after the plan's start (>= 0).
    pub fn after_s(&self, elapsed_s: f64) -> AxisState {
        // The trajectory's times, which the step trusts: elapsed time is a
        // time, each phase lasts a finite, non-negative time.
        debug_assert!(elapsed_s >= 0.0, "elapsed {elapsed_s} s before the plan");
        debug_assert!(
            self.phases
                .iter()
                .all(|p| p.duration_s.is_finite() && p.duration_s >= 0.0),
            "a phase of {self:?} has no valid duration"
        );
        let mut left_s = elapsed_s;
        let (mut x, mut v) = (self.x0_m, self.v0_mps);
        for phase in &self.phases {
            let a = phase.accel_mps2;
            if left_s <= phase.duration_s {
                return AxisState {
                    x_m: x + v * left_s + 0.5 * a * left_s * left_s,
                    v_mps: v + a * left_s,
                };
            }
            let dt = phase.duration_s;
            x += v * dt + 0.5 * a * dt * dt;
            v += a * dt;
            left_s -= dt;
        }
        AxisState {
            x_m: self.end_m,
            v_mps: 0.0,
        }
    }

    /// The acceleration at `t_ns` (>= the plan's start), m/s^2: that of the
    /// phase [`AxisPlan::at`] evaluates there (a phase's end belongs to it),
    /// 0 once the plan holds.
    pub fn accel_at(&self, t_ns: u64) -> f64 {
        let mut left_s = ns_to_s(t_ns.saturating_sub(self.start_ns));
        for phase in &self.phases {
            if left_s <= phase.duration_s {
                return phase.accel_mps2;
            }
            left_s -= phase.duration_s;
        }
        0.0
    }

    /// Whether the plan holds at `t_ns` (its phases are over: the instant
    /// a phase ends still belongs to it, as in [`AxisPlan::at`]).
    pub fn holds_at(&self, t_ns: u64) -> bool {
        let mut left_s = ns_to_s(t_ns.saturating_sub(self.start_ns));
        for phase in &self.phases {
            if left_s <= phase.duration_s {
                return false;
            }
            left_s -= phase.duration_s;
        }
        true
    }

    /// The velocity's step where the plan starts to hold, m/s: minus the
    /// speed at the end of its phases (a [`AxisPlan::segment`]'s own speed;
    /// a move to a target or a brake ends at rest, so about 0).
    pub fn end_step_mps(&self) -> f64 {
        -self.after_s(self.duration_s()).v_mps
    }

    /// The same motion `dt_ns` later (its start moved on; saturating): what
    /// a streamed trajectory becomes when the loop came late and its next
    /// set point follows the last one by one period (issue 33).
    pub fn delayed(&self, dt_ns: u64) -> Self {
        Self {
            start_ns: self.start_ns.saturating_add(dt_ns),
            ..*self
        }
    }

    /// Where the plan ends (and holds), m.
    pub fn end_m(&self) -> f64 {
        self.end_m
    }

    /// Time from the plan's start to its end, s.
    pub fn duration_s(&self) -> f64 {
        self.phases.iter().map(|p| p.duration_s).sum()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    const LIMITS: Limits = Limits {
        max_speed_mps: 0.05,
        max_accel_mps2: 0.5,
    };

    fn sweep(plan: &AxisPlan, until_ns: u64, step_ns: u64) -> Vec<AxisState> {
        (0..=until_ns / step_ns)
            .map(|k| plan.at(k * step_ns))
            .collect()
    }

    fn check_limits(states: &[AxisState], step_ns: u64) {
        let dt = step_ns as f64 * 1e-9;
        for pair in states.windows(2) {
            assert!(pair[1].v_mps.abs() <= LIMITS.max_speed_mps * (1.0 + 1e-12));
            let accel = (pair[1].v_mps - pair[0].v_mps) / dt;
            assert!(
                accel.abs() <= LIMITS.max_accel_mps2 * (1.0 + 1e-9),
                "{accel}"
            );
            // Positions are consistent with the velocities (trapezoid rule is
            // exact for piecewise-constant acceleration within a step, up to
            // a phase change inside the step).
            let mid = 0.5 * (pair[0].v_mps + pair[1].v_mps) * dt;
            let dx = pair[1].x_m - pair[0].x_m;
            assert!(
                (dx - mid).abs() <= LIMITS.max_accel_mps2 * dt * dt,
                "{dx} vs {mid}"
            );
        }
    }

    #[test]
    fn trapezoid_arrives_exactly_without_overshoot() {
        let start = AxisState {
            x_m: 0.01,
            v_mps: 0.0,
        };
        let plan = AxisPlan::to_target(0, start, 0.11, LIMITS);
        let states = sweep(&plan, 3_000_000_000, 100_000);
        check_limits(&states, 100_000);
        assert!(states.iter().all(|s| s.x_m <= 0.11 + 1e-15));
        // 0.1 m at 0.05 m/s with 0.1 s ramps: 2.1 s.
        let arrival = states.iter().position(|s| s.x_m == 0.11).unwrap();
        assert!((arrival as f64 * 1e-4 - 2.1).abs() < 2e-4, "{arrival}");
        assert_eq!(states.last().unwrap().v_mps, 0.0);
    }

    #[test]
    fn triangle_and_reversal_respect_the_limits() {
        // Short move: never reaches the speed limit.
        let plan = AxisPlan::to_target(
            0,
            AxisState {
                x_m: 0.0,
                v_mps: 0.0,
            },
            -0.002,
            LIMITS,
        );
        let states = sweep(&plan, 500_000_000, 100_000);
        check_limits(&states, 100_000);
        let peak = states.iter().map(|s| s.v_mps.abs()).fold(0.0, f64::max);
        assert!((peak - (0.5f64 * 0.002).sqrt()).abs() < 1e-4 && peak < 0.05);
        assert!(states.iter().all(|s| s.x_m >= -0.002 - 1e-15));
        // Moving away from the target at full speed: brake, come back.
        let plan = AxisPlan::to_target(
            0,
            AxisState {
                x_m: 0.0,
                v_mps: 0.05,
            },
            -0.01,
            LIMITS,
        );
        let states = sweep(&plan, 1_500_000_000, 100_000);
        check_limits(&states, 100_000);
        assert_eq!(states.last().unwrap().x_m, -0.01);
        let furthest = states.iter().map(|s| s.x_m).fold(f64::MIN, f64::max);
        assert!((furthest - 0.0025).abs() < 1e-6, "{furthest}");
    }

    #[test]
    fn brake_stops_at_the_stopping_point() {
        let state = AxisState {
            x_m: 0.2,
            v_mps: -0.04,
        };
        let plan = AxisPlan::brake(1_000, state, LIMITS);
        let stop = 0.2 - 0.04 * 0.04 / (2.0 * 0.5);
        let end = plan.at(1_000 + 80_000_000);
        assert_eq!(end.v_mps, 0.0);
        assert!((end.x_m - stop).abs() < 1e-15);
        assert!((plan.end_m() - stop).abs() < 1e-15);
        assert_eq!(plan.at(1_000 + 80_000_001).x_m, plan.end_m());
        let mid = plan.at(1_000 + 40_000_000);
        assert!((mid.v_mps + 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_segment_holds_after_its_period_and_its_speed_steps_to_zero() {
        let plan = AxisPlan::segment(5_000, 0.1, 0.1002, 1_000_000);
        // The period's last instant still moves (as `at` evaluates it).
        assert!(!plan.holds_at(0));
        assert!(!plan.holds_at(1_005_000));
        assert!(plan.holds_at(1_005_001));
        let v_mps = plan.at(1_005_000).v_mps;
        assert!((v_mps - 0.2).abs() < 1e-9, "{v_mps}");
        assert_eq!(plan.at(1_005_001).v_mps, 0.0);
        assert_eq!(plan.end_step_mps(), -v_mps);
        // A move to a target ends at rest (no step); a hold has none.
        let rest = AxisState {
            x_m: 0.0,
            v_mps: 0.0,
        };
        let to = AxisPlan::to_target(0, rest, 0.01, LIMITS);
        assert!(to.end_step_mps().abs() < 1e-12);
        assert!(!to.holds_at(100_000_000) && to.holds_at(10_000_000_000));
        assert_eq!(AxisPlan::hold(0, 0.1).end_step_mps(), 0.0);
    }
}

// Snapshots (issue 17): a plan is stored whole (the loop's trajectory).
sar_snapshot::snap_struct!(Phase {
    duration_s,
    accel_mps2,
});
sar_snapshot::snap_struct!(AxisPlan {
    start_ns,
    x0_m,
    v0_mps,
    phases,
    end_m,
});
// The snapshot's configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(Limits {
    max_speed_mps,
    max_accel_mps2
});
