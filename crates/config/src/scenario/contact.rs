//! What touches the tip: `[[contact]]`, the scripted tip force (keyframes
//! sorted by time), and `[[tissue]]`, tissues that push back.

use super::raw::{ContactToml, TissueModelName, TissueToml};
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_hal::Vec3;
use sar_sim::{Breathing, ContactKey, Tissue, TissueModel, TissueShift};

/// Largest tissue stiffness accepted, N/m (soft tissue: about 100 to 5000).
pub const MAX_STIFFNESS_N_PER_M: f64 = 1e6;
/// Largest exponential stiffening accepted, 1/m.
pub const MAX_BETA_PER_M: f64 = 1e4;
/// Largest tissue damping accepted, N s/m.
pub const MAX_DAMPING_N_S_PER_M: f64 = 1e5;
/// Largest breathing amplitude accepted, m.
pub const MAX_BREATHING_AMPLITUDE_M: f64 = 0.1;
/// Largest breathing frequency accepted, Hz.
pub const MAX_BREATHING_HZ: f64 = 10.0;
/// Largest tissue shift accepted, m.
pub const MAX_SHIFT_M: f64 = 1.0;

/// The `[[contact]]` keyframes, in file order (which must be time order).
pub(super) fn keys(ctx: &Ctx<'_>, file: &[ContactToml]) -> Result<Vec<ContactKey>, ConfigError> {
    let mut contact = Vec::with_capacity(file.len());
    let mut last_t: Option<(f64, usize)> = None;
    for (i, key) in file.iter().enumerate() {
        let t_key = format!("contact[{i}].t_s");
        let t_ns = ctx.time_ns(&t_key, key.t_s)?;
        if let Some((t, j)) = last_t
            && key.t_s < t
        {
            return Err(ctx.err(
                &t_key,
                format!(
                    "contact keyframes must be sorted by time: {} s is before \
                     contact[{j}].t_s = {t} s",
                    key.t_s
                ),
            ));
        }
        last_t = Some((key.t_s, i));
        contact.push(ContactKey {
            t_ns,
            force_n: Vec3::from(key.force_n),
        });
    }
    Ok(contact)
}

/// A unit vector from a non-zero one (`key` names it in the error).
fn unit(ctx: &Ctx<'_>, key: &str, v: [f64; 3]) -> Result<Vec3, ConfigError> {
    let v = Vec3::from(v);
    let norm = v.norm();
    if norm < 1e-9 {
        return Err(ctx.err(key, "must not be the zero vector"));
    }
    Ok(v / norm)
}

/// A value in (0, max] (`key` names it in the error).
fn in_range(
    ctx: &Ctx<'_>,
    key: &str,
    value: f64,
    max: f64,
    unit: &str,
) -> Result<f64, ConfigError> {
    if value > 0.0 && value <= max {
        Ok(value)
    } else {
        Err(ctx.err(
            key,
            format!("must be in (0, {max}] {unit}, got {value} {unit}"),
        ))
    }
}

/// Every `[[tissue]]`, in file order.
pub(super) fn tissues(ctx: &Ctx<'_>, file: &[TissueToml]) -> Result<Vec<Tissue>, ConfigError> {
    file.iter()
        .enumerate()
        .map(|(i, t)| tissue(ctx, &format!("tissue[{i}]"), t))
        .collect()
}

/// One `[[tissue]]`: its direction, stiffness model, damping, breathing
/// and shifts, each checked under its key.
fn tissue(ctx: &Ctx<'_>, key: &str, t: &TissueToml) -> Result<Tissue, ConfigError> {
    let k = |name: &str| format!("{key}.{name}");
    let direction = unit(ctx, &k("direction"), t.direction)?;
    let model = tissue_model(ctx, key, t)?;
    let damping_n_s_per_m = t.damping_n_s_per_m.unwrap_or(0.0);
    if !(0.0..=MAX_DAMPING_N_S_PER_M).contains(&damping_n_s_per_m) {
        return Err(ctx.err(
            &k("damping_n_s_per_m"),
            format!("must be in [0, {MAX_DAMPING_N_S_PER_M}] N s/m, got {damping_n_s_per_m} N s/m"),
        ));
    }
    let breathing = breathing(ctx, key, t, direction)?;
    let shifts = shifts(ctx, key, t)?;
    Ok(Tissue {
        direction,
        rest_m: Vec3::from(t.rest_m),
        model,
        damping_n_s_per_m,
        breathing,
        shifts,
    })
}

