//! `sarctl identify --dynamic`'s pure parts (MODEL.md 10, issue 26 section 3):
//! the rod's inertia I_perp, with m and c again, from a recording of an
//! excitation motion with the tip free.
//!
//! 1. `/sar/joints` is smoothed without phase lag ([`super::smooth`], a
//!    centred Savitzky–Golay of order 6 over 0.2 s that keeps the
//!    acceleration's gain) into q, q', q'' per joint sample;
//! 2. at each `/sar/sensor/wrench` sample's stamp (less the sensor's
//!    latency) they are interpolated linearly between the two neighbouring
//!    joint samples, giving A, A', A'' (A = P_home + (q3, q2, q1) + a_off);
//! 3. each sample feeds the estimator's accumulator
//!    ([`sar_estimator::identification::dynamic`]): (m, M, J_A), the
//!    support's friction f unless `--no-friction` and the adapter's mass m_s
//!    between the sensor and the U-joint unless `--adapter-mass-kg` gives it
//!    (issue 34: an adapter left out of the configuration read as +28 % on
//!    I_perp), weighted by the sensor's noise; I_perp = J_A - M^2 / m.
//!
//! A recording whose carriage never accelerates is refused ("the recording
//! holds no excitation"), and so is a fit whose condition number is above
//! the limit.

use super::error::{self, InputError};
use super::smooth::{self, Smoothed, SmootherSpec};
use sar_config::Config;
use sar_estimator::identification::IdentificationError;
use sar_estimator::identification::dynamic::{DynamicIdentification, DynamicResult, MotionSample};
use sar_estimator::{Calibration, Vec3};
use sar_msgs::msgs::{ActiveJointState, GuardEvent, GuardStateCode, Topic, WrenchStamped};
use sar_record::McapReader;
use serde_json::json;

/// Default largest condition number of the dynamic fit (column-scaled), the
/// static identification's ([`super::DEFAULT_MAX_CONDITION`], one
/// `--max-condition` for both): an excitation of the README gives about 7.
pub const DEFAULT_MAX_CONDITION: f64 = super::DEFAULT_MAX_CONDITION;

/// Default smallest peak acceleration of the carriage that counts as an
/// excitation, m/s^2 (the excitation of the README reaches 0.4).
pub const DEFAULT_MIN_PEAK_ACCEL_MPS2: f64 = 0.05;

/// Samples of the fit kept for the figure (evenly spaced).
const FIGURE_POINTS: usize = 4000;

/// How to identify the inertia.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicOptions {
    /// The sensor's force bias measured with the rod detached (sensor frame, N).
    pub tare_n: [f64; 3],
    /// The encoders' smoother.
    pub smoother: SmootherSpec,
    /// The sensor's latency: a sample's stamp less this is when it was
    /// measured, s.
    pub sensor_latency_s: f64,
    /// The mass between the sensor and the U-joint, kg: held there, or
    /// where the estimate of it starts (`estimate_adapter`).
    pub adapter_mass_kg: f64,
    /// Estimate the adapter's mass (the default; `--adapter-mass-kg` holds it).
    pub estimate_adapter: bool,
    /// Estimate the support's Coulomb friction.
    pub friction: bool,
    /// Largest accepted condition number.
    pub max_condition: f64,
    /// Largest accepted chi-square per degree of freedom.
    pub max_chi2_dof: f64,
    /// Smallest peak acceleration that counts as an excitation, m/s^2.
    pub min_peak_accel_mps2: f64,
}

impl Default for DynamicOptions {
    fn default() -> Self {
        Self {
            tare_n: [0.0; 3],
            smoother: SmootherSpec::default(),
            sensor_latency_s: 0.0,
            adapter_mass_kg: 0.0,
            estimate_adapter: true,
            friction: true,
            max_condition: DEFAULT_MAX_CONDITION,
            max_chi2_dof: super::SupportOptions::DEFAULT_MAX_CHI2_DOF,
            min_peak_accel_mps2: DEFAULT_MIN_PEAK_ACCEL_MPS2,
        }
    }
}

