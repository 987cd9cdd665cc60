//! `sarctl identify`'s pure parts (MODEL.md 5, 5.1; INTERFACES.md 3): the
//! static dwells of a recording, the identification of m and c and the
//! calibration of the support B from them, the refusal of a fit the poses
//! cannot support, the report (JSON and human), the write-back into the
//! configuration ([`writeback`]) and the figure ([`plot`]).
//!
//! The recording is read twice, streaming: once for `/sar/joints` (the
//! dwells, [`dwell`]), once for `/sar/sensor/wrench` (each dwell's mean
//! force). Then:
//! 1. the linear identification of (m, M, f) at the configured B
//!    ([`sar_estimator::identification`]): too few poses, or poses that cannot
//!    tell m from M (condition number), are refused here;
//! 2. unless the support is kept, the support calibration of (m, M, B, f)
//!    ([`sar_estimator::support`]), which holds the components of B that the
//!    poses do not determine (reported as such); a chi-square per degree of
//!    freedom above the limit, or a condition number above it, is refused.
//!
//! The sensor's force bias must have been removed with the rod detached
//! (MODEL.md 5): either the device was tared then (the readings carry no
//! bias: the default tare of zero), or the bias measured then is given
//! ([`IdentifyOptions::tare_n`]).

pub mod dwell;
pub mod dynamic;
pub mod error;
pub mod excitation;
pub mod plot;
pub mod plot_dynamic;
pub mod poses;
pub mod servo;
pub mod smooth;
pub mod writeback;

use dwell::{Dwell, DwellFinder, DwellOptions, SensorAverager};
use error::InputError;
use sar_config::Config;
use sar_estimator::cycle::EstimatorConfig;
use sar_estimator::identification::{
    Identification, IdentificationError, IdentificationOptions, IdentificationResult,
};
use sar_estimator::support::{
    SUPPORT_CAPACITY, SupportCalibration, SupportError, SupportFit, SupportOptions,
};
use sar_estimator::{Calibration, StaticPose, Vec3};
use sar_kinematics::forward;
use sar_msgs::msgs::{ActiveJointState, Topic, WrenchStamped};
use sar_record::McapReader;
use serde_json::json;

/// The poses to add, named in every refusal that more or other poses cure.
pub const ADD_POSES: &str = "add static poses at support distances a from 0.04 to 0.30 m, with the rod tilted and turned (the cone set of MODEL.md 5.1: 4 rod directions on a 35 degree cone around X0 x a in {0.04, 0.07, 0.12, 0.20, 0.30} m, sweeping alternately outward and inward), each held still at least settle + minimum dwell";

/// Default largest condition number (column-scaled) of the linear fit and of
/// the support fit: on the fixtures the cone set gives 5.8 and the article's
/// protocol (B_x, B_y fitted) 18; poses at one support distance give 1e14 or
/// more (or a mass below zero, refused too).
pub const DEFAULT_MAX_CONDITION: f64 = 1e5;

/// How to identify.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifyOptions {
    /// How dwells are found.
    pub dwell: DwellOptions,
    /// The sensor's force bias measured with the rod detached (sensor frame,
    /// N); zero when the device was tared then.
    pub tare_n: [f64; 3],
    /// Calibrate the support B (false: keep the configured B, all held).
    pub calibrate_support: bool,
    /// Estimate the support's Coulomb friction (default true).
    pub friction: bool,
    /// Largest accepted chi-square per degree of freedom (default 4).
    pub max_chi2_dof: f64,
    /// Largest accepted condition number (default [`DEFAULT_MAX_CONDITION`]).
    pub max_condition: f64,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            dwell: DwellOptions::default(),
            tare_n: [0.0; 3],
            calibrate_support: true,
            friction: true,
            max_chi2_dof: SupportOptions::DEFAULT_MAX_CHI2_DOF,
            max_condition: DEFAULT_MAX_CONDITION,
        }
    }
}

