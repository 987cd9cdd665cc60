//! The torque residual: the sensor's measured torque against the model's
//! prediction (MODEL.md 4) `t = R_0s^T ((A - S) x (-F_A) - M_T n) + b_t`,
//! with its standard deviation per sensor axis (the torque noise, the force
//! noise through the lever, and for d != 0 through the torsion's estimate
//! as well, widened in motion by the torsion's uncertainty); a residual
//! beyond `max_sigma` standard deviations on any sensor axis is a Fault
//! ([`Reason::TorqueImplausible`]). The same prediction gives the tare's
//! torque bias.

use super::plausibility::TorqueLimits;
use super::vocabulary::{Bias, SensorSample, TorqueResidual};
use crate::guard::{Axis, Reason};
use crate::{Calibration, Mat3, Pose, Profile, SensorNoise, Vec3};

/// The torque check, fixed at construction.
#[derive(Debug, Clone, Copy)]
pub(super) struct TorqueCheck {
    /// The residual's standard deviation per sensor axis with d = 0, N m.
    std_nm: Vec3,
    /// The lever's cross-product matrix \[l\]x, sensor frame.
    cross: Mat3,
    /// The force noise's variance per sensor axis, N^2.
    force_var_n2: Vec3,
    /// The torque noise's variance per sensor axis, N^2 m^2.
    torque_var_nm2: Vec3,
    /// d, m: with d != 0 the torsion's estimate carries force noise too.
    offset_m: f64,
    /// The configured multiple.
    max_sigma: f64,
}

impl TorqueCheck {
    pub(super) fn new(
        cal: &Calibration,
        profile: &Profile,
        noise: &SensorNoise,
        limits: &TorqueLimits,
    ) -> Self {
        let lever_s_m = SensorFrame::new(cal).lever_s_m;
        // The prediction l x (f - b) carries the force noise through [l]x:
        // var_i = sigma_t,i^2 + sum_j [l]x_ij^2 sigma_f,j^2.
        let cross = lever_s_m.cross_matrix();
        let force_var = noise.std_n().component_mul(&noise.std_n());
        let torque_var = limits.noise_nm.component_mul(&limits.noise_nm);
        let var = torque_var + cross.component_mul(&cross) * force_var;
        Self {
            std_nm: var.map(nalgebra::ComplexField::sqrt),
            cross,
            force_var_n2: force_var,
            torque_var_nm2: torque_var,
            offset_m: profile.offset_m(),
            max_sigma: limits.max_sigma,
        }
    }
}

/// The model's sensor torque without the torque bias, sensor frame:
/// `R_0s^T ((A - S) x (-F_A) - M_T n)` with `-F_A = R_0s (f - b_f)`, i.e.
/// `(R_0s^T (A - S)) x (f - b_f) - R_0s^T n M_T` (MODEL.md 4), N m.
/// `torsion_axis_s` gives R_0s^T n ([`SensorFrame::torsion_axis_s`]); it is
/// called only when the torsion is not 0 (never with d = 0), so that a caller
/// which has it already passes it, and one which has not pays only when needed.
pub(super) fn predicted_torque_nm(
    frame: &SensorFrame,
    reading_n: &Vec3,
    bias_n: &Vec3,
    torsion_nm: f64,
    torsion_axis_s: impl FnOnce() -> Vec3,
) -> Vec3 {
    let wrench = frame.lever_s_m.cross(&(reading_n - bias_n));
    if torsion_nm == 0.0 {
        wrench
    } else {
        wrench - torsion_axis_s() * torsion_nm
    }
}

/// What the torque model needs of the calibration, fixed at construction.
#[derive(Debug, Clone, Copy)]
pub(super) struct SensorFrame {
    /// R_0s^T.
    r_t: Mat3,
    /// R_0s^T (A - S): the lever from S to A in the sensor frame (constant:
    /// both are fixed offsets of the carriage), m.
    lever_s_m: Vec3,
}

impl SensorFrame {
    pub(super) fn new(cal: &Calibration) -> Self {
        let r_t = cal.sensor_rotation().transpose();
        Self {
            r_t,
            lever_s_m: r_t * (cal.ujoint_offset_m() - cal.sensor_offset_m()),
        }
    }

    /// R_0s^T n: the torsion axis of `pose` in the sensor frame.
    pub(super) fn torsion_axis_s(&self, pose: &Pose) -> Vec3 {
        self.r_t * torsion_axis(&rod_cross(pose))
    }
}

/// v = u x w, the q5 axis (c4, 0, -s4), as the tip-force estimator forms it.
fn rod_cross(pose: &Pose) -> Vec3 {
    pose.rod_dir.cross(&pose.rod_normal)
}

