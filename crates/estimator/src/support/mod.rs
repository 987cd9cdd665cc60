//! Support calibration (MODEL.md 5.1): a noise-weighted Levenberg-Marquardt fit of
//! the mass m, the first moment M = m c, the support point B and (optionally) the
//! support's friction f from static poses with nothing at the tip (d = 0).
//!
//! Model of the force the robot applies to the rod at A, in {0}:
//!
//! ```text
//! F_A = -m g + (M / a) (g - (g.u) u) + sigma f u,   a = |B - A|,  u = (B - A) / a
//! ```
//!
//! with sigma the pose's slide sign ([`crate::SlideSign`]). The measured
//! F_A = -R_0s (f_s - b) uses the tare b given at construction. Each pose is
//! weighted by the inverse of its noise covariance `R_0s diag(std^2) R_0s^T / K`,
//! through the inverse of its Cholesky factor, so that chi-square per degree of
//! freedom is about 1 when the model and the noise figures are right.
//!
//! The fit looks for the global minimum: besides the start at the configured B,
//! it scans a bounded grid of supports within [`SEARCH_RADIUS_M`] of it with
//! (m, M, f) eliminated (the model is linear in them) and starts again from the
//! best point; the lower of the two minima wins. A result whose chi-square per
//! degree of freedom is above [`SupportOptions::max_chi2_dof`] is refused
//! ([`SupportError::PoorFit`]).
//!
//! The components of B that the poses do not determine (their standard error
//! would exceed [`SupportOptions::max_support_std_m`]) are held at the configured
//! value and reported in [`SupportFit::held`]: under the article's protocol (rod
//! horizontal at the support's height) that is B_z.
//!
//! A pose whose slide sign is unknown (no slide seen before it) is refused when
//! friction is estimated ([`SupportError::UnknownSlideSign`]): each of its three
//! force components involves f, and no coefficient may be guessed for it
//! (MODEL.md 5). Without the friction unknown it is used as any other.
//!
//! Fixed capacity ([`SUPPORT_CAPACITY`] poses; check a procedure's length
//! before it starts with [`SupportCalibration::check_capacity`]), no
//! allocation, no panics. Files: `error` ([`SupportError`]), `model` (unknowns, model, normal equations),
//! `solver` (scaling, factorisation, Levenberg-Marquardt), `held` (covariance,
//! the choice of held components), `search` (the global start); `watch` (the
//! support watch: the shift of B from free-tip samples while the robot runs,
//! issue 34).

mod error;
mod held;
mod model;
mod search;
mod solver;
mod watch;

use crate::{
    Calibration, Mat3, SensorNoise, SettingError, SlideSign, StaticPose, Vec3, check_finite,
    com_std_m, non_negative,
};
use model::{Free, N_UNKNOWNS, Normal, Params, Problem};
use nalgebra::{Cholesky, ComplexField};
use solver::{Pass, PassEnd};
pub use watch::{
    FREE_AGAIN_CHI2_DOF, JACOBIAN_STEP_M, MAX_CHI2_DOF, MIN_SAMPLES, NAME_SAMPLES, NAME_SIGMA,
    PRIOR_FRICTION_N, PRIOR_STD_M, RECENTER_M, SupportStatus, SupportVerdict, SupportWatch,
    SupportWatchConfig,
};

pub use error::SupportError;

/// How many static poses a [`SupportCalibration`] holds at most: the cone set
/// of MODEL.md 5.1 has 20, so a procedure may repeat it six times.
pub const SUPPORT_CAPACITY: usize = 128;

/// Largest accepted distance between the fitted and the configured support
/// point, m. B is measured by hand to a few millimetres; the fit finds the
/// global minimum from a configured B up to [`SEARCH_RADIUS_M`] off, and this
/// leaves a margin of half as much again. Trial steps beyond it are refused, and
/// a fit that ends within 1 % of it has diverged (its minimum lies outside).
pub const MAX_SUPPORT_SHIFT_M: f64 = 0.075;

