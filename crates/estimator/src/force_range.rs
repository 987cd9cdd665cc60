//! The force loop's stability over the plant's range (issue 34 item 4,
//! FORCE_CONTROL.md "Stability over the plant's range"): the servo and the
//! rod are never exactly what the configuration says, so
//! [`crate::force_control::ForceControlConfig::new`] checks the phase margin
//! not at the configured plant alone but over the range [`PlantRange`]
//! states (`[force_control] servo_*` and `inertia_perp_ratio_*`).
//!
//! The loop, per tip-frame part, from the commanded tip `x_c` to the force
//! the law acts on (FORCE_CONTROL.md derives it):
//!
//! ```text
//! L(s) = [k G(s) + s^2 (m_true G(s) - m_conf G_model(s))] H(s) e^(-s T) / (s (M s + D))
//! ```
//!
//! with `G` the real servo (its bandwidth, damping and pure delay within
//! the range), `G_model` the loop's model of it (`[axes] servo_*`), with
//! which the estimator compensates the rod's inertia, `m_conf` the rod's
//! inertia at the tip as configured ([`TipInertia`]: along the rod `m +
//! m_s`; across it `J_B / b^2`), `m_true` the real one (across the rod
//! `J_B / b^2 + (r - 1) I_perp / b^2` for an I_perp `r` times the
//! configured one), `H` the law's filter (the bilinear Butterworth's exact
//! response) and `T` the other delays. The margin is the smallest
//! `180 - |arg L(jw)|` over the frequencies where `|L(jw)| >= 1` (for a
//! single crossover, the classic phase margin), over a grid of the range's
//! corners and insides and of stiffnesses up to the stiffest tissue.
//!
//! Fixed-size, no allocation: a sweep of [`FREQUENCIES`] points per case.

use core::fmt;

/// The plant the force loop must stay stable on, against the configured
/// servo (`[axes] servo_bandwidth_hz`, `servo_damping`) and rod
/// (`[manipulator] inertia_perp_kgm2`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantRange {
    /// The slowest servo, a fraction of the configured bandwidth (0 < r <= 1).
    pub servo_bandwidth_min_ratio: f64,
    /// The fastest servo, a fraction of the configured bandwidth (>= 1);
    /// 0: up to ideal drives (no lag).
    pub servo_bandwidth_max_ratio: f64,
    /// The least damped servo (> 0).
    pub servo_damping_min: f64,
    /// The most damped servo (>= `servo_damping_min`).
    pub servo_damping_max: f64,
    /// The longest pure delay the servo adds to its reference, s (>= 0).
    pub servo_delay_max_s: f64,
    /// The lightest rod, I_perp as a fraction of the configured (0 < r <= 1).
    pub inertia_perp_ratio_min: f64,
    /// The heaviest rod, I_perp as a fraction of the configured (>= 1).
    pub inertia_perp_ratio_max: f64,
}

/// The rod's inertia as the estimator's compensation sees it at the tip,
/// per m/s^2 of the tip's acceleration (MODEL.md 10; FORCE_CONTROL.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipInertia {
    /// Along the rod: the rod's and the adapter's mass `m + m_s`, kg (>= 0).
    pub axial_kg: f64,
    /// Across the rod: `J_B / b^2`, the rod's inertia about the support
    /// `J_B = I_perp + m (a - c)^2` over the square of the tip's distance
    /// past the support `b` at the shallowest tip checked, kg (>= 0).
    pub lateral_kg: f64,
    /// Its part that I_perp makes: `I_perp / b^2`, kg (>= 0).
    pub inertia_perp_kg: f64,
}

impl TipInertia {
    /// No rod inertia (nothing compensated: no phantom path).
    pub const NONE: Self = Self {
        axial_kg: 0.0,
        lateral_kg: 0.0,
        inertia_perp_kg: 0.0,
    };
}

/// The points of each sweep, log-spaced from 0.1 rad/s to the sensor's
/// Nyquist frequency.
pub const FREQUENCIES: usize = 400;

