//! The support watch (issue 34 section 3, MODEL.md 5.1): while the tip can be
//! taken as free, what the estimated tip force at varying poses says about
//! the support point B, accumulated sample by sample, allocation-free and
//! bounded (7x7 normal equations with exponential forgetting).
//!
//! With the tip free the true F_tip is 0, so the estimate computed with the
//! configured B0 is the phantom of the support's shift delta = B_true - B0:
//! to first order `F_tip(B0) = -J delta`, J = dF_tip/dB at the sample's pose
//! (finite differences of the estimator itself, with B0 moved by
//! [`JACOBIAN_STEP_M`] along each base axis: the kinematics, the lever and
//! the inertia's compensation all included). Along the rod the support's
//! Coulomb friction reads as a tip force (MODEL.md 4.1): it is an unknown
//! with the sign of the last slide (before the first slide the component
//! along the rod is not used, nor after a motion across the rod whose
//! slide a shifted support could reverse: [`SLIDE_SHIFT_M`]).
//!
//! A small contact reads as a shift would: at one pose a constant tip force
//! and a shift give the same phantom (a horizontal rod: 0.5 N down is 6 mm
//! along the rod; the demo's still support was named so before this fit).
//! So a constant tip force (the contact, in {0}) is an unknown of the fit
//! too, with `free_tip_max_n` as its prior standard deviation: the shift is
//! what the phantom's change with the pose says, never the force's size at
//! one pose. One pose determines no component of the shift (the verdict
//! stays [`SupportVerdict::NotRun`]); turning the rod by about 11 degrees
//! and sliding it (`sarctl support check`) determines all three. A weak
//! prior ([`PRIOR_STD_M`]) keeps the solve defined: a component the poses
//! do not determine keeps a standard error near it and is reported as not
//! determined (above [`SupportWatchConfig::max_std_m`]).
//!
//! What the caller guarantees (the loop, `step/support.rs`): only samples
//! where the tip can be taken as free (no force control, no guarded move,
//! the guard in Ok or awaiting its first reset, the filtered tip force below
//! [`SupportWatchConfig::free_tip_max_n`]). Whether the force was really a
//! shift's phantom is this file's test, which judges the samples by more
//! than their size: the chi-square per degree of freedom of the free tip's
//! fit (shift and friction alone) must stay below [`MAX_CHI2_DOF`] (a
//! contact force does not follow the poses as a support shift does), and
//! the contact found must stay within [`CONTACT_SIGMA`] standard errors or
//! [`MIN_CONTACT_N`]; otherwise the check says it could not run
//! ([`SupportVerdict::NotFree`]).
//!
//! A shift is named ([`SupportVerdict::Shifted`], latched) when a determined
//! component (of the fit with the contact) differs from the acknowledged one
//! (the configured B, or the shift last confirmed) by more than
//! [`SupportWatchConfig::max_shift_m`] and by more than [`NAME_SIGMA`]
//! standard errors, for [`NAME_SAMPLES`] samples in a row. Until
//! [`SupportWatch::confirm`], [`SupportWatch::refuses_force`] holds.

use crate::motion::CarriageMotion;
use crate::tip_force::{TipForceEstimate, TipForceEstimator};
use crate::{Calibration, Mat3, Profile, SettingError, Vec3, positive};
use nalgebra::ComplexField;
use sar_kinematics::slide::SlideDirection;
use sar_kinematics::{ActiveJoints, Pose, forward};

/// The step of B for the finite-difference Jacobian, m.
pub const JACOBIAN_STEP_M: f64 = 1e-3;

/// The prior standard deviation of each component of the shift, m: what
/// keeps the 3x3 solve defined when the poses determine fewer than three
/// components (the largest shift MODEL.md 10 expects is 20 mm).
pub const PRIOR_STD_M: f64 = 0.05;

/// Above this chi-square per degree of freedom the samples are not those of
/// a free tip under a shifted support: the check could not run.
pub const MAX_CHI2_DOF: f64 = 1.5;

/// A shift is named only beyond this many standard errors (besides the
/// configured limit): the noise alone never names one.
pub const NAME_SIGMA: f64 = 5.0;

