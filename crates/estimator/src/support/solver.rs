//! The Levenberg-Marquardt solver of support calibration: column scaling, one
//! Cholesky factorisation per trial step (the undamped step for the convergence
//! test, then the damped one), and one pass over the poses per trial, whose
//! normal equations become the next iteration's when the step is accepted.

use super::model::{Free, Mat6, N_UNKNOWNS, Normal, Params, Problem, Unknown, Vec6, below_or_nan};
use super::{MAX_SUPPORT_SHIFT_M, SupportError, check_shift};
use crate::Vec3;
use nalgebra::{Cholesky, ComplexField, Const};

/// Convergence: the Levenberg-Marquardt step, in units of the column-scaled
/// (whitened) Jacobian, i.e. roughly in standard errors of each unknown.
const STEP_TOL: f64 = 1e-10;
/// Convergence: relative decrease of the cost (chi-square), achieved by an
/// accepted step or predicted for the undamped step.
const COST_TOL: f64 = 1e-12;
/// Damping of the first step, relative to the unit diagonal of the scaled matrix.
const LAMBDA_START: f64 = 1e-3;
/// Largest damping before the fit gives up on finding a downhill step.
const LAMBDA_MAX: f64 = 1e16;
/// Smallest damping.
const LAMBDA_MIN: f64 = 1e-12;
/// The damping loop's counted bound: the damping rises tenfold per refused
/// trial from at least [`LAMBDA_MIN`] and the search gives up above
/// [`LAMBDA_MAX`], that is after at most log10(LAMBDA_MAX / LAMBDA_MIN) + 1 =
/// 29 trials; 32 leaves room for the rounding of the repeated products. The
/// count bounds the loop whatever the damping does (it cannot rely on a
/// comparison that NaN would make false). Hitting either limit is
/// [`SupportError::DampingExhausted`].
pub(super) const MAX_DAMPING_TRIALS: u32 = 32;
const _: () = assert!(LAMBDA_MIN > 0.0 && LAMBDA_MIN <= LAMBDA_START && LAMBDA_START < LAMBDA_MAX);
const _: () = assert!((MAX_DAMPING_TRIALS as usize) > 16 + 12 + 1);
/// Smallest accepted pivot (squared diagonal of the Cholesky factor) of the
/// column-scaled normal matrix: below it the unknowns are not determined.
const MIN_PIVOT: f64 = 1e-13;

/// The Cholesky factor of a 6x6.
pub(super) type Factor = Cholesky<f64, Const<N_UNKNOWNS>>;

/// `unknown` is not determined (its pivot in the scaled normal matrix).
pub(super) fn undetermined(unknown: Unknown, pivot: f64) -> SupportError {
    SupportError::Undetermined {
        unknown: unknown.name(),
        pivot,
        hint: unknown.hint(),
    }
}

/// A column-scaled symmetric system over the free unknowns.
pub(super) struct Scaled {
    /// sqrt of the diagonal for free unknowns, 1 for held ones.
    pub scale: Vec6,
    /// The scaled matrix (unit diagonal over the free unknowns) with the held
    /// rows and columns replaced by the identity.
    pub matrix: Mat6,
    /// 1 for free unknowns, 0 for held ones.
    mask: Vec6,
}

impl Scaled {
    /// Scales `matrix` (held rows and columns zero) over `free`. Errors when a
    /// free column is zero or not finite.
    pub(super) fn new(matrix: &Mat6, free: &Free) -> Result<Self, SupportError> {
        let mask = free.mask();
        let diagonal: [f64; N_UNKNOWNS] = matrix.diagonal().into();
        let free_flags: [f64; N_UNKNOWNS] = mask.into();
        for ((unknown, diag), is_free) in Unknown::ALL.iter().zip(diagonal).zip(free_flags) {
            if is_free > 0.0 && (below_or_nan(diag, f64::MIN_POSITIVE) || !diag.is_finite()) {
                return Err(undetermined(*unknown, 0.0));
            }
        }
        let held = Vec6::repeat(1.0) - mask;
        let scale = matrix
            .diagonal()
            .map(ComplexField::sqrt)
            .component_mul(&mask)
            + held;
        let inv = Mat6::from_diagonal(&scale.map(|s| 1.0 / s).component_mul(&mask));
        Ok(Self {
            scale,
            matrix: inv * matrix * inv + Mat6::from_diagonal(&held),
            mask,
        })
    }

