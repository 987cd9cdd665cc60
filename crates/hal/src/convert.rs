//! Small conversions that the hardware layer and its implementations (the
//! simulator, the CANopen drives) share: nanoseconds to seconds and the
//! active joints to and from arrays.

use sar_kinematics::ActiveJoints;

/// Nanoseconds as seconds (exact below 2^53 ns, about 104 days).
pub fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// The active joints from `[q1, q2, q3]`, m (the order of arrays indexed by axis).
pub fn joints_from_array(q_m: [f64; 3]) -> ActiveJoints {
    let [q1_m, q2_m, q3_m] = q_m;
    ActiveJoints { q1_m, q2_m, q3_m }
}

/// The active joints as `[q1, q2, q3]`, m.
pub fn joints_to_array(q: &ActiveJoints) -> [f64; 3] {
    [q.q1_m, q.q2_m, q.q3_m]
}
