//! Force control on the estimated tip force (issue 15): the control law of
//! the compliant hold and of the axial force regulation, in the tip frame
//! (axial: along the rod direction u; lateral: across it), as a pure,
//! fixed-size, allocation-free step per control period. The loop's step owns
//! one [`ForceController`], feeds it the cycle's tip-force estimate and the
//! rod direction, and turns the commanded tip it returns into joint set
//! points through the inverse kinematics at the fulcrum (MODEL.md 3), which
//! it streams to the drives. FORCE_CONTROL.md derives the law, its signs and
//! its stability bounds.
//!
//! Signs (MODEL.md 4): F_tip is what the tip applies to the tissue, in {0}.
//! Moving the tip along +F_tip pushes deeper and raises the force; along
//! -F_tip relieves it. The axial force is `F_tip . u`, positive when the tip
//! pushes along the rod (inserting).
//!
//! The law: a commanded tip `x_ref + x` with an admittance per tip-frame
//! part (axial, lateral): `M a = e - D v - K x` (K: the hold's return
//! stiffness, 0 in a push), where `e` is the force error the mode asks to
//! remove:
//! - [`ForceMode::Push`] (axial regulation to `N`): `e = (N - F . u) u`
//!   (below N the tip moves along +u, deeper); the lateral part is held
//!   (x and v across u are kept at zero: the lateral position is held);
//! - [`ForceMode::Hold`] (compliant hold below `N`): `e = -(|F| - N) F/|F|`
//!   when `|F| > N`, else 0 (the tip yields along -F by as much as the
//!   force exceeds N, and the stiffness K brings it back to the held point
//!   when the tissue lets go).
//!
//! With M small this is an integral force controller `v = e / D`: zero
//! steady error on a still tissue, a force error of `D v` while it follows a
//! tissue moving at v. The acceleration, the speed and the excursion from
//! the reference are bounded (no wind-up: the state is the commanded motion
//! itself, and it stops at its bounds). The force is low-passed by the
//! controller's own filter (`filter_cutoff_hz`), whose delay is part of the
//! stability bound ([`ForceControlConfig::phase_margin_deg`]).

use crate::filter::{FilterConfig, TipFilter};
use crate::force_range::{Loop, STIFFNESS_FRACTIONS, case_margin, each_servo};
pub use crate::force_range::{PlantRange, RangeCase, TipInertia};
use crate::{SettingError, Vec3, positive};

/// The admittance of one tip-frame part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Admittance {
    /// Virtual mass M, kg (finite, > 0).
    pub mass_kg: f64,
    /// Virtual damping D, N s/m (finite, > 0): the force error per speed.
    pub damping_n_s_per_m: f64,
}

/// The force controller's settings, as the caller fills them
/// (`[force_control]` of the configuration). [`ForceControlConfig::new`]
/// checks them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceControlLimits {
    /// Along the rod.
    pub axial: Admittance,
    /// Across the rod.
    pub lateral: Admittance,
    /// The largest speed of the commanded tip, m/s (finite, > 0).
    pub max_speed_mps: f64,
    /// The largest acceleration of the commanded tip, m/s^2 (finite, > 0).
    pub max_accel_mps2: f64,
    /// The largest distance of the commanded tip from the reference, m
    /// (finite, > 0): the bound of a push into nothing.
    pub max_excursion_m: f64,
    /// In the compliant hold, the virtual stiffness K back to the held
    /// point, N/m (finite, >= 0): it brings the tip back when the tissue
    /// lets go, and adds `K x` to the force the hold settles at (a push has
    /// none: it must settle at its setpoint exactly).
    pub hold_return_n_per_m: f64,
    /// The cutoff of the controller's low-pass of F_tip, Hz.
    pub filter_cutoff_hz: f64,
    /// The sensor's sample period, s (the filter's step).
    pub sample_period_s: f64,
    /// The control period, s (the loop's).
    pub period_s: f64,
    /// Delays of the loop besides the filter's (sensor latency, half a
    /// sample, one control period, the drive's interpolation), s (>= 0).
    pub other_delay_s: f64,
    /// The stiffest tissue the loop must stay stable on, N/m (> 0).
    pub max_stiffness_n_per_m: f64,
    /// The smallest accepted phase margin at that stiffness, degrees.
    pub min_phase_margin_deg: f64,
    /// The axes' position loop (issue 26): its natural frequency, Hz
    /// (finite, > 0; the configuration's `[axes] servo_bandwidth_hz`). The
    /// carriage follows a set point through `wn^2 / (s^2 + 2 zeta wn s +
    /// wn^2)`, whose phase is part of the stability bound.
    pub servo_bandwidth_hz: f64,
    /// Its damping ratio zeta (finite, > 0; `[axes] servo_damping`).
    pub servo_damping: f64,
}

