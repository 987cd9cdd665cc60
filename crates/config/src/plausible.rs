//! The plausible range of every physical key of the configuration (issue
//! 25): a value the checks of the estimator and the kinematics accept can
//! still be a unit mistake (`length_m = 35.0` for 0.35 put the tip 34.8 m
//! past the support and blinded the lateral guard) or no number a robot can
//! have (`mass_kg = 1e308`). [`PLAUSIBLE`] states each range (the README's
//! configuration part and the crate docs show the same table); [`check`]
//! refuses a value outside it, naming the key, its line, the range and, when
//! the value divided by a common factor falls within it, the likely unit
//! ("a value in cm?"). The relations between keys (the centre of mass
//! within the rod, the noise against the sensor's range, the force limits
//! against the sensor's range) are checked here too.

use crate::toml_file::{Ctx, num};
use crate::{ConfigError, FileToml};

/// What a range bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Applies {
    /// The value.
    Value,
    /// Each component of an array (each bound of each axis for
    /// `axes.travel_m`).
    EachComponent,
    /// The vector's magnitude.
    Magnitude,
}

/// A physical key's plausible range (both bounds included).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plausible {
    /// The dotted key.
    pub key: &'static str,
    /// The smallest plausible value.
    pub lo: f64,
    /// The largest plausible value.
    pub hi: f64,
    /// The unit, as the key's name says it.
    pub unit: &'static str,
    /// What the range bounds.
    pub applies: Applies,
    /// What else bounds the key ("" when nothing).
    pub also: &'static str,
}

const fn row(key: &'static str, lo: f64, hi: f64, unit: &'static str) -> Plausible {
    Plausible {
        key,
        lo,
        hi,
        unit,
        applies: Applies::Value,
        also: "",
    }
}

const fn each(key: &'static str, lo: f64, hi: f64, unit: &'static str) -> Plausible {
    Plausible {
        applies: Applies::EachComponent,
        ..row(key, lo, hi, unit)
    }
}

const fn also(p: Plausible, also: &'static str) -> Plausible {
    Plausible { also, ..p }
}

/// The sensor's smallest force range bounds every force limit.
const BELOW_RANGE: &str = "at most the smallest of sensor.range_n";

