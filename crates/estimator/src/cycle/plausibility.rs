//! The settings of a cycle's plausibility checks, as the caller fills them
//! ([`PlausibilityLimits`], with their documented defaults) and as they are
//! checked once at start ([`PlausibilityConfig`]): the joints' speed, the
//! sensor's counter and sample period, the torque check, the frozen-sensor
//! and spike checks, the sensor's range, the tare's age and mean at rest,
//! and the first reset's check of the wrench at rest. What each check does
//! with them is in `input_checks`, `torque_residual`, `tare` and
//! `mounting`.

use crate::{SettingError, Vec3, at_least, finite_non_negative, positive, require};

/// The limits of the input plausibility checks, as the caller fills them.
/// [`PlausibilityConfig::new`] checks them; [`PlausibilityLimits::default`]
/// gives the documented defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlausibilityLimits {
    /// The axes' speed limit, m/s (finite, > 0). Default 0.05 m/s (the
    /// simulator's axes); set the drives' configured limit.
    pub max_joint_speed_mps: f64,
    /// Added to the distance the speed allows between two joint samples, m
    /// (finite, >= 0): quantisation, stamp jitter. Default 0.2 mm.
    pub joint_margin_m: f64,
    /// The largest accepted step of the sensor counter between two new
    /// samples beyond the samples their stamps' difference explains
    /// (1 = no sample lost; >= 1). Default 3. A late cycle (the loop did not
    /// look) explains its samples by the time that passed: the newest sample
    /// then is `round(dt / sample_period_ns)` after the last one judged, and
    /// that many less one are added to the accepted step; the time itself is
    /// judged by the cycle gap ([`crate::guard::Reason::CycleGap`]).
    pub max_counter_gap: u32,
    /// The sensor's sample period, ns (> 0; `[tip] sample_rate_hz`):
    /// explains a counter step by the stamps' difference. Default 2 ms
    /// (500 Hz).
    pub sample_period_ns: u64,
    /// The torque check; `None` switches it off (a sensor without torque).
    /// Default on, with [`TorqueLimits`]' defaults.
    pub torque: Option<TorqueLimits>,
    /// The frozen-sensor check. Default on with
    /// [`FrozenCheck::DEFAULT_REPEATS`]; [`super::frozen_repeats`] derives the
    /// count from the sensor's noise and resolution.
    pub frozen: FrozenCheck,
    /// The sensor's measuring range (saturation check); `None` switches it
    /// off. Default the HEX-6 ([`SensorRange::HEX6`]).
    pub range: Option<SensorRange>,
    /// The spike check; `None` switches it off. Default on
    /// ([`SpikeLimits::default`]).
    pub spikes: Option<SpikeLimits>,
    /// The tare's age and the bias drift ([`TareLimits::default`]).
    pub tare: TareLimits,
    /// The first reset's check of the wrench at rest against the model;
    /// `None` switches it off. Default on ([`MountingLimits::default`]).
    pub mounting: Option<MountingLimits>,
}

impl Default for PlausibilityLimits {
    fn default() -> Self {
        let [x, y, z] = TorqueLimits::DEFAULT_NOISE_NM;
        Self {
            max_joint_speed_mps: 0.05,
            joint_margin_m: 2e-4,
            max_counter_gap: 3,
            sample_period_ns: 2_000_000,
            torque: Some(TorqueLimits {
                noise_nm: Vec3::new(x, y, z),
                max_sigma: TorqueLimits::DEFAULT_MAX_SIGMA,
            }),
            frozen: FrozenCheck::On {
                repeats: FrozenCheck::DEFAULT_REPEATS,
            },
            range: Some(SensorRange::HEX6),
            spikes: Some(SpikeLimits::default()),
            tare: TareLimits::default(),
            mounting: Some(MountingLimits::default()),
        }
    }
}

/// Checked plausibility limits. Exists only if valid (the default is
/// [`PlausibilityLimits::default`], which is valid).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlausibilityConfig {
    limits: PlausibilityLimits,
}

