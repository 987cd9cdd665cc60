//! The article's linear systems for the tip force (MODEL.md 4.2), kept for
//! side-by-side comparison only: not on the real-time path, never the default.
//!
//! Unknowns (F_D, F_B1, F_B2), with the support force written in the basis
//! u_B1 = (g x r_AB)/|g x r_AB|, u_B2 = (u_B1 x r_AB)/|u_B1 x r_AB|. Eq. 23
//! stacks the moments about A (X, Y, Z) and the forces: six equations.
//!
//! - [`tip_force_article`] is Eq. 24: it drops the Y moment row and inverts the
//!   5x5. That matrix is exactly singular for every horizontal rod; in floating
//!   point it is merely very badly conditioned, so the singular case is judged by
//!   the condition number of the equilibrated matrix (see [`MAX_CONDITION`]),
//!   never by a pivot being exactly zero.
//! - [`tip_force_article_lsq`] solves all six rows by least squares; with d = 0
//!   it equals MODEL.md 4.1 exactly.
//!
//! Both use the real geometry of the pose (r_AC = C - A, r_AD = D - A) but have no
//! U-joint torsion: with an offset d != 0 they are biased (MODEL.md 4.3).
//!
//! The systems are equilibrated before they are judged or solved: the moment
//! rows are divided by L, so that every entry is dimensionless and of order one.
//! They are solved by LU (the 5x5) and Householder QR (the 6x5), whose
//! condition is measured exactly in the 1-norm from the explicit inverse (of the
//! 5x5, or of the QR's triangular factor R, which has the singular values of the
//! 6x5). nalgebra's SVD is not used: on some of these very matrices it returns
//! a wrong decomposition without reporting it.

use crate::{Calibration, Pose, Profile, Vec3, check_finite};
use nalgebra::{Matrix5, SMatrix, Vector5};

/// Above this condition number (1-norm: |A|_1 |A^-1|_1, within a factor 5 of
/// the ratio of extreme singular values) of the equilibrated system, the
/// system counts as singular. Round-off in the answer grows like the condition
/// number times 1e-16, so this keeps it below about 1e-8 relative. A rod tilted
/// by an angle t out of the horizontal gives a 5x5 condition number of order
/// 10/t (8.4/t for manipulator 2 at a = 0.15 m), so Eq. 24 is refused within
/// about 1e-7 rad of the horizontal, and exactly horizontal rods (condition 1e16
/// and more in floating point, or an exactly zero pivot) always.
pub const MAX_CONDITION: f64 = 1e8;

/// Below this value of |g x r_AB| / (|g| |r_AB|) the rod is taken as parallel to
/// gravity, where the article's support basis is undefined.
pub const MIN_SUPPORT_BASIS_SINE: f64 = 1e-9;

/// Why the article's method gave no answer.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ArticleError {
    /// An input is NaN or infinite.
    #[error("{input} is not a finite number ({value})")]
    NonFinite {
        /// Which input.
        input: &'static str,
        /// The offending value (the first non-finite component).
        value: f64,
    },
    /// The system is singular: its condition number exceeds [`MAX_CONDITION`]
    /// (infinite when it cannot be inverted at all). Every horizontal rod gives
    /// this with Eq. 24.
    #[error("the article's system is singular: condition number {condition:e} above 1e8")]
    Singular {
        /// 1-norm condition number of the equilibrated system.
        condition: f64,
    },
    /// The rod (r_AB) is parallel to gravity or of zero length: u_B1 is undefined.
    #[error("the support basis is undefined: |g x r_AB| / (|g| |r_AB|) = {sine:e}")]
    NoSupportBasis {
        /// |g x r_AB| / (|g| |r_AB|), or 0 when r_AB = 0.
        sine: f64,
    },
    /// The answer is not finite.
    #[error("the article's tip force is not finite")]
    NonFiniteResult,
}