/// The plausible ranges, in the file's order. The README's table of them is
/// checked against this one (`crates/config/tests/config.rs`).
pub const PLAUSIBLE: &[Plausible] = &[
    Plausible {
        applies: Applies::Magnitude,
        ..row("geometry.gravity", 9.7, 9.9, "m/s^2")
    },
    also(
        each("geometry.support", -2.0, 2.0, "m"),
        "closer than length_m to the U-joint's travel (axes.travel_m)",
    ),
    each("geometry.p_home", -2.0, 2.0, "m"),
    each("geometry.ujoint_offset", -0.5, 0.5, "m"),
    each("geometry.sensor_offset", -0.5, 0.5, "m"),
    row("manipulator.length_m", 0.1, 1.5, "m"),
    also(
        row("manipulator.offset_m", -0.1, 0.1, "m"),
        "below length_m in magnitude",
    ),
    row("manipulator.mass_kg", 0.0, 10.0, "kg"),
    also(
        row("manipulator.com_m", 0.0, 1.5, "m"),
        "at most length_m (within the rod)",
    ),
    row("manipulator.inertia_perp_kgm2", 0.0, 2.0, "kg m^2"),
    row("manipulator.inertia_perp_std_kgm2", 0.0, 2.0, "kg m^2"),
    row("manipulator.inertia_axial_kgm2", 0.0, 0.1, "kg m^2"),
    also(
        each("sensor.noise_n", 1e-4, 10.0, "N"),
        "at most a tenth of sensor.range_n",
    ),
    each("sensor.range_n", 1.0, 10_000.0, "N"),
    each("sensor.range_nm", 0.01, 1000.0, "N m"),
    row("sensor.adapter_mass_kg", 0.0, 5.0, "kg"),
    also(row("guard.warn_total_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.stop_total_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.warn_axial_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.stop_axial_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.warn_lateral_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.stop_lateral_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.max_stop_total_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(row("guard.max_stop_axial_n", 0.1, 100.0, "N"), BELOW_RANGE),
    also(
        row("guard.max_stop_lateral_n", 0.1, 100.0, "N"),
        BELOW_RANGE,
    ),
    row("guard.hysteresis_n", 0.0, 10.0, "N"),
    row("guard.max_sensor_age_s", 1e-4, 1.0, "s"),
    row("guard.max_joints_age_s", 1e-4, 1.0, "s"),
    row("guard.retreat_rise_n", 0.0, 100.0, "N"),
    row("plausibility.max_joint_speed_mps", 1e-3, 1.0, "m/s"),
    row("plausibility.joint_margin_m", 0.0, 0.01, "m"),
    also(
        each("plausibility.torque_noise_nm", 1e-5, 1.0, "N m"),
        "at most a tenth of sensor.range_nm",
    ),
    row("tip.max_std_n", 1e-3, 20.0, "N"),
    each("axes.travel_m", -2.0, 2.0, "m"),
    row("axes.max_speed_mps", 1e-4, 1.0, "m/s"),
    row("axes.retreat_speed_mps", 1e-5, 1.0, "m/s"),
    row("axes.servo_bandwidth_hz", 0.0, 300.0, "Hz"),
    row("axes.servo_damping", 0.1, 2.0, "(ratio)"),
    row("force_control.axial_damping_n_s_per_m", 1.0, 1e5, "N s/m"),
    row("force_control.axial_mass_kg", 1e-3, 100.0, "kg"),
    row("force_control.lateral_damping_n_s_per_m", 1.0, 1e5, "N s/m"),
    row("force_control.lateral_mass_kg", 1e-3, 100.0, "kg"),
    row("force_control.hold_return_n_per_m", 0.0, 1e5, "N/m"),
    row("force_control.max_speed_mps", 1e-5, 0.1, "m/s"),
    row("force_control.max_accel_mps2", 1e-4, 10.0, "m/s^2"),
    row("force_control.max_excursion_m", 1e-4, 0.2, "m"),
    row("force_control.other_delay_s", 0.0, 1.0, "s"),
    row("force_control.max_stiffness_n_per_m", 1.0, 1e6, "N/m"),
    row("drivers.sensor.counts_per_n", 1.0, 1e9, "counts/N"),
    row("drivers.sensor.counts_per_nm", 1.0, 1e9, "counts/(N m)"),
];

/// The range of `key` (every key [`check`] names has one: a missing row is
/// refused as a bug, never skipped).
fn range_of<'p>(ctx: &Ctx<'_>, key: &str) -> Result<&'p Plausible, ConfigError> {
    PLAUSIBLE
        .iter()
        .find(|p| p.key == key)
        .ok_or_else(|| ctx.err(key, "no plausible range is defined for this key (a bug)"))
}

/// The smaller units a value of `unit` is often written in by mistake, with
/// their size in `unit`.
fn smaller_units(unit: &str) -> &'static [(&'static str, f64)] {
    match unit {
        "m" => &[("cm", 0.01), ("mm", 0.001)],
        "kg" => &[("g", 0.001)],
        "N" => &[("mN", 0.001)],
        "N m" => &[("N mm", 0.001)],
        "m/s" => &[("mm/s", 0.001)],
        "m/s^2" => &[("cm/s^2", 0.01), ("mm/s^2", 0.001), ("g", 9.80665)],
        "s" => &[("ms", 0.001)],
        _ => &[],
    }
}

/// " (a value in cm? 35 cm is 0.35 m)" when `v` in a smaller unit lands in
/// `lo..=hi`, else "".
fn unit_hint(v: f64, lo: f64, hi: f64, unit: &str) -> String {
    smaller_units(unit)
        .iter()
        .find(|(_, size)| (lo..=hi).contains(&(v * size)) && v != 0.0)
        .map(|(name, size)| {
            format!(
                " (a value in {name}? {} {name} is {} {unit})",
                num(v),
                // Rounded to 1e-9: "0.35", not "0.35000000000000003".
                num((v * size * 1e9).round() / 1e9)
            )
        })
        .unwrap_or_default()
}

