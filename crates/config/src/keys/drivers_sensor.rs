//! `[drivers.sensor]`: the force/torque sensor's driver, the simulator
//! (default) or an RDT sensor (OnRobot HEX / ATI Net F/T over UDP) with its
//! address and scale.

use crate::decl::{KeyDecl, choice, num, text};
use crate::toml_file::Ctx;
use crate::{ConfigError, SensorDriver};
use std::net::SocketAddr;

/// Required with `kind = "rdt"`.
const RDT: &str = "required with kind = \"rdt\"";

crate::section! {
    /// The force/torque sensor's driver (INTERFACES.md 2).
    section "drivers.sensor";
    /// "sim" | "rdt" (OnRobot HEX / ATI Net F/T over UDP)
    kind: String = value("sim"), choice(&["sim", "rdt"]) => [SensorDriver];
    /// the sensor's address and port
    address: String = absent(RDT, "192.168.1.1:49152"),
        text("an IP address with a port") => [SensorDriver::Rdt.address];
    /// counts per newton
    counts_per_n: f64 = absent(RDT, 10000.0),
        num(1.0, 1e9, "counts/N") => [SensorDriver::Rdt.counts_per_n];
    /// counts per newton metre
    counts_per_nm: f64 = absent(RDT, 100000.0),
        num(1.0, 1e9, "counts/(N m)") => [SensorDriver::Rdt.counts_per_nm];
}

/// `[drivers.sensor]`: the simulator, or the RDT sensor with its keys.
pub(crate) fn build(ctx: &Ctx<'_>, s: &Section) -> Result<SensorDriver, ConfigError> {
    if s.kind != "rdt" {
        let given = [
            (&KEY.address, s.address.is_some()),
            (&KEY.counts_per_n, s.counts_per_n.is_some()),
            (&KEY.counts_per_nm, s.counts_per_nm.is_some()),
        ];
        return refuse_given(ctx, "the simulated sensor", &given).map(|()| SensorDriver::Sim);
    }
    let required = |d: &KeyDecl, v: Option<f64>| v.ok_or_else(|| crate::decl::missing(ctx, d));
    let address = s
        .address
        .as_deref()
        .ok_or_else(|| crate::decl::missing(ctx, &KEY.address))?;
    let address: SocketAddr = address.parse().map_err(|_| {
        ctx.err(
            KEY.address.key,
            format!("not an IP address with a port (e.g. \"192.168.1.1:49152\"): {address:?}"),
        )
    })?;
    Ok(SensorDriver::Rdt {
        address,
        counts_per_n: required(&KEY.counts_per_n, s.counts_per_n)?,
        counts_per_nm: required(&KEY.counts_per_nm, s.counts_per_nm)?,
    })
}

/// Refuses the first key of `given` (`(key, given)`) that is given: not a
/// key of `what` (the simulated device, `kind = "sim"`).
pub(crate) fn refuse_given(
    ctx: &Ctx<'_>,
    what: &str,
    given: &[(&KeyDecl, bool)],
) -> Result<(), ConfigError> {
    match given.iter().find(|(_, given)| *given) {
        Some((d, _)) => Err(ctx.err(d.key, format!("not a key of {what} (kind = \"sim\")"))),
        None => Ok(()),
    }
}
