//! The per-cycle path: kinematics, tip force and the force-limit guard, once per
//! control cycle, with no allocation, no panic and no I/O.
//!
//! [`Estimator::cycle`] is what the daemon's fixed-rate loop calls every
//! millisecond with the latest sensor and joint samples; everything it needs is
//! fixed at construction.

use crate::guard::{
    Guard, GuardConfig, GuardInput, GuardState, Reason, ResetRefused, TipInput, Transition,
};
use crate::tip_force::{TipForceConfig, TipForceError, TipForceEstimate, TipForceEstimator};
use crate::{Calibration, Pose, Profile, SensorNoise, SettingError, Vec3};
use sar_kinematics::{ActiveJoints, PoseError, forward};

/// One force/torque sample as the sensor driver delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSample {
    /// Force, sensor frame, N, after count scaling, before bias removal.
    pub force_n: Vec3,
    /// Torque, sensor frame, N m.
    pub torque_nm: Vec3,
    /// Host monotonic time the sample was received, ns.
    pub stamp_ns: u64,
    /// The driver's word that the sample is good (device status, counter continuity).
    pub valid: bool,
}

/// One set of axis positions as the drive driver delivers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSample {
    /// q1, q2, q3, m.
    pub joints: ActiveJoints,
    /// Host monotonic time of the positions, ns.
    pub stamp_ns: u64,
    /// The driver's word that the positions are good.
    pub valid: bool,
}

/// What one cycle consumes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleInput {
    /// The cycle number; strictly increasing.
    pub cycle: u64,
    /// Host monotonic time now, ns.
    pub now_ns: u64,
    /// Latest sensor sample.
    pub sensor: SensorSample,
    /// Latest joint positions.
    pub joints: JointSample,
}

/// The tip force of one cycle, or why there is none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TipOutcome {
    /// A number, with its standard deviation.
    Estimate(TipForceEstimate),
    /// The estimator could not give a trustworthy number.
    Refused(TipForceError),
    /// The kinematics refused the pose.
    PoseInvalid(PoseError),
    /// The sensor sample was marked invalid, stamped in the future, or not finite.
    SensorInvalid,
    /// The joint positions were marked invalid or stamped in the future: no
    /// pose, no estimate.
    JointsInvalid,
}

/// What one cycle produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleOutput {
    /// The cycle number of the input.
    pub cycle: u64,
    /// The pose, when the kinematics gave one.
    pub pose: Option<Pose>,
    /// The tip force.
    pub tip: TipOutcome,
    /// now - sensor stamp, ns (0 for a stamp in the future, which is also invalid).
    pub sensor_age_ns: u64,
    /// now - joints stamp, ns.
    pub joints_age_ns: u64,
    /// The guard's state after this cycle.
    pub guard_state: GuardState,
    /// Why the guard is in that state.
    pub guard_reason: Reason,
    /// The guard's transition in this cycle, if any.
    pub transition: Option<Transition>,
}

/// Everything fixed at start for the per-cycle path.
#[derive(Debug, Clone, Copy)]
pub struct EstimatorConfig {
    /// The robot's calibration.
    pub calibration: Calibration,
    /// The manipulator in use.
    pub profile: Profile,
    /// The sensor's noise.
    pub noise: SensorNoise,
    /// The force-limit guard. Its `max_std_n` is also the tip-force
    /// estimator's limit of observability (one setting, one place).
    pub guard: GuardConfig,
}

/// Refuses a tare with a NaN or infinite component, reporting that component.
fn check_tare(bias_n: &Vec3) -> Result<(), SettingError> {
    crate::check_finite(bias_n, |value| SettingError::Invalid {
        field: "bias_n",
        value,
        why: "the tare must be finite",
    })
}

/// The per-cycle estimator: owns the tip-force estimator, the tare and the guard.
#[derive(Debug, Clone)]
pub struct Estimator {
    calibration: Calibration,
    profile: Profile,
    tip: TipForceEstimator,
    guard: Guard,
    bias_n: Vec3,
    last: CycleOutput,
    /// `now_ns` of the previous cycle: time must advance from cycle to cycle.
    last_now_ns: Option<u64>,
}

