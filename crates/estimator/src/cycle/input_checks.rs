//! The plausibility checks of one cycle's inputs, decided from the inputs
//! alone, in a fixed order, each a latched Fault of its own reason (limits
//! in [`super::PlausibilityLimits`]): a clock that cannot be read or does
//! not advance; a cycle that comes longer after the previous one than the
//! sensor's accepted age (a stall; a late cycle within it is an input the
//! loop carries on from, issue 33); a sensor counter that jumps by more than
//! `max_counter_gap` beyond the samples the stamps' difference explains; a
//! sample whose counter has not changed for longer than the guard's
//! `max_sensor_age_ns` (the age runs from the stamp of the sample that first
//! carried the counter); a device status other than 0; a reading at or
//! beyond the sensor's range, frozen, or spiking; a joint that moves between
//! two joint samples by more than `max_joint_speed_mps` allows over their
//! stamp difference plus `joint_margin_m`; a joint sample off the commanded
//! trajectory (the following error). The torque's plausibility is
//! `torque_residual`'s.

use super::Estimator;
use super::plausibility::{FrozenCheck, SpikeLimits};
use super::vocabulary::{
    CycleInput, DrainedSamples, FollowingReference, JointSample, SensorSample,
};
use crate::Vec3;
use crate::guard::{Reason, SensorChannel};
use sar_kinematics::ActiveJoints;

/// What the checks of the sensor's own values found in one new sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct SampleVerdict {
    pub(super) fault: Option<Reason>,
    pub(super) spike: bool,
}

/// What the plausibility checks of one cycle's inputs found
/// ([`Estimator::check_inputs`]): the clock, the sensor's counter, status and
/// values, the joints. Each fault is kept apart, so that the guard gets the
/// first in the fixed order ([`InputChecks::first_fault`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct InputChecks {
    /// The clock's reading, when it can be trusted (read, and advancing).
    pub(super) now_ns: Option<u64>,
    pub(super) clock_fault: Option<Reason>,
    /// The sensor sample is a new one (its counter changed).
    pub(super) new_sample: bool,
    /// The counter jumped beyond what the time explains (the filter
    /// restarts; an explained gap is stepped over, [`crate::filter::TipFilter::update_counted`]).
    pub(super) lost_samples: bool,
    pub(super) counter_fault: Option<Reason>,
    pub(super) status_fault: Option<Reason>,
    pub(super) values: SampleVerdict,
    pub(super) joint_fault: Option<Reason>,
}

impl InputChecks {
    /// The guard's input fault: the first of clock, counter, status, the
    /// sensor's values, the host's fault, joints, torque.
    pub(super) fn first_fault(
        &self,
        host_fault: Option<Reason>,
        torque_fault: Option<Reason>,
    ) -> Option<Reason> {
        self.clock_fault
            .or(self.counter_fault)
            .or(self.status_fault)
            .or(self.values.fault)
            .or(host_fault)
            .or(self.joint_fault)
            .or(torque_fault)
    }
}

/// The following-error verdict of finite joints `q` against `r`.
fn following_fault(q: &ActiveJoints, r: &FollowingReference) -> Option<Reason> {
    let errors = axis_moves(q, &r.joints);
    let tolerance_m = r.tolerance_m;
    let tolerance_ok = tolerance_m.is_finite() && tolerance_m > 0.0;
    errors
        .into_iter()
        // NaN compares false: a non-finite reference faults.
        .find(|(_, error_m)| !(tolerance_ok && *error_m <= tolerance_m))
        .map(|(axis, error_m)| Reason::FollowingError {
            axis,
            error_m,
            tolerance_m,
        })
}

/// |a - b| on each of the three axes, with its axis (1, 2, 3).
fn axis_moves(a: &ActiveJoints, b: &ActiveJoints) -> [(u8, f64); 3] {
    [
        (1, (a.q1_m - b.q1_m).abs()),
        (2, (a.q2_m - b.q2_m).abs()),
        (3, (a.q3_m - b.q3_m).abs()),
    ]
}

/// The largest |dq| over the three axes, with its axis (1, 2, 3).
fn largest_move(a: &ActiveJoints, b: &ActiveJoints) -> (u8, f64) {
    axis_moves(a, b)
        .into_iter()
        .fold((1, 0.0), |acc, m| if m.1 > acc.1 { m } else { acc })
}

/// Whether a mean at rest taken at the joints `since` restarts at `q`:
/// none was started, or the joints moved beyond `margin_m` (the joint
/// margin) on some axis. One rule for the tare's mean and the first
/// reset's.
pub(super) fn moved_since(since: Option<ActiveJoints>, q: &ActiveJoints, margin_m: f64) -> bool {
    since.is_none_or(|p| largest_move(q, &p).1 > margin_m)
}