/// Why no result: each message is one line, and where more or other poses
/// help it says which. What the dynamic identification refuses alike is
/// [`InputError`] (the one home of it, [`error`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IdentifyError {
    /// A bad option or recording, an offset d: refused before any fit.
    #[error(transparent)]
    Input(#[from] InputError),
    /// Too few usable poses.
    #[error("{found} static poses found ({why}), at least {needed} needed: {ADD_POSES}")]
    TooFewPoses {
        /// Poses found.
        found: usize,
        /// Poses needed.
        needed: usize,
        /// What was looked for.
        why: String,
    },
    /// More poses than the support fit holds.
    #[error(
        "{found} static poses found, the support fit holds {capacity}: cut the recording, lengthen --min-dwell, or keep the support (--keep-support)"
    )]
    TooManyPoses {
        /// Poses found.
        found: usize,
        /// [`SUPPORT_CAPACITY`].
        capacity: usize,
    },
    /// The poses cannot tell the unknowns apart.
    #[error(
        "the poses cannot be trusted: condition number {condition:.3e} above {limit:.1e} ({what}); {ADD_POSES}"
    )]
    IllConditioned {
        /// The condition number.
        condition: f64,
        /// The limit.
        limit: f64,
        /// Which fit, what it could not tell apart.
        what: String,
    },
    /// The model does not explain the readings.
    #[error(
        "the poses cannot be trusted: chi-square per degree of freedom {chi2_dof:.2} above {limit} (the model does not fit: sensor not tared with the rod detached? an offset d? wrong noise figures? a support that does not pivot about one point?); repeat the procedure and {ADD_POSES}"
    )]
    PoorFit {
        /// chi2 / dof.
        chi2_dof: f64,
        /// The limit.
        limit: f64,
    },
    /// Any other refusal of the estimator.
    #[error("{fit} refused: {reason}; {ADD_POSES}")]
    Fit {
        /// Which fit.
        fit: &'static str,
        /// The estimator's reason.
        reason: String,
    },
}

impl From<sar_record::ReadError> for IdentifyError {
    fn from(e: sar_record::ReadError) -> Self {
        Self::Input(e.into())
    }
}

impl From<sar_record::lean::LeanReadError> for IdentifyError {
    fn from(e: sar_record::lean::LeanReadError) -> Self {
        Self::Input(e.into())
    }
}

/// One pose as used, for the report and the figure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UsedPose {
    /// The dwell it comes from.
    pub dwell: Dwell,
    /// The estimator's pose.
    pub pose: StaticPose,
    /// a = |B - A| at the fitted B, m.
    pub support_distance_m: f64,
    /// F_A measured (-R_0s (f_s - tare)), base frame, N.
    pub measured_n: Vec3,
    /// F_A of the fitted model, base frame, N.
    pub model_n: Vec3,
}

/// The result.
#[derive(Debug, Clone, PartialEq)]
pub struct Identified {
    /// m, kg.
    pub mass_kg: f64,
    /// Its standard error, kg.
    pub mass_std_kg: f64,
    /// c, m.
    pub com_m: f64,
    /// Its standard error, m.
    pub com_std_m: f64,
    /// M = m c, kg m.
    pub moment_kgm: f64,
    /// B, base frame, m (held components: the configured value).
    pub support_m: [f64; 3],
    /// Standard errors of B, m; None for a held component.
    pub support_std_m: [Option<f64>; 3],
    /// B as configured, m.
    pub configured_support_m: [f64; 3],
    /// The friction at the support, N (None: not estimated).
    pub friction_n: Option<f64>,
    /// Its standard error, N.
    pub friction_std_n: Option<f64>,
    /// chi2 / dof.
    pub chi2_dof: f64,
    /// RMS of the force residuals, N.
    pub residual_rms_n: f64,
    /// Condition number of the (column-scaled) problem.
    pub condition: f64,
    /// Poses used.
    pub poses: usize,
    /// Dwells found but left out of the final fit (unknown slide sign with
    /// friction estimated, no sensor sample, a pose the kinematics refuse).
    pub left_out: usize,
    /// What was done, one line.
    pub method: String,
    /// The linear fit at the configured support (step 1).
    pub linear: IdentificationResult,
    /// The poses used, with measured and modelled forces.
    pub used: Vec<UsedPose>,
    /// Gravity, base frame, m/s^2.
    pub gravity_mps2: [f64; 3],
}