    /// Cholesky of the scaled matrix plus `lambda` on the free diagonal.
    pub(super) fn factor(&self, lambda: f64) -> Result<Factor, SupportError> {
        factor(&(self.matrix + Mat6::from_diagonal(&(self.mask * lambda))))
    }

    /// The damped Gauss-Newton step `(N_s + lambda I) d_s = b_s` in scaled
    /// unknowns, returned unscaled (zero for held unknowns).
    pub(super) fn step(&self, rhs: &Vec6, lambda: f64) -> Result<Vec6, SupportError> {
        let chol = self.factor(lambda)?;
        Ok(chol
            .solve(&rhs.component_div(&self.scale))
            .component_div(&self.scale)
            .component_mul(&self.mask))
    }

    /// The inverse of the scaled matrix, unscaled back: the covariance of the
    /// unknowns (held rows and columns zero), and the scaled inverse.
    pub(super) fn inverse(&self) -> Result<(Mat6, Mat6), SupportError> {
        let scaled_inverse = self.factor(0.0)?.inverse();
        let unscale = Mat6::from_diagonal(&self.scale.map(|s| 1.0 / s).component_mul(&self.mask));
        Ok((unscale * scaled_inverse * unscale, scaled_inverse))
    }
}

/// Cholesky of a scaled matrix, refusing pivots below [`MIN_PIVOT`].
fn factor(matrix: &Mat6) -> Result<Factor, SupportError> {
    let Some(chol) = Cholesky::new(*matrix) else {
        let (unknown, pivot) = first_failing_pivot(matrix);
        return Err(undetermined(unknown, pivot));
    };
    let diagonal: [f64; N_UNKNOWNS] = chol.l_dirty().diagonal().into();
    for (unknown, diag) in Unknown::ALL.iter().zip(diagonal) {
        let pivot = diag * diag;
        if below_or_nan(pivot, MIN_PIVOT) {
            return Err(undetermined(*unknown, pivot));
        }
    }
    Ok(chol)
}

/// For a matrix that Cholesky refused: the first unknown whose pivot fails and
/// that pivot, from the leading principal minors (pivot k = det_k+1 / det_k;
/// fixed-size views with constant shapes, so no index can be out of range).
fn first_failing_pivot(matrix: &Mat6) -> (Unknown, f64) {
    let minors = [
        1.0,
        matrix.fixed_view::<1, 1>(0, 0).determinant(),
        matrix.fixed_view::<2, 2>(0, 0).determinant(),
        matrix.fixed_view::<3, 3>(0, 0).determinant(),
        matrix.fixed_view::<4, 4>(0, 0).into_owned().determinant(),
        matrix.fixed_view::<5, 5>(0, 0).into_owned().determinant(),
        matrix.determinant(),
    ];
    for ((unknown, before), after) in Unknown::ALL.iter().zip(minors).zip(minors.iter().skip(1)) {
        let pivot = after / before;
        if below_or_nan(pivot, MIN_PIVOT) {
            return (*unknown, pivot);
        }
    }
    // Cholesky refused a matrix whose minors all pass: rounding at the edge.
    (Unknown::Mass, 0.0)
}

/// How a Levenberg-Marquardt pass ended.
pub(super) enum PassEnd {
    /// Converged with the free set it was given.
    Converged,
    /// The free components of B changed to these; fit again.
    Changed(Free),
}

/// What a pass needs besides the problem.
pub(super) struct Pass<'a, D> {
    pub free: Free,
    pub max_iterations: u32,
    pub configured: &'a Vec3,
    /// Re-decides the free set from the full normal equations after every
    /// accepted step (`None`: keep it).
    pub recheck: Option<D>,
}

