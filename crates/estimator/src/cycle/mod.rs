//! The per-cycle path: input plausibility, kinematics, tip force, the
//! force-limit guard and the operator's commands, once per control cycle, with
//! no allocation, no panic and no I/O. [`Estimator::cycle`] is its one entry
//! point, a pipeline of named phases (this file); each idea it draws on is a
//! file of this folder: `vocabulary` (what a cycle consumes and produces),
//! `plausibility` (the checks' settings) and `frozen` (the frozen-sensor
//! check's statistics), `input_checks` (the inputs' plausibility),
//! `torque_residual` (the sensor torque against the model), `tare` (the bias
//! over a mean at rest), `mounting` (the first reset's check of the wrench at
//! rest) and `command` (the operator's commands). Their items are public
//! here, under `cycle`, whatever file holds them.
//!
//! Design rule: everything [`Estimator::cycle`] decides is a pure function of
//! the recorded inputs ([`CycleInput`]: the clock reading, the sensor sample
//! with its counter and status, the joint sample and the command of that
//! cycle; and [`CycleContext`], which the caller derives from inputs it
//! records) and of the estimator's state, which is itself built only from
//! earlier inputs. A recording of the inputs therefore replays to the same
//! decisions bit for bit. There is no other way to change the estimator's
//! state: a reset, a tare and a new bias are [`Command`]s of a cycle, judged on
//! that cycle's fresh input after it has been evaluated, and reported in its
//! [`CycleOutput::command`] as accepted or refused with a typed reason.

mod command;
mod frozen;
mod input_checks;
mod mounting;
mod plausibility;
mod tare;
mod torque_residual;
mod vocabulary;

pub use frozen::{
    FROZEN_NOISE_FRACTION, SAMPLES_IN_TEN_YEARS_1KHZ, frozen_false_alarms_in_ten_years,
    frozen_repeat_probability, frozen_repeats,
};
pub use plausibility::{
    FrozenCheck, MountingLimits, PlausibilityConfig, PlausibilityLimits, SensorRange, SpikeLimits,
    TareLimits, TorqueLimits,
};
pub use vocabulary::{
    Bias, Command, CommandAccepted, CommandEvent, CommandRefused, CycleContext, CycleInput,
    CycleOutput, DrainedSamples, FollowingReference, JointSample, SensorSample, TareRefused,
    TipOutcome, TorqueResidual,
};

use crate::filter::{FilterConfig, TipFilter};
use crate::guard::{Guard, GuardConfig, GuardInput, GuardState, Reason, TipInput};
use crate::inertial::RodInertia;
use crate::motion::CarriageMotion;
use crate::tip_force::{TipForceConfig, TipForceEstimator};
use crate::{Calibration, Profile, SensorNoise, SettingError, Vec3};
use input_checks::InputChecks;
use mounting::RestMean;
use sar_kinematics::{ActiveJoints, forward};
use tare::{TareMean, TareStatus};
use torque_residual::{SensorFrame, TorqueCheck, torque_residual, torque_verdict, widened};

/// Everything fixed at start for the per-cycle path.
#[derive(Debug, Clone, Copy)]
pub struct EstimatorConfig {
    /// The robot's calibration.
    pub calibration: Calibration,
    /// The manipulator in use.
    pub profile: Profile,
    /// The sensor's force noise.
    pub noise: SensorNoise,
    /// The tip-force estimator's settings (its observability limit; default
    /// [`TipForceConfig::DEFAULT_MAX_STD_N`]). The guard acts on its flag.
    pub tip: TipForceConfig,
    /// The force-limit guard.
    pub guard: GuardConfig,
    /// The input plausibility checks.
    pub plausibility: PlausibilityConfig,
    /// The tip-force low-pass beside the unfiltered estimate (`None`: none).
    /// Its `sample_period_s` is the sensor's sample period.
    pub filter: Option<FilterConfig>,
    /// The rod's inertia and the adapter's mass, for the tip force in motion
    /// ([`CycleContext::motion`], MODEL.md 10). The stated default when
    /// nothing was measured: [`RodInertia::slender_rod`].
    pub inertia: RodInertia,
}