/// A constant tip force (the fit's contact) beyond this many standard
/// errors on an axis says the tip is not free.
pub const CONTACT_SIGMA: f64 = 5.0;

/// ... and beyond this, N.
pub const MIN_CONTACT_N: f64 = 0.2;

/// Fewer (forgetting-weighted) samples than this: no verdict yet.
pub const MIN_SAMPLES: f64 = 250.0;

/// A shift is named only after this many samples in a row found it beyond
/// the limit (with the fit consistent): a passing excursion of the running
/// estimate, or a contact's force before the fit's chi-square shows it, is
/// not named.
pub const NAME_SAMPLES: u32 = 250;

/// The support watch's settings (`[support]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportWatchConfig {
    /// A shift beyond this on a determined axis is named, m (> 0).
    pub max_shift_m: f64,
    /// The tip is taken as free only while the filtered tip force is below
    /// this, N (> 0).
    pub free_tip_max_n: f64,
    /// The forgetting's window, in samples (> 1): each sample's weight
    /// decays by 1 - 1/window per sample after it.
    pub window_samples: f64,
    /// A component of the shift whose standard error exceeds this is not
    /// determined (not judged), m (> 0).
    pub max_std_m: f64,
}

impl SupportWatchConfig {
    /// The built-in settings: 3 mm, 2.5 N, 5 s at 500 Hz, 1 mm.
    pub const DEFAULT: Self = Self {
        max_shift_m: 0.003,
        free_tip_max_n: 2.5,
        window_samples: 2_500.0,
        max_std_m: 0.001,
    };

    /// Every value in its range.
    pub fn check(&self) -> Result<(), SettingError> {
        positive("support.max_shift_m", self.max_shift_m)?;
        positive("support.free_tip_max_n", self.free_tip_max_n)?;
        positive("support.max_std_m", self.max_std_m)?;
        crate::require(
            self.window_samples.is_finite() && self.window_samples > 1.0,
            "support.window_samples",
            self.window_samples,
            "must be finite and > 1",
        )
    }
}

/// What the watch says of the support now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SupportVerdict {
    /// Too few free samples yet, or poses that determine no component of
    /// the shift (one pose: a contact would read the same): the check has
    /// not run.
    NotRun,
    /// The tip force does not follow the poses as a support shift does (a
    /// contact, or another model error): the check could not run.
    NotFree,
    /// Every determined component within the limit.
    Within,
    /// A shift beyond the limit was named; force control is refused until
    /// it is confirmed.
    Shifted,
}

impl SupportVerdict {
    /// The wire's code (the published state): 0 not run, 1 not free, 2
    /// within, 3 shifted.
    pub fn code(self) -> u32 {
        match self {
            Self::NotRun => 0,
            Self::NotFree => 1,
            Self::Within => 2,
            Self::Shifted => 3,
        }
    }

    /// In words.
    pub fn words(self) -> &'static str {
        match self {
            Self::NotRun => "not run (too few free-tip samples, or poses that determine no axis)",
            Self::NotFree => "could not run (the tip force is not that of a free tip)",
            Self::Within => "within the limit",
            Self::Shifted => "shifted beyond the limit",
        }
    }
}

/// The support's estimated shift now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportStatus {
    /// B_true - B_configured, base frame, m.
    pub shift_m: Vec3,
    /// Its standard error per base axis, m (widened by sqrt(chi2/dof) when
    /// above 1).
    pub std_m: Vec3,
    /// The constant tip force the fit with a contact finds, base frame, N
    /// (the nuisance that keeps a single pose from naming a shift).
    pub contact_n: Vec3,
    /// Its standard error per base axis, N.
    pub contact_std_n: Vec3,
    /// Chi-square per degree of freedom of the free tip's fit.
    pub chi2_dof: f64,
    /// Forgetting-weighted free samples behind it.
    pub samples: f64,
    /// The verdict.
    pub verdict: SupportVerdict,
    /// The shift named (latched until confirmed), m.
    pub named_m: Option<Vec3>,
}