/// The range of the defaults (FORCE_CONTROL.md, "Stability over the
/// plant's range"): what the default law holds with its margin at the
/// stiffest tissue for rods of up to 4.2 kg (26.5 degrees with
/// manipulator 2 at 0.15 m past the support, 25.3 with manipulator 4): the
/// servo within 0.95-1.05x the configured bandwidth, damping 0.65-0.75, no
/// pure delay; I_perp 0.67-1.5x. Issue 34's range (0.4x to ideal
/// drives, damping 0.45-1.0, a 2 ms delay) is not stable with this law:
/// the estimator's inertia compensation, driven by the servo's model,
/// feeds back `m s^2 (G - G_model)`.
pub const DEFAULT_RANGE: PlantRange = PlantRange {
    servo_bandwidth_min_ratio: 0.95,
    servo_bandwidth_max_ratio: 1.05,
    servo_damping_min: 0.65,
    servo_damping_max: 0.75,
    servo_delay_max_s: 0.0,
    inertia_perp_ratio_min: 0.67,
    inertia_perp_ratio_max: 1.5,
};

impl Default for ForceControlLimits {
    /// The defaults of FORCE_CONTROL.md: axial D 80 N s/m, M 0.2 kg;
    /// lateral D 150 N s/m, M 0.4 kg; the hold's return 50 N/m; 6 mm/s,
    /// 0.2 m/s^2, 40 mm; a 25 Hz filter of 500 Hz samples; 1 kHz; 3 ms of
    /// other delays; the axes' servos at 30 Hz, damping 0.7; stable to
    /// 4000 N/m with at least 25 degrees of phase margin (issue 26: the
    /// servos' lag took 5000 N/m's margin, FORCE_CONTROL.md).
    fn default() -> Self {
        Self {
            axial: Admittance {
                mass_kg: 0.2,
                damping_n_s_per_m: 80.0,
            },
            lateral: Admittance {
                mass_kg: 0.4,
                damping_n_s_per_m: 150.0,
            },
            max_speed_mps: 0.006,
            max_accel_mps2: 0.2,
            max_excursion_m: 0.04,
            hold_return_n_per_m: 50.0,
            filter_cutoff_hz: 25.0,
            sample_period_s: 0.002,
            period_s: 0.001,
            other_delay_s: 0.003,
            max_stiffness_n_per_m: 4000.0,
            min_phase_margin_deg: 25.0,
            servo_bandwidth_hz: 30.0,
            servo_damping: 0.7,
        }
    }
}

/// Checked force-control settings. Exists only if valid, which includes a
/// phase margin of at least `min_phase_margin_deg` on both parts at
/// `max_stiffness_n_per_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceControlConfig {
    limits: ForceControlLimits,
    filter: FilterConfig,
    /// The filter's low-frequency group delay, s.
    filter_delay_s: f64,
}

fn invalid(field: &'static str, value: f64, why: &'static str) -> SettingError {
    SettingError::Invalid { field, value, why }
}