impl PlausibilityConfig {
    /// Checks: speed finite and > 0; margin finite and >= 0; counter gap >= 1;
    /// torque noise finite and > 0 per axis; max_sigma finite and >= 1.
    /// Then each optional check's settings, in the order of the fields.
    pub fn new(limits: PlausibilityLimits) -> Result<Self, SettingError> {
        positive("max_joint_speed_mps", limits.max_joint_speed_mps)?;
        finite_non_negative("joint_margin_m", limits.joint_margin_m)?;
        require(
            limits.max_counter_gap != 0,
            "max_counter_gap",
            0.0,
            "must be >= 1",
        )?;
        require(
            limits.sample_period_ns != 0,
            "sample_period_ns",
            0.0,
            "must be > 0",
        )?;
        if let Some(t) = limits.torque {
            t.check()?;
        }
        if let FrozenCheck::On { repeats } = limits.frozen {
            let ok = (1..=FrozenCheck::MAX_REPEATS).contains(&repeats);
            require(ok, "frozen.repeats", f64::from(repeats), "must be 1..=1000")?;
        }
        if let Some(r) = limits.range {
            for &v in r.force_n.iter().chain(r.torque_nm.iter()) {
                positive("range", v)?;
            }
        }
        if let Some(sp) = limits.spikes {
            sp.check()?;
        }
        limits.tare.check()?;
        if let Some(m) = limits.mounting {
            m.check()?;
        }
        Ok(Self { limits })
    }

    /// The checked limits.
    pub fn limits(&self) -> PlausibilityLimits {
        self.limits
    }
}

/// A count of samples that must be 1..=100000.
fn window(field: &'static str, samples: u32) -> Result<(), SettingError> {
    let ok = (1..=100_000).contains(&samples);
    require(ok, field, f64::from(samples), "must be 1..=100000")
}

/// The torque check's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueLimits {
    /// Torque noise, one standard deviation per sensor axis, N m (finite, > 0).
    pub noise_nm: Vec3,
    /// A residual beyond this many standard deviations on any axis is a
    /// Fault (finite, >= 1).
    pub max_sigma: f64,
}

impl TorqueLimits {
    /// Default torque noise, N m: the simulator's HEX-6 figures (0.01, 0.01,
    /// 0.002); set the real sensor's.
    pub const DEFAULT_NOISE_NM: [f64; 3] = [0.01, 0.01, 0.002];
    /// Default multiple: 7 standard deviations, i.e. about one false Fault in
    /// 10^11 samples per axis for Gaussian noise (years at 500 Hz).
    pub const DEFAULT_MAX_SIGMA: f64 = 7.0;
}

impl TorqueLimits {
    /// Noise finite and > 0 per axis; max_sigma finite and >= 1.
    fn check(&self) -> Result<(), SettingError> {
        for &n in self.noise_nm.iter() {
            positive("torque.noise_nm", n)?;
        }
        at_least(
            "torque.max_sigma",
            self.max_sigma,
            1.0,
            "must be finite and >= 1",
        )
    }
}

/// The frozen-sensor (stuck-at) check: N new samples in a row whose six
/// values repeat the previous new sample's bit for bit, while the counter
/// advances, are a Fault ([`crate::guard::Reason::SensorFrozen`]). A live sensor always
/// shows noise, so that a repeat of all six quantised channels is rare; how
/// rare is [`super::frozen_repeat_probability`], and [`super::frozen_repeats`] picks N.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrozenCheck {
    /// Fault after `repeats` (>= 1) identical new samples in a row.
    On {
        /// N.
        repeats: u32,
    },
    /// Off: said explicitly, because a sensor whose configured noise is 0,
    /// or whose resolution is far coarser than its noise, repeats by
    /// itself, and then the check cannot tell a frozen sensor from a live
    /// one. The daemon logs it at start.
    Off,
}

impl FrozenCheck {
    /// The default and smallest N that [`super::frozen_repeats`] returns: a device
    /// that sends a sample twice (an output rate above its converter's)
    /// must not trip it; 3 new samples are 6 ms at 500 Hz.
    pub const DEFAULT_REPEATS: u32 = 3;
    /// The largest accepted N (a larger one would in effect switch it off).
    pub const MAX_REPEATS: u32 = 1000;
}

/// The sensor's measuring range per channel (sensor frame): a raw reading at
/// or beyond it (either sign) is a Fault ([`crate::guard::Reason::SensorSaturated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorRange {
    /// Fx, Fy, Fz range, N (finite, > 0).
    pub force_n: Vec3,
    /// Tx, Ty, Tz range, N m (finite, > 0).
    pub torque_nm: Vec3,
}

