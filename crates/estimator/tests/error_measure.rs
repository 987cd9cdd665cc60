//! The error measures of MODEL.md 6 on hand-computed cases, the article's own
//! tables, and every error case.
#![allow(clippy::unwrap_used, clippy::panic)]

use sar_estimator::error_measure::{ErrorMeasureError, absolute_relative_error, relative_error};

#[test]
fn absolute_relative_error_hand_computed() {
    // mean(y) = 3; sum |y - 3| = 2 + 0 + 2 = 4; sum |x - y| = 0 + 1 + 2 = 3.
    let e = absolute_relative_error(&[1.0, 2.0, 3.0], &[1.0, 3.0, 5.0]).unwrap();
    assert!((e - 0.75).abs() < 1e-15, "{e}");
    // mean(y) = 0.5; sum |y - 0.5| = 1; sum |x - y| = 0.25 + 0.25 = 0.5.
    let e = absolute_relative_error(&[0.25, 0.75], &[0.0, 1.0]).unwrap();
    assert!((e - 0.5).abs() < 1e-15, "{e}");
    // Negative values and a sign flip: y = (-2, 2), mean 0, denominator 4;
    // x = (2, -2): numerator 8.
    let e = absolute_relative_error(&[2.0, -2.0], &[-2.0, 2.0]).unwrap();
    assert!((e - 2.0).abs() < 1e-15, "{e}");
    // A perfect match.
    let y = [0.3, -1.7, 4.25, 9.0];
    assert_eq!(absolute_relative_error(&y, &y).unwrap(), 0.0);
    // Shifting x by a constant d adds n |d| to the numerator only: y mean 2.5,
    // sum |y - 2.5| = 1.5 + 0.5 + 0.5 + 1.5 = 4; x = y + 0.1: numerator 0.4.
    let y = [1.0, 2.0, 3.0, 4.0];
    let x: Vec<f64> = y.iter().map(|v| v + 0.1).collect();
    let e = absolute_relative_error(&x, &y).unwrap();
    assert!((e - 0.1).abs() < 1e-15, "{e}");
}

#[test]
fn absolute_relative_error_refusals() {
    assert_eq!(
        absolute_relative_error(&[1.0, 2.0], &[1.0]),
        Err(ErrorMeasureError::LengthMismatch {
            computed: 2,
            measured: 1
        })
    );
    assert_eq!(
        absolute_relative_error(&[], &[]),
        Err(ErrorMeasureError::Empty)
    );
    match absolute_relative_error(&[1.0, f64::NAN], &[1.0, 2.0]) {
        Err(ErrorMeasureError::NonFinite {
            series: "computed",
            index: 1,
            value,
        }) => assert!(value.is_nan()),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        absolute_relative_error(&[1.0, 2.0, 3.0], &[1.0, 2.0, f64::NEG_INFINITY]),
        Err(ErrorMeasureError::NonFinite {
            series: "measured",
            index: 2,
            value: f64::NEG_INFINITY
        })
    );
    // All measured equal: zero denominator, even where the rounded mean of
    // 0.1, 0.1, 0.1 is not exactly 0.1.
    assert_eq!(
        absolute_relative_error(&[0.0, 0.2, 0.1], &[0.1, 0.1, 0.1]),
        Err(ErrorMeasureError::ZeroDenominator {
            count: 3,
            value: 0.1
        })
    );
    assert_eq!(
        absolute_relative_error(&[5.0], &[4.0]),
        Err(ErrorMeasureError::ZeroDenominator {
            count: 1,
            value: 4.0
        })
    );
    // Finite inputs whose differences overflow.
    assert!(matches!(
        absolute_relative_error(&[-1e308, 1e308], &[1e308, -1e308]),
        Err(ErrorMeasureError::Overflow { .. })
    ));
}

/// The article's Table 2 and Table 3 (MODEL.md 8), recomputed from the printed
/// true and identified values, against the printed errors (2 decimals; Table 3
/// 3 decimals, with its last sign corrected).
#[test]
fn relative_error_reproduces_the_article_tables() {
    let table2 = [
        (1.611, 1.538, -4.53, 0.115, 0.1129, -1.83),
        (2.593, 2.5602, -1.26, 0.103, 0.1055, 2.43),
        (3.198, 3.2208, 0.71, 0.125, 0.1303, 4.24),
        (4.159, 4.206, 1.13, 0.1456, 0.1398, -3.98),
    ];
    for (m, m_id, m_err, c, c_id, c_err) in table2 {
        let em = 100.0 * relative_error(m_id, m).unwrap();
        let ec = 100.0 * relative_error(c_id, c).unwrap();
        assert!((em - m_err).abs() < 0.005 + 1e-12, "m {em} vs {m_err}");
        assert!((ec - c_err).abs() < 0.005 + 1e-12, "c {ec} vs {c_err}");
    }
    let table3 = [
        (0.51, 0.5061, -0.765),
        (1.03, 1.013, -1.650),
        (2.04, 2.030, -0.490),
    ];
    for (truth, estimate, printed) in table3 {
        let e = 100.0 * relative_error(estimate, truth).unwrap();
        assert!((e - printed).abs() < 0.0005 + 1e-12, "{e} vs {printed}");
    }
    // Exact small cases.
    assert_eq!(relative_error(3.0, 2.0).unwrap(), 0.5);
    assert_eq!(relative_error(-1.0, -2.0).unwrap(), -0.5);
    assert_eq!(relative_error(2.0, 2.0).unwrap(), 0.0);
}

#[test]
fn relative_error_refusals() {
    assert_eq!(relative_error(1.0, 0.0), Err(ErrorMeasureError::ZeroTruth));
    assert_eq!(relative_error(1.0, -0.0), Err(ErrorMeasureError::ZeroTruth));
    assert!(matches!(
        relative_error(f64::NAN, 1.0),
        Err(ErrorMeasureError::NonFinite {
            series: "estimate",
            ..
        })
    ));
    assert_eq!(
        relative_error(1.0, f64::INFINITY),
        Err(ErrorMeasureError::NonFinite {
            series: "truth",
            index: 0,
            value: f64::INFINITY
        })
    );
    assert!(matches!(
        relative_error(1e308, 1e-308),
        Err(ErrorMeasureError::Overflow { .. })
    ));
}