impl ForceControlConfig {
    /// Checks every setting, and the stability bound.
    pub fn new(limits: ForceControlLimits) -> Result<Self, SettingError> {
        positive("axial.mass_kg", limits.axial.mass_kg)?;
        positive("axial.damping_n_s_per_m", limits.axial.damping_n_s_per_m)?;
        positive("lateral.mass_kg", limits.lateral.mass_kg)?;
        positive(
            "lateral.damping_n_s_per_m",
            limits.lateral.damping_n_s_per_m,
        )?;
        let k = limits.hold_return_n_per_m;
        if !(k.is_finite() && k >= 0.0) {
            return Err(invalid("hold_return_n_per_m", k, "must be finite and >= 0"));
        }
        positive("max_speed_mps", limits.max_speed_mps)?;
        positive("max_accel_mps2", limits.max_accel_mps2)?;
        positive("max_excursion_m", limits.max_excursion_m)?;
        positive("period_s", limits.period_s)?;
        positive("max_stiffness_n_per_m", limits.max_stiffness_n_per_m)?;
        if !(limits.other_delay_s.is_finite() && limits.other_delay_s >= 0.0) {
            return Err(invalid(
                "other_delay_s",
                limits.other_delay_s,
                "must be finite and >= 0",
            ));
        }
        // 0: ideal drives (no servo lag in the margin).
        let bw = limits.servo_bandwidth_hz;
        if !(bw.is_finite() && bw >= 0.0) {
            return Err(invalid(
                "servo_bandwidth_hz",
                bw,
                "must be finite and >= 0 (0: ideal drives)",
            ));
        }
        positive("servo_damping", limits.servo_damping)?;
        let pm = limits.min_phase_margin_deg;
        if !(pm.is_finite() && (0.0..90.0).contains(&pm)) {
            return Err(invalid("min_phase_margin_deg", pm, "must be within 0..90"));
        }
        let filter = FilterConfig {
            cutoff_hz: limits.filter_cutoff_hz,
            sample_period_s: limits.sample_period_s,
        };
        let filter_delay_s = TipFilter::new(filter)?.group_delay_s();
        let config = Self {
            limits,
            filter,
            filter_delay_s,
        };
        for (field, a) in [
            ("axial.damping_n_s_per_m", &limits.axial),
            ("lateral.damping_n_s_per_m", &limits.lateral),
        ] {
            if config.phase_margin_deg(a, limits.max_stiffness_n_per_m) < pm {
                return Err(invalid(
                    field,
                    a.damping_n_s_per_m,
                    "too small for the stiffest tissue: the loop would not keep its phase \
                     margin with the filter's, the other delays' and the axes' servo lag \
                     (filter_cutoff_hz, other_delay_s, [axes] servo_bandwidth_hz and \
                     servo_damping; raise the damping, or the filter's cutoff)",
                ));
            }
        }
        Ok(config)
    }

    /// [`Self::new`], and stable over the plant's range (issue 34): the
    /// phase margin at least `min_phase_margin_deg` for every servo and rod
    /// of `range`, on the rod `tip` ([`Self::range_margin`]). The range and
    /// the rod gate the start only: they are not part of the settings the
    /// loop runs with (nor of a snapshot's fingerprint).
    pub fn over_range(
        limits: ForceControlLimits,
        range: &PlantRange,
        tip: &TipInertia,
    ) -> Result<Self, SettingError> {
        let config = Self::new(limits)?;
        check_range(range, tip)?;
        let worst = config.range_margin(range, tip);
        if worst.margin_deg < limits.min_phase_margin_deg {
            return Err(SettingError::NotStableOverRange {
                field: worst_field(&limits, range, &worst),
                case: worst,
                min_deg: limits.min_phase_margin_deg,
            });
        }
        Ok(config)
    }

    /// The smallest phase margin over the plant's `range` on the rod `tip`
    /// (`crate::force_range`), both parts, stiffnesses up to
    /// `max_stiffness_n_per_m`: the worst case.
    pub fn range_margin(&self, range: &PlantRange, tip: &TipInertia) -> RangeCase {
        let l = &self.limits;
        let ti = tip;
        let sweep = Loop {
            filter: TipFilter::new(self.filter)
                .map_or(([0.0; 3], [1.0, 0.0, 0.0]), |f| f.coefficients()),
            sample_period_s: l.sample_period_s,
            other_delay_s: l.other_delay_s,
            model: (l.servo_bandwidth_hz, l.servo_damping),
        };
        let r = range;
        let mut worst: Option<RangeCase> = None;
        let mut keep = |c: RangeCase| {
            if worst.is_none_or(|w| c.margin_deg < w.margin_deg) {
                worst = Some(c);
            }
        };
        each_servo(
            (l.servo_bandwidth_hz, l.servo_damping),
            r,
            |bw, damping, delay_s| {
                for fraction in STIFFNESS_FRACTIONS {
                    let case = RangeCase {
                        axial: true,
                        servo_bandwidth_hz: bw,
                        servo_damping: damping,
                        servo_delay_s: delay_s,
                        inertia_perp_ratio: 1.0,
                        stiffness_n_per_m: fraction * l.max_stiffness_n_per_m,
                        margin_deg: 0.0,
                        at_rad_s: 0.0,
                    };
                    let ax = (l.axial.mass_kg, l.axial.damping_n_s_per_m);
                    keep(case_margin(&sweep, case, ax, (ti.axial_kg, ti.axial_kg)));
                    let lat = (l.lateral.mass_kg, l.lateral.damping_n_s_per_m);
                    for ratio in [r.inertia_perp_ratio_min, 1.0, r.inertia_perp_ratio_max] {
                        let m_true = ti.lateral_kg + (ratio - 1.0) * ti.inertia_perp_kg;
                        let case = RangeCase {
                            axial: false,
                            inertia_perp_ratio: ratio,
                            ..case
                        };
                        keep(case_margin(&sweep, case, lat, (ti.lateral_kg, m_true)));
                    }
                }
            },
        );
        worst.unwrap_or(RangeCase {
            axial: true,
            servo_bandwidth_hz: l.servo_bandwidth_hz,
            servo_damping: l.servo_damping,
            servo_delay_s: 0.0,
            inertia_perp_ratio: 1.0,
            stiffness_n_per_m: 0.0,
            margin_deg: 180.0,
            at_rad_s: 0.0,
        })
    }

