//! The pose set of the identification procedure (MODEL.md 5.1), for the
//! robot of a configuration: the cone set (four rod directions on a 35 degree
//! cone around X0, times a in {0.04, 0.07, 0.12, 0.20, 0.30} m, swept
//! alternately outward and inward, each inward sweep entered by a turnaround
//! 20 mm beyond its first pose so that it is reached sliding inward), shrunk
//! until every target lies in the configured travel: first the distances
//! beyond the shortest (0.04 m, kept) by 10 % steps down to half (the tilt,
//! which determines B across the rod, is kept as long as possible), then the
//! cone angle by 5 degrees, down to 10 degrees. A pose is also kept clear of
//! the observability limit: the tip force's standard deviation there (it
//! grows as a/(L - a) as the tip nears the support) at most
//! [`OBSERVABLE_FRACTION`] of `[tip] max_std_n`, or the guard would fault
//! (`not_observable`) while the daemon holds it. `sarctl identify --live`
//! drives the daemon through this set.

use sar_config::Config;
use sar_estimator::tip_force::TipForceEstimator;
use sar_kinematics::{ActiveJoints, Vec3, forward};
use sar_kinematics::{Shown, ShownAll};

/// The cone's half angle of MODEL.md 5.1, degrees.
pub const CONE_DEG: f64 = 35.0;
/// The distances a = |B - A| of MODEL.md 5.1, m.
pub const DISTANCES_M: [f64; 5] = [0.04, 0.07, 0.12, 0.20, 0.30];
/// How far past an inward sweep's first pose its turnaround goes, m.
pub const TURNAROUND_M: f64 = 0.02;
/// The tip stays at least this far past the support, m.
const TIP_MARGIN_M: f64 = 0.01;
/// A pose's tip-force standard deviation, at most this part of `[tip]
/// max_std_n` (the guard faults beyond it; the rest is margin for the
/// noise of a live run).
pub const OBSERVABLE_FRACTION: f64 = 0.5;

/// One target of the procedure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseTarget {
    /// The rod's direction u (unit, from A towards B).
    pub direction: Vec3,
    /// a = |B - A|, m.
    pub support_distance_m: f64,
    /// A, the U-joint centre, {0}, m.
    pub ujoint_m: Vec3,
    /// D, the tip (d = 0: A + L u), {0}, m: the move-tip target.
    pub tip_m: Vec3,
    /// The active joints at A, m.
    pub joints: ActiveJoints,
    /// A turnaround (pass through, do not hold).
    pub turnaround: bool,
}

/// The targets for `angle_deg` and distances scaled by `scale`, or None when
/// one of them is outside the travel or refused by the kinematics.
fn attempt(config: &Config, angle_deg: f64, scale: f64) -> Option<Vec<PoseTarget>> {
    let cal = &config.estimator.calibration;
    let profile = &config.estimator.profile;
    let b = cal.support_m();
    let base = cal.p_home_m() + cal.ujoint_offset_m();
    let (s, c) = angle_deg.to_radians().sin_cos();
    let dirs = [
        Vec3::new(c, s, 0.0),
        Vec3::new(c, 0.0, s),
        Vec3::new(c, -s, 0.0),
        Vec3::new(c, 0.0, -s),
    ];
    let travel = config.axes.travel_m;
    let est = &config.estimator;
    let tip = TipForceEstimator::new(&est.calibration, &est.profile, &est.noise, est.tip).ok()?;
    let zero = Vec3::zeros();
    let target = |u: &Vec3, a: f64, turnaround: bool| -> Option<PoseTarget> {
        if a + TIP_MARGIN_M >= profile.length_m() {
            return None;
        }
        let ujoint = b - u * a;
        let d = ujoint - base;
        let joints = ActiveJoints {
            q1_m: d.z,
            q2_m: d.y,
            q3_m: d.x,
        };
        let inside = [joints.q1_m, joints.q2_m, joints.q3_m]
            .iter()
            .zip(travel)
            .all(|(q, (lo, hi))| (lo..=hi).contains(q));
        let pose = forward(cal, profile, &joints).ok()?;
        let std_n = tip.estimate(&pose, &zero, &zero).ok()?.std_n;
        let observable = std_n.max() <= OBSERVABLE_FRACTION * tip.max_std_n();
        (inside && observable).then_some(PoseTarget {
            direction: *u,
            support_distance_m: a,
            ujoint_m: ujoint,
            tip_m: pose.tip_m,
            joints,
            turnaround,
        })
    };
    let mut out = Vec::new();
    for (k, u) in dirs.iter().enumerate() {
        // The shortest distance stays (most of B's information, MODEL.md
        // 5.1; shorter ones load the sensor with M g / a): the others move
        // towards it.
        let nearest = DISTANCES_M[0];
        let mut sweep: Vec<f64> = DISTANCES_M
            .iter()
            .map(|a| nearest + (a - nearest) * scale)
            .collect();
        let inward = k % 2 == 1;
        if inward {
            sweep.reverse();
            let first = sweep.first().copied()?;
            out.push(target(u, first + TURNAROUND_M, true)?);
        }
        for a in sweep {
            out.push(target(u, a, false)?);
        }
    }
    Some(out)
}

