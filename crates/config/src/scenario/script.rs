//! The motion script: each `[[motion]]` target and the `[random_motion]`
//! ones resolved to active joints, each checked inside the travel and in the
//! kinematics, and the path between them checked too (each axis on its own
//! trapezoid, as the simulator's move), with the planned slide of the rod.

use super::raw::{MotionToml, RandomMotionToml};
use super::{
    ConfigError, MotionStep, PATH_CHECK_INTERVAL_S, PATH_CHECK_MAX_POINTS, PATH_CHECK_POINTS,
    VERTICAL_CLEARANCE_M,
};
use crate::toml_file::Ctx;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sar_hal::Vec3;
use sar_hal::motion::{SlideTracker, axis_progress_m, move_time_s};
use sar_kinematics::{
    ActiveJoints, Calibration, MIN_DISTANCE_M, PoseError, Profile, ShownAll, forward, inverse,
};

/// The motion part of a file.
pub(super) struct MotionFile<'a> {
    /// `[[motion]]`.
    pub motion: &'a [MotionToml],
    /// `[random_motion]`.
    pub random: Option<&'a RandomMotionToml>,
    /// The file's seed (the random targets' stream is drawn from it).
    pub seed: u64,
    /// `axes.start`.
    pub start: Option<[f64; 3]>,
    /// (speed, acceleration) limits of each axis, m/s and m/s^2.
    pub limits: (f64, f64),
}

/// The steps of the script in order (`[[motion]]`, then `[random_motion]`)
/// and where the axes start, every target and every path checked.
pub(super) fn steps(
    ctx: &Ctx<'_>,
    machine: &Machine,
    file: &MotionFile<'_>,
) -> Result<(ActiveJoints, Vec<MotionStep>), ConfigError> {
    let mut targets: Vec<(String, ActiveJoints, u64)> = Vec::new();
    for (i, step) in file.motion.iter().enumerate() {
        let key = format!("motion[{i}]");
        let (target_key, q) = resolve_step(ctx, machine, &key, step)?;
        machine.check_pose(ctx, &target_key, &q)?;
        let hold_ns = ctx.time_ns(&format!("{key}.hold_s"), step.hold_s.unwrap_or(0.0))?;
        targets.push((key, q, hold_ns));
    }
    if let Some(random) = file.random {
        targets.extend(random_steps(ctx, machine, random, file.seed)?);
    }
    if targets.is_empty() {
        return Err(ctx.err(
            "motion",
            "the script has no steps: give at least one [[motion]] or a [random_motion]",
        ));
    }
    let start = match file.start {
        Some(q) => {
            let q = joints_from_array(q);
            machine.check_pose(ctx, "axes.start", &q)?;
            q
        }
        None => targets.first().map(|t| t.1).unwrap_or_default(),
    };
    let mut steps = Vec::with_capacity(targets.len());
    let mut from = start;
    let mut tracker = SlideTracker::new(&machine.calibration);
    tracker.update(&start);
    for (key, target, hold_ns) in targets {
        machine.check_path(ctx, &key, &from, &target, file.limits, &mut tracker)?;
        steps.push(MotionStep {
            key,
            target,
            hold_ns,
            planned_slide_sign: tracker.sign(),
        });
        from = target;
    }
    Ok((start, steps))
}

/// The active joints that put A at `ujoint_m`.
fn joints_for_ujoint(cal: &Calibration, ujoint_m: &Vec3) -> ActiveJoints {
    joints_from_displacement(&(ujoint_m - cal.ujoint_offset_m() - cal.p_home_m()))
}

/// The geometry a script is checked against.
pub(super) struct Machine {
    pub calibration: Calibration,
    pub profile: Profile,
    pub travel_m: [(f64, f64); 3],
}

impl Machine {
    /// Checks that `q` is inside the travel and a pose the kinematics accepts.
    pub fn check_pose(
        &self,
        ctx: &Ctx<'_>,
        key: &str,
        q: &ActiveJoints,
    ) -> Result<(), ConfigError> {
        let values = joints_to_array(q);
        for ((name, value), (min, max)) in ["q1", "q2", "q3"].iter().zip(values).zip(self.travel_m)
        {
            if !(min..=max).contains(&value) {
                return Err(ctx.err(
                    key,
                    format!(
                        "{name} = {value:.6} m is outside the travel {min}..{max} m of that axis"
                    ),
                ));
            }
        }
        forward(&self.calibration, &self.profile, q)
            .map(|_| ())
            .map_err(|e| ctx.err(key, format!("the kinematics refuses this pose: {e}")))
    }