/// The per-cycle estimator: owns the tip-force estimator, the bias, the
/// guard and what the plausibility checks remember of earlier cycles.
#[derive(Debug, Clone)]
pub struct Estimator {
    calibration: Calibration,
    profile: Profile,
    tip: TipForceEstimator,
    frame: SensorFrame,
    filter: Option<TipFilter>,
    guard: Guard,
    limits: PlausibilityLimits,
    torque: Option<TorqueCheck>,
    bias: Bias,
    last: CycleOutput,
    /// The largest `now_ns` seen: time must advance from cycle to cycle.
    last_now_ns: Option<u64>,
    /// The sensor counter of the previous cycle.
    last_counter: Option<u32>,
    /// The stamp of the sample that first carried `last_counter`, ns.
    counter_stamp_ns: u64,
    /// The previous valid, finite joint sample and its stamp.
    last_joints: Option<(ActiveJoints, u64)>,
    /// The force noise per sensor axis, N (the spike threshold's unit).
    noise_n: Vec3,
    /// The six values of the previous new sample, as bits (frozen check).
    last_values: Option<[u64; 6]>,
    /// New samples in a row identical to the one before them.
    repeats: u32,
    /// The force of the previous new finite sample, sensor frame, N (spikes).
    last_force_n: Option<Vec3>,
    /// Spikes in the current window.
    spikes: u32,
    /// New samples left in the current spike window (0: no window open).
    spike_window_left: u32,
    /// `now_ns` of the cycle whose tare (or start bias) is in use.
    tare_ns: Option<u64>,
    /// The means at rest, kept until the first reset is accepted.
    rest: RestMean,
    /// The mean reading at rest a tare is taken over.
    tare_mean: TareMean,
    /// `now_ns` of the last accepted tare (the rate limit).
    last_tare_ns: Option<u64>,
}

/// How old the inputs are and whether they may be used
/// ([`Estimator::freshness`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Freshness {
    /// now - stamp of the sample that first carried the current counter, ns.
    sensor_age_ns: Option<u64>,
    /// now - joints stamp, ns.
    joints_age_ns: Option<u64>,
    /// Marked valid, stamped no later than now, and finite.
    sensor_valid: bool,
    /// Marked valid and stamped no later than now.
    joints_valid: bool,
}

impl Estimator {
    /// Builds the estimator with a force bias `bias_n` (sensor frame, N) and
    /// no torque bias.
    pub fn new(config: &EstimatorConfig, bias_n: Vec3) -> Result<Self, SettingError> {
        Self::with_bias(config, Bias::force_only(bias_n))
    }

    /// Builds the estimator with the sensor's bias (sensor frame).
    pub fn with_bias(config: &EstimatorConfig, bias: Bias) -> Result<Self, SettingError> {
        bias.check().map_err(|value| SettingError::Invalid {
            field: "bias",
            value,
            why: "the tare must be finite",
        })?;
        let guard = Guard::new(config.guard);
        let limits = config.plausibility.limits();
        let last = CycleOutput {
            cycle: 0,
            pose: None,
            tip: TipOutcome::SensorInvalid,
            sensor_age_ns: None,
            joints_age_ns: None,
            new_sample: false,
            torque: None,
            guard_state: guard.state(),
            guard_reason: guard.reason(),
            transition: None,
            command: None,
            filtered: None,
            spike: false,
            tare_age_ns: None,
        };
        let filter = match config.filter {
            Some(filter) => Some(TipFilter::new(filter)?),
            None => None,
        };
        Ok(Self {
            calibration: config.calibration,
            profile: config.profile,
            tip: TipForceEstimator::new(
                &config.calibration,
                &config.profile,
                &config.noise,
                config.tip,
            )?
            .with_inertia(config.inertia)?,
            frame: SensorFrame::new(&config.calibration),
            filter,
            guard,
            limits,
            torque: limits
                .torque
                .map(|t| TorqueCheck::new(&config.calibration, &config.profile, &config.noise, &t)),
            bias,
            last,
            last_now_ns: None,
            last_counter: None,
            counter_stamp_ns: 0,
            last_joints: None,
            noise_n: config.noise.std_n(),
            last_values: None,
            repeats: 0,
            last_force_n: None,
            spikes: 0,
            spike_window_left: 0,
            tare_ns: None,
            rest: RestMean::EMPTY,
            tare_mean: TareMean::EMPTY,
            last_tare_ns: None,
        })
    }