/// The global search covers supports within this distance of the configured
/// one, m (a cube of grid points [`SEARCH_STEP_M`] apart, cut to
/// [`MAX_SUPPORT_SHIFT_M`]).
pub const SEARCH_RADIUS_M: f64 = 0.05;

/// Spacing of the global search's grid, m: every support within
/// [`SEARCH_RADIUS_M`] has a grid point within sqrt(3)/2 of this (21.7 mm),
/// inside the region from which Levenberg-Marquardt reaches the global minimum
/// (about 30 mm on the cone set; some starts 40 mm off end in local minima).
/// At most 5^3 = 125 grid points, fewer inside the allowed region.
pub const SEARCH_STEP_M: f64 = 0.025;

/// Relative difference of chi-square below which two minima count as one.
const SAME_MINIMUM: f64 = 1e-9;

/// Fraction of [`MAX_SUPPORT_SHIFT_M`] beyond which a final B counts as diverged.
const SHIFT_EDGE: f64 = 0.99;

/// Most Levenberg-Marquardt passes of one fit from one start. A pass ends when
/// it converges or when the set of components of B that the poses determine
/// (re-checked after every accepted step and at the solution) changes; the last
/// pass keeps its set.
pub const MAX_PASSES: u32 = 4;

/// What to estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportOptions {
    /// Estimate the support's Coulomb friction f (with the slide sign as its
    /// coefficient) as an unknown.
    pub friction: bool,
    /// Estimate B. `false`: hold all of B at the configured value, which gives the
    /// linear (m, M, f) estimate.
    pub calibrate_support: bool,
    /// A component of B whose standard error would exceed this is held at its
    /// configured value, m (finite, > 0).
    pub max_support_std_m: f64,
    /// Largest number of Levenberg-Marquardt iterations per pass (>= 1).
    pub max_iterations: u32,
    /// Largest accepted chi-square per degree of freedom of the result (> 0;
    /// infinity accepts every fit). Above it the fit is refused with
    /// [`SupportError::PoorFit`].
    pub max_chi2_dof: f64,
}

impl SupportOptions {
    /// Default of [`SupportOptions::max_support_std_m`]: 0.5 mm (MODEL.md 5.1).
    pub const DEFAULT_MAX_SUPPORT_STD_M: f64 = 0.5e-3;
    /// Default of [`SupportOptions::max_chi2_dof`]: 4, residuals scattering
    /// twice as much as the configured noise. A consistent fit of the cone set
    /// (54 degrees of freedom) gives 1 +- 0.2; a held B_z 1 mm off about 2; a
    /// rod offset d of 5 mm, an untared sensor, friction left out of the model
    /// or a 2 mm error in a held B give 8 to several hundred.
    pub const DEFAULT_MAX_CHI2_DOF: f64 = 4.0;
}

impl Default for SupportOptions {
    /// Friction and support estimated, B components with a standard error above
    /// 0.5 mm held, 50 iterations, chi-square per degree of freedom up to 4.
    fn default() -> Self {
        Self {
            friction: true,
            calibrate_support: true,
            max_support_std_m: Self::DEFAULT_MAX_SUPPORT_STD_M,
            max_iterations: 50,
            max_chi2_dof: Self::DEFAULT_MAX_CHI2_DOF,
        }
    }
}