impl Estimator {
    /// Builds the estimator; `bias_n` is the sensor's tare (sensor frame, N).
    pub fn new(config: &EstimatorConfig, bias_n: Vec3) -> Result<Self, SettingError> {
        check_tare(&bias_n)?;
        let guard = Guard::new(config.guard);
        let last = CycleOutput {
            cycle: 0,
            pose: None,
            tip: TipOutcome::SensorInvalid,
            sensor_age_ns: u64::MAX,
            joints_age_ns: u64::MAX,
            guard_state: guard.state(),
            guard_reason: guard.reason(),
            transition: None,
        };
        Ok(Self {
            calibration: config.calibration,
            profile: config.profile,
            tip: TipForceEstimator::new(
                &config.calibration,
                &config.profile,
                &config.noise,
                TipForceConfig {
                    max_std_n: config.guard.limits().max_std_n,
                },
            )?,
            guard,
            bias_n,
            last,
            last_now_ns: None,
        })
    }

    /// Runs one control cycle and returns its result, which stays readable as
    /// [`Estimator::last`] until the next cycle (written in place: no copy of
    /// the large output on the loop's path).
    pub fn cycle(&mut self, input: &CycleInput) -> &CycleOutput {
        let sensor_age_ns = input.now_ns.saturating_sub(input.sensor.stamp_ns);
        let joints_age_ns = input.now_ns.saturating_sub(input.joints.stamp_ns);
        // A clock that does not advance (stuck, or gone back) makes every age
        // meaningless: no input is trusted in such a cycle.
        let clock_advances = self.last_now_ns.is_none_or(|last| input.now_ns > last);
        self.last_now_ns = Some(input.now_ns);
        // A sample stamped in the future, or with a non-finite force, is invalid
        // whatever the driver said.
        let sensor_valid = clock_advances
            && input.sensor.valid
            && input.sensor.stamp_ns <= input.now_ns
            && input.sensor.force_n.iter().all(|x| x.is_finite());
        let joints_valid =
            clock_advances && input.joints.valid && input.joints.stamp_ns <= input.now_ns;
        let out = &mut self.last;
        out.cycle = input.cycle;
        out.sensor_age_ns = sensor_age_ns;
        out.joints_age_ns = joints_age_ns;
        let pose = if joints_valid {
            Some(forward(
                &self.calibration,
                &self.profile,
                &input.joints.joints,
            ))
        } else {
            None
        };
        let tip_input = match pose {
            None => {
                out.pose = None;
                out.tip = TipOutcome::JointsInvalid;
                TipInput::NotObservable
            }
            Some(Err(e)) => {
                out.pose = None;
                out.tip = TipOutcome::PoseInvalid(e);
                TipInput::PoseInvalid
            }
            Some(Ok(pose)) => {
                let pose = out.pose.insert(pose);
                if !sensor_valid {
                    out.tip = TipOutcome::SensorInvalid;
                    TipInput::NotObservable
                } else {
                    match self.tip.estimate(pose, &input.sensor.force_n, &self.bias_n) {
                        Ok(estimate) => {
                            out.tip = TipOutcome::Estimate(estimate);
                            TipInput::Estimate {
                                force_n: estimate.force_n,
                                std_n: estimate.std_n,
                                rod_dir: pose.rod_dir,
                            }
                        }
                        Err(e) => {
                            out.tip = TipOutcome::Refused(e);
                            TipInput::NotObservable
                        }
                    }
                }
            }
        };
        out.transition = self.guard.step(&GuardInput {
            cycle: input.cycle,
            sensor_age_ns,
            sensor_valid,
            joints_age_ns,
            joints_valid,
            tip: tip_input,
        });
        out.guard_state = self.guard.state();
        out.guard_reason = self.guard.reason();
        &self.last
    }

    /// The result of the last cycle (before the first: no pose, no input, the
    /// guard's initial state).
    pub fn last(&self) -> &CycleOutput {
        &self.last
    }

    /// Asks the guard to leave Stop or Fault; refused while the cause persists.
    pub fn reset_guard(&mut self, cycle: u64) -> Result<Option<Transition>, ResetRefused> {
        self.guard.reset(cycle)
    }

    /// Replaces the tare (sensor frame, N). Refuses a non-finite one.
    pub fn set_bias(&mut self, bias_n: Vec3) -> Result<(), SettingError> {
        check_tare(&bias_n)?;
        self.bias_n = bias_n;
        Ok(())
    }

    /// The guard's state.
    pub fn guard_state(&self) -> GuardState {
        self.guard.state()
    }
}