    /// Runs one control cycle and returns its result, which stays readable as
    /// [`Estimator::last`] until the next cycle (written in place: no copy of
    /// the large output on the loop's path). The one entry point of the
    /// per-cycle path: the loop calls it once per cycle; offline, the replay
    /// of a recording of the inputs alone, the tests and the benchmarks.
    /// `context` is what the caller derives beside
    /// the recorded input ([`CycleContext`]: the following reference, a fault
    /// of its host, the carriage's commanded motion); [`CycleContext::AT_REST`]
    /// for a caller that commands no motion. It cannot fail: every fault of
    /// the input is the guard's decision, in the output.
    pub fn cycle(&mut self, input: &CycleInput, context: &CycleContext) -> &CycleOutput {
        let checks = self.check_inputs(input, context.reference.as_ref());
        let sensor = &input.sensor;
        let joints = &input.joints;
        let fresh = self.freshness(checks.now_ns, sensor, joints);
        let tare = self.tare_status(checks.now_ns);
        self.begin_output(input.cycle, &checks, &fresh, &tare);
        let (tip_input, torque_fault) = self.estimate_tip(
            &joints.joints,
            fresh.joints_valid,
            fresh.sensor_valid,
            sensor,
            &context.motion,
        );
        self.step_filter(checks.lost_samples, sensor.counter);
        if checks.new_sample && self.guard.awaiting_first_reset() {
            self.update_rest_mean(&joints.joints);
        }
        if checks.new_sample {
            self.update_tare_mean(&joints.joints, sensor);
        }
        self.last.transition = self.guard.step(&GuardInput {
            cycle: input.cycle,
            input_fault: checks.first_fault(context.host_fault, torque_fault),
            new_sample: checks.new_sample,
            sensor_age_ns: fresh.sensor_age_ns.unwrap_or(0),
            sensor_valid: fresh.sensor_valid,
            joints_age_ns: fresh.joints_age_ns.unwrap_or(0),
            joints_valid: fresh.joints_valid,
            tip: tip_input,
            extra_margin_n: tare.extra_margin_n,
            tare_due: tare.due,
            smoothed_force_n: self.last.filtered.map(|f| f.force_n),
        });
        if let Some(command) = input.command {
            let result = self.apply(command, input, checks.now_ns);
            self.last.command = Some(CommandEvent { command, result });
        }
        self.finish_output();
        &self.last
    }

    /// The inputs' ages and validity at `now_ns` (none without a trusted
    /// clock). A sample stamped in the future, or not finite, is invalid
    /// whatever the driver said; so are joints stamped in the future.
    fn freshness(
        &self,
        now_ns: Option<u64>,
        sensor: &SensorSample,
        joints: &JointSample,
    ) -> Freshness {
        match now_ns {
            Some(now) => Freshness {
                sensor_age_ns: Some(now.saturating_sub(self.counter_stamp_ns)),
                joints_age_ns: Some(now.saturating_sub(joints.stamp_ns)),
                sensor_valid: sensor.valid
                    && self.counter_stamp_ns <= now
                    && sensor.force_n.iter().all(|x| x.is_finite())
                    && sensor.torque_nm.iter().all(|x| x.is_finite()),
                joints_valid: joints.valid && joints.stamp_ns <= now,
            },
            None => Freshness {
                sensor_age_ns: None,
                joints_age_ns: None,
                sensor_valid: false,
                joints_valid: false,
            },
        }
    }

    /// The output's fields known before the estimate; the torque check and
    /// the command are cleared (this cycle writes them if it has them).
    fn begin_output(
        &mut self,
        cycle: u64,
        checks: &InputChecks,
        fresh: &Freshness,
        tare: &TareStatus,
    ) {
        let out = &mut self.last;
        out.cycle = cycle;
        out.sensor_age_ns = fresh.sensor_age_ns;
        out.joints_age_ns = fresh.joints_age_ns;
        out.new_sample = checks.new_sample;
        out.torque = None;
        out.command = None;
        out.spike = checks.values.spike;
        out.tare_age_ns = tare.age_ns;
    }

    /// The guard's state and reason after the step and the command, into the
    /// output; in debug builds, the output's coherence.
    fn finish_output(&mut self) {
        self.last.guard_state = self.guard.state();
        self.last.guard_reason = self.guard.reason();
        self.debug_check_output();
    }

    /// What a reader of [`CycleOutput`] may rely on, checked in debug builds
    /// after every cycle: a pose exactly when the kinematics gave one (an
    /// estimate, a refusal of the estimator and an invalid sensor sample
    /// come with one); the torque residual and the filtered force only
    /// beside an estimate (the filtered one beside an observable one); a
    /// spike only in a new sample; the guard's state as the guard holds it.
    #[inline]
    fn debug_check_output(&self) {
        let out = &self.last;
        let with_pose = matches!(
            out.tip,
            TipOutcome::Estimate(_) | TipOutcome::Refused(_) | TipOutcome::SensorInvalid
        );
        debug_assert_eq!(out.pose.is_some(), with_pose, "pose vs {:?}", out.tip);
        debug_assert!(
            out.torque.is_none() || matches!(out.tip, TipOutcome::Estimate(_)),
            "a torque residual without an estimate"
        );
        debug_assert!(
            out.filtered.is_none() || matches!(out.tip, TipOutcome::Estimate(e) if e.observable),
            "a filtered force without an observable estimate"
        );
        debug_assert!(!out.spike || out.new_sample, "a spike in a repeated sample");
        debug_assert_eq!(out.guard_state, self.guard.state());
    }

