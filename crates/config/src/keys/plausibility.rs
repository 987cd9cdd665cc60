//! `[plausibility]`: the checks of the inputs (joint speed, sensor counter,
//! torque, frozen sensor, spikes, the wrench at rest before the first
//! reset), with the `[sensor]` and `[tip]` keys they depend on, through the
//! estimator's own checks.

use crate::decl::{each, int, num, setting_error, switch};
use crate::keys::{File, sensor, tip, u32_of, vec3};
use crate::toml_file::Ctx;
use crate::{ConfigError, SensorDriver};
use sar_estimator::cycle::{
    FrozenCheck, MountingLimits, PlausibilityConfig, PlausibilityLimits, SpikeLimits, TorqueLimits,
    frozen_repeats,
};

crate::section! {
    /// The plausibility checks of the inputs: a failed one is a Fault.
    section "plausibility";
    /// faster joints: an encoder jump (Fault); the drives' configured speed limit
    max_joint_speed_mps: f64 = value(PlausibilityLimits::default().max_joint_speed_mps),
        num(1e-3, 1.0, "m/s") => [PlausibilityLimits.max_joint_speed_mps];
    /// added to the distance the speed allows between two joint samples, m
    joint_margin_m: f64 = value(PlausibilityLimits::default().joint_margin_m),
        num(0.0, 0.01, "m") => [PlausibilityLimits.joint_margin_m];
    /// largest step of the sensor counter beyond what the stamps explain
    max_counter_gap: i64 = value(i64::from(PlausibilityLimits::default().max_counter_gap)),
        int(1, 1_000_000, "") => [PlausibilityLimits.max_counter_gap];
    /// the torque's noise std per sensor axis, N m
    torque_noise_nm: [f64; 3] = value(TorqueLimits::DEFAULT_NOISE_NM),
        each(1e-5, 1.0, "N m").also("at most a tenth of sensor.range_nm") => [TorqueLimits.noise_nm];
    /// the torque check's limit in standard deviations (0 switches the torque check off)
    torque_max_sigma: f64 = value(TorqueLimits::DEFAULT_MAX_SIGMA),
        num(0.0, 1000.0, "(standard deviations)").also("0 or at least 1") => [TorqueLimits.max_sigma];
    /// identical samples in a row: Fault (SensorFrozen)
    frozen_check: bool = value(true), switch() => [PlausibilityLimits.frozen];
    /// how many identical samples in a row
    frozen_repeats: i64 = absent("from the noise and the sensor's resolution", 3),
        int(1, FrozenCheck::MAX_REPEATS as i64, "samples").also("only with frozen_check = true")
        => [PlausibilityLimits.frozen];
    /// jumps beyond spike_sigma: counted; too many: Fault
    spike_check: bool = value(true), switch() => [PlausibilityLimits.spikes];
    /// a jump beyond this many standard deviations is a spike
    spike_sigma: f64 = value(SpikeLimits::default().jump_sigma),
        num(3.0, 1e3, "(standard deviations)") => [SpikeLimits.jump_sigma];
    /// spikes within the window that fault
    spike_max: i64 = value(i64::from(SpikeLimits::default().max_spikes)),
        int(2, 100_000, "") => [SpikeLimits.max_spikes];
    /// the spikes' window, new samples
    spike_window_samples: i64 = value(i64::from(SpikeLimits::default().window_samples)),
        int(1, 10_000_000, "samples") => [SpikeLimits.window_samples];
    /// first reset: the wrench at rest against the model
    rest_check: bool = value(true), switch() => [PlausibilityLimits.mounting];
    /// the rest check's allowance in standard deviations of the mean
    rest_sigma: f64 = value(MountingLimits::default().sigma),
        num(0.0, 100.0, "(standard deviations)") => [MountingLimits.sigma];
    /// the rest check's force tolerance, N
    rest_tolerance_n: f64 = value(MountingLimits::default().tolerance_n),
        num(1e-3, 100.0, "N") => [MountingLimits.tolerance_n];
    /// the rest check's torque tolerance, N m
    rest_tolerance_nm: f64 = value(MountingLimits::default().tolerance_nm),
        num(1e-4, 10.0, "N m") => [MountingLimits.tolerance_nm];
    /// the mean at rest, samples: the first reset waits for it
    rest_samples: i64 = value(i64::from(MountingLimits::default().rest_samples)),
        int(1, 100_000, "samples") => [MountingLimits.rest_samples];
    /// largest static friction of the support, N
    support_friction_n: f64 = value(MountingLimits::default().friction_n),
        num(0.0, 100.0, "N") => [MountingLimits.friction_n];
}

