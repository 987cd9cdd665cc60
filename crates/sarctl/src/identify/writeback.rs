//! Writes the identified values back into the configuration's text
//! (INTERFACES.md 3): `[manipulator] mass_kg`, `com_m` and `[geometry]
//! support`, with `toml_edit`, so that everything else (comments, key order,
//! spacing, the other values) stays as it was. Each replaced value keeps its
//! own decoration (the comment after it, the spaces around it).

use toml_edit::{DocumentMut, Item, Value};

/// Rounding of the written values: 0.01 g for m, 1 um for c and B (far below
/// their standard errors).
const MASS_STEP_KG: f64 = 1e-5;
const LENGTH_STEP_M: f64 = 1e-6;

fn rounded(x: f64, step: f64) -> f64 {
    let r = (x / step).round() * step;
    // Shortest decimal that reads back as the rounded value.
    format!("{r:.9}").parse().unwrap_or(r)
}

/// Replaces `old` by the float `x`, keeping `old`'s decoration.
fn replace(old: &mut Value, x: f64) {
    let decor = old.decor().clone();
    let mut new = Value::from(x);
    *new.decor_mut() = decor;
    *old = new;
}

/// Sets `table.key` to `x`, keeping the old value's decoration when there is one.
fn set_float(doc: &mut DocumentMut, table: &str, key: &str, x: f64) -> Result<(), String> {
    let t = doc
        .get_mut(table)
        .and_then(Item::as_table_like_mut)
        .ok_or_else(|| format!("the configuration has no [{table}] table"))?;
    match t.get_mut(key).and_then(Item::as_value_mut) {
        Some(v) => replace(v, x),
        None => {
            t.insert(key, toml_edit::value(x));
        }
    }
    Ok(())
}

/// The configuration text with m, c and B replaced.
pub fn write_back(
    text: &str,
    mass_kg: f64,
    com_m: f64,
    support_m: [f64; 3],
) -> Result<String, String> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| format!("not valid TOML: {}", e.message()))?;
    set_float(
        &mut doc,
        "manipulator",
        "mass_kg",
        rounded(mass_kg, MASS_STEP_KG),
    )?;
    set_float(
        &mut doc,
        "manipulator",
        "com_m",
        rounded(com_m, LENGTH_STEP_M),
    )?;
    let geometry = doc
        .get_mut("geometry")
        .and_then(Item::as_table_like_mut)
        .ok_or("the configuration has no [geometry] table")?;
    let support = geometry
        .get_mut("support")
        .and_then(Item::as_value_mut)
        .and_then(Value::as_array_mut)
        .filter(|a| a.len() == 3)
        .ok_or("geometry.support is not an array of 3 numbers")?;
    for (i, x) in support_m.into_iter().enumerate() {
        if let Some(v) = support.get_mut(i) {
            replace(v, rounded(x, LENGTH_STEP_M));
        }
    }
    Ok(doc.to_string())
}

/// Rounding of the written inertia: 1e-7 kg m^2 (far below its standard error).
const INERTIA_STEP_KGM2: f64 = 1e-7;

/// The configuration text with `[manipulator] inertia_perp_kgm2` and
/// `inertia_perp_std_kgm2` replaced (or appended to the table), the rest kept.
pub fn write_inertia(text: &str, inertia_kgm2: f64, std_kgm2: f64) -> Result<String, String> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| format!("not valid TOML: {}", e.message()))?;
    set_float(
        &mut doc,
        "manipulator",
        "inertia_perp_kgm2",
        rounded(inertia_kgm2, INERTIA_STEP_KGM2),
    )?;
    set_float(
        &mut doc,
        "manipulator",
        "inertia_perp_std_kgm2",
        rounded(std_kgm2, INERTIA_STEP_KGM2),
    )?;
    Ok(doc.to_string())
}

/// The configuration text with `[sensor] adapter_mass_kg` replaced (or
/// appended, the table too), rounded to 0.01 g, the rest kept.
pub fn write_adapter(text: &str, adapter_mass_kg: f64) -> Result<String, String> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| format!("not valid TOML: {}", e.message()))?;
    if doc.get("sensor").is_none() {
        doc.insert("sensor", toml_edit::table());
    }
    set_float(
        &mut doc,
        "sensor",
        "adapter_mass_kg",
        rounded(adapter_mass_kg, MASS_STEP_KG),
    )?;
    Ok(doc.to_string())
}