/// Eq. 23, equilibrated: rows 0..3 the moments about A (X, Y, Z) divided by L,
/// rows 3..6 the forces; columns (F_D, F_B1, F_B2). Returns the matrix and the
/// right-hand side.
fn equation_23(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    ujoint_force_n: &Vec3,
) -> Result<(SMatrix<f64, 6, 5>, SMatrix<f64, 6, 1>), ArticleError> {
    check_finite(ujoint_force_n, |value| ArticleError::NonFinite {
        input: "ujoint_force_n",
        value,
    })?;
    check_finite(
        pose.ujoint_m.iter().chain(&pose.com_m).chain(&pose.tip_m),
        |value| ArticleError::NonFinite {
            input: "pose",
            value,
        },
    )?;
    let a = pose.ujoint_m;
    let g = cal.gravity_mps2();
    let weight = g * profile.mass_kg();
    let length = profile.length_m();
    let r_ab = cal.support_m() - a;
    let r_ac = (pose.com_m - a) / length;
    let r_ad = (pose.tip_m - a) / length;
    let g_cross_r = g.cross(&r_ab);
    let scale = g.norm() * r_ab.norm();
    let sine = if scale > 0.0 {
        g_cross_r.norm() / scale
    } else {
        0.0
    };
    if sine.is_nan() || sine <= MIN_SUPPORT_BASIS_SINE {
        return Err(ArticleError::NoSupportBasis { sine });
    }
    let u_b1 = g_cross_r.normalize();
    let u_b2 = u_b1.cross(&r_ab).normalize();
    let r_ab = r_ab / length;

    let mut m = SMatrix::<f64, 6, 5>::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&r_ad.cross_matrix());
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&r_ab.cross(&u_b1));
    m.fixed_view_mut::<3, 1>(0, 4).copy_from(&r_ab.cross(&u_b2));
    m.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&nalgebra::Matrix3::identity());
    m.fixed_view_mut::<3, 1>(3, 3).copy_from(&u_b1);
    m.fixed_view_mut::<3, 1>(3, 4).copy_from(&u_b2);

    let mut rhs = SMatrix::<f64, 6, 1>::zeros();
    rhs.fixed_view_mut::<3, 1>(0, 0)
        .copy_from(&(-r_ac.cross(&weight)));
    rhs.fixed_view_mut::<3, 1>(3, 0)
        .copy_from(&(-(ujoint_force_n + weight)));
    check_finite(m.iter().chain(&rhs), |_| ArticleError::NonFiniteResult)?;
    Ok((m, rhs))
}

/// Largest column sum of absolute values.
fn norm_1(m: &Matrix5<f64>) -> f64 {
    m.column_iter().fold(0.0_f64, |acc, col| {
        acc.max(col.iter().map(|x| x.abs()).sum::<f64>())
    })
}

/// Refuses a matrix whose 1-norm condition number, from its inverse,
/// exceeds [`MAX_CONDITION`].
fn check_condition(m: &Matrix5<f64>, inverse: Option<&Matrix5<f64>>) -> Result<(), ArticleError> {
    let condition = match inverse {
        Some(inv) => norm_1(m) * norm_1(inv),
        None => f64::INFINITY,
    };
    if condition <= MAX_CONDITION {
        Ok(())
    } else {
        Err(ArticleError::Singular {
            // NaN (from an overflowing inverse) is reported as infinite.
            condition: if condition.is_nan() {
                f64::INFINITY
            } else {
                condition
            },
        })
    }
}

/// F_tip = -F_D from the solution vector (F_D, F_B1, F_B2).
fn tip_force_of(x: &Vector5<f64>) -> Result<Vec3, ArticleError> {
    let tip_force_n: Vec3 = -x.fixed_view::<3, 1>(0, 0).clone_owned();
    check_finite(&tip_force_n, |_| ArticleError::NonFiniteResult)?;
    Ok(tip_force_n)
}

/// The article's Eq. 24: Eq. 23 without the Y moment row, a 5x5 inverted.
/// Returns F_tip = -F_D in {0}, N, from F_A (`ujoint_force_n`, {0}, N).
///
/// Refuses every (nearly) horizontal rod with [`ArticleError::Singular`].
pub fn tip_force_article(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    ujoint_force_n: &Vec3,
) -> Result<Vec3, ArticleError> {
    let (m, rhs) = equation_23(cal, profile, pose, ujoint_force_n)?;
    // Keep rows 0 (moment X), 2 (moment Z), 3, 4, 5 (forces).
    let keep = [0_usize, 2, 3, 4, 5];
    let mut m5 = Matrix5::<f64>::zeros();
    let mut rhs5 = Vector5::<f64>::zeros();
    for (dst, &src) in keep.iter().enumerate() {
        m5.row_mut(dst).copy_from(&m.row(src));
        rhs5.row_mut(dst).copy_from(&rhs.row(src));
    }
    let lu = m5.lu();
    let inverse = lu.try_inverse();
    check_condition(&m5, inverse.as_ref())?;
    let x = lu.solve(&rhs5).ok_or(ArticleError::Singular {
        condition: f64::INFINITY,
    })?;
    tip_force_of(&x)
}

/// The article's Eq. 23 solved by least squares over all six rows (the moment
/// rows equilibrated by 1/L). Returns F_tip = -F_D in {0}, N. With d = 0 it
/// equals MODEL.md 4.1 exactly, horizontal rods included.
pub fn tip_force_article_lsq(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    ujoint_force_n: &Vec3,
) -> Result<Vec3, ArticleError> {
    let (m, rhs) = equation_23(cal, profile, pose, ujoint_force_n)?;
    let qr = m.qr();
    // R has the singular values of m.
    let r: Matrix5<f64> = qr.r();
    let inverse = r.solve_upper_triangular(&Matrix5::identity());
    check_condition(&r, inverse.as_ref())?;
    let mut qtb = rhs;
    qr.q_tr_mul(&mut qtb);
    let top: Vector5<f64> = qtb.fixed_rows::<5>(0).clone_owned();
    let x = r
        .solve_upper_triangular(&top)
        .ok_or(ArticleError::Singular {
            condition: f64::INFINITY,
        })?;
    tip_force_of(&x)
}