    /// Checks the path from `from` to `to`, each axis on its own trapezoid,
    /// and follows the slide of the rod along it. The kinematics checks the
    /// path at [`PATH_CHECK_POINTS`] instants at least, [`PATH_CHECK_INTERVAL_S`]
    /// apart at most (up to [`PATH_CHECK_MAX_POINTS`]); the conditions that hold
    /// at single points (the U-joint at the support or within the rod offset of
    /// it, a vertical rod) are checked on the chords between those instants too.
    pub fn check_path(
        &self,
        ctx: &Ctx<'_>,
        key: &str,
        from: &ActiveJoints,
        to: &ActiveJoints,
        limits: (f64, f64),
        tracker: &mut SlideTracker,
    ) -> Result<(), ConfigError> {
        let (max_speed_mps, max_accel_mps2) = limits;
        let start = from.displacement_m();
        let delta = to.displacement_m() - start;
        let total_s = move_time_s(from, to, max_speed_mps, max_accel_mps2);
        let points = (total_s / PATH_CHECK_INTERVAL_S).ceil().clamp(
            f64::from(PATH_CHECK_POINTS),
            f64::from(PATH_CHECK_MAX_POINTS),
        ) as u32;
        let b = self.calibration.support_m();
        let a_at_zero = self.calibration.p_home_m() + self.calibration.ujoint_offset_m();
        let min_distance_m = self.profile.offset_m().abs() + MIN_DISTANCE_M;
        let mut previous_a = a_at_zero + start;
        for k in 1..=points {
            let t_s = total_s * f64::from(k) / f64::from(points);
            let progress = |d: f64| axis_progress_m(d, max_speed_mps, max_accel_mps2, t_s);
            let p = start + Vec3::new(progress(delta.x), progress(delta.y), progress(delta.z));
            let a = a_at_zero + p;
            let percent = t_s / total_s * 100.0;
            let distance_m = distance_to_segment(&b, &previous_a, &a);
            if distance_m <= min_distance_m {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position takes the U-joint {distance_m:.2e} m \
                         from the support (around {percent:.0} % of the move's time), a pose the \
                         kinematics refuses"
                    ),
                ));
            }
            let flat = |v: Vec3| Vec3::new(v.x, 0.0, v.z);
            let horizontal_m = distance_to_segment(&flat(b), &flat(previous_a), &flat(a));
            if horizontal_m <= VERTICAL_CLEARANCE_M {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position puts the rod vertical (the U-joint \
                         passes {horizontal_m:.2e} m from the vertical through the support, \
                         around {percent:.0} % of the move's time), a pose the kinematics refuses"
                    ),
                ));
            }
            previous_a = a;
            let q = joints_from_displacement(&p);
            if k < points
                && let Err(e) = forward(&self.calibration, &self.profile, &q)
            {
                return Err(ctx.err(
                    key,
                    format!(
                        "the path from the previous position crosses a pose the kinematics \
                         refuses ({percent:.0} % of the move's time): {e}"
                    ),
                ));
            }
            tracker.update(&q);
        }
        Ok(())
    }
}

/// Distance from `p` to the segment from `a` to `b`.
fn distance_to_segment(p: &Vec3, a: &Vec3, b: &Vec3) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).norm()
}

/// The target of one `[[motion]]` step as active joints, with the key of the
/// target that the file gave.
fn resolve_step(
    ctx: &Ctx<'_>,
    machine: &Machine,
    key: &str,
    step: &MotionToml,
) -> Result<(String, ActiveJoints), ConfigError> {
    check_one_target(ctx, key, step)?;
    let cal = &machine.calibration;
    if let Some(q) = step.joints {
        return Ok((format!("{key}.joints"), joints_from_array(q)));
    }
    if let Some(a) = step.ujoint {
        return Ok((
            format!("{key}.ujoint"),
            joints_for_ujoint(cal, &Vec3::from(a)),
        ));
    }
    if let Some(d) = step.tip {
        let tip_key = format!("{key}.tip");
        let q = inverse(cal, &machine.profile, &Vec3::from(d)).map_err(|e| {
            ctx.err(
                &tip_key,
                format!("the kinematics cannot put the tip there: {e}"),
            )
        })?;
        return Ok((tip_key, q));
    }
    let dir_key = format!("{key}.rod_dir");
    let q = rod_dir_target(ctx, cal, key, &dir_key, step)?;
    Ok((dir_key, q))
}

/// Refuses a step with no target or several (of joints, ujoint, tip,
/// rod_dir), and a support distance without a rod direction.
fn check_one_target(ctx: &Ctx<'_>, key: &str, step: &MotionToml) -> Result<(), ConfigError> {
    let given: Vec<&str> = [
        ("joints", step.joints.is_some()),
        ("ujoint", step.ujoint.is_some()),
        ("tip", step.tip.is_some()),
        ("rod_dir", step.rod_dir.is_some()),
    ]
    .iter()
    .filter(|(_, present)| *present)
    .map(|(name, _)| *name)
    .collect();
    match given.as_slice() {
        [] => {
            return Err(ctx.err(
                key,
                "no target: give exactly one of joints, ujoint, tip, rod_dir (with \
                 support_distance_m)",
            ));
        }
        [_] => {}
        several => {
            return Err(ctx.err(
                key,
                format!(
                    "{} targets ({}): give exactly one of joints, ujoint, tip, rod_dir",
                    several.len(),
                    several.join(", ")
                ),
            ));
        }
    }
    if step.support_distance_m.is_some() && step.rod_dir.is_none() {
        return Err(ctx.err(
            &format!("{key}.support_distance_m"),
            "only allowed with rod_dir",
        ));
    }
    Ok(())
}