impl SupportStatus {
    /// Before any sample.
    pub const NONE: Self = Self {
        shift_m: Vec3::new(0.0, 0.0, 0.0),
        std_m: Vec3::new(PRIOR_STD_M, PRIOR_STD_M, PRIOR_STD_M),
        contact_n: Vec3::new(0.0, 0.0, 0.0),
        contact_std_n: Vec3::new(0.0, 0.0, 0.0),
        chi2_dof: 0.0,
        samples: 0.0,
        verdict: SupportVerdict::NotRun,
        named_m: None,
    };

    /// Whether component `axis` (0 X0, 1 Y0, 2 Z0) is determined under
    /// `max_std_m`.
    pub fn determined(&self, axis: usize, max_std_m: f64) -> bool {
        self.std_m.get(axis).is_some_and(|s| *s <= max_std_m)
    }
}

/// The accumulating support watch (see the module documentation).
#[derive(Debug, Clone)]
pub struct SupportWatch {
    config: SupportWatchConfig,
    profile: Profile,
    /// The configured calibration (B0).
    calibration: Calibration,
    /// The estimator with the configured B.
    base: TipForceEstimator,
    /// The covariance of one sample's F_A, {0}, N^2.
    ujoint_covariance_n2: Mat3,
    /// The normal equations over (shift, friction), forgetting-weighted:
    /// the shift's block, 1/N^2 (N/m)^2 = 1/m^2.
    info_b: Mat3,
    /// The shift-friction block, 1/(m N).
    info_bf: Vec3,
    /// The friction's, 1/N^2.
    info_ff: f64,
    /// The shift-contact block (the contact: a constant tip force, the
    /// nuisance that a single pose cannot tell from a shift), 1/(m N).
    info_bc: Mat3,
    /// The friction-contact block, 1/N^2.
    info_fc: Vec3,
    /// The contact's block, 1/N^2.
    info_cc: Mat3,
    /// J^T W r over the shift, 1/m.
    rhs_b: Vec3,
    /// Over the contact, 1/N.
    rhs_c: Vec3,
    /// Over the friction, 1/N.
    rhs_f: f64,
    /// r^T W r.
    rr: f64,
    /// Forgetting-weighted rows (3 per sample with the slide sign known, 2
    /// without).
    rows: f64,
    /// Forgetting-weighted sample count.
    count: f64,
    /// The direction of the rod's last slide through the support (from a,
    /// with the simulator's and identification's hysteresis): the sign of
    /// the friction's coefficient; unknown before the first slide.
    slide: SlideDirection,
    /// The acknowledged shift (the configured B: 0; or the one confirmed), m.
    acknowledged_m: Vec3,
    /// Samples in a row that found a shift beyond the limit.
    beyond_run: u32,
    /// Where the model is linearised: B0 + center, m (moved to the
    /// determined estimate once it is more than [`RECENTER_M`] away, so
    /// that a large shift is not judged on a first-order model about the
    /// wrong point).
    center_m: Vec3,
    /// The fit's chi-square said "not a free tip" (left below
    /// [`FREE_AGAIN_CHI2_DOF`]: no flapping at the limit).
    not_free: bool,
    /// The shift named (latched until confirmed), m.
    named_m: Option<Vec3>,
}

/// The linearisation point moves when the estimate is this far from it, m.
pub const RECENTER_M: f64 = 1e-3;

/// Once "not a free tip", the chi-square per degree of freedom must fall
/// below this to judge again.
pub const FREE_AGAIN_CHI2_DOF: f64 = 1.3;

/// One sample linearised about B0 + center: the pose and the estimate there,
/// and dF_tip/dB at the free reading.
struct Linearised {
    pose: Pose,
    estimate: TipForceEstimate,
    jac: Mat3,
}

/// The largest distance between the support and where the watch believes
/// it (B0 + its linearisation point) against which the friction's sign is
/// taken as known, m (the largest shift expected, SAFETY.md M5): a slide
/// whose direction a support that far would reverse leaves the friction's
/// sign unknown (see [`SupportWatch::observe`]). Once the estimate is
/// determined the reach is its own error's ([`SLIDE_SIGMA`]).
pub const SLIDE_SHIFT_M: f64 = 0.02;

