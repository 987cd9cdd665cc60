//! The plant in motion (issue 26): the rod's inertia (`[manipulator]
//! inertia_perp_kgm2`, `inertia_axial_kgm2`), the adapter's mass (`[sensor]
//! adapter_mass_kg`), the axes' servos (`[axes] servo_bandwidth_hz`,
//! `servo_damping`, `servo_max_accel_mps2`; issue 34, a servo that is not
//! the loop's model: `servo_delay_s`, a pure delay of the reference, and
//! `servo_inner_loop_hz`, an inner velocity loop that makes the axis third
//! order) and the drives' quick-stop
//! deceleration (`[axes] quick_stop_decel_mps2`). Each group is opt-in: with
//! none of its keys the simulator is the plant of before (no inertia, ideal
//! axes, a quick stop at the acceleration limit), bit for bit. Within a
//! group, a missing key takes its stated default (I_perp: the slender rod's
//! m L^2 / 12; I_axial and the adapter: 0; the servo: 30 Hz, 0.7, 5 m/s^2,
//! no delay, no inner loop).

use super::raw::FileToml;
use super::{DEFAULT_SERVO_BANDWIDTH_HZ, DEFAULT_SERVO_DAMPING, DEFAULT_SERVO_MAX_ACCEL_MPS2};
use crate::ConfigError;
use crate::toml_file::Ctx;
use sar_kinematics::Profile;
use sar_sim::{PlantSpec, RodInertia, ServoSpec};

/// The plant's keys, checked (each error names its key).
pub(super) fn plant(
    ctx: &Ctx<'_>,
    file: &FileToml,
    profile: &Profile,
) -> Result<PlantSpec, ConfigError> {
    let m = &file.manipulator;
    let adapter = file.sensor.as_ref().and_then(|s| s.adapter_mass_kg);
    let inertia =
        if m.inertia_perp_kgm2.is_some() || m.inertia_axial_kgm2.is_some() || adapter.is_some() {
            let slender = profile.mass_kg() * profile.length_m().powi(2) / 12.0;
            let key = |k: &str, v: Option<f64>, default: f64, unit: &str| match v {
                Some(x) => ctx.non_negative(k, x, unit),
                None => Ok(default),
            };
            Some(RodInertia {
                inertia_perp_kgm2: key(
                    "manipulator.inertia_perp_kgm2",
                    m.inertia_perp_kgm2,
                    slender,
                    "kg m^2",
                )?,
                inertia_axial_kgm2: key(
                    "manipulator.inertia_axial_kgm2",
                    m.inertia_axial_kgm2,
                    0.0,
                    "kg m^2",
                )?,
                adapter_mass_kg: key("sensor.adapter_mass_kg", adapter, 0.0, "kg")?,
            })
        } else {
            None
        };
    let axes = file.axes.as_ref();
    let get = |f: fn(&super::raw::AxesToml) -> Option<f64>| axes.and_then(f);
    let (bandwidth, damping, max_accel) = (
        get(|a| a.servo_bandwidth_hz),
        get(|a| a.servo_damping),
        get(|a| a.servo_max_accel_mps2),
    );
    let (delay, inner) = (get(|a| a.servo_delay_s), get(|a| a.servo_inner_loop_hz));
    let any_servo_key = [bandwidth, damping, max_accel, delay, inner]
        .iter()
        .any(Option::is_some);
    let servo = if any_servo_key {
        let key = |k: &str, v: Option<f64>, default: f64, unit: &str| {
            v.map_or(Ok(default), |x| ctx.positive(k, x, unit))
        };
        Some(ServoSpec {
            bandwidth_hz: key(
                "axes.servo_bandwidth_hz",
                bandwidth,
                DEFAULT_SERVO_BANDWIDTH_HZ,
                "Hz",
            )?,
            damping: key("axes.servo_damping", damping, DEFAULT_SERVO_DAMPING, "")?,
            max_accel_mps2: key(
                "axes.servo_max_accel_mps2",
                max_accel,
                DEFAULT_SERVO_MAX_ACCEL_MPS2,
                "m/s^2",
            )?,
            delay_ns: delay.map_or(Ok(0), |s| ctx.time_ns("axes.servo_delay_s", s))?,
            inner_loop_hz: inner.map_or(Ok(0.0), |hz| {
                ctx.non_negative("axes.servo_inner_loop_hz", hz, "Hz")
            })?,
        })
    } else {
        None
    };
    let quick_stop_decel_mps2 = get(|a| a.quick_stop_decel_mps2)
        .map(|x| ctx.positive("axes.quick_stop_decel_mps2", x, "m/s^2"))
        .transpose()?;
    Ok(PlantSpec {
        inertia,
        servo,
        quick_stop_decel_mps2,
    })
}
