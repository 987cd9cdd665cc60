//! The simulated drives: positions, state, faults injected, enable,
//! disable, targets and streamed set points, quick stop and fault reset.

use super::World;
use super::validate::{check_fault, fault_start_ns};
use crate::SimError;
use crate::spec::Fault;
use sar_hal::convert::{joints_to_array, ns_to_s};
use sar_hal::motion::{AxisPlan, SlideSign};
use sar_hal::{Clock, DriveState, JointPositions};
use sar_kinematics::{ActiveJoints, forward};

impl<C: Clock> World<C> {
    /// The sign of the last slide (unknown before any slide).
    pub fn slide_sign(&self) -> SlideSign {
        self.slide.sign()
    }

    /// The latest position report.
    pub fn positions(&self) -> JointPositions {
        self.positions
    }

    /// The drives' state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Adds a fault; it must start after the present time.
    pub fn inject(&mut self, fault: Fault) -> Result<(), SimError> {
        check_fault(self.faults.len(), &fault)?;
        let at_ns = fault_start_ns(&fault);
        if at_ns <= self.done_ns {
            return Err(SimError::FaultNotInFuture {
                at_ns,
                elapsed_ns: self.done_ns,
            });
        }
        self.faults.push((fault, false));
        Ok(())
    }

    // Commands (at the present time, after `advance`).

    /// `Ready -> Enabled`.
    pub fn enable(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Ready | DriveState::Enabled => {
                // The axes keep their present plan (a hold, or the stop that
                // followed a disable): enabling does not move them.
                self.state = DriveState::Enabled;
                Ok(())
            }
            state => Err(SimError::InvalidState {
                command: "enable",
                state,
            }),
        }
    }

    /// `Enabled | QuickStop -> Ready`; the axes brake to a stop.
    pub fn disable(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Enabled | DriveState::QuickStop => {
                self.state = DriveState::Ready;
                self.brake_all(self.done_ns, self.limits.max_accel_mps2);
                Ok(())
            }
            DriveState::Ready => Ok(()),
            state @ DriveState::Fault { .. } => Err(SimError::InvalidState {
                command: "disable",
                state,
            }),
        }
    }

    /// New targets (only while `Enabled`).
    pub fn set_targets(&mut self, targets: &ActiveJoints) -> Result<(), SimError> {
        let wanted = self.check_targets("set_targets", targets)?;
        let now = self.done_ns;
        let limits = self.limits;
        self.servos_follow(now);
        let states = self.reference_at(now);
        let mut plans = self.plans;
        for ((plan, state), target) in plans.iter_mut().zip(states).zip(wanted) {
            *plan = AxisPlan::to_target(now, state, target, limits);
        }
        self.replace_plans(now, plans);
        Ok(())
    }

    /// A cyclic set point (only while `Enabled`): each axis moves at constant
    /// speed from where it is to its set point in `period_ns` and holds
    /// there (an ideal CSP servo; with servos, their reference). A set point
    /// beyond the speed limit over the period (from the reference) is refused.
    pub fn stream(&mut self, targets: &ActiveJoints, period_ns: u64) -> Result<(), SimError> {
        let wanted = self.check_targets("stream", targets)?;
        let now = self.done_ns;
        self.servos_follow(now);
        let states = self.reference_at(now);
        let speed_mps = self
            .spec
            .axes
            .drive_max_speed_mps
            .unwrap_or(self.limits.max_speed_mps);
        let reach_m = speed_mps * ns_to_s(period_ns.max(1)) * (1.0 + 1e-9);
        for (axis, (state, target)) in states.iter().zip(wanted).enumerate() {
            if (target - state.x_m).abs() > reach_m {
                return Err(SimError::SetPointTooFar {
                    axis,
                    distance_m: (target - state.x_m).abs(),
                    reach_m,
                });
            }
        }
        let mut plans = self.plans;
        for ((plan, state), target) in plans.iter_mut().zip(states).zip(wanted) {
            *plan = AxisPlan::segment(now, state.x_m, target, period_ns);
        }
        self.replace_plans(now, plans);
        Ok(())
    }

    /// Checks targets for `command`: Enabled, finite, within the travel, a
    /// pose the kinematics accepts.
    pub(super) fn check_targets(
        &self,
        command: &'static str,
        targets: &ActiveJoints,
    ) -> Result<[f64; 3], SimError> {
        if self.state != DriveState::Enabled {
            return Err(SimError::InvalidState {
                command,
                state: self.state,
            });
        }
        let wanted = joints_to_array(targets);
        for (axis, (&value_m, &(min_m, max_m))) in wanted
            .iter()
            .zip(self.spec.axes.travel_m.iter())
            .enumerate()
        {
            if !value_m.is_finite() {
                return Err(SimError::TargetNonFinite { axis, value_m });
            }
            if !(min_m..=max_m).contains(&value_m) {
                return Err(SimError::TargetOutOfTravel {
                    axis,
                    target_m: value_m,
                    min_m,
                    max_m,
                });
            }
        }
        forward(
            &self.calibration_at(self.done_ns),
            &self.spec.profile,
            targets,
        )
        .map_err(SimError::TargetPose)?;
        Ok(wanted)
    }

    /// Quick stop: brake at the quick-stop deceleration (the acceleration
    /// limit when none is given) and hold (a fault stays a fault).
    pub fn quick_stop(&mut self) -> Result<(), SimError> {
        if !matches!(self.state, DriveState::Fault { .. }) {
            self.state = DriveState::QuickStop;
            let decel = self.spec.plant.quick_stop_decel_mps2;
            self.brake_all(self.done_ns, decel.unwrap_or(self.limits.max_accel_mps2));
        }
        Ok(())
    }

    /// `Fault -> Ready` (the simulated cause is gone at once).
    pub fn fault_reset(&mut self) -> Result<(), SimError> {
        match self.state {
            DriveState::Fault { .. } => {
                self.state = DriveState::Ready;
                Ok(())
            }
            state => Err(SimError::InvalidState {
                command: "fault_reset",
                state,
            }),
        }
    }
}
