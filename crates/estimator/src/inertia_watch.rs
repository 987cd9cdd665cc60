//! The inertia watch (issue 34 item 2; MODEL.md 10, "When the model is not
//! the plant"): in free motion the estimated tip force must not follow the
//! carriage's acceleration. The compensation of the rod's inertia is linear
//! in I_perp and in the adapter's mass m_s, so a plant whose values are the
//! configured ones plus dI and dm_s reads, with the tip free (F_tip = 0),
//!
//! ```text
//! F_est = -(dI g_I + dm_s g_s) + b + noise
//! ```
//!
//! with g_I = dF_tip/dI_perp and g_s = dF_tip/dm_s at the cycle's pose and
//! commanded motion ([`crate::tip_force::TipForceEstimator::inertia_sensitivity`])
//! and b the static model's slowly varying error (m, c, B, the bias). The
//! watch is a least squares of (dI, dm_s, b) over the free samples' three
//! components, each row weighted by the estimate's own standard deviation,
//! with exponential forgetting over `window_s` of free samples (a fixed
//! 6 x 6 Gram matrix: no allocation, a pure function of its inputs). The
//! standard errors are the fit's covariance times max(1, chi2 / dof).
//!
//! It names I_perp when |dI| is above `max_ratio` of the configured I_perp
//! and [`NAME_SIGMAS`] of its standard error, and m_s when |dm_s| is above
//! both max(`max_ratio` m_s, `min_adapter_kg`) and [`NAME_SIGMAS`] of its
//! standard error, after at least [`MIN_SAMPLES`] free samples, at
//! [`NAME_PERSIST_SAMPLES`] free samples in a row, and only while neither
//! implied value is impossible (below 0 by [`IMPOSSIBLE_SIGMAS`]: then the
//! phantom is not the inertia's, e.g. drives faster than their model read
//! as a negative adapter). A name stays (it is a finding about the robot, not a state of the motion); the
//! implied values go on following the window. It decides nothing: the
//! guard's margin covers the configured standard deviation of I_perp
//! meanwhile (`crate::inertial`'s variance), not the adapter's.

use crate::inertial::RodInertia;
use crate::{SettingError, Vec3};
use nalgebra::{ComplexField, SMatrix, SVector};

/// Unknowns: dI, dm_s and the offset b (x, y, z).
const UNKNOWNS: usize = 5;
/// The augmented Gram matrix's size.
const WIDTH: usize = UNKNOWNS + 1;
type Gram = SMatrix<f64, WIDTH, WIDTH>;
type Square = SMatrix<f64, UNKNOWNS, UNKNOWNS>;
type Unknowns = SVector<f64, UNKNOWNS>;

/// A value is named beyond this many of its standard errors.
pub const NAME_SIGMAS: f64 = 5.0;
/// Free samples (effective, after forgetting) before anything is named.
pub const MIN_SAMPLES: f64 = 100.0;
/// A value is named when it has been beyond its limits at this many free
/// samples in a row (a transient of the fit, e.g. a servo's lag read
/// early in a move, is not a finding).
pub const NAME_PERSIST_SAMPLES: u8 = 100;
/// Implied values below 0 by more than this many standard errors (a
/// negative I_perp or adapter mass) say that the inertia is not what the
/// phantom comes from (the servo, the support): nothing is named then.
pub const IMPOSSIBLE_SIGMAS: f64 = 3.0;

/// The watch's settings (`[manipulator] inertia_watch_*`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaWatchConfig {
    /// I_perp (or m_s) is named when off by more than this fraction of the
    /// configured value (ratio, > 0).
    pub max_ratio: f64,
    /// m_s is named when off by more than this too, kg (>= 0: an adapter
    /// configured as 0 has no fraction).
    pub min_adapter_kg: f64,
    /// The window of free samples the fit remembers (its forgetting time
    /// constant), s (> 0).
    pub window_s: f64,
}