/// The result of a support calibration.
///
/// Standard errors come from the inverse of the weighted normal matrix at the
/// solution, with the configured sensor noise as the weights, multiplied by
/// `max(1, sqrt(chi2_dof))`: never smaller than the noise model says, and widened
/// when the residuals scatter more than it (the same rule as
/// [`crate::identification`]). A `chi2_dof` far above 1 means the model does not
/// fit (an offset d, an untared sensor, a support that does not pivot about one
/// point): the widened errors are then still only a lower bound of the real ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportFit {
    /// m, kg.
    pub mass_kg: f64,
    /// Standard error of m, kg.
    pub mass_std_kg: f64,
    /// c = M / m, from A along the rod, m.
    pub com_m: f64,
    /// Standard error of c (first-order propagation from m and M), m.
    pub com_std_m: f64,
    /// M = m c, kg m.
    pub moment_kgm: f64,
    /// Standard error of M, kg m.
    pub moment_std_kgm: f64,
    /// B, {0}, m: fitted components, and the configured value for held ones.
    pub support_m: Vec3,
    /// Standard error of each component of B, m; `None` for a held component.
    pub support_std_m: [Option<f64>; 3],
    /// Which components of B were held at the configured value (the poses do not
    /// determine them, or `calibrate_support` is off).
    pub held: [bool; 3],
    /// f, N (`None` when not estimated). Positive: the support resists sliding.
    pub friction_n: Option<f64>,
    /// Standard error of f, N.
    pub friction_std_n: Option<f64>,
    /// Chi-square per degree of freedom (3 per pose minus the free unknowns).
    pub chi2_dof: f64,
    /// RMS of the force residuals F_A,measured - F_A,model over all components, N.
    pub residual_rms_n: f64,
    /// Condition number of the column-scaled weighted Jacobian at the solution,
    /// over the free unknowns.
    pub condition: f64,
    /// Accepted Levenberg-Marquardt steps, over all passes from the start
    /// that gave the result.
    pub iterations: u32,
    /// Whether the result came from the global search's start rather than the
    /// configured B (the configured B led to a higher minimum, or to none).
    pub from_search: bool,
    /// Poses used.
    pub poses: u32,
}

/// Collects static poses and fits m, M, B and f (MODEL.md 5.1).
#[derive(Debug, Clone)]
pub struct SupportCalibration {
    poses: [StaticPose; SUPPORT_CAPACITY],
    len: usize,
    calibration: Calibration,
    /// Inverse of the lower Cholesky factor of one sample's covariance of F_A in {0}.
    whitening: Mat3,
    tare_n: Vec3,
    options: SupportOptions,
}

/// A converged fit from one start, before its figures are computed.
struct Solution {
    theta: Params,
    free: Free,
    /// Full normal equations at `theta`.
    normal: Normal,
    iterations: u32,
}

/// The fitted B must stay finite and within `limit_m` of the configured one
/// (and every unknown finite).
fn check_shift(theta: &Params, configured: &Vec3, limit_m: f64) -> Result<(), SupportError> {
    let shift = theta.support_m.metric_distance(configured);
    let finite = theta.to_vector().iter().all(|x| x.is_finite());
    if finite && shift <= limit_m {
        Ok(())
    } else {
        Err(SupportError::Diverged {
            shift_m: if shift.is_finite() {
                shift
            } else {
                f64::INFINITY
            },
        })
    }
}

impl SupportCalibration {
    /// A calibration with no poses, for the robot `cal` (its support point is the
    /// configured B), the sensor noise `noise` and the sensor's force tare
    /// `bias_n` (sensor frame, measured with no rod in the U-joint).
    pub fn new(
        cal: &Calibration,
        noise: &SensorNoise,
        bias_n: Vec3,
        options: SupportOptions,
    ) -> Result<Self, SupportError> {
        check_finite(&bias_n, |value| SettingError::Invalid {
            field: "bias_n",
            value,
            why: "each tare component must be finite",
        })?;
        if !(options.max_support_std_m.is_finite() && options.max_support_std_m > 0.0) {
            return Err(SettingError::Invalid {
                field: "max_support_std_m",
                value: options.max_support_std_m,
                why: "must be finite and > 0",
            }
            .into());
        }
        if options.max_iterations == 0 {
            return Err(SettingError::Invalid {
                field: "max_iterations",
                value: 0.0,
                why: "must be >= 1",
            }
            .into());
        }
        // NaN fails this too; infinity accepts every fit.
        if options.max_chi2_dof.is_nan() || options.max_chi2_dof <= 0.0 {
            return Err(SettingError::Invalid {
                field: "max_chi2_dof",
                value: options.max_chi2_dof,
                why: "must be > 0 (infinity: no bound)",
            }
            .into());
        }
        let covariance = noise.base_covariance_n2(&cal.sensor_rotation());
        let whitening = Cholesky::new(covariance)
            .and_then(|chol| chol.l().solve_lower_triangular(&Mat3::identity()))
            .filter(|w| w.iter().all(|x| x.is_finite()));
        let Some(whitening) = whitening else {
            return Err(SettingError::Invalid {
                field: "noise_n",
                value: noise.std_n().min(),
                why: "the noise covariance in the base frame is not positive definite",
            }
            .into());
        };
        let empty = StaticPose {
            ujoint_m: Vec3::zeros(),
            mean_reading_n: Vec3::zeros(),
            samples: 1,
            slide_sign: SlideSign::Unknown,
        };
        Ok(Self {
            poses: [empty; SUPPORT_CAPACITY],
            len: 0,
            calibration: *cal,
            whitening,
            tare_n: bias_n,
            options,
        })
    }