/// Why no result: one line each. What the static identification refuses
/// alike is [`InputError`] (its one home, [`super::error`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DynamicError {
    /// A bad option or recording, an offset d: refused before any fit.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The joints could not be smoothed, or no sensor sample lies inside them.
    #[error("the joints cannot give the carriage's acceleration: {0}")]
    Smoothing(String),
    /// The carriage never accelerates.
    #[error(
        "the recording holds no excitation: the carriage's largest acceleration is {peak_mps2:.3} m/s^2, below {min_mps2} m/s^2; record sines per axis with the tip free (sarctl identify --dynamic --live, README)"
    )]
    NoExcitation {
        /// The largest |A''| over the samples, m/s^2.
        peak_mps2: f64,
        /// The limit.
        min_mps2: f64,
    },
    /// The fit cannot tell the unknowns apart.
    #[error(
        "the excitation cannot tell m, m c and the inertia apart: condition number {condition:.3e} above {limit:.1e}; excite every axis with sines of distinct frequencies, the rod's direction sweeping (README)"
    )]
    IllConditioned {
        /// The condition number (may be infinite).
        condition: f64,
        /// The limit.
        limit: f64,
    },
    /// The model does not explain the readings.
    #[error(
        "the model in motion does not fit the recording: chi-square per degree of freedom {chi2_dof:.2} above {limit} (the support B off? the sensor not tared with the rod detached? an offset d? the sensor's latency? a contact at the tip?); calibrate the support (sarctl identify) and record the excitation again"
    )]
    PoorFit {
        /// chi2 / dof.
        chi2_dof: f64,
        /// The limit.
        limit: f64,
    },
    /// The inertia came out not positive: the motion does not show it.
    #[error(
        "the fit gives I_perp = {inertia_kgm2:.5} +- {std_kgm2:.5} kg m^2, not positive: the motion does not show the rod's inertia; excite every axis with sines of distinct frequencies, the rod turning (README)"
    )]
    NonPositiveInertia {
        /// I_perp, kg m^2.
        inertia_kgm2: f64,
        /// Its standard error, kg m^2.
        std_kgm2: f64,
    },
    /// Any other refusal of the estimator.
    #[error("the dynamic identification refused: {0}")]
    Fit(IdentificationError),
    /// A recorded sample is not finite.
    #[error(
        "{topic}: sample {index} (stamped {stamp_ns} ns) is not finite ({what}): a reading the device did not give (the loop faults on it); identify --dynamic refuses the recording rather than guess around it"
    )]
    NonFinite {
        /// The topic.
        topic: &'static str,
        /// The sample's place in the recording (0: the first).
        index: usize,
        /// Its stamp, ns.
        stamp_ns: u64,
        /// Its values.
        what: String,
    },
    /// The stamps of a topic go back.
    #[error(
        "{topic}: sample {index} is stamped {stamp_ns} ns, before the sample recorded ahead of it ({previous_ns} ns): the stamps go back (the device's clock, or a corrupt recording); identify --dynamic needs them in time order"
    )]
    StampsBack {
        /// The topic.
        topic: &'static str,
        /// The sample's place in the recording.
        index: usize,
        /// Its stamp, ns.
        stamp_ns: u64,
        /// The stamp before it, ns.
        previous_ns: u64,
    },
    /// The sensor's stamps are not on a regular grid.
    #[error(
        "{topic}: {irregular} of {steps} stamp steps differ from the median step ({median_ms} ms) by more than half of it (the largest, {worst_ms} ms, after sample {at}): the stamps are not when the samples were measured (the device's clock, or the recording); identify --dynamic interpolates the joints at them"
    )]
    IrregularStamps {
        /// The topic.
        topic: &'static str,
        /// Steps off the grid.
        irregular: usize,
        /// Steps in all.
        steps: usize,
        /// The median step, ms.
        median_ms: sar_kinematics::Shown,
        /// The step furthest from it, ms.
        worst_ms: sar_kinematics::Shown,
        /// The sample before that step.
        at: usize,
    },
    /// More samples than an excitation's recording holds.
    #[error(
        "the recording holds more than {limit} {topic} samples (over an hour at 1 kHz): identify --dynamic reads the recording of one excitation, a few minutes"
    )]
    TooLong {
        /// The topic.
        topic: &'static str,
        /// [`MAX_SERIES_SAMPLES`].
        limit: usize,
    },
    /// The guard left Ok during the samples fitted: what follows is a
    /// braking, a contact or a fault, not the excitation.
    #[error(
        "the guard went from Ok to {state} ({reason}) at cycle {cycle}, {at_s} s into the samples fitted: the excitation did not run to its end with the tip free (a quick stop's braking, a contact or a fault follows, and the readings after it cannot be trusted); reset and record the excitation again (sarctl identify --dynamic --live)"
    )]
    GuardLeftOk {
        /// The state entered.
        state: &'static str,
        /// Why.
        reason: &'static str,
        /// The cycle.
        cycle: u64,
        /// When, from the first sample fitted, s.
        at_s: sar_kinematics::Shown,
    },
}