impl SensorRange {
    /// OnRobot HEX-E / HEX-H QC (the article's sensor): nominal capacity
    /// Fxy 200 N, Fz 200 N, Txy 10 N m, Tz 6.5 N m (OnRobot HEX-E/H QC
    /// datasheet, "Nominal capacity (N.C)").
    pub const HEX6: SensorRange = SensorRange {
        force_n: Vec3::new(200.0, 200.0, 200.0),
        torque_nm: Vec3::new(10.0, 10.0, 6.5),
    };
    /// ATI Mini45 SI-145-5 on a Net F/T box: Fxy 145 N, Fz 290 N, Txy 5 N m,
    /// Tz 5 N m (ATI Mini45 calibration table, SI-145-5).
    pub const ATI_MINI45_SI_145_5: SensorRange = SensorRange {
        force_n: Vec3::new(145.0, 145.0, 290.0),
        torque_nm: Vec3::new(5.0, 5.0, 5.0),
    };
}

/// The spike check: a new sample whose force jumps from the previous new
/// sample's by more than `jump_sigma * sqrt(2) * noise` on any sensor axis
/// is a spike. One spike changes no state: the guard's debounce is by design
/// the filter of single-sample noise, and a force that persists still stops
/// within the debounce time; it is counted and reported
/// ([`super::CycleOutput::spike`]). `max_spikes` spikes within `window_samples` new
/// samples of the first are a Fault ([`crate::guard::Reason::SensorSpikes`]): a sensor
/// that keeps jumping is not to be trusted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpikeLimits {
    /// The jump threshold in standard deviations of the difference of two
    /// samples (finite, >= 3).
    pub jump_sigma: f64,
    /// Spikes within the window that fault (>= 2).
    pub max_spikes: u32,
    /// The window, new samples (>= 1).
    pub window_samples: u32,
}

impl SpikeLimits {
    /// Whether `next` jumps from `previous` (forces, sensor frame, N) by
    /// more than `jump_sigma * sqrt(2)` times the noise `noise_n` on any
    /// axis: one formula for the estimator's own check and the loop's count
    /// of the samples it drains ([`super::DrainedSamples`]).
    pub fn is_jump(&self, noise_n: &Vec3, previous: &Vec3, next: &Vec3) -> bool {
        let threshold_n = noise_n * (self.jump_sigma * core::f64::consts::SQRT_2);
        let jump = (next - previous).abs();
        jump.iter().zip(threshold_n.iter()).any(|(j, t)| j > t)
    }
}

impl Default for SpikeLimits {
    /// 10 sigma (a Gaussian difference beyond it: 1.5e-23 per sample and
    /// axis), 10 spikes within 500 new samples (1 s at 500 Hz).
    fn default() -> Self {
        Self {
            jump_sigma: 10.0,
            max_spikes: 10,
            window_samples: 500,
        }
    }
}

impl SpikeLimits {
    /// Jump finite and >= 3 sigma; at least 2 spikes in a window of >= 1.
    fn check(&self) -> Result<(), SettingError> {
        at_least(
            "spikes.jump_sigma",
            self.jump_sigma,
            3.0,
            "must be finite and >= 3",
        )?;
        let n = f64::from(self.max_spikes);
        require(self.max_spikes >= 2, "spikes.max_spikes", n, "must be >= 2")?;
        require(
            self.window_samples != 0,
            "spikes.window_samples",
            0.0,
            "must be >= 1",
        )
    }
}

/// The tare's age and the bias drift since the tare.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TareLimits {
    /// After this long since the last tare (or the start bias), the guard
    /// warns that a tare is due ([`crate::guard::Reason::TareDue`]), ns; `None`: never.
    pub max_age_ns: Option<u64>,
    /// The sensor's bias drift bound, N/s (finite, >= 0): every part is
    /// compared with its limits after adding `drift_n_per_s * age_s` besides
    /// the standard-deviation margin, so that a bias that drifted by up to
    /// that much since the tare cannot hide a force above a limit.
    pub drift_n_per_s: f64,
    /// A tare takes the mean reading of this many new samples at rest
    /// (1..=100000; beyond, an exponential mean of that length): with one
    /// sample it would carry that sample's noise into the bias (eight
    /// one-sample tares at rest moved the mean tip force by up to 0.17 N).
    /// Refused until the mean holds that many ([`super::TareRefused::NotAtRest`]).
    pub window_samples: u32,
    /// The readings' standard deviation over the mean, per sensor axis, may
    /// be at most this multiple of the sensor's configured noise (finite,
    /// at least 1): beyond, the robot is not at rest (a contact that
    /// changes, a vibration) and the tare is refused
    /// ([`super::TareRefused::NotSteady`]).
    pub max_spread: f64,
    /// Two accepted tares at least this far apart, ns
    /// ([`super::TareRefused::TooSoon`]); 0: no limit.
    pub min_interval_ns: u64,
}

