//! The excitation of `sarctl identify --dynamic` (MODEL.md 10, issue 26
//! section 3): a sine per axis around a centre pose, of distinct frequencies,
//! faded in and out by a raised cosine so that it starts and ends at rest,
//! scaled so that no axis exceeds the excitation's own speed, acceleration
//! and jerk limits (their peaks over the whole run, fades included, by the
//! loop's own bound, [`sar_loop::excite::unit_peaks`]: what is planned here
//! the loop accepts), and checked inside the travel. [`Excitation::plan`]
//! gives, before anything moves, the condition number and the standard
//! errors that the fit will have: the covariance of the least squares on the
//! planned trajectory with the sensor's noise (noise-free readings of the
//! configured rod, I_perp the slender rod's m L^2 / 12 unless given).
//!
//! The default (about manipulator 2's nominal pose): a slow sweep of up to
//! 8 cm along the rod's direction (q3, 0.07 Hz: the support distance
//! varies, which tells m from m c as the static poses do) and faster sines
//! across it (q1 at 1.3 Hz, q2 at 1.7 Hz: the rod turns, which tells the
//! inertia), each at up to the speed limit.

use sar_config::Config;
use sar_estimator::identification::dynamic::{
    DynamicIdentification, DynamicResult, InertialParameters, MotionSample, model_force_n,
    rod_motion,
};
use sar_estimator::tip_force::TipForceEstimator;
use sar_estimator::{Calibration, Vec3};

/// One axis's sine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisSine {
    /// Frequency, Hz (> 0).
    pub freq_hz: f64,
    /// The largest amplitude wanted, m (the plan may scale it down).
    pub amplitude_m: f64,
}

/// The excitation's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExcitationSpec {
    /// The centre pose, joints (q1, q2, q3), m.
    pub centre_m: [f64; 3],
    /// The sine of q1, q2, q3.
    pub sines: [AxisSine; 3],
    /// Duration, s, with the fades.
    pub duration_s: f64,
    /// Fade in and out, s each.
    pub fade_s: f64,
    /// Largest joint speed, m/s.
    pub max_speed_mps: f64,
    /// Largest joint acceleration, m/s^2.
    pub max_accel_mps2: f64,
    /// Largest joint jerk, m/s^3.
    pub max_jerk_mps3: f64,
}

impl ExcitationSpec {
    /// The default sines about `centre_m` (see the module's doc) under the
    /// limits `(speed m/s, acceleration m/s^2, jerk m/s^3)`.
    pub fn around(
        centre_m: [f64; 3],
        duration_s: f64,
        (max_speed_mps, max_accel_mps2, max_jerk_mps3): (f64, f64, f64),
    ) -> Self {
        Self {
            centre_m,
            sines: [
                AxisSine {
                    freq_hz: 1.3,
                    amplitude_m: 0.01,
                },
                AxisSine {
                    freq_hz: 1.7,
                    amplitude_m: 0.01,
                },
                AxisSine {
                    freq_hz: 0.07,
                    amplitude_m: 0.08,
                },
            ],
            duration_s,
            fade_s: 3.0,
            max_speed_mps,
            max_accel_mps2,
            max_jerk_mps3,
        }
    }
}

/// A planned excitation: the amplitudes after scaling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excitation {
    /// The settings.
    pub spec: ExcitationSpec,
    /// Each axis's amplitude as planned, m.
    pub amplitude_m: [f64; 3],
    /// Each axis's peak speed as planned, m/s.
    pub peak_speed_mps: [f64; 3],
    /// Each axis's peak acceleration as planned, m/s^2.
    pub peak_accel_mps2: [f64; 3],
}

/// Position offset, speed and acceleration of one axis of unit amplitude at
/// `t`: the loop's own formula ([`sar_loop::excite::unit_axis`]), so that
/// the plan printed and checked here is the motion the loop runs.
fn unit_axis(t: f64, freq_hz: f64, spec: &ExcitationSpec) -> (f64, f64, f64) {
    sar_loop::excite::unit_axis(t, freq_hz, spec.duration_s, spec.fade_s)
}