/// The most samples of a topic read for one identification (about 67
/// minutes of a 1 kHz sensor; 128 MB of samples): a crafted recording of
/// highly compressed messages cannot make the reader hold more.
pub const MAX_SERIES_SAMPLES: usize = 4_000_000;

/// A step off the grid differs from the median step by more than this
/// fraction of it.
pub const MAX_SENSOR_STEP_JITTER: f64 = 0.5;

/// The largest share of the sensor's stamp steps off the grid accepted
/// (sample losses, a busy host's bunched packets).
pub const MAX_IRREGULAR_SHARE: f64 = 0.1;

impl From<IdentificationError> for DynamicError {
    fn from(e: IdentificationError) -> Self {
        match e {
            IdentificationError::IllConditioned { condition, limit } => {
                Self::IllConditioned { condition, limit }
            }
            other => Self::Fit(other),
        }
    }
}

impl From<sar_record::ReadError> for DynamicError {
    fn from(e: sar_record::ReadError) -> Self {
        Self::Input(e.into())
    }
}

impl From<sar_record::lean::LeanReadError> for DynamicError {
    fn from(e: sar_record::lean::LeanReadError) -> Self {
        Self::Input(e.into())
    }
}

/// One sample of the fit kept for the figure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitPoint {
    /// Time since the first sample, s.
    pub t_s: f64,
    /// F_A measured (adapter removed), base frame, N.
    pub measured_n: Vec3,
    /// F_A of the fitted model, base frame, N.
    pub model_n: Vec3,
    /// The carriage's acceleration, m/s^2.
    pub accel_mps2: Vec3,
}

/// The result.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicIdentified {
    /// The estimator's result.
    pub fit: DynamicResult,
    /// Sensor samples outside the smoothed joints (the first and last
    /// 0.1 s, gaps), left out.
    pub left_out: usize,
    /// The largest |A''| over the samples used, m/s^2.
    pub peak_accel_mps2: f64,
    /// The joints' sample period, s.
    pub joints_period_s: f64,
    /// What was done, one line.
    pub method: String,
    /// Evenly spaced samples of the fit, for the figure.
    pub points: Vec<FitPoint>,
}

/// The recording's joints and sensor forces, in stamp order, and the
/// guard's transitions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// (stamp ns, q1, q2, q3 m).
    pub joints: Vec<(u64, [f64; 3])>,
    /// (stamp ns, force in the sensor frame N).
    pub sensor: Vec<(u64, [f64; 3])>,
    /// The guard's transitions (`/sar/guard/events`), as recorded.
    pub guard: Vec<GuardEvent>,
}

/// Appends `item` to `v`, up to [`MAX_SERIES_SAMPLES`].
fn push_bounded<T>(v: &mut Vec<T>, item: T, topic: &'static str) -> Result<(), DynamicError> {
    if v.len() >= MAX_SERIES_SAMPLES {
        return Err(DynamicError::TooLong {
            topic,
            limit: MAX_SERIES_SAMPLES,
        });
    }
    v.push(item);
    Ok(())
}