impl Default for TareLimits {
    /// A tare due after one hour; a drift bound of 1e-4 N/s (0.36 N after
    /// the hour). The HEX-6's datasheet gives no drift over time: this is an
    /// assumption to replace by the sensor's measured drift (a recording at
    /// rest over an hour after warm-up). A tare over the mean of 500 samples
    /// at rest (1 s at 500 Hz), refused when the readings spread more than
    /// twice the configured noise, and at most one tare every 5 s.
    fn default() -> Self {
        Self {
            max_age_ns: Some(3_600_000_000_000),
            drift_n_per_s: 1e-4,
            window_samples: 500,
            max_spread: 2.0,
            min_interval_ns: 5_000_000_000,
        }
    }
}

impl TareLimits {
    /// Drift finite and >= 0; an age bound > 0; a window of 1..=100000
    /// samples; a spread finite and >= 1.
    fn check(&self) -> Result<(), SettingError> {
        finite_non_negative("tare.drift_n_per_s", self.drift_n_per_s)?;
        require(
            self.max_age_ns != Some(0),
            "tare.max_age",
            0.0,
            "must be > 0",
        )?;
        window("tare.window_samples", self.window_samples)?;
        at_least(
            "tare.max_spread",
            self.max_spread,
            1.0,
            "must be finite and >= 1",
        )
    }
}

/// The first reset's check of the wrench at rest: with the tip free, the
/// model predicts the whole sensor wrench, so the estimated F_tip and the
/// torque residual are the residuals of the model. Both are averaged over
/// the new samples since the joints last moved (at most `rest_samples`;
/// beyond, an exponential mean of that length), so that the noise of the
/// mean is small and the tolerances decide. The mean F_tip across the rod
/// must be within `sigma std/sqrt(n) + tolerance_n`, along the rod within
/// `sigma std/sqrt(n) + friction_n + tolerance_n` (the support's friction
/// acts along the rod, like an axial tip force), the mean torque residual on
/// each sensor axis within `sigma std/sqrt(n) + tolerance_nm`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountingLimits {
    /// Multiple of the mean's standard deviation (finite, >= 0).
    pub sigma: f64,
    /// The largest static friction of the support along the rod, N (finite,
    /// >= 0).
    pub friction_n: f64,
    /// What the force model may be off beyond noise and friction, N (finite,
    /// > 0).
    pub tolerance_n: f64,
    /// What the torque model may be off beyond noise, N m (finite, > 0).
    pub tolerance_nm: f64,
    /// The length of the mean, new samples (1..=100000).
    pub rest_samples: u32,
}

impl Default for MountingLimits {
    /// 4 sigma, 0.5 N friction, 1 N and 0.02 N m tolerance, a mean of 500
    /// samples (1 s at 500 Hz).
    fn default() -> Self {
        Self {
            sigma: 4.0,
            friction_n: 0.5,
            tolerance_n: 1.0,
            tolerance_nm: 0.02,
            rest_samples: 500,
        }
    }
}

impl MountingLimits {
    /// Sigma and friction finite and >= 0; tolerances finite and > 0; a
    /// rest of 1..=100000 samples.
    fn check(&self) -> Result<(), SettingError> {
        finite_non_negative("mounting.sigma", self.sigma)?;
        finite_non_negative("mounting.friction_n", self.friction_n)?;
        positive("mounting.tolerance_n", self.tolerance_n)?;
        positive("mounting.tolerance_nm", self.tolerance_nm)?;
        window("mounting.rest_samples", self.rest_samples)
    }
}

// The configuration fingerprint (names and values, never `Debug`).

sar_snapshot::config_struct!(PlausibilityLimits {
    max_joint_speed_mps,
    joint_margin_m,
    max_counter_gap,
    sample_period_ns,
    torque,
    frozen,
    range,
    spikes,
    tare,
    mounting,
});

sar_snapshot::config_struct!(TorqueLimits {
    noise_nm,
    max_sigma
});

sar_snapshot::config_enum!(FrozenCheck { On { repeats }, Off });

sar_snapshot::config_struct!(SensorRange { force_n, torque_nm });

sar_snapshot::config_struct!(SpikeLimits {
    jump_sigma,
    max_spikes,
    window_samples,
});

sar_snapshot::config_struct!(TareLimits {
    max_age_ns,
    drift_n_per_s,
    window_samples,
    max_spread,
    min_interval_ns,
});

sar_snapshot::config_struct!(MountingLimits {
    sigma,
    friction_n,
    tolerance_n,
    tolerance_nm,
    rest_samples,
});