/// One plant of the range and a stiffness: where a margin was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeCase {
    /// Along the rod (`true`) or across it.
    pub axial: bool,
    /// The servo's bandwidth, Hz (0: ideal drives).
    pub servo_bandwidth_hz: f64,
    /// Its damping.
    pub servo_damping: f64,
    /// Its pure delay, s.
    pub servo_delay_s: f64,
    /// I_perp, a fraction of the configured.
    pub inertia_perp_ratio: f64,
    /// The tissue's stiffness, N/m.
    pub stiffness_n_per_m: f64,
    /// The margin there, degrees (180 - |arg L| where |L| >= 1).
    pub margin_deg: f64,
    /// The frequency of the smallest margin, rad/s (0: |L| < 1 nowhere
    /// but at rest).
    pub at_rad_s: f64,
}

impl fmt::Display for RangeCase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the {} loop keeps {:.1} deg at {:.0} rad/s with ",
            if self.axial { "axial" } else { "lateral" },
            self.margin_deg,
            self.at_rad_s
        )?;
        if self.servo_bandwidth_hz == 0.0 {
            write!(f, "ideal drives")?;
        } else {
            write!(
                f,
                "a servo of {:.1} Hz, damping {:.2}",
                self.servo_bandwidth_hz, self.servo_damping
            )?;
        }
        write!(
            f,
            ", a delay of {:.1} ms, I_perp {:.2}x, on {:.0} N/m",
            self.servo_delay_s * 1e3,
            self.inertia_perp_ratio,
            self.stiffness_n_per_m
        )
    }
}

/// A complex number (no_std, no allocation).
#[derive(Debug, Clone, Copy)]
struct C {
    re: f64,
    im: f64,
}

impl C {
    const ONE: C = C { re: 1.0, im: 0.0 };
    fn cis(phase: f64) -> C {
        C {
            re: libm::cos(phase),
            im: libm::sin(phase),
        }
    }
    fn mul(self, o: C) -> C {
        C {
            re: self.re * o.re - self.im * o.im,
            im: self.re * o.im + self.im * o.re,
        }
    }
    fn div(self, o: C) -> C {
        let d = o.re * o.re + o.im * o.im;
        C {
            re: (self.re * o.re + self.im * o.im) / d,
            im: (self.im * o.re - self.re * o.im) / d,
        }
    }
    fn scale(self, k: f64) -> C {
        C {
            re: self.re * k,
            im: self.im * k,
        }
    }
    fn sub(self, o: C) -> C {
        C {
            re: self.re - o.re,
            im: self.im - o.im,
        }
    }
    fn add(self, o: C) -> C {
        C {
            re: self.re + o.re,
            im: self.im + o.im,
        }
    }
    fn abs(self) -> f64 {
        libm::hypot(self.re, self.im)
    }
}

/// The servo `wn^2 / (s^2 + 2 zeta wn s + wn^2)` at `w` (bandwidth 0:
/// ideal, 1).
fn servo(w: f64, bandwidth_hz: f64, damping: f64) -> C {
    if bandwidth_hz == 0.0 {
        return C::ONE;
    }
    let wn = core::f64::consts::TAU * bandwidth_hz;
    C {
        re: wn * wn,
        im: 0.0,
    }
    .div(C {
        re: wn * wn - w * w,
        im: 2.0 * damping * wn * w,
    })
}

/// What the sweep needs of the loop besides the plant.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Loop {
    /// The filter's `([b0, b1, b2], [1, a1, a2])`.
    pub filter: ([f64; 3], [f64; 3]),
    /// Its sample period, s.
    pub sample_period_s: f64,
    /// The other delays, s.
    pub other_delay_s: f64,
    /// The configured servo's bandwidth (0: ideal) and damping.
    pub model: (f64, f64),
}

/// The shared factors at `w`: `H(jw) e^(-jwT)` and the modelled servo.
fn shared(l: &Loop, w: f64) -> (C, C) {
    let (b, a) = l.filter;
    let z1 = C::cis(-w * l.sample_period_s);
    let z2 = z1.mul(z1);
    let num = C::ONE.scale(b[0]).add(z1.scale(b[1])).add(z2.scale(b[2]));
    let den = C::ONE.scale(a[0]).add(z1.scale(a[1])).add(z2.scale(a[2]));
    let h = num.div(den).mul(C::cis(-w * l.other_delay_s));
    (h, servo(w, l.model.0, l.model.1))
}