/// The joints' and the sensor's dwells of a recording held in memory.
pub fn find_dwells(
    bytes: &[u8],
    config: &Config,
    options: &DwellOptions,
) -> Result<Vec<Dwell>, IdentifyError> {
    find_dwells_in(|| McapReader::new(bytes), config, options)
}

/// The dwells of a recording file, streamed twice (joints, then the
/// sensor): memory holds the dwells, never the file.
pub fn find_dwells_in_file(
    path: &std::path::Path,
    config: &Config,
    options: &DwellOptions,
) -> Result<Vec<Dwell>, IdentifyError> {
    find_dwells_in(|| McapReader::open(path), config, options)
}

/// The dwells, reading the recording twice through `open`.
fn find_dwells_in<'a>(
    open: impl Fn() -> Result<McapReader<'a>, sar_record::ReadError>,
    config: &Config,
    options: &DwellOptions,
) -> Result<Vec<Dwell>, IdentifyError> {
    options.check().map_err(InputError::Option)?;
    let mut finder = DwellFinder::new(&config.estimator.calibration, *options);
    // A lean recording (`[record] mode = "inputs"`) holds the joint and
    // sensor messages in its batches.
    let lean = sar_record::lean::is_lean(open()?);
    if lean {
        for c in sar_record::lean::cycles(open()?) {
            let c = c?;
            if c.joints_message {
                finder.push(c.input.joints_stamp_ns, c.input.joints_q_m);
            }
        }
    }
    for item in open()?.typed::<ActiveJointState>(Topic::Joints.name()) {
        let (_, js) = item?;
        finder.push(js.stamp_ns, js.q_m);
    }
    if finder.seen == 0 {
        return Err(InputError::MissingTopic {
            topic: Topic::Joints.name(),
        }
        .into());
    }
    let mut averager = SensorAverager::new(finder.finish());
    if lean {
        for c in sar_record::lean::cycles(open()?) {
            for w in c?.sensors {
                averager.push(w.stamp_ns, w.force_n);
            }
        }
    }
    for item in open()?.typed::<WrenchStamped>(Topic::SensorWrench.name()) {
        let (_, w) = item?;
        averager.push(w.stamp_ns, w.force_n);
    }
    if averager.seen == 0 {
        return Err(InputError::MissingTopic {
            topic: Topic::SensorWrench.name(),
        }
        .into());
    }
    Ok(averager.finish())
}

/// Identifies m, c (and B, f) from a recording held in memory (see
/// [`identify_file`]).
pub fn identify(
    bytes: &[u8],
    config: &Config,
    options: &IdentifyOptions,
) -> Result<Identified, IdentifyError> {
    let dwells = find_dwells(bytes, config, &options.dwell)?;
    identify_dwells(&dwells, config, options)
}

/// Identifies from a recording file, streamed (`sarctl identify --input`).
pub fn identify_file(
    path: &std::path::Path,
    config: &Config,
    options: &IdentifyOptions,
) -> Result<Identified, IdentifyError> {
    let dwells = find_dwells_in_file(path, config, &options.dwell)?;
    identify_dwells(&dwells, config, options)
}

fn check_options(options: &IdentifyOptions) -> Result<(), InputError> {
    error::check_fit_limits(&options.tare_n, options.max_chi2_dof, options.max_condition)
}

fn dwell_description(o: &DwellOptions) -> String {
    format!(
        "joints still within {} um for at least {} s + {} s settle",
        o.still_tolerance_m * 1e6,
        o.min_dwell_s,
        o.settle_s
    )
}