impl Default for InertiaWatchConfig {
    fn default() -> Self {
        Self {
            max_ratio: 0.2,
            min_adapter_kg: 0.1,
            window_s: 10.0,
        }
    }
}

impl InertiaWatchConfig {
    /// Every value in range.
    pub fn check(&self) -> Result<(), SettingError> {
        let positive = |field, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SettingError::Invalid {
                    field,
                    value,
                    why: "must be finite and > 0",
                })
            }
        };
        positive("inertia_watch_max_ratio", self.max_ratio)?;
        positive("inertia_watch_window_s", self.window_s)?;
        crate::finite_non_negative("inertia_watch_min_adapter_kg", self.min_adapter_kg)
    }
}

/// One free sample: the estimate and its sensitivities, {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchSample {
    /// The estimated F_tip, N.
    pub force_n: Vec3,
    /// Its standard deviation per axis, N (> 0).
    pub std_n: Vec3,
    /// dF_tip / dI_perp, N per kg m^2.
    pub d_inertia: Vec3,
    /// dF_tip / dm_s, N per kg.
    pub d_adapter: Vec3,
}

/// What the watch has named (latched).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InertiaNamed {
    /// I_perp off by more than the limit.
    pub inertia_perp: bool,
    /// m_s off by more than the limit.
    pub adapter: bool,
}

impl InertiaNamed {
    /// Whether anything is named.
    pub fn any(&self) -> bool {
        self.inertia_perp || self.adapter
    }

    /// The published code: bit 0 I_perp, bit 1 the adapter.
    pub fn code(&self) -> u32 {
        u32::from(self.inertia_perp) | (u32::from(self.adapter) << 1)
    }
}

/// The watch's result after a cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaVerdict {
    /// The I_perp the free motion implies (the configured one plus dI),
    /// kg m^2 (the configured one before any fit).
    pub inertia_perp_kgm2: f64,
    /// Its standard error, kg m^2 (infinite before any fit).
    pub inertia_perp_std_kgm2: f64,
    /// The implied I_perp over the configured one.
    pub inertia_perp_ratio: f64,
    /// The m_s the free motion implies, kg.
    pub adapter_mass_kg: f64,
    /// Its standard error, kg.
    pub adapter_mass_std_kg: f64,
    /// Free samples in the window (effective, after forgetting).
    pub samples: f64,
    /// What is named (latched).
    pub named: InertiaNamed,
    /// Something was named first in this cycle (the log line's cue).
    pub newly_named: bool,
}

/// The Gram matrix's entries that are not always 0, (row, column) with
/// row <= column, as they are stored: the offsets' columns (2, 3, 4) meet
/// only themselves (each row holds one of them).
const ENTRIES: [(usize, usize); 18] = [
    (0, 0),
    (0, 1),
    (0, 2),
    (0, 3),
    (0, 4),
    (0, 5),
    (1, 1),
    (1, 2),
    (1, 3),
    (1, 4),
    (1, 5),
    (2, 2),
    (2, 5),
    (3, 3),
    (3, 5),
    (4, 4),
    (4, 5),
    (5, 5),
];

/// The watch (see the module's doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaWatch {
    config: InertiaWatchConfig,
    /// The configured I_perp, kg m^2.
    inertia_perp_kgm2: f64,
    /// The configured m_s, kg.
    adapter_mass_kg: f64,
    /// The forgetting factor per free sample.
    forget: f64,
    /// The window's augmented Gram matrix [X y]^T [X y]: its [`ENTRIES`]
    /// (the rest is 0 or their mirror), in that order.
    gram: [[f64; 6]; 3],
    /// Free samples since the start (the window's effective count is
    /// (1 - f^n) / (1 - f) with the forgetting factor f).
    free_samples: u32,
    /// Free samples in a row at which I_perp, and m_s, were beyond their
    /// limits; [`NAMED`] once named (latched).
    over: [u8; 2],
}

/// [`InertiaWatch`]'s count of a value named (latched).
const NAMED: u8 = u8::MAX;

