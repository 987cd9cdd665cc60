//! The covariance of the fitted unknowns and the choice of the components of B
//! that the poses determine (MODEL.md 5.1: hold a component whose standard
//! error would exceed the configured bound, 0.5 mm by default).

use super::SupportError;
use super::model::{Free, Mat6, N_UNKNOWNS, Normal};
use super::solver::Scaled;
use crate::{linalg, non_negative};
use nalgebra::ComplexField;

/// Covariance of the unknowns from a normal matrix over `free` (held rows and
/// columns zero), and the condition number of the column-scaled weighted
/// Jacobian over the free unknowns (the identity rows of held unknowns do not
/// change it: a unit-diagonal matrix's eigenvalues bracket 1).
pub(super) fn covariance_and_condition(
    matrix: &Mat6,
    free: &Free,
) -> Result<(Mat6, f64), SupportError> {
    let scaled = Scaled::new(matrix, free)?;
    let (covariance, scaled_inverse) = scaled.inverse()?;
    // N_s = J_s^T J_s: cond(J_s) = sqrt(lambda_max(N_s) lambda_max(N_s^-1)).
    let condition = linalg::condition_from_gram(&scaled.matrix, &scaled_inverse);
    Ok((covariance, condition))
}

/// Standard errors of B_x, B_y, B_z from the covariance over `free`.
fn support_std_m(matrix: &Mat6, free: &Free) -> Option<[f64; 3]> {
    let scaled = Scaled::new(matrix, free).ok()?;
    let (covariance, _) = scaled.inverse().ok()?;
    let [_, _, x, y, z, _]: [f64; N_UNKNOWNS] = covariance.diagonal().into();
    Some([x, y, z].map(|v| ComplexField::sqrt(non_negative(v))))
}

/// Which unknowns to fit, from the full normal equations at the present
/// estimate: m, M (and f) always; of B, the largest set of components whose
/// standard errors are all within `max_support_std_m` (among sets of equal
/// size, the one with the smallest largest standard error). Sets are tried by
/// decreasing size and the search stops at the first size that has one, so
/// when all of B is determined (the cone set) this is one factorisation.
pub(super) fn decide(
    normal: &Normal,
    friction: bool,
    max_support_std_m: f64,
) -> Result<Free, SupportError> {
    // Subsets of B by decreasing size.
    const SUBSETS: [[bool; 3]; 8] = [
        [true, true, true],
        [true, true, false],
        [true, false, true],
        [false, true, true],
        [true, false, false],
        [false, true, false],
        [false, false, true],
        [false, false, false],
    ];
    let mut best: Option<(Free, usize, f64)> = None;
    for support in SUBSETS {
        let size = support.iter().filter(|&&s| s).count();
        if let Some((_, best_size, _)) = best
            && size < best_size
        {
            break;
        }
        let free = Free { support, friction };
        let masked = normal.masked(&free);
        let Some(stds) = support_std_m(&masked.matrix, &free) else {
            continue;
        };
        let mut worst = 0.0f64;
        let mut determined = true;
        for (std, is_free) in stds.iter().zip(support) {
            if is_free {
                // NaN fails this too (f64::max would drop it).
                determined &= *std <= max_support_std_m;
                worst = worst.max(*std);
            }
        }
        if !determined {
            continue;
        }
        if best.is_none_or(|(_, _, best_worst)| worst < best_worst) {
            best = Some((free, size, worst));
        }
    }
    match best {
        Some((free, _, _)) => Ok(free),
        // Not even (m, M, f) alone is determined: say which unknown fails.
        None => {
            let base = Free::base(friction);
            covariance_and_condition(&normal.masked(&base).matrix, &base)?;
            Ok(base)
        }
    }
}
