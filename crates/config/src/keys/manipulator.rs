//! `[manipulator]`: the rod in use, through the kinematics' own checks, its
//! name (shown by the log and the tools: one line, shown as written) and its
//! inertia (MODEL.md 10) with the adapter's mass of `[sensor]`.

use crate::decl::{num, setting_error, text};
use crate::keys::{File, sensor};
use crate::toml_file::Ctx;
use crate::{Config, ConfigError, MAX_NAME_CHARS, is_format_char};
use sar_estimator::inertia_watch::InertiaWatchConfig;
use sar_estimator::inertial::RodInertia;
use sar_kinematics::{Profile, ProfileSpec};

crate::section! {
    /// The manipulator in use: a straight rod hanging in the U-joint A.
    section "manipulator";
    /// its name, shown by the log, `sarctl status` and the recordings
    name: String = required("manipulator-2"),
        text("one line of at most 100 characters, no control or invisible character")
        => [Config.manipulator_name];
    /// L: from the U-joint A to the tip along the rod, m
    length_m: f64 = required(0.35), num(0.1, 1.5, "m") => [ProfileSpec.length_m];
    /// d: the rod's axis from A, m
    offset_m: f64 = required(0.0),
        num(-0.1, 0.1, "m").also("below length_m in magnitude") => [ProfileSpec.offset_m];
    /// m: the rod's mass, kg (written by `sarctl identify`)
    mass_kg: f64 = required(2.593), num(0.0, 10.0, "kg") => [ProfileSpec.mass_kg];
    /// c: from A to the centre of mass along the rod, m (written by `sarctl identify`)
    com_m: f64 = required(0.103),
        num(0.0, 1.5, "m").also("at most length_m (within the rod)") => [ProfileSpec.com_m];
    /// I_perp about C, across the rod (MODEL.md 10; written by `sarctl identify --dynamic`)
    inertia_perp_kgm2: f64 = absent("m L^2 / 12, a stated default, not a measurement (logged so), 50 % std", 0.0265),
        num(0.0, 2.0, "kg m^2") => [RodInertia.inertia_perp_kgm2];
    /// I_perp's standard deviation
    inertia_perp_std_kgm2: f64 = absent("5 % of a given inertia_perp_kgm2", 0.0013),
        num(0.0, 2.0, "kg m^2").also("only with inertia_perp_kgm2")
        => [RodInertia.inertia_perp_std_kgm2];
    /// I_axial about the rod's axis (matters for d != 0)
    inertia_axial_kgm2: f64 = value(0.0), num(0.0, 0.1, "kg m^2") => [RodInertia.inertia_axial_kgm2];
    /// the inertia watch names I_perp (or the adapter's mass) off by more than this fraction in free motion (issue 34)
    inertia_watch_max_ratio: f64 = value(InertiaWatchConfig::default().max_ratio),
        num(0.01, 10.0, "(ratio)") => [InertiaWatchConfig.max_ratio];
    /// the inertia watch names the adapter's mass only when off by more than this too
    inertia_watch_min_adapter_kg: f64 = value(InertiaWatchConfig::default().min_adapter_kg),
        num(0.0, 5.0, "kg") => [InertiaWatchConfig.min_adapter_kg];
    /// the free motion the inertia watch remembers (its forgetting time constant)
    inertia_watch_window_s: f64 = value(InertiaWatchConfig::default().window_s),
        num(0.5, 600.0, "s") => [InertiaWatchConfig.window_s];
}

/// The inertia watch's limits (`inertia_watch_*`).
pub(crate) fn inertia_watch(m: &Section) -> InertiaWatchConfig {
    InertiaWatchConfig {
        max_ratio: m.inertia_watch_max_ratio,
        min_adapter_kg: m.inertia_watch_min_adapter_kg,
        window_s: m.inertia_watch_window_s,
    }
}

/// The name checked, and the rod through the kinematics' own checks.
pub(crate) fn profile(ctx: &Ctx<'_>, m: &Section) -> Result<Profile, ConfigError> {
    check_name(ctx, &m.name)?;
    Profile::new(&ProfileSpec {
        length_m: m.length_m,
        offset_m: m.offset_m,
        mass_kg: m.mass_kg,
        com_m: m.com_m,
    })
    .map_err(|e| {
        let key = crate::decl::key_of_field(&[KEYS], e.field()).map_or(SECTION, |d| d.key);
        ctx.err(key, e.to_string())
    })
}

/// Shown by `--check-config`, the log and the recordings: one line, shown
/// as written (a control character broke the line; a bidi override such as
/// U+202E reversed how the rest of a log line reads).
fn check_name(ctx: &Ctx<'_>, name: &str) -> Result<(), ConfigError> {
    let key = KEY.name.key;
    if name.trim().is_empty() {
        return Err(ctx.err(key, "must not be empty"));
    }
    let chars = name.chars().count();
    if chars > MAX_NAME_CHARS {
        return Err(ctx.err(
            key,
            format!("must be at most {MAX_NAME_CHARS} characters, got {chars} characters"),
        ));
    }
    if let Some((at, c)) = name.chars().enumerate().find(|(_, c)| c.is_control()) {
        return Err(ctx.err(
            key,
            format!(
                "must not hold a control character, got U+{:04X} at character {}",
                u32::from(c),
                at + 1
            ),
        ));
    }
    if let Some((at, c)) = name.chars().enumerate().find(|(_, c)| is_format_char(*c)) {
        return Err(ctx.err(
            key,
            format!(
                "must not hold an invisible or direction-changing character (it changes how the log and the tools show the text), got U+{:04X} at character {}",
                u32::from(c),
                at + 1
            ),
        ));
    }
    Ok(())
}

/// The rod's inertia and the adapter's mass (`[sensor] adapter_mass_kg`),
/// MODEL.md 10, and whether I_perp was given. Without I_perp: the slender
/// rod's m L^2 / 12 with a 50 % standard deviation (a stated default); I_perp
/// without its standard deviation: 5 % of it (a standard deviation without
/// I_perp is refused by `crate::relations`).
pub(crate) fn inertia(
    ctx: &Ctx<'_>,
    f: &File,
    profile: &Profile,
) -> Result<(RodInertia, bool), ConfigError> {
    let m = &f.manipulator;
    let (perp_kgm2, fraction) = match m.inertia_perp_kgm2 {
        Some(v) => (v, RodInertia::GIVEN_STD_FRACTION),
        None => (
            RodInertia::slender_rod_kgm2(profile),
            RodInertia::SLENDER_ROD_STD_FRACTION,
        ),
    };
    let inertia = RodInertia {
        inertia_perp_kgm2: perp_kgm2,
        inertia_perp_std_kgm2: m.inertia_perp_std_kgm2.unwrap_or(perp_kgm2 * fraction),
        inertia_axial_kgm2: m.inertia_axial_kgm2,
        adapter_mass_kg: f.sensor.adapter_mass_kg,
    };
    inertia
        .check()
        .map_err(|e| setting_error(ctx, &[KEYS, sensor::KEYS], &e))?;
    Ok((inertia, m.inertia_perp_kgm2.is_some()))
}