/// Refuses a non-finite sample or a stamp that goes back, as recorded
/// (before they are sorted), naming the sample.
fn check_recorded(v: &[(u64, [f64; 3])], topic: &'static str) -> Result<(), DynamicError> {
    let mut previous: Option<u64> = None;
    for (index, &(stamp_ns, x)) in v.iter().enumerate() {
        if !x.iter().all(|c| c.is_finite()) {
            return Err(DynamicError::NonFinite {
                topic,
                index,
                stamp_ns,
                what: sar_kinematics::ShownAll(&x).to_string(),
            });
        }
        if let Some(previous_ns) = previous
            && stamp_ns < previous_ns
        {
            return Err(DynamicError::StampsBack {
                topic,
                index,
                stamp_ns,
                previous_ns,
            });
        }
        previous = Some(stamp_ns);
    }
    Ok(())
}

/// Refuses sensor stamps off a regular grid: more than
/// [`MAX_IRREGULAR_SHARE`] of the steps (ascending, distinct stamps)
/// differ from the median step by more than [`MAX_SENSOR_STEP_JITTER`] of
/// it (a clock shifted on every other sample; lost samples and a busy
/// host's bunched packets stay below).
fn check_grid(v: &[(u64, [f64; 3])], topic: &'static str) -> Result<(), DynamicError> {
    let steps: Vec<u64> = v
        .windows(2)
        .filter_map(|w| Some(w.get(1)?.0 - w.first()?.0))
        .collect();
    let mut sorted = steps.clone();
    sorted.sort_unstable();
    let Some(&median) = sorted.get(sorted.len() / 2) else {
        return Ok(());
    };
    let median = median as f64;
    let off = |step: u64| (step as f64 - median).abs();
    let irregular = steps
        .iter()
        .filter(|s| off(**s) > MAX_SENSOR_STEP_JITTER * median)
        .count();
    if (irregular as f64) <= MAX_IRREGULAR_SHARE * steps.len() as f64 {
        return Ok(());
    }
    let (at, worst) = steps
        .iter()
        .enumerate()
        .max_by(|a, b| off(*a.1).total_cmp(&off(*b.1)))
        .map_or((0, 0), |(i, s)| (i, *s));
    Err(DynamicError::IrregularStamps {
        topic,
        irregular,
        steps: steps.len(),
        median_ms: sar_kinematics::Shown(median * 1e-6),
        worst_ms: sar_kinematics::Shown(worst as f64 * 1e-6),
        at,
    })
}

/// Refuses samples fitted across the guard leaving Ok (a Warn, a Stop, a
/// Fault, a Retreat: a contact or a fault, and the drives' quick stop)
/// between the first and the last sample fitted (`t0_ns..=t1_ns`).
fn check_guard(guard: &[GuardEvent], t0_ns: u64, t1_ns: u64) -> Result<(), DynamicError> {
    let left = guard.iter().find(|e| {
        (t0_ns..=t1_ns).contains(&e.stamp_ns)
            && e.from_state == GuardStateCode::Ok
            && e.to_state != GuardStateCode::Ok
    });
    let Some(e) = left else {
        return Ok(());
    };
    Err(DynamicError::GuardLeftOk {
        state: sar_msgs::wire::guard_state_name(u32::from(e.to_state.code())),
        reason: sar_msgs::wire::reason_name(u32::from(e.reason_code)),
        cycle: e.cycle,
        at_s: sar_kinematics::Shown(e.stamp_ns.saturating_sub(t0_ns) as f64 * 1e-9),
    })
}

