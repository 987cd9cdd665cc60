//! Every key of the configuration file (INTERFACES.md 2), declared once: one
//! module per section, each with its [`section!`](crate::section) table
//! (every key's type, default, range, one-line doc and the domain field it
//! sets) and the functions that build the section's domain types from the
//! keys read. [`SECTIONS`] lists the sections in the file's order; the README's
//! table and `default_config.toml` are made from them (`crate::docs`).
//!
//! A new key is one line in its section's table and the code that uses the
//! field; its serde field, default, range check, README row and
//! `default_config.toml` line follow from the line.

use crate::ConfigError;
use crate::decl::{KeyDecl, SectionDecl};
use crate::toml_file::Ctx;
use sar_kinematics::Vec3;
use serde::Deserialize;

pub mod axes;
pub mod drivers_axes;
pub mod drivers_sensor;
pub mod force_control;
pub mod geometry;
pub mod guard;
pub mod identify;
pub mod loop_;
pub mod manipulator;
pub mod plausibility;
pub mod record;
pub mod ros2;
pub mod sensor;
pub mod support;
pub mod tip;

/// Every section, in the file's order (the order `default_config.toml` and
/// the README's table list them in, and the order the ranges are checked
/// in).
pub const SECTIONS: &[SectionDecl] = &[
    geometry::DECL,
    manipulator::DECL,
    sensor::DECL,
    loop_::DECL,
    guard::DECL,
    plausibility::DECL,
    tip::DECL,
    axes::DECL,
    record::DECL,
    force_control::DECL,
    identify::DECL,
    support::DECL,
    ros2::DECL,
    drivers_sensor::DECL,
    drivers_axes::DECL,
];

/// Every key, in the file's order.
pub fn keys() -> impl Iterator<Item = &'static KeyDecl> {
    SECTIONS.iter().flat_map(|s| s.keys.iter())
}

/// The file as written: the three required sections, the others optional
/// (each key then takes its default); unknown sections refused.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FileRaw {
    geometry: Option<geometry::Raw>,
    manipulator: Option<manipulator::Raw>,
    sensor: Option<sensor::Raw>,
    #[serde(default, rename = "loop")]
    loop_: loop_::Raw,
    #[serde(default)]
    guard: guard::Raw,
    #[serde(default)]
    plausibility: plausibility::Raw,
    #[serde(default)]
    tip: tip::Raw,
    #[serde(default)]
    axes: axes::Raw,
    #[serde(default)]
    record: record::Raw,
    #[serde(default)]
    force_control: force_control::Raw,
    #[serde(default)]
    identify: identify::Raw,
    #[serde(default)]
    support: support::Raw,
    #[serde(default)]
    ros2: ros2::Raw,
    #[serde(default)]
    drivers: DriversRaw,
}

/// `[drivers]`: the sensor's and the axes' (both optional: the simulator).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct DriversRaw {
    #[serde(default)]
    sensor: drivers_sensor::Raw,
    #[serde(default)]
    axes: drivers_axes::Raw,
}

/// The file read: every key's value or its default, by section (in a
/// loaded [`Config`](crate::Config), [`Config::file`](crate::Config::file):
/// each within its declared range and every check passed).
#[derive(Debug, Clone, PartialEq)]
pub struct File {
    /// `[geometry]`.
    pub geometry: geometry::Section,
    /// `[manipulator]`.
    pub manipulator: manipulator::Section,
    /// `[sensor]`.
    pub sensor: sensor::Section,
    /// `[loop]`.
    pub loop_: loop_::Section,
    /// `[guard]`.
    pub guard: guard::Section,
    /// `[plausibility]`.
    pub plausibility: plausibility::Section,
    /// `[tip]`.
    pub tip: tip::Section,
    /// `[axes]`.
    pub axes: axes::Section,
    /// `[record]`.
    pub record: record::Section,
    /// `[force_control]`.
    pub force_control: force_control::Section,
    /// `[identify]`.
    pub identify: identify::Section,
    /// `[support]`.
    pub support: support::Section,
    /// `[ros2]`.
    pub ros2: ros2::Section,
    /// `[drivers.sensor]`.
    pub drivers_sensor: drivers_sensor::Section,
    /// `[drivers.axes]`.
    pub drivers_axes: drivers_axes::Section,
}

impl FileRaw {
    /// Every key's value or default; a missing required section or key is
    /// refused (the first, in the file's order).
    pub(crate) fn resolve(self, ctx: &Ctx<'_>) -> Result<File, ConfigError> {
        let missing = |section: &str| ctx.err(section, "missing key");
        let geometry = self.geometry.ok_or_else(|| missing(geometry::SECTION))?;
        let manipulator = self
            .manipulator
            .ok_or_else(|| missing(manipulator::SECTION))?;
        let sensor = self.sensor.ok_or_else(|| missing(sensor::SECTION))?;
        Ok(File {
            geometry: geometry.resolve(ctx)?,
            manipulator: manipulator.resolve(ctx)?,
            sensor: sensor.resolve(ctx)?,
            loop_: self.loop_.resolve(ctx)?,
            guard: self.guard.resolve(ctx)?,
            plausibility: self.plausibility.resolve(ctx)?,
            tip: self.tip.resolve(ctx)?,
            axes: self.axes.resolve(ctx)?,
            record: self.record.resolve(ctx)?,
            force_control: self.force_control.resolve(ctx)?,
            identify: self.identify.resolve(ctx)?,
            support: self.support.resolve(ctx)?,
            ros2: self.ros2.resolve(ctx)?,
            drivers_sensor: self.drivers.sensor.resolve(ctx)?,
            drivers_axes: self.drivers.axes.resolve(ctx)?,
        })
    }
}

impl File {
    /// Every key's declared range, in the file's order: a value outside is
    /// refused naming the key, its line, the range and the likely unit.
    pub(crate) fn check_ranges(&self, ctx: &Ctx<'_>) -> Result<(), ConfigError> {
        self.geometry.check_ranges(ctx)?;
        self.manipulator.check_ranges(ctx)?;
        self.sensor.check_ranges(ctx)?;
        self.loop_.check_ranges(ctx)?;
        self.guard.check_ranges(ctx)?;
        self.plausibility.check_ranges(ctx)?;
        self.tip.check_ranges(ctx)?;
        self.axes.check_ranges(ctx)?;
        self.record.check_ranges(ctx)?;
        self.force_control.check_ranges(ctx)?;
        self.identify.check_ranges(ctx)?;
        self.support.check_ranges(ctx)?;
        self.ros2.check_ranges(ctx)?;
        self.drivers_sensor.check_ranges(ctx)?;
        self.drivers_axes.check_ranges(ctx)
    }
}

pub(crate) fn vec3(v: [f64; 3]) -> Vec3 {
    Vec3::from(v)
}

/// Seconds to whole ns (a value within its declared range).
pub(crate) fn ns(s: f64) -> u64 {
    (s * 1e9).round() as u64
}

/// An integer within its declared range (within `u32`) as a `u32`.
pub(crate) fn u32_of(v: i64) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}
