//! The relations between keys, checked in one place after every key's own
//! range (`crate::decl`): a value within its range can still be wrong
//! against another key (a centre of mass beyond the rod's tip, a force
//! limit the sensor saturates before, a planned speed the plausibility
//! check would call an encoder jump), and some keys only make sense
//! together. The README's table names each relation in its "also" column.
//! The relations the domain types check themselves (warn below stop, a
//! stable force law, ...) stay theirs; the support's reach from the travel
//! needs the built geometry ([`check_reach`]).

use crate::ConfigError;
use crate::keys::{File, axes, drivers_axes, guard, identify, manipulator, plausibility, sensor};
use crate::toml_file::{Ctx, num};
use sar_kinematics::{Calibration, Profile, Vec3};

/// Every relation, in the file's order.
pub(crate) fn check(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    rod(ctx, f)?;
    noise_within_range(ctx, f)?;
    limits_within_range(ctx, f)?;
    travel(ctx, f)?;
    speeds(ctx, f)?;
    decelerations(ctx, f)?;
    given_together(ctx, f)
}

/// Refuses `v` (at `key`) above `bound` (in `unit`; what `bound` is: `what`).
fn at_most(
    ctx: &Ctx<'_>,
    key: &str,
    v: f64,
    (bound, unit): (f64, &str),
    what: &str,
) -> Result<(), ConfigError> {
    if v <= bound {
        Ok(())
    } else {
        Err(ctx.err(
            key,
            format!(
                "must be at most {what}, {} {unit}, got {} {unit}",
                num(bound),
                num(v)
            ),
        ))
    }
}

/// The centre of mass on the rod.
fn rod(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let (m, k) = (&f.manipulator, &manipulator::KEY);
    let what = format!("{} (the centre of mass is on the rod)", k.length_m.key);
    at_most(ctx, k.com_m.key, m.com_m, (m.length_m, "m"), &what)
}

/// Refuses a noise component (`(key, values)`) above a tenth of the range's
/// (`(key, values)`) on its axis, in `unit`.
fn tenth_of_range(
    ctx: &Ctx<'_>,
    (noise_key, noise): (&str, &[f64; 3]),
    (range_key, range): (&str, &[f64; 3]),
    unit: &str,
) -> Result<(), ConfigError> {
    for (i, (noise, range)) in noise.iter().zip(range).enumerate() {
        at_most(
            ctx,
            &format!("{noise_key}[{i}]"),
            *noise,
            (range / 10.0, unit),
            &format!("a tenth of {range_key}[{i}]"),
        )?;
    }
    Ok(())
}

/// The sensor's noise, and the torque check's, at most a tenth of the
/// sensor's range.
fn noise_within_range(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let (s, k) = (&f.sensor, &sensor::KEY);
    tenth_of_range(
        ctx,
        (k.noise_n.key, &s.noise_n),
        (k.range_n.key, &s.range_n),
        "N",
    )?;
    let torque = (
        plausibility::KEY.torque_noise_nm.key,
        &f.plausibility.torque_noise_nm,
    );
    tenth_of_range(ctx, torque, (k.range_nm.key, &s.range_nm), "N m")
}

/// Each force limit given, at most the sensor's smallest force range (the
/// sensor would saturate before the limit).
fn limits_within_range(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let (g, k) = (&f.guard, &guard::KEY);
    let smallest_range_n = f
        .sensor
        .range_n
        .iter()
        .fold(f64::INFINITY, |a, b| a.min(*b));
    let limits = [
        (&k.warn_total_n, Some(g.warn_total_n)),
        (&k.stop_total_n, Some(g.stop_total_n)),
        (&k.warn_axial_n, Some(g.warn_axial_n)),
        (&k.stop_axial_n, Some(g.stop_axial_n)),
        (&k.warn_lateral_n, Some(g.warn_lateral_n)),
        (&k.stop_lateral_n, Some(g.stop_lateral_n)),
        (&k.max_stop_total_n, g.max_stop_total_n),
        (&k.max_stop_axial_n, g.max_stop_axial_n),
        (&k.max_stop_lateral_n, g.max_stop_lateral_n),
    ];
    let what = format!(
        "the sensor's smallest force range ({}; the sensor would saturate before the limit)",
        sensor::KEY.range_n.key
    );
    for (d, v) in limits {
        if let Some(v) = v {
            at_most(ctx, d.key, v, (smallest_range_n, "N"), &what)?;
        }
    }
    Ok(())
}

/// Each axis's travel: min below max.
fn travel(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    for (i, [lo, hi]) in f.axes.travel_m.iter().enumerate() {
        if lo >= hi {
            return Err(ctx.err(
                &format!("{}[{i}]", axes::KEY.travel_m.key),
                format!("min must be below max, got [{lo}, {hi}]"),
            ));
        }
    }
    Ok(())
}

