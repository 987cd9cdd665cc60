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
    for _ in 0..pass.max_iterations {
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
        loop {
            let step = scaled.step(&masked.rhs, lambda)?;
            let scaled_step = step.component_mul(&scaled.scale).norm();
            last_step = scaled_step;
            let trial = Params::from_vector(&(theta.to_vector() + step));
            let evaluated = check_shift(&trial, pass.configured, MAX_SUPPORT_SHIFT_M)
                .and_then(|()| problem.normal(&trial));
            match evaluated {
                Ok(next) if next.cost.is_finite() && next.cost < masked.cost => {
                    *theta = trial;
                    *normal = next;
                    accepted = accepted.saturating_add(1);
                    lambda = (lambda * 0.1).max(LAMBDA_MIN);
                    if masked.cost - next.cost <= tolerance || scaled_step <= STEP_TOL {
                        return Ok((accepted, PassEnd::Converged));
                    }
                    break;
                }
                other => {
                    // The fit keeps pushing B out of its allowed region.
                    let out_of_region = other.err();
                    if scaled_step <= STEP_TOL {
                        // Rounding: no smaller step can matter.
                        return match out_of_region {
                            Some(error) => Err(error),
                            None => Ok((accepted, PassEnd::Converged)),
                        };
                    }
                    lambda *= 10.0;
                    if lambda > LAMBDA_MAX {
                        // No downhill step even with the heaviest damping.
                        return Err(out_of_region.unwrap_or(SupportError::NotConverged {
                            iterations: pass.max_iterations,
                            step: scaled_step,
                        }));
                    }
                }
            }
        }
    }
    Err(SupportError::NotConverged {
        iterations: pass.max_iterations,
        step: last_step,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