/// The cone set of MODEL.md 5.1 for `config`, shrunk to fit its travel
/// (see the module's doc); the error says why none fits.
pub fn cone_set(config: &Config) -> Result<Vec<PoseTarget>, String> {
    let mut angle = CONE_DEG;
    while angle >= 10.0 {
        let mut scale = 1.0;
        while scale >= 0.5 - 1e-9 {
            if let Some(set) = attempt(config, angle, scale) {
                return Ok(set);
            }
            scale -= 0.1;
        }
        angle -= 5.0;
    }
    Err(format!(
        "no cone set fits the travel {} m around the support {} m (tried cones of 35 to 10 degrees, distances down to half of 0.04..0.30 m)",
        config
            .axes
            .travel_m
            .map(|(lo, hi)| format!("{}..{}", Shown(lo), Shown(hi)))
            .join(", "),
        ShownAll(config.estimator.calibration.support_m().as_slice())
    ))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_robot_gets_the_cone_set_clear_of_the_observability_limit() {
        let config = sar_config::builtin().unwrap();
        let set = cone_set(&config).unwrap();
        let holds: Vec<&PoseTarget> = set.iter().filter(|p| !p.turnaround).collect();
        assert_eq!(holds.len(), 20);
        assert_eq!(set.len(), 22);
        let b = config.estimator.calibration.support_m();
        let l = config.estimator.profile.length_m();
        for p in &set {
            // A on the rod's line through B at distance a; the tip at L from A.
            assert!(((b - p.ujoint_m).norm() - p.support_distance_m).abs() < 1e-12);
            assert!(((p.tip_m - p.ujoint_m).norm() - l).abs() < 1e-9);
            assert!((p.direction.x - CONE_DEG.to_radians().cos()).abs() < 1e-12);
        }
        // Direction 2 is swept inward, entered past its first pose; the far
        // distance shrunk from 0.30 m (the tip 5 cm past the support, where
        // the guard would fault: not observable).
        assert!(set[5].turnaround && set[5].support_distance_m > set[6].support_distance_m);
        assert!(set[6].support_distance_m < 0.30 - 1e-9);
        assert_eq!(set[10].support_distance_m, 0.04);
        let est = &config.estimator;
        let tip =
            TipForceEstimator::new(&est.calibration, &est.profile, &est.noise, est.tip).unwrap();
        for p in &set {
            let pose = forward(&est.calibration, &est.profile, &p.joints).unwrap();
            let std_n = tip
                .estimate(&pose, &Vec3::zeros(), &Vec3::zeros())
                .unwrap()
                .std_n;
            assert!(
                std_n.max() <= OBSERVABLE_FRACTION * tip.max_std_n(),
                "{std_n:?}"
            );
        }
        // Without the bound the far poses would be beyond it.
        let far = ActiveJoints {
            q1_m: 0.0,
            q2_m: 0.28,
            q3_m: 0.45 - 0.30,
        };
        let pose = forward(&est.calibration, &est.profile, &far).unwrap();
        let std_n = tip
            .estimate(&pose, &Vec3::zeros(), &Vec3::zeros())
            .unwrap()
            .std_n;
        assert!(
            std_n.max() > OBSERVABLE_FRACTION * tip.max_std_n(),
            "{std_n:?}"
        );
    }

    #[test]
    fn a_small_travel_shrinks_the_set_or_is_refused() {
        let mut config = sar_config::builtin().unwrap();
        // q2 (height) within 0.1 m of the support's: the 35 degree cone at
        // a = 0.30 needs 0.17 m; with the distances beyond 0.04 m halved
        // (0.17 m at most) it fits.
        config.axes.travel_m[1] = (0.18, 0.38);
        let set = cone_set(&config).unwrap();
        let far = set
            .iter()
            .filter(|p| !p.turnaround)
            .map(|p| p.support_distance_m)
            .fold(0.0, f64::max);
        assert!(far < 0.30 - 1e-9, "distances not shrunk: {far}");
        for p in &set {
            let q2 = p.joints.q2_m;
            assert!((0.18..=0.38).contains(&q2), "q2 {q2}");
        }
        config.axes.travel_m[2] = (0.0, 0.01);
        assert!(cone_set(&config).unwrap_err().contains("no cone set fits"));
    }
}