impl InertiaWatch {
    /// A watch of the configured `inertia`, the sensor sampled every
    /// `sample_period_s`.
    pub fn new(
        config: InertiaWatchConfig,
        inertia: &RodInertia,
        sample_period_s: f64,
    ) -> Result<Self, SettingError> {
        config.check()?;
        inertia.check()?;
        if !(sample_period_s.is_finite() && sample_period_s > 0.0) {
            return Err(SettingError::Invalid {
                field: "sample_period_s",
                value: sample_period_s,
                why: "must be finite and > 0",
            });
        }
        let window_samples = (config.window_s / sample_period_s).max(1.0);
        Ok(Self {
            config,
            inertia_perp_kgm2: inertia.inertia_perp_kgm2,
            adapter_mass_kg: inertia.adapter_mass_kg,
            forget: 1.0 - 1.0 / window_samples,
            gram: [[0.0; 6]; 3],
            free_samples: 0,
            over: [0; 2],
        })
    }

    /// The settings.
    pub fn config(&self) -> &InertiaWatchConfig {
        &self.config
    }

    /// The verdict as the window stands (`newly_named` false): what a
    /// cycle without a free sample reports.
    pub fn idle(&self) -> InertiaVerdict {
        self.judge(&self.gram()).0
    }

    /// Adds one free sample (the tip free, the carriage moving) and judges.
    /// A sample that is not finite, or whose standard deviation is not
    /// positive, is left out.
    pub fn update(&mut self, s: &WatchSample) -> InertiaVerdict {
        let finite = [s.force_n, s.std_n, s.d_inertia, s.d_adapter]
            .iter()
            .all(|v| v.iter().all(|x| x.is_finite()));
        if !finite || s.std_n.iter().any(|x| *x <= 0.0) {
            return self.idle();
        }
        let mut gram = self.gram() * self.forget;
        let components = s.force_n.iter().zip(s.std_n.iter());
        let sensitivities = s.d_inertia.iter().zip(s.d_adapter.iter());
        for (k, ((force, std), (d_i, d_s))) in components.zip(sensitivities).enumerate() {
            let w = 1.0 / std;
            let unit = Vec3::ith(k, w);
            let row =
                SVector::<f64, WIDTH>::new(-d_i * w, -d_s * w, unit.x, unit.y, unit.z, force * w);
            gram += row * row.transpose();
        }
        for (&(i, j), stored) in ENTRIES.iter().zip(self.gram.iter_mut().flatten()) {
            *stored = gram.get((i, j)).copied().unwrap_or(0.0);
        }
        self.free_samples = self.free_samples.saturating_add(1);
        // Judged on the matrix as stored (a restored watch judges alike).
        let (mut verdict, off) = self.judge(&self.gram());
        let before = self.named();
        for (over, off) in self.over.iter_mut().zip(off) {
            *over = match (*over, off) {
                (NAMED, _) => NAMED,
                (n, true) if n.saturating_add(1) >= NAME_PERSIST_SAMPLES => NAMED,
                (n, true) => n + 1,
                (_, false) => 0,
            };
        }
        verdict.named = self.named();
        verdict.newly_named = verdict.named != before;
        verdict
    }

    /// What is named (latched).
    fn named(&self) -> InertiaNamed {
        let [inertia, adapter] = self.over;
        InertiaNamed {
            inertia_perp: inertia == NAMED,
            adapter: adapter == NAMED,
        }
    }

    /// Free samples in the window (effective, after forgetting).
    fn samples(&self) -> f64 {
        let n = i32::try_from(self.free_samples).unwrap_or(i32::MAX);
        (1.0 - ComplexField::powi(self.forget, n)) / (1.0 - self.forget)
    }

    /// The stored Gram matrix, whole.
    fn gram(&self) -> Gram {
        let mut gram = Gram::zeros();
        for (&(i, j), &v) in ENTRIES.iter().zip(self.gram.iter().flatten()) {
            for at in [(i, j), (j, i)] {
                if let Some(x) = gram.get_mut(at) {
                    *x = v;
                }
            }
        }
        gram
    }

