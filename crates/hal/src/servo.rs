//! The drives' position loop (issue 26), the one model of it that the
//! simulator's axes run (`sar_sim`) and the loop follows its commanded
//! trajectory through (`sar_loop::motion`): each axis a second-order
//! position loop that follows its reference (the set point's profile) with a
//! lag, `x'' = wn^2 (r - x) - 2 zeta wn x'`, `wn = 2 pi bandwidth`, the
//! acceleration clipped to the servo's own limit where one is modelled (the
//! simulator's; the loop models none). It is sampled once per step: the
//! acceleration computed at a step's start holds until the next (a drive's
//! loop runs at a fixed rate too), so the position between steps is exact
//! for that constant acceleration and any instant's state depends only on
//! the step grid, never on when it is evaluated.

use crate::convert::ns_to_s;
use crate::motion::{AxisPlan, AxisState};

/// One axis's servo state: position and velocity at its last sample and
/// the acceleration it applies from there to the next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoAxis {
    /// m.
    pub x_m: f64,
    /// m/s.
    pub v_mps: f64,
    /// m/s^2.
    pub a_mps2: f64,
}

impl ServoAxis {
    /// At rest at `x_m`.
    pub fn rest(x_m: f64) -> Self {
        Self {
            x_m,
            v_mps: 0.0,
            a_mps2: 0.0,
        }
    }

    /// A plan's state at `t_ns` (the drives exactly on it).
    pub fn on(plan: &AxisPlan, t_ns: u64) -> Self {
        let s = plan.at(t_ns);
        Self {
            x_m: s.x_m,
            v_mps: s.v_mps,
            a_mps2: plan.accel_at(t_ns),
        }
    }

    /// Position and velocity `dt_ns` after its sample, the acceleration
    /// held.
    pub fn after(&self, dt_ns: u64) -> Self {
        let dt = ns_to_s(dt_ns);
        Self {
            x_m: self.x_m + self.v_mps * dt + 0.5 * self.a_mps2 * dt * dt,
            v_mps: self.v_mps + self.a_mps2 * dt,
            a_mps2: self.a_mps2,
        }
    }

    /// Its position and velocity.
    pub fn state(&self) -> AxisState {
        AxisState {
            x_m: self.x_m,
            v_mps: self.v_mps,
        }
    }

    /// Moves `dt_ns` on and samples the loop there against the reference
    /// position `reference_m`: natural frequency `wn_rad_s` (2 pi times the
    /// bandwidth), damping ratio `damping`, the acceleration clipped to
    /// `max_accel_mps2` when there is one.
    pub fn step(
        &mut self,
        dt_ns: u64,
        reference_m: f64,
        wn_rad_s: f64,
        damping: f64,
        max_accel_mps2: Option<f64>,
    ) {
        let now = self.after(dt_ns);
        let wn = wn_rad_s;
        let wanted = wn * wn * (reference_m - now.x_m) - 2.0 * damping * wn * now.v_mps;
        *self = Self {
            a_mps2: match max_accel_mps2 {
                Some(limit) => wanted.clamp(-limit, limit),
                None => wanted,
            },
            ..now
        };
    }
}

sar_snapshot::snap_struct!(ServoAxis { x_m, v_mps, a_mps2 });

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Step response of the sampled loop at 30 Hz, damping 0.7, 10 kHz:
    /// the continuous loop's overshoot exp(-pi z / sqrt(1 - z^2)) = 4.60 %
    /// and 10-90 % rise time (computed here from its closed form), each
    /// within 3 % of its value.
    #[test]
    fn step_response_matches_the_second_order_loop() {
        let wn = core::f64::consts::TAU * 30.0;
        let step_m = 0.001;
        let dt_ns = 100_000;
        let mut axis = ServoAxis::rest(0.0);
        let mut xs = vec![0.0];
        for _ in 0..2000 {
            axis.step(dt_ns, step_m, wn, 0.7, Some(1e3));
            xs.push(axis.x_m);
        }
        let peak = xs.iter().copied().fold(f64::MIN, f64::max);
        let overshoot = peak / step_m - 1.0;
        let z: f64 = 0.7;
        let expected = (-core::f64::consts::PI * z / (1.0 - z * z).sqrt()).exp();
        assert!((overshoot / expected - 1.0).abs() < 0.01, "{overshoot}");
        let cross = |xs: &[f64], level: f64| xs.iter().position(|&x| x >= level).unwrap();
        let rise_s = (cross(&xs, 0.9 * step_m) - cross(&xs, 0.1 * step_m)) as f64 * 1e-4;
        // The continuous response, sampled at 1 us.
        let wn = core::f64::consts::TAU * 30.0;
        let wd = wn * (1.0 - z * z).sqrt();
        let exact: Vec<f64> = (0..200_000)
            .map(|k| {
                let t = f64::from(k) * 1e-6;
                1.0 - (-z * wn * t).exp() * ((wd * t).cos() + z * wn / wd * (wd * t).sin())
            })
            .collect();
        let exact_rise_s = (cross(&exact, 0.9) - cross(&exact, 0.1)) as f64 * 1e-6;
        eprintln!(
            "servo step: overshoot {:.3} % (continuous {:.3} %), 10-90 % rise {:.2} ms (continuous {:.2} ms)",
            overshoot * 100.0,
            expected * 100.0,
            rise_s * 1e3,
            exact_rise_s * 1e3
        );
        assert!(
            (rise_s / exact_rise_s - 1.0).abs() < 0.03,
            "{rise_s} vs {exact_rise_s}"
        );
        assert!((xs.last().unwrap() - step_m).abs() < 1e-9);
    }

    #[test]
    fn the_acceleration_limit_holds() {
        let wn = core::f64::consts::TAU * 30.0;
        let mut axis = ServoAxis::rest(0.0);
        axis.step(100_000, 0.01, wn, 0.7, Some(2.0));
        assert_eq!(axis.a_mps2, 2.0);
        // Without a limit, the loop's own acceleration.
        let mut free = ServoAxis::rest(0.0);
        free.step(100_000, 0.01, wn, 0.7, None);
        assert_eq!(free.a_mps2, wn * wn * 0.01);
    }
}