    /// Whether a procedure of `planned` poses fits in a calibration: call it
    /// before the procedure starts, so that a long one is refused before the
    /// robot moves rather than at its 129th pose.
    pub fn check_capacity(planned: usize) -> Result<(), SupportError> {
        if planned > SUPPORT_CAPACITY {
            Err(SupportError::TooManyPlanned {
                planned,
                capacity: SUPPORT_CAPACITY,
            })
        } else {
            Ok(())
        }
    }

    /// Adds one static pose. Errors when full, when the pose has a NaN or
    /// infinite value or no samples, or when friction is estimated and the
    /// pose's slide sign is unknown.
    pub fn push(&mut self, pose: &StaticPose) -> Result<(), SupportError> {
        let index = self.len;
        if index >= SUPPORT_CAPACITY {
            return Err(SupportError::Full {
                capacity: SUPPORT_CAPACITY,
            });
        }
        pose.check()
            .map_err(|error| SupportError::Pose { pose: index, error })?;
        if self.options.friction && !pose.slide_sign.is_known() {
            return Err(SupportError::UnknownSlideSign { pose: index });
        }
        let Some(slot) = self.poses.get_mut(index) else {
            return Err(SupportError::Full {
                capacity: SUPPORT_CAPACITY,
            });
        };
        *slot = *pose;
        self.len = index + 1;
        Ok(())
    }

    /// Number of poses held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No poses held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Removes all poses (the settings stay).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The options in use.
    pub fn options(&self) -> &SupportOptions {
        &self.options
    }

    /// Fits m, M, B and f to the poses held (MODEL.md 5.1).
    ///
    /// From the configured B: the linear (m, M, f) estimate at it (one
    /// Gauss-Newton step from zero with B held), the choice of the components
    /// of B that the poses determine, Levenberg-Marquardt (analytic Jacobian,
    /// column scaling, at most `max_iterations` iterations per pass), with that
    /// choice re-checked along the way and at the solution and the fit made
    /// again when it changes (at most [`MAX_PASSES`] passes; a component that
    /// becomes held goes back to its configured value). Then the same from the
    /// best point of the global search ([`SEARCH_RADIUS_M`]), when it is not
    /// the configured B; the lower minimum wins. Its chi-square per degree of
    /// freedom must be within `max_chi2_dof`.
    pub fn fit(&self) -> Result<SupportFit, SupportError> {
        // len <= SUPPORT_CAPACITY is kept by push.
        debug_assert!(self.len <= SUPPORT_CAPACITY);
        let poses = self.poses.get(..self.len).unwrap_or(&[]);
        let problem = Problem {
            poses,
            calibration: &self.calibration,
            whitening: &self.whitening,
            tare_n: &self.tare_n,
            gravity: self.calibration.gravity_mps2(),
            friction: self.options.friction,
        };
        let configured = self.calibration.support_m();
        self.check_count(&Free::base(self.options.friction))?;
        let mut best = self.fit_from(&problem, &configured);
        let mut from_search = false;
        if self.options.calibrate_support
            && let Some(start) = search::best_start(&problem, &configured)
            && start != configured
        {
            let other = self.fit_from(&problem, &start);
            let lower = match (&best, &other) {
                // Lower beyond rounding: the same minimum reached from both
                // starts stays the configured start's.
                (Ok(a), Ok(b)) => b.normal.cost < a.normal.cost * (1.0 - SAME_MINIMUM),
                (Err(_), Ok(_)) => true,
                _ => false,
            };
            if lower {
                best = other;
                from_search = true;
            }
        }
        let solution = best?;
        self.result(&solution, from_search)
    }

