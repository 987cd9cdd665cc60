//! The closed forms of MODEL.md 3 against an independent Denavit-Hartenberg chain,
//! inverse kinematics round trips, degenerate poses and calibration validation.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::panic
)]

use core::f64::consts::{FRAC_PI_2, PI};
use nalgebra::{Matrix3, Rotation3, Vector3};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use sar_kinematics::dh::{axis, origin, sar_chain};
use sar_kinematics::{
    ActiveJoints, Calibration, CalibrationSpec, ConfigError, PoseError, Profile, ProfileSpec, Vec3,
    forward, inverse, rod_frame,
};

fn config(cases: u32, seed: u64) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

fn gravity() -> Vec3 {
    Vec3::new(0.0, -9.80665, 0.0)
}

fn calibration(p_home: Vec3, a_off: Vec3, support: Vec3) -> Calibration {
    Calibration::new(&CalibrationSpec {
        p_home_m: p_home,
        ujoint_offset_m: a_off,
        sensor_offset_m: Vec3::new(0.0, -0.03, 0.0),
        sensor_rotation: Matrix3::identity(),
        support_m: support,
        gravity_mps2: gravity(),
    })
    .unwrap()
}

/// Wraps an angle difference into (-pi, pi].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * PI);
    if d > PI { d - 2.0 * PI } else { d }
}

fn close(a: &Vec3, b: &Vec3, tol: f64) -> bool {
    (a - b).amax() <= tol
}

prop_compose! {
    fn vec3(range: f64)(x in -range..range, y in -range..range, z in -range..range) -> Vec3 {
        Vec3::new(x, y, z)
    }
}

