//! The plant in motion (issue 26 section 1): the sensor's Newton-Euler
//! wrench against an independent formulation from positions only, the
//! statics at rest, the phantom tip force of MODEL.md 10's table, the
//! servos and the quick-stop deceleration.

use super::*;
use sar_kinematics::{Pose, forward};
use sar_sim::{RodInertia, ServoSpec};

/// Half the central differences' step, ns (h = 100 us: the truncation
/// error, ~h^2 |C''''| m / 12, is below 1e-7 N here, the rounding of
/// positions, ~4 eps |C| m / h^2, about 5e-8 N).
const H_NS: u64 = 100_000;

pub(super) fn inertia(perp: f64, axial: f64, adapter: f64) -> RodInertia {
    RodInertia {
        inertia_perp_kgm2: perp,
        inertia_axial_kgm2: axial,
        adapter_mass_kg: adapter,
    }
}

/// A quiet, bias-free world in motion: 0.2 m/s, 2 m/s^2 axes, the given
/// inertia, a constant tip force and the support's friction.
fn moving_spec(offset_m: f64, rod: RodInertia) -> SimSpec {
    let mut spec = quiet_spec();
    spec.sensor.bias_n = Vec3::zeros();
    spec.sensor.bias_nm = Vec3::zeros();
    spec.profile = Profile::new(&ProfileSpec {
        length_m: LENGTH_M,
        offset_m,
        mass_kg: MASS_KG,
        com_m: COM_M,
    })
    .unwrap();
    spec.axes.max_speed_mps = 0.2;
    spec.axes.max_accel_mps2 = 2.0;
    spec.axes.start = ActiveJoints {
        q1_m: 0.02,
        q2_m: 0.25,
        q3_m: 0.27,
    };
    spec.friction_n = 0.4;
    spec.contact = vec![ContactKey {
        t_ns: 0,
        force_n: Vec3::new(3.0, -1.0, 2.0),
    }];
    spec.plant.inertia = Some(rod);
    spec
}

/// What positions alone give at the middle of five instants h apart: A,
/// A', A'' (central differences of the U-joint), a_C and a_D (of the COM
/// and the tip), omega at the three middle instants (from the rod's frame
/// (u, w, u x w): the skew part of R' R^T), and the poses.
struct FromPositions {
    poses: [Pose; 5],
    a_dot: Vec3,
    a_ddot: Vec3,
    com_accel: Vec3,
    tip_accel: Vec3,
    omega: [Vec3; 3],
}

fn second_difference(a: &Vec3, b: &Vec3, c: &Vec3, h: f64) -> Vec3 {
    (a - b * 2.0 + c) / (h * h)
}

fn frame(p: &Pose) -> Matrix3<f64> {
    let (u, w) = (p.rod_dir, p.rod_normal);
    Matrix3::from_columns(&[u, w, u.cross(&w)])
}

fn from_positions(poses: [Pose; 5]) -> FromPositions {
    let h = H_NS as f64 * 1e-9;
    let [p0, p1, p2, p3, p4] = &poses;
    let omega_at = |before: &Pose, at: &Pose, after: &Pose| {
        let s = (frame(after) - frame(before)) / (2.0 * h) * frame(at).transpose();
        let k = (s - s.transpose()) * 0.5;
        Vec3::new(k[(2, 1)], k[(0, 2)], k[(1, 0)])
    };
    FromPositions {
        a_dot: (p3.ujoint_m - p1.ujoint_m) / (2.0 * h),
        a_ddot: second_difference(&p1.ujoint_m, &p2.ujoint_m, &p3.ujoint_m, h),
        com_accel: second_difference(&p1.com_m, &p2.com_m, &p3.com_m, h),
        tip_accel: second_difference(&p1.tip_m, &p2.tip_m, &p3.tip_m, h),
        omega: [
            omega_at(p0, p1, p2),
            omega_at(p1, p2, p3),
            omega_at(p2, p3, p4),
        ],
        poses,
    }
}

impl FromPositions {
    /// H_C' = d(I_C omega)/dt, central difference of H at t +- h.
    fn h_dot(&self, rod: &RodInertia) -> Vec3 {
        let h = H_NS as f64 * 1e-9;
        let momentum = |p: &Pose, w: &Vec3| {
            let u = p.rod_dir;
            let along = u.dot(w);
            (w - u * along) * rod.inertia_perp_kgm2 + u * (along * rod.inertia_axial_kgm2)
        };
        let [_, p1, _, p3, _] = &self.poses;
        let [w1, _, w3] = &self.omega;
        (momentum(p3, w3) - momentum(p1, w1)) / (2.0 * h)
    }
}