/// Refuses `v` (at `key`, a component's key for an array) outside `p`.
fn within(ctx: &Ctx<'_>, p: &Plausible, key: &str, v: f64) -> Result<(), ConfigError> {
    if (p.lo..=p.hi).contains(&v) {
        return Ok(());
    }
    let what = match p.applies {
        Applies::Magnitude => "its magnitude must be",
        _ => "must be",
    };
    Err(ctx.err(
        key,
        format!(
            "{what} within {}..={} {}, got {}{}",
            num(p.lo),
            num(p.hi),
            p.unit,
            num(v),
            unit_hint(v, p.lo, p.hi, p.unit)
        ),
    ))
}

fn value(ctx: &Ctx<'_>, key: &str, v: f64) -> Result<(), ConfigError> {
    within(ctx, range_of(ctx, key)?, key, v)
}

fn components(ctx: &Ctx<'_>, key: &str, v: &[f64]) -> Result<(), ConfigError> {
    let p = range_of(ctx, key)?;
    for (i, x) in v.iter().enumerate() {
        within(ctx, p, &format!("{key}[{i}]"), *x)?;
    }
    Ok(())
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

/// Every key of [`PLAUSIBLE`] the file gives (or defaults), in the file's
/// order, then the relations between keys.
pub(crate) fn check(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    check_geometry(ctx, f)?;
    check_manipulator(ctx, f)?;
    check_sensor(ctx, f)?;
    check_guard(ctx, f)?;
    check_plausibility(ctx, f)?;
    check_tip_and_axes(ctx, f)?;
    check_force_control(ctx, f)?;
    check_drivers(ctx, f)
}

/// `[geometry]`: |gravity| and each component of the points.
fn check_geometry(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let g = &f.geometry;
    let gravity_mps2 = g.gravity.iter().map(|x| x * x).sum::<f64>().sqrt();
    value(ctx, "geometry.gravity", gravity_mps2)?;
    components(ctx, "geometry.support", &g.support)?;
    components(ctx, "geometry.p_home", &g.p_home)?;
    components(ctx, "geometry.ujoint_offset", &g.ujoint_offset)?;
    components(ctx, "geometry.sensor_offset", &g.sensor_offset)?;
    Ok(())
}

/// `[manipulator]`, with the centre of mass on the rod.
fn check_manipulator(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let m = &f.manipulator;
    value(ctx, "manipulator.length_m", m.length_m)?;
    value(ctx, "manipulator.offset_m", m.offset_m)?;
    value(ctx, "manipulator.mass_kg", m.mass_kg)?;
    value(ctx, "manipulator.com_m", m.com_m)?;
    at_most(
        ctx,
        "manipulator.com_m",
        m.com_m,
        (m.length_m, "m"),
        "manipulator.length_m (the centre of mass is on the rod)",
    )?;
    for (key, v) in [
        ("manipulator.inertia_perp_kgm2", m.inertia_perp_kgm2),
        ("manipulator.inertia_perp_std_kgm2", m.inertia_perp_std_kgm2),
        ("manipulator.inertia_axial_kgm2", m.inertia_axial_kgm2),
    ] {
        if let Some(v) = v {
            value(ctx, key, v)?;
        }
    }
    Ok(())
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

/// `[sensor]`: noise and ranges, the noise at most a tenth of the range.
fn check_sensor(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let s = &f.sensor;
    components(ctx, "sensor.noise_n", &s.noise_n)?;
    components(ctx, "sensor.range_n", &s.range_n)?;
    components(ctx, "sensor.range_nm", &s.range_nm)?;
    if let Some(v) = s.adapter_mass_kg {
        value(ctx, "sensor.adapter_mass_kg", v)?;
    }
    tenth_of_range(
        ctx,
        ("sensor.noise_n", &s.noise_n),
        ("sensor.range_n", &s.range_n),
        "N",
    )
}

/// `[guard]`: each force limit given, at most the sensor's smallest force
/// range (the sensor would saturate before the limit); the other keys.
fn check_guard(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let gt = &f.guard;
    let s = &f.sensor;
    let smallest_range_n = s.range_n.iter().fold(f64::INFINITY, |a, b| a.min(*b));
    let limits = [
        ("guard.warn_total_n", Some(gt.warn_total_n)),
        ("guard.stop_total_n", Some(gt.stop_total_n)),
        ("guard.warn_axial_n", Some(gt.warn_axial_n)),
        ("guard.stop_axial_n", Some(gt.stop_axial_n)),
        ("guard.warn_lateral_n", Some(gt.warn_lateral_n)),
        ("guard.stop_lateral_n", Some(gt.stop_lateral_n)),
        ("guard.max_stop_total_n", gt.max_stop_total_n),
        ("guard.max_stop_axial_n", gt.max_stop_axial_n),
        ("guard.max_stop_lateral_n", gt.max_stop_lateral_n),
    ];
    for (key, v) in limits {
        let Some(v) = v else { continue };
        value(ctx, key, v)?;
        at_most(
            ctx,
            key,
            v,
            (smallest_range_n, "N"),
            "the sensor's smallest force range (sensor.range_n; the sensor would saturate \
             before the limit)",
        )?;
    }
    value(ctx, "guard.hysteresis_n", gt.hysteresis_n)?;
    value(ctx, "guard.max_sensor_age_s", gt.max_sensor_age_s)?;
    value(ctx, "guard.max_joints_age_s", gt.max_joints_age_s)?;
    value(ctx, "guard.retreat_rise_n", gt.retreat_rise_n)?;
    Ok(())
}

/// `[plausibility]`, the torque noise at most a tenth of the torque range.
fn check_plausibility(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let p = &f.plausibility;
    let s = &f.sensor;
    value(
        ctx,
        "plausibility.max_joint_speed_mps",
        p.max_joint_speed_mps,
    )?;
    value(ctx, "plausibility.joint_margin_m", p.joint_margin_m)?;
    components(ctx, "plausibility.torque_noise_nm", &p.torque_noise_nm)?;
    let noise = ("plausibility.torque_noise_nm", &p.torque_noise_nm);
    tenth_of_range(ctx, noise, ("sensor.range_nm", &s.range_nm), "N m")
}

/// `[tip]`'s observability limit; `[axes]`: each bound of each travel, the
/// speeds.
fn check_tip_and_axes(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    value(ctx, "tip.max_std_n", f.tip.max_std_n)?;

    let a = &f.axes;
    let travel = range_of(ctx, "axes.travel_m")?;
    for (i, axis) in a.travel_m.iter().enumerate() {
        for (j, bound) in axis.iter().enumerate() {
            within(ctx, travel, &format!("axes.travel_m[{i}][{j}]"), *bound)?;
        }
    }
    value(ctx, "axes.max_speed_mps", a.max_speed_mps)?;
    value(ctx, "axes.retreat_speed_mps", a.retreat_speed_mps)?;
    value(ctx, "axes.servo_bandwidth_hz", a.servo_bandwidth_hz)?;
    value(ctx, "axes.servo_damping", a.servo_damping)?;
    Ok(())
}

/// `[force_control]`: each setting of the admittance law.
fn check_force_control(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    let fc = &f.force_control;
    for (key, v) in [
        (
            "force_control.axial_damping_n_s_per_m",
            fc.axial_damping_n_s_per_m,
        ),
        ("force_control.axial_mass_kg", fc.axial_mass_kg),
        (
            "force_control.lateral_damping_n_s_per_m",
            fc.lateral_damping_n_s_per_m,
        ),
        ("force_control.lateral_mass_kg", fc.lateral_mass_kg),
        ("force_control.hold_return_n_per_m", fc.hold_return_n_per_m),
        ("force_control.max_speed_mps", fc.max_speed_mps),
        ("force_control.max_accel_mps2", fc.max_accel_mps2),
        ("force_control.max_excursion_m", fc.max_excursion_m),
        ("force_control.other_delay_s", fc.other_delay_s),
        (
            "force_control.max_stiffness_n_per_m",
            fc.max_stiffness_n_per_m,
        ),
    ] {
        value(ctx, key, v)?;
    }
    Ok(())
}

/// `[drivers.sensor]`: the counts per unit, where given.
fn check_drivers(ctx: &Ctx<'_>, f: &FileToml) -> Result<(), ConfigError> {
    if let Some(d) = &f.drivers.sensor {
        for (key, v) in [
            ("drivers.sensor.counts_per_n", d.counts_per_n),
            ("drivers.sensor.counts_per_nm", d.counts_per_nm),
        ] {
            if let Some(v) = v {
                value(ctx, key, v)?;
            }
        }
    }
    Ok(())
}
