//! The support moving (issue 26; MODEL.md 10: the patient shifts a few
//! millimetres, up to 20 mm): `[[support_shift]] t_s, shift_m = [x, y, z],
//! duration_s` (0 by default: at once). The true B of `[robot] support` moves
//! by `shift_m`, {0}, m, from `t_s` on over `duration_s` (a smooth ramp);
//! shifts add up. The daemon's configured B does not move: this is a
//! misalignment the estimator does not know of.

use super::raw::SupportShiftToml;
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_hal::Vec3;
use sar_sim::{MAX_SUPPORT_SHIFT_M, SupportShift};

/// The `[[support_shift]]` tables, each key checked under its name.
pub(super) fn support_shifts(
    ctx: &Ctx<'_>,
    file: &[SupportShiftToml],
) -> Result<Vec<SupportShift>, ConfigError> {
    let mut shifts = Vec::with_capacity(file.len());
    for (i, s) in file.iter().enumerate() {
        let key = |k: &str| format!("support_shift[{i}].{k}");
        let t_ns = ctx.time_ns(&key("t_s"), s.t_s)?;
        let duration_ns = ctx.time_ns(&key("duration_s"), s.duration_s)?;
        let shift_m = Vec3::from(s.shift_m);
        let length_m = shift_m.norm();
        if !(length_m.is_finite() && length_m <= MAX_SUPPORT_SHIFT_M) {
            return Err(ctx.err(
                &key("shift_m"),
                format!(
                    "must be finite and at most {MAX_SUPPORT_SHIFT_M} m long, got {length_m} m"
                ),
            ));
        }
        shifts.push(SupportShift {
            t_ns,
            shift_m,
            duration_ns,
        });
    }
    Ok(shifts)
}