/// Starts a move from `spec.axes.start` at t = 0 and returns the truths at
/// 50 ms + k h, k = -2..=2 (inside every axis's first, constant-acceleration
/// phase: a smooth trajectory).
fn five_truths(spec: SimSpec, target: ActiveJoints) -> [Truth; 5] {
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(target).unwrap();
    [0u64, 1, 2, 3, 4].map(|k| {
        rig.run_until(50 * MS - 2 * H_NS + k * H_NS);
        rig.truth()
    })
}

const TARGET: ActiveJoints = ActiveJoints {
    q1_m: -0.03,
    q2_m: 0.3,
    q3_m: 0.33,
};

/// Issue 26's test: the simulated sensor against MODEL.md 10's explicit
/// construction (d = 0) fed only by central differences of positions.
#[test]
fn the_sensor_in_motion_agrees_with_differences_of_positions() {
    let rod = inertia(0.8 * MASS_KG * LENGTH_M * LENGTH_M / 12.0, 0.002, 0.3);
    let spec = moving_spec(0.0, rod);
    let (cal, profile) = (spec.calibration, spec.profile);
    let friction = spec.friction_n;
    let truths = five_truths(spec, TARGET);
    let poses = truths
        .each_ref()
        .map(|t| forward(&cal, &profile, &t.joints).unwrap());
    let fd = from_positions(poses);
    let truth = &truths[2];
    // The motion is real: about 0.1 m/s and 2 m/s^2 on every axis.
    assert!(fd.a_dot.iter().all(|v| v.abs() > 0.09), "{:?}", fd.a_dot);
    assert!(fd.a_ddot.iter().all(|a| (a.abs() - 2.0).abs() < 1e-6));
    let p = &fd.poses[2];
    let (u, g, m) = (p.rod_dir, gravity(), MASS_KG);
    let rho = p.support_distance_m;
    let f_d = -truth.tip_force_n;
    let f_axial = -fd.a_dot.dot(&u).signum() * friction;
    let r_m =
        fd.h_dot(&rod) + u.cross(&((fd.com_accel - g) * m)) * COM_M - u.cross(&f_d) * LENGTH_M;
    let q4 = u.x.atan2(u.z);
    let n = -Vec3::new(q4.sin(), 0.0, q4.cos());
    let cos_q5 = u.x.hypot(u.z);
    let m_t = -r_m.dot(&u) / cos_q5;
    let f_b = ((r_m - n * m_t) / rho).cross(&u) + u * f_axial;
    let f_a = fd.com_accel * m - g * m - f_d - f_b;
    let on_sensor = -f_a - fd.a_ddot * rod.adapter_mass_kg;
    let torque = (p.ujoint_m - p.sensor_m).cross(&on_sensor) - n * m_t;
    let force_err = (truth.reading_n - on_sensor).amax();
    let torque_err = (truth.reading_nm - torque).amax();
    eprintln!("FD agreement (d = 0): force {force_err:.2e} N, torque {torque_err:.2e} N m");
    assert!(force_err < 1e-6, "{:?} vs {on_sensor:?}", truth.reading_n);
    assert!(torque_err < 1e-6, "{:?} vs {torque:?}", truth.reading_nm);
    // The inertial part is not small beside the agreement.
    let mut statics = moving_spec(0.0, rod);
    statics.plant = PlantSpec::default();
    let inertial_n = (five_truths(statics, TARGET)[2].reading_n - truth.reading_n).norm();
    eprintln!("inertial part of that reading: {inertial_n:.3} N");
    assert!(inertial_n > 1.0, "{inertial_n}");
}