impl Excitation {
    /// Scales each axis's amplitude down to its speed, acceleration and
    /// jerk limits (its peaks over the whole run, fades included: the
    /// loop's [`sar_loop::excite::unit_peaks`]) and checks the sweep in the
    /// configured travel.
    pub fn plan(spec: &ExcitationSpec, config: &Config) -> Result<Self, String> {
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !(ok(spec.duration_s)
            && ok(spec.fade_s)
            && 2.0 * spec.fade_s <= spec.duration_s
            && ok(spec.max_speed_mps)
            && ok(spec.max_accel_mps2)
            && ok(spec.max_jerk_mps3))
        {
            return Err(format!(
                "the excitation needs a duration of at least two fades ({} s, fade {} s) and positive limits ({} m/s, {} m/s^2, {} m/s^3)",
                spec.duration_s,
                spec.fade_s,
                spec.max_speed_mps,
                spec.max_accel_mps2,
                spec.max_jerk_mps3
            ));
        }
        let mut amplitude_m = [0.0; 3];
        let mut peak_speed_mps = [0.0; 3];
        let mut peak_accel_mps2 = [0.0; 3];
        let travel = config.axes.travel_m;
        for i in 0..3 {
            let (Some(sine), Some(centre), Some(range)) =
                (spec.sines.get(i), spec.centre_m.get(i), travel.get(i))
            else {
                continue;
            };
            if !(ok(sine.freq_hz) && sine.amplitude_m.is_finite() && sine.amplitude_m >= 0.0) {
                return Err(format!(
                    "axis q{}: frequency and amplitude out of range",
                    i + 1
                ));
            }
            let [v, a, j] = sar_loop::excite::unit_peaks(sine.freq_hz, spec.fade_s);
            let amp = sine
                .amplitude_m
                .min(spec.max_speed_mps / v)
                .min(spec.max_accel_mps2 / a)
                .min(spec.max_jerk_mps3 / j);
            let (lo, hi) = *range;
            if centre - amp < lo || centre + amp > hi {
                return Err(format!(
                    "axis q{}: the excitation {centre} +- {amp:.4} m leaves the travel [{lo}, {hi}] m",
                    i + 1
                ));
            }
            if let (Some(x), Some(pv), Some(pa)) = (
                amplitude_m.get_mut(i),
                peak_speed_mps.get_mut(i),
                peak_accel_mps2.get_mut(i),
            ) {
                (*x, *pv, *pa) = (amp, amp * v, amp * a);
            }
        }
        Ok(Self {
            spec: *spec,
            amplitude_m,
            peak_speed_mps,
            peak_accel_mps2,
        })
    }

    /// The loop's own judgement of this excitation about its centre
    /// ([`sar_loop::excite::judge`], with the configuration's limits: the
    /// drives' speed, the loop's period, the travel), before anything
    /// moves: `Err` is the refusal the loop would give, in its words.
    pub fn judged_by_the_loop(&self, config: &Config) -> Result<(), String> {
        let step = config.step_config();
        let request = sar_loop::excite::ExciteRequest {
            amplitude_m: self.amplitude_m,
            freq_hz: self.spec.sines.map(|s| s.freq_hz),
            duration_s: self.spec.duration_s,
            fade_s: self.spec.fade_s,
        };
        sar_loop::excite::judge(&request, &self.spec.centre_m, &step.travel_m, &step.excite)
            .map_err(|refusal| format!("the loop would refuse this excitation: {refusal}"))
    }