/// Identifies from dwells already found: the poses of the dwells, the
/// linear fit at the configured support, the support calibration (all of B
/// held when it is kept), and the report of what was used.
pub fn identify_dwells(
    dwells: &[Dwell],
    config: &Config,
    options: &IdentifyOptions,
) -> Result<Identified, IdentifyError> {
    check_options(options)?;
    let est = &config.estimator;
    let cal = &est.calibration;
    error::check_offset(config)?;
    let tare = Vec3::from(options.tare_n);
    let poses = static_poses(dwells, est, options)?;
    // 1. The linear fit at the configured support.
    let fits = Fits { est, tare, options };
    let linear = fits.linear(&poses)?;
    // 2. The support calibration (all of B held when it is kept).
    let usable: Vec<(Dwell, StaticPose)> = poses
        .iter()
        .copied()
        .filter(|(_, p)| !options.friction || p.slide_sign.is_known())
        .collect();
    let left_out = dwells.len() - usable.len();
    let fit = fits.support(&usable)?;
    let method = method(options, usable.len(), &fit);
    let used = used_poses(cal, tare, &fit, &usable);
    Ok(Identified {
        mass_kg: fit.mass_kg,
        mass_std_kg: fit.mass_std_kg,
        com_m: fit.com_m,
        com_std_m: fit.com_std_m,
        moment_kgm: fit.moment_kgm,
        support_m: fit.support_m.into(),
        support_std_m: fit.support_std_m,
        configured_support_m: cal.support_m().into(),
        friction_n: fit.friction_n,
        friction_std_n: fit.friction_std_n,
        chi2_dof: fit.chi2_dof,
        residual_rms_n: fit.residual_rms_n,
        condition: fit.condition,
        poses: usable.len(),
        left_out,
        method,
        linear,
        used,
        gravity_mps2: cal.gravity_mps2().into(),
    })
}

/// The unknowns of the fits besides B: m and M, and f with friction.
fn unknowns(options: &IdentifyOptions) -> usize {
    2 + usize::from(options.friction)
}

/// The static poses of the dwells (A at the mean joints, the mean force);
/// a dwell without a force or a pose is left out. Too few for the
/// unknowns is an error.
fn static_poses(
    dwells: &[Dwell],
    est: &EstimatorConfig,
    options: &IdentifyOptions,
) -> Result<Vec<(Dwell, StaticPose)>, IdentifyError> {
    let mut poses: Vec<(Dwell, StaticPose)> = Vec::new();
    for d in dwells {
        let Some(force) = d.mean_force_n() else {
            continue;
        };
        let Ok(pose) = forward(&est.calibration, &est.profile, &d.joints) else {
            continue;
        };
        poses.push((
            *d,
            StaticPose {
                ujoint_m: pose.ujoint_m,
                mean_reading_n: Vec3::from(force),
                samples: d.sensor_samples,
                slide_sign: d.slide_sign,
            },
        ));
    }
    let unknowns = unknowns(options);
    if poses.len() < unknowns + 1 {
        return Err(IdentifyError::TooFewPoses {
            found: poses.len(),
            needed: unknowns + 1,
            why: dwell_description(&options.dwell),
        });
    }
    Ok(poses)
}

/// A fit whose condition number is above `limit` cannot tell `what`.
fn check_condition(condition: f64, limit: f64, what: &str) -> Result<(), IdentifyError> {
    if condition > limit {
        return Err(IdentifyError::IllConditioned {
            condition,
            limit,
            what: what.into(),
        });
    }
    Ok(())
}

/// What the linear fit cannot tell when it is ill-conditioned.
const LINEAR_CANNOT_TELL: &str = "the linear identification cannot tell m from M and f";

/// What both fits start from: the estimator's configuration (B, g, R_0s,
/// the noise), the tare and the options.
struct Fits<'a> {
    est: &'a EstimatorConfig,
    tare: Vec3,
    options: &'a IdentifyOptions,
}

