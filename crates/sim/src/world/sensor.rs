//! The simulated sensor: its scripted failures (silence, NaN, frozen,
//! scaled, spikes, saturation), each measurement and its reception after
//! the latency, the samples drained, the device-side tare.

use super::{Physics, World, join6, split6};
use crate::spec::Fault;
use crate::{STATUS_OUT_OF_MODEL, SimError};
use rand::Rng;
use rand_distr::StandardNormal;
use sar_hal::convert::{joints_from_array, joints_to_array};
use sar_hal::{Clock, DriveState, JointPositions, Rail, SensorStatus, Vec3, WrenchSample};

impl<C: Clock> World<C> {
    pub(super) fn silent_at(&self, t_ns: u64) -> bool {
        self.faults.iter().any(|(f, _)| match *f {
            Fault::SensorSilent { from_ns, until_ns } => {
                from_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until)
            }
            _ => false,
        })
    }

    pub(super) fn nan_at(&self, k: u64) -> bool {
        let period = self.spec.sensor.period_ns;
        self.faults.iter().any(|(f, _)| match *f {
            Fault::NanSample { at_ns } => at_ns.div_ceil(period) == k,
            _ => false,
        })
    }

    pub(super) fn frozen_at(&self, t_ns: u64) -> bool {
        self.faults.iter().any(|(f, _)| match *f {
            Fault::SensorFrozen { from_ns, until_ns } => {
                from_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until)
            }
            _ => false,
        })
    }

    /// The gain of the active `sensor_scale` faults (their product), `None`
    /// when none is active.
    pub(super) fn scale_at(&self, t_ns: u64) -> Option<f64> {
        self.faults
            .iter()
            .filter_map(|(f, _)| match *f {
                Fault::SensorScale { from_ns, factor } if from_ns <= t_ns => Some(factor),
                _ => None,
            })
            .reduce(|a, b| a * b)
    }

    /// The wrench the active `sensor_spike` faults add to sample `k` (their
    /// sum), `None` when none is active.
    pub(super) fn spike_at(&self, k: u64) -> Option<(Vec3, Vec3)> {
        let period = self.spec.sensor.period_ns;
        self.faults
            .iter()
            .filter_map(|(f, _)| match *f {
                Fault::SensorSpike {
                    at_ns,
                    force_n,
                    torque_nm,
                    samples,
                } => {
                    let first = at_ns.div_ceil(period);
                    (first <= k && k - first < u64::from(samples)).then_some((force_n, torque_nm))
                }
                _ => None,
            })
            .reduce(|(f, t), (g, u)| (f + g, t + u))
    }

    /// Per channel, whether a `sensor_saturated` fault pins it at `t_ns`, and
    /// at which rail (`None` inside: the reading's side); the later fault in
    /// the list wins.
    pub(super) fn saturated_at(&self, t_ns: u64) -> [Option<Option<Rail>>; 6] {
        let mut pinned = [None; 6];
        for (f, _) in &self.faults {
            if let Fault::SensorSaturated {
                from_ns,
                until_ns,
                channels,
                rail,
            } = *f
                && from_ns <= t_ns
                && until_ns.is_none_or(|until| t_ns < until)
            {
                for (p, on) in pinned.iter_mut().zip(channels) {
                    if on {
                        *p = Some(rail);
                    }
                }
            }
        }
        pinned
    }

    /// What the device sends for measurement `k` at `t_ns` (before a freeze
    /// or a NaN): the raw reading (the world's wrench and bias, the noise,
    /// times the gain of a `sensor_scale`, plus a `sensor_spike`), clipped to
    /// the measuring range, saturated channels pinned at it, less the
    /// device-side tare. Fx, Fy, Fz, Tx, Ty, Tz, sensor frame.
    pub(super) fn device_output(
        &self,
        k: u64,
        t_ns: u64,
        p: &Physics,
        noise_n: &Vec3,
        noise_nm: &Vec3,
    ) -> [f64; 6] {
        let sensor = &self.spec.sensor;
        let (tare_n, tare_nm) = self.tare.unwrap_or((Vec3::zeros(), Vec3::zeros()));
        let scale = self.scale_at(t_ns);
        let spike = self.spike_at(k);
        let (raw, mut out) = if scale.is_none() && spike.is_none() {
            (
                join6(&(p.reading_n + noise_n), &(p.reading_nm + noise_nm)),
                // The fault-free arithmetic, bit for bit as it always was.
                join6(
                    &(p.reading_n - tare_n + noise_n),
                    &(p.reading_nm - tare_nm + noise_nm),
                ),
            )
        } else {
            let gain = scale.unwrap_or(1.0);
            let (spike_n, spike_nm) = spike.unwrap_or((Vec3::zeros(), Vec3::zeros()));
            let raw_n = (p.reading_n + noise_n) * gain + spike_n;
            let raw_nm = (p.reading_nm + noise_nm) * gain + spike_nm;
            (
                join6(&raw_n, &raw_nm),
                join6(&(raw_n - tare_n), &(raw_nm - tare_nm)),
            )
        };
        let range = join6(&sensor.range_n, &sensor.range_nm);
        let tare = join6(&tare_n, &tare_nm);
        let pinned = self.saturated_at(t_ns);
        for ((((o, r), range), tare), pin) in
            out.iter_mut().zip(raw).zip(range).zip(tare).zip(pinned)
        {
            if let Some(rail) = pin {
                let sign = rail.map_or(if r >= 0.0 { 1.0 } else { -1.0 }, Rail::sign);
                *o = sign * range - tare;
            } else if r.abs() > range {
                *o = range.copysign(r) - tare;
            }
        }
        quantise(&mut out, sensor.counts_per_n, sensor.counts_per_nm);
        out
    }

    /// Sensor measurement `k` at `t_ns`.
    pub(super) fn measure(&mut self, k: u64, t_ns: u64) {
        // Draw the noise of every sample, sent or not, so that the noise of a
        // sample depends only on the seed and its index.
        let mut draw = [0.0; 6];
        for x in &mut draw {
            *x = self.rng.sample(StandardNormal);
        }
        if self.silent_at(t_ns) {
            return;
        }
        let sensor = &self.spec.sensor;
        let [n0, n1, n2, n3, n4, n5] = draw;
        let noise_n = Vec3::new(n0, n1, n2).component_mul(&sensor.noise_n);
        let noise_nm = Vec3::new(n3, n4, n5).component_mul(&sensor.noise_nm);
        let (mut output, status) = match self.physics_at(t_ns) {
            Ok(p) => (
                self.device_output(k, t_ns, &p, &noise_n, &noise_nm),
                SensorStatus::OK,
            ),
            Err(_) => {
                let (bias_n, bias_nm) = self.bias_at(t_ns);
                (join6(&bias_n, &bias_nm), STATUS_OUT_OF_MODEL)
            }
        };
        // A frozen sensor repeats the last sample measured before the freeze
        // (this one's own values when there was none).
        if self.frozen_at(t_ns) {
            output = *self
                .frozen_output
                .get_or_insert(self.last_output.unwrap_or(output));
        } else {
            self.frozen_output = None;
        }
        self.last_output = Some(output);
        let (mut force_n, mut torque_nm) = split6(output);
        if self.nan_at(k) {
            force_n = Vec3::repeat(f64::NAN);
            torque_nm = Vec3::repeat(f64::NAN);
        }
        let receive_ns = t_ns.saturating_add(self.spec.sensor.latency_ns);
        self.in_flight.push_back((
            receive_ns,
            WrenchSample {
                force_n,
                torque_nm,
                // The device's counter wraps at u32::MAX by design.
                counter: (k & u64::from(u32::MAX)) as u32,
                status,
                received_ns: self.t0_ns.saturating_add(receive_ns),
            },
        ));
    }

    /// Position report at `t_ns`.
    pub(super) fn report(&mut self, t_ns: u64) {
        let axes = &self.spec.axes;
        let count_m = axes.lead_m_per_turn / f64::from(axes.counts_per_turn);
        let mut offsets = [0.0; 3];
        let mut frozen = [false; 3];
        for (f, _) in &self.faults {
            match *f {
                Fault::EncoderJump {
                    at_ns,
                    axis,
                    jump_m,
                } if at_ns <= t_ns => {
                    if let Some(o) = offsets.get_mut(axis) {
                        *o += jump_m;
                    }
                }
                Fault::EncoderCountLoss {
                    at_ns,
                    axis,
                    counts,
                } if at_ns <= t_ns => {
                    if let Some(o) = offsets.get_mut(axis) {
                        *o -= f64::from(counts) * count_m;
                    }
                }
                Fault::EncoderFrozen {
                    at_ns,
                    axis,
                    until_ns,
                } if at_ns <= t_ns && until_ns.is_none_or(|until| t_ns < until) => {
                    if let Some(x) = frozen.get_mut(axis) {
                        *x = true;
                    }
                }
                _ => {}
            }
        }
        // A frozen encoder repeats its previous report.
        let previous = joints_to_array(&self.positions.joints);
        let mut reported = [0.0; 3];
        for ((((r, s), o), stuck), before) in reported
            .iter_mut()
            .zip(self.axes_at(t_ns))
            .zip(offsets)
            .zip(frozen)
            .zip(previous)
        {
            *r = if stuck {
                before
            } else {
                ((s.x_m + o) / count_m).round() * count_m
            };
        }
        self.positions = JointPositions {
            joints: joints_from_array(reported),
            stamp_ns: self.t0_ns.saturating_add(t_ns),
            valid: !matches!(self.state, DriveState::Fault { .. }),
        };
    }

    /// Takes the newest received sample not yet returned.
    pub fn take_newest(&mut self) -> Option<WrenchSample> {
        self.newest.take()
    }

    /// Moves the undrained samples, oldest first, into `out` (as many as fit).
    pub fn drain(&mut self, out: &mut [WrenchSample]) -> sar_hal::Drained {
        let mut count = 0;
        for slot in out.iter_mut() {
            let Some(sample) = self.undrained.pop_front() else {
                break;
            };
            *slot = sample;
            count += 1;
        }
        sar_hal::Drained {
            count,
            lost: core::mem::take(&mut self.drain_lost),
            remaining: self.undrained.len(),
        }
    }

    /// The clock time at which the next sample will be received, if any will.
    pub fn next_receive_ns(&self) -> Option<u64> {
        if let Some((t, _)) = self.in_flight.front() {
            return Some(self.t0_ns.saturating_add(*t));
        }
        let period = self.spec.sensor.period_ns;
        let mut t = self.next_measurement.saturating_mul(period);
        // Each pass leaves at least one silent window behind for good, so
        // faults.len() + 1 passes suffice.
        for _ in 0..=self.faults.len() {
            let mut moved = false;
            for (f, _) in &self.faults {
                if let Fault::SensorSilent { from_ns, until_ns } = *f
                    && from_ns <= t
                    && until_ns.is_none_or(|until| t < until)
                {
                    let until = until_ns?;
                    t = until.div_ceil(period).saturating_mul(period);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
        Some(
            self.t0_ns
                .saturating_add(t)
                .saturating_add(self.spec.sensor.latency_ns),
        )
    }

    /// Sets the device-side tare to the present noise-free reading (as the
    /// device reads it: times the gain of an active `sensor_scale`).
    pub fn tare(&mut self) -> Result<(), SimError> {
        let p = self.physics_at(self.done_ns)?;
        self.tare = Some(match self.scale_at(self.done_ns) {
            None => (p.reading_n, p.reading_nm),
            Some(gain) => (p.reading_n * gain, p.reading_nm * gain),
        });
        Ok(())
    }

    /// Removes the device-side tare.
    pub fn clear_tare(&mut self) {
        self.tare = None;
    }

    /// The device-side tare, if set (force, torque; sensor frame).
    pub fn tare_value(&self) -> Option<(Vec3, Vec3)> {
        self.tare
    }
}

/// The device's counts (`[sensor] counts_per_n`, `counts_per_nm`; 0: none):
/// each channel as `counts / per` with the counts rounded to an i32, as
/// the RDT driver makes its floats (`f64::from(counts) / per`); a value that
/// is not finite stays as it is.
pub(super) fn quantise(out: &mut [f64; 6], counts_per_n: f64, counts_per_nm: f64) {
    for (k, v) in out.iter_mut().enumerate() {
        let per = if k < 3 { counts_per_n } else { counts_per_nm };
        if per > 0.0 && v.is_finite() {
            let counts = (*v * per)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX));
            *v = counts / per;
        }
    }
}
