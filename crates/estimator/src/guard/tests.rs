//! The guard's own tests of what only it sees: its debounce counts and its
//! force parts across the scaling threshold.

use super::*;

fn limits(debounce_samples: u32) -> GuardLimits {
    GuardLimits {
        force: ForceLimits {
            warn_total_n: 9.0,
            stop_total_n: 17.0,
            warn_axial_n: 8.0,
            stop_axial_n: 15.0,
            warn_lateral_n: 6.0,
            stop_lateral_n: 10.0,
        },
        hysteresis_n: 1.0,
        debounce_samples,
        max_sensor_age_ns: 1_000_000,
        max_joints_age_ns: 1_000_000,
        std_margin: 0.0,
    }
}

fn input(cycle: u64, force_n: Vec3) -> GuardInput {
    GuardInput {
        cycle,
        input_fault: None,
        new_sample: true,
        sensor_age_ns: 0,
        sensor_valid: true,
        joints_age_ns: 0,
        joints_valid: true,
        tip: TipInput::Estimate {
            force_n,
            std_n: Vec3::zeros(),
            rod_dir: Vec3::x(),
            observable: true,
            max_std_n: 2.0,
        },
        extra_margin_n: 0.0,
        tare_due: None,
        smoothed_force_n: None,
    }
}

#[test]
fn counts_stay_within_the_debounce_and_repeats_do_not_count() {
    let mut g = Guard::new(GuardConfig::new(limits(MAX_DEBOUNCE_SAMPLES)).unwrap());
    g.step(&input(0, Vec3::zeros()));
    g.reset(0).unwrap();
    let high = Vec3::new(20.0, 0.0, 0.0);
    // In Stop (latched) the counts keep voting but never pass the debounce.
    g.state = GuardState::Stop;
    for c in 1..300 {
        assert_eq!(g.step(&input(c, high)), None);
    }
    assert_eq!((g.stop_count, g.warn_count), (100, 100));
    assert_eq!(g.clear_count, 0);
    // A repeated sample (no new counter) moves nothing.
    let mut repeat = input(300, Vec3::zeros());
    repeat.new_sample = false;
    g.step(&repeat);
    assert_eq!((g.stop_count, g.warn_count, g.clear_count), (100, 100, 0));
    g.step(&input(301, Vec3::zeros()));
    assert_eq!((g.stop_count, g.warn_count, g.clear_count), (99, 99, 1));
}

#[test]
fn force_parts_are_continuous_across_the_scaling_threshold() {
    let u = Vec3::new(0.6, 0.0, 0.8);
    let dir = Vec3::new(0.3, -0.5, 0.2).normalize();
    for k in [0.999_999, 1.0, 1.000_001] {
        let f = dir * (SCALE_ABOVE_N * k / dir.amax());
        let p = force_parts_n(&f, &u);
        let mag = SCALE_ABOVE_N * k / dir.amax();
        let axial = dir.dot(&u).abs() * mag;
        let lateral = newton_sqrt(1.0 - dir.dot(&u) * dir.dot(&u)) * mag;
        assert!((p[0] / mag - 1.0).abs() < 1e-12, "{p:?}");
        assert!((p[1] / axial - 1.0).abs() < 1e-12, "{p:?}");
        assert!((p[2] / lateral - 1.0).abs() < 1e-12, "{p:?}");
    }
    let p = force_parts_n(&Vec3::new(f64::MAX, f64::MAX, f64::MAX), &u);
    assert!(p.iter().all(|x| !x.is_nan()));
    assert_eq!(p[0], f64::INFINITY);
}

/// sqrt by Newton's method, so the check does not reuse the norm under test.
fn newton_sqrt(x: f64) -> f64 {
    let mut y = if x > 1.0 { x } else { 1.0 };
    for _ in 0..100 {
        y = 0.5 * (y + x / y);
    }
    y
}
