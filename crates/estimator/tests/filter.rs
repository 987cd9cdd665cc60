//! The tip-force low-pass (`sar_estimator::filter`): settings refused with typed
//! errors, DC gain 1, -3 dB at the cutoff (from the coefficients and from a
//! simulated sine), the step response, the variance gain against the impulse
//! response and a seeded Monte-Carlo, the propagated deviation, the group delay,
//! reset on invalid input, and a repeated sample not stepped twice.
#![allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sar_estimator::filter::{FilterConfig, FilterError, TipFilter};
use std::f64::consts::PI;

const PERIOD_S: f64 = 0.002;

fn filter(cutoff_hz: f64) -> TipFilter {
    TipFilter::new(FilterConfig {
        cutoff_hz,
        sample_period_s: PERIOD_S,
    })
    .unwrap()
}

fn v(x: f64) -> Vector3<f64> {
    Vector3::new(x, -2.0 * x, 0.5 * x)
}

/// |H(e^{j w T})| from the coefficients, by hand in complex arithmetic.
fn magnitude(f: &TipFilter, freq_hz: f64) -> f64 {
    let (b, a) = f.coefficients();
    let w = 2.0 * PI * freq_hz * f.config().sample_period_s;
    let eval = |c: [f64; 3]| {
        let re: f64 = (0..3).map(|k| c[k] * (w * k as f64).cos()).sum();
        let im: f64 = (0..3).map(|k| -c[k] * (w * k as f64).sin()).sum();
        (re * re + im * im).sqrt()
    };
    eval(b) / eval(a)
}

#[test]
fn settings_are_checked_with_typed_errors() {
    let make = |cutoff_hz, sample_period_s| {
        TipFilter::new(FilterConfig {
            cutoff_hz,
            sample_period_s,
        })
    };
    for bad in [f64::NAN, f64::INFINITY, 0.0, -1.0] {
        assert!(
            matches!(make(bad, PERIOD_S), Err(FilterError::InvalidCutoff { .. })),
            "{bad}"
        );
        assert!(
            matches!(make(5.0, bad), Err(FilterError::InvalidSamplePeriod { .. })),
            "{bad}"
        );
    }
    assert!(matches!(
        make(250.0, PERIOD_S),
        Err(FilterError::CutoffAboveNyquist { nyquist_hz, .. }) if nyquist_hz == 250.0
    ));
    assert!(matches!(
        make(400.0, PERIOD_S),
        Err(FilterError::CutoffAboveNyquist { .. })
    ));
    assert!(make(249.0, PERIOD_S).is_ok());
    assert!(make(0.01, PERIOD_S).is_ok());
}

#[test]
fn dc_gain_is_one_and_minus_3_db_at_the_cutoff() {
    for cutoff_hz in [0.5, 5.0, 20.0, 100.0, 200.0] {
        let f = filter(cutoff_hz);
        let (b, a) = f.coefficients();
        let dc = b.iter().sum::<f64>() / a.iter().sum::<f64>();
        // 1 + a1 + a2 cancels to ~(2 pi fc T)^2: a few ulps of it at 0.5 Hz.
        assert!((dc - 1.0).abs() < 1e-10, "{cutoff_hz} Hz: DC gain {dc}");
        let at_cutoff = magnitude(&f, cutoff_hz);
        assert!(
            (at_cutoff - 0.5f64.sqrt()).abs() < 1e-9,
            "{cutoff_hz} Hz: |H(fc)| = {at_cutoff}"
        );
        // Maximally flat: monotonic decrease from DC.
        assert!(magnitude(&f, 0.5 * cutoff_hz) > at_cutoff);
        assert!(magnitude(&f, 0.5 * cutoff_hz) < 1.0);
    }
}

#[test]
fn a_sine_at_the_cutoff_comes_out_at_minus_3_db() {
    let cutoff_hz = 20.0;
    let mut f = filter(cutoff_hz);
    let std = Vector3::zeros();
    let mut peak: f64 = 0.0;
    for i in 0..5000 {
        let x = (2.0 * PI * cutoff_hz * i as f64 * PERIOD_S).sin();
        let y = f.update(&v(x), &std).unwrap().force_n;
        if i >= 4000 {
            peak = peak.max(y.x.abs());
        }
    }
    assert!((peak - 0.5f64.sqrt()).abs() < 2e-3, "peak {peak}");
}