    /// The estimate's noise along the planned motion against the guard's
    /// warn limits, before anything moves (issue 33: at the old default
    /// centre the sweep brought the tip so near the support that the noise
    /// alone, growing as a / (L - a), crossed the lateral warn limit within
    /// 10 s and the Warn ended the excitation). At every
    /// [`NOISE_CHECK_STEP_S`] of the plan the tip force's deviations
    /// (`|std_n|` bounds every part's, whatever their correlation) must
    /// leave the guard's margin (`std_margin |std_n|`, added to each part)
    /// and [`NOISE_SIGMA`] deviations of noise below the smallest warn
    /// limit. The worst pose is the error's, in one line.
    pub fn noise_within_warn(&self, config: &Config) -> Result<(), String> {
        let est = &config.estimator;
        let tip = TipForceEstimator::new(&est.calibration, &est.profile, &est.noise, est.tip)
            .map_err(|e| e.to_string())?;
        let guard = est.guard.limits();
        let f = guard.force;
        let warn_n = f.warn_total_n.min(f.warn_axial_n).min(f.warn_lateral_n);
        let zero = Vec3::zeros();
        let steps = (self.spec.duration_s / NOISE_CHECK_STEP_S).ceil() as u64;
        let mut worst: Option<(f64, f64, [f64; 3])> = None;
        for k in 0..=steps {
            let t_s = (k as f64 * NOISE_CHECK_STEP_S).min(self.spec.duration_s);
            let (q, _, _) = self.at(t_s);
            let [q1_m, q2_m, q3_m] = q;
            let joints = sar_kinematics::ActiveJoints { q1_m, q2_m, q3_m };
            let pose = sar_kinematics::forward(&est.calibration, &est.profile, &joints)
                .map_err(|e| format!("the excitation at {t_s} s has no pose: {e}"))?;
            let std_n = tip
                .estimate(&pose, &zero, &zero)
                .map_err(|e| format!("the excitation at {t_s} s: {e}"))?
                .std_n
                .norm();
            let reach_n = (guard.std_margin + NOISE_SIGMA) * std_n;
            if worst.is_none_or(|(w, _, _)| reach_n > w) {
                worst = Some((reach_n, pose.support_distance_m, q));
            }
        }
        match worst {
            Some((reach_n, a_m, q)) if reach_n > warn_n => Err(format!(
                "the excitation would end in a Warn on noise: at q = ({:.3}, {:.3}, {:.3}) m the tip is {:.3} m past the support (a = {a_m:.3} m) and the estimate's noise with the guard's margin ({} x its deviation) reaches {reach_n:.2} N, above the smallest warn limit {warn_n} N; centre it nearer the support (--centre-m with a larger q3)",
                q[0],
                q[1],
                q[2],
                est.profile.length_m() - a_m,
                guard.std_margin + NOISE_SIGMA,
            )),
            _ => Ok(()),
        }
    }

    /// The joints (q1, q2, q3) at `t`, their speeds and accelerations.
    pub fn at(&self, t_s: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let mut q = self.spec.centre_m;
        let (mut v, mut a) = ([0.0; 3], [0.0; 3]);
        for (i, (sine, amp)) in self.spec.sines.iter().zip(self.amplitude_m).enumerate() {
            let (x, xv, xa) = unit_axis(t_s, sine.freq_hz, &self.spec);
            if let (Some(q), Some(v), Some(a)) = (q.get_mut(i), v.get_mut(i), a.get_mut(i)) {
                *q += amp * x;
                *v = amp * xv;
                *a = amp * xa;
            }
        }
        (q, v, a)
    }