impl Estimator {
    /// The plausibility checks of the inputs, in their fixed order (each
    /// moves its own memory of earlier cycles): clock, sensor counter,
    /// device status, the sensor's values, joints (with the following error
    /// against `reference`).
    pub(super) fn check_inputs(
        &mut self,
        input: &CycleInput,
        reference: Option<&FollowingReference>,
    ) -> InputChecks {
        let (now_ns, clock_fault) = self.check_clock(input.now_ns);
        let sensor = &input.sensor;
        let (new_sample, lost_samples, counter_fault) = self.check_counter(sensor);
        let status_fault = (sensor.status != 0).then_some(Reason::SensorStatus {
            status: sensor.status,
        });
        let values = self.check_values(sensor, new_sample);
        let joint_fault = self.check_joints(&input.joints, reference);
        InputChecks {
            now_ns,
            clock_fault,
            new_sample,
            lost_samples,
            counter_fault,
            status_fault,
            values,
            joint_fault,
        }
    }

    /// The clock: no reading, or one that does not advance, trusts nothing;
    /// a cycle later after the previous one than the sensor's accepted age
    /// is a Fault of its own (a stall: nothing was judged meanwhile), its
    /// time trusted.
    fn check_clock(&mut self, now_ns: Option<u64>) -> (Option<u64>, Option<Reason>) {
        match now_ns {
            None => (None, Some(Reason::ClockFailed)),
            Some(now_ns) => match self.last_now_ns {
                Some(previous_ns) if now_ns <= previous_ns => (
                    None,
                    Some(Reason::ClockNotAdvancing {
                        previous_ns,
                        now_ns,
                    }),
                ),
                previous => {
                    self.last_now_ns = Some(now_ns);
                    let max_ns = self.guard.config().limits().max_sensor_age_ns;
                    let gap = previous
                        .map(|p| now_ns - p)
                        .filter(|&gap_ns| gap_ns > max_ns)
                        .map(|gap_ns| Reason::CycleGap { gap_ns, max_ns });
                    (Some(now_ns), gap)
                }
            },
        }
    }

    /// The sensor counter: a new sample, a gap, or the same sample again
    /// (whose age runs from its first stamp, however it was re-stamped).
    /// Returns (new sample, samples lost beyond what the time explains,
    /// fault).
    fn check_counter(&mut self, sensor: &SensorSample) -> (bool, bool, Option<Reason>) {
        let new_sample = self.last_counter != Some(sensor.counter);
        let mut fault = None;
        if new_sample {
            if let Some(previous) = self.last_counter {
                // Samples the time since the last one explains (a late
                // cycle): that many, less the one step of no loss.
                let explained = sensor
                    .stamp_ns
                    .saturating_sub(self.counter_stamp_ns)
                    .saturating_add(self.limits.sample_period_ns / 2);
                let explained = explained / self.limits.sample_period_ns.max(1);
                let explained = u32::try_from(explained).unwrap_or(u32::MAX);
                let max_gap = self
                    .limits
                    .max_counter_gap
                    .saturating_add(explained.saturating_sub(1));
                if sensor.counter.wrapping_sub(previous) > max_gap {
                    fault = Some(Reason::SensorCounterGap {
                        previous,
                        got: sensor.counter,
                        max_gap,
                    });
                }
            }
            self.last_counter = Some(sensor.counter);
            self.counter_stamp_ns = sensor.stamp_ns;
        }
        (new_sample, fault.is_some(), fault)
    }

    /// The sensor's own values: saturation (this cycle's sample), frozen
    /// (identical new samples in a row), spikes (jumps far beyond the noise
    /// between new samples). The frozen and spike memories move only with
    /// new samples; their faults hold as long as their cause does, so that a
    /// reset is judged on them in every cycle.
    fn check_values(&mut self, sensor: &SensorSample, new_sample: bool) -> SampleVerdict {
        let f = &sensor.force_n;
        let t = &sensor.torque_nm;
        let finite = f.iter().chain(t.iter()).all(|v| v.is_finite());
        let mut fault = None;
        if finite && let Some(range) = self.limits.range {
            let values = [f.x, f.y, f.z, t.x, t.y, t.z];
            let ranges = [
                range.force_n.x,
                range.force_n.y,
                range.force_n.z,
                range.torque_nm.x,
                range.torque_nm.y,
                range.torque_nm.z,
            ];
            fault = SensorChannel::ALL
                .iter()
                .zip(values.iter().zip(ranges.iter()))
                .find(|(_, (value, range))| value.abs() >= **range)
                .map(|(channel, (value, range))| Reason::SensorSaturated {
                    channel: *channel,
                    value: *value,
                    range: *range,
                });
        }
        let spike = self.new_values(sensor, new_sample, finite);
        if let FrozenCheck::On { repeats } = self.limits.frozen
            && self.repeats >= repeats
        {
            fault = fault.or(Some(Reason::SensorFrozen {
                repeats: self.repeats,
            }));
        }
        if let Some(limits) = self.limits.spikes
            && self.spike_window_left > 0
            && self.spikes >= limits.max_spikes
        {
            fault = fault.or(Some(Reason::SensorSpikes {
                spikes: self.spikes,
                window: limits.window_samples,
            }));
        }
        SampleVerdict { fault, spike }
    }

