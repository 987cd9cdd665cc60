//! `[drivers.axes]`: the axis drives' driver, the simulator (default) or
//! CiA 402 drives over CANopen with the bus, the nodes, the scale and the
//! drives' own limits that no other key gives. The quick stop's
//! deceleration is every kind's (`sard --sim` sets the simulated drives'
//! from it; the loop's model of the drives takes it, `crate::keys::axes`).

use crate::decl::{choice, int, int_each, num, text};
use crate::keys::drivers_sensor::refuse_given;
use crate::toml_file::Ctx;
use crate::{AxesDriver, ConfigError, DEFAULT_MAX_TORQUE_PERMILLE, DEFAULT_QUICK_STOP_DECEL_MPS2};
use sar_loop::motion::MotionConfig;

/// Required with `kind = "canopen"`.
const CANOPEN: &str = "required with kind = \"canopen\"";

crate::section! {
    /// The axis drives' driver (INTERFACES.md 2).
    section "drivers.axes";
    /// "sim" | "canopen" (CiA 402 drives over CANopen)
    kind: String = value("sim"), choice(&["sim", "canopen"]) => [AxesDriver];
    /// the CAN interface
    interface: String = absent(CANOPEN, "can0"),
        text("a network interface name of 1 to 15 bytes") => [AxesDriver::Canopen.interface];
    /// the CANopen node ids of q1, q2, q3
    node_ids: Vec<i64> = absent(CANOPEN, [1, 2, 3]),
        int_each(1, 127, "").also("three, distinct") => [AxesDriver::Canopen.node_ids];
    /// carriage travel per motor turn, m
    lead_m: f64 = absent(CANOPEN, 0.01), num(1e-5, 1.0, "m") => [AxesDriver::Canopen.lead_m];
    /// encoder counts per motor turn
    counts_per_turn: i64 = absent(CANOPEN, 4096),
        int(1, u32::MAX as i64, "counts") => [AxesDriver::Canopen.counts_per_turn];
    /// the drives' own quick stop (CiA 402 0x6085), m/s^2, every kind
    quick_stop_decel_mps2: f64 = value(DEFAULT_QUICK_STOP_DECEL_MPS2),
        num(1e-6, 10.0, "m/s^2").also("at least axes.max_accel_mps2")
        => [MotionConfig.quick_stop_decel_mps2];
    /// the drives' own max torque (0x6072), per mille of the motor's rated torque
    max_torque_permille: i64 = absent("the motor's rated torque, with kind = \"canopen\"", i64::from(DEFAULT_MAX_TORQUE_PERMILLE)),
        int(1, 3000, "per mille") => [AxesDriver::Canopen.max_torque_permille];
}

/// `[drivers.axes]`: the simulated axes, or CANopen drives with their keys.
pub(crate) fn build(ctx: &Ctx<'_>, a: &Section) -> Result<AxesDriver, ConfigError> {
    if a.kind != "canopen" {
        // The quick stop's deceleration is every kind's.
        let given = [
            (&KEY.interface, a.interface.is_some()),
            (&KEY.node_ids, a.node_ids.is_some()),
            (&KEY.lead_m, a.lead_m.is_some()),
            (&KEY.counts_per_turn, a.counts_per_turn.is_some()),
            (&KEY.max_torque_permille, a.max_torque_permille.is_some()),
        ];
        return refuse_given(ctx, "the simulated axes", &given).map(|()| AxesDriver::Sim);
    }
    let missing = |d| crate::decl::missing(ctx, d);
    let interface = a.interface.clone().ok_or_else(|| missing(&KEY.interface))?;
    if interface.is_empty() || interface.len() > 15 {
        return Err(ctx.err(
            KEY.interface.key,
            format!("must be a network interface name of 1 to 15 bytes, got {interface:?}"),
        ));
    }
    let node_ids = node_ids(ctx, a)?;
    let lead_m = a.lead_m.ok_or_else(|| missing(&KEY.lead_m))?;
    let cpt = a
        .counts_per_turn
        .ok_or_else(|| missing(&KEY.counts_per_turn))?;
    let torque = a
        .max_torque_permille
        .and_then(|t| u16::try_from(t).ok())
        .unwrap_or(DEFAULT_MAX_TORQUE_PERMILLE);
    Ok(AxesDriver::Canopen {
        interface,
        node_ids,
        lead_m,
        counts_per_turn: u32::try_from(cpt).unwrap_or(1),
        quick_stop_decel_mps2: a.quick_stop_decel_mps2,
        max_torque_permille: torque,
    })
}

/// `node_ids`: three distinct CANopen node ids (each 1 to 127 by its
/// range), for q1, q2, q3.
fn node_ids(ctx: &Ctx<'_>, a: &Section) -> Result<[u8; 3], ConfigError> {
    let key = KEY.node_ids.key;
    let ids = a
        .node_ids
        .as_ref()
        .ok_or_else(|| crate::decl::missing(ctx, &KEY.node_ids))?;
    let [q1, q2, q3] = ids.as_slice() else {
        return Err(ctx.err(
            key,
            format!("must name 3 nodes (q1, q2, q3), got {}", ids.len()),
        ));
    };
    let node_ids = [q1, q2, q3].map(|id| u8::try_from(*id).unwrap_or(1));
    let [n1, n2, n3] = node_ids;
    if n1 == n2 || n2 == n3 || n1 == n3 {
        return Err(ctx.err(
            key,
            format!("the three node ids must differ, got {node_ids:?}"),
        ));
    }
    Ok(node_ids)
}