/// The plausibility checks, through the estimator's own checks; the
/// sensor's sample period from `[tip] sample_rate_hz`.
pub(crate) fn build(
    ctx: &Ctx<'_>,
    f: &File,
    sensor_driver: &SensorDriver,
) -> Result<PlausibilityConfig, ConfigError> {
    let p = &f.plausibility;
    let torque = (p.torque_max_sigma != 0.0).then(|| TorqueLimits {
        noise_nm: vec3(p.torque_noise_nm),
        max_sigma: p.torque_max_sigma,
    });
    PlausibilityConfig::new(PlausibilityLimits {
        max_joint_speed_mps: p.max_joint_speed_mps,
        joint_margin_m: p.joint_margin_m,
        max_counter_gap: u32_of(p.max_counter_gap),
        sample_period_ns: tip::sample_period_ns(&f.tip),
        torque,
        frozen: frozen_check(ctx, f, torque.as_ref(), sensor_driver)?,
        range: Some(sensor::range(&f.sensor)),
        spikes: p.spike_check.then(|| SpikeLimits {
            jump_sigma: p.spike_sigma,
            max_spikes: u32_of(p.spike_max),
            window_samples: u32_of(p.spike_window_samples),
        }),
        tare: sensor::tare_limits(&f.sensor),
        mounting: p.rest_check.then(|| MountingLimits {
            sigma: p.rest_sigma,
            friction_n: p.support_friction_n,
            tolerance_n: p.rest_tolerance_n,
            tolerance_nm: p.rest_tolerance_nm,
            rest_samples: u32_of(p.rest_samples),
        }),
    })
    .map_err(|e| setting_error(ctx, &[KEYS, sensor::KEYS, tip::KEYS], &e))
}

/// The frozen-sensor check: off only when the file says so; otherwise the
/// count given, or derived from the noise and the sensor's resolution
/// (`frozen_repeats`: fewer than one false alarm in ten years of 1 kHz); a
/// sensor that would repeat by itself is refused with what to change.
fn frozen_check(
    ctx: &Ctx<'_>,
    f: &File,
    torque: Option<&TorqueLimits>,
    driver: &SensorDriver,
) -> Result<FrozenCheck, ConfigError> {
    let p = &f.plausibility;
    if !p.frozen_check {
        return Ok(FrozenCheck::Off);
    }
    if let Some(n) = p.frozen_repeats {
        return Ok(FrozenCheck::On { repeats: u32_of(n) });
    }
    let (resolution_n, resolution_nm) = match driver {
        SensorDriver::Rdt {
            counts_per_n,
            counts_per_nm,
            ..
        } => (1.0 / counts_per_n, 1.0 / counts_per_nm),
        SensorDriver::Sim => (0.0, 0.0),
    };
    let noise_nm = torque.map(|t| t.noise_nm);
    match frozen_repeats(
        &vec3(f.sensor.noise_n),
        noise_nm.as_ref(),
        resolution_n,
        resolution_nm,
    ) {
        Some(repeats) => Ok(FrozenCheck::On { repeats }),
        None => Err(ctx.err(
            KEY.frozen_check.key,
            format!(
                "the sensor's noise is too small for its resolution to tell a frozen sensor from \
                 a live one; set {}, or {} = false to switch the check off",
                KEY.frozen_repeats.key, KEY.frozen_check.name
            ),
        )),
    }
}