    /// A cycle's sample for the frozen and spike memories: whether it is a
    /// spike. The memories move with new samples (a NaN restarts them);
    /// when the loop counted the samples it drained since the previous
    /// cycle, the spike check takes its counts (new sample or not).
    fn new_values(&mut self, sensor: &SensorSample, new_sample: bool, finite: bool) -> bool {
        let (f, t) = (&sensor.force_n, &sensor.torque_nm);
        let mut spike = false;
        if new_sample {
            if finite {
                let bits = [f.x, f.y, f.z, t.x, t.y, t.z].map(f64::to_bits);
                self.repeats = if self.last_values == Some(bits) {
                    self.repeats.saturating_add(1)
                } else {
                    0
                };
                self.last_values = Some(bits);
                if let Some(limits) = self.limits.spikes
                    && !sensor.drained.counted
                {
                    spike = self.count_spike(&limits, f);
                }
                self.last_force_n = Some(*f);
            } else {
                // NaN is a fault of its own; the memories restart after it.
                self.last_values = None;
                self.repeats = 0;
                self.last_force_n = None;
            }
        }
        // The loop counted every sample received since the previous cycle:
        // the check takes its counts (new sample or not).
        if let Some(limits) = self.limits.spikes
            && sensor.drained.counted
        {
            spike = self.count_drained(&limits, sensor.drained);
        }
        spike
    }

    /// The samples the loop drained this cycle for the spike check: the
    /// window moves by them, and their jumps (counted at the last of them)
    /// open or fill it, as [`Estimator::count_spike`] does one new sample
    /// at a time. Whether any jumped.
    fn count_drained(&mut self, limits: &SpikeLimits, drained: DrainedSamples) -> bool {
        let samples = u32::from(drained.samples);
        // At most one jump per sample received.
        let jumps = u32::from(drained.jumps).min(samples);
        if self.spike_window_left > 0 {
            self.spike_window_left = self.spike_window_left.saturating_sub(samples);
            if self.spike_window_left == 0 {
                self.spikes = 0;
            }
        }
        if jumps == 0 {
            return false;
        }
        if self.spike_window_left == 0 {
            self.spike_window_left = limits.window_samples;
            self.spikes = 0;
        }
        self.spikes = self.spikes.saturating_add(jumps).min(limits.window_samples);
        true
    }

    /// One new finite sample for the spike check: whether it is a spike.
    fn count_spike(&mut self, limits: &SpikeLimits, force_n: &Vec3) -> bool {
        if self.spike_window_left > 0 {
            self.spike_window_left -= 1;
            if self.spike_window_left == 0 {
                self.spikes = 0;
            }
        }
        let Some(previous) = self.last_force_n else {
            return false;
        };
        let spike = limits.is_jump(&self.noise_n, &previous, force_n);
        if spike {
            if self.spike_window_left == 0 {
                self.spike_window_left = limits.window_samples;
                self.spikes = 0;
            }
            self.spikes = self.spikes.saturating_add(1);
        }
        // A window holds at most `window_samples` new samples, so at most
        // that many spikes.
        debug_assert!(self.spike_window_left <= limits.window_samples);
        debug_assert!(
            self.spikes <= limits.window_samples,
            "{} spikes in a window of {}",
            self.spikes,
            limits.window_samples
        );
        spike
    }

    /// The joints: no faster than the axes can move, the stamp not going
    /// back, and (with a reference) within the following tolerance.
    fn check_joints(
        &mut self,
        joints: &JointSample,
        reference: Option<&FollowingReference>,
    ) -> Option<Reason> {
        let q = &joints.joints;
        if !(joints.valid && q.q1_m.is_finite() && q.q2_m.is_finite() && q.q3_m.is_finite()) {
            return None;
        }
        let mut fault = None;
        if let Some((previous, previous_ns)) = self.last_joints {
            if joints.stamp_ns < previous_ns {
                fault = Some(Reason::JointsStampBackwards {
                    previous_ns,
                    got_ns: joints.stamp_ns,
                });
            } else {
                let dt_s = (joints.stamp_ns - previous_ns) as f64 * 1e-9;
                let allowed_m = self.limits.max_joint_speed_mps * dt_s + self.limits.joint_margin_m;
                let (axis, moved_m) = largest_move(q, &previous);
                if moved_m > allowed_m {
                    fault = Some(Reason::JointJump {
                        axis,
                        moved_m,
                        allowed_m,
                    });
                }
            }
        }
        self.last_joints = Some((*q, joints.stamp_ns));
        fault.or_else(|| reference.and_then(|r| following_fault(q, r)))
    }
}