    /// The fit from a start at support `start_m` (see [`Self::fit`]).
    fn fit_from(&self, problem: &Problem<'_>, start_m: &Vec3) -> Result<Solution, SupportError> {
        let friction = self.options.friction;
        let configured = self.calibration.support_m();
        let base = Free::base(friction);
        let mut theta = Params {
            mass_kg: 0.0,
            moment_kgm: 0.0,
            support_m: *start_m,
            friction_n: 0.0,
        };
        // Linear estimate at the start: the model is linear in (m, M, f), so
        // one Gauss-Newton step from zero solves it exactly.
        let normal = problem.normal(&theta)?.masked(&base);
        let step = solver::Scaled::new(&normal.matrix, &base)?.step(&normal.rhs, 0.0)?;
        theta = Params::from_vector(&(theta.to_vector() + step));
        let mut normal = problem.normal(&theta)?;
        let mut iterations = 0u32;
        let mut free = base;
        if self.options.calibrate_support {
            let max_std = self.options.max_support_std_m;
            let decide = |n: &Normal| held::decide(n, friction, max_std);
            free = decide(&normal)?;
            if theta.support_m != configured {
                // Components held from the start sit at their configured value.
                free.reset_held(&mut theta, &configured);
                normal = problem.normal(&theta)?;
            }
            let mut passes = 1u32;
            loop {
                // The last pass cannot change the free set: it ends the loop.
                debug_assert!(passes <= MAX_PASSES, "pass {passes} of {MAX_PASSES}");
                self.check_count(&free)?;
                let last_pass = passes >= MAX_PASSES;
                let pass = Pass {
                    free,
                    max_iterations: self.options.max_iterations,
                    configured: &configured,
                    recheck: (!last_pass).then_some(&decide),
                };
                let (accepted, end) =
                    solver::levenberg_marquardt(problem, &mut theta, &mut normal, &pass)?;
                iterations = iterations.saturating_add(accepted);
                let again = match end {
                    PassEnd::Converged if !last_pass => decide(&normal)?,
                    PassEnd::Converged => free,
                    PassEnd::Changed(again) => again,
                };
                if again == free {
                    break;
                }
                // Newly held components go back to their configured value.
                again.reset_held(&mut theta, &configured);
                normal = problem.normal(&theta)?;
                free = again;
                passes += 1;
            }
        }
        // A solution on the edge of the allowed region is no minimum: the cost
        // still falls outside it.
        check_shift(&theta, &configured, SHIFT_EDGE * MAX_SUPPORT_SHIFT_M)?;
        Ok(Solution {
            theta,
            free,
            normal,
            iterations,
        })
    }

    fn check_count(&self, free: &Free) -> Result<(), SupportError> {
        let unknowns = free.count();
        let equations = 3 * self.len;
        if equations <= unknowns {
            return Err(SupportError::TooFewPoses {
                poses: self.len,
                equations,
                unknowns,
            });
        }
        Ok(())
    }

