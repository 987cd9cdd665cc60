//! `[[fault]]`: faults on demand; each kind takes exactly its own keys (the
//! table in `scenarios/README.md`), each value checked under its own key.

use super::raw::{AxisName, ChannelName, FaultKind, FaultToml, RailName};
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_hal::{Channels, Rail, Vec3};
use sar_sim::Fault;

/// Largest offset an encoder fault may put on a position, m.
pub const MAX_ENCODER_OFFSET_M: f64 = 1.0;
/// Largest gain error of a `sensor_scale` fault (and smallest: its inverse).
pub const MAX_SCALE_FACTOR: f64 = 100.0;

/// Every `[[fault]]`, in file order; `count_m` is one encoder count, m.
pub(super) fn faults(
    ctx: &Ctx<'_>,
    file: &[FaultToml],
    count_m: f64,
) -> Result<Vec<Fault>, ConfigError> {
    let mut faults = Vec::with_capacity(file.len());
    for (i, f) in file.iter().enumerate() {
        faults.push(resolve_fault(ctx, &format!("fault[{i}]"), f, count_m)?);
    }
    Ok(faults)
}

/// The kind's name in the file and the keys it takes (besides `kind`).
fn kind_keys(kind: FaultKind) -> (&'static str, &'static [&'static str]) {
    match kind {
        FaultKind::SensorSilent => ("sensor_silent", &["from_s", "until_s"]),
        FaultKind::NanSample => ("nan_sample", &["at_s"]),
        FaultKind::EncoderJump => ("encoder_jump", &["at_s", "axis", "jump_m"]),
        FaultKind::DriveFault => ("drive_fault", &["at_s", "code"]),
        FaultKind::SensorFrozen => ("sensor_frozen", &["from_s", "until_s"]),
        FaultKind::SensorSaturated => ("sensor_saturated", &["from_s", "until_s", "axes", "rail"]),
        FaultKind::SensorSpike => ("sensor_spike", &["at_s", "force_n", "torque_nm", "samples"]),
        FaultKind::SensorDrift => (
            "sensor_drift",
            &["from_s", "drift_n_per_s", "drift_nm_per_s"],
        ),
        FaultKind::SensorScale => ("sensor_scale", &["from_s", "factor"]),
        FaultKind::EncoderFrozen => ("encoder_frozen", &["at_s", "axis", "until_s"]),
        FaultKind::EncoderCountLoss => ("encoder_count_loss", &["at_s", "axis", "counts"]),
        FaultKind::DriveHeartbeatLoss => ("drive_heartbeat_loss", &["at_s", "axis"]),
        FaultKind::DriveEmcy => ("drive_emcy", &["at_s", "axis", "code"]),
    }
}

/// One `[[fault]]` table being read: its dotted key and its values.
struct Table<'c, 'a> {
    ctx: &'c Ctx<'a>,
    key: &'c str,
    f: &'c FaultToml,
}

impl Table<'_, '_> {
    fn key(&self, name: &str) -> String {
        format!("{}.{name}", self.key)
    }

    fn missing(&self, name: &str) -> ConfigError {
        self.ctx.err(&self.key(name), "missing key")
    }

    fn required<T: Copy>(&self, name: &str, value: Option<T>) -> Result<T, ConfigError> {
        value.ok_or_else(|| self.missing(name))
    }

    /// A time key (`at_s` or `from_s`): (s, ns).
    fn time(&self, name: &str, value: Option<f64>) -> Result<(f64, u64), ConfigError> {
        let s = self.required(name, value)?;
        Ok((s, self.ctx.time_ns(&self.key(name), s)?))
    }

    fn at(&self) -> Result<(f64, u64), ConfigError> {
        self.time("at_s", self.f.at_s)
    }

    fn from(&self) -> Result<(f64, u64), ConfigError> {
        self.time("from_s", self.f.from_s)
    }

    /// The optional `until_s`, after the start `start_name` = `start_s`.
    fn until(&self, start_name: &str, start_s: f64) -> Result<Option<u64>, ConfigError> {
        let Some(until_s) = self.f.until_s else {
            return Ok(None);
        };
        let until_key = self.key("until_s");
        let until_ns = self.ctx.time_ns(&until_key, until_s)?;
        if until_s <= start_s {
            return Err(self.ctx.err(
                &until_key,
                format!("must be after {start_name} = {start_s} s, got {until_s} s"),
            ));
        }
        Ok(Some(until_ns))
    }

    fn axis(&self) -> Result<usize, ConfigError> {
        Ok(match self.required("axis", self.f.axis)? {
            AxisName::Q1 => 0,
            AxisName::Q2 => 1,
            AxisName::Q3 => 2,
        })
    }

    /// `axes`: one or more channels, each once.
    fn channels(&self) -> Result<Channels, ConfigError> {
        let names = self.f.axes.as_deref().ok_or_else(|| self.missing("axes"))?;
        if names.is_empty() {
            return Err(self.ctx.err(
                &self.key("axes"),
                "must name at least one channel (fx, fy, fz, tx, ty, tz)",
            ));
        }
        let mut channels = [false; 6];
        for (i, name) in names.iter().enumerate() {
            let c = match name {
                ChannelName::Fx => 0,
                ChannelName::Fy => 1,
                ChannelName::Fz => 2,
                ChannelName::Tx => 3,
                ChannelName::Ty => 4,
                ChannelName::Tz => 5,
            };
            if let Some(slot) = channels.get_mut(c) {
                if *slot {
                    return Err(self.ctx.err(
                        &format!("{}.axes[{i}]", self.key),
                        format!(
                            "names {} twice",
                            sar_hal::sensor::CHANNEL_NAMES
                                .get(c)
                                .copied()
                                .unwrap_or("?")
                        ),
                    ));
                }
                *slot = true;
            }
        }
        Ok(channels)
    }

    /// `encoder_jump`: a non-zero jump of at most [`MAX_ENCODER_OFFSET_M`].
    fn encoder_jump(&self) -> Result<Fault, ConfigError> {
        let at_ns = self.at()?.1;
        let axis = self.axis()?;
        let jump_m = self.required("jump_m", self.f.jump_m)?;
        if jump_m == 0.0 || jump_m.abs() > MAX_ENCODER_OFFSET_M {
            return Err(self.ctx.err(
                &self.key("jump_m"),
                format!("must be non-zero and at most 1 m in size, got {jump_m} m"),
            ));
        }
        Ok(Fault::EncoderJump {
            at_ns,
            axis,
            jump_m,
        })
    }

    /// `sensor_saturated`: one or more channels, pinned to a rail or to the
    /// side of their reading.
    fn sensor_saturated(&self) -> Result<Fault, ConfigError> {
        let (from_s, from_ns) = self.from()?;
        let until_ns = self.until("from_s", from_s)?;
        let channels = self.channels()?;
        let rail = self.f.rail.map(|r| match r {
            RailName::Positive => Rail::Positive,
            RailName::Negative => Rail::Negative,
        });
        Ok(Fault::SensorSaturated {
            from_ns,
            until_ns,
            channels,
            rail,
        })
    }

    /// Refuses `what` (a spike, a drift; given at `name`) of zero force and
    /// zero torque: it changes nothing.
    fn changes_something(
        &self,
        name: &str,
        force: &Vec3,
        torque: &Vec3,
        what: &str,
    ) -> Result<(), ConfigError> {
        if *force == Vec3::zeros() && *torque == Vec3::zeros() {
            return Err(self.ctx.err(
                &self.key(name),
                format!("{what} of zero force and zero torque changes nothing"),
            ));
        }
        Ok(())
    }

    /// `sensor_spike`: a force or a torque, for at least one sample.
    fn sensor_spike(&self) -> Result<Fault, ConfigError> {
        let at_ns = self.at()?.1;
        let force_n = Vec3::from(self.required("force_n", self.f.force_n)?);
        let torque_nm = Vec3::from(self.f.torque_nm.unwrap_or_default());
        self.changes_something("force_n", &force_n, &torque_nm, "a spike")?;
        let samples = self.f.samples.unwrap_or(1);
        if samples == 0 {
            return Err(self.ctx.err(&self.key("samples"), "must be >= 1, got 0"));
        }
        Ok(Fault::SensorSpike {
            at_ns,
            force_n,
            torque_nm,
            samples,
        })
    }

    /// `sensor_drift`: a drift of force or of torque.
    fn sensor_drift(&self) -> Result<Fault, ConfigError> {
        let from_ns = self.from()?.1;
        let drift_n_per_s = Vec3::from(self.required("drift_n_per_s", self.f.drift_n_per_s)?);
        let drift_nm_per_s = Vec3::from(self.f.drift_nm_per_s.unwrap_or_default());
        self.changes_something("drift_n_per_s", &drift_n_per_s, &drift_nm_per_s, "a drift")?;
        Ok(Fault::SensorDrift {
            from_ns,
            drift_n_per_s,
            drift_nm_per_s,
        })
    }

    /// `sensor_scale`: a gain within [`MAX_SCALE_FACTOR`] either way.
    fn sensor_scale(&self) -> Result<Fault, ConfigError> {
        let from_ns = self.from()?.1;
        let factor = self.required("factor", self.f.factor)?;
        if !(1.0 / MAX_SCALE_FACTOR..=MAX_SCALE_FACTOR).contains(&factor) {
            return Err(self.ctx.err(
                &self.key("factor"),
                format!(
                    "must be in [{}, {MAX_SCALE_FACTOR}], got {factor}",
                    1.0 / MAX_SCALE_FACTOR
                ),
            ));
        }
        Ok(Fault::SensorScale { from_ns, factor })
    }

    /// `encoder_count_loss`: a non-zero loss of at most
    /// [`MAX_ENCODER_OFFSET_M`] of travel (`count_m`: one count, m).
    fn encoder_count_loss(&self, count_m: f64) -> Result<Fault, ConfigError> {
        let at_ns = self.at()?.1;
        let axis = self.axis()?;
        let counts = self.required("counts", self.f.counts)?;
        let offset_m = f64::from(counts) * count_m;
        if counts == 0 || offset_m.abs() > MAX_ENCODER_OFFSET_M {
            return Err(self.ctx.err(
                &self.key("counts"),
                format!(
                    "must be non-zero and at most 1 m of travel in size ({:.0} counts), got \
                     {counts}",
                    (MAX_ENCODER_OFFSET_M / count_m).floor()
                ),
            ));
        }
        Ok(Fault::EncoderCountLoss {
            at_ns,
            axis,
            counts,
        })
    }

    /// `drive_emcy`: an EMCY with a non-zero code.
    fn drive_emcy(&self) -> Result<Fault, ConfigError> {
        let at_ns = self.at()?.1;
        let axis = self.axis()?;
        let code = self.required("code", self.f.code)?;
        if code == 0 {
            return Err(self.ctx.err(
                &self.key("code"),
                "must not be 0 (an EMCY with code 0 says the error is gone)",
            ));
        }
        Ok(Fault::DriveEmcy { at_ns, axis, code })
    }
}

/// Checks that a `[[fault]]` gives exactly the keys its kind takes, and each value.
fn resolve_fault(
    ctx: &Ctx<'_>,
    key: &str,
    f: &FaultToml,
    count_m: f64,
) -> Result<Fault, ConfigError> {
    check_keys(ctx, key, f)?;
    let t = Table { ctx, key, f };
    Ok(match f.kind {
        FaultKind::SensorSilent => {
            let (from_s, from_ns) = t.from()?;
            let until_ns = t.until("from_s", from_s)?;
            Fault::SensorSilent { from_ns, until_ns }
        }
        FaultKind::NanSample => Fault::NanSample { at_ns: t.at()?.1 },
        FaultKind::EncoderJump => t.encoder_jump()?,
        FaultKind::DriveFault => {
            let at_ns = t.at()?.1;
            let code = t.required("code", f.code)?;
            Fault::DriveFault { at_ns, code }
        }
        FaultKind::SensorFrozen => {
            let (from_s, from_ns) = t.from()?;
            let until_ns = t.until("from_s", from_s)?;
            Fault::SensorFrozen { from_ns, until_ns }
        }
        FaultKind::SensorSaturated => t.sensor_saturated()?,
        FaultKind::SensorSpike => t.sensor_spike()?,
        FaultKind::SensorDrift => t.sensor_drift()?,
        FaultKind::SensorScale => t.sensor_scale()?,
        FaultKind::EncoderFrozen => {
            let (at_s, at_ns) = t.at()?;
            let axis = t.axis()?;
            let until_ns = t.until("at_s", at_s)?;
            Fault::EncoderFrozen {
                at_ns,
                axis,
                until_ns,
            }
        }
        FaultKind::EncoderCountLoss => t.encoder_count_loss(count_m)?,
        FaultKind::DriveHeartbeatLoss => {
            let at_ns = t.at()?.1;
            let axis = t.axis()?;
            Fault::DriveHeartbeatLoss { at_ns, axis }
        }
        FaultKind::DriveEmcy => t.drive_emcy()?,
    })
}

/// Refuses a key the fault's kind does not take.
fn check_keys(ctx: &Ctx<'_>, key: &str, f: &FaultToml) -> Result<(), ConfigError> {
    let present = [
        ("from_s", f.from_s.is_some()),
        ("until_s", f.until_s.is_some()),
        ("at_s", f.at_s.is_some()),
        ("axis", f.axis.is_some()),
        ("jump_m", f.jump_m.is_some()),
        ("code", f.code.is_some()),
        ("axes", f.axes.is_some()),
        ("rail", f.rail.is_some()),
        ("force_n", f.force_n.is_some()),
        ("torque_nm", f.torque_nm.is_some()),
        ("samples", f.samples.is_some()),
        ("drift_n_per_s", f.drift_n_per_s.is_some()),
        ("drift_nm_per_s", f.drift_nm_per_s.is_some()),
        ("factor", f.factor.is_some()),
        ("counts", f.counts.is_some()),
    ];
    let (kind_name, takes) = kind_keys(f.kind);
    if let Some((name, _)) = present
        .iter()
        .find(|(name, is)| *is && !takes.contains(name))
    {
        return Err(ctx.err(
            &format!("{key}.{name}"),
            format!(
                "not a key of a {kind_name} fault (it takes: {})",
                takes.join(", ")
            ),
        ));
    }
    Ok(())
}