impl Fits<'_> {
    /// The linear identification of (m, M, f) at the configured support.
    fn linear(&self, poses: &[(Dwell, StaticPose)]) -> Result<IdentificationResult, IdentifyError> {
        let (est, tare, options) = (self.est, self.tare, self.options);
        let fit_error = |reason: String| IdentifyError::Fit {
            fit: "the linear identification",
            reason,
        };
        let mut linear = Identification::new(
            &est.calibration,
            &est.noise,
            tare,
            IdentificationOptions {
                bias_across_gravity: false,
                friction: options.friction,
            },
        )
        .map_err(|e| InputError::Option(e.to_string()))?;
        for (_, p) in poses {
            linear.add(p).map_err(|e| fit_error(e.to_string()))?;
        }
        let linear = linear.solve().map_err(|e| match e {
            IdentificationError::IllConditioned { condition, limit } => {
                IdentifyError::IllConditioned {
                    condition,
                    limit,
                    what: LINEAR_CANNOT_TELL.into(),
                }
            }
            IdentificationError::TooFewRows { poses, needed, .. } => IdentifyError::TooFewPoses {
                found: poses as usize,
                needed: needed.div_ceil(2) as usize,
                why: dwell_description(&options.dwell),
            },
            IdentificationError::NonPositiveMass { mass_kg } => fit_error(format!(
                "it gives a mass of {mass_kg} kg: the poses cannot tell m from M"
            )),
            other => fit_error(other.to_string()),
        })?;
        check_condition(linear.condition, options.max_condition, LINEAR_CANNOT_TELL)?;
        Ok(linear)
    }

    /// The support calibration of (m, M, B, f) over the `usable` poses (those
    /// with a known slide when friction is estimated).
    fn support(&self, usable: &[(Dwell, StaticPose)]) -> Result<SupportFit, IdentifyError> {
        let (est, tare, options) = (self.est, self.tare, self.options);
        if usable.len() > SUPPORT_CAPACITY {
            return Err(IdentifyError::TooManyPoses {
                found: usable.len(),
                capacity: SUPPORT_CAPACITY,
            });
        }
        let fit_error = |reason: String| IdentifyError::Fit {
            fit: "the support calibration",
            reason,
        };
        let support_options = SupportOptions {
            friction: options.friction,
            calibrate_support: options.calibrate_support,
            max_chi2_dof: options.max_chi2_dof,
            ..SupportOptions::default()
        };
        let mut support =
            SupportCalibration::new(&est.calibration, &est.noise, tare, support_options)
                .map_err(|e| InputError::Option(e.to_string()))?;
        for (_, p) in usable {
            support.push(p).map_err(|e| fit_error(e.to_string()))?;
        }
        let fit = support.fit().map_err(|e| match e {
            SupportError::PoorFit { chi2_dof, limit } => IdentifyError::PoorFit { chi2_dof, limit },
            SupportError::TooFewPoses { poses, .. } => IdentifyError::TooFewPoses {
                found: poses,
                needed: unknowns(options) + 1,
                why: format!(
                    "{}, reached by a slide of the rod",
                    dwell_description(&options.dwell)
                ),
            },
            SupportError::Undetermined { unknown, pivot, .. } => IdentifyError::IllConditioned {
                condition: if pivot > 0.0 {
                    1.0 / pivot
                } else {
                    f64::INFINITY
                },
                limit: options.max_condition,
                what: format!("the support calibration cannot determine {unknown}"),
            },
            other => fit_error(other.to_string()),
        })?;
        check_condition(
            fit.condition,
            options.max_condition,
            "the support calibration cannot tell m, M, B and f apart",
        )?;
        Ok(fit)
    }
}

/// The method, as the report names it: the fit, over how many poses, and
/// which components of B were held.
fn method(options: &IdentifyOptions, poses: usize, fit: &SupportFit) -> String {
    if !options.calibrate_support {
        return format!(
            "weighted least squares of (m, M{}) over {} static poses at the configured B (MODEL.md 5)",
            if options.friction { ", f" } else { "" },
            poses
        );
    }
    let names = ["B_x", "B_y", "B_z"];
    let held: Vec<&str> = names
        .iter()
        .zip(fit.held)
        .filter_map(|(n, h)| h.then_some(*n))
        .collect();
    format!(
        "support calibration (MODEL.md 5.1): noise-weighted Levenberg-Marquardt of (m, M, B{}) over {} static poses{}, started from the linear fit at the configured B; {}",
        if options.friction { ", f" } else { "" },
        poses,
        if fit.from_search {
            " (global search start)"
        } else {
            ""
        },
        if held.is_empty() {
            "all of B determined".to_owned()
        } else {
            format!("{} held as configured", held.join(", "))
        }
    )
}