/// Levenberg-Marquardt from `theta` over the free unknowns; `normal` holds the
/// full normal equations at `theta` on entry and on return. Returns the number
/// of accepted steps and how the pass ended.
///
/// Stops when the undamped Gauss-Newton step predicts a cost decrease below
/// [`COST_TOL`] times the cost (plus the cost's rounding floor), when an
/// accepted step lowered the cost by less than that, or when a trial step is
/// below [`STEP_TOL`] in column-scaled units. With `recheck`, the choice of
/// the free components of B is re-made after every accepted step, and the pass
/// ends as soon as it changes (a component can be determined at the configured
/// B only because of the configured error, e.g. B_z through a tilt that the
/// fit then removes).
pub(super) fn levenberg_marquardt<D>(
    problem: &Problem<'_>,
    theta: &mut Params,
    normal: &mut Normal,
    pass: &Pass<'_, D>,
) -> Result<(u32, PassEnd), SupportError>
where
    D: Fn(&Normal) -> Result<Free, SupportError>,
{
    let free = &pass.free;
    let mut lambda = LAMBDA_START;
    let mut accepted = 0u32;
    let mut last_step = f64::INFINITY;
    for iteration in 0..pass.max_iterations {
        // Each iteration ends with one accepted step or returns.
        debug_assert_eq!(accepted, iteration);
        if accepted > 0
            && let Some(decide) = &pass.recheck
        {
            let again = decide(normal)?;
            if again != *free {
                return Ok((accepted, PassEnd::Changed(again)));
            }
        }
        let masked = normal.masked(free);
        let tolerance = COST_TOL * masked.cost + masked.cost_floor;
        if masked.cost <= masked.cost_floor {
            return Ok((accepted, PassEnd::Converged));
        }
        let scaled = Scaled::new(&masked.matrix, free)?;
        // What the undamped step could gain, to first order.
        let gauss_newton = scaled.step(&masked.rhs, 0.0)?;
        if gauss_newton.dot(&masked.rhs) <= tolerance {
            return Ok((accepted, PassEnd::Converged));
        }
        let search = damped_search(
            &scaled,
            &masked,
            &mut lambda,
            MAX_DAMPING_TRIALS,
            (theta, normal),
            |trial| {
                check_shift(trial, pass.configured, MAX_SUPPORT_SHIFT_M)
                    .and_then(|()| problem.normal(trial))
            },
        )?;
        match accepted_step(search, tolerance)? {
            Some((scaled_step, converged)) => {
                last_step = scaled_step;
                accepted = accepted.saturating_add(1);
                if converged {
                    return Ok((accepted, PassEnd::Converged));
                }
            }
            // Rounding: no smaller step can matter.
            None => return Ok((accepted, PassEnd::Converged)),
        }
    }
    Err(SupportError::NotConverged {
        iterations: pass.max_iterations,
        step: last_step,
    })
}

/// What one damped search means for a pass: an accepted step's norm in
/// column-scaled units and whether the pass has converged with it (it
/// gained at most `tolerance`, or was below [`STEP_TOL`]); `None` when
/// rounding ends the pass (converged, no step); else why the pass fails.
fn accepted_step(search: Damped, tolerance: f64) -> Result<Option<(f64, bool)>, SupportError> {
    match search {
        Damped::Accepted { scaled_step, gain } => Ok(Some((
            scaled_step,
            gain <= tolerance || scaled_step <= STEP_TOL,
        ))),
        // Rounding: no smaller step can matter.
        Damped::Rounding { region: None } => Ok(None),
        // The fit keeps pushing B out of its allowed region.
        Damped::Rounding {
            region: Some(error),
        }
        | Damped::Exhausted {
            region: Some(error),
            ..
        } => Err(error),
        // No downhill step even with the heaviest damping.
        Damped::Exhausted {
            trials,
            lambda,
            step,
            region: None,
        } => Err(SupportError::DampingExhausted {
            trials,
            lambda,
            step,
        }),
    }
}

/// How one damped search for a downhill step ended ([`damped_search`]).
#[derive(Debug)]
pub(super) enum Damped {
    /// A step that lowers the cost (now in the point and normal equations
    /// given): its norm in column-scaled units, and the cost's decrease.
    Accepted { scaled_step: f64, gain: f64 },
    /// A refused step below [`STEP_TOL`] in column-scaled units: rounding, no
    /// smaller step can matter. `region`: the last trial's error (B out of
    /// its allowed region), if that is why it was refused.
    Rounding { region: Option<SupportError> },
    /// The damping rose above [`LAMBDA_MAX`], or `max_trials` trials were
    /// refused: no downhill step. `trials` refused, the damping reached, the
    /// last step's scaled norm, and the last trial's error as for `Rounding`.
    Exhausted {
        trials: u32,
        lambda: f64,
        step: f64,
        region: Option<SupportError>,
    },
}