/// With an offset d (and a mass hung at the tip), Newton-Euler's six
/// equations hold for the simulator's F_A, support force and torsion with
/// a_C, a_D and H_C' from positions only; the sensor reads -F_A - m_s A''.
#[test]
fn with_an_offset_the_newton_euler_residuals_vanish_from_positions_alone() {
    let rod = inertia(0.03, 0.004, 0.25);
    let mut spec = moving_spec(0.01, rod);
    spec.tip_mass_kg = 0.5;
    let (cal, profile) = (spec.calibration, spec.profile);
    let truths = five_truths(spec, TARGET);
    let poses = truths
        .each_ref()
        .map(|t| forward(&cal, &profile, &t.joints).unwrap());
    let fd = from_positions(poses);
    let t = &truths[2];
    let p = &fd.poses[2];
    let (g, m) = (gravity(), MASS_KG);
    assert!(t.torsion_nm.abs() > 1e-3, "{}", t.torsion_nm);
    let tip_load = -t.tip_force_n + (g - fd.tip_accel) * 0.5;
    let support = t.support_reaction_n + t.friction_force_n;
    let force = t.ujoint_force_n + support + g * m + tip_load - fd.com_accel * m;
    let q4 = p.rod_dir.x.atan2(p.rod_dir.z);
    let n = -Vec3::new(q4.sin(), 0.0, q4.cos());
    let at_a = |x: &Vec3| x - p.ujoint_m;
    let moment = at_a(&cal.support_m()).cross(&support)
        + at_a(&p.com_m).cross(&(g * m))
        + at_a(&p.tip_m).cross(&tip_load)
        + n * t.torsion_nm
        - fd.h_dot(&rod)
        - at_a(&p.com_m).cross(&(fd.com_accel * m));
    let on_sensor = -t.ujoint_force_n - fd.a_ddot * rod.adapter_mass_kg;
    eprintln!(
        "FD residuals (d = 10 mm): force {:.2e} N, moment {:.2e} N m, sensor {:.2e} N",
        force.amax(),
        moment.amax(),
        (t.reading_n - on_sensor).amax()
    );
    assert!(force.amax() < 1e-6, "{force:?}");
    assert!(moment.amax() < 1e-6, "{moment:?}");
    assert!((t.reading_n - on_sensor).amax() < 1e-6);
}

/// At rest (q' = q'' = 0) the plant with inertia reads the statics bit for
/// bit, whatever its inertia, offset, friction, tip load and adapter.
#[test]
fn at_rest_the_wrench_in_motion_is_the_statics_exactly() {
    for offset_m in [0.0, 0.01] {
        let still = moving_spec(offset_m, inertia(0.05, 0.01, 0.4));
        let mut statics = still.clone();
        statics.plant = PlantSpec::default();
        let mut rigs = [Rig::new(still), Rig::new(statics)];
        for target in [TARGET, horizontal(0.18)] {
            for rig in &mut rigs {
                rig.move_to(target);
            }
            let [a, b] = rigs.each_ref().map(Rig::truth);
            assert_eq!(a.joint_accels_mps2, [0.0; 3]);
            assert_eq!(a.reading_n, b.reading_n);
            assert_eq!(a.reading_nm, b.reading_nm);
            assert_eq!(a.ujoint_force_n, b.ujoint_force_n);
            assert_eq!(a.torsion_nm, b.torsion_nm);
            assert_eq!(a.friction_force_n, b.friction_force_n);
        }
    }
}

/// MODEL.md 10's table: at the nominal pose of manipulator 2 (A = (0.25,
/// 0.2, 0), q' = 0, I_perp = m L^2 / 12) the static closed form (4.1) reads
/// 2.59 N per m/s^2 along the rod and 1.70 across (the sensor's inertial
/// part: 1.27 across).
#[test]
fn the_static_closed_form_reads_the_phantom_force_of_model_10() {
    let rod = inertia(MASS_KG * LENGTH_M * LENGTH_M / 12.0, 0.0, 0.0);
    let nominal = horizontal(0.2);
    let mut spec = quiet_spec();
    spec.sensor.bias_n = Vec3::zeros();
    spec.sensor.bias_nm = Vec3::zeros();
    spec.axes.max_accel_mps2 = 1.0;
    spec.axes.start = nominal;
    spec.plant.inertia = Some(rod);
    let at_rest = Rig::new(spec.clone()).truth().ujoint_force_n;
    let mut phantoms = Vec::new();
    for axis in 0..3 {
        let mut rig = Rig::new(spec.clone());
        let mut target = axes(&nominal);
        target[axis] += 0.02;
        rig.drives.enable().unwrap();
        rig.drives.set_targets(joints(target)).unwrap();
        let t = rig.truth();
        assert_eq!(t.joint_speeds_mps, [0.0; 3]);
        assert_eq!(t.joint_accels_mps2[axis], 1.0);
        let phantom = tip_force_closed_form(&t, MASS_KG, COM_M);
        let inertial = (at_rest - t.ujoint_force_n).norm();
        phantoms.push((phantom.norm(), inertial));
    }
    eprintln!("phantom tip force, inertial part of -F_A per m/s^2 (q1, q2, q3): {phantoms:?}");
    let [(z, z_in), (y, y_in), (x, x_in)] = [phantoms[0], phantoms[1], phantoms[2]];
    assert!(
        (x - 2.59).abs() < 0.005 && (x_in - 2.59).abs() < 0.005,
        "{x} {x_in}"
    );
    for (across, inertial) in [(y, y_in), (z, z_in)] {
        assert!((across - 1.70).abs() < 0.005, "{across}");
        assert!((inertial - 1.27).abs() < 0.005, "{inertial}");
    }
}