/// Reads the joints and the sensor's forces of a recording file (full or lean).
pub fn read_series(path: &std::path::Path) -> Result<Series, DynamicError> {
    let open = || McapReader::open(path);
    let mut s = Series::default();
    let (joints, sensor) = (Topic::Joints.name(), Topic::SensorWrench.name());
    if sar_record::lean::is_lean(open()?) {
        for c in sar_record::lean::cycles(open()?) {
            let c = c?;
            if c.joints_message {
                let j = (c.input.joints_stamp_ns, c.input.joints_q_m);
                push_bounded(&mut s.joints, j, joints)?;
            }
            for w in &c.sensors {
                push_bounded(&mut s.sensor, (w.stamp_ns, w.force_n), sensor)?;
            }
        }
    }
    for item in open()?.typed::<ActiveJointState>(joints) {
        let (_, js) = item?;
        push_bounded(&mut s.joints, (js.stamp_ns, js.q_m), joints)?;
    }
    for item in open()?.typed::<WrenchStamped>(sensor) {
        let (_, w) = item?;
        push_bounded(&mut s.sensor, (w.stamp_ns, w.force_n), sensor)?;
    }
    for item in open()?.typed::<GuardEvent>(Topic::GuardEvents.name()) {
        let (_, e) = item?;
        push_bounded(&mut s.guard, e, Topic::GuardEvents.name())?;
    }
    for (v, topic) in [(&mut s.joints, joints), (&mut s.sensor, sensor)] {
        if v.is_empty() {
            return Err(InputError::MissingTopic { topic }.into());
        }
        // As recorded: finite, in time order (a sample recorded twice, at
        // the same stamp, once).
        check_recorded(v, topic)?;
        v.dedup_by_key(|x| x.0);
    }
    check_grid(&s.sensor, sensor)?;
    Ok(s)
}

/// Identifies from a recording file (`sarctl identify --dynamic --input`).
pub fn identify_file(
    path: &std::path::Path,
    config: &Config,
    options: &DynamicOptions,
) -> Result<DynamicIdentified, DynamicError> {
    identify_series(&read_series(path)?, config, options)
}

fn check_options(config: &Config, o: &DynamicOptions) -> Result<(), InputError> {
    error::check_offset(config)?;
    error::check_fit_limits(&o.tare_n, o.max_chi2_dof, o.max_condition)?;
    let bad = |what: &str, x: f64| InputError::Option(format!("{what} {x} is out of range"));
    if !(o.sensor_latency_s.is_finite() && o.sensor_latency_s >= 0.0) {
        return Err(bad("the sensor latency (s, >= 0)", o.sensor_latency_s));
    }
    if !(o.adapter_mass_kg.is_finite() && o.adapter_mass_kg >= 0.0) {
        return Err(bad("the adapter mass (kg, >= 0)", o.adapter_mass_kg));
    }
    if !(o.min_peak_accel_mps2.is_finite() && o.min_peak_accel_mps2 >= 0.0) {
        return Err(bad(
            "the excitation's least peak acceleration (m/s^2, >= 0)",
            o.min_peak_accel_mps2,
        ));
    }
    Ok(())
}

/// A, A', A'' ({0}) from smoothed joints: A = P_home + (q3, q2, q1) + a_off.
fn carriage(cal: &Calibration, s: &Smoothed) -> (Vec3, Vec3, Vec3) {
    let swap = |q: [f64; 3]| Vec3::new(q[2], q[1], q[0]);
    (
        cal.p_home_m() + swap(s.q_m) + cal.ujoint_offset_m(),
        swap(s.v_mps),
        swap(s.a_mps2),
    )
}