/// The tissue's stiffness: linear, or exponential with its `beta_per_m`.
fn tissue_model(ctx: &Ctx<'_>, key: &str, t: &TissueToml) -> Result<TissueModel, ConfigError> {
    let k = |name: &str| format!("{key}.{name}");
    let stiffness_n_per_m = in_range(
        ctx,
        &k("stiffness_n_per_m"),
        t.stiffness_n_per_m,
        MAX_STIFFNESS_N_PER_M,
        "N/m",
    )?;
    let model = match (t.model.unwrap_or(TissueModelName::Linear), t.beta_per_m) {
        (TissueModelName::Linear, None) => TissueModel::Linear { stiffness_n_per_m },
        (TissueModelName::Linear, Some(_)) => {
            return Err(ctx.err(
                &k("beta_per_m"),
                "only allowed with model = \"exponential\"",
            ));
        }
        (TissueModelName::Exponential, None) => {
            return Err(ctx.err(
                &k("beta_per_m"),
                "missing key (model = \"exponential\" needs it)",
            ));
        }
        (TissueModelName::Exponential, Some(beta)) => TissueModel::Exponential {
            stiffness_n_per_m,
            beta_per_m: in_range(ctx, &k("beta_per_m"), beta, MAX_BETA_PER_M, "1/m")?,
        },
    };
    Ok(model)
}

/// The breathing: both its amplitude and its rate, or neither (and then no
/// direction); along the tissue's `direction` unless it names its own.
fn breathing(
    ctx: &Ctx<'_>,
    key: &str,
    t: &TissueToml,
    direction: Vec3,
) -> Result<Option<Breathing>, ConfigError> {
    let k = |name: &str| format!("{key}.{name}");
    let breathing = match (t.breathing_amplitude_m, t.breathing_hz) {
        (None, None) => {
            if t.breathing_direction.is_some() {
                return Err(ctx.err(
                    &k("breathing_direction"),
                    "only allowed with breathing_amplitude_m",
                ));
            }
            None
        }
        (None, Some(_)) => {
            return Err(ctx.err(
                &k("breathing_hz"),
                "only allowed with breathing_amplitude_m",
            ));
        }
        (Some(_), None) => {
            return Err(ctx.err(
                &k("breathing_hz"),
                "missing key (breathing_amplitude_m needs it)",
            ));
        }
        (Some(amplitude_m), Some(hz)) => Some(Breathing {
            amplitude_m: in_range(
                ctx,
                &k("breathing_amplitude_m"),
                amplitude_m,
                MAX_BREATHING_AMPLITUDE_M,
                "m",
            )?,
            hz: in_range(ctx, &k("breathing_hz"), hz, MAX_BREATHING_HZ, "Hz")?,
            direction: match t.breathing_direction {
                Some(d) => unit(ctx, &k("breathing_direction"), d)?,
                None => direction,
            },
        }),
    };
    Ok(breathing)
}

/// The shifts of the rest position, sorted by time, each within
/// [`MAX_SHIFT_M`].
fn shifts(ctx: &Ctx<'_>, key: &str, t: &TissueToml) -> Result<Vec<TissueShift>, ConfigError> {
    let k = |name: &str| format!("{key}.{name}");
    let mut shifts = Vec::with_capacity(t.shift.len());
    let mut last_t: Option<(f64, usize)> = None;
    for (i, shift) in t.shift.iter().enumerate() {
        let t_key = k(&format!("shift[{i}].t_s"));
        let t_ns = ctx.time_ns(&t_key, shift.t_s)?;
        if let Some((t, j)) = last_t
            && shift.t_s < t
        {
            return Err(ctx.err(
                &t_key,
                format!(
                    "shifts must be sorted by time: {} s is before {key}.shift[{j}].t_s = {t} s",
                    shift.t_s
                ),
            ));
        }
        last_t = Some((shift.t_s, i));
        if shift.offset_m.abs() > MAX_SHIFT_M {
            return Err(ctx.err(
                &k(&format!("shift[{i}].offset_m")),
                format!(
                    "must be at most {MAX_SHIFT_M} m in size, got {} m",
                    shift.offset_m
                ),
            ));
        }
        shifts.push(TissueShift {
            t_ns,
            offset_m: shift.offset_m,
        });
    }
    Ok(shifts)
}