fn joints(q: [f64; 3]) -> ActiveJoints {
    ActiveJoints {
        q1_m: q[0],
        q2_m: q[1],
        q3_m: q[2],
    }
}

pub(super) const SERVO: ServoSpec = ServoSpec {
    bandwidth_hz: 30.0,
    damping: 0.7,
    max_accel_mps2: 5.0,
    delay_ns: 0,
    inner_loop_hz: 0.0,
};

/// A servo lags its profile: in the cruise at v the following error of the
/// plain second-order loop is 2 zeta v / wn (0.371 mm at 0.05 m/s), and
/// it settles at the target.
#[test]
fn a_servo_axis_lags_its_set_point_and_settles() {
    let mut spec = quiet_spec();
    spec.plant.servo = Some(SERVO);
    let mut rig = Rig::new(spec);
    let start = horizontal(0.15);
    let target = horizontal(0.05);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(target).unwrap();
    rig.run_until(S);
    let distance = target.q3_m - start.q3_m;
    let reference = start.q3_m + sar_hal::motion::axis_progress_m(distance, V_MAX, A_MAX, 1.0);
    let lag = reference - rig.truth().joints.q3_m;
    let expected = 2.0 * 0.7 * V_MAX / (core::f64::consts::TAU * 30.0);
    eprintln!(
        "servo following error in the cruise: {lag:.4e} m (2 zeta v / wn = {expected:.4e} m)"
    );
    assert!((lag / expected - 1.0).abs() < 1e-3, "{lag} vs {expected}");
    rig.run_until(3 * S);
    let t = rig.truth();
    assert!((t.joints.q3_m - target.q3_m).abs() < 1e-9);
    assert!(t.joint_speeds_mps[2].abs() < 1e-9);
    // Streamed set points at full speed are measured from the reference,
    // not from the lagging axis: none is refused.
    let mut q = axes(&target);
    for _ in 0..200 {
        q[2] += V_MAX * 1e-3;
        rig.drives.stream(joints(q), MS).unwrap();
        rig.clock.advance_ns(MS);
    }
    let lag = q[2] - rig.truth().joints.q3_m;
    assert!((lag / expected - 1.0).abs() < 0.05, "{lag}");
}

/// The positions of q3, every millisecond for `ms` ms, of a move from
/// `horizontal(0.15)` to `horizontal(0.05)` commanded at 0 on `servo`.
fn q3_track(servo: ServoSpec, ms: u64) -> Vec<f64> {
    let mut spec = quiet_spec();
    spec.plant.servo = Some(servo);
    let mut rig = Rig::new(spec);
    rig.drives.enable().unwrap();
    rig.drives.set_targets(horizontal(0.05)).unwrap();
    (0..ms)
        .map(|k| {
            rig.run_until(k * MS);
            rig.truth().joints.q3_m
        })
        .collect()
}

/// Issue 34, a servo that is not the loop's model: a pure delay of the
/// reference makes the axis the same servo, later (the delay rounded to
/// physics steps, 0.1 ms here): with 2 ms, every position is the
/// undelayed servo's of 2 ms before, to 1e-12 m; and the delay shows (the
/// two differ by more than 0.05 mm during the move).
#[test]
fn a_servo_with_a_pure_delay_is_the_same_servo_later() {
    let plain = q3_track(SERVO, 1500);
    let delayed = q3_track(
        ServoSpec {
            delay_ns: 2 * MS,
            ..SERVO
        },
        1500,
    );
    let mut largest_m: f64 = 0.0;
    for k in 2..1500 {
        let d = (delayed[k] - plain[k - 2]).abs();
        assert!(d < 1e-12, "at {k} ms: {d} m");
        largest_m = largest_m.max((delayed[k] - plain[k]).abs());
    }
    eprintln!("a 2 ms delay: largest difference from the undelayed servo {largest_m:.3e} m");
    assert!(largest_m > 5e-5, "{largest_m}");
}