/// The damping loop of one Levenberg-Marquardt iteration at `theta`, whose
/// (masked) normal equations are `masked` and `scaled`: the damped step
/// `(N_s + lambda I) d_s = b_s` for the current `lambda`, its trial point's
/// normal equations by `evaluate` (or why it has none), accepted when they
/// lower the cost (then `theta` and `normal` become the trial's); otherwise
/// `lambda` rises tenfold and the step is tried again, at most `max_trials`
/// times. On return `lambda` is the damping for the next iteration (lowered
/// tenfold, not below [`LAMBDA_MIN`], after an accepted step).
pub(super) fn damped_search(
    scaled: &Scaled,
    masked: &Normal,
    lambda: &mut f64,
    max_trials: u32,
    (theta, normal): (&mut Params, &mut Normal),
    mut evaluate: impl FnMut(&Params) -> Result<Normal, SupportError>,
) -> Result<Damped, SupportError> {
    let mut step_norm = f64::INFINITY;
    let mut region = None;
    for trial_index in 0..max_trials {
        debug_assert!(
            *lambda >= LAMBDA_MIN && *lambda <= LAMBDA_MAX,
            "damping {} outside [{LAMBDA_MIN:e}, {LAMBDA_MAX:e}]",
            *lambda
        );
        let step = scaled.step(&masked.rhs, *lambda)?;
        let scaled_step = step.component_mul(&scaled.scale).norm();
        step_norm = scaled_step;
        let trial = Params::from_vector(&(theta.to_vector() + step));
        match evaluate(&trial) {
            Ok(next) if next.cost.is_finite() && next.cost < masked.cost => {
                let gain = masked.cost - next.cost;
                *theta = trial;
                *normal = next;
                *lambda = (*lambda * 0.1).max(LAMBDA_MIN);
                return Ok(Damped::Accepted { scaled_step, gain });
            }
            other => {
                region = other.err();
                if scaled_step <= STEP_TOL {
                    return Ok(Damped::Rounding { region });
                }
                *lambda *= 10.0;
                if *lambda > LAMBDA_MAX {
                    return Ok(Damped::Exhausted {
                        trials: trial_index + 1,
                        lambda: *lambda,
                        step: scaled_step,
                        region,
                    });
                }
            }
        }
    }
    Ok(Damped::Exhausted {
        trials: max_trials,
        lambda: *lambda,
        step: step_norm,
        region,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every unknown free, unit scaled matrix.
    fn unit_scaled() -> Scaled {
        let all_free = Free {
            support: [true; 3],
            friction: true,
        };
        Scaled::new(&Mat6::identity(), &all_free).unwrap_or_else(|e| panic!("{e}"))
    }

    fn normal_with_cost(cost: f64) -> Normal {
        Normal {
            matrix: Mat6::identity(),
            rhs: Vec6::zeros(),
            cost,
            raw_sq_n2: cost,
            cost_floor: 0.0,
        }
    }

    /// The equations at the start: cost 1, gradient `rhs` on every unknown.
    fn start(rhs: f64) -> Normal {
        Normal {
            rhs: Vec6::repeat(rhs),
            ..normal_with_cost(1.0)
        }
    }

    /// A large gradient, so that the damped steps stay above STEP_TOL up to
    /// the heaviest damping (|step| ~ 1e8 / lambda).
    const RHS: f64 = 1e8;

    /// Runs `damped_search` from a zero point with `lambda`, `max_trials` and
    /// `evaluate`; returns the outcome, the damping after, the point after,
    /// and how many trials were evaluated.
    fn search(
        rhs: f64,
        lambda: f64,
        max_trials: u32,
        mut evaluate: impl FnMut(&Params) -> Result<Normal, SupportError>,
    ) -> (Result<Damped, SupportError>, f64, Params, u32) {
        let masked = start(rhs);
        let (mut theta, mut normal) = (Params::from_vector(&Vec6::zeros()), masked);
        let (mut lambda, mut evaluated) = (lambda, 0u32);
        let end = damped_search(
            &unit_scaled(),
            &masked,
            &mut lambda,
            max_trials,
            (&mut theta, &mut normal),
            |trial| {
                evaluated += 1;
                evaluate(trial)
            },
        );
        (end, lambda, theta, evaluated)
    }

    /// A cost that never falls: the damping rises tenfold per trial until it
    /// passes its ceiling, within the counted bound; each trial is evaluated
    /// once, and the point stays where it was.
    #[test]
    fn uphill_everywhere_exhausts_the_damping_at_its_ceiling() {
        let (end, lambda, theta, evaluated) = search(RHS, LAMBDA_START, MAX_DAMPING_TRIALS, |_| {
            Ok(normal_with_cost(2.0))
        });
        let Ok(Damped::Exhausted {
            trials,
            lambda: reached,
            step,
            region: None,
        }) = end
        else {
            panic!("not exhausted: {end:?}");
        };
        // 1e-3 * 10^19 = 1e16 is the ceiling itself: 19 or 20 trials, by
        // the rounding of the products.
        assert!((19..=20).contains(&trials), "{trials}");
        assert_eq!(trials, evaluated);
        assert!(reached > LAMBDA_MAX && reached == lambda, "{reached}");
        assert!(step > STEP_TOL, "{step}");
        assert_eq!(theta.to_vector(), Vec6::zeros());
    }

    /// The counted bound ends the loop by itself: with 5 trials allowed, a
    /// search that the ceiling would let go on (a NaN cost: never accepted)
    /// stops after exactly 5, with its typed outcome.
    #[test]
    fn the_trial_count_bounds_the_damping_loop() {
        let (end, lambda, _, evaluated) =
            search(RHS, LAMBDA_START, 5, |_| Ok(normal_with_cost(f64::NAN)));
        let Ok(Damped::Exhausted {
            trials, lambda: l, ..
        }) = end
        else {
            panic!("not exhausted: {end:?}");
        };
        assert_eq!((trials, evaluated), (5, 5));
        assert_eq!(l, lambda);
        assert!(
            l < LAMBDA_MAX && (l / (LAMBDA_START * 1e5) - 1.0).abs() < 1e-9,
            "{l}"
        );
    }

    /// A refusal because B left its region is handed back with the outcome;
    /// a step below STEP_TOL ends the search as rounding.
    #[test]
    fn a_region_error_is_kept_and_a_tiny_step_is_rounding() {
        let diverged = SupportError::Diverged { shift_m: 0.2 };
        let (end, ..) = search(RHS, LAMBDA_START, MAX_DAMPING_TRIALS, |_| Err(diverged));
        assert!(
            matches!(
                end,
                Ok(Damped::Exhausted {
                    region: Some(SupportError::Diverged { .. }),
                    ..
                })
            ),
            "{end:?}"
        );
        let (end, lambda, _, evaluated) = search(1e-12, LAMBDA_START, MAX_DAMPING_TRIALS, |_| {
            Ok(normal_with_cost(2.0))
        });
        assert!(
            matches!(end, Ok(Damped::Rounding { region: None })),
            "{end:?}"
        );
        assert_eq!((lambda, evaluated), (LAMBDA_START, 1));
    }

    /// A step downhill is accepted at the first trial: the point moves to
    /// it, the gain is the cost's decrease, and the damping falls tenfold
    /// (not below LAMBDA_MIN).
    #[test]
    fn a_downhill_step_is_accepted_and_the_damping_falls() {
        for (before, after) in [(LAMBDA_START, LAMBDA_START * 0.1), (LAMBDA_MIN, LAMBDA_MIN)] {
            let (end, lambda, theta, evaluated) = search(1.0, before, MAX_DAMPING_TRIALS, |_| {
                Ok(normal_with_cost(0.25))
            });
            let Ok(Damped::Accepted { gain, scaled_step }) = end else {
                panic!("not accepted: {end:?}");
            };
            assert_eq!((gain, evaluated, lambda), (0.75, 1, after));
            // The step (I + lambda I) d = 1 on every unknown.
            let d = 1.0 / (1.0 + before);
            assert!((theta.to_vector() - Vec6::repeat(d)).norm() < 1e-15);
            assert!((scaled_step - d * 6f64.sqrt()).abs() < 1e-15);
        }
    }

    /// The leading-minor pivots name the first dependent unknown.
    #[test]
    fn first_failing_pivot_names_the_dependent_unknown() {
        let mut m = Mat6::identity();
        // B_y (index 3) a copy of M (index 1).
        m.fixed_view_mut::<1, 1>(3, 3).fill(1.0);
        m.fixed_view_mut::<1, 1>(1, 3).fill(1.0);
        m.fixed_view_mut::<1, 1>(3, 1).fill(1.0);
        let (unknown, pivot) = first_failing_pivot(&m);
        assert_eq!(unknown, Unknown::SupportY);
        assert!(pivot.abs() < 1e-12, "{pivot}");
        assert!(matches!(
            factor(&m),
            Err(SupportError::Undetermined {
                unknown: "support_y_m",
                ..
            })
        ));
    }
}