/// The configuration text with `[axes] servo_bandwidth_hz`, `servo_damping`
/// and `servo_delay_s` replaced (or appended, the table too), the rest kept:
/// rounded to 1 mHz, 1e-4 and 1 us (below their standard deviations).
pub fn write_servo(
    text: &str,
    bandwidth_hz: f64,
    damping: f64,
    delay_s: f64,
) -> Result<String, String> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| format!("not valid TOML: {}", e.message()))?;
    if doc.get("axes").is_none() {
        doc.insert("axes", toml_edit::table());
    }
    set_float(
        &mut doc,
        "axes",
        "servo_bandwidth_hz",
        rounded(bandwidth_hz, 1e-3),
    )?;
    set_float(&mut doc, "axes", "servo_damping", rounded(damping, 1e-4))?;
    set_float(&mut doc, "axes", "servo_delay_s", rounded(delay_s, 1e-6))?;
    Ok(doc.to_string())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_servo_keys_keep_the_file_and_a_missing_table_is_added() {
        let text = "# robot\n[axes]\nservo_bandwidth_hz = 30.0 # as built\nmax_speed_mps = 0.02\n";
        let out = write_servo(text, 12.0123456, 0.4512345, 0.00150049).unwrap();
        assert_eq!(
            out,
            "# robot\n[axes]\nservo_bandwidth_hz = 12.012 # as built\nmax_speed_mps = 0.02\nservo_damping = 0.4512\nservo_delay_s = 0.0015\n"
        );
        let added = write_servo("[tip]\nx = 1\n", 30.0, 0.7, 0.0).unwrap();
        assert!(
            added.contains("[axes]\nservo_bandwidth_hz = 30.0\n"),
            "{added}"
        );
    }

    #[test]
    fn the_adapter_is_written_keeping_the_sensor_table() {
        let text = "[sensor]\nnoise_n = [0.2, 0.2, 0.8]\nadapter_mass_kg = 0.0 # m_s\n";
        let out = write_adapter(text, 0.3512345).unwrap();
        assert_eq!(
            out,
            "[sensor]\nnoise_n = [0.2, 0.2, 0.8]\nadapter_mass_kg = 0.35123 # m_s\n"
        );
        let added = write_adapter("[tip]\nx = 1\n", 0.1).unwrap();
        assert!(
            added.contains("[sensor]\nadapter_mass_kg = 0.1\n"),
            "{added}"
        );
    }

    #[test]
    fn keeps_comments_order_and_spacing() {
        let text = "# robot\n[geometry]\nsupport = [0.45, 0.20, 0.0]   # B, measured by hand\ngravity = [0.0, -9.80665, 0.0]\n\n[manipulator]\nname = \"m2\"\nmass_kg = 2.593                        # m\ncom_m = 0.103 # c\n";
        let out = write_back(text, 2.6012345678, 0.10412345, [0.4512345, 0.1987654, 0.0]).unwrap();
        assert_eq!(
            out,
            "# robot\n[geometry]\nsupport = [0.451235, 0.198765, 0.0]   # B, measured by hand\ngravity = [0.0, -9.80665, 0.0]\n\n[manipulator]\nname = \"m2\"\nmass_kg = 2.60123                        # m\ncom_m = 0.104123 # c\n"
        );
    }

    #[test]
    fn the_inertia_is_written_and_replaced_keeping_comments() {
        let text = "[manipulator]\nname = \"m2\"\nmass_kg = 2.593 # m\n\n[sensor]\nnoise_n = [0.2, 0.2, 0.8]\n";
        let out = write_inertia(text, 0.026471234, 0.000091234).unwrap();
        assert_eq!(
            out,
            "[manipulator]\nname = \"m2\"\nmass_kg = 2.593 # m\ninertia_perp_kgm2 = 0.0264712\ninertia_perp_std_kgm2 = 0.0000912\n\n[sensor]\nnoise_n = [0.2, 0.2, 0.8]\n"
        );
        let again = write_inertia(
            "[manipulator]\ninertia_perp_kgm2 = 0.02   # I_perp\ninertia_perp_std_kgm2 = 0.001\n",
            0.03,
            0.0002,
        )
        .unwrap();
        assert_eq!(
            again,
            "[manipulator]\ninertia_perp_kgm2 = 0.03   # I_perp\ninertia_perp_std_kgm2 = 0.0002\n"
        );
    }
}