    /// The checked settings.
    pub fn limits(&self) -> &ForceControlLimits {
        &self.limits
    }

    /// The delay of the loop: the filter's group delay plus the other
    /// delays, s.
    pub fn loop_delay_s(&self) -> f64 {
        self.filter_delay_s + self.limits.other_delay_s
    }

    /// The axes' servo's low-frequency group delay `2 zeta / wn`, s (30 Hz,
    /// 0.7: 7.4 ms): the delay its phase amounts to well below `wn`.
    pub fn servo_delay_s(&self) -> f64 {
        if self.limits.servo_bandwidth_hz == 0.0 {
            return 0.0;
        }
        2.0 * self.limits.servo_damping / (core::f64::consts::TAU * self.limits.servo_bandwidth_hz)
    }

    /// The phase lag of the axes' servo `wn^2 / (s^2 + 2 zeta wn s + wn^2)`
    /// at `w` rad/s, radians: `atan2(2 zeta w / wn, 1 - (w / wn)^2)`
    /// (about `w 2 zeta / wn` well below `wn`; a little more above).
    pub fn servo_phase_lag_rad(&self, w: f64) -> f64 {
        if self.limits.servo_bandwidth_hz == 0.0 {
            return 0.0;
        }
        let wn = core::f64::consts::TAU * self.limits.servo_bandwidth_hz;
        let x = w / wn;
        libm::atan2(2.0 * self.limits.servo_damping * x, 1.0 - x * x)
    }

    /// The phase margin, degrees, of the force loop of part `a` on a tissue
    /// of stiffness `k` (N/m): the loop
    /// `k / (s (M s + D)) e^(-s T) G_servo(s)` crosses over near `w = k / D`
    /// (where M w << D), with the phase
    /// `-90 - atan(w M / D) - w T - servo(w)` degrees there (T:
    /// [`Self::loop_delay_s`]; servo: [`Self::servo_phase_lag_rad`]).
    pub fn phase_margin_deg(&self, a: &Admittance, k: f64) -> f64 {
        let w = k / a.damping_n_s_per_m;
        let lag_rad = libm::atan(w * a.mass_kg / a.damping_n_s_per_m)
            + w * self.loop_delay_s()
            + self.servo_phase_lag_rad(w);
        90.0 - lag_rad.to_degrees()
    }

    /// The low-pass of the controller.
    pub fn filter(&self) -> FilterConfig {
        self.filter
    }
}