/// Issue 34: an inner (velocity) loop at f_i makes the axis third order,
/// `x'' = a`, `a' = 2 pi f_i (wn^2 (r - x) - 2 zeta wn x' - a)`: the
/// simulated axis follows an independent integration of those equations
/// (RK4 at 10 us, the reference the plan's own profile) within 10 nm all
/// along a move at 0.5 m/s^2 (measured: 0.3 nm), while the second-order
/// servo is more than 2 um away from it (4.9 um: the inner loop's lag
/// shows), and the third order settles at the target.
#[test]
fn an_inner_loop_makes_the_servo_third_order() {
    let inner_hz = 40.0;
    let third = q3_track(
        ServoSpec {
            inner_loop_hz: inner_hz,
            ..SERVO
        },
        2500,
    );
    let second = q3_track(SERVO, 2500);
    let (start, target) = (horizontal(0.15).q3_m, horizontal(0.05).q3_m);
    let reference = |t_s: f64| {
        start + sar_hal::motion::axis_progress_m(target - start, V_MAX, A_MAX, t_s.max(0.0))
    };
    let wn = core::f64::consts::TAU * SERVO.bandwidth_hz;
    let wi = core::f64::consts::TAU * inner_hz;
    let z = SERVO.damping;
    let f = |t: f64, y: [f64; 3]| {
        let wanted = wn * wn * (reference(t) - y[0]) - 2.0 * z * wn * y[1];
        [y[1], y[2], wi * (wanted - y[2])]
    };
    let h = 1e-5;
    let mut y = [start, 0.0, 0.0];
    let (mut largest_third_m, mut largest_second_m): (f64, f64) = (0.0, 0.0);
    for (k, (x3, x2)) in third.iter().zip(&second).enumerate() {
        let t_ms = k as f64 * 1e-3;
        for i in 0..100 {
            let t = t_ms - 1e-3 + f64::from(i) * h;
            if k == 0 {
                break;
            }
            let k1 = f(t, y);
            let at = |y: [f64; 3], k: [f64; 3], s: f64| core::array::from_fn(|j| y[j] + s * k[j]);
            let k2 = f(t + h / 2.0, at(y, k1, h / 2.0));
            let k3 = f(t + h / 2.0, at(y, k2, h / 2.0));
            let k4 = f(t + h, at(y, k3, h));
            y = core::array::from_fn(|j| {
                y[j] + h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            });
        }
        largest_third_m = largest_third_m.max((x3 - y[0]).abs());
        largest_second_m = largest_second_m.max((x2 - y[0]).abs());
    }
    eprintln!(
        "inner loop at {inner_hz} Hz: the simulated axis within {largest_third_m:.3e} m of the \
         third-order equations; the second-order servo {largest_second_m:.3e} m from them"
    );
    assert!(largest_third_m < 1e-8, "{largest_third_m}");
    assert!(largest_second_m > 2e-6, "{largest_second_m}");
    assert!((third.last().unwrap() - target).abs() < 1e-9);
}

/// A servo's delay beyond its bounds, or a negative inner loop, is refused
/// naming its key.
#[test]
fn a_servo_delay_or_inner_loop_out_of_range_is_refused() {
    for (servo, key) in [
        (
            ServoSpec {
                delay_ns: 25 * MS,
                ..SERVO
            },
            "axes.servo_delay_s",
        ),
        (
            ServoSpec {
                inner_loop_hz: -1.0,
                ..SERVO
            },
            "axes.servo_inner_loop_hz",
        ),
    ] {
        let mut spec = quiet_spec();
        spec.plant.servo = Some(servo);
        let e = sar_sim::validate(&spec).unwrap_err();
        assert!(e.to_string().contains(key), "{e}");
    }
    let mut spec = quiet_spec();
    spec.plant.servo = Some(ServoSpec {
        delay_ns: 20 * MS,
        ..SERVO
    });
    sar_sim::validate(&spec).unwrap();
}