/// The planned moves at most the speed the plausibility check allows, the
/// retreat at most the planned moves' speed, the excitation below the
/// plausibility check's speed and at most the planned moves' (the drives'
/// streamed limit).
fn speeds(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let (a, k) = (&f.axes, &axes::KEY);
    let joint_key = plausibility::KEY.max_joint_speed_mps.key;
    let max_joint_speed_mps = f.plausibility.max_joint_speed_mps;
    let speed = a.max_speed_mps;
    if speed > max_joint_speed_mps {
        return Err(ctx.err(
            k.max_speed_mps.key,
            format!("must be at most {joint_key} ({max_joint_speed_mps} m/s), got {speed}"),
        ));
    }
    let retreat = a.retreat_speed_mps;
    if retreat > speed {
        return Err(ctx.err(
            k.retreat_speed_mps.key,
            format!(
                "must be at most {} ({speed} m/s), got {retreat}",
                k.max_speed_mps.key
            ),
        ));
    }
    let excitation_key = identify::KEY.excitation_max_speed_mps.key;
    let excitation = f.identify.excitation_max_speed_mps;
    if excitation >= max_joint_speed_mps {
        return Err(ctx.err(
            excitation_key,
            format!(
                "{excitation} m/s must be below {joint_key} ({max_joint_speed_mps} m/s), whose check faults faster joints"
            ),
        ));
    }
    if excitation > speed {
        let axes_key = k.max_speed_mps.key;
        return Err(ctx.err(
            excitation_key,
            format!(
                "{excitation} m/s is above {axes_key} ({speed} m/s): the drives refuse a streamed set point faster than that, so `sarctl identify --dynamic --live` would be refused; lower it or raise {axes_key}"
            ),
        ));
    }
    Ok(())
}

/// The drives' quick stop brakes at least as hard as the planned moves
/// accelerate; a guarded move's brake lies between the two.
fn decelerations(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let accel_key = axes::KEY.max_accel_mps2.in_section();
    let accel = f.axes.max_accel_mps2;
    let quick_key = &drivers_axes::KEY.quick_stop_decel_mps2;
    let quick = f.drivers_axes.quick_stop_decel_mps2;
    if quick < accel {
        return Err(ctx.err(
            quick_key.key,
            format!(
                "must be at least {accel_key} ({} m/s^2), got {}",
                num(accel),
                num(quick)
            ),
        ));
    }
    if let Some(brake) = f.axes.brake_decel_mps2
        && !(accel..=quick).contains(&brake)
    {
        return Err(ctx.err(
            axes::KEY.brake_decel_mps2.key,
            format!(
                "must be at least {accel_key} ({} m/s^2) and at most {} ({} m/s^2), got {}",
                num(accel),
                quick_key.in_section(),
                num(quick),
                num(brake)
            ),
        ));
    }
    Ok(())
}

/// Keys that only make sense with another: I_perp's standard deviation
/// without I_perp (the default m L^2 / 12 has its own), a frozen-sensor
/// count with the check off.
fn given_together(ctx: &Ctx<'_>, f: &File) -> Result<(), ConfigError> {
    let m = &manipulator::KEY;
    if f.manipulator.inertia_perp_std_kgm2.is_some() && f.manipulator.inertia_perp_kgm2.is_none() {
        return Err(ctx.err(
            m.inertia_perp_std_kgm2.key,
            format!(
                "given without {} (the default m L^2 / 12 has its own)",
                m.inertia_perp_kgm2.key
            ),
        ));
    }
    let p = &plausibility::KEY;
    if !f.plausibility.frozen_check && f.plausibility.frozen_repeats.is_some() {
        return Err(ctx.err(
            p.frozen_repeats.key,
            format!("given while {} = false", p.frozen_check.key),
        ));
    }
    Ok(())
}

/// The support must be reachable: some U-joint position A within the travel
/// must be closer to B than the rod's length (the rod goes through B with
/// its tip beyond it), and not at B itself.
pub(crate) fn check_reach(
    ctx: &Ctx<'_>,
    cal: &Calibration,
    profile: &Profile,
    travel_m: &[(f64, f64); 3],
) -> Result<(), ConfigError> {
    // A = P_home + (q3, q2, q1) + a_off: a box in {0}.
    let base = cal.p_home_m() + cal.ujoint_offset_m();
    let (lo, hi) = (
        base + Vec3::new(travel_m[2].0, travel_m[1].0, travel_m[0].0),
        base + Vec3::new(travel_m[2].1, travel_m[1].1, travel_m[0].1),
    );
    let b = cal.support_m();
    let nearest = Vec3::new(
        b.x.clamp(lo.x, hi.x),
        b.y.clamp(lo.y, hi.y),
        b.z.clamp(lo.z, hi.z),
    );
    let distance_m = (b - nearest).norm();
    if distance_m >= profile.length_m() {
        return Err(ctx.err(
            crate::keys::geometry::KEY.support.key,
            format!(
                "the carriage cannot reach the support: it is at least {distance_m:.4} m from \
                 every U-joint position in {}, the rod is {:.4} m long",
                axes::KEY.travel_m.key,
                profile.length_m()
            ),
        ));
    }
    Ok(())
}