proptest! {
    #![proptest_config(config(5000, 0x5a4_0001))]

    /// Random joints q1..q5, offset d and support distance s: the DH chain gives A,
    /// u, w and D; a support placed on that rod axis must give back the same q4, q5
    /// and points through the closed form, to 1e-12.
    #[test]
    fn closed_form_matches_dh_chain(
        p_home in vec3(0.5),
        a_off in vec3(0.1),
        q123 in vec3(0.2),
        q4 in -PI..PI,
        q5 in -1.2f64..1.2,
        length_m in 0.2f64..0.5,
        offset_m in prop_oneof![Just(0.0), -0.01f64..0.01],
        s_frac in 0.0f64..1.0,
        com_m in -0.05f64..0.3,
    ) {
        let profile = Profile::new(&ProfileSpec { length_m, offset_m, mass_kg: 2.0, com_m }).unwrap();
        let provisional = calibration(p_home, a_off, Vec3::zeros());
        let chain = sar_chain(&provisional, &profile);
        let joints = [q123.x, q123.y, q123.z, q4, q5];
        let a_dh = origin(&chain.frame(&joints, 3));
        let frame5 = chain.frame(&joints, 5);
        let u_dh = axis(&frame5, 0);
        let w_dh = -axis(&frame5, 1);
        let d_dh = origin(&chain.tool_frame(&joints));
        // The DH chain agrees with MODEL.md's u and w written from q4, q5.
        let (u_model, w_model) = rod_frame(q4, q5);
        prop_assert!(close(&u_dh, &u_model, 1e-12) && close(&w_dh, &w_model, 1e-12));

        let s = 0.04 + s_frac * (length_m - 0.05);
        let support = a_dh + w_dh * offset_m + u_dh * s;
        let cal = calibration(p_home, a_off, support);
        let q = ActiveJoints { q3_m: q123.x, q2_m: q123.y, q1_m: q123.z };
        let pose = forward(&cal, &profile, &q).unwrap();
        prop_assert!(angle_diff(pose.q4_rad(), q4).abs() < 1e-12, "q4 {} vs {}", pose.q4_rad(), q4);
        prop_assert!((pose.q5_rad() - q5).abs() < 1e-12, "q5 {} vs {}", pose.q5_rad(), q5);
        prop_assert!(close(&pose.ujoint_m, &a_dh, 1e-12));
        prop_assert!(close(&pose.rod_dir, &u_dh, 1e-12));
        prop_assert!(close(&pose.rod_normal, &w_dh, 1e-12));
        prop_assert!(close(&pose.tip_m, &d_dh, 1e-12), "D {:?} vs {:?}", pose.tip_m, d_dh);
        let c_dh = a_dh + w_dh * offset_m + u_dh * com_m;
        prop_assert!(close(&pose.com_m, &c_dh, 1e-12));
        prop_assert!((pose.support_along_rod_m - s).abs() < 1e-12);
        prop_assert!((pose.support_distance_m - (s * s + offset_m * offset_m).sqrt()).abs() < 1e-12);
        prop_assert!((pose.tip_beyond_support_m - (length_m - s)).abs() < 1e-12);
        prop_assert!(close(&pose.sensor_m, &(pose.carriage_m + Vec3::new(0.0, -0.03, 0.0)), 0.0));
    }

    /// Inverse then forward kinematics puts the tip where it was asked, for d = 0
    /// and d != 0, to 1e-12 m.
    #[test]
    fn inverse_then_forward_reaches_the_tip(
        support in vec3(0.5),
        p_home in vec3(0.5),
        a_off in vec3(0.1),
        q4 in -PI..PI,
        q5 in -1.0f64..1.0,
        beyond_frac in 0.05f64..0.85,
        length_m in 0.2f64..0.5,
        offset_m in prop_oneof![Just(0.0), -0.01f64..0.01],
    ) {
        let profile = Profile::new(&ProfileSpec { length_m, offset_m, mass_kg: 2.0, com_m: 0.1 }).unwrap();
        let cal = calibration(p_home, a_off, support);
        let (u, _) = rod_frame(q4, q5);
        let tip = support + u * (beyond_frac * length_m);
        let q = inverse(&cal, &profile, &tip).unwrap();
        let pose = forward(&cal, &profile, &q).unwrap();
        prop_assert!(close(&pose.tip_m, &tip, 1e-12), "{:?} vs {:?}", pose.tip_m, tip);
        prop_assert!(close(&pose.rod_dir, &u, 1e-12));
    }

    /// With d != 0 and steep rods (including within asin(|d| / rho) of
    /// vertical, where the line through B at offset d has two branches): the
    /// inverse either refuses the tip as a vertical rod, exactly when B - A
    /// would head against the rod, or gives joints that put the tip there.
    #[test]
    fn inverse_never_returns_the_other_branch(
        support in vec3(0.5),
        q4 in -PI..PI,
        tilt in 1e-4f64..0.3,
        down in any::<bool>(),
        beyond_frac in 0.05f64..0.95,
        offset_m in prop_oneof![-0.02f64..-0.001, 0.001f64..0.02],
    ) {
        let length_m = 0.35;
        let profile = Profile::new(&ProfileSpec { length_m, offset_m, mass_kg: 2.0, com_m: 0.1 }).unwrap();
        let cal = calibration(Vec3::zeros(), Vec3::zeros(), support);
        let q5 = if down { tilt - FRAC_PI_2 } else { FRAC_PI_2 - tilt };
        let (u, _) = rod_frame(q4, q5);
        let tip = support + u * (beyond_frac * length_m);
        let s = length_m - beyond_frac * length_m;
        // Written from MODEL.md 3: B - A = s u + d w, horizontal part (s c5 + d s5) heading.
        let ahead = s * q5.cos() + offset_m * q5.sin();
        match inverse(&cal, &profile, &tip) {
            Ok(q) => {
                prop_assert!(ahead > 0.0, "accepted a tip on the other branch");
                let pose = forward(&cal, &profile, &q).unwrap();
                prop_assert!(close(&pose.tip_m, &tip, 1e-9), "{:?} vs {:?}", pose.tip_m, tip);
            }
            Err(PoseError::VerticalRod { horizontal_m }) => {
                prop_assert!(ahead <= 1e-9 * (s * s + offset_m * offset_m).sqrt() + 1e-15);
                prop_assert!((horizontal_m - ahead).abs() < 1e-12);
            }
            Err(other) => prop_assert!(false, "{other:?}"),
        }
    }

    /// No finite input, however odd, gives a NaN or infinite output: either a
    /// finite pose or a typed error.
    #[test]
    fn forward_never_returns_non_finite_numbers(
        support in vec3(2.0),
        q123 in vec3(2.0),
        length_m in 1e-3f64..3.0,
        offset_frac in -0.99f64..0.99,
    ) {
        let profile = Profile::new(&ProfileSpec { length_m, offset_m: offset_frac * length_m, mass_kg: 1.0, com_m: 0.1 }).unwrap();
        let cal = calibration(Vec3::zeros(), Vec3::zeros(), support);
        let q = ActiveJoints { q3_m: q123.x, q2_m: q123.y, q1_m: q123.z };
        if let Ok(pose) = forward(&cal, &profile, &q) {
            for v in [pose.ujoint_m, pose.tip_m, pose.com_m, pose.rod_dir, pose.rod_normal] {
                prop_assert!(v.iter().all(|x| x.is_finite()));
            }
            prop_assert!(pose.q4_rad().is_finite() && pose.q5_rad().is_finite());
            prop_assert!(pose.tip_beyond_support_m > 0.0);
            prop_assert!((pose.rod_dir.norm() - 1.0).abs() < 1e-12);
            prop_assert!(pose.rod_dir.dot(&pose.rod_normal).abs() < 1e-12);
        }
    }
}