/// Identifies from a recording's joints and sensor forces.
pub fn identify_series(
    series: &Series,
    config: &Config,
    options: &DynamicOptions,
) -> Result<DynamicIdentified, DynamicError> {
    check_options(config, options)?;
    check_recorded(&series.joints, Topic::Joints.name())?;
    check_recorded(&series.sensor, Topic::SensorWrench.name())?;
    check_grid(&series.sensor, Topic::SensorWrench.name())?;
    let est = &config.estimator;
    let cal = &est.calibration;
    let (smoothed, period_s) =
        smooth::smooth(&series.joints, &options.smoother).map_err(DynamicError::Smoothing)?;
    let latency_ns = (options.sensor_latency_s * 1e9).round() as u64;
    let mut id = new_fit(config, options)?;
    let mut used: Vec<MotionSample> = Vec::new();
    let mut stamps: Vec<u64> = Vec::new();
    let mut hint = 0;
    for &(stamp_ns, force) in &series.sensor {
        let measured_ns = stamp_ns.saturating_sub(latency_ns);
        let Some(s) = smooth::interpolate(&smoothed, measured_ns, period_s, &mut hint) else {
            continue;
        };
        let (a, v, acc) = carriage(cal, &s);
        let sample = MotionSample {
            ujoint_m: a,
            velocity_mps: v,
            accel_mps2: acc,
            reading_n: Vec3::from(force),
        };
        id.add(&sample)?;
        used.push(sample);
        stamps.push(measured_ns);
    }
    if let (Some(&t0), Some(&t1)) = (stamps.first(), stamps.last()) {
        check_guard(&series.guard, t0, t1)?;
    }
    if used.is_empty() {
        return Err(DynamicError::Smoothing(format!(
            "no sensor sample lies within the smoothed joints ({} joint samples, {} sensor samples)",
            series.joints.len(),
            series.sensor.len()
        )));
    }
    let peak = used.iter().map(|s| s.accel_mps2.norm()).fold(0.0, f64::max);
    if peak < options.min_peak_accel_mps2 {
        return Err(DynamicError::NoExcitation {
            peak_mps2: peak,
            min_mps2: options.min_peak_accel_mps2,
        });
    }
    let fit = id.solve(options.max_condition)?;
    check_fit(&fit, options)?;
    let points = figure_points(&id, &fit, &used, &stamps)?;
    Ok(DynamicIdentified {
        fit,
        left_out: series.sensor.len() - used.len(),
        peak_accel_mps2: peak,
        joints_period_s: period_s,
        method: method(options, used.len()),
        points,
    })
}

/// The empty fit of `options`: the tare, the adapter held or estimated,
/// the friction or not.
fn new_fit(
    config: &Config,
    options: &DynamicOptions,
) -> Result<DynamicIdentification, DynamicError> {
    let est = &config.estimator;
    let id = DynamicIdentification::new(
        &est.calibration,
        &est.noise,
        Vec3::from(options.tare_n),
        options.adapter_mass_kg,
        options.friction,
    )?;
    Ok(if options.estimate_adapter {
        id.estimating_adapter()
    } else {
        id
    })
}

/// Refuses an inertia that is not positive, then a poor fit.
fn check_fit(fit: &DynamicResult, options: &DynamicOptions) -> Result<(), DynamicError> {
    if fit.inertia_perp_kgm2 <= 0.0 {
        return Err(DynamicError::NonPositiveInertia {
            inertia_kgm2: fit.inertia_perp_kgm2,
            std_kgm2: fit.inertia_perp_std_kgm2,
        });
    }
    if fit.chi2_dof > options.max_chi2_dof {
        return Err(DynamicError::PoorFit {
            chi2_dof: fit.chi2_dof,
            limit: options.max_chi2_dof,
        });
    }
    Ok(())
}

fn method(o: &DynamicOptions, samples: usize) -> String {
    format!(
        "noise-weighted least squares of (m, m c, J_A = I_perp + m c^2{}{}) over {samples} sensor samples' force rows (MODEL.md 10, d = 0), A'' from the encoders smoothed by a centred polynomial of order {} over {} s",
        if o.friction { ", f" } else { "" },
        if o.estimate_adapter { ", m_s" } else { "" },
        o.smoother.order,
        o.smoother.span_s
    )
}

/// Evenly spaced samples with the measured and the fitted F_A, as the
/// identification itself gives them ([`DynamicIdentification::forces`]: its
/// own rows at its result, not a second model here).
fn figure_points(
    id: &DynamicIdentification,
    fit: &DynamicResult,
    used: &[MotionSample],
    stamps: &[u64],
) -> Result<Vec<FitPoint>, DynamicError> {
    let step = used.len().div_ceil(FIGURE_POINTS).max(1);
    let t0 = stamps.first().copied().unwrap_or(0);
    let mut out = Vec::new();
    for (s, &t) in used.iter().zip(stamps).step_by(step) {
        let forces = id.forces(s, fit)?;
        out.push(FitPoint {
            t_s: t.saturating_sub(t0) as f64 * 1e-9,
            measured_n: forces.measured_n,
            model_n: forces.model_n,
            accel_mps2: s.accel_mps2,
        });
    }
    Ok(out)
}