/// The range's own checks: every bound finite, within its sense.
fn check_range(r: &PlantRange, ti: &TipInertia) -> Result<(), SettingError> {
    let within = |field, v: f64, ok: bool, why| {
        if v.is_finite() && ok {
            Ok(())
        } else {
            Err(invalid(field, v, why))
        }
    };
    let bw_min = r.servo_bandwidth_min_ratio;
    within(
        "servo_bandwidth_min_ratio",
        bw_min,
        bw_min > 0.0 && bw_min <= 1.0,
        "must be within (0, 1]",
    )?;
    let bw_max = r.servo_bandwidth_max_ratio;
    within(
        "servo_bandwidth_max_ratio",
        bw_max,
        bw_max == 0.0 || bw_max >= 1.0,
        "must be 0 (up to ideal drives) or at least 1",
    )?;
    let (z_min, z_max) = (r.servo_damping_min, r.servo_damping_max);
    within("servo_damping_min", z_min, z_min > 0.0, "must be > 0")?;
    within(
        "servo_damping_max",
        z_max,
        z_max >= z_min,
        "must be at least servo_damping_min",
    )?;
    let d = r.servo_delay_max_s;
    within("servo_delay_max_s", d, d >= 0.0, "must be >= 0")?;
    let (i_min, i_max) = (r.inertia_perp_ratio_min, r.inertia_perp_ratio_max);
    within(
        "inertia_perp_ratio_min",
        i_min,
        i_min > 0.0 && i_min <= 1.0,
        "must be within (0, 1]",
    )?;
    within(
        "inertia_perp_ratio_max",
        i_max,
        i_max >= 1.0,
        "must be at least 1",
    )?;
    for (field, v) in [
        ("tip_inertia.axial_kg", ti.axial_kg),
        ("tip_inertia.lateral_kg", ti.lateral_kg),
        ("tip_inertia.inertia_perp_kg", ti.inertia_perp_kg),
    ] {
        within(field, v, v >= 0.0, "must be finite and >= 0")?;
    }
    Ok(())
}

/// The range's bound the worst case sits at (the key a refusal names):
/// the rod's inertia, else the servo's bandwidth, delay or damping, else
/// the part's damping.
fn worst_field(l: &ForceControlLimits, r: &PlantRange, w: &RangeCase) -> &'static str {
    if !w.axial && w.inertia_perp_ratio < 1.0 {
        "inertia_perp_ratio_min"
    } else if !w.axial && w.inertia_perp_ratio > 1.0 {
        "inertia_perp_ratio_max"
    } else if w.servo_bandwidth_hz == 0.0 && l.servo_bandwidth_hz > 0.0 {
        "servo_bandwidth_max_ratio"
    } else if w.servo_bandwidth_hz < l.servo_bandwidth_hz * (1.0 - 1e-9) {
        "servo_bandwidth_min_ratio"
    } else if w.servo_bandwidth_hz > l.servo_bandwidth_hz * (1.0 + 1e-9) {
        "servo_bandwidth_max_ratio"
    } else if w.servo_delay_s > 0.0 {
        "servo_delay_max_s"
    } else if w.servo_damping < l.servo_damping && r.servo_damping_min < l.servo_damping {
        "servo_damping_min"
    } else if w.servo_damping > l.servo_damping && r.servo_damping_max > l.servo_damping {
        "servo_damping_max"
    } else if w.axial {
        "axial.damping_n_s_per_m"
    } else {
        "lateral.damping_n_s_per_m"
    }
}

/// What the controller regulates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ForceMode {
    /// Hold the tip while |F_tip| is below `max_force_n`; above, yield along
    /// -F_tip so that it stays near it; come back when the tissue lets go.
    Hold {
        /// N (finite, > 0).
        max_force_n: f64,
    },
    /// Regulate the axial force F_tip . u to `axial_n`, the lateral position
    /// held.
    Push {
        /// N (finite).
        axial_n: f64,
    },
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutput {
    /// The commanded tip, {0}, m.
    pub tip_m: Vec3,
    /// Its velocity, m/s.
    pub velocity_mps: Vec3,
    /// The filtered F_tip the law acted on, {0}, N.
    pub force_n: Vec3,
    /// The commanded tip is at its largest excursion from the reference.
    pub at_excursion_limit: bool,
}

/// Why the controller did not step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ControlError {
    /// No mode is active.
    #[error("no force-control mode is active")]
    Idle,
    /// There is no filtered force yet (no observable estimate).
    #[error("no filtered tip force to act on")]
    NoForce,
    /// The rod direction is not a finite unit vector.
    #[error("the rod direction is not a finite unit vector")]
    BadRodDirection,
}

/// The force controller: fixed-size state, set at construction.
#[derive(Debug, Clone)]
pub struct ForceController {
    config: ForceControlConfig,
    filter: TipFilter,
    /// The last filtered force.
    force_n: Option<Vec3>,
    mode: Option<ForceMode>,
    /// The reference tip (where the mode started), {0}, m.
    reference_m: Vec3,
    /// The commanded tip's offset from the reference, m.
    offset_m: Vec3,
    /// Its velocity, m/s.
    velocity_mps: Vec3,
}