/// MODEL.md 3 with P_home + a_off = 0: the article's equations 8-10.
#[test]
fn article_equations_8_to_10() {
    let (q1, q2, q3) = (0.03, -0.02, 0.05);
    let (l, d) = (0.35, 0.004);
    let (q4, q5) = (1.3f64, 0.2f64);
    let (u, w) = rod_frame(q4, q5);
    let a = Vec3::new(q3, q2, q1);
    let s = 0.12;
    let support = a + w * d + u * s;
    let cal = calibration(
        Vec3::new(0.1, 0.2, 0.3),
        Vec3::new(-0.1, -0.2, -0.3),
        support,
    );
    let profile = Profile::new(&ProfileSpec {
        length_m: l,
        offset_m: d,
        mass_kg: 1.0,
        com_m: 0.1,
    })
    .unwrap();
    let pose = forward(
        &cal,
        &profile,
        &ActiveJoints {
            q1_m: q1,
            q2_m: q2,
            q3_m: q3,
        },
    )
    .unwrap();
    let (s4, c4, s5, c5) = (q4.sin(), q4.cos(), q5.sin(), q5.cos());
    let expected = Vec3::new(
        l * s4 * c5 + d * s4 * s5 + q3,
        l * s5 - d * c5 + q2,
        l * c4 * c5 + d * c4 * s5 + q1,
    );
    assert!(
        close(&pose.tip_m, &expected, 1e-15),
        "{:?} vs {expected:?}",
        pose.tip_m
    );
}

/// d = 0: u = r/|r|, q5 = asin(ry/|r|), s = |r|; nominal insertion is q4 = pi/2, q5 = 0.
#[test]
fn zero_offset_is_the_plain_direction_to_the_support() {
    let support = Vec3::new(0.45, 0.2, 0.0);
    let cal = calibration(Vec3::zeros(), Vec3::new(0.0, -0.08, 0.0), support);
    let profile = Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m: 0.0,
        mass_kg: 2.593,
        com_m: 0.103,
    })
    .unwrap();
    let nominal = forward(
        &cal,
        &profile,
        &ActiveJoints {
            q1_m: 0.0,
            q2_m: 0.28,
            q3_m: 0.3,
        },
    )
    .unwrap();
    assert!((nominal.q4_rad() - FRAC_PI_2).abs() < 1e-15 && nominal.q5_rad().abs() < 1e-15);
    assert!(close(&nominal.rod_dir, &Vec3::x(), 1e-15));
    assert!((nominal.support_distance_m - 0.15).abs() < 1e-15);
    let q = ActiveJoints {
        q1_m: 0.02,
        q2_m: 0.25,
        q3_m: 0.31,
    };
    let pose = forward(&cal, &profile, &q).unwrap();
    let r = support - (q.displacement_m() + Vec3::new(0.0, -0.08, 0.0));
    assert!(close(&pose.rod_dir, &(r / r.norm()), 1e-15));
    assert!((pose.q5_rad() - (r.y / r.norm()).asin()).abs() < 1e-15);
    assert!((pose.support_along_rod_m - r.norm()).abs() < 1e-15);
}

