//! What the guard's reasons name: a part of the tip force with its own
//! limits ([`ForcePart`]), a vector field of the estimate and a component of
//! it ([`TipField`], [`Axis`]), a residual of the wrench at rest
//! ([`RestResidual`]), a channel of the force/torque sensor
//! ([`SensorChannel`]). Each shows as the log prints it and is stored by a
//! fixed tag in snapshots.

use core::fmt;

/// One of the three parts of the tip force that have their own limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForcePart {
    /// |F_tip|.
    Total,
    /// |F_tip . u|, along the rod.
    Axial,
    /// |F_tip - (F_tip . u) u|, across the rod.
    Lateral,
}

impl ForcePart {
    /// The parts in the order they are checked (and reported when several
    /// exceed their limits in the same cycle).
    pub const ALL: [ForcePart; 3] = [Self::Total, Self::Axial, Self::Lateral];
}

impl fmt::Display for ForcePart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Total => "total",
            Self::Axial => "axial",
            Self::Lateral => "lateral",
        })
    }
}

/// A vector field of [`super::TipInput::Estimate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TipField {
    /// `force_n`.
    Force,
    /// `std_n`.
    Std,
    /// `rod_dir`.
    RodDir,
}

impl fmt::Display for TipField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Force => "force_n",
            Self::Std => "std_n",
            Self::RodDir => "rod_dir",
        })
    }
}

/// A component of a vector in {0}.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// X0.
    X,
    /// Y0.
    Y,
    /// Z0.
    Z,
}

impl Axis {
    /// X, Y, Z.
    pub const ALL: [Axis; 3] = [Self::X, Self::Y, Self::Z];
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::X => "x",
            Self::Y => "y",
            Self::Z => "z",
        })
    }
}

/// A residual of the wrench at rest against the model (the first reset's
/// check).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestResidual {
    /// The tip force along the rod, N.
    Axial,
    /// The tip force across the rod, N.
    Lateral,
    /// The sensor torque on one sensor axis, N m.
    Torque(Axis),
}

impl fmt::Display for RestResidual {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Axial => f.write_str("axial force"),
            Self::Lateral => f.write_str("lateral force"),
            Self::Torque(axis) => write!(f, "torque {axis}"),
        }
    }
}

/// A channel of the force/torque sensor, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorChannel {
    /// Force x.
    Fx,
    /// Force y.
    Fy,
    /// Force z.
    Fz,
    /// Torque x.
    Tx,
    /// Torque y.
    Ty,
    /// Torque z.
    Tz,
}

impl SensorChannel {
    /// Fx, Fy, Fz, Tx, Ty, Tz.
    pub const ALL: [SensorChannel; 6] =
        [Self::Fx, Self::Fy, Self::Fz, Self::Tx, Self::Ty, Self::Tz];
}

impl fmt::Display for SensorChannel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Fx => "Fx",
            Self::Fy => "Fy",
            Self::Fz => "Fz",
            Self::Tx => "Tx",
            Self::Ty => "Ty",
            Self::Tz => "Tz",
        })
    }
}

// Snapshots (issue 17): each by a fixed tag.

sar_snapshot::snap_enum!(ForcePart { 0 => Total, 1 => Axial, 2 => Lateral });

sar_snapshot::snap_enum!(TipField { 0 => Force, 1 => Std, 2 => RodDir });

sar_snapshot::snap_enum!(Axis { 0 => X, 1 => Y, 2 => Z });

sar_snapshot::snap_enum!(SensorChannel { 0 => Fx, 1 => Fy, 2 => Fz, 3 => Tx, 4 => Ty, 5 => Tz });

impl sar_snapshot::Snap for RestResidual {
    fn put(&self, w: &mut sar_snapshot::Writer<'_>) {
        match self {
            Self::Axial => w.put_u8(0),
            Self::Lateral => w.put_u8(1),
            Self::Torque(axis) => {
                w.put_u8(2);
                axis.put(w);
            }
        }
    }
    fn get(r: &mut sar_snapshot::Reader<'_>) -> Result<Self, sar_snapshot::SnapshotError> {
        let at = r.position();
        match r.get_u8()? {
            0 => Ok(Self::Axial),
            1 => Ok(Self::Lateral),
            2 => Ok(Self::Torque(sar_snapshot::Snap::get(r)?)),
            value => Err(sar_snapshot::SnapshotError::BadTag {
                what: "RestResidual",
                value,
                at,
            }),
        }
    }
}