/// Each used pose with the force measured at A and the fitted model's.
fn used_poses(
    cal: &Calibration,
    tare: Vec3,
    fit: &SupportFit,
    usable: &[(Dwell, StaticPose)],
) -> Vec<UsedPose> {
    let g = cal.gravity_mps2();
    usable
        .iter()
        .map(|(d, p)| {
            let measured = sar_estimator::ujoint_force_n(cal, &p.mean_reading_n, &tare);
            let r = fit.support_m - p.ujoint_m;
            let a = r.norm();
            let u = r / a;
            let sigma = p.slide_sign.sigma().unwrap_or(0.0);
            let model = -g * fit.mass_kg
                + (g - u * g.dot(&u)) * (fit.moment_kgm / a)
                + u * (sigma * fit.friction_n.unwrap_or(0.0));
            UsedPose {
                dwell: *d,
                pose: *p,
                support_distance_m: a,
                measured_n: measured,
                model_n: model,
            }
        })
        .collect()
}

impl Identified {
    /// The JSON object of INTERFACES.md 3 (and a few more keys).
    pub fn to_json(&self, written: Option<&str>) -> serde_json::Value {
        json!({
            "mass_kg": self.mass_kg,
            "com_m": self.com_m,
            "mass_std_kg": self.mass_std_kg,
            "com_std_m": self.com_std_m,
            "support_m": self.support_m,
            "support_std_m": self.support_std_m,
            "support_held": self.support_std_m.map(|s| s.is_none()),
            "configured_support_m": self.configured_support_m,
            "friction_n": self.friction_n,
            "friction_std_n": self.friction_std_n,
            "chi2_dof": self.chi2_dof,
            "poses": self.poses,
            "poses_left_out": self.left_out,
            "residual_rms_n": self.residual_rms_n,
            "condition": self.condition,
            "method": self.method,
            "written": written,
        })
    }

    /// The human report, several lines.
    pub fn to_text(&self, written: Option<&str>) -> String {
        let b: Vec<String> = self
            .support_m
            .iter()
            .zip(self.support_std_m)
            .zip(self.configured_support_m)
            .zip(["x", "y", "z"])
            .map(|(((b, s), c), n)| match s {
                Some(s) => format!(
                    "  B_{n} = {b:.5} +- {s:.5} m (configured {c:.5}, moved {:+.2} mm)",
                    (b - c) * 1e3
                ),
                None => format!(
                    "  B_{n} = {b:.5} m held (as configured: the poses do not determine it)"
                ),
            })
            .collect();
        let friction = match (self.friction_n, self.friction_std_n) {
            (Some(f), Some(s)) => format!("friction f = {f:.3} +- {s:.3} N"),
            _ => "friction not estimated".to_owned(),
        };
        let written = match written {
            Some(path) => format!(
                "written to {path}: manipulator.mass_kg, manipulator.com_m, geometry.support"
            ),
            None => "dry run: the configuration is unchanged".to_owned(),
        };
        format!(
            "mass  m = {:.4} +- {:.4} kg\ncentre c = {:.5} +- {:.5} m\nsupport:\n{}\n{friction}\nchi2/dof {:.2}, residual RMS {:.3} N, condition {:.1}, {} poses ({} left out)\nmethod: {}\n{written}",
            self.mass_kg,
            self.mass_std_kg,
            self.com_m,
            self.com_std_m,
            b.join("\n"),
            self.chi2_dof,
            self.residual_rms_n,
            self.condition,
            self.poses,
            self.left_out,
            self.method
        )
    }
}