/// n = -(s4, 0, c4) = Y0 x v, from v = u x w ([`rod_cross`]), as the
/// tip-force estimator forms it.
fn torsion_axis(v: &Vec3) -> Vec3 {
    Vec3::y().cross(v)
}

/// Measured minus predicted torque, with its standard deviation.
pub(super) fn torque_residual(
    check: &TorqueCheck,
    frame: &SensorFrame,
    pose: &Pose,
    sensor: &SensorSample,
    bias: &Bias,
    torsion_nm: f64,
) -> TorqueResidual {
    if check.offset_m == 0.0 {
        // d = 0: the torsion is 0 and the deviation a constant. The same
        // prediction as the tare's (one model of the sensor torque).
        let predicted =
            predicted_torque_nm(frame, &sensor.force_n, &bias.force_n, torsion_nm, || {
                frame.torsion_axis_s(pose)
            }) + bias.torque_nm;
        return TorqueResidual {
            residual_nm: sensor.torque_nm - predicted,
            std_nm: check.std_nm,
        };
    }
    // d != 0: v and n = Y0 x v in the sensor frame, once for the prediction
    // and the deviation.
    let r_t = &frame.r_t;
    let v = rod_cross(pose);
    let n_s = r_t * torsion_axis(&v);
    let predicted = predicted_torque_nm(frame, &sensor.force_n, &bias.force_n, torsion_nm, || n_s)
        + bias.torque_nm;
    // The prediction also holds -R_0s^T n M_T, with the torsion's estimate
    // M_T = d (F_A . v) / w_y and F_A = -R_0s (f - b_f), so its Jacobian in
    // the reading f is J = [l]x + (d / w_y) (R_0s^T n) (R_0s^T v)^T, and
    // var_i = sigma_t,i^2 + sum_j J_ij^2 sigma_f,j^2.
    // Written out per entry (no 3x3 temporaries), in nalgebra's order of
    // operations for `[l]x + n_s v_s^T k` and `(J o J) sigma_f^2`, so the
    // result is the same to the bit.
    let v_s = r_t * v;
    let k = check.offset_m / pose.rod_normal.y;
    let (l, fv, tv) = (&check.cross, &check.force_var_n2, &check.torque_var_nm2);
    // Row i of J: l_i + n_i k v_s^T, squared per entry, against sigma_f^2.
    let std = |l_i: [f64; 3], n_i: f64, tv_i: f64| {
        let sq = |l_ic: f64, v_c: f64| {
            let j_ic = l_ic + n_i * v_c * k;
            j_ic * j_ic
        };
        let [l0, l1, l2] = l_i;
        let sum = sq(l0, v_s.x) * fv.x + sq(l1, v_s.y) * fv.y + sq(l2, v_s.z) * fv.z;
        nalgebra::ComplexField::sqrt(tv_i + sum)
    };
    TorqueResidual {
        residual_nm: sensor.torque_nm - predicted,
        std_nm: Vec3::new(
            std([l.m11, l.m12, l.m13], n_s.x, tv.x),
            std([l.m21, l.m22, l.m23], n_s.y, tv.y),
            std([l.m31, l.m32, l.m33], n_s.z, tv.z),
        ),
    }
}

/// `r` with the torsion's standard deviation in motion, `torsion_std_nm`
/// along the torsion axis `axis_s` (sensor frame), added to its deviation
/// per sensor axis; unchanged when it is 0 (at rest: to the bit).
pub(super) fn widened(
    r: TorqueResidual,
    torsion_std_nm: f64,
    axis_s: impl FnOnce() -> Vec3,
) -> TorqueResidual {
    if torsion_std_nm == 0.0 {
        return r;
    }
    let spread = axis_s() * torsion_std_nm;
    TorqueResidual {
        std_nm: (r.std_nm.component_mul(&r.std_nm) + spread.component_mul(&spread))
            .map(nalgebra::ComplexField::sqrt),
        ..r
    }
}

/// A Fault for the first sensor axis whose residual is beyond `max_sigma`
/// standard deviations (NaN counts as beyond).
pub(super) fn torque_verdict(check: &TorqueCheck, r: &TorqueResidual) -> Option<Reason> {
    for ((axis, residual_nm), std_nm) in Axis::ALL
        .iter()
        .zip(r.residual_nm.iter())
        .zip(r.std_nm.iter())
    {
        let within = residual_nm.abs() <= check.max_sigma * std_nm;
        if !within {
            return Some(Reason::TorqueImplausible {
                axis: *axis,
                residual_nm: *residual_nm,
                std_nm: *std_nm,
                max_sigma: check.max_sigma,
            });
        }
    }
    None
}

sar_snapshot::config_struct!(TorqueCheck {
    std_nm,
    cross,
    force_var_n2,
    torque_var_nm2,
    offset_m,
    max_sigma,
});

sar_snapshot::config_struct!(SensorFrame { r_t, lever_s_m });