/// The reach of the slide's sign once the estimate is determined: its
/// distance from the linearisation point plus this many standard errors.
pub const SLIDE_SIGMA: f64 = 3.0;

/// The prior standard deviation of the support's friction unknown, N.
pub const PRIOR_FRICTION_N: f64 = 5.0;

type Mat4 = nalgebra::Matrix4<f64>;
type Vec4 = nalgebra::Vector4<f64>;
type Mat7 = nalgebra::SMatrix<f64, 7, 7>;
type Vec7 = nalgebra::SVector<f64, 7>;

impl SupportWatch {
    /// A watch for the robot `base` (its estimator's calibration, profile and
    /// tip settings, inertia included).
    pub fn new(
        config: SupportWatchConfig,
        calibration: &Calibration,
        profile: &Profile,
        base: &TipForceEstimator,
    ) -> Result<Self, SettingError> {
        config.check()?;
        Ok(Self {
            config,
            profile: *profile,
            calibration: *calibration,
            ujoint_covariance_n2: base.ujoint_covariance_n2(),
            base: *base,
            info_b: Mat3::zeros(),
            info_bf: Vec3::zeros(),
            info_ff: 0.0,
            info_bc: Mat3::zeros(),
            info_fc: Vec3::zeros(),
            info_cc: Mat3::zeros(),
            rhs_b: Vec3::zeros(),
            rhs_c: Vec3::zeros(),
            rhs_f: 0.0,
            rr: 0.0,
            rows: 0.0,
            count: 0.0,
            slide: SlideDirection::new(),
            acknowledged_m: Vec3::zeros(),
            beyond_run: 0,
            center_m: Vec3::zeros(),
            not_free: false,
            named_m: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &SupportWatchConfig {
        &self.config
    }

    /// The status after the last sample (or confirmation): the shift and
    /// its standard errors solved from the sums (a pure function of the
    /// watch's state), the verdict.
    pub fn status(&self) -> SupportStatus {
        let solved = self.solve();
        let verdict = if self.named_m.is_some() {
            SupportVerdict::Shifted
        } else if self.count < MIN_SAMPLES
            || determined_mask(&solved, self.config.max_std_m) == Vec3::zeros()
        {
            // Too few samples, or poses that determine no component.
            SupportVerdict::NotRun
        } else if self.not_free {
            SupportVerdict::NotFree
        } else {
            SupportVerdict::Within
        };
        SupportStatus {
            verdict,
            named_m: self.named_m,
            ..solved
        }
    }

    /// A shift was named and not yet confirmed: force control is refused.
    pub fn refuses_force(&self) -> bool {
        self.named_m.is_some()
    }

    /// The operator confirms the support as it is now: the named shift (or
    /// the present estimate of the determined components) becomes the
    /// acknowledged one, against which a later shift is judged.
    pub fn confirm(&mut self) {
        let s = self.status();
        for axis in 0..3 {
            if s.determined(axis, self.config.max_std_m)
                && let (Some(a), Some(v)) = (self.acknowledged_m.get_mut(axis), s.shift_m.get(axis))
            {
                *a = *v;
            }
        }
        if let Some(named) = s.named_m {
            self.acknowledged_m = named;
        }
        self.named_m = None;
        self.beyond_run = 0;
    }

    /// One sample with the tip taken as free: the joints `q`, the raw
    /// reading and the bias (sensor frame), the carriage's motion, and the
    /// cycle's estimate
    /// `estimate` at `base_pose` (both computed with the configured B). A sample
    /// whose shifted estimates cannot be computed (a pose invalid with a
    /// shifted B) is skipped. Until the rod has slid the component along it
    /// is not used (the support's friction there has no known sign), nor
    /// after a motion whose slide a support as far as the estimate's reach
    /// from where it is believed could reverse (turning the rod across it:
    /// [`SLIDE_SHIFT_M`], [`SLIDE_SIGMA`]), until the next slide that none
    /// reverses. The slide is followed about B0 + the linearisation point.
    pub fn observe(
        &mut self,
        q: &ActiveJoints,
        reading_n: &Vec3,
        bias_n: &Vec3,
        motion: &CarriageMotion,
        estimate: &TipForceEstimate,
        base_pose: &Pose,
    ) {
        let Some(lin) = self.linearise(q, reading_n, bias_n, motion, estimate, base_pose) else {
            return;
        };
        // The slide about the linearisation point B0 + center (where the
        // support is believed to be), its sign unknown after a motion whose
        // slide a support within the estimate's reach of it could reverse.
        let center_m = self.calibration.support_m() + self.center_m;
        if slide_unsure(&center_m, &lin.pose, motion, self.slide_reach_m()) {
            self.slide = SlideDirection::new();
        }
        self.slide.update(lin.pose.support_distance_m);
        let rod_dir = &lin.pose.rod_dir;
        let sigma = self.slide.sign().sigma();
        let keep_axial = sigma.is_some();
        let rows = if keep_axial {
            Mat3::identity()
        } else {
            Mat3::identity() - rod_dir * rod_dir.transpose()
        };
        let jac = rows * lin.jac;
        // The friction reads as a tip force along the rod: sigma f u.
        let friction = rod_dir * sigma.unwrap_or(0.0);
        let residual = rows * lin.estimate.force_n;
        let Some(w) = self.weight(&lin.estimate, &lin.pose, &rows, keep_axial) else {
            return;
        };
        let keep = 1.0 - 1.0 / self.config.window_samples;
        let jw = jac.transpose() * w;
        // The contact's columns: a constant tip force, in the rows used.
        let cw = rows.transpose() * w;
        self.info_b = self.info_b * keep + jw * jac;
        self.info_bf = self.info_bf * keep + jw * friction;
        self.info_ff = self.info_ff * keep + friction.dot(&(w * friction));
        self.info_bc = self.info_bc * keep + jw * rows;
        self.info_fc = self.info_fc * keep + cw * friction;
        self.info_cc = self.info_cc * keep + cw * rows;
        self.rhs_b = self.rhs_b * keep + jw * residual;
        self.rhs_c = self.rhs_c * keep + cw * residual;
        self.rhs_f = self.rhs_f * keep + friction.dot(&(w * residual));
        self.rr = self.rr * keep + residual.dot(&(w * residual));
        self.rows = self.rows * keep + if keep_axial { 3.0 } else { 2.0 };
        self.count = self.count * keep + 1.0;
        self.judge();
        if self.recenter() {
            self.judge();
        }
    }

    /// The sample about B0 + center: the estimate there (the cycle's own
    /// when the center is B0) and the Jacobian at the reading a free tip
    /// would give (the estimate's own noise taken out: a Jacobian from the
    /// noisy reading correlates with the residual and biases the shift, 4
    /// standard errors in 5000 samples). F_tip = T F_A + const with T =
    /// u u^T - a/(L - a) P (MODEL.md 4.1), so the free reading is f_s +
    /// R_0s^T T^-1 F_tip, T^-1 = u u^T - (L - a)/a P. `None` when a pose or
    /// an estimate cannot be computed.
    fn linearise(
        &self,
        q: &ActiveJoints,
        reading_n: &Vec3,
        bias_n: &Vec3,
        motion: &CarriageMotion,
        estimate: &TipForceEstimate,
        base_pose: &Pose,
    ) -> Option<Linearised> {
        let b0 = self.calibration.support_m();
        let at = |support_m: Vec3| -> Option<(TipForceEstimator, Pose)> {
            let cal = self.calibration.with_support(support_m).ok()?;
            let pose = forward(&cal, &self.profile, q).ok()?;
            Some((self.base.with_calibration(&cal), pose))
        };
        let (center, pose, estimate) = if self.center_m == Vec3::zeros() {
            (self.base, *base_pose, *estimate)
        } else {
            let (est, pose) = at(b0 + self.center_m)?;
            let e = est
                .estimate_in_motion(&pose, reading_n, bias_n, motion)
                .ok()?;
            (est, pose, e)
        };
        let u = pose.rod_dir;
        let along = u * u.transpose();
        let inverse_lever = pose.tip_beyond_support_m / pose.support_distance_m;
        let t_inverse = along - (Mat3::identity() - along) * inverse_lever;
        let rotation = self.calibration.sensor_rotation();
        let free_reading_n = reading_n + rotation.transpose() * (t_inverse * estimate.force_n);
        let free = center
            .estimate_in_motion(&pose, &free_reading_n, bias_n, motion)
            .ok()?;
        let mut jac = Mat3::zeros();
        for (k, axis) in [Vec3::x(), Vec3::y(), Vec3::z()].iter().enumerate() {
            let (est, shifted) = at(b0 + self.center_m + axis * JACOBIAN_STEP_M)?;
            let e = est
                .estimate_in_motion(&shifted, &free_reading_n, bias_n, motion)
                .ok()?;
            jac.set_column(k, &((e.force_n - free.force_n) / JACOBIAN_STEP_M));
        }
        jac.iter().all(|x| x.is_finite()).then_some(Linearised {
            pose,
            estimate,
            jac,
        })
    }

    /// How far from B0 + center the support may be, m, for the slide's
    /// sign: the determined estimate's distance from the center plus
    /// [`SLIDE_SIGMA`] standard errors on each axis, at most
    /// [`SLIDE_SHIFT_M`] (before any component is determined, the prior's
    /// standard error makes it `SLIDE_SHIFT_M`).
    fn slide_reach_m(&self) -> f64 {
        let s = self.solve();
        s.shift_m
            .iter()
            .zip(self.center_m.iter())
            .zip(s.std_m.iter())
            .map(|((v, c), sd)| (v - c).abs() + SLIDE_SIGMA * sd)
            .fold(0.0, f64::max)
            .min(SLIDE_SHIFT_M)
    }

    /// Moves the linearisation point to the determined components of the
    /// estimate when it is more than [`RECENTER_M`] away; the sums follow
    /// (the residual about the new point is r + J dc, to first order).
    /// Whether it moved.
    fn recenter(&mut self) -> bool {
        let s = self.status();
        if s.verdict == SupportVerdict::NotRun || self.not_free {
            return false;
        }
        let max_std_m = self.config.max_std_m;
        let mask = determined_mask(&s, max_std_m);
        let dc = (s.shift_m - self.center_m).component_mul(&mask);
        let far = dc.norm() > RECENTER_M;
        if !far {
            return false;
        }
        let target = self.center_m + dc;
        self.rr += 2.0 * dc.dot(&self.rhs_b) + dc.dot(&(self.info_b * dc));
        self.rhs_f += self.info_bf.dot(&dc);
        self.rhs_c += self.info_bc.transpose() * dc;
        self.rhs_b += self.info_b * dc;
        self.center_m = target;
        // The slide is followed about the new point: its distance jumps,
        // the sign is unknown until the next sure slide.
        self.slide = SlideDirection::new();
        true
    }

    /// The weight of one sample's rows: the inverse of the tip force's
    /// covariance, from the sensor's (F_tip = (u u^T - a/(L - a) P) F_A
    /// plus constants, MODEL.md 4.1), with what the motion adds on the
    /// diagonal; over the rows across the rod only when the component along
    /// it is not used. `None` when not finite or not invertible.
    fn weight(
        &self,
        estimate: &TipForceEstimate,
        pose: &Pose,
        rows: &Mat3,
        keep_axial: bool,
    ) -> Option<Mat3> {
        let u = pose.rod_dir;
        let along = u * u.transpose();
        let across = Mat3::identity() - along;
        let lever = pose.support_distance_m / pose.tip_beyond_support_m;
        let t = along - across * lever;
        let mut c = t * self.ujoint_covariance_n2 * t.transpose();
        for k in 0..3 {
            let (Some(var), Some(std)) = (c.get_mut((k, k)), estimate.std_n.get(k)) else {
                return None;
            };
            *var = var.max(std * std);
        }
        let w = if keep_axial {
            c.try_inverse()?
        } else {
            rows * (rows * c * rows + along).try_inverse()? * rows
        };
        w.iter().all(|x| x.is_finite()).then_some(w)
    }

    /// The normal equations over (shift, friction, contact) and their
    /// right-hand side.
    fn normal(&self) -> (Mat7, Vec7) {
        let mut info = Mat7::zeros();
        info.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.info_b);
        info.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.info_bf);
        info.fixed_view_mut::<1, 3>(3, 0)
            .copy_from(&self.info_bf.transpose());
        info.fixed_view_mut::<3, 3>(0, 4).copy_from(&self.info_bc);
        info.fixed_view_mut::<3, 3>(4, 0)
            .copy_from(&self.info_bc.transpose());
        info.fixed_view_mut::<1, 3>(3, 4)
            .copy_from(&self.info_fc.transpose());
        info.fixed_view_mut::<3, 1>(4, 3).copy_from(&self.info_fc);
        info.fixed_view_mut::<3, 3>(4, 4).copy_from(&self.info_cc);
        info.fixed_view_mut::<1, 1>(3, 3).fill(self.info_ff);
        let mut rhs = Vec7::zeros();
        rhs.fixed_rows_mut::<3>(0).copy_from(&self.rhs_b);
        rhs.fixed_rows_mut::<1>(3).fill(self.rhs_f);
        rhs.fixed_rows_mut::<3>(4).copy_from(&self.rhs_c);
        (info, rhs)
    }

    /// The shift, its standard errors and the verdict from the sums.
    fn judge(&mut self) {
        let solved = self.solve();
        let mut beyond = false;
        if self.count >= MIN_SAMPLES && !self.not_free_now(&solved) {
            beyond = self.beyond(&solved);
        }
        self.beyond_run = if beyond {
            self.beyond_run.saturating_add(1)
        } else {
            0
        };
        if self.named_m.is_none() && self.beyond_run >= NAME_SAMPLES {
            // The determined components; the others are not known (0).
            let mask = determined_mask(&solved, self.config.max_std_m);
            self.named_m = Some(solved.shift_m.component_mul(&mask));
        }
    }

    /// The shift, its standard errors, the contact and the chi-square from
    /// the sums (the verdict and the named shift left as before any
    /// sample): the shift and the contact from the fit with the contact
    /// (what the poses' variation determines), the chi-square from the fit
    /// of a free tip (a contact's misfit).
    fn solve(&self) -> SupportStatus {
        let (info, rhs) = self.normal();
        let b = 1.0 / (PRIOR_STD_M * PRIOR_STD_M);
        let f = 1.0 / (PRIOR_FRICTION_N * PRIOR_FRICTION_N);
        let c = 1.0 / (self.config.free_tip_max_n * self.config.free_tip_max_n);
        let prior = Mat7::from_diagonal(&Vec7::from_column_slice(&[b, b, b, f, c, c, c]));
        // The free tip's fit: (shift, friction), the top-left block.
        let info4: Mat4 = info.fixed_view::<4, 4>(0, 0).into_owned();
        let rhs4: Vec4 = rhs.fixed_rows::<4>(0).into_owned();
        let prior4: Mat4 = prior.fixed_view::<4, 4>(0, 0).into_owned();
        let Some(chol4) = (info4 + prior4).cholesky() else {
            return SupportStatus::NONE;
        };
        // F_tip(B0) = -(J delta + sigma u f - contact): theta = -(N)^-1 X^T W r.
        let theta4 = -chol4.solve(&rhs4);
        let chi2 = self.rr + 2.0 * theta4.dot(&rhs4) + theta4.dot(&(info4 * theta4));
        let dof = (self.rows - 4.0).max(1.0);
        let chi2_dof = chi2.max(0.0) / dof;
        let scale = chi2_dof.max(1.0);
        let Some(chol) = (info + prior).cholesky() else {
            return SupportStatus::NONE;
        };
        let theta = -chol.solve(&rhs);
        let covariance = chol.inverse();
        let std = covariance
            .diagonal()
            .map(|v| ComplexField::sqrt(v.max(0.0) * scale));
        SupportStatus {
            shift_m: self.center_m + theta.fixed_rows::<3>(0).into_owned(),
            std_m: std.fixed_rows::<3>(0).into_owned(),
            // The contact's column is +I: theta holds minus the contact.
            contact_n: -theta.fixed_rows::<3>(4).into_owned(),
            contact_std_n: std.fixed_rows::<3>(4).into_owned(),
            chi2_dof,
            samples: self.count,
            ..SupportStatus::NONE
        }
    }

    /// The samples are not those of a free tip: the free tip's fit's
    /// chi-square per degree of freedom above [`MAX_CHI2_DOF`] (until it
    /// falls below [`FREE_AGAIN_CHI2_DOF`]), or a constant tip force found
    /// beyond [`CONTACT_SIGMA`] standard errors and [`MIN_CONTACT_N`] on an
    /// axis (a contact that stays, which the poses' variation tells from a
    /// shift).
    fn not_free_now(&mut self, s: &SupportStatus) -> bool {
        let limit = if self.not_free {
            FREE_AGAIN_CHI2_DOF
        } else {
            MAX_CHI2_DOF
        };
        let contact = s
            .contact_n
            .iter()
            .zip(s.contact_std_n.iter())
            .any(|(c, sd)| c.abs() > MIN_CONTACT_N && c.abs() > CONTACT_SIGMA * sd);
        self.not_free = s.chi2_dof.is_nan() || s.chi2_dof > limit || contact;
        self.not_free
    }

    /// A determined component beyond the limit and beyond [`NAME_SIGMA`]
    /// standard errors from the acknowledged shift.
    fn beyond(&self, s: &SupportStatus) -> bool {
        (0..3).any(|axis| {
            let (Some(v), Some(a), Some(std)) = (
                s.shift_m.get(axis),
                self.acknowledged_m.get(axis),
                s.std_m.get(axis),
            ) else {
                return false;
            };
            let off = (v - a).abs();
            *std <= self.config.max_std_m && off > self.config.max_shift_m && off > NAME_SIGMA * std
        })
    }
}

/// Whether the carriage's motion slides the rod through the support at
/// `support_m` one way but possibly the other way for a support up to
/// `reach_m` from it: the distance a = |B - A| (along the rod) shrinks as
/// (B - A) . A' > 0, and for every B within `reach_m` that sign is the
/// same only when |(B - A) . A'| > reach_m |A'|. A move across the rod
/// (turning it) slides it by a second-order amount whose direction depends
/// on where B really is: with B 10 mm above the configured B, the slide
/// about the configured B had the other sign than the true one for 13 % of
/// the check's moving samples (0.3 N of friction read with the wrong sign
/// along the rod), which read as a contact and a wrong shift. At rest
/// (A' = 0) the last slide's sign stays.
fn slide_unsure(support_m: &Vec3, pose: &Pose, motion: &CarriageMotion, reach_m: f64) -> bool {
    let speed_mps = motion.velocity_mps.norm();
    let towards_m = (support_m - pose.ujoint_m).dot(&motion.velocity_mps);
    speed_mps > 0.0 && towards_m.abs() <= reach_m * speed_mps
}

/// 1 for each component of `s` determined under `max_std_m`, 0 for the others.
fn determined_mask(s: &SupportStatus, max_std_m: f64) -> Vec3 {
    let one = |k| if s.determined(k, max_std_m) { 1.0 } else { 0.0 };
    Vec3::new(one(0), one(1), one(2))
}

// Snapshots: the sums, the acknowledged shift and the status are state; the
// settings and the shifted estimators come from the configuration.
sar_snapshot::snap_enum!(SupportVerdict {
    0 => NotRun,
    1 => NotFree,
    2 => Within,
    3 => Shifted,
});
sar_snapshot::snap_struct!(SupportStatus {
    shift_m,
    std_m,
    contact_n,
    contact_std_n,
    chi2_dof,
    samples,
    verdict,
    named_m,
});
sar_snapshot::config_struct!(SupportWatchConfig {
    max_shift_m,
    free_tip_max_n,
    window_samples,
    max_std_m,
});
sar_snapshot::snap_state!(SupportWatch {
    state: [
        info_b,
        info_bf,
        info_ff,
        info_bc,
        info_fc,
        info_cc,
        rhs_b,
        rhs_f,
        rhs_c,
        rr,
        rows,
        count,
        slide,
        acknowledged_m,
        beyond_run,
        center_m,
        not_free,
        named_m
    ],
    nested: [],
    config: [config, profile, calibration, base, ujoint_covariance_n2],
    output: [],
});