    /// The window's fit: the verdict (named: as latched) and whether I_perp
    /// and m_s are now beyond their limits (see the module's doc).
    fn judge(&self, gram: &Gram) -> (InertiaVerdict, [bool; 2]) {
        let mut verdict = InertiaVerdict {
            inertia_perp_kgm2: self.inertia_perp_kgm2,
            inertia_perp_std_kgm2: f64::INFINITY,
            inertia_perp_ratio: 1.0,
            adapter_mass_kg: self.adapter_mass_kg,
            adapter_mass_std_kg: f64::INFINITY,
            samples: self.samples(),
            named: self.named(),
            newly_named: false,
        };
        let none = [false; 2];
        let g: Square = gram.fixed_view::<UNKNOWNS, UNKNOWNS>(0, 0).into_owned();
        let b: Unknowns = gram.fixed_view::<UNKNOWNS, 1>(0, UNKNOWNS).into_owned();
        // Column scaling: the sensitivities are of very different sizes.
        let scale = g.diagonal().map(|d| {
            if d > 0.0 {
                1.0 / ComplexField::sqrt(d)
            } else {
                0.0
            }
        });
        if scale.iter().any(|x| *x == 0.0 || !x.is_finite()) {
            return (verdict, none);
        }
        let d = Square::from_diagonal(&scale);
        let Some(chol) = (d * g * d).cholesky() else {
            return (verdict, none);
        };
        let inv = d * chol.inverse() * d;
        let theta = inv * b;
        let samples = self.samples();
        let dof = 3.0 * samples - UNKNOWNS as f64;
        if dof.is_nan() || dof <= 0.0 {
            return (verdict, none);
        }
        let chi2 = (gram.m66 - theta.dot(&b)).max(0.0);
        let widen = (chi2 / dof).max(1.0);
        let std = |var: f64| ComplexField::sqrt((var * widen).max(0.0));
        let (d_i, d_s) = (theta.x, theta.y);
        let (std_i, std_s) = (std(inv.m11), std(inv.m22));
        if ![d_i, d_s, std_i, std_s].iter().all(|x| x.is_finite()) {
            return (verdict, none);
        }
        let i_cfg = self.inertia_perp_kgm2;
        verdict.inertia_perp_kgm2 = i_cfg + d_i;
        verdict.inertia_perp_std_kgm2 = std_i;
        verdict.inertia_perp_ratio = if i_cfg > 0.0 {
            (i_cfg + d_i) / i_cfg
        } else {
            f64::INFINITY
        };
        verdict.adapter_mass_kg = self.adapter_mass_kg + d_s;
        verdict.adapter_mass_std_kg = std_s;
        if samples < MIN_SAMPLES {
            return (verdict, none);
        }
        let c = &self.config;
        let possible = verdict.inertia_perp_kgm2 + IMPOSSIBLE_SIGMAS * std_i >= 0.0
            && verdict.adapter_mass_kg + IMPOSSIBLE_SIGMAS * std_s >= 0.0;
        let inertia_off = d_i.abs() > c.max_ratio * i_cfg && d_i.abs() > NAME_SIGMAS * std_i;
        let adapter_limit = (c.max_ratio * self.adapter_mass_kg).max(c.min_adapter_kg);
        let adapter_off = d_s.abs() > adapter_limit && d_s.abs() > NAME_SIGMAS * std_s;
        (verdict, [possible && inertia_off, possible && adapter_off])
    }
}

sar_snapshot::config_struct!(InertiaWatchConfig {
    max_ratio,
    min_adapter_kg,
    window_s,
});
sar_snapshot::snap_state!(InertiaWatch {
    state: [gram, free_samples, over],
    nested: [],
    config: [config, inertia_perp_kgm2, adapter_mass_kg, forget],
    output: [],
});
