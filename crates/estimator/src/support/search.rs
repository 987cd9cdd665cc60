//! The global start of support calibration: a bounded scan of supports on a
//! grid around the configured one, each judged by its chi-square with
//! (m, M, f) at their best values (the model is linear in them), so that the
//! Levenberg-Marquardt fit can start inside the global minimum's basin from a
//! configured B up to [`super::SEARCH_RADIUS_M`] off.

use super::model::Problem;
use super::{MAX_SUPPORT_SHIFT_M, SEARCH_RADIUS_M, SEARCH_STEP_M, SHIFT_EDGE};
use crate::Vec3;

/// Grid points per side of the centre: the grid reaches [`SEARCH_RADIUS_M`].
const STEPS: i32 = 2;
const _: () = assert!((STEPS as f64) * SEARCH_STEP_M >= SEARCH_RADIUS_M);

/// The grid point (at most (2 STEPS + 1)^3 = 125 of them, each within the
/// allowed region around `configured_m`) with the lowest projected chi-square;
/// `None` when no grid point can be evaluated.
pub(super) fn best_start(problem: &Problem<'_>, configured_m: &Vec3) -> Option<Vec3> {
    let limit_m = SHIFT_EDGE * MAX_SUPPORT_SHIFT_M;
    let mut best: Option<(f64, Vec3)> = None;
    for i in -STEPS..=STEPS {
        for j in -STEPS..=STEPS {
            for k in -STEPS..=STEPS {
                let offset = Vec3::new(f64::from(i), f64::from(j), f64::from(k)) * SEARCH_STEP_M;
                if offset.norm() > limit_m {
                    continue;
                }
                let support = configured_m + offset;
                let Some(cost) = problem.projected_cost(&support) else {
                    continue;
                };
                if best.is_none_or(|(lowest, _)| cost < lowest) {
                    best = Some((cost, support));
                }
            }
        }
    }
    best.map(|(_, support)| support)
}