    /// The fit this excitation promises: noise-free readings of `truth` at
    /// `sensor_rate_hz`, fitted with the configured noise; its
    /// `*_model_*` standard errors and condition number are the expected ones.
    pub fn expected(
        &self,
        config: &Config,
        truth: &InertialParameters,
        sensor_rate_hz: f64,
        max_condition: f64,
    ) -> Result<DynamicResult, String> {
        let est = &config.estimator;
        let cal: &Calibration = &est.calibration;
        // As identify --dynamic fits by default: the adapter's mass estimated.
        let mut id = DynamicIdentification::new(cal, &est.noise, Vec3::zeros(), 0.0, false)
            .map_err(|e| e.to_string())?
            .estimating_adapter();
        let n = (self.spec.duration_s * sensor_rate_hz).floor() as u64;
        for k in 0..n {
            let (q, v, a) = self.at(k as f64 / sensor_rate_hz);
            let swap = |q: [f64; 3]| Vec3::new(q[2], q[1], q[0]);
            let ujoint_m = cal.p_home_m() + swap(q) + cal.ujoint_offset_m();
            let (velocity_mps, accel_mps2) = (swap(v), swap(a));
            let rod = rod_motion(&cal.support_m(), &ujoint_m, &velocity_mps, &accel_mps2)
                .map_err(|e| e.to_string())?;
            let force_a_n = model_force_n(truth, &rod, &accel_mps2, &cal.gravity_mps2());
            let sample = MotionSample {
                ujoint_m,
                velocity_mps,
                accel_mps2,
                reading_n: -(cal.sensor_rotation().transpose() * force_a_n),
            };
            id.add(&sample).map_err(|e| e.to_string())?;
        }
        id.solve(max_condition).map_err(|e| e.to_string())
    }
}

/// The step of [`Excitation::noise_within_warn`]'s scan of the plan, s.
pub const NOISE_CHECK_STEP_S: f64 = 0.01;

/// The deviations of noise [`Excitation::noise_within_warn`] keeps below
/// the warn limits beside the guard's margin: a part crosses it with a
/// probability of at most `2 Phi(-4.5)` = 7e-6 per sample (Szekely and
/// Bakirov 2003), and the guard needs three such samples (its debounce).
pub const NOISE_SIGMA: f64 = 4.5;

/// The centre of the excitation with the U-joint `a_m` behind the support
/// along X0, the rod horizontal, joints (q1, q2, q3), m.
pub fn centre_at_m(cal: &Calibration, a_m: f64) -> [f64; 3] {
    let a = cal.support_m() - Vec3::new(a_m, 0.0, 0.0);
    let q = a - cal.p_home_m() - cal.ujoint_offset_m();
    [q.z, q.y, q.x]
}

/// The default centre of the excitation for `config`, joints (q1, q2, q3),
/// m: [`centre_at_m`] at the largest support distance from
/// [`DEFAULT_SUPPORT_DISTANCE_M`] (MODEL.md 10's nominal pose) down to
/// [`MIN_SUPPORT_DISTANCE_M`] in 1 cm steps whose excitation the loop
/// accepts and whose noise stays clear of the warn limits
/// ([`Excitation::noise_within_warn`]: the sweep along the rod brings the
/// tip nearer the support, where the noise grows); the nearest's refusal
/// when none is.
pub fn default_centre_m(config: &Config) -> Result<[f64; 3], String> {
    let limits = &config.identify;
    let cal = &config.estimator.calibration;
    let mut refusal = String::new();
    let mut a_m = DEFAULT_SUPPORT_DISTANCE_M;
    while a_m >= MIN_SUPPORT_DISTANCE_M - 1e-9 {
        let centre_m = centre_at_m(cal, a_m);
        let spec = ExcitationSpec::around(
            centre_m,
            limits.excitation_duration_s,
            (
                limits.excitation_max_speed_mps,
                limits.excitation_max_accel_mps2,
                limits.excitation_max_jerk_mps3,
            ),
        );
        let checked = Excitation::plan(&spec, config).and_then(|e| {
            e.judged_by_the_loop(config)?;
            e.noise_within_warn(config)
        });
        match checked {
            Ok(()) => return Ok(centre_m),
            Err(e) => refusal = e,
        }
        a_m -= 0.01;
    }
    Err(format!(
        "no default centre from a = {DEFAULT_SUPPORT_DISTANCE_M} m to {MIN_SUPPORT_DISTANCE_M} m suits this robot (at the nearest: {refusal}); give one (--centre-m)"
    ))
}

/// The default centre's largest distance from the support, m.
pub const DEFAULT_SUPPORT_DISTANCE_M: f64 = 0.2;