/// The margin of one case (its fields but the result filled in), over the
/// sweep, for the admittance `(mass_kg, damping)` and the tip inertia
/// `(m_conf, m_true)`.
pub(crate) fn case_margin(
    l: &Loop,
    mut case: RangeCase,
    admittance: (f64, f64),
    inertia: (f64, f64),
) -> RangeCase {
    let (mass, damping) = admittance;
    let (m_conf, m_true) = inertia;
    let w_lo: f64 = 0.1;
    let w_hi = core::f64::consts::PI / l.sample_period_s;
    let step = libm::log(w_hi / w_lo) / (FREQUENCIES - 1) as f64;
    case.margin_deg = 180.0;
    case.at_rad_s = 0.0;
    for i in 0..FREQUENCIES {
        let w = w_lo * libm::exp(step * i as f64);
        let (h, g_model) = shared(l, w);
        let g = servo(w, case.servo_bandwidth_hz, case.servo_damping)
            .mul(C::cis(-w * case.servo_delay_s));
        // k G - w^2 (m_true G - m_conf G_model), s = jw.
        let plant = g
            .scale(case.stiffness_n_per_m)
            .sub(g.scale(m_true).sub(g_model.scale(m_conf)).scale(w * w));
        // s (M s + D) = -M w^2 + j D w.
        let law = C {
            re: -mass * w * w,
            im: damping * w,
        };
        let open = plant.mul(h).div(law);
        if open.abs() >= 1.0 {
            let margin = 180.0 - libm::atan2(open.im, open.re).abs().to_degrees();
            if margin < case.margin_deg {
                case.margin_deg = margin;
                case.at_rad_s = w;
            }
        }
    }
    case
}

/// The servo bandwidths of the sweep: from the slowest to the fastest in
/// [`BANDWIDTHS`] - 1 geometric steps (to 16 times the configured when the
/// range goes to ideal drives), then ideal drives if the range goes there.
pub const BANDWIDTHS: usize = 7;

/// The dampings of the sweep: the least, the most, and between.
pub const DAMPINGS: usize = 3;

/// The stiffnesses of the sweep, fractions of the stiffest tissue: the
/// phantom of a servo or rod that is not the model dominates where the
/// tissue is soft (0: none).
pub const STIFFNESS_FRACTIONS: [f64; 4] = [0.0, 0.1, 0.4, 1.0];

/// Every servo of the sweep: `(bandwidth_hz (0: ideal), damping,
/// delay_s)`, `f` called on each: the configured one, then the range's.
pub(crate) fn each_servo(configured: (f64, f64), r: &PlantRange, mut f: impl FnMut(f64, f64, f64)) {
    let (configured_hz, configured_damping) = configured;
    // The configured servo itself, whatever the range says.
    f(configured_hz, configured_damping, 0.0);
    let ideal_too = r.servo_bandwidth_max_ratio == 0.0 || configured_hz == 0.0;
    let hi = if r.servo_bandwidth_max_ratio == 0.0 {
        16.0
    } else {
        r.servo_bandwidth_max_ratio
    };
    let lo = r.servo_bandwidth_min_ratio;
    let delays = [0.0, r.servo_delay_max_s];
    let n_delays = if r.servo_delay_max_s > 0.0 { 2 } else { 1 };
    for delay_s in delays.iter().take(n_delays) {
        if configured_hz > 0.0 {
            for i in 0..BANDWIDTHS - 1 {
                let ratio = lo * libm::pow(hi / lo, i as f64 / (BANDWIDTHS - 2) as f64);
                for j in 0..DAMPINGS {
                    let t = j as f64 / (DAMPINGS - 1) as f64;
                    let damping = r.servo_damping_min
                        * libm::pow(r.servo_damping_max / r.servo_damping_min, t);
                    f(configured_hz * ratio, damping, *delay_s);
                }
            }
        }
        if ideal_too {
            f(0.0, 0.0, *delay_s);
        }
    }
}