impl DynamicIdentified {
    /// The JSON object (README, `identify --dynamic`).
    pub fn to_json(&self, written: Option<&str>) -> serde_json::Value {
        let f = &self.fit;
        json!({
            "inertia_perp_kgm2": f.inertia_perp_kgm2,
            "inertia_perp_std_kgm2": f.inertia_perp_std_kgm2,
            "expected_inertia_perp_std_kgm2": f.inertia_perp_model_std_kgm2,
            "inertia_a_kgm2": f.inertia_a_kgm2,
            "mass_kg": f.mass_kg,
            "mass_std_kg": f.mass_std_kg,
            "com_m": f.com_m,
            "com_std_m": f.com_std_m,
            "friction_n": f.friction_n,
            "friction_std_n": f.friction_std_n,
            "adapter_mass_kg": f.adapter_mass_kg,
            "adapter_mass_std_kg": f.adapter_mass_std_kg,
            "adapter_correlation": f.adapter_correlation,
            "chi2_dof": f.chi2_dof,
            "condition": f.condition,
            "residual_rms_n": f.residual_rms_n,
            "samples": f.samples,
            "samples_left_out": self.left_out,
            "peak_accel_mps2": self.peak_accel_mps2,
            "method": self.method,
            "written": written,
        })
    }

    /// The human report, several lines.
    pub fn to_text(&self, written: Option<&str>) -> String {
        let f = &self.fit;
        let pct = |s: f64, x: f64| 100.0 * s / x.abs();
        let friction = match (f.friction_n, f.friction_std_n) {
            (Some(x), Some(s)) => format!("friction f = {x:.3} +- {s:.3} N"),
            _ => "friction not estimated".to_owned(),
        };
        let adapter = match (f.adapter_mass_std_kg, f.adapter_correlation) {
            (Some(s), Some(r)) => format!(
                "adapter m_s = {:.4} +- {s:.4} kg (its largest correlation with the others {r:.2}){}",
                f.adapter_mass_kg,
                if f.adapter_mass_kg < 0.0 {
                    "; written as 0"
                } else {
                    ""
                }
            ),
            _ => format!(
                "adapter m_s held at {} kg (--adapter-mass-kg)",
                f.adapter_mass_kg
            ),
        };
        let written = match written {
            Some(path) => format!(
                "written to {path}: manipulator.inertia_perp_kgm2, manipulator.inertia_perp_std_kgm2{}",
                if f.adapter_mass_std_kg.is_some() {
                    ", sensor.adapter_mass_kg"
                } else {
                    ""
                }
            ),
            None => "dry run: the configuration is unchanged".to_owned(),
        };
        format!(
            "inertia I_perp = {:.5} +- {:.5} kg m^2 ({:.2} %; the excitation promised {:.2} %)\nmass  m = {:.4} +- {:.4} kg\ncentre c = {:.5} +- {:.5} m\n{adapter}\n{friction}\nchi2/dof {:.2}, residual RMS {:.3} N, condition {:.1}, {} samples ({} left out), peak acceleration {:.3} m/s^2\nmethod: {}\n{written}",
            f.inertia_perp_kgm2,
            f.inertia_perp_std_kgm2,
            pct(f.inertia_perp_std_kgm2, f.inertia_perp_kgm2),
            pct(f.inertia_perp_model_std_kgm2, f.inertia_perp_kgm2),
            f.mass_kg,
            f.mass_std_kg,
            f.com_m,
            f.com_std_m,
            f.chi2_dof,
            f.residual_rms_n,
            f.condition,
            f.samples,
            self.left_out,
            self.peak_accel_mps2,
            self.method
        )
    }
}