/// A quick stop decelerates at the drive's quick-stop deceleration (not the
/// planning acceleration) and stops after v^2 / (2 a), with a servo or
/// without.
#[test]
fn a_quick_stop_brakes_at_the_quick_stop_deceleration() {
    for servo in [None, Some(SERVO)] {
        let mut spec = quiet_spec();
        spec.plant.servo = servo;
        spec.plant.quick_stop_decel_mps2 = Some(2.0);
        let mut rig = Rig::new(spec);
        rig.drives.enable().unwrap();
        rig.drives.set_targets(horizontal(0.04)).unwrap();
        rig.run_until(S);
        rig.drives.quick_stop().unwrap();
        let before = rig.truth();
        let v = before.joint_speeds_mps[2];
        assert!((v - V_MAX).abs() < 1e-6, "{v}");
        for k in 1..=10 {
            rig.clock.advance_ns(2 * MS);
            let t = rig.truth();
            let expected = (v - 2.0 * k as f64 * 0.002).max(0.0);
            assert!((t.joint_speeds_mps[2] - expected).abs() < 1e-12, "{k}");
            assert!(t.joint_speeds_mps[2] == 0.0 || t.joint_accels_mps2[2] == -2.0);
        }
        rig.clock.advance_ns(20 * MS);
        let stopped = rig.truth();
        let travelled = stopped.joints.q3_m - before.joints.q3_m;
        eprintln!("quick stop from {v} m/s: {travelled:.6e} m");
        assert!((travelled - v * v / 4.0).abs() < 1e-12, "{travelled}");
        rig.clock.advance_ns(S);
        assert_eq!(rig.truth().joints, stopped.joints);
        // Enabled again, the axis follows new set points (the servo from
        // where the ramp left it).
        rig.drives.disable().unwrap();
        rig.drives.enable().unwrap();
        rig.drives.set_targets(horizontal(0.1)).unwrap();
        rig.clock.advance_ns(3 * S);
        assert!((rig.truth().joints.q3_m - horizontal(0.1).q3_m).abs() < 1e-9);
    }
}

/// The axes' motion in the truth as the estimator's [`CarriageMotion`]:
/// A' = (q3', q2', q1'), A'' likewise, known exactly.
fn carriage_motion(t: &Truth) -> sar_estimator::motion::CarriageMotion {
    let [v1, v2, v3] = t.joint_speeds_mps;
    let [a1, a2, a3] = t.joint_accels_mps2;
    sar_estimator::motion::CarriageMotion {
        velocity_mps: Vec3::new(v3, v2, v1),
        accel_mps2: Vec3::new(a3, a2, a1),
        accel_std_mps2: 0.0,
    }
}

/// The estimator's inertia for the simulator's.
fn estimator_inertia(rod: &RodInertia) -> sar_estimator::inertial::RodInertia {
    sar_estimator::inertial::RodInertia {
        inertia_perp_kgm2: rod.inertia_perp_kgm2,
        inertia_perp_std_kgm2: 0.0,
        inertia_axial_kgm2: rod.inertia_axial_kgm2,
        adapter_mass_kg: rod.adapter_mass_kg,
    }
}

/// Issue 26 section 2: the estimator's compensation (sar-estimator's closed
/// forms) recovers the simulator's tip force, F_A and torsion (its
/// Newton-Euler solve from second-order jets) during a 2 m/s^2 move, with
/// d = 0 and d != 0, I_axial and an adapter; the static estimate does not.
#[test]
fn the_estimators_compensation_recovers_the_simulators_tip_force() {
    for offset_m in [0.0, 0.01] {
        let rod = inertia(1.3 * MASS_KG * LENGTH_M * LENGTH_M / 12.0, 0.002, 0.3);
        let mut spec = moving_spec(offset_m, rod);
        spec.friction_n = 0.0;
        let (cal, prof) = (spec.calibration, spec.profile);
        let estimator = sar_estimator::tip_force::TipForceEstimator::new(
            &cal,
            &prof,
            &sar_estimator::SensorNoise::hex6(),
            sar_estimator::tip_force::TipForceConfig { max_std_n: 5.0 },
        )
        .unwrap()
        .with_inertia(estimator_inertia(&rod))
        .unwrap();
        let mut rig = Rig::new(spec);
        rig.drives.enable().unwrap();
        rig.drives.set_targets(TARGET).unwrap();
        let mut worst_n: f64 = 0.0;
        let mut phantom_n: f64 = 0.0;
        for t_ms in [20u64, 60, 90, 150, 200, 260] {
            rig.run_until(t_ms * MS);
            let t = rig.truth();
            let motion = carriage_motion(&t);
            let e = estimator
                .estimate_in_motion(&t.pose, &t.reading_n, &t.bias_n, &motion)
                .unwrap();
            worst_n = worst_n.max((e.force_n - t.tip_force_n).amax());
            assert!(
                (e.force_n - t.tip_force_n).amax() < 1e-6,
                "d {offset_m}, {t_ms} ms: {} vs {}",
                e.force_n,
                t.tip_force_n
            );
            assert!((e.ujoint_force_n - t.ujoint_force_n).amax() < 1e-6);
            assert!((e.torsion_nm - t.torsion_nm).abs() < 1e-7);
            let still = estimator
                .estimate(&t.pose, &t.reading_n, &t.bias_n)
                .unwrap();
            phantom_n = phantom_n.max((still.force_n - t.tip_force_n).norm());
        }
        eprintln!(
            "d = {offset_m}: compensated within {worst_n:.1e} N, static off by up to {phantom_n:.2} N"
        );
        assert!(phantom_n > 2.0, "{phantom_n}");
    }
}