#[test]
fn a_constant_input_passes_exactly_and_a_step_settles() {
    let cutoff_hz = 5.0;
    let mut f = filter(cutoff_hz);
    let std = Vector3::repeat(0.3);
    // Started at 2 N: no transient at all.
    for _ in 0..100 {
        let y = f.update(&v(2.0), &std).unwrap().force_n;
        assert!((y - v(2.0)).amax() < 1e-12, "{y:?}");
    }
    // A step to 12 N: a second-order Butterworth overshoots by about 4.3 %
    // and settles.
    let mut max = f64::MIN;
    let mut last = Vector3::zeros();
    let mut reached_90_at = None;
    for i in 0..2000 {
        last = f.update(&v(12.0), &std).unwrap().force_n;
        max = max.max(last.x);
        if reached_90_at.is_none() && last.x >= 2.0 + 0.9 * 10.0 {
            reached_90_at = Some(i + 1);
        }
    }
    assert!((last - v(12.0)).amax() < 1e-9, "{last:?}");
    let overshoot = (max - 12.0) / 10.0;
    assert!((0.035..0.05).contains(&overshoot), "overshoot {overshoot}");
    // 10-90 % rise of a second-order Butterworth: about 0.34 / fc.
    let rise_s = reached_90_at.unwrap() as f64 * PERIOD_S;
    assert!(
        (0.2 / cutoff_hz..0.5 / cutoff_hz).contains(&rise_s),
        "90 % after {rise_s} s"
    );
}

#[test]
fn variance_gain_matches_the_impulse_response_and_a_seeded_monte_carlo() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_f117);
    let normal = Normal::new(0.0, 1.0).unwrap();
    for cutoff_hz in [5.0, 20.0, 100.0] {
        let mut f = filter(cutoff_hz);
        let g = f.variance_gain();
        // Impulse response: start at 0, then one unit sample, then zeros.
        let zero = Vector3::zeros();
        f.update(&zero, &zero).unwrap();
        let mut sum_h2 = 0.0;
        let mut x = Vector3::repeat(1.0);
        for _ in 0..200_000 {
            let h = f.update(&x, &zero).unwrap().force_n.x;
            sum_h2 += h * h;
            x = zero;
        }
        assert!(
            ((sum_h2 - g) / g).abs() < 1e-9,
            "{cutoff_hz} Hz: sum h^2 {sum_h2} vs closed form {g}"
        );
        // Monte-Carlo: white noise of deviation sigma per axis.
        let sigma = Vector3::new(0.2, 0.5, 0.8);
        f.reset();
        let n = 400_000;
        let mut sum2 = Vector3::zeros();
        let mut last_std = Vector3::zeros();
        for i in 0..n + 1000 {
            let x = Vector3::from_fn(|k, _| sigma[k] * normal.sample(&mut rng));
            let out = f.update(&x, &sigma).unwrap();
            if i >= 1000 {
                sum2 += out.force_n.component_mul(&out.force_n);
            }
            last_std = out.std_n;
        }
        for k in 0..3 {
            let measured = (sum2[k] / n as f64).sqrt();
            let expected = g.sqrt() * sigma[k];
            assert!(
                ((measured - expected) / expected).abs() < 0.03,
                "{cutoff_hz} Hz axis {k}: Monte-Carlo std {measured} vs sqrt(G) sigma {expected}"
            );
            assert!(
                ((last_std[k] - expected) / expected).abs() < 1e-9,
                "propagated std {} vs {expected}",
                last_std[k]
            );
        }
    }
}

#[test]
fn the_propagated_std_starts_at_the_sample_and_decays_to_the_steady_value() {
    let mut f = filter(5.0);
    let sigma = Vector3::new(0.4, 0.4, 1.0);
    let first = f.update(&v(1.0), &sigma).unwrap();
    assert_eq!(first.std_n, sigma);
    assert_eq!(first.force_n, v(1.0));
    let steady = sigma * f.variance_gain().sqrt();
    let mut last = first.std_n;
    for _ in 0..3000 {
        last = f.update(&v(1.0), &sigma).unwrap().std_n;
    }
    assert!((last - steady).amax() < 1e-9, "{last:?} vs {steady:?}");
    // A zero deviation input carries none.
    let mut g = filter(5.0);
    let zero = Vector3::zeros();
    for _ in 0..10 {
        assert_eq!(g.update(&v(3.0), &zero).unwrap().std_n, zero);
    }
}