#[test]
fn degenerate_poses_are_typed_errors() {
    let support = Vec3::new(0.45, 0.2, 0.0);
    let cal = calibration(Vec3::zeros(), Vec3::zeros(), support);
    let rod = Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m: 0.0,
        mass_kg: 2.0,
        com_m: 0.1,
    })
    .unwrap();
    let offset_rod = Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m: 0.02,
        mass_kg: 2.0,
        com_m: 0.1,
    })
    .unwrap();
    let at = |x: f64, y: f64, z: f64| ActiveJoints {
        q3_m: x,
        q2_m: y,
        q1_m: z,
    };
    assert!(matches!(
        forward(&cal, &rod, &at(0.45, 0.2, 0.0)),
        Err(PoseError::UJointAtSupport { .. })
    ));
    assert!(matches!(
        forward(&cal, &offset_rod, &at(0.44, 0.2, 0.0)),
        Err(PoseError::SupportWithinOffset { .. })
    ));
    assert!(matches!(
        forward(&cal, &rod, &at(0.45, 0.0, 0.0)),
        Err(PoseError::VerticalRod { .. })
    ));
    assert!(matches!(
        forward(&cal, &rod, &at(0.10, 0.2, 0.0)),
        Err(PoseError::TipAtSupport { .. })
    ));
    assert!(matches!(
        forward(&cal, &rod, &at(0.05, 0.2, 0.0)),
        Err(PoseError::SupportBeyondTip { .. })
    ));
    assert!(matches!(
        forward(&cal, &rod, &at(f64::NAN, 0.2, 0.0)),
        Err(PoseError::NonFinite { value, .. }) if value.is_nan()
    ));
    // Inverse: the tip at the support, out of reach, vertical, NaN.
    assert!(matches!(
        inverse(&cal, &rod, &support),
        Err(PoseError::TipAtSupport { .. })
    ));
    assert!(matches!(
        inverse(&cal, &rod, &(support + Vec3::x() * 0.4)),
        Err(PoseError::SupportBeyondTip { .. })
    ));
    assert!(matches!(
        inverse(&cal, &rod, &(support - Vec3::y() * 0.1)),
        Err(PoseError::VerticalRod { .. })
    ));
    // d = 10 mm, B 0.1 m from A along the rod, the rod 0.05 rad from pointing
    // straight down: A to B heads against the rod (0.1 sin 0.05 < 0.01 cos 0.05).
    // The joints for it would put the tip about 5 cm away; it is refused.
    let tilted = Vec3::new(0.05f64.sin(), -0.05f64.cos(), 0.0);
    assert!(matches!(
        inverse(&cal, &offset_rod_10mm(), &(support + tilted * 0.25)),
        Err(PoseError::VerticalRod { horizontal_m }) if horizontal_m < 0.0
    ));
    assert!(matches!(
        inverse(&cal, &rod, &Vec3::new(f64::INFINITY, 0.0, 0.0)),
        Err(PoseError::NonFinite {
            input: "tip position",
            value
        }) if value == f64::INFINITY
    ));
}

fn offset_rod_10mm() -> Profile {
    Profile::new(&ProfileSpec {
        length_m: 0.35,
        offset_m: 0.01,
        mass_kg: 2.0,
        com_m: 0.1,
    })
    .unwrap()
}