    fn result(&self, solution: &Solution, from_search: bool) -> Result<SupportFit, SupportError> {
        let Solution {
            theta,
            free,
            normal,
            iterations,
        } = solution;
        let normal = normal.masked(free);
        let (cov, condition) = held::covariance_and_condition(&normal.matrix, free)?;
        let mass = theta.mass_kg;
        if mass.is_nan() || mass <= 0.0 {
            return Err(SupportError::NonPositiveMass { mass_kg: mass });
        }
        let moment = theta.moment_kgm;
        let unknowns = free.count();
        let equations = 3 * self.len;
        let dof = equations.saturating_sub(unknowns).max(1);
        let chi2_dof = normal.cost / dof as f64;
        // Never claim more than the noise model, nor less than the scatter shows.
        let inflation = chi2_dof.max(1.0);
        let covariance = cov * inflation;
        let [var_m, var_mm, var_x, var_y, var_z, var_f]: [f64; N_UNKNOWNS] =
            covariance.diagonal().into();
        // Column 0 of the covariance: (m, m), (M, m), ...
        let [[_, cov_mass_moment, ..], ..]: [[f64; N_UNKNOWNS]; N_UNKNOWNS] = covariance.into();
        let std = |v: f64| ComplexField::sqrt(non_negative(v));
        let [fx, fy, fz] = free.support;
        let support_std = [(fx, var_x), (fy, var_y), (fz, var_z)].map(|(f, v)| f.then(|| std(v)));
        let friction = self.options.friction;
        let fit = SupportFit {
            mass_kg: mass,
            mass_std_kg: std(var_m),
            com_m: moment / mass,
            com_std_m: com_std_m(mass, moment, var_m, var_mm, cov_mass_moment),
            moment_kgm: moment,
            moment_std_kgm: std(var_mm),
            support_m: theta.support_m,
            support_std_m: support_std,
            held: free.support.map(|f| !f),
            friction_n: friction.then_some(theta.friction_n),
            friction_std_n: friction.then(|| std(var_f)),
            chi2_dof,
            residual_rms_n: ComplexField::sqrt(normal.raw_sq_n2 / equations.max(1) as f64),
            condition,
            iterations: *iterations,
            from_search,
            poses: u32::try_from(self.len).unwrap_or(u32::MAX),
        };
        check_result(&fit)?;
        // NaN is refused too (check_result has already caught it).
        if fit.chi2_dof.is_nan() || fit.chi2_dof > self.options.max_chi2_dof {
            return Err(SupportError::PoorFit {
                chi2_dof: fit.chi2_dof,
                limit: self.options.max_chi2_dof,
            });
        }
        Ok(fit)
    }
}

/// Every number of a fit is finite: finite but huge readings can overflow the
/// cost (then chi2_dof and the standard errors are infinite, or NaN).
fn check_result(fit: &SupportFit) -> Result<(), SupportError> {
    // A held component has no standard error and an unestimated friction no
    // value: nothing to check there (not a 0 standing in for a number).
    let [sx, sy, sz] = fit.support_std_m;
    let values = [
        ("mass_kg", Some(fit.mass_kg)),
        ("mass_std_kg", Some(fit.mass_std_kg)),
        ("com_m", Some(fit.com_m)),
        ("com_std_m", Some(fit.com_std_m)),
        ("moment_kgm", Some(fit.moment_kgm)),
        ("moment_std_kgm", Some(fit.moment_std_kgm)),
        ("support_m.x", Some(fit.support_m.x)),
        ("support_m.y", Some(fit.support_m.y)),
        ("support_m.z", Some(fit.support_m.z)),
        ("support_std_m.x", sx),
        ("support_std_m.y", sy),
        ("support_std_m.z", sz),
        ("friction_n", fit.friction_n),
        ("friction_std_n", fit.friction_std_n),
        ("chi2_dof", Some(fit.chi2_dof)),
        ("residual_rms_n", Some(fit.residual_rms_n)),
        ("condition", Some(fit.condition)),
    ];
    for (field, value) in values {
        if let Some(value) = value
            && !value.is_finite()
        {
            return Err(SupportError::NonFiniteResult { field, value });
        }
    }
    Ok(())
}