#[test]
fn group_delay_matches_the_phase_slope_and_the_analog_value() {
    for cutoff_hz in [1.0, 5.0, 20.0] {
        let f = filter(cutoff_hz);
        let tau = f.group_delay_s();
        let analog = 2f64.sqrt() / (2.0 * PI * cutoff_hz);
        assert!(
            ((tau - analog) / analog).abs() < 0.02,
            "{cutoff_hz} Hz: {tau} s vs analog {analog} s"
        );
        // A slow ramp is followed late by tau.
        let mut g = filter(cutoff_hz);
        let slope = 3.0; // N/s
        let std = Vector3::zeros();
        let mut y = 0.0;
        let n = 20_000;
        for i in 0..n {
            let x = slope * i as f64 * PERIOD_S;
            y = g.update(&Vector3::repeat(x), &std).unwrap().force_n.x;
        }
        let lag_s = ((n - 1) as f64 * PERIOD_S) - y / slope;
        assert!(
            (lag_s - tau).abs() < 1e-6,
            "{cutoff_hz} Hz: ramp lag {lag_s} s vs group delay {tau} s"
        );
    }
}

#[test]
fn invalid_input_is_refused_and_the_next_valid_sample_restarts_cleanly() {
    let mut f = filter(5.0);
    let std = Vector3::repeat(0.2);
    for _ in 0..500 {
        f.update(&v(5.0), &std).unwrap();
    }
    let nan = Vector3::new(1.0, f64::NAN, 0.0);
    assert!(matches!(
        f.update(&nan, &std),
        Err(FilterError::NonFiniteForce { axis: 1, value }) if value.is_nan()
    ));
    assert!(!f.is_running());
    assert_eq!(f.last(), None);
    // Restart at -3 N: the output is the sample itself, then stays there: no
    // transient from the stale 5 N state.
    let out = f.update(&v(-3.0), &std).unwrap();
    assert_eq!(out.force_n, v(-3.0));
    assert_eq!(out.std_n, std);
    for _ in 0..200 {
        let y = f.update(&v(-3.0), &std).unwrap().force_n;
        assert!((y - v(-3.0)).amax() < 1e-12, "{y:?}");
    }
    // Infinite force, NaN, infinite or negative deviation: refused, reset.
    for (force, s) in [
        (Vector3::new(f64::INFINITY, 0.0, 0.0), std),
        (v(1.0), Vector3::new(0.2, 0.2, f64::NAN)),
        (v(1.0), Vector3::new(f64::INFINITY, 0.2, 0.2)),
        (v(1.0), Vector3::new(0.2, -0.1, 0.2)),
    ] {
        f.update(&v(-3.0), &std).unwrap();
        assert!(f.is_running());
        let r = f.update(&force, &s);
        assert!(
            matches!(
                r,
                Err(FilterError::NonFiniteForce { .. } | FilterError::InvalidStd { .. })
            ),
            "{r:?}"
        );
        assert!(!f.is_running());
    }
    // An overflowing input is refused too, never a non-finite output.
    let huge = Vector3::repeat(f64::MAX);
    f.update(&(-huge), &std).unwrap();
    let mut overflowed = false;
    for i in 0..20 {
        let x = if i % 2 == 0 { huge } else { -huge };
        match f.update(&x, &std) {
            Ok(out) => assert!(out.force_n.iter().all(|v| v.is_finite()), "{out:?}"),
            Err(e) => {
                assert!(matches!(e, FilterError::Overflow { .. }), "{e:?}");
                overflowed = true;
                break;
            }
        }
    }
    assert!(overflowed);
    assert!(!f.is_running());
    // An explicit reset does the same.
    f.update(&v(5.0), &std).unwrap();
    f.update(&v(5.0), &std).unwrap();
    f.reset();
    assert_eq!(f.update(&v(1.0), &std).unwrap().force_n, v(1.0));
}

#[test]
fn a_repeated_sample_is_not_stepped_twice() {
    let std = Vector3::repeat(0.2);
    let mut once = filter(20.0);
    let mut repeated = filter(20.0);
    for i in 0..300u32 {
        let x = v(if i < 50 { 0.0 } else { 10.0 });
        let a = once.update_counted(i, &x, &std).unwrap();
        // A 4 kHz loop sees each 500 Hz sample 8 times.
        for _ in 0..8 {
            let b = repeated.update_counted(i, &x, &std).unwrap();
            assert_eq!(a, b, "sample {i}");
        }
    }
    // Counter wrap-around is a new sample.
    let mut f = filter(20.0);
    f.update_counted(u32::MAX, &v(0.0), &std).unwrap();
    let y = f.update_counted(0, &v(10.0), &std).unwrap();
    assert!(y.force_n.x > 0.0);
}
