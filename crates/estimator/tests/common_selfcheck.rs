//! Checks of the test simulator itself against hand-derived cases.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod common;
use common::*;
use nalgebra::Vector3;

/// A horizontal rod with nothing at the tip and no friction: the vertical force
/// at A follows the article's line F_A,y = m g - M g / a (MODEL.md 5.2).
#[test]
fn horizontal_rod_matches_the_article_line() {
    let truth = Truth {
        mass_kg: 2.0,
        com_m: 0.1,
        length_m: 0.35,
        offset_m: 0.0,
        support_m: Vector3::new(0.45, 0.2, 0.0),
        gravity_mps2: gravity(),
        friction_n: 0.0,
    };
    for a in [0.05, 0.1, 0.2, 0.3] {
        let a_m = truth.support_m - Vector3::x() * a;
        let (u, w) = rod_frame(core::f64::consts::FRAC_PI_2, 0.0);
        let (f_a, torsion) = ujoint_force(&truth, &a_m, &u, &w, &Vector3::zeros(), 1.0);
        let g = 9.80665;
        let expected_y = 2.0 * g - 2.0 * 0.1 * g / a;
        assert!(
            (f_a.y - expected_y).abs() < 1e-9,
            "a={a}: {} vs {expected_y}",
            f_a.y
        );
        assert!(f_a.x.abs() < 1e-9 && f_a.z.abs() < 1e-9 && torsion.abs() < 1e-9);
    }
}

/// Friction: the robot pushes harder along u after the rod slid along u.
#[test]
fn friction_adds_along_the_rod_with_the_slide_sign() {
    let truth = Truth {
        mass_kg: 1.0,
        com_m: 0.1,
        length_m: 0.35,
        offset_m: 0.0,
        support_m: Vector3::new(0.45, 0.2, 0.0),
        gravity_mps2: gravity(),
        friction_n: 0.3,
    };
    let a_m = truth.support_m - Vector3::x() * 0.1;
    let (u, w) = rod_frame(core::f64::consts::FRAC_PI_2, 0.0);
    let (plus, _) = ujoint_force(&truth, &a_m, &u, &w, &Vector3::zeros(), 1.0);
    let (minus, _) = ujoint_force(&truth, &a_m, &u, &w, &Vector3::zeros(), -1.0);
    assert!((plus.x - 0.3).abs() < 1e-9 && (minus.x + 0.3).abs() < 1e-9);
}