/// The named-field specs: `new` and `spec()` agree, and a spec
/// read back is the one given (each field lands where it is named).
#[test]
fn calibration_and_profile_come_from_named_fields() {
    let spec = CalibrationSpec {
        p_home_m: Vec3::new(0.01, 0.02, 0.03),
        ujoint_offset_m: Vec3::new(0.0, -0.08, 0.0),
        sensor_offset_m: Vec3::new(0.0, -0.03, 0.001),
        sensor_rotation: Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner(),
        support_m: Vec3::new(0.45, 0.2, 0.0),
        gravity_mps2: gravity(),
    };
    let cal = Calibration::new(&spec).unwrap();
    assert_eq!(cal.spec(), spec);
    assert_eq!(cal.p_home_m(), spec.p_home_m);
    assert_eq!(cal.ujoint_offset_m(), spec.ujoint_offset_m);
    assert_eq!(cal.sensor_offset_m(), spec.sensor_offset_m);
    assert_eq!(cal.sensor_rotation(), spec.sensor_rotation);
    assert_eq!(cal.support_m(), spec.support_m);
    assert_eq!(cal.gravity_mps2(), spec.gravity_mps2);
    let spec = ProfileSpec {
        length_m: 0.35,
        offset_m: 0.004,
        mass_kg: 2.593,
        com_m: 0.103,
    };
    let profile = Profile::new(&spec).unwrap();
    assert_eq!(profile.spec(), spec);
    assert_eq!(
        (
            profile.length_m(),
            profile.offset_m(),
            profile.mass_kg(),
            profile.com_m()
        ),
        (0.35, 0.004, 2.593, 0.103)
    );
    // The field names carry into the errors.
    assert!(matches!(
        Profile::new(&ProfileSpec {
            mass_kg: -1.0,
            ..spec
        }),
        Err(ConfigError::NegativeMass { mass_kg }) if mass_kg == -1.0
    ));
}

#[test]
fn invalid_calibrations_and_profiles_are_refused() {
    let ok = |r: Matrix3<f64>, g: Vec3| {
        Calibration::new(&CalibrationSpec {
            p_home_m: Vec3::zeros(),
            ujoint_offset_m: Vec3::zeros(),
            sensor_offset_m: Vec3::zeros(),
            sensor_rotation: r,
            support_m: Vec3::x(),
            gravity_mps2: g,
        })
    };
    let rotation = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    assert!(ok(rotation, gravity()).is_ok());
    assert!(matches!(
        ok(rotation * 1.001, gravity()),
        Err(ConfigError::RotationNotOrthonormal { .. })
    ));
    let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    assert!(matches!(
        ok(reflection, gravity()),
        Err(ConfigError::RotationNotProper { .. })
    ));
    let mut nan_rotation = Matrix3::identity();
    nan_rotation[(1, 2)] = f64::NAN;
    assert!(matches!(
        ok(nan_rotation, gravity()),
        Err(ConfigError::NonFinite {
            field: "sensor_rotation",
            value
        }) if value.is_nan()
    ));
    assert!(matches!(
        ok(Matrix3::identity(), Vec3::zeros()),
        Err(ConfigError::GravityOutOfRange { .. })
    ));
    assert!(matches!(
        Calibration::new(&CalibrationSpec { p_home_m: Vec3::new(f64::NAN, 0.0, 0.0), ujoint_offset_m: Vec3::zeros(), sensor_offset_m: Vec3::zeros(), sensor_rotation: Matrix3::identity(), support_m: Vec3::x(), gravity_mps2: gravity() }),
        Err(ConfigError::NonFinite {
            field: "p_home",
            value
        }) if value.is_nan()
    ));
    assert!(matches!(
        Profile::new(&ProfileSpec {
            length_m: 0.0,
            offset_m: 0.0,
            mass_kg: 1.0,
            com_m: 0.1
        }),
        Err(ConfigError::NonPositiveLength { .. })
    ));
    assert!(matches!(
        Profile::new(&ProfileSpec {
            length_m: 0.3,
            offset_m: 0.3,
            mass_kg: 1.0,
            com_m: 0.1
        }),
        Err(ConfigError::OffsetTooLarge { .. })
    ));
    assert!(matches!(
        Profile::new(&ProfileSpec {
            length_m: 0.3,
            offset_m: 0.0,
            mass_kg: -1.0,
            com_m: 0.1
        }),
        Err(ConfigError::NegativeMass { .. })
    ));
    assert!(matches!(
        Profile::new(&ProfileSpec { length_m: 0.3, offset_m: 0.0, mass_kg: 1.0, com_m: f64::NAN }),
        Err(ConfigError::NonFinite {
            field: "com_m",
            value
        }) if value.is_nan()
    ));
}