/// The target given as `rod_dir` and `support_distance_m`: the U-joint that
/// far from the support, back along the rod's direction (`dir_key`: where
/// the file gives the direction).
fn rod_dir_target(
    ctx: &Ctx<'_>,
    cal: &Calibration,
    key: &str,
    dir_key: &str,
    step: &MotionToml,
) -> Result<ActiveJoints, ConfigError> {
    let u = Vec3::from(step.rod_dir.unwrap_or_default());
    let norm = u.norm();
    if norm < 1e-9 {
        return Err(ctx.err(dir_key, "must not be the zero vector"));
    }
    let Some(a) = step.support_distance_m else {
        return Err(ctx.err(
            &format!("{key}.support_distance_m"),
            "missing key (rod_dir needs it)",
        ));
    };
    ctx.positive(&format!("{key}.support_distance_m"), a, "m")?;
    let ujoint_m = cal.support_m() - u * (a / norm);
    Ok(joints_for_ujoint(cal, &ujoint_m))
}

/// Stream of the random motion: the seed mixed with a constant, so that it
/// differs from the simulator's noise streams made from the same seed.
const RANDOM_MOTION_STREAM: u64 = 0x6d6f_7469_6f6e_0001;

/// The `[random_motion]` steps: tip targets with the rod within
/// `max_angle_deg` of +X0 (uniform over the cap) and the tip `beyond_m` past
/// the support.
fn random_steps(
    ctx: &Ctx<'_>,
    machine: &Machine,
    random: &RandomMotionToml,
    seed: u64,
) -> Result<Vec<(String, ActiveJoints, u64)>, ConfigError> {
    if random.count == 0 || random.count > 10_000 {
        return Err(ctx.err(
            "random_motion.count",
            format!("must be in 1..=10000, got {}", random.count),
        ));
    }
    if !(0.0..=80.0).contains(&random.max_angle_deg) {
        return Err(ctx.err(
            "random_motion.max_angle_deg",
            format!("must be in 0..=80 deg, got {}", random.max_angle_deg),
        ));
    }
    let [min_m, max_m] = random.beyond_m;
    let length_m = machine.profile.length_m();
    if !(min_m > 0.0 && min_m <= max_m && max_m < length_m) {
        return Err(ctx.err(
            "random_motion.beyond_m",
            format!("must satisfy 0 < min <= max < L = {length_m} m, got [{min_m}, {max_m}] m"),
        ));
    }
    let hold_ns = ctx.time_ns("random_motion.hold_s", random.hold_s)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ RANDOM_MOTION_STREAM);
    let cos_max = random.max_angle_deg.to_radians().cos();
    let mut steps = Vec::new();
    for i in 0..random.count {
        let key = format!("random_motion[{i}]");
        // Uniform over the spherical cap: cos(theta) uniform in [cos_max, 1].
        let cos_theta = 1.0 - rng.random::<f64>() * (1.0 - cos_max);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = rng.random::<f64>() * std::f64::consts::TAU;
        let beyond = min_m + rng.random::<f64>() * (max_m - min_m);
        let u = Vec3::new(cos_theta, sin_theta * phi.cos(), sin_theta * phi.sin());
        let tip_m = machine.calibration.support_m() + u * beyond;
        let q =
            inverse(&machine.calibration, &machine.profile, &tip_m).map_err(|e: PoseError| {
                ctx.err(
                    &key,
                    format!(
                        "the kinematics cannot reach tip {} m: {e}",
                        ShownAll(tip_m.as_slice())
                    ),
                )
            })?;
        machine.check_pose(ctx, &key, &q)?;
        steps.push((key, q, hold_ns));
    }
    Ok(steps)
}

/// The active joints from `[q1, q2, q3]`, m (the order of arrays indexed by axis).
fn joints_from_array(q_m: [f64; 3]) -> ActiveJoints {
    let [q1_m, q2_m, q3_m] = q_m;
    ActiveJoints { q1_m, q2_m, q3_m }
}

/// The active joints as `[q1, q2, q3]`, m.
fn joints_to_array(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}

/// The active joints whose displacement (q3, q2, q1), in base X, Y, Z order,
/// is `displacement_m` (the inverse of [`ActiveJoints::displacement_m`]).
fn joints_from_displacement(displacement_m: &Vec3) -> ActiveJoints {
    ActiveJoints {
        q1_m: displacement_m.z,
        q2_m: displacement_m.y,
        q3_m: displacement_m.x,
    }
}
