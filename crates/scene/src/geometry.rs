//! The robot's geometry as the 3D scene draws it ([`SceneGeometry`]), from a
//! configuration.

use sar_estimator::cycle::EstimatorConfig;

/// What the scene needs beyond the published state: the configuration's
/// geometry and the drawing's sizes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneGeometry {
    /// P_home, m.
    pub p_home_m: [f64; 3],
    /// B, the support, m.
    pub support_m: [f64; 3],
    /// L, the tip's distance along the rod from A's foot, m.
    pub length_m: f64,
    /// d, the rod axis' offset from A along w, m.
    pub offset_m: f64,
    /// The arrow's length per newton of F_tip, m/N.
    pub force_scale_m_per_n: f64,
    /// The rod's drawn diameter, m.
    pub rod_diameter_m: f64,
    /// The support ring's radius, m.
    pub support_radius_m: f64,
    /// The base frame's axes' length, m.
    pub axis_length_m: f64,
}

impl SceneGeometry {
    /// The geometry of a configuration, with the default drawing sizes
    /// (1 cm per newton: a 15 N stop limit is a 15 cm sphere radius).
    pub fn from_config(cfg: &EstimatorConfig) -> Self {
        let (cal, prof) = (&cfg.calibration, &cfg.profile);
        let v = |p: sar_estimator::Vec3| [p.x, p.y, p.z];
        Self {
            p_home_m: v(cal.p_home_m()),
            support_m: v(cal.support_m()),
            length_m: prof.length_m(),
            offset_m: prof.offset_m(),
            force_scale_m_per_n: 0.01,
            rod_diameter_m: 0.008,
            support_radius_m: 0.012,
            axis_length_m: 0.1,
        }
    }
}