    /// The pose, the tip force and the torque check, written into
    /// `self.last`; returns what the guard gets and the torque's verdict.
    fn estimate_tip(
        &mut self,
        q: &ActiveJoints,
        joints_valid: bool,
        sensor_valid: bool,
        sensor: &SensorSample,
        motion: &CarriageMotion,
    ) -> (TipInput, Option<Reason>) {
        let out = &mut self.last;
        let pose = if joints_valid {
            Some(forward(&self.calibration, &self.profile, q))
        } else {
            None
        };
        let mut torque_fault = None;
        let out_pose = match pose {
            None => {
                out.pose = None;
                out.tip = TipOutcome::JointsInvalid;
                return (TipInput::NotObservable, None);
            }
            Some(Err(e)) => {
                out.pose = None;
                out.tip = TipOutcome::PoseInvalid(e);
                return (TipInput::PoseInvalid, None);
            }
            Some(Ok(pose)) => out.pose.insert(pose),
        };
        if !sensor_valid {
            out.tip = TipOutcome::SensorInvalid;
            return (TipInput::NotObservable, None);
        }
        match self
            .tip
            .estimate_in_motion(out_pose, &sensor.force_n, &self.bias.force_n, motion)
        {
            Ok(estimate) => {
                out.tip = TipOutcome::Estimate(estimate);
                if let Some(check) = &self.torque {
                    let residual = torque_residual(
                        check,
                        &self.frame,
                        out_pose,
                        sensor,
                        &self.bias,
                        estimate.torsion_nm,
                    );
                    let residual = widened(residual, estimate.torsion_std_nm, || {
                        self.frame.torsion_axis_s(out_pose)
                    });
                    torque_fault = torque_verdict(check, &residual);
                    out.torque = Some(residual);
                }
                let tip_input = TipInput::Estimate {
                    force_n: estimate.force_n,
                    std_n: estimate.std_n,
                    rod_dir: out_pose.rod_dir,
                    observable: estimate.observable,
                    max_std_n: self.tip.max_std_n(),
                };
                (tip_input, torque_fault)
            }
            Err(e) => {
                out.tip = TipOutcome::Refused(e);
                (TipInput::NotObservable, None)
            }
        }
    }

    /// The filter: stepped with each new sample's observable estimate (a
    /// gap the time explains stepped over with the sample held), reset when
    /// there is none or samples were lost (no stale state carried over).
    fn step_filter(&mut self, lost_samples: bool, counter: u32) {
        let out = &mut self.last;
        out.filtered = None;
        if let Some(filter) = &mut self.filter {
            if lost_samples {
                filter.reset();
            }
            match out.tip {
                TipOutcome::Estimate(e) if e.observable => {
                    // A refused input resets the filter: no output then.
                    out.filtered = filter.update_counted(counter, &e.force_n, &e.std_n).ok();
                }
                _ => filter.reset(),
            }
        }
    }

    /// The result of the last cycle (before the first: no pose, no input, the
    /// guard's initial state).
    pub fn last(&self) -> &CycleOutput {
        &self.last
    }

    /// The bias in use (sensor frame).
    pub fn bias(&self) -> Bias {
        self.bias
    }

    /// The tip-force estimator in use (its calibration, profile, inertia;
    /// the watches' sensitivities).
    pub fn tip_estimator(&self) -> &TipForceEstimator {
        &self.tip
    }

    /// The guard still waits for its first accepted reset (the tip taken
    /// as free at rest: the first reset's mounting check).
    pub fn awaiting_first_reset(&self) -> bool {
        self.guard.awaiting_first_reset()
    }

    /// The guard's state.
    pub fn guard_state(&self) -> GuardState {
        self.guard.state()
    }

    /// The guard's configuration (its worst-case stop time:
    /// [`GuardConfig::stop_within_ns`]).
    pub fn guard_config(&self) -> &GuardConfig {
        self.guard.config()
    }
}

// Snapshots (issue 17). `last` is the latest cycle's result: every field of
// it is written by each cycle before anything reads it, so it is output.

sar_snapshot::snap_state!(Estimator {
    state: [
        guard,
        bias,
        last_now_ns,
        last_counter,
        counter_stamp_ns,
        last_joints,
        last_values,
        repeats,
        last_force_n,
        spikes,
        spike_window_left,
        tare_ns,
        rest,
        tare_mean,
        last_tare_ns,
    ],
    nested: [filter],
    config: [calibration, profile, tip, frame, limits, torque, noise_n],
    output: [last],
});