/// `v` split into its part along the unit `u` and the rest.
fn split(v: &Vec3, u: &Vec3) -> (Vec3, Vec3) {
    let along = u * v.dot(u);
    (along, v - along)
}

impl ForceController {
    /// A controller with no mode active.
    pub fn new(config: ForceControlConfig) -> Result<Self, SettingError> {
        Ok(Self {
            config,
            filter: TipFilter::new(config.filter)?,
            force_n: None,
            mode: None,
            reference_m: Vec3::zeros(),
            offset_m: Vec3::zeros(),
            velocity_mps: Vec3::zeros(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &ForceControlConfig {
        &self.config
    }

    /// Feeds the cycle's tip-force estimate to the filter (every cycle, in
    /// every mode: a repeated sample is skipped by its counter); `None`
    /// (no observable estimate) resets it.
    pub fn observe(&mut self, sample: Option<(u32, &Vec3, &Vec3)>) {
        self.force_n = match sample {
            Some((counter, force_n, std_n)) => self
                .filter
                .update_counted(counter, force_n, std_n)
                .ok()
                .map(|f| f.force_n),
            None => {
                self.filter.reset();
                None
            }
        };
    }

    /// The filtered F_tip of the last observation, {0}, N.
    pub fn filtered_force_n(&self) -> Option<Vec3> {
        self.force_n
    }

    /// Starts `mode` with the commanded tip at `tip_m` at rest.
    pub fn start(&mut self, mode: ForceMode, tip_m: Vec3) {
        self.mode = Some(mode);
        self.reference_m = tip_m;
        self.offset_m = Vec3::zeros();
        self.velocity_mps = Vec3::zeros();
    }

    /// Ends the mode (position control again).
    pub fn stop(&mut self) {
        self.mode = None;
        self.velocity_mps = Vec3::zeros();
    }

    /// The active mode.
    pub fn mode(&self) -> Option<ForceMode> {
        self.mode
    }

    /// One control period: the commanded tip after it. `no_deeper_along`
    /// (the guard's Warn: the tip force it judged, {0}, N) forbids any
    /// motion of the commanded tip along that force in this period: the
    /// velocity along it is removed (in a push, whose motion is axial only,
    /// all of it), and an excursion bound that would bring the tip along it
    /// holds the tip where it is.
    pub fn step(
        &mut self,
        rod_dir: &Vec3,
        no_deeper_along: Option<&Vec3>,
    ) -> Result<ControlOutput, ControlError> {
        let mode = self.mode.ok_or(ControlError::Idle)?;
        let f = self.force_n.ok_or(ControlError::NoForce)?;
        let norm = rod_dir.norm();
        if !(norm.is_finite() && (norm - 1.0).abs() < 1e-6) {
            return Err(ControlError::BadRodDirection);
        }
        let u = rod_dir;
        let error = force_error(mode, &f, u);
        // The commanded offset of the last period (a push drops a lateral
        // part the rod's turn may have left in it).
        let previous_m = self.offset_m;
        let accel = self.admittance_accel_mps2(mode, &error, u);
        let l = &self.config.limits;
        let dt = l.period_s;
        let accel = clamp_norm(&accel, l.max_accel_mps2);
        let mut v = clamp_norm(&(self.velocity_mps + accel * dt), l.max_speed_mps);
        if let Some(g) = no_deeper_along {
            v = no_velocity_along(mode, v, g);
        }
        let (mut x, mut v, mut at_limit) = onto_excursion_bound(self.offset_m + v * dt, v, l);
        // Pulled back onto the bound, the tip may move along the force:
        // then it stays where it is.
        if let Some(g) = no_deeper_along
            && (x - previous_m).dot(g) > 0.0
        {
            x = previous_m;
            v = Vec3::zeros();
            at_limit = x.norm() >= l.max_excursion_m;
        }
        debug_assert!(x.norm() <= l.max_excursion_m * (1.0 + 1e-9));
        debug_assert!(v.norm() <= l.max_speed_mps * (1.0 + 1e-9));
        self.offset_m = x;
        self.velocity_mps = v;
        Ok(ControlOutput {
            tip_m: self.reference_m + x,
            velocity_mps: v,
            force_n: f,
            at_excursion_limit: at_limit,
        })
    }

    /// The admittance law's acceleration for the force error `error`, the
    /// axial (along `u`) and lateral parts each through their own
    /// admittance. A push keeps only the axial parts of the offset and the
    /// velocity (no lateral motion at all, no return stiffness: it must
    /// settle at its setpoint); a hold pulls both parts back with the
    /// return stiffness.
    fn admittance_accel_mps2(&mut self, mode: ForceMode, error: &Vec3, u: &Vec3) -> Vec3 {
        let l = &self.config.limits;
        let (ea, el) = split(error, u);
        let (xa, xl) = split(&self.offset_m, u);
        let (va, vl) = split(&self.velocity_mps, u);
        let part = |a: &Admittance, e: Vec3, x: Vec3, v: Vec3, k: f64| {
            (e - v * a.damping_n_s_per_m - x * k) / a.mass_kg
        };
        match mode {
            ForceMode::Push { .. } => {
                self.offset_m = xa;
                self.velocity_mps = va;
                part(&l.axial, ea, xa, va, 0.0)
            }
            ForceMode::Hold { .. } => {
                let k = l.hold_return_n_per_m;
                part(&l.axial, ea, xa, va, k) + part(&l.lateral, el, xl, vl, k)
            }
        }
    }
}

/// The force error the mode regulates, {0}, N: a push's axial setpoint
/// minus the axial force (along `u`); a hold's excess of |F| over its
/// bound, against the force (none under the bound).
fn force_error(mode: ForceMode, f: &Vec3, u: &Vec3) -> Vec3 {
    match mode {
        ForceMode::Push { axial_n } => u * (axial_n - f.dot(u)),
        ForceMode::Hold { max_force_n } => {
            let m = f.norm();
            if m > max_force_n {
                -f * ((m - max_force_n) / m)
            } else {
                Vec3::zeros()
            }
        }
    }
}

/// The velocity `v` with no part along the force `g` (the guard's Warn):
/// unchanged if it does not go along `g`; else a hold drops the part along
/// it, and a push (axial only: the one axial velocity with no part along
/// the force is none, unless the force is across the rod, where the part
/// along it is 0) stops.
fn no_velocity_along(mode: ForceMode, v: Vec3, g: &Vec3) -> Vec3 {
    let along = v.dot(g);
    if along > 0.0 {
        match mode {
            ForceMode::Push { .. } => Vec3::zeros(),
            ForceMode::Hold { .. } => v - g * (along / g.norm_squared()),
        }
    } else {
        v
    }
}

/// The offset `x` and velocity `v` held to the excursion bound: at or past
/// it, `x` back onto it and no speed outward. Returns them and whether the
/// bound was reached.
fn onto_excursion_bound(mut x: Vec3, mut v: Vec3, l: &ForceControlLimits) -> (Vec3, Vec3, bool) {
    let reach = x.norm();
    let at_limit = reach >= l.max_excursion_m;
    if at_limit {
        x *= l.max_excursion_m / reach;
        let outward = v.dot(&x);
        if outward > 0.0 {
            v -= x * (outward / x.norm_squared());
        }
    }
    (x, v, at_limit)
}

/// `v` scaled down to norm `max` if longer (a NaN stays NaN).
fn clamp_norm(v: &Vec3, max: f64) -> Vec3 {
    let n = v.norm();
    if n > max { v * (max / n) } else { *v }
}

// Snapshots (issue 17): the mode and the law's state are stored; the
// settings come from the configuration.
sar_snapshot::snap_enum!(ForceMode {
    0 => Hold { max_force_n },
    1 => Push { axial_n },
});
sar_snapshot::config_struct!(ForceControlConfig {
    limits,
    filter,
    filter_delay_s
});
sar_snapshot::config_struct!(ForceControlLimits {
    axial,
    lateral,
    max_speed_mps,
    max_accel_mps2,
    max_excursion_m,
    hold_return_n_per_m,
    filter_cutoff_hz,
    sample_period_s,
    period_s,
    other_delay_s,
    max_stiffness_n_per_m,
    min_phase_margin_deg,
    servo_bandwidth_hz,
    servo_damping,
});
sar_snapshot::config_struct!(Admittance {
    mass_kg,
    damping_n_s_per_m
});
sar_snapshot::snap_state!(ForceController {
    state: [force_n, mode, reference_m, offset_m, velocity_mps],
    nested: [filter],
    config: [config],
    output: [],
});