/// The default centre's smallest distance from the support, m.
pub const MIN_SUPPORT_DISTANCE_M: f64 = 0.1;

/// The planned excitation and its promise, as `identify --dynamic --plan`
/// prints it before anything moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// The excitation.
    pub excitation: Excitation,
    /// The configured rod the promise is computed for (I_perp: m L^2 / 12).
    pub rod: InertialParameters,
    /// The expected fit (its `*_model_*` standard errors and condition).
    pub expected: DynamicResult,
}

impl Plan {
    /// The excitation of `[identify]`'s limits about `centre_m` for the
    /// configured rod, at `sensor_rate_hz`.
    pub fn new(config: &Config, centre_m: [f64; 3], sensor_rate_hz: f64) -> Result<Self, String> {
        let limits = &config.identify;
        let spec = ExcitationSpec::around(
            centre_m,
            limits.excitation_duration_s,
            (
                limits.excitation_max_speed_mps,
                limits.excitation_max_accel_mps2,
                limits.excitation_max_jerk_mps3,
            ),
        );
        let excitation = Excitation::plan(&spec, config)?;
        excitation.judged_by_the_loop(config)?;
        excitation.noise_within_warn(config)?;
        let p = &config.estimator.profile;
        let rod = InertialParameters {
            mass_kg: p.mass_kg(),
            com_m: p.com_m(),
            inertia_perp_kgm2: p.mass_kg() * p.length_m() * p.length_m() / 12.0,
            friction_n: 0.0,
        };
        let expected = excitation.expected(config, &rod, sensor_rate_hz, f64::INFINITY)?;
        Ok(Self {
            excitation,
            rod,
            expected,
        })
    }

    /// The JSON object.
    pub fn to_json(&self) -> serde_json::Value {
        let e = &self.excitation;
        let x = &self.expected;
        serde_json::json!({
            "centre_m": e.spec.centre_m,
            "freq_hz": e.spec.sines.map(|s| s.freq_hz),
            "amplitude_m": e.amplitude_m,
            "peak_speed_mps": e.peak_speed_mps,
            "peak_accel_mps2": e.peak_accel_mps2,
            "duration_s": e.spec.duration_s,
            "condition": x.condition,
            "expected_inertia_perp_std_kgm2": x.inertia_perp_model_std_kgm2,
            "expected_inertia_perp_std_rel": x.inertia_perp_model_std_kgm2 / self.rod.inertia_perp_kgm2,
            "expected_mass_std_kg": x.mass_std_kg,
            "expected_com_std_m": x.com_std_m,
            "assumed_inertia_perp_kgm2": self.rod.inertia_perp_kgm2,
        })
    }

    /// The human report.
    pub fn to_text(&self) -> String {
        let e = &self.excitation;
        let x = &self.expected;
        let axes: Vec<String> = (0..3)
            .filter_map(|i| {
                Some(format!(
                    "  q{}: {:.4} m +- {:.4} m at {} Hz (peak {:.3} m/s, {:.3} m/s^2)",
                    i + 1,
                    e.spec.centre_m.get(i)?,
                    e.amplitude_m.get(i)?,
                    e.spec.sines.get(i)?.freq_hz,
                    e.peak_speed_mps.get(i)?,
                    e.peak_accel_mps2.get(i)?
                ))
            })
            .collect();
        format!(
            "excitation: {} s, sines per axis faded in and out over {} s:\n{}\ncondition number {:.1}; expected standard errors (sensor noise only, I_perp assumed {:.5} kg m^2 = m L^2 / 12): I_perp {:.2} %, m {:.3} %, c {:.3} %",
            e.spec.duration_s,
            e.spec.fade_s,
            axes.join("\n"),
            x.condition,
            self.rod.inertia_perp_kgm2,
            100.0 * x.inertia_perp_model_std_kgm2 / self.rod.inertia_perp_kgm2,
            100.0 * x.mass_std_kg / self.rod.mass_kg,
            100.0 * x.com_std_m / self.rod.com_m
        )
    }
}