/// A planned move at 2 m/s^2 (0.2 m/s) on the noisy simulator with the
/// rod's inertia, an axial inertia, an adapter and d != 0: the estimator
/// given the move's A' and A'' keeps the guard at Ok and the torque check
/// quiet all the way (HEX-6 noise, the torque check at its default 7 sigma).
#[test]
fn a_fast_move_keeps_the_guard_ok_and_the_torque_check_quiet() {
    use sar_estimator::cycle::{
        Bias, Command, CycleContext, CycleInput, Estimator, EstimatorConfig, JointSample,
        PlausibilityConfig, PlausibilityLimits, SensorSample, TorqueLimits,
    };
    use sar_estimator::guard::{GuardConfig, GuardLimits, GuardState};
    let rod = inertia(MASS_KG * LENGTH_M * LENGTH_M / 12.0, 0.002, 0.3);
    let mut spec = moving_spec(0.008, rod);
    spec.friction_n = 0.0;
    spec.contact.clear();
    spec.sensor.noise_n = base_spec().sensor.noise_n;
    spec.sensor.noise_nm = base_spec().sensor.noise_nm;
    spec.sensor.bias_n = base_spec().sensor.bias_n;
    let config = EstimatorConfig {
        calibration: spec.calibration,
        profile: spec.profile,
        noise: sar_estimator::SensorNoise::new(spec.sensor.noise_n).unwrap(),
        tip: sar_estimator::tip_force::TipForceConfig::default(),
        guard: GuardConfig::new(GuardLimits::EXAMPLE).unwrap(),
        plausibility: PlausibilityConfig::new(PlausibilityLimits {
            max_joint_speed_mps: 0.5,
            torque: Some(TorqueLimits {
                noise_nm: spec.sensor.noise_nm,
                max_sigma: TorqueLimits::DEFAULT_MAX_SIGMA,
            }),
            mounting: None,
            ..PlausibilityLimits::default()
        })
        .unwrap(),
        filter: None,
        inertia: estimator_inertia(&rod),
    };
    let bias = Bias {
        force_n: spec.sensor.bias_n,
        torque_nm: spec.sensor.bias_nm,
    };
    let mut compensated = Estimator::with_bias(&config, bias).unwrap();
    // The same inputs without the motion: the static model.
    let mut uncompensated = Estimator::with_bias(&config, bias).unwrap();
    let mut largest_still_n: f64 = 0.0;
    let mut widened = 0;
    let mut rig = Rig::new(spec);
    let mut moving = 0;
    let mut largest_n: f64 = 0.0;
    for k in 0..250u64 {
        // Rest for 100 ms (the first reset), then the move.
        if k == 50 {
            rig.drives.enable().unwrap();
            rig.drives.set_targets(TARGET).unwrap();
        }
        let t_ns = 2 * k * MS;
        rig.run_until(t_ns);
        let truth = rig.truth();
        rig.run_until(t_ns + MS / 2);
        let s = rig.sensor.poll().unwrap().unwrap();
        let input = CycleInput {
            cycle: k,
            now_ns: Some(s.received_ns),
            sensor: SensorSample {
                force_n: s.force_n,
                torque_nm: s.torque_nm,
                counter: s.counter,
                status: s.status.0,
                stamp_ns: s.received_ns,
                valid: s.is_valid(),
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: JointSample {
                joints: truth.joints,
                stamp_ns: s.received_ns,
                valid: true,
            },
            command: (k < 50).then_some(Command::Reset),
        };
        let still = uncompensated.cycle(&input, &CycleContext::AT_REST);
        if let (true, sar_estimator::cycle::TipOutcome::Estimate(e)) = (k >= 50, still.tip) {
            largest_still_n = largest_still_n.max(e.force_n.norm());
        }
        let still_torque_std = still.torque.map(|t| t.std_nm);
        // A'' known to 0.05 m/s^2: the adapter (d != 0) makes M_T uncertain.
        let motion = sar_estimator::motion::CarriageMotion {
            accel_std_mps2: 0.05,
            ..carriage_motion(&truth)
        };
        let in_motion = CycleContext {
            motion,
            ..CycleContext::AT_REST
        };
        let out = compensated.cycle(&input, &in_motion);
        if let (Some(a), Some(b)) = (out.torque.map(|t| t.std_nm), still_torque_std) {
            assert!((a - b).min() >= 0.0, "{a:?} vs {b:?}");
            if (a - b).max() > 0.0 {
                widened += 1;
            }
        }
        if k >= 50 {
            assert_eq!(
                out.guard_state,
                GuardState::Ok,
                "cycle {k}: {:?}",
                out.guard_reason
            );
            if let sar_estimator::cycle::TipOutcome::Estimate(e) = out.tip {
                largest_n = largest_n.max(e.force_n.norm());
            }
            if truth.joint_accels_mps2.iter().any(|a| a.abs() >= 2.0) {
                moving += 1;
            }
        }
    }
    eprintln!(
        "fast move: largest |F_tip| compensated {largest_n:.2} N (noise only), \
         uncompensated {largest_still_n:.2} N"
    );
    assert!(largest_n < 3.0, "{largest_n}");
    // The torque check's deviation grew by the torsion's in motion.
    assert!(widened > 20, "{widened}");
    assert!(largest_still_n > 4.0, "{largest_still_n}");
    assert!(moving > 20, "{moving} samples at 2 m/s^2");
}

/// Issue 34 item 4: ideal drives streaming set points step their velocity
/// at each one (and stop dead when none follows); the sensor sees those
/// impulses' mean over its period (2 ms here): at every instant, before
/// the commands there, the accelerations are (v(t) - v(t - period)) /
/// period of the velocities the axes had then (point-sampled they would
/// be 0 throughout), and every sample the sensor sends reads the truth of
/// its instant.
#[test]
fn ideal_drives_show_the_sensor_their_velocity_steps_over_its_period() {
    let mut rig = Rig::new(moving_spec(0.0, inertia(0.03, 0.0, 0.2)));
    rig.drives.enable().unwrap();
    let mut q = axes(&rig.truth().joints);
    let (mut speeds, mut accels, mut readings) = (Vec::new(), Vec::new(), Vec::new());
    let mut samples = 0;
    // 300 set points of a varying speed, then 10 ms without.
    for k in 0..310u64 {
        rig.run_until(k * MS);
        let t = rig.truth();
        speeds.push(t.joint_speeds_mps);
        accels.push(t.joint_accels_mps2);
        readings.push(t.reading_n);
        if let Some(s) = rig.sensor.poll().unwrap() {
            let at_ms = 2 * s.counter as usize;
            assert!((s.force_n - readings[at_ms]).amax() < 1e-9, "{at_ms}");
            samples += 1;
        }
        if k < 300 {
            let v_mps = 0.05 * (k as f64 / 20.0).sin();
            q[2] += v_mps * 1e-3;
            q[1] -= 0.5 * v_mps * 1e-3;
            rig.drives.stream(joints(q), MS).unwrap();
        }
    }
    assert!(samples >= 150, "{samples}");
    let mut largest = 0.0f64;
    for k in 2..speeds.len() {
        for axis in 0..3 {
            let mean = (speeds[k][axis] - speeds[k - 2][axis]) / 2e-3;
            assert!((accels[k][axis] - mean).abs() < 1e-9, "{k} {axis}");
            largest = largest.max(mean.abs());
        }
    }
    // The velocity stepping at the set points is seen (up to 0.05 / 20 /
    // 1 ms = 2.5 m/s^2), and so is the stop after the last one.
    assert!(largest > 2.0, "{largest}");
    assert!(accels[301][2].abs() > 1.0, "{:?}", accels[301]);
}
