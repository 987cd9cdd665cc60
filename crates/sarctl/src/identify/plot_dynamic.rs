//! The figure of `sarctl identify --dynamic --plot FILE.svg`: over the first
//! [`WINDOW_S`] of the excitation, the force at A across the rod's mean
//! direction in the vertical plane (the one that carries the inertia) as
//! measured and as the fitted model gives it, and below the residuals
//! (measured - model) of the three components over the whole run. SVG only.

use super::dynamic::DynamicIdentified;
use super::plot::{err, range};
use plotters::prelude::*;

/// The span of the upper panel, s.
pub const WINDOW_S: f64 = 10.0;

/// The figure as SVG text.
pub fn svg(result: &DynamicIdentified, gravity_mps2: [f64; 3]) -> Result<String, String> {
    let g = nalgebra::Vector3::from(gravity_mps2);
    let up = -g / g.norm();
    let pts: Vec<(f64, f64, f64)> = result
        .points
        .iter()
        .filter(|p| p.t_s <= WINDOW_S)
        .map(|p| (p.t_s, p.measured_n.dot(&up), p.model_n.dot(&up)))
        .collect();
    let residuals: Vec<(f64, f64)> = result
        .points
        .iter()
        .flat_map(|p| {
            let r = p.measured_n - p.model_n;
            [(p.t_s, r.x), (p.t_s, r.y), (p.t_s, r.z)]
        })
        .collect();
    let t_all = range(result.points.iter().map(|p| p.t_s));
    let t_window = range(pts.iter().map(|p| p.0));
    let y = range(pts.iter().flat_map(|p| [p.1, p.2]));
    let r = range(residuals.iter().map(|p| p.1));
    let f = &result.fit;
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (900, 820)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let (upper, lower) = root.split_vertically(520);
        let caption = format!(
            "vertical force at A: I_perp = {:.5} kg m^2, m = {:.4} kg, c = {:.5} m",
            f.inertia_perp_kgm2, f.mass_kg, f.com_m
        );
        let mut fit = chart(&upper, caption, t_window, y, "F_A up (N)").map_err(err)?;
        fit.draw_series(
            pts.iter()
                .map(|&(t, m, _)| Circle::new((t, m), 1, BLUE.filled())),
        )
        .map_err(err)?;
        fit.draw_series(LineSeries::new(
            pts.iter().map(|&(t, _, model)| (t, model)),
            RED.stroke_width(2),
        ))
        .map_err(err)?;
        let caption = format!(
            "residuals (measured - model, x y z), RMS {:.3} N, chi2/dof {:.2}",
            f.residual_rms_n, f.chi2_dof
        );
        let mut res = chart(&lower, caption, t_all, r, "residual (N)").map_err(err)?;
        res.draw_series(
            residuals
                .iter()
                .map(|&(t, x)| Circle::new((t, x), 1, BLUE.filled())),
        )
        .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(out)
}

/// A chart of f64 over f64.
type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, plotters::coord::Shift>,
    caption: String,
    x: (f64, f64),
    y: (f64, f64),
    y_desc: &str,
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}
