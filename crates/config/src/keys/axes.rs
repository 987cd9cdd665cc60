//! `[axes]`: the axes' travel and the moves the daemon plans on them, and
//! the drives as the loop models them (issue 26: their position loop and
//! brakes, `sar_loop::motion`).

use crate::AxesConfig;
use crate::decl::{each, num};
use crate::keys::{File, ns};
use crate::scenario::{
    DEFAULT_COUNTS_PER_TURN, DEFAULT_LEAD_M_PER_TURN, DEFAULT_SERVO_BANDWIDTH_HZ,
    DEFAULT_SERVO_DAMPING, DEFAULT_TRAVEL_M,
};
use sar_loop::motion::{MAX_SERVO_BANDWIDTH_HZ, MAX_SERVO_DELAY_NS, MotionConfig};

crate::section! {
    /// The axes: their travel, the moves the daemon plans, the drives' position loop.
    section "axes";
    /// (min, max) of q1, q2, q3, m
    travel_m: [[f64; 2]; 3] = value(DEFAULT_TRAVEL_M),
        each(-2.0, 2.0, "m").also("min below max") => [AxesConfig.travel_m];
    /// speed of the moves the daemon plans
    max_speed_mps: f64 = value(0.02),
        num(1e-4, 1.0, "m/s").also("at most plausibility.max_joint_speed_mps")
        => [AxesConfig.max_speed_mps];
    /// acceleration of the moves the daemon plans
    max_accel_mps2: f64 = value(0.2), num(1e-6, 10.0, "m/s^2") => [AxesConfig.max_accel_mps2];
    /// farther from the commanded trajectory: Fault
    following_tolerance_m: f64 = value(0.001),
        num(1e-5, 0.05, "m") => [AxesConfig.following_tolerance_m];
    /// speed of the moves in Retreat
    retreat_speed_mps: f64 = value(0.005),
        num(1e-5, 1.0, "m/s").also("at most axes.max_speed_mps") => [AxesConfig.retreat_speed_mps];
    /// the drives' position loop: natural frequency (force control's stability check; 0: ideal)
    servo_bandwidth_hz: f64 = value(DEFAULT_SERVO_BANDWIDTH_HZ),
        num(0.0, MAX_SERVO_BANDWIDTH_HZ, "Hz") => [MotionConfig.servo_bandwidth_hz];
    /// its damping ratio
    servo_damping: f64 = value(DEFAULT_SERVO_DAMPING),
        num(0.1, 2.0, "(ratio)") => [MotionConfig.servo_damping];
    /// a pure delay of its reference (a fieldbus's, an interpolator's; `sarctl identify --servo` measures it)
    servo_delay_s: f64 = value(0.0),
        num(0.0, MAX_SERVO_DELAY_NS as f64 * 1e-9, "s") => [MotionConfig.servo_delay_ns];
    /// a guarded move's brake
    brake_decel_mps2: f64 = absent("[drivers.axes] quick_stop_decel_mps2", 2.0),
        num(1e-6, 10.0, "m/s^2")
            .also("at least axes.max_accel_mps2, at most drivers.axes.quick_stop_decel_mps2")
        => [MotionConfig.brake_decel_mps2];
}

/// The axes as the daemon plans moves on them.
pub(crate) fn build(f: &File) -> AxesConfig {
    let a = &f.axes;
    AxesConfig {
        travel_m: a.travel_m.map(|[lo, hi]| (lo, hi)),
        max_speed_mps: a.max_speed_mps,
        max_accel_mps2: a.max_accel_mps2,
        following_tolerance_m: a.following_tolerance_m,
        retreat_speed_mps: a.retreat_speed_mps,
        motion: motion(f),
    }
}

/// The drives as the loop models them: their position loop, their quick
/// stop (`[drivers.axes] quick_stop_decel_mps2`, every kind), a guarded
/// move's brake (default: the quick stop's) and `[tip] sensor_latency_s`,
/// where the motion is evaluated.
fn motion(f: &File) -> MotionConfig {
    let quick_stop_decel_mps2 = f.drivers_axes.quick_stop_decel_mps2;
    MotionConfig {
        servo_bandwidth_hz: f.axes.servo_bandwidth_hz,
        servo_damping: f.axes.servo_damping,
        servo_delay_ns: ns(f.axes.servo_delay_s),
        quick_stop_decel_mps2,
        brake_decel_mps2: f.axes.brake_decel_mps2.unwrap_or(quick_stop_decel_mps2),
        sensor_latency_ns: ns(f.tip.sensor_latency_s),
        encoder_count_m: encoder_count_m(f),
    }
}

/// One encoder count, m: `[drivers.axes] lead_m / counts_per_turn` for
/// CANopen drives, the simulator's default axes' count for the simulated
/// ones (`crate::scenario::DEFAULT_LEAD_M_PER_TURN` /
/// `DEFAULT_COUNTS_PER_TURN`).
fn encoder_count_m(f: &File) -> f64 {
    let a = &f.drivers_axes;
    match (a.lead_m, a.counts_per_turn) {
        (Some(lead_m), Some(counts)) if counts > 0 => lead_m / counts as f64,
        _ => DEFAULT_LEAD_M_PER_TURN / f64::from(DEFAULT_COUNTS_PER_TURN),
    }
}
