//! What the step derives from a cycle's input before the estimator judges
//! it: the trajectory as the cycle finds it (a late cycle absorbed), the
//! following reference, the axes' speed, the carriage's motion and the
//! host's faults. Queries, but for the axes' speed
//! ([`LoopStep::measure_speed`], an explicit update): what they would change
//! (the servo model advanced, the drives' state remembered) they return, for
//! the commit point.

use super::LoopStep;
use super::config::REST_SPEED_MPS;
use super::trajectory::Trajectory;
use super::vocabulary::LoopInput;
use crate::motion::AxesMotion;
use sar_estimator::cycle::{FollowingReference, JointSample};
use sar_estimator::guard::Reason;
use sar_estimator::motion::CarriageMotion;
use sar_hal::DriveState;
use sar_kinematics::ActiveJoints;

impl LoopStep {
    /// The trajectory as this cycle finds it. A cycle later than one period
    /// after the last streamed set point finds the streamed trajectory
    /// delayed by the excess, before anything evaluates it, so that this
    /// cycle's set point is one period of its time after the last one (the
    /// drives held that one meanwhile, as the servo model knows: it follows
    /// the set points as streamed). The set points never jump by the time
    /// the loop was late; the trajectory ends that much later. An early
    /// cycle delays nothing (its set point comes less than a period after
    /// the last: slower, never faster).
    pub(super) fn absorb_late_cycle(&self, input: &LoopInput) -> Option<Trajectory> {
        let mut found = self.trajectory;
        let (Some(last_ns), Some(now_ns)) = (self.last_stream_ns, input.now_ns) else {
            return found;
        };
        let late_ns = now_ns
            .saturating_sub(last_ns)
            .saturating_sub(self.config.period_ns);
        if let Some(t) = &mut found
            && t.streamed
            && late_ns > 0
        {
            t.delay(late_ns);
        }
        found
    }

    /// The carriage's motion where the sensor sample was measured (its
    /// stamp less the sensor's latency), from the trajectory commanded so
    /// far and the drives' quick stop ([`crate::motion`]); with the model of
    /// the axes advanced to it (the commit point keeps it).
    pub(super) fn carriage_motion(
        &self,
        input: &LoopInput,
        trajectory: Option<&Trajectory>,
    ) -> (CarriageMotion, AxesMotion) {
        let mut axes = self.motion;
        if let Some(m) = self.excitation_motion(input, trajectory) {
            return (m, axes);
        }
        axes.measured(&input.joints);
        let motion = axes.motion(
            &self.config.motion,
            self.config.axis_limits.max_accel_mps2,
            trajectory.map(|t| &t.axes),
            input.drive_state,
            input
                .sensor
                .stamp_ns
                .saturating_sub(self.config.motion.sensor_latency_ns),
            self.speed_mps <= REST_SPEED_MPS,
        );
        (motion, axes)
    }

    /// An excitation's own motion for ideal drives (no servo model, which
    /// otherwise follows its streamed set points), at the sensor sample's
    /// instant; `None` otherwise.
    fn excitation_motion(
        &self,
        input: &LoopInput,
        trajectory: Option<&Trajectory>,
    ) -> Option<CarriageMotion> {
        let e = trajectory?.excite?;
        let ideal = self.config.motion.servo_wn_rad_s() <= 0.0;
        let enabled = input.drive_state == Some(DriveState::Enabled);
        let stamp_ns = (input.sensor.stamp_ns).saturating_sub(self.config.motion.sensor_latency_ns);
        (ideal && enabled && self.motion.halt.is_none()).then(|| e.carriage_motion(stamp_ns))
    }

    /// The trajectory at the joint sample's stamp, which the estimator
    /// checks the joints against (following error), or during the drives'
    /// quick stop its profile; none without either or a valid sample.
    pub(super) fn following_reference(
        &self,
        input: &LoopInput,
        trajectory: Option<&Trajectory>,
    ) -> Option<FollowingReference> {
        let tolerance_m = self.config.following_tolerance_m;
        if !input.joints.valid {
            return None;
        }
        let stamp_ns = input.joints.stamp_ns;
        if let Some(t) = trajectory {
            return Some(FollowingReference {
                joints: t.position(stamp_ns),
                tolerance_m,
            });
        }
        // During the drives' own quick stop: its profile at the configured
        // deceleration (a drive that brakes weaker runs on beyond it).
        if input.drive_state != Some(DriveState::QuickStop) {
            return None;
        }
        self.motion
            .halt_position(stamp_ns)
            .map(|[q1_m, q2_m, q3_m]| FollowingReference {
                joints: ActiveJoints { q1_m, q2_m, q3_m },
                tolerance_m,
            })
    }

    /// Updates the axes' speed from the last two valid joint samples.
    pub(super) fn measure_speed(&mut self, joints: &JointSample) {
        let q = &joints.joints;
        if joints.valid && [q.q1_m, q.q2_m, q.q3_m].iter().all(|v| v.is_finite()) {
            if let Some((p, stamp_ns)) = self.last_joints
                && joints.stamp_ns > stamp_ns
            {
                let dt_s = (joints.stamp_ns - stamp_ns) as f64 * 1e-9;
                self.speed_mps = [q.q1_m - p.q1_m, q.q2_m - p.q2_m, q.q3_m - p.q3_m]
                    .iter()
                    .fold(0.0, |m: f64, d| m.max(d.abs() / dt_s));
            }
            self.last_joints = Some((*q, joints.stamp_ns));
        }
    }

    /// The host's own faults: the publishing thread stalled; the drives
    /// entering Fault (latched by the guard in that cycle only: the reset
    /// that leaves it is what resets the drives), against the drives' state
    /// of the previous cycle (the commit point remembers this one's).
    pub(super) fn host_fault(&self, input: &LoopInput) -> Option<Reason> {
        let drive_fault = match (self.last_drive_state, input.drive_state) {
            (Some(DriveState::Fault { .. }), _) => None,
            (_, Some(DriveState::Fault { axis, code })) => Some(Reason::DriveFault {
                axis: axis.map_or(0, |a| a.saturating_add(1)),
                code,
            }),
            _ => None,
        };
        (input.publisher_idle_ns > self.config.publisher_stall_ns)
            .then(|| Reason::PublisherStalled {
                stalled_ms: u32::try_from(input.publisher_idle_ns / 1_000_000).unwrap_or(u32::MAX),
            })
            .or(drive_fault)
    }
}
